//! LAMMPS data files (the `read_data` command's input): what one holds,
//! [`LammpsData`] with its [`Bond`]s, [`Angle`]s and [`AtomStyle`], read
//! by [`read_lammps_data`] (the format and its parser: `parser`).

mod parser;

pub use parser::{parse_lammps_data, read_lammps_data};

use super::SimBox;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// How the Atoms section's rows are laid out (LAMMPS' atom_style).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum AtomStyle {
    /// id type x y z.
    Atomic,
    /// id mol type x y z.
    Molecular,
    /// id mol type q x y z.
    Full,
}

impl AtomStyle {
    /// Columns before the image flags.
    fn columns(self) -> usize {
        match self {
            AtomStyle::Atomic => 5,
            AtomStyle::Molecular => 6,
            AtomStyle::Full => 7,
        }
    }
}

/// One row of the Bonds section: its type and its two atoms (particle
/// indices, not ids).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct Bond {
    /// The bond type.
    pub bond_type: u32,
    /// The two atoms.
    pub atoms: [usize; 2],
    /// The row's line in the file.
    pub line: usize,
}

/// One row of the Angles section: its type and its three atoms, the apex
/// in the middle (particle indices).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct Angle {
    /// The angle type.
    pub angle_type: u32,
    /// The outer atom, the apex, the other outer atom.
    pub atoms: [usize; 3],
    /// The row's line in the file.
    pub line: usize,
}

/// What a LAMMPS data file holds, atoms in increasing id.
///
/// ```
/// use geoshake_runtime::particles::io::parse_lammps_data;
/// let text = "\
/// one water
///
/// 3 atoms
/// 2 bonds
/// 2 atom types
/// 0 10 xlo xhi
/// 0 10 ylo yhi
/// 0 10 zlo zhi
///
/// Masses
///
/// 1 15.9994 # O
/// 2 1.008 # H
///
/// Atoms # molecular
///
/// 7 1 2 1.0 0.0 0.0
/// 3 1 1 0.0 0.0 0.0
/// 9 1 2 0.0 1.0 0.0
///
/// Bonds
///
/// 1 1 3 7
/// 2 1 3 9
/// ";
/// let data = parse_lammps_data(text, "water.data").unwrap();
/// assert_eq!(data.ids, vec![3, 7, 9]); // sorted: particle 0 is id 3
/// assert_eq!(data.masses, vec![15.9994, 1.008, 1.008]);
/// assert_eq!(data.bonds[0].atoms, [0, 1]);
/// assert_eq!(data.species(), vec!["O", "H", "H"]);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct LammpsData {
    /// The file it was read from (or the name it was given).
    pub file: PathBuf,
    /// The first line.
    pub title: String,
    /// The box.
    pub sim_box: SimBox,
    /// The Atoms rows' layout.
    pub atom_style: AtomStyle,
    /// Atom ids, increasing: particle a is atom `ids[a]`.
    pub ids: Vec<u64>,
    /// Atom types.
    pub types: Vec<u32>,
    /// Molecule ids (0 for atom style atomic).
    pub molecules: Vec<u64>,
    /// Charges (atom style full), else `None`.
    pub charges: Option<Vec<f64>>,
    /// Positions, 3 per atom, unwrapped with the image flags: x + i·a +
    /// j·b + k·c.
    pub positions: Vec<f64>,
    /// Image flags (0 where the file has none).
    pub images: Vec<[i32; 3]>,
    /// Velocities, 3 per atom (0 without a Velocities section).
    pub velocities: Vec<f64>,
    /// Whether the file has a Velocities section.
    pub has_velocities: bool,
    /// Mass per atom, from its type.
    pub masses: Vec<f64>,
    /// Mass per type, from the Masses section.
    pub type_masses: BTreeMap<u32, f64>,
    /// The comment after a type's mass (`1 15.9994 # O`), trimmed.
    pub type_labels: BTreeMap<u32, String>,
    /// The Bonds section.
    pub bonds: Vec<Bond>,
    /// The Angles section.
    pub angles: Vec<Angle>,
    /// The Bond Coeffs section, per type (K r0 for the harmonic style).
    pub bond_coeffs: BTreeMap<u32, Vec<f64>>,
    /// The Angle Coeffs section, per type (K θ0 in degrees for harmonic).
    pub angle_coeffs: BTreeMap<u32, Vec<f64>>,
    /// The style named in the comment after `Bond Coeffs`, if any.
    pub bond_style: Option<String>,
    /// The style named in the comment after `Angle Coeffs`, if any.
    pub angle_style: Option<String>,
}

impl LammpsData {
    /// The number of atoms.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether the file has no atoms.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// Momenta p = m v, 3 per atom.
    pub fn momenta(&self) -> Vec<f64> {
        self.velocities
            .iter()
            .enumerate()
            .map(|(i, v)| self.masses[i / 3] * v)
            .collect()
    }

    /// A chemical symbol per atom, for the extended XYZ species: the
    /// comment after the type's mass when it is one word (`1 15.9994 # O`),
    /// else the element whose standard atomic weight is within 0.05 of the
    /// mass (H, C, N, O, Na, P, S, Cl), else `X` (ASE's unknown element).
    pub fn species(&self) -> Vec<String> {
        const ELEMENTS: [(&str, f64); 8] = [
            ("H", 1.008),
            ("C", 12.011),
            ("N", 14.007),
            ("O", 15.999),
            ("Na", 22.990),
            ("P", 30.974),
            ("S", 32.06),
            ("Cl", 35.45),
        ];
        let label = |t: u32| -> String {
            if let Some(l) = self.type_labels.get(&t)
                && !l.is_empty()
                && !l.contains(char::is_whitespace)
            {
                return l.clone();
            }
            let m = self.type_masses.get(&t).copied().unwrap_or(f64::NAN);
            ELEMENTS
                .iter()
                .find(|(_, w)| (w - m).abs() < 0.05)
                .map_or("X", |(s, _)| s)
                .to_string()
        };
        let mut memo: BTreeMap<u32, String> = BTreeMap::new();
        self.types
            .iter()
            .map(|&t| memo.entry(t).or_insert_with(|| label(t)).clone())
            .collect()
    }
}
