//! A system of particles: masses, constraint families, potential families
//! and the forces the user brings ([`ParticleSystem`]).

use super::family::{ConstraintFamily, Family, PotentialFamily, MAX_LOCAL};
use super::{ForceField, Stencil, Table, TopologyError};
use std::sync::Arc;

/// n particles in R^D with masses, constraint families, potential
/// families and forces the user brings ([`ForceField`]):
/// H = Σ_a |p_a|²/(2 m_a) + Σ_fam V_fam(x) + V_ext(x), g = (g_fam)_fam.
///
/// Coordinates are stored particle by particle: x_a's c-th coordinate is
/// `q[a * D + c]`, and likewise for p. Constraints are numbered family by
/// family in the order they were added, member by member within a family.
///
/// ```
/// use geoshake_runtime::particles::{ParticleSystem, Stencil, Table};
/// # struct Distance;
/// # impl Stencil for Distance {
/// #     const ARITY: usize = 2; const DIM: usize = 3; const DATA: usize = 1;
/// #     fn value(&self, x: &[f64], c: &[f64]) -> f64 {
/// #         (0..3).map(|k| (x[k] - x[3 + k]).powi(2)).sum::<f64>() - c[0] * c[0] }
/// #     fn gradient(&self, x: &[f64], c: &[f64], g: &mut [f64]) -> f64 {
/// #         for k in 0..3 { let r = x[k] - x[3 + k]; g[k] = 2.0 * r; g[3 + k] = -2.0 * r; }
/// #         self.value(x, c) }
/// # }
/// let mut bonds = Table::new(2, 1);
/// bonds.push(&[0, 1], &[1.0]).unwrap();
/// let dimer = ParticleSystem::new(3, vec![1.0, 2.0])
///     .unwrap()
///     .with_constraints("bond", Distance, bonds)
///     .unwrap();
/// assert_eq!((dimer.particles(), dimer.constraints()), (2, 1));
/// ```
pub struct ParticleSystem {
    /// Everything but the brought forces, shared by the clones of a
    /// [`Rattle`](super::Rattle) (the threads of an ensemble): read-only
    /// once the system is built.
    parts: Arc<Parts>,
    /// The brought forces: each clone has its own copy, since a field may
    /// keep buffers it writes between calls.
    external: Option<Box<dyn Field>>,
}

/// The read-only part of a [`ParticleSystem`].
struct Parts {
    dim: usize,
    masses: Vec<f64>,
    inverse_masses: Vec<f64>,
    constraints: Vec<Box<dyn ConstraintFamily>>,
    potentials: Vec<Box<dyn PotentialFamily>>,
}

/// A brought force field as the system stores it: one that can be copied
/// for another clone of the solver, and shared by reference with the
/// threads that copy it.
trait Field: ForceField + Sync {
    fn clone_box(&self) -> Box<dyn Field>;
}

impl<F: ForceField + Clone + Sync + 'static> Field for F {
    fn clone_box(&self) -> Box<dyn Field> {
        Box::new(self.clone())
    }
}

impl ParticleSystem {
    /// Particles in R^`dim` with the given masses (finite and positive,
    /// with a finite inverse: the steps divide by them), no constraint and
    /// no potential yet.
    pub fn new(dim: usize, masses: Vec<f64>) -> Result<Self, TopologyError> {
        if let Some((a, &m)) = masses
            .iter()
            .enumerate()
            .find(|(_, m)| !(m.is_finite() && **m > 0.0 && (1.0 / **m).is_finite()))
        {
            return Err(TopologyError::BadValue {
                family: "masses".into(),
                member: a,
                value: m,
                why: "a mass must be finite and positive, and so must its inverse",
            });
        }
        let inverse_masses = masses.iter().map(|m| 1.0 / m).collect();
        let parts = Parts {
            dim,
            masses,
            inverse_masses,
            constraints: Vec::new(),
            potentials: Vec::new(),
        };
        Ok(ParticleSystem {
            parts: Arc::new(parts),
            external: None,
        })
    }

    /// The system for another clone of a solver: the same families and
    /// masses, shared, and a copy of the brought forces.
    pub(crate) fn share(&self) -> ParticleSystem {
        ParticleSystem {
            parts: Arc::clone(&self.parts),
            external: self.external.as_ref().map(|f| f.clone_box()),
        }
    }

    /// The parts, to add a family to.
    fn parts_mut(&mut self) -> &mut Parts {
        // A system is shared only inside a solver, which never hands it
        // out by value: a system being built is its parts' only owner.
        Arc::get_mut(&mut self.parts).expect("a system being built is not shared")
    }

    /// Adds a constraint family: `stencil` applied to every row of `table`.
    /// Refuses rows of the wrong shape, particles that do not exist, and a
    /// member that repeats another.
    pub fn with_constraints<S: Stencil + 'static>(
        mut self,
        name: &str,
        stencil: S,
        table: Table,
    ) -> Result<Self, TopologyError> {
        let family = self.family(name, stencil, table, true)?;
        self.parts_mut().constraints.push(Box::new(family));
        Ok(self)
    }

    /// Adds a potential family: V gains Σ_k f(x_{i_k}; c_k).
    pub fn with_potential<S: Stencil + 'static>(
        mut self,
        name: &str,
        stencil: S,
        table: Table,
    ) -> Result<Self, TopologyError> {
        let family = self.family(name, stencil, table, false)?;
        self.parts_mut().potentials.push(Box::new(family));
        Ok(self)
    }

    /// Adds the forces of an external potential V_ext, evaluated by the
    /// user's code ([`ForceField`]); replaces one given before. The field
    /// is `Clone` and `Sync` so that a solver can be cloned (one clone per
    /// thread of an [`ensemble`](crate::ensemble())): each clone calls its
    /// own copy.
    pub fn with_forces(mut self, field: impl ForceField + Clone + Sync + 'static) -> Self {
        self.external = Some(Box::new(field));
        self
    }

    /// Validates a table against a stencil and this system's particles.
    fn family<S: Stencil>(
        &self,
        name: &str,
        stencil: S,
        table: Table,
        unique: bool,
    ) -> Result<Family<S>, TopologyError> {
        let family = || name.to_string();
        if S::DIM != self.parts.dim {
            return Err(TopologyError::Dimension {
                family: family(),
                stencil: S::DIM,
                system: self.parts.dim,
            });
        }
        let shape = |what, got, expected| TopologyError::RowShape {
            family: family(),
            member: 0,
            what,
            got,
            expected,
        };
        if table.arity() != S::ARITY || S::ARITY * S::DIM > MAX_LOCAL {
            return Err(shape("particle list", table.arity(), S::ARITY));
        }
        if table.width() != S::DATA {
            return Err(shape("data", table.width(), S::DATA));
        }
        let n = self.particles();
        for k in 0..table.len() {
            if let Some(&i) = table.particles(k).iter().find(|&&i| i as usize >= n) {
                return Err(TopologyError::DanglingParticle {
                    family: family(),
                    member: k,
                    particle: i as usize,
                    particles: n,
                });
            }
        }
        if unique {
            // Members are equal when they touch the same set of particles
            // with the same numbers (a bond given as (i, j) and as (j, i)).
            let mut keys: Vec<(Vec<u32>, Vec<u64>, usize)> = (0..table.len())
                .map(|k| {
                    let mut p = table.particles(k).to_vec();
                    p.sort_unstable();
                    let c = table.data(k).iter().map(|v| v.to_bits()).collect();
                    (p, c, k)
                })
                .collect();
            keys.sort_unstable();
            if let Some(w) = keys
                .windows(2)
                .find(|w| w[0].0 == w[1].0 && w[0].1 == w[1].1)
            {
                return Err(TopologyError::DuplicateMember {
                    family: family(),
                    first: w[0].2.min(w[1].2),
                    second: w[0].2.max(w[1].2),
                });
            }
        }
        Ok(Family {
            name: name.to_string(),
            stencil,
            table,
            dim: self.parts.dim,
        })
    }

    /// The dimension D of each particle's position.
    pub fn dim(&self) -> usize {
        self.parts.dim
    }

    /// The number n of particles (d = n·D degrees of freedom).
    pub fn particles(&self) -> usize {
        self.parts.masses.len()
    }

    /// The masses m_a.
    pub fn masses(&self) -> &[f64] {
        &self.parts.masses
    }

    /// 1/m_a.
    pub fn inverse_masses(&self) -> &[f64] {
        &self.parts.inverse_masses
    }

    /// The number m of constraints, all families together.
    pub fn constraints(&self) -> usize {
        self.parts.constraints.iter().map(|f| f.table().len()).sum()
    }

    /// The constraint families, in the order they were added.
    pub fn constraint_families(&self) -> &[Box<dyn ConstraintFamily>] {
        &self.parts.constraints
    }

    /// The potential families, in the order they were added.
    pub fn potential_families(&self) -> &[Box<dyn PotentialFamily>] {
        &self.parts.potentials
    }

    /// True when forces were brought with [`with_forces`](Self::with_forces).
    pub fn has_forces(&self) -> bool {
        self.external.is_some()
    }

    /// True when H has a potential: a potential family or brought forces.
    pub fn has_potential(&self) -> bool {
        !self.parts.potentials.is_empty() || self.external.is_some()
    }

    /// The kinetic energy Σ_a |p_a|²/(2 m_a) of momenta `p` (n·D entries).
    ///
    /// ```
    /// use geoshake_runtime::particles::ParticleSystem;
    /// let s = ParticleSystem::new(2, vec![1.0, 4.0]).unwrap();
    /// assert_eq!(s.kinetic_energy(&[1.0, 0.0, 0.0, 2.0]), 0.5 + 0.5);
    /// ```
    pub fn kinetic_energy(&self, p: &[f64]) -> f64 {
        let d = self.parts.dim;
        let mut two_k = 0.0;
        for (a, w) in self.parts.inverse_masses.iter().enumerate() {
            two_k += w * p[a * d..(a + 1) * d].iter().map(|p| p * p).sum::<f64>();
        }
        0.5 * two_k
    }

    /// V(q) = Σ_fam V_fam(q) + V_ext(q), with ∇V(q) written into `grad`
    /// (n·D entries): the brought forces (negated) first, then every
    /// family's gradient added.
    pub(crate) fn potential_gradient(&mut self, q: &[f64], grad: &mut [f64]) -> f64 {
        grad.fill(0.0);
        let mut v = 0.0;
        if let Some(field) = &mut self.external {
            v += field.forces(q, grad);
            for g in grad.iter_mut() {
                *g = -*g;
            }
        }
        for f in &self.parts.potentials {
            v += f.energy_gradient(q, grad);
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masses_and_their_inverses_must_be_finite_and_positive() {
        assert!(ParticleSystem::new(3, vec![1.0, 2.0, f64::MIN_POSITIVE]).is_ok());
        // 5e-324 is positive and finite; its inverse is not, and every
        // step divides by the masses.
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, 5e-324] {
            let e = ParticleSystem::new(3, vec![1.0, bad]).err();
            assert!(
                matches!(e, Some(TopologyError::BadValue { member: 1, value, .. }) if value.to_bits() == bad.to_bits()),
                "{bad}: {e:?}"
            );
        }
    }
}
