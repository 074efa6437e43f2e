//! How a particle system's declaration is refused: its topology.

/// Why a topology was refused. Every variant names the family and, where one
/// member is at fault, the member (its row in the table).
///
/// ```
/// use geoshake_runtime::particles::{Table, TopologyError};
/// let mut bonds = Table::new(2, 1);
/// let e = bonds.push(&[0, 0], &[1.0]).unwrap_err();
/// assert!(matches!(e, TopologyError::RepeatedParticle { member: 0, particle: 0, .. }));
/// ```
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TopologyError {
    /// A row has the wrong number of particle indices or numbers.
    #[error(
        "family `{family}`, member {member}: {what} has {got} entries, the family takes {expected}"
    )]
    RowShape {
        /// The family (empty while the table is not yet named).
        family: String,
        /// The row.
        member: usize,
        /// "particle list" or "data".
        what: &'static str,
        /// Entries given.
        got: usize,
        /// Entries the family takes.
        expected: usize,
    },
    /// A member names the same particle twice.
    #[error("family `{family}`, member {member}: particle {particle} appears twice")]
    RepeatedParticle {
        /// The family.
        family: String,
        /// The row.
        member: usize,
        /// The repeated particle.
        particle: usize,
    },
    /// A member names a particle the system does not have.
    #[error("family `{family}`, member {member}: particle {particle} does not exist (the system has {particles})")]
    DanglingParticle {
        /// The family.
        family: String,
        /// The row.
        member: usize,
        /// The index given.
        particle: usize,
        /// The number of particles.
        particles: usize,
    },
    /// Two members of a family touch the same particles with the same
    /// numbers: the same constraint twice, so N is singular.
    #[error("family `{family}`: members {first} and {second} are the same constraint")]
    DuplicateMember {
        /// The family.
        family: String,
        /// The earlier row.
        first: usize,
        /// The later row.
        second: usize,
    },
    /// A number in a row (or a mass) is NaN or infinite, or a mass is not
    /// positive.
    #[error("family `{family}`, member {member}: value {value} is not allowed ({why})")]
    BadValue {
        /// The family ("masses" for the masses).
        family: String,
        /// The row (the particle for masses).
        member: usize,
        /// The value.
        value: f64,
        /// What it must be.
        why: &'static str,
    },
    /// A connected cluster of constraints has more constraints than the
    /// coordinates it moves: G cannot have full rank, N = G M⁻¹ Gᵀ is
    /// singular (the nondegeneracy condition fails on every state).
    #[error("{constraints} constraints (from member {member} of `{family}` on) act on {coordinates} coordinates: more constraints than coordinates, N = G M⁻¹ Gᵀ is singular")]
    TooManyConstraints {
        /// A family of the cluster.
        family: String,
        /// A member of the cluster.
        member: usize,
        /// Constraints in the cluster.
        constraints: usize,
        /// Coordinates the cluster moves.
        coordinates: usize,
    },
    /// The stencil's dimension differs from the system's.
    #[error(
        "family `{family}` is written for particles in R^{stencil}, the system's are in R^{system}"
    )]
    Dimension {
        /// The family.
        family: String,
        /// The stencil's DIM.
        stencil: usize,
        /// The system's dimension.
        system: usize,
    },
}

impl TopologyError {
    /// The error with its family named `name` where it was not yet (an
    /// error of [`Table::push`](super::Table::push), before the table is
    /// given to a family).
    ///
    /// ```
    /// use geoshake_runtime::particles::Table;
    /// let e = Table::new(2, 1).push(&[0, 0], &[1.0]).unwrap_err().in_family("bond");
    /// assert_eq!(e.to_string(), "family `bond`, member 0: particle 0 appears twice");
    /// ```
    pub fn in_family(mut self, name: &str) -> Self {
        let (TopologyError::RowShape { family, .. }
        | TopologyError::RepeatedParticle { family, .. }
        | TopologyError::DanglingParticle { family, .. }
        | TopologyError::DuplicateMember { family, .. }
        | TopologyError::BadValue { family, .. }
        | TopologyError::TooManyConstraints { family, .. }
        | TopologyError::Dimension { family, .. }) = &mut self;
        if family.is_empty() {
            *family = name.to_string();
        }
        self
    }
}
