//! `particles::io`: LAMMPS data files in (every typed error with its line),
//! extended XYZ and dump frames out and back bit for bit, frames written
//! while a run runs, and a run from a data file that is the
//! `examples/scale.rs --lammps-data` run.

use std::io::Write;
use std::path::PathBuf;

use geoshake::runtime::particles::io::{
    parse_lammps_data, read_lammps_data, AtomStyle, DumpReader, DumpWriter, ExtXyzReader,
    ExtXyzWriter, FileError, FrameSink, SimBox,
};
use geoshake::runtime::particles::{
    generate, stencils::Distance, Options, ParticleState, ParticleSystem, Rattle, Table,
};
use geoshake::runtime::Stop;

/// A file of its own under the system's temporary directory.
fn temp_file(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("geoshake-particles-io-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// Two waters and an ion, atom style full: ids unsorted and with gaps, a
/// triclinic box, image flags, velocities, harmonic coefficients.
const DATA: &str = "\
hand-written: two waters and a sodium ion

7 atoms
4 bonds
2 angles
3 atom types
1 bond types
1 angle types
-1.0 9.0 xlo xhi
0.0 8.0 ylo yhi
0.5 6.5 zlo zhi
2.0 -1.0 0.5 xy xz yz

Masses

1 15.9994 # O
2 1.008 # H
3 22.99

Pair Coeffs # lj/cut

1 0.1553 3.166
2 0.0 0.0
3 0.1 2.0

Bond Coeffs # harmonic

1 450.0 1.0

Angle Coeffs # harmonic

1 55.0 109.47

Atoms # full

30 2 2 0.4238 0.5 0.0 1.0 0 0 0
10 1 1 -0.8476 1.0 1.0 1.0 0 0 0
12 1 2 0.4238 1.9 1.2 1.0 1 -1 2
11 1 2 0.4238 0.7 2.0 1.0 0 0 0
28 2 1 -0.8476 1.0 1.0 3.0 0 0 0
29 2 2 0.4238 1.6 1.0 3.8 0 0 0
99 3 3 1.0 4.0 4.0 4.0 0 0 0

Velocities

99 0.0 0.0 0.0
10 0.001 -0.002 0.003
11 0.1 0.2 0.3
12 -1e-3 2.5e-4 0.0
28 0.0 0.0 1.0
29 0.0 1.0 0.0
30 1.0 0.0 0.0

Bonds

1 1 10 11
2 1 10 12
7 1 28 29
8 1 28 30

Angles

1 1 11 10 12
5 1 29 28 30
";

#[test]
fn reads_a_hand_written_triclinic_file() {
    let path = temp_file("hand.data", DATA);
    let d = read_lammps_data(&path).unwrap();
    assert_eq!(d.file, path);
    assert_eq!(d.atom_style, AtomStyle::Full);
    assert_eq!(d.ids, [10, 11, 12, 28, 29, 30, 99]);
    assert_eq!(d.types, [1, 2, 2, 1, 2, 2, 3]);
    assert_eq!(d.molecules, [1, 1, 1, 2, 2, 2, 3]);
    assert_eq!(d.charges.as_ref().unwrap()[6], 1.0);
    assert_eq!(
        d.masses,
        [15.9994, 1.008, 1.008, 15.9994, 1.008, 1.008, 22.99]
    );
    assert_eq!(d.species(), ["O", "H", "H", "O", "H", "H", "Na"]);
    assert_eq!(
        d.sim_box,
        SimBox::orthogonal([-1.0, 0.0, 0.5], [9.0, 8.0, 6.5]).with_tilt([2.0, -1.0, 0.5])
    );
    // Atom 12 has images (1, −1, 2): x + a − b + 2c with a = (10, 0, 0),
    // b = (2, 8, 0), c = (−1, 0.5, 6).
    assert_eq!(d.images[2], [1, -1, 2]);
    let x12 = [1.9 + 10.0 - 2.0 - 2.0, 1.2 - 8.0 + 1.0, 1.0 + 12.0];
    assert_eq!(&d.positions[6..9], &x12);
    assert_eq!(&d.positions[0..3], &[1.0, 1.0, 1.0]);
    assert!(d.has_velocities);
    assert_eq!(&d.velocities[3..6], &[0.1, 0.2, 0.3]);
    assert_eq!(&d.velocities[6..9], &[-1e-3, 2.5e-4, 0.0]);
    assert_eq!(d.momenta()[15], 1.008);
    let bonds: Vec<_> = d.bonds.iter().map(|b| b.atoms).collect();
    assert_eq!(bonds, [[0, 1], [0, 2], [3, 4], [3, 5]]);
    assert_eq!(d.angles[1].atoms, [4, 3, 5]);
    assert_eq!(d.bond_coeffs[&1], [450.0, 1.0]);
    assert_eq!(d.angle_style.as_deref(), Some("harmonic"));

    // The constraints from the coefficients: O–H at 1.0, H–H at
    // 2 sin(109.47°/2), rows sorted by (min, max).
    let (system, state) = d.rigid().build().unwrap();
    assert_eq!((system.particles(), system.constraints()), (7, 6));
    let t = system.constraint_families()[0].table();
    let rows: Vec<_> = (0..t.len())
        .map(|k| (t.particles(k).to_vec(), t.data(k)[0]))
        .collect();
    let hh = 2.0 * (109.47f64.to_radians() / 2.0).sin();
    assert_eq!(
        rows,
        [
            (vec![0, 1], 1.0),
            (vec![0, 2], 1.0),
            (vec![1, 2], hh),
            (vec![3, 4], 1.0),
            (vec![3, 5], 1.0),
            (vec![4, 5], hh),
        ]
    );
    assert_eq!(state.q(), d.positions.as_slice());
    // Given lengths win over the coefficients; unequal legs use the law
    // of cosines; choosing no angle type leaves the bonds only.
    let (s2, _) = d
        .rigid()
        .bond_length(1, 2.0)
        .angle_degrees(1, 60.0)
        .build()
        .unwrap();
    let hh2 = s2.constraint_families()[0].table().data(2)[0];
    assert!((hh2 - 2.0).abs() < 1e-15, "{hh2}");
    let (s3, _) = d.rigid().angles(&[]).build().unwrap();
    assert_eq!(s3.constraints(), 4);
}

/// `DATA` with `from` replaced by `to` (exactly once).
fn edit(from: &str, to: &str) -> String {
    assert_eq!(DATA.matches(from).count(), 1, "{from}");
    DATA.replace(from, to)
}

fn line_of(text: &str, needle: &str) -> usize {
    text.lines().position(|l| l.contains(needle)).unwrap() + 1
}

#[test]
fn every_error_names_its_line() {
    let check = |text: String, needle: &str, ok: &dyn Fn(&FileError) -> bool| {
        let e = parse_lammps_data(&text, "bad.data").unwrap_err();
        assert!(ok(&e), "{e:?}");
        let line = line_of(&text, needle);
        assert_eq!(e.line(), Some(line), "{e}");
        let msg = e.to_string();
        assert!(msg.starts_with(&format!("bad.data:{line}: ")), "{msg}");
    };
    // A bond naming an atom id the file does not have.
    check(edit("8 1 28 30", "8 1 28 31"), "8 1 28 31", &|e| {
        matches!(
            e,
            FileError::DanglingAtom {
                id: 31,
                section: "Bonds",
                ..
            }
        )
    });
    check(edit("5 1 29 28 30", "5 1 29 28 3"), "5 1 29 28 3", &|e| {
        matches!(
            e,
            FileError::DanglingAtom {
                id: 3,
                section: "Angles",
                ..
            }
        )
    });
    check(
        edit("99 0.0 0.0 0.0", "98 0.0 0.0 0.0"),
        "98 0.0 0.0 0.0",
        &|e| {
            matches!(
                e,
                FileError::DanglingAtom {
                    id: 98,
                    section: "Velocities",
                    ..
                }
            )
        },
    );
    // Two atoms with one id: the second is named, the first's line given.
    let text = edit("99 3 3 1.0", "11 3 3 1.0");
    let first = line_of(&text, "11 1 2 0.4238");
    check(
        text,
        "11 3 3 1.0",
        &|e| matches!(e, FileError::DuplicateAtom { id: 11, first: f, .. } if *f == first),
    );
    // A type with no mass: its first atom.
    check(edit("99 3 3 1.0", "99 3 4 1.0"), "99 3 4", &|e| {
        matches!(e, FileError::MissingMass { atom_type: 4, .. })
    });
    // Counts against the header: the section's name line.
    check(edit("7 atoms", "8 atoms"), "Atoms # full", &|e| {
        matches!(
            e,
            FileError::CountMismatch {
                header: 8,
                found: 7,
                what: "atoms",
                ..
            }
        )
    });
    check(edit("4 bonds", "5 bonds"), "Bonds", &|e| {
        matches!(
            e,
            FileError::CountMismatch {
                header: 5,
                found: 4,
                ..
            }
        )
    });
    check(edit("3 atom types", "4 atom types"), "Masses", &|e| {
        matches!(
            e,
            FileError::CountMismatch {
                header: 4,
                found: 3,
                ..
            }
        )
    });
    // Numbers that do not parse, in the header and in a section.
    check(
        edit("1.0 4.0 4.0 4.0", "1.0 4.0 4,0 4.0"),
        "4,0",
        &|e| matches!(e, FileError::Number { found, expected, .. } if found == "4,0" && expected == "a coordinate"),
    );
    check(
        edit("-1.0 9.0 xlo xhi", "-1.0 nine xlo xhi"),
        "nine",
        &|e| matches!(e, FileError::Number { found, .. } if found == "nine"),
    );
    check(
        edit(
            "12 1 2 0.4238 1.9 1.2 1.0 1 -1 2",
            "12 1 2 0.4238 1.9 1.2 1.0 1 -1 2.5",
        ),
        "2.5",
        &|e| matches!(e, FileError::Number { expected, .. } if expected.contains("image flag")),
    );
    // A row with a column too many for its style.
    check(
        edit(
            "99 3 3 1.0 4.0 4.0 4.0 0 0 0",
            "99 3 3 1.0 4.0 4.0 4.0 0 0 0 7",
        ),
        "4.0 0 0 0 7",
        &|e| matches!(e, FileError::Malformed { .. }),
    );
    // A section the header requires.
    let text = DATA[..DATA.find("Angles\n\n1 1").unwrap()].to_string();
    let e = parse_lammps_data(&text, "bad.data").unwrap_err();
    assert!(
        matches!(
            e,
            FileError::MissingSection {
                section: "Angles",
                count: 2,
                ..
            }
        ),
        "{e:?}"
    );
    assert_eq!(
        e.to_string(),
        "bad.data: the header announces 2 angles, but there is no Angles section"
    );
    // Lengths the constraints need and nobody gave.
    let d = parse_lammps_data(&edit("1 450.0 1.0", "1 450.0 1.0 2.0"), "x.data").unwrap();
    let e = d.rigid().build().err().unwrap();
    assert!(
        matches!(
            e,
            FileError::MissingLength {
                kind: "bond",
                type_id: 1,
                ..
            }
        ),
        "{e:?}"
    );
    // An angle whose leg is not a bond.
    let d = parse_lammps_data(&edit("5 1 29 28 30", "5 1 29 99 30"), "x.data").unwrap();
    let e = d.rigid().build().err().unwrap();
    assert_eq!(e.line(), Some(line_of(DATA, "5 1 29 28 30")));
    // A missing file.
    let e = read_lammps_data("/nonexistent/dir/x.data").unwrap_err();
    assert!(
        matches!(e, FileError::Io { .. }) && e.to_string().starts_with("/nonexistent/dir/x.data: ")
    );
}

/// Awkward f64s: tiny, huge, subnormal, negative zero, thirds.
fn awkward(n: usize, seed: u64) -> Vec<f64> {
    let mut s = seed;
    (0..n)
        .map(|i| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (s >> 11) as f64 / (1u64 << 53) as f64;
            match i % 7 {
                0 => u,
                1 => -u * 1e-300,
                2 => u * 1e300,
                3 => 5e-324 * (i as f64),
                4 => -0.0,
                5 => (i as f64) / 3.0,
                _ => (u - 0.5) * 40.0,
            }
        })
        .collect()
}

fn bits(x: &[f64]) -> Vec<u64> {
    x.iter().map(|v| v.to_bits()).collect()
}

#[test]
fn extxyz_round_trip_bit_for_bit() {
    let n = 11;
    let species: Vec<String> = (0..n)
        .map(|a| ["O", "H", "Na"][a % 3].to_string())
        .collect();
    let b = SimBox::orthogonal([-1.0, 0.0, 0.25], [9.0, 8.0, 6.5]).with_tilt([2.0, -1.0, 0.5]);
    let path = temp_file("round.xyz", "");
    let mut w = ExtXyzWriter::create(&path, species.clone())
        .unwrap()
        .with_box(b);
    let frames: Vec<_> = (0..4u64)
        .map(|k| {
            (
                k * 7,
                k as f64 * 0.1,
                awkward(3 * n, k),
                awkward(3 * n, 100 + k),
            )
        })
        .collect();
    for (step, t, q, p) in &frames {
        w.write_frame(*step, *t, q, p).unwrap();
    }
    assert_eq!(w.frames(), 4);
    w.finish().unwrap();
    let back: Vec<_> = ExtXyzReader::open(&path)
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(back.len(), 4);
    for ((step, t, q, p), f) in frames.iter().zip(&back) {
        assert_eq!((f.step, f.time.to_bits()), (*step, t.to_bits()));
        assert_eq!(bits(&f.positions), bits(q));
        assert_eq!(bits(&f.momenta), bits(p));
        assert_eq!(f.species, species);
        let fb = f.sim_box.unwrap();
        assert_eq!((fb.lo, fb.tilt), (b.lo, b.tilt));
        assert_eq!(fb.lengths(), b.lengths());
    }
    // A wrong-length state is refused before anything is written.
    let mut w = ExtXyzWriter::new(Vec::new(), species);
    let e = w.write_frame(0, 0.0, &[0.0; 3], &[0.0; 3]).unwrap_err();
    assert!(matches!(
        e,
        FileError::Shape {
            what: "positions",
            got: 3,
            expected: 33,
            ..
        }
    ));
    assert!(w.finish().unwrap().is_empty());
}

#[test]
fn dump_round_trip_bit_for_bit() {
    let n = 10;
    let types: Vec<u32> = (0..n).map(|a| 1 + (a % 3) as u32).collect();
    let masses: Vec<f64> = (0..n).map(|a| [15.9994, 1.008, 12.011][a % 3]).collect();
    let ids: Vec<u64> = (0..n as u64).map(|a| 5 + 3 * a).collect();
    for b in [
        SimBox::orthogonal([-1.0, 0.0, 0.25], [9.0, 8.0, 6.5]),
        SimBox::orthogonal([0.0; 3], [10.0, 8.0, 6.0]).with_tilt([2.0, -1.0, 0.5]),
    ] {
        let mut w =
            DumpWriter::new(Vec::new(), b, types.clone(), masses.clone()).with_ids(ids.clone());
        let frames: Vec<_> = (0..3u64)
            .map(|k| {
                (
                    k * 100,
                    k as f64 * 2.0,
                    awkward(3 * n, k),
                    awkward(3 * n, 50 + k),
                )
            })
            .collect();
        for (step, t, q, p) in &frames {
            w.write_frame(*step, *t, q, p).unwrap();
        }
        let text = w.finish().unwrap();
        let back: Vec<_> = DumpReader::new(&text[..], "mem")
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(back.len(), 3);
        for ((step, t, q, p), f) in frames.iter().zip(&back) {
            assert_eq!((f.step, f.time), (*step, Some(*t)));
            assert_eq!((&f.ids, &f.types, f.unwrapped), (&ids, &types, true));
            assert_eq!(bits(&f.positions), bits(q));
            // Written as v = p/m: what was written comes back.
            let v: Vec<f64> = p
                .iter()
                .enumerate()
                .map(|(i, p)| p / masses[i / 3])
                .collect();
            assert_eq!(bits(&f.velocities), bits(&v));
            if b.is_triclinic() {
                assert_eq!(f.sim_box.tilt, b.tilt);
                for c in 0..3 {
                    assert!((f.sim_box.lo[c] - b.lo[c]).abs() <= 1e-15 * 10.0);
                    assert!((f.sim_box.hi[c] - b.hi[c]).abs() <= 1e-15 * 10.0);
                }
            } else {
                assert_eq!(f.sim_box, b);
            }
        }
    }
    // Without ITEM: TIME (for tools that expect TIMESTEP first).
    let b = SimBox::default();
    let mut w = DumpWriter::new(Vec::new(), b, vec![1], vec![1.0]).time(false);
    w.write_frame(3, 1.0, &[0.0; 3], &[0.0; 3]).unwrap();
    let text = w.finish().unwrap();
    assert!(text.starts_with(b"ITEM: TIMESTEP\n3\n"));
    let f = DumpReader::new(&text[..], "mem").next().unwrap().unwrap();
    assert_eq!((f.step, f.time), (3, None));
    // A truncated frame: a typed error naming the line after the end.
    let cut = &text[..text.len() - 10];
    let e = DumpReader::new(cut, "cut.dump")
        .next()
        .unwrap()
        .unwrap_err();
    assert!(
        matches!(e, FileError::Malformed { .. } | FileError::Number { .. }),
        "{e:?}"
    );
    assert_eq!(e.line(), Some(10));
}

/// A small box of projected waters at 300 K, with its rattle.
fn waters(n: usize) -> (Rattle, ParticleState) {
    let (system, mut state) = generate::water(n, 3).unwrap();
    let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    rattle.project(&mut state).unwrap();
    generate::set_temperature(rattle.system(), &mut state, 300.0);
    (rattle, state)
}

#[test]
fn streaming_every_kth_step_of_a_water_run() {
    let (mut rattle, state) = waters(8);
    let n = rattle.system().particles();
    let species: Vec<String> = (0..n)
        .map(|a| if a % 3 == 0 { "O" } else { "H" }.into())
        .collect();
    let types = (0..n).map(|a| if a % 3 == 0 { 1 } else { 2 }).collect();
    let l = generate::water_box(8);
    let b = SimBox::orthogonal([0.0; 3], l);
    let masses = rattle.system().masses().to_vec();
    let mut xyz = ExtXyzWriter::new(Vec::new(), species).with_box(b);
    let mut dump = DumpWriter::new(Vec::new(), b, types, masses.clone());
    // Observe every 5th step (and keep them), write every 10th: 0 … 40,
    // not the last (45) that the run also observes.
    let out = rattle
        .run(&state, Stop::Steps(45))
        .stride(5)
        .observe(|k, t, z| {
            xyz.every(10)(k, t, z);
            dump.every(10)(k, t, z);
        })
        .execute();
    assert!(out.error.is_none(), "{:?}", out.error);
    let traj = out.trajectory;
    assert_eq!(traj.len(), 10);
    let xyz = xyz.finish().unwrap();
    let frames: Vec<_> = ExtXyzReader::new(&xyz[..], "mem")
        .collect::<Result<_, _>>()
        .unwrap();
    let steps: Vec<u64> = frames.iter().map(|f| f.step).collect();
    assert_eq!(steps, [0, 10, 20, 30, 40]);
    let dump = dump.finish().unwrap();
    let dframes: Vec<_> = DumpReader::new(&dump[..], "mem")
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(dframes.len(), 5);
    for (i, (f, d)) in frames.iter().zip(&dframes).enumerate() {
        let (zq, zp) = (traj.q(2 * i), traj.p(2 * i));
        assert_eq!(traj.step(2 * i), f.step);
        assert_eq!(f.time, 20.0 * i as f64);
        assert_eq!(bits(&f.positions), bits(zq));
        assert_eq!(bits(&f.momenta), bits(zp));
        assert_eq!(bits(&d.positions), bits(zq));
        let v: Vec<f64> = zp
            .iter()
            .enumerate()
            .map(|(j, p)| p / masses[j / 3])
            .collect();
        assert_eq!(bits(&d.velocities), bits(&v));
    }
}

/// A sink that takes `limit` bytes and then refuses.
#[derive(Debug)]
struct Full {
    bytes: Vec<u8>,
    limit: usize,
}

impl Write for Full {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.bytes.len() + buf.len() > self.limit {
            return Err(std::io::Error::other("disk full"));
        }
        self.bytes.extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[test]
fn a_failing_writer_keeps_its_frames_and_returns_the_error() {
    let (mut rattle, state) = waters(4);
    let n = rattle.system().particles();
    let species: Vec<String> = vec!["X".into(); n];
    // Room for two frames and a half.
    let mut probe = ExtXyzWriter::new(Vec::new(), species.clone());
    probe.write_frame(0, 0.0, state.q(), state.p()).unwrap();
    let frame = probe.finish().unwrap().len();
    let sink = Full {
        bytes: Vec::new(),
        limit: 2 * frame + frame / 2,
    };
    let mut w = ExtXyzWriter::new(sink, species).named("full.xyz");
    let out = rattle
        .run(&state, Stop::Steps(50))
        .stride(10)
        .store(false)
        .observe(w.observer())
        .execute();
    assert!(out.error.is_none());
    assert!(w.failed());
    assert_eq!(w.frames(), 2);
    let e = w.finish().unwrap_err();
    assert!(
        matches!(&e, FileError::Io { file, .. } if file.to_str() == Some("full.xyz")),
        "{e:?}"
    );
    assert!(e.to_string().contains("disk full"));
}

/// The reader `examples/scale.rs` had before `particles::io`: the oracle
/// for the library's reading of a `bench/lammps/gen_data.py` water file.
fn old_scale_reader(text: &str) -> (ParticleSystem, ParticleState) {
    let mut lines = text.lines();
    let (mut q, mut v, mut types) = (Vec::new(), Vec::new(), Vec::new());
    let mut box_len = [0.0f64; 3];
    let mut type_mass = std::collections::HashMap::new();
    let mut pairs: Vec<(usize, usize, f64)> = Vec::new();
    let r_hh = 2.0 * (109.47f64.to_radians() / 2.0).sin();
    while let Some(line) = lines.next() {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            [n, "atoms"] => {
                let n: usize = n.parse().unwrap();
                (q, v, types) = (vec![0.0; 3 * n], vec![0.0; 3 * n], vec![0usize; n]);
            }
            [lo, hi, lab, _] if lab.ends_with("lo") => {
                let k = (lab.as_bytes()[0] - b'x') as usize;
                let (lo, hi): (f64, f64) = (lo.parse().unwrap(), hi.parse().unwrap());
                box_len[k] = hi - lo;
            }
            [section @ ("Masses" | "Atoms" | "Bonds" | "Angles" | "Velocities"), ..] => {
                lines.next();
                for row in lines.by_ref() {
                    let r: Vec<&str> = row.split_whitespace().collect();
                    if r.is_empty() {
                        break;
                    }
                    let num = |i: usize| -> f64 { r[i].parse().unwrap() };
                    let idx = |i: usize| -> usize { r[i].parse::<usize>().unwrap() - 1 };
                    match *section {
                        "Masses" => {
                            type_mass.insert(num(0) as usize, num(1));
                        }
                        "Atoms" => {
                            let a = idx(0);
                            types[a] = num(2) as usize;
                            for c in 0..3 {
                                q[3 * a + c] = num(3 + c) + num(6 + c) * box_len[c];
                            }
                        }
                        "Bonds" => pairs.push((idx(2), idx(3), 1.0)),
                        "Angles" => pairs.push((idx(2), idx(4), r_hh)),
                        _ => {
                            let a = idx(0);
                            for c in 0..3 {
                                v[3 * a + c] = num(1 + c);
                            }
                        }
                    }
                }
            }
            _ => {}
        }
    }
    let masses: Vec<f64> = types.iter().map(|t| type_mass[t]).collect();
    let p = v
        .iter()
        .enumerate()
        .map(|(i, v)| masses[i / 3] * v)
        .collect();
    pairs.sort_by_key(|&(a, b, _)| (a.min(b), a.max(b)));
    let mut table = Table::with_capacity(2, 1, pairs.len());
    for (a, b, l) in pairs {
        table.push(&[a, b], &[l]).unwrap();
    }
    let system = ParticleSystem::new(3, masses)
        .unwrap()
        .with_constraints("bond", Distance::<3>, table)
        .unwrap();
    (system, ParticleState::new(q, p))
}

/// A water box written as `bench/lammps/gen_data.py` writes it: positions
/// wrapped into the box with image flags (12 decimals), velocities
/// (15 significant digits), all bonds, then all angles.
fn gen_data_text(n: usize) -> String {
    let (rattle, state) = waters(n);
    let l = generate::water_box(n);
    let (q, p, m) = (state.q(), state.p(), rattle.system().masses());
    let mut s = format!("SPC/E-geometry water, {n} molecules (gen_data.py)\n\n");
    s += &format!(
        "{} atoms\n{} bonds\n{n} angles\n\n2 atom types\n1 bond types\n1 angle types\n\n",
        3 * n,
        2 * n
    );
    for (d, lab) in l.iter().zip(["x", "y", "z"]) {
        s += &format!("0.0 {d:.10} {lab}lo {lab}hi\n");
    }
    s += "\nMasses\n\n1 15.9994\n2 1.008\n\nAtoms # molecular\n\n";
    for i in 0..3 * n {
        let t = if i % 3 == 0 { 1 } else { 2 };
        let x: Vec<f64> = (0..3).map(|c| q[3 * i + c]).collect();
        // Move a few atoms out of the box (images ±1) as the wrapping does.
        let img: Vec<i32> = (0..3)
            .map(|c| {
                if (i + c) % 5 == 0 {
                    1
                } else if (i + c) % 7 == 0 {
                    -1
                } else {
                    0
                }
            })
            .collect();
        let lq: Vec<f64> = (0..3)
            .map(|c| format!("{:.10}", l[c]).parse().unwrap())
            .collect();
        s += &format!("{} {} {t}", i + 1, i / 3 + 1);
        for c in 0..3 {
            s += &format!(" {:.12}", x[c] - img[c] as f64 * lq[c]);
        }
        s += &format!(" {} {} {}\n", img[0], img[1], img[2]);
    }
    s += "\nBonds\n\n";
    for k in 0..n {
        let o = 3 * k + 1;
        s += &format!(
            "{} 1 {o} {}\n{} 1 {o} {}\n",
            2 * k + 1,
            o + 1,
            2 * k + 2,
            o + 2
        );
    }
    s += "\nAngles\n\n";
    for k in 0..n {
        let o = 3 * k + 1;
        s += &format!("{} 1 {} {o} {}\n", k + 1, o + 1, o + 2);
    }
    s += "\nVelocities\n\n";
    for i in 0..3 * n {
        let v: Vec<f64> = (0..3).map(|c| p[3 * i + c] / m[i]).collect();
        s += &format!("{} {:.15e} {:.15e} {:.15e}\n", i + 1, v[0], v[1], v[2]);
    }
    s
}

#[test]
fn a_run_from_a_data_file_is_the_scale_example_run() {
    let n = 27;
    let text = gen_data_text(n);
    let path = temp_file("water_27.data", &text);
    // What examples/scale.rs --lammps-data builds now.
    let (system, state) = read_lammps_data(&path)
        .unwrap()
        .rigid()
        .bond_length(1, 1.0)
        .angle_degrees(1, 109.47)
        .build()
        .unwrap();
    let (old_system, old_state) = old_scale_reader(&text);
    assert_eq!(bits(system.masses()), bits(old_system.masses()));
    let (t, t_old) = (
        system.constraint_families()[0].table(),
        old_system.constraint_families()[0].table(),
    );
    assert_eq!(t.all_particles(), t_old.all_particles());
    assert_eq!(bits(t.all_data()), bits(t_old.all_data()));
    assert_eq!(bits(state.q()), bits(old_state.q()));
    assert_eq!(bits(state.p()), bits(old_state.p()));
    // And the runs agree bit for bit, on M and M^H to the tolerance.
    let mut runs = Vec::new();
    for (system, state) in [(system, state), (old_system, old_state)] {
        let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
        let mut state = state;
        rattle.project(&mut state).unwrap();
        let out = rattle.run(&state, Stop::Steps(100)).stride(50).execute();
        assert!(out.error.is_none(), "{:?}", out.error);
        assert!(out.summary.max_residual.unwrap() <= 1e-10);
        runs.push(out.trajectory.last().unwrap().q.as_slice().to_vec());
    }
    assert_eq!(bits(&runs[0]), bits(&runs[1]));
}

/// ASE reads our extended XYZ: cell, positions, momenta, step and time.
/// Needs a Python with ASE: `GEOSHAKE_PYTHON` or `python3`; skipped (with
/// the reason printed) without one, unless `GEOSHAKE_REQUIRE_ASE` is set
/// (CI sets both, to the Python package's venv, which has ASE).
#[test]
fn ase_reads_our_extxyz() {
    let python = std::env::var("GEOSHAKE_PYTHON").unwrap_or_else(|_| "python3".into());
    let has_ase = std::process::Command::new(&python)
        .args(["-c", "import ase"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_ase {
        assert!(
            std::env::var_os("GEOSHAKE_REQUIRE_ASE").is_none(),
            "GEOSHAKE_REQUIRE_ASE is set but `{python} -c 'import ase'` fails"
        );
        eprintln!(
            "ase_reads_our_extxyz: skipped, `{python} -c 'import ase'` fails (set GEOSHAKE_PYTHON)"
        );
        return;
    }
    let b = SimBox::orthogonal([0.0; 3], [10.0, 8.0, 6.0]).with_tilt([2.0, -1.0, 0.5]);
    let path = temp_file("ase.xyz", "");
    let mut w = ExtXyzWriter::create(&path, vec!["O".into(), "H".into(), "H".into()])
        .unwrap()
        .with_box(b);
    let q = [0.1, 0.2, 0.3, 1.0 / 3.0, 1.5, 2.5, 3.0, 4.0, 5.0];
    let p = [1.0, -2.0, 1e-20, 0.0, 0.5, 0.25, 7.0, 8.0, 9.0];
    w.write_frame(0, 0.0, &q, &p).unwrap();
    w.write_frame(10, 20.0, &q, &p).unwrap();
    w.finish().unwrap();
    let script = r#"
import sys, ase.io
fs = ase.io.read(sys.argv[1], index=":", format="extxyz")
a = fs[1]
print(len(fs), a.get_chemical_symbols(), a.info["step"], a.info["Time"])
print(" ".join(repr(float(x)) for x in a.cell.array.ravel()))
print(" ".join(repr(float(x)) for x in a.positions.ravel()))
print(" ".join(repr(float(x)) for x in a.get_momenta().ravel()))
"#;
    let out = std::process::Command::new(&python)
        .args(["-c", script])
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "2 ['O', 'H', 'H'] 10 20.0");
    let nums = |l: &str| -> Vec<f64> { l.split_whitespace().map(|x| x.parse().unwrap()).collect() };
    assert_eq!(
        nums(lines[1]),
        [10.0, 0.0, 0.0, 2.0, 8.0, 0.0, -1.0, 0.5, 6.0]
    );
    assert_eq!(bits(&nums(lines[2])), bits(&q));
    assert_eq!(bits(&nums(lines[3])), bits(&p));
}
