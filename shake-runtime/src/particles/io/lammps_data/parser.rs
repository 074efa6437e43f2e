//! The parser of LAMMPS data files: [`read_lammps_data`] and
//! [`parse_lammps_data`], which make a [`LammpsData`].
//!
//! The format, as LAMMPS documents it (docs.lammps.org/read_data.html):
//! the first line is a title; then header lines, one count or box bound
//! each (`N atoms`, `N bonds`, `N angles`, `N atom types`, `xlo xhi`,
//! `ylo yhi`, `zlo zhi`, `xy xz yz`); then sections, each a name on its
//! own line, a blank line and one row per entry. `#` starts a comment.
//! Read here: Masses, Atoms, Velocities, Bonds, Angles, Bond Coeffs and
//! Angle Coeffs; every other section (Pair Coeffs, Dihedrals, …) is
//! skipped. The Atoms rows follow the atom style, taken from the comment
//! after `Atoms` (`Atoms # full`) or else from the number of columns
//! (images flags are optional):
//!
//! | style     | columns                          |
//! |-----------|----------------------------------|
//! | atomic    | id type x y z [ix iy iz]         |
//! | molecular | id mol type x y z [ix iy iz]     |
//! | full      | id mol type q x y z [ix iy iz]   |
//!
//! Atom ids may be in any order and need not be contiguous: the atoms are
//! numbered 0, 1, … in increasing id, which is the particle index of the
//! system built from them.

use super::{Angle, AtomStyle, Bond, LammpsData};
use crate::particles::io::number::parse;
use crate::particles::io::{FileError, SimBox};
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// Reads a LAMMPS data file.
///
/// Errors ([`FileError`], each with the file and the line): a number that
/// does not parse, a row with too few columns, two atoms with one id, a
/// bond, angle or velocity naming an id that is not an atom, an atom type
/// with no mass, a section with another count than the header's, a section
/// the header's counts require but the file lacks.
///
/// ```no_run
/// use geoshake_runtime::particles::io::read_lammps_data;
/// let data = read_lammps_data("bench/lammps/water_1000.data")?;
/// let (system, state) = data.rigid().angle_degrees(1, 109.47).build()?;
/// # Ok::<(), geoshake_runtime::particles::io::FileError>(())
/// ```
pub fn read_lammps_data(path: impl AsRef<Path>) -> Result<LammpsData, FileError> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|e| FileError::io(path, e))?;
    parse_lammps_data(&text, path)
}

/// One line: its number, its tokens before `#`, and the comment after it.
struct Line<'a> {
    no: usize,
    toks: Vec<&'a str>,
    comment: &'a str,
}

fn split(no: usize, raw: &str) -> Line<'_> {
    let (body, comment) = raw.split_once('#').unwrap_or((raw, ""));
    Line {
        no,
        toks: body.split_whitespace().collect(),
        comment: comment.trim(),
    }
}

/// A section: the line of its name, its style comment, and its rows.
struct Section<'a> {
    line: usize,
    comment: &'a str,
    rows: Vec<Line<'a>>,
}

/// A coefficient section: numbers per type, and the style its comment
/// names.
type Coeffs = (BTreeMap<u32, Vec<f64>>, Option<String>);

/// Header counts.
#[derive(Default)]
struct Counts {
    atoms: usize,
    bonds: usize,
    angles: usize,
    atom_types: usize,
}

/// [`read_lammps_data`] of a file's text; `name` is the file named in the
/// errors.
pub fn parse_lammps_data(text: &str, name: impl AsRef<Path>) -> Result<LammpsData, FileError> {
    let file = name.as_ref();
    let mut lines = text.lines().enumerate().map(|(i, l)| split(i + 1, l));
    let title = text.lines().next().unwrap_or("").trim().to_string();
    lines.next();
    let mut counts = Counts::default();
    let mut sim_box = SimBox::default();
    let mut sections: HashMap<String, Section> = HashMap::new();
    let mut current: Option<String> = None;
    for line in lines {
        let Some(&first) = line.toks.first() else {
            continue;
        };
        let starts_numeric = first
            .chars()
            .next()
            .is_some_and(|c| c.is_ascii_digit() || c == '-' || c == '+' || c == '.');
        if !starts_numeric {
            // A section's name: every token is a word.
            let name = line.toks.join(" ");
            if sections.contains_key(&name) {
                return Err(FileError::Malformed {
                    file: file.to_path_buf(),
                    line: line.no,
                    expected: format!("one {name} section, not a second"),
                });
            }
            sections.insert(
                name.clone(),
                Section {
                    line: line.no,
                    comment: line.comment,
                    rows: Vec::new(),
                },
            );
            current = Some(name);
        } else if let Some(name) = &current {
            sections.get_mut(name).expect("inserted").rows.push(line);
        } else {
            header_line(file, &line, &mut counts, &mut sim_box)?;
        }
    }
    build(file, title, counts, sim_box, sections)
}

fn header_line(
    file: &Path,
    line: &Line,
    counts: &mut Counts,
    sim_box: &mut SimBox,
) -> Result<(), FileError> {
    let t = &line.toks;
    let count = |what: &str| parse::<usize>(file, line.no, t.first().copied(), what);
    let float = |i: usize, what: &str| parse::<f64>(file, line.no, t.get(i).copied(), what);
    match t[1..] {
        ["atoms"] => counts.atoms = count("the number of atoms")?,
        ["bonds"] => counts.bonds = count("the number of bonds")?,
        ["angles"] => counts.angles = count("the number of angles")?,
        ["atom", "types"] => counts.atom_types = count("the number of atom types")?,
        [_, lo, hi] if lo.ends_with("lo") && hi.ends_with("hi") && lo.len() == 3 => {
            let c = match lo.as_bytes()[0] {
                b'x' => 0,
                b'y' => 1,
                b'z' => 2,
                _ => return Ok(()),
            };
            sim_box.lo[c] = float(0, "a lower box bound")?;
            sim_box.hi[c] = float(1, "an upper box bound")?;
        }
        [_, _, "xy", "xz", "yz"] => {
            for c in 0..3 {
                sim_box.tilt[c] = float(c, "a tilt factor")?;
            }
        }
        // Other header keywords (dihedrals, extra bond per atom, …) say
        // nothing the particle path uses.
        _ => {}
    }
    Ok(())
}

fn build(
    file: &Path,
    title: String,
    counts: Counts,
    sim_box: SimBox,
    mut sections: HashMap<String, Section>,
) -> Result<LammpsData, FileError> {
    let path = file.to_path_buf();
    let mismatch = |s: &Section, section: &str, what: &'static str, header: usize| {
        (s.rows.len() != header).then(|| FileError::CountMismatch {
            file: path.clone(),
            line: s.line,
            section: section.to_string(),
            what,
            header,
            found: s.rows.len(),
        })
    };
    let missing =
        |section: &'static str, what: &'static str, count: usize| FileError::MissingSection {
            file: path.clone(),
            section,
            what,
            count,
        };

    // Masses.
    let mut type_masses = BTreeMap::new();
    let mut type_labels = BTreeMap::new();
    if let Some(s) = sections.remove("Masses") {
        if let Some(e) = mismatch(&s, "Masses", "atom types", counts.atom_types) {
            return Err(e);
        }
        for r in &s.rows {
            let t: u32 = parse(file, r.no, r.toks.first().copied(), "an atom type")?;
            let m: f64 = parse(file, r.no, r.toks.get(1).copied(), "the mass of a type")?;
            type_masses.insert(t, m);
            if !r.comment.is_empty() {
                type_labels.insert(t, r.comment.to_string());
            }
        }
    }

    // Atoms.
    let atoms = match sections.remove("Atoms") {
        Some(s) => s,
        None if counts.atoms == 0 => Section {
            line: 0,
            comment: "",
            rows: Vec::new(),
        },
        None => return Err(missing("Atoms", "atoms", counts.atoms)),
    };
    if let Some(e) = mismatch(&atoms, "Atoms", "atoms", counts.atoms) {
        return Err(e);
    }
    let style = atom_style(file, &atoms)?;
    let ncol = style.columns();
    struct Row {
        id: u64,
        line: usize,
        mol: u64,
        ty: u32,
        q: f64,
        x: [f64; 3],
        image: [i32; 3],
    }
    let mut rows = Vec::with_capacity(atoms.rows.len());
    for r in &atoms.rows {
        let n = r.toks.len();
        if n != ncol && n != ncol + 3 {
            return Err(FileError::Malformed {
                file: path.clone(),
                line: r.no,
                expected: format!(
                    "{ncol} or {} columns for atom style {style:?}, found {n}",
                    ncol + 3
                ),
            });
        }
        let tok = |i: usize| r.toks.get(i).copied();
        let (mol, ty, q, x0) = match style {
            AtomStyle::Atomic => (0, tok(1), 0.0, 2),
            AtomStyle::Molecular => (parse(file, r.no, tok(1), "a molecule id")?, tok(2), 0.0, 3),
            AtomStyle::Full => (
                parse(file, r.no, tok(1), "a molecule id")?,
                tok(2),
                parse(file, r.no, tok(3), "a charge")?,
                4,
            ),
        };
        let mut x = [0.0; 3];
        for (c, xc) in x.iter_mut().enumerate() {
            *xc = parse(file, r.no, tok(x0 + c), "a coordinate")?;
        }
        let mut image = [0; 3];
        if n == ncol + 3 {
            for (c, ic) in image.iter_mut().enumerate() {
                *ic = parse(file, r.no, tok(ncol + c), "an image flag (integer)")?;
            }
        }
        rows.push(Row {
            id: parse(file, r.no, tok(0), "an atom id")?,
            line: r.no,
            mol,
            ty: parse(file, r.no, ty, "an atom type")?,
            q,
            x,
            image,
        });
    }
    rows.sort_by_key(|r| (r.id, r.line));
    for w in rows.windows(2) {
        if w[0].id == w[1].id {
            return Err(FileError::DuplicateAtom {
                file: path.clone(),
                line: w[1].line,
                id: w[1].id,
                first: w[0].line,
            });
        }
    }
    let n = rows.len();
    let index: HashMap<u64, usize> = rows.iter().enumerate().map(|(a, r)| (r.id, a)).collect();
    let lookup = |section: &'static str, line: usize, tok: Option<&str>| {
        let id: u64 = parse(file, line, tok, "an atom id")?;
        index.get(&id).copied().ok_or(FileError::DanglingAtom {
            file: path.clone(),
            line,
            section,
            id,
        })
    };
    let mut masses = Vec::with_capacity(n);
    let mut positions = Vec::with_capacity(3 * n);
    for r in &rows {
        let m = type_masses.get(&r.ty).copied().ok_or_else(|| {
            // Name the first atom of that type in the file.
            let line = rows
                .iter()
                .filter(|o| o.ty == r.ty)
                .map(|o| o.line)
                .min()
                .unwrap_or(r.line);
            FileError::MissingMass {
                file: path.clone(),
                line,
                atom_type: r.ty,
            }
        })?;
        masses.push(m);
        positions.extend(sim_box.unwrap(r.x, r.image));
    }

    // Velocities.
    let mut velocities = vec![0.0; 3 * n];
    let has_velocities = sections.contains_key("Velocities");
    if let Some(s) = sections.remove("Velocities") {
        if let Some(e) = mismatch(&s, "Velocities", "atoms", counts.atoms) {
            return Err(e);
        }
        for r in &s.rows {
            let a = lookup("Velocities", r.no, r.toks.first().copied())?;
            for c in 0..3 {
                velocities[3 * a + c] =
                    parse(file, r.no, r.toks.get(1 + c).copied(), "a velocity")?;
            }
        }
    }

    // Bonds and angles.
    let mut bonds = Vec::new();
    match sections.remove("Bonds") {
        Some(s) => {
            if let Some(e) = mismatch(&s, "Bonds", "bonds", counts.bonds) {
                return Err(e);
            }
            for r in &s.rows {
                let t = |i: usize| r.toks.get(i).copied();
                bonds.push(Bond {
                    bond_type: parse(file, r.no, t(1), "a bond type")?,
                    atoms: [lookup("Bonds", r.no, t(2))?, lookup("Bonds", r.no, t(3))?],
                    line: r.no,
                });
            }
        }
        None if counts.bonds > 0 => return Err(missing("Bonds", "bonds", counts.bonds)),
        None => {}
    }
    let mut angles = Vec::new();
    match sections.remove("Angles") {
        Some(s) => {
            if let Some(e) = mismatch(&s, "Angles", "angles", counts.angles) {
                return Err(e);
            }
            for r in &s.rows {
                let t = |i: usize| r.toks.get(i).copied();
                angles.push(Angle {
                    angle_type: parse(file, r.no, t(1), "an angle type")?,
                    atoms: [
                        lookup("Angles", r.no, t(2))?,
                        lookup("Angles", r.no, t(3))?,
                        lookup("Angles", r.no, t(4))?,
                    ],
                    line: r.no,
                });
            }
        }
        None if counts.angles > 0 => return Err(missing("Angles", "angles", counts.angles)),
        None => {}
    }

    let coeffs = |s: Option<Section>| -> Result<Coeffs, FileError> {
        let mut out = BTreeMap::new();
        let Some(s) = s else {
            return Ok((out, None));
        };
        for r in &s.rows {
            let t: u32 = parse(file, r.no, r.toks.first().copied(), "a type")?;
            let c = r.toks[1..]
                .iter()
                .map(|&x| parse(file, r.no, Some(x), "a coefficient"))
                .collect::<Result<Vec<f64>, _>>()?;
            out.insert(t, c);
        }
        let style = (!s.comment.is_empty()).then(|| s.comment.to_string());
        Ok((out, style))
    };
    let (bond_coeffs, bond_style) = coeffs(sections.remove("Bond Coeffs"))?;
    let (angle_coeffs, angle_style) = coeffs(sections.remove("Angle Coeffs"))?;

    Ok(LammpsData {
        file: path,
        title,
        sim_box,
        atom_style: style,
        ids: rows.iter().map(|r| r.id).collect(),
        types: rows.iter().map(|r| r.ty).collect(),
        molecules: rows.iter().map(|r| r.mol).collect(),
        charges: (style == AtomStyle::Full).then(|| rows.iter().map(|r| r.q).collect()),
        images: rows.iter().map(|r| r.image).collect(),
        positions,
        velocities,
        has_velocities,
        masses,
        type_masses,
        type_labels,
        bonds,
        angles,
        bond_coeffs,
        angle_coeffs,
        bond_style,
        angle_style,
    })
}

/// The atom style: from the comment after `Atoms`, else from the columns
/// of the first row (5/8, 6/9 and 7/10 columns are atomic, molecular and
/// full without and with image flags: no count is two styles').
fn atom_style(file: &Path, atoms: &Section) -> Result<AtomStyle, FileError> {
    let malformed = |line, expected: String| FileError::Malformed {
        file: file.to_path_buf(),
        line,
        expected,
    };
    match atoms.comment.split_whitespace().next() {
        Some("atomic") => return Ok(AtomStyle::Atomic),
        Some("molecular" | "bond" | "angle") => return Ok(AtomStyle::Molecular),
        Some("full") => return Ok(AtomStyle::Full),
        Some(other) => {
            return Err(malformed(
                atoms.line,
                format!("atom style atomic, bond, angle, molecular or full, found `{other}`"),
            ))
        }
        None => {}
    }
    let Some(first) = atoms.rows.first() else {
        return Ok(AtomStyle::Atomic);
    };
    match first.toks.len() {
        5 | 8 => Ok(AtomStyle::Atomic),
        6 | 9 => Ok(AtomStyle::Molecular),
        7 | 10 => Ok(AtomStyle::Full),
        n => Err(malformed(
            first.no,
            format!("an Atoms row of 5 to 10 columns (atomic, molecular or full), found {n}"),
        )),
    }
}
