//! Files that molecular tools read and write: LAMMPS data files in,
//! extended XYZ and LAMMPS dump frames out (and back in).
//!
//! - [`read_lammps_data`]: a LAMMPS data file (docs.lammps.org/read_data.html)
//!   as [`LammpsData`]: box (orthogonal or triclinic, [`SimBox`]), atoms in
//!   increasing id with types, molecules, masses, unwrapped positions and
//!   velocities, bonds, angles and their harmonic coefficients.
//!   [`LammpsData::rigid`] turns bonds and angles into distance
//!   constraints, as LAMMPS' `fix shake … b … a …` does, and builds the
//!   [`ParticleSystem`](super::ParticleSystem) and its
//!   [`ParticleState`](super::ParticleState).
//! - [`ExtXyzWriter`] / [`ExtXyzReader`]: extended XYZ (ASE, OVITO).
//! - [`DumpWriter`] / [`DumpReader`]: LAMMPS' text dump
//!   (docs.lammps.org/dump.html).
//! - [`FrameSink`]: either writer as a run's observer, every k-th step.
//!
//! Numbers are written in their shortest form that reads back as the same
//! f64, so a frame read back is the state written, bit for bit. Every
//! error is a [`FileError`] naming the file and the line.
//!
//! ```
//! use geoshake_runtime::particles::io::{parse_lammps_data, ExtXyzReader, ExtXyzWriter, FrameSink};
//! use geoshake_runtime::particles::{Options, Rattle};
//! use geoshake_runtime::Stop;
//!
//! // Two rigid waters; ids need not be contiguous, image flags unwrap.
//! let text = "\
//! two waters
//!
//! 6 atoms
//! 4 bonds
//! 2 angles
//! 2 atom types
//! 0 20 xlo xhi
//! 0 20 ylo yhi
//! 0 20 zlo zhi
//!
//! Masses
//!
//! 1 15.9994
//! 2 1.008
//!
//! Atoms # molecular
//!
//! 10 1 1 1.0 1.0 1.0 0 0 0
//! 11 1 2 2.0 1.0 1.0 0 0 0
//! 12 1 2 0.6664 1.9428 1.0 0 0 0
//! 20 2 1 19.0 5.0 5.0 0 0 0
//! 21 2 2 0.0 5.0 5.0 1 0 0
//! 22 2 2 18.6664 5.9428 5.0 0 0 0
//!
//! Bonds
//!
//! 1 1 10 11
//! 2 1 10 12
//! 3 1 20 21
//! 4 1 20 22
//!
//! Angles
//!
//! 1 1 11 10 12
//! 2 1 21 20 22
//! ";
//! let data = parse_lammps_data(text, "two.data")?;
//! assert_eq!(data.positions[12], 20.0); // atom 21: x = 0 + 1·lx
//! let (system, mut state) = data.rigid().bond_length(1, 1.0).angle_degrees(1, 109.47).build()?;
//! let mut rattle = Rattle::new(system, 1.0, Options::default()).unwrap();
//! rattle.project(&mut state).unwrap();
//!
//! let mut xyz = ExtXyzWriter::new(Vec::new(), data.species()).with_box(data.sim_box);
//! let out = rattle.run(&state, Stop::Steps(20)).stride(10).observe(xyz.observer()).execute();
//! assert!(out.error.is_none());
//! let bytes = xyz.finish()?;
//! let frames = ExtXyzReader::new(&bytes[..], "mem").collect::<Result<Vec<_>, _>>()?;
//! assert_eq!(frames.len(), 3); // steps 0, 10, 20
//! assert_eq!(frames[2].positions, out.trajectory.last().unwrap().q.as_slice());
//! # Ok::<(), geoshake_runtime::particles::io::FileError>(())
//! ```

mod dump;
mod error;
mod lammps_data;
mod number;
mod rigid;
mod sim_box;
mod stream;
mod xyz;

pub use dump::{DumpFrame, DumpReader, DumpWriter};
pub use error::FileError;
pub use lammps_data::{parse_lammps_data, read_lammps_data, Angle, AtomStyle, Bond, LammpsData};
pub use rigid::Rigid;
pub use sim_box::SimBox;
pub use stream::FrameSink;
pub use xyz::{ExtXyzReader, ExtXyzWriter, XyzFrame};
