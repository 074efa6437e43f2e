//! A Hamiltonian without constraints, seen as a constrained system with
//! m = 0, so the drivers run plain symplectic integration too.

use crate::system::{ConstrainedSystem, ConstraintKind, Hamiltonian};

/// Wraps any [`Hamiltonian`] as a [`ConstrainedSystem`] with no constraints:
/// SHAKE and RATTLE then reduce to the base map φ_h.
///
/// ```
/// use geoshake_runtime::{Integrator, StormerVerlet, Unconstrained, State, Stop};
/// use geoshake_runtime::examples::HarmonicOscillator;
/// let mut integ = Integrator::new(Unconstrained(HarmonicOscillator), StormerVerlet, 0.01);
/// let out = integ.run(State::from_slices(&[1.0], &[0.0]), Stop::Time(std::f64::consts::PI)).execute();
/// let last = out.trajectory.last().unwrap();
/// assert!((last.q[0] + 1.0).abs() < 1e-4);
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct Unconstrained<H>(pub H);

impl<H: Hamiltonian> Hamiltonian for Unconstrained<H> {
    fn dof(&self) -> usize {
        self.0.dof()
    }
    fn separable(&self) -> bool {
        self.0.separable()
    }
    fn quadratic_kinetic(&self) -> bool {
        self.0.quadratic_kinetic()
    }

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
    fn constraint_count(&self) -> usize {
        0
    }
    fn kind(&self) -> ConstraintKind {
        ConstraintKind::None
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        &[]
    }
    fn constraint_name(&self, i: usize) -> &str {
        panic!("an unconstrained system has no constraint {i}")
    }

    fn constraints(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
    fn constraint_jacobian(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
    fn constraint_hessian(&self, _: &[f64], _: &[f64], _: &[f64], _: &mut [f64]) {}
    fn hidden_constraints(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
    fn hidden_constraint_jacobian(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
    fn nondegeneracy_matrix(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
}
