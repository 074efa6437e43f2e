//! What a figure measures of a stored state: its energy ([`Energy`]) and
//! how far it lies from the constraint and the hidden constraint
//! ([`Residuals`]), the same two questions for a system declared with the
//! macro and for a particle run.

use crate::particles::{ParticleState, Rattle};
use crate::{ConstrainedSystem, Hamiltonian};

/// The energy of a stored state: what [`energy_error`](super::energy_error)
/// draws.
///
/// Implemented for `&S`, every [`Hamiltonian`] S (H itself), and for
/// `&mut` [`particles::Rattle`](crate::particles::Rattle), the solver of a
/// particle run: H = Σ_a |p_a|²/(2 m_a) + V(q), V evaluated as the solver
/// does, with its force buffers and the forces brought to its system (a
/// [`ForceField`](crate::particles::ForceField) may keep buffers of its
/// own), hence `&mut`. The next step from a stored state then evaluates
/// its forces afresh.
pub trait Energy {
    /// d, the number of entries of q: a trajectory of another size is
    /// refused.
    fn dof(&self) -> usize;
    /// H(q, p); NaN when it cannot be evaluated (the figure then names
    /// the state).
    fn energy(&mut self, q: &[f64], p: &[f64]) -> f64;
}

/// How far a stored state lies from M (g = 0) and from M^H ({g, H} = 0):
/// what [`constraint_residual`](super::constraint_residual) draws.
///
/// For `&S`, every [`ConstrainedSystem`] S: max_i |g_i| and max_i
/// |{g_i, H}|, absolute. For `&mut` [`particles::Rattle`](crate::particles::Rattle):
/// relative to each member's own scale, the measure the particle solver's
/// tolerance judges (and [`StepInfo::residual`](crate::StepInfo::residual)
/// and [`StepInfo::hidden`](crate::StepInfo::hidden) report), so that bonds
/// of any length and particles of any mass compare: max_k |g_k| /
/// (|∇g_k| · extent_k), extent_k² = Σ_a |x_a − x̄|² over the member's
/// particles (for a distance constraint g = |r|² − l² this is
/// |r² − l²| / (2 r²), the relative bond-length error |r − l| / l to first
/// order), and max_k |∇g_k · M⁻¹p| / (|∇g_k| · |M⁻¹p|), |M⁻¹p| over the
/// member's particles (the cosine of the angle between the constraint's
/// normal and the member's velocity).
pub trait Residuals: Energy {
    /// Whether the residuals are relative to each constraint's scale (the
    /// axis and the legend say so).
    const RELATIVE: bool;
    /// m, the number of constraints.
    fn constraint_count(&self) -> usize;
    /// [the constraint's residual, the hidden constraint's] at (q, p),
    /// each the largest over the constraints; NaN when one is (the figure
    /// then names the state).
    fn residuals(&mut self, q: &[f64], p: &[f64]) -> [f64; 2];
}

impl<S: Hamiltonian + ?Sized> Energy for &S {
    fn dof(&self) -> usize {
        Hamiltonian::dof(*self)
    }
    fn energy(&mut self, q: &[f64], p: &[f64]) -> f64 {
        self.hamiltonian(q, p)
    }
}

impl<S: ConstrainedSystem + ?Sized> Residuals for &S {
    const RELATIVE: bool = false;
    fn constraint_count(&self) -> usize {
        ConstrainedSystem::constraint_count(*self)
    }
    fn residuals(&mut self, q: &[f64], p: &[f64]) -> [f64; 2] {
        let mut g = vec![0.0; ConstrainedSystem::constraint_count(*self)];
        self.constraints(q, p, &mut g);
        let constraint = max_abs(&g);
        self.hidden_constraints(q, p, &mut g);
        [constraint, max_abs(&g)]
    }
}

impl Energy for &mut Rattle {
    fn dof(&self) -> usize {
        self.system().particles() * self.system().dim()
    }
    fn energy(&mut self, q: &[f64], p: &[f64]) -> f64 {
        // A stored state is no state the solver made: its forces are
        // evaluated, not read from the cache.
        let state = ParticleState::new(q.to_vec(), p.to_vec());
        let potential = self.potential_energy(&state).unwrap_or(f64::NAN);
        self.system().kinetic_energy(p) + potential
    }
}

impl Residuals for &mut Rattle {
    const RELATIVE: bool = true;
    fn constraint_count(&self) -> usize {
        self.system().constraints()
    }
    fn residuals(&mut self, q: &[f64], p: &[f64]) -> [f64; 2] {
        let system = self.system();
        let (mut constraint, mut hidden) = (0.0, 0.0);
        for family in system.constraint_families() {
            let members = family.table().len();
            let width = family.table().arity() * system.dim();
            let (mut g, mut inv_scale) = (vec![0.0; members], vec![0.0; members]);
            let mut grad = vec![0.0; members * width];
            family.gradients_scaled(q, &mut g, &mut grad, &mut inv_scale);
            for (g, s) in g.iter().zip(&inv_scale) {
                constraint = worst(constraint, (g * s).abs());
            }
            // The solver's own ratio, judged against the velocity itself
            // (no projection started from another: `before` = 0); `g`
            // takes the unscaled ∇g_k · M⁻¹p.
            let mut before = vec![0.0; members];
            let ratio = family.hidden(&grad, system.inverse_masses(), p, &mut g, &mut before, true);
            hidden = worst(hidden, ratio);
        }
        [constraint, hidden]
    }
}

/// The larger of a running maximum and a new value; a NaN wins and stays
/// (f64::max would drop it, and the figure would hide a broken state).
fn worst(m: f64, v: f64) -> f64 {
    if m.is_nan() || v <= m {
        m
    } else {
        v
    }
}

fn max_abs(x: &[f64]) -> f64 {
    x.iter().fold(0.0, |m, v| worst(m, v.abs()))
}
