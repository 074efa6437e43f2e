//! Forces the user brings: a potential V_ext(q) evaluated by the user's own
//! code, beside the potential families declared on the system.

/// An external potential V_ext(q) with its forces F = −∇V_ext(q): a force
/// field with its neighbour lists, a machine-learned model, a wall. The
/// Hamiltonian becomes H = Σ_a |p_a|²/(2 m_a) + Σ_fam V_fam(x) + V_ext(x),
/// and Störmer–Verlet kicks with the sum of the forces (the paper's
/// Section 5.1.3 with V = Σ_fam V_fam + V_ext).
///
/// [`Rattle`](super::Rattle) calls [`forces`](Self::forces) once per step,
/// at the new positions q1 (whose forces the next step's first kick
/// reuses), and once more when a run starts from a state it did not make.
/// `&mut self`: the field may keep what it likes between calls (cell
/// lists, buffers). [`ParticleSystem::with_forces`](super::ParticleSystem::with_forces)
/// asks it to be `Clone` and `Sync` besides: a clone of the solver (one
/// per thread of an [`ensemble`](crate::ensemble())) calls a copy of its
/// own, so a field whose forces depend only on q gives every clone the
/// same steps.
///
/// Any closure `FnMut(&[f64], &mut [f64]) -> f64 + Send` is a force field
/// (and `Clone` and `Sync` when what it captures is).
///
/// ```
/// use geoshake_runtime::particles::{ForceField, ParticleSystem};
/// // A harmonic trap V = (k/2) Σ_c q_c², F = −k q, written by hand.
/// let k = 0.5;
/// let trap = move |q: &[f64], f: &mut [f64]| {
///     for (f, q) in f.iter_mut().zip(q) {
///         *f -= k * q;
///     }
///     0.5 * k * q.iter().map(|q| q * q).sum::<f64>()
/// };
/// let system = ParticleSystem::new(3, vec![1.0; 2]).unwrap().with_forces(trap);
/// assert!(system.has_forces());
/// ```
pub trait ForceField: Send {
    /// Adds the forces F = −∇V_ext(q) into `f` and returns V_ext(q). `q`
    /// and `f` have n·D entries in the system's layout (`q[a * D + c]`);
    /// `f` arrives filled with zeros. A force that is NaN or infinite stops
    /// the step with [`StepError::NonFinite`](crate::StepError::NonFinite)
    /// at the entry of p it would change.
    fn forces(&mut self, q: &[f64], f: &mut [f64]) -> f64;
}

impl<F> ForceField for F
where
    F: FnMut(&[f64], &mut [f64]) -> f64 + Send,
{
    fn forces(&mut self, q: &[f64], f: &mut [f64]) -> f64 {
        self(q, f)
    }
}
