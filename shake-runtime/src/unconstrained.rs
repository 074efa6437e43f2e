//! A Hamiltonian without constraints, seen as a constrained system with
//! m = 0, so the drivers run plain symplectic integration too.

use crate::system::{ConstrainedSystem, ConstraintKind, Hamiltonian};

/// Wraps any [`Hamiltonian`] as a [`ConstrainedSystem`] with no constraints:
/// SHAKE and RATTLE then reduce to the base map φ_h.
///
/// ```
/// use shake_runtime::{Integrator, StormerVerlet, Unconstrained, State, Stop};
/// use shake_runtime::examples::HarmonicOscillator;
/// let mut integ = Integrator::new(Unconstrained(HarmonicOscillator), StormerVerlet, 0.01);
/// let out = integ.run(State::from_slices(&[1.0], &[0.0]), Stop::Time(std::f64::consts::PI)).execute();
/// let last = out.trajectory.last().unwrap();
/// assert!((last.q[0] + 1.0).abs() < 1e-4);
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct Unconstrained<H>(pub H);

impl<H: Hamiltonian> Hamiltonian for Unconstrained<H> {
    const DOF: usize = H::DOF;
    const SEPARABLE: bool = H::SEPARABLE;
    const QUADRATIC_KINETIC: bool = H::QUADRATIC_KINETIC;

    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        self.0.hamiltonian(q, p)
    }
    fn grad_q(&self, q: &[f64], p: &[f64], h_q: &mut [f64]) {
        self.0.grad_q(q, p, h_q)
    }
    fn grad_p(&self, q: &[f64], p: &[f64], h_p: &mut [f64]) {
        self.0.grad_p(q, p, h_p)
    }
    fn gradient(&self, q: &[f64], p: &[f64], h_q: &mut [f64], h_p: &mut [f64]) {
        self.0.gradient(q, p, h_q, h_p)
    }
    fn hessian(&self, q: &[f64], p: &[f64], h_zz: &mut [f64]) {
        self.0.hessian(q, p, h_zz)
    }
}

impl<H: Hamiltonian> ConstrainedSystem for Unconstrained<H> {
    const CONSTRAINTS: usize = 0;
    const KIND: ConstraintKind = ConstraintKind::None;
    const JACOBIAN_PATTERN: &'static [(usize, usize)] = &[];
    const CONSTRAINT_NAMES: &'static [&'static str] = &[];

    fn constraints(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
    fn constraint_jacobian(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
    fn constraint_hessian(&self, _: &[f64], _: &[f64], _: &[f64], _: &mut [f64]) {}
    fn hidden_constraints(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
    fn hidden_constraint_jacobian(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
    fn nondegeneracy_matrix(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
}
