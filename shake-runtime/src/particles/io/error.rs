//! Why a file could not be read or written: [`FileError`], naming the file,
//! the line (for a reader) or the frame (for a writer), and what was
//! expected there.

use std::path::PathBuf;

/// Why reading or writing a particle file failed.
///
/// Every variant names the file (for a reader or writer over a stream that
/// is not a file: the name it was given) and, where one line is at fault,
/// its number (1-based, as an editor shows it).
///
/// ```
/// use geoshake_runtime::particles::io::{parse_lammps_data, FileError};
/// let text = "title\n\n1 atoms\n1 atom types\n\nMasses\n\n1 x\n";
/// let e = parse_lammps_data(text, "in.data").unwrap_err();
/// assert!(matches!(e, FileError::Number { line: 8, .. }));
/// assert_eq!(e.to_string(), "in.data:8: expected the mass of a type, found `x`");
/// ```
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The operating system refused to open, read, write or flush.
    #[error("{}: {source}", file.display())]
    Io {
        /// The file.
        file: PathBuf,
        /// What the operating system said.
        source: std::io::Error,
    },
    /// A token that should be a number is not one.
    #[error("{}:{line}: expected {expected}, found `{found}`", file.display())]
    Number {
        /// The file.
        file: PathBuf,
        /// The line.
        line: usize,
        /// What the token should have been.
        expected: String,
        /// The token (empty when the line ended first).
        found: String,
    },
    /// A line that does not have the shape its place asks for.
    #[error("{}:{line}: expected {expected}", file.display())]
    Malformed {
        /// The file.
        file: PathBuf,
        /// The line.
        line: usize,
        /// What should have been there.
        expected: String,
    },
    /// Two atoms with the same id.
    #[error("{}:{line}: atom id {id} already given at line {first}", file.display())]
    DuplicateAtom {
        /// The file.
        file: PathBuf,
        /// The line of the second one.
        line: usize,
        /// The id.
        id: u64,
        /// The line of the first one.
        first: usize,
    },
    /// A bond, angle or velocity that names an atom id the Atoms section
    /// does not have.
    #[error("{}:{line}: {section} names atom id {id}, which is not in the Atoms section", file.display())]
    DanglingAtom {
        /// The file.
        file: PathBuf,
        /// The line.
        line: usize,
        /// The section of the line ("Bonds", "Angles", "Velocities").
        section: &'static str,
        /// The id.
        id: u64,
    },
    /// An atom whose type has no mass in the Masses section.
    #[error("{}:{line}: atom type {atom_type} has no mass (no Masses line for it)", file.display())]
    MissingMass {
        /// The file.
        file: PathBuf,
        /// The line of the first atom of that type.
        line: usize,
        /// The type.
        atom_type: u32,
    },
    /// A section with another number of rows than the header announced.
    #[error("{}:{line}: the header announces {header} {what}, the {section} section has {found}", file.display())]
    CountMismatch {
        /// The file.
        file: PathBuf,
        /// The line of the section's name.
        line: usize,
        /// The section.
        section: String,
        /// What the header counts ("atoms", "bonds", …).
        what: &'static str,
        /// The header's count.
        header: usize,
        /// The rows found.
        found: usize,
    },
    /// A section the header requires (its count is not zero) is absent.
    #[error("{}: the header announces {count} {what}, but there is no {section} section", file.display())]
    MissingSection {
        /// The file.
        file: PathBuf,
        /// The section.
        section: &'static str,
        /// What the header counts.
        what: &'static str,
        /// The header's count.
        count: usize,
    },
    /// A constrained bond or angle type with no length: neither given by
    /// the caller nor found in a harmonic `Bond Coeffs` / `Angle Coeffs`
    /// section.
    #[error("{}: {kind} type {type_id} is constrained but has no {what} (give it, or add a harmonic {kind} coefficient)", file.display())]
    MissingLength {
        /// The file the topology came from.
        file: PathBuf,
        /// "bond" or "angle".
        kind: &'static str,
        /// The type.
        type_id: u32,
        /// "length" or "angle".
        what: &'static str,
    },
    /// A constrained angle whose two legs are not both bonds of the file,
    /// so the distance between its outer atoms has no bond lengths.
    #[error("{}:{line}: the angle's leg {a}–{b} (atom ids) is not a bond of the file", file.display())]
    AngleWithoutBond {
        /// The file.
        file: PathBuf,
        /// The angle's line.
        line: usize,
        /// One atom id of the leg.
        a: u64,
        /// The other.
        b: u64,
    },
    /// The constraints built from the file were refused as a topology.
    #[error("{}: {source}", file.display())]
    Topology {
        /// The file.
        file: PathBuf,
        /// Why the topology was refused.
        source: crate::particles::TopologyError,
    },
    /// A state to write whose length does not match the writer's atoms.
    #[error("{}: frame {frame}: {what} has {got} numbers, the writer's {atoms} atoms need {expected}", file.display())]
    Shape {
        /// The file.
        file: PathBuf,
        /// The frame (0-based count of frames written before).
        frame: u64,
        /// "positions" or "momenta".
        what: &'static str,
        /// Numbers given.
        got: usize,
        /// Numbers needed.
        expected: usize,
        /// Atoms of the writer.
        atoms: usize,
    },
}

impl FileError {
    pub(crate) fn io(file: &std::path::Path, source: std::io::Error) -> Self {
        FileError::Io {
            file: file.to_path_buf(),
            source,
        }
    }

    /// The line at fault, for the errors that have one.
    ///
    /// ```
    /// use geoshake_runtime::particles::io::parse_lammps_data;
    /// let e = parse_lammps_data("t\n\n2 atoms\n", "a.data").unwrap_err();
    /// assert_eq!(e.line(), None); // no Atoms section: no line to name
    /// ```
    pub fn line(&self) -> Option<usize> {
        match self {
            FileError::Number { line, .. }
            | FileError::Malformed { line, .. }
            | FileError::DuplicateAtom { line, .. }
            | FileError::DanglingAtom { line, .. }
            | FileError::MissingMass { line, .. }
            | FileError::CountMismatch { line, .. }
            | FileError::AngleWithoutBond { line, .. } => Some(*line),
            _ => None,
        }
    }
}
