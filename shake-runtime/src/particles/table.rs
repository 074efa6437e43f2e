//! The run-time topology of one family: a row per member.

use super::TopologyError;

/// The rows of one family: for member k, the indices of the `arity`
/// particles it touches and `width` numbers (bond lengths, spring
/// constants). Indices are stored as `u32`: 4·10⁹ particles is beyond one
/// machine's memory, and the table of a 10⁶-link chain takes 8 MB instead
/// of 16.
///
/// ```
/// use geoshake_runtime::particles::Table;
/// let mut bonds = Table::new(2, 1);
/// bonds.push(&[0, 1], &[1.0]).unwrap();
/// bonds.push(&[1, 2], &[1.5]).unwrap();
/// assert_eq!(bonds.len(), 2);
/// assert_eq!(bonds.particles(1), &[1, 2]);
/// assert_eq!(bonds.data(1), &[1.5]);
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Table {
    arity: usize,
    width: usize,
    particles: Vec<u32>,
    data: Vec<f64>,
}

impl Table {
    /// An empty table whose rows hold `arity` particle indices and `width`
    /// numbers.
    pub fn new(arity: usize, width: usize) -> Self {
        Table {
            arity,
            width,
            particles: Vec::new(),
            data: Vec::new(),
        }
    }

    /// An empty table with room for `rows` rows.
    pub fn with_capacity(arity: usize, width: usize, rows: usize) -> Self {
        Table {
            arity,
            width,
            particles: Vec::with_capacity(arity * rows),
            data: Vec::with_capacity(width * rows),
        }
    }

    /// Appends a row. Refuses (and leaves the table as it was) a row of the
    /// wrong shape, a particle named twice, an index beyond `u32`, or a
    /// non-finite number.
    pub fn push(&mut self, particles: &[usize], data: &[f64]) -> Result<(), TopologyError> {
        let member = self.len();
        let shape = |what, got, expected| TopologyError::RowShape {
            family: String::new(),
            member,
            what,
            got,
            expected,
        };
        if particles.len() != self.arity {
            return Err(shape("particle list", particles.len(), self.arity));
        }
        if data.len() != self.width {
            return Err(shape("data", data.len(), self.width));
        }
        for (a, &i) in particles.iter().enumerate() {
            if particles[..a].contains(&i) {
                return Err(TopologyError::RepeatedParticle {
                    family: String::new(),
                    member,
                    particle: i,
                });
            }
            if i > u32::MAX as usize {
                return Err(TopologyError::DanglingParticle {
                    family: String::new(),
                    member,
                    particle: i,
                    particles: u32::MAX as usize,
                });
            }
        }
        if let Some(&value) = data.iter().find(|v| !v.is_finite()) {
            return Err(TopologyError::BadValue {
                family: String::new(),
                member,
                value,
                why: "must be finite",
            });
        }
        self.particles.extend(particles.iter().map(|&i| i as u32));
        self.data.extend_from_slice(data);
        Ok(())
    }

    /// The number of rows (members).
    pub fn len(&self) -> usize {
        self.particles.len().checked_div(self.arity).unwrap_or(0)
    }

    /// True when the table has no row.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Particle indices per row.
    pub fn arity(&self) -> usize {
        self.arity
    }

    /// Numbers per row.
    pub fn width(&self) -> usize {
        self.width
    }

    /// The particles of member k.
    #[inline]
    pub fn particles(&self, k: usize) -> &[u32] {
        &self.particles[k * self.arity..(k + 1) * self.arity]
    }

    /// The numbers of member k.
    #[inline]
    pub fn data(&self, k: usize) -> &[f64] {
        &self.data[k * self.width..(k + 1) * self.width]
    }

    /// Every row's particle indices, row after row.
    pub fn all_particles(&self) -> &[u32] {
        &self.particles
    }

    /// Every row's numbers, row after row.
    pub fn all_data(&self) -> &[f64] {
        &self.data
    }

    /// Bytes held by the table.
    pub fn bytes(&self) -> usize {
        self.particles.capacity() * 4 + self.data.capacity() * 8
    }
}
