//! SHAKE is presymplectic on M and RATTLE symplectic on M^H
//! (Proposition 4.4, Corollary 4.6): ω(DS u, DS v) = ω(u, v) for tangent
//! vectors u, v of M (SHAKE) or of M^H (RATTLE).
//!
//! The derivative is a sixth-order central difference of the step map with
//! δ = 1e-3: truncation O(δ⁶) ~ 1e-18 times the seventh derivative, rounding
//! ~ ε/δ ~ 1e-13 (the step is solved to round-off); so ω of the differenced
//! vectors is accurate to ~1e-11, and we check at 1e-9. The maps are
//! evaluated slightly off M (by O(δ²)); they are defined by the same
//! equations there, and their derivative along TM is the derivative on M.
//!
//! Each check can fail: the same test for a generic u, v ∉ TM must (and does)
//! find ω not preserved by SHAKE, whose image lies in a submanifold.

use crate::common;

use common::models::*;
use geoshake::{
    BaseMap, ConstrainedSystem, ImplicitMidpoint, Integrator, Method, Options, State,
    StormerVerlet, SymplecticEuler,
};
use nalgebra::{DMatrix, DVector};

const DELTA: f64 = 1e-3;
const TOL: f64 = 1e-9;

fn omega(u: &DVector<f64>, v: &DVector<f64>) -> f64 {
    let d = u.len() / 2;
    (0..d).map(|k| u[k] * v[d + k] - u[d + k] * v[k]).sum()
}

/// Orthonormal basis of ker A (A: r × n) from the SVD.
fn kernel(a: &DMatrix<f64>) -> Vec<DVector<f64>> {
    let n = a.ncols();
    let svd = (a.transpose() * a).symmetric_eigen();
    (0..n)
        .filter(|&i| svd.eigenvalues[i].abs() < 1e-10)
        .map(|i| svd.eigenvectors.column(i).into_owned())
        .collect()
}

fn jacobians<S: ConstrainedSystem>(sys: &S, z: &State) -> (DMatrix<f64>, DMatrix<f64>) {
    let (d, m) = (sys.dof(), sys.constraint_count());
    let (mut gz, mut hz) = (vec![0.0; m * 2 * d], vec![0.0; m * 2 * d]);
    sys.constraint_jacobian(z.q.as_slice(), z.p.as_slice(), &mut gz);
    sys.hidden_constraint_jacobian(z.q.as_slice(), z.p.as_slice(), &mut hz);
    (
        DMatrix::from_column_slice(m, 2 * d, &gz),
        DMatrix::from_column_slice(m, 2 * d, &hz),
    )
}

/// D(step)(z)·u by the sixth-order central difference.
fn derivative<S: ConstrainedSystem + Clone, B: BaseMap>(
    integ: &mut Integrator<S, B>,
    z: &DVector<f64>,
    u: &DVector<f64>,
) -> DVector<f64> {
    let mut f = |s: f64| {
        integ
            .step(&State::from_vector(&(z + u * (s * DELTA))))
            .unwrap()
            .to_vector()
    };
    (f(-3.0) * -1.0 + f(-2.0) * 9.0 - f(-1.0) * 45.0 + f(1.0) * 45.0 - f(2.0) * 9.0 + f(3.0))
        / (60.0 * DELTA)
}

/// Max |ω(DS u_i, DS u_j) − ω(u_i, u_j)| over pairs of the basis of `tangent`.
fn defect<S: ConstrainedSystem + Clone, B: BaseMap>(
    sys: &S,
    base: B,
    method: Method,
    z0: &State,
    tangent: &[DVector<f64>],
) -> f64 {
    let opts = Options {
        constraint_tolerance: 0.1,
        ..Options::default()
    };
    let mut integ = Integrator::new(sys.clone(), base, 0.1)
        .with_method(method)
        .with_options(opts);
    let z = z0.to_vector();
    let images: Vec<_> = tangent
        .iter()
        .map(|u| derivative(&mut integ, &z, u))
        .collect();
    let mut worst: f64 = 0.0;
    for i in 0..tangent.len() {
        for j in i + 1..tangent.len() {
            worst =
                worst.max((omega(&images[i], &images[j]) - omega(&tangent[i], &tangent[j])).abs());
        }
    }
    worst
}

fn check<S: ConstrainedSystem + Clone>(name: &str, sys: S, z0: State) {
    let (gz, hz) = jacobians(&sys, &z0);
    let tm = kernel(&gz);
    let mut both = gz.clone().insert_rows(gz.nrows(), hz.nrows(), 0.0);
    both.rows_mut(gz.nrows(), hz.nrows()).copy_from(&hz);
    let tmh = kernel(&both);
    assert_eq!(tm.len(), 2 * sys.dof() - sys.constraint_count());
    assert_eq!(tmh.len(), 2 * sys.dof() - 2 * sys.constraint_count());
    for (bname, s, r) in [
        (
            "midpoint",
            defect(&sys, ImplicitMidpoint, Method::Shake, &z0, &tm),
            defect(&sys, ImplicitMidpoint, Method::Rattle, &z0, &tmh),
        ),
        (
            "Störmer–Verlet",
            defect(&sys, StormerVerlet, Method::Shake, &z0, &tm),
            defect(&sys, StormerVerlet, Method::Rattle, &z0, &tmh),
        ),
        (
            "symplectic Euler",
            defect(&sys, SymplecticEuler, Method::Shake, &z0, &tm),
            defect(&sys, SymplecticEuler, Method::Rattle, &z0, &tmh),
        ),
    ] {
        println!("{name:>22} / {bname:<16} SHAKE on TM: {s:.1e}   RATTLE on TM^H: {r:.1e}");
        assert!(s < TOL, "{name}/{bname}: SHAKE not presymplectic: {s:e}");
        assert!(
            r < TOL,
            "{name}/{bname}: RATTLE not symplectic on M^H: {r:e}"
        );
    }
}

#[test]
fn pendulum() {
    let sys = Pendulum::default();
    check("pendulum", sys, sys.state(1.0, 0.5));
}

#[test]
fn non_separable_pendulum() {
    let sys = NonSeparablePendulum::default();
    check("non-separable pendulum", sys, sys.state_on_mh(0.8, 0.4));
}

#[test]
fn spherical_pendulum() {
    let sys = SphericalPendulum::default();
    check("spherical pendulum", sys, sys.state(1.0, 0.3, 0.4, 0.8));
}

#[test]
fn double_pendulum() {
    let sys = DoublePendulum::default();
    check("double pendulum", sys, sys.state(0.5, 1.0, 0.3, -0.2));
}

#[test]
fn hopf_free() {
    let (a, b) = (0.8f64, 0.6f64);
    check(
        "Hopf H=|p|²/2",
        Hopf::free(),
        State::from_slices(&[a, 0.0], &[0.0, b]),
    );
}

#[test]
fn hopf_gravity() {
    let sys = Hopf::gravity();
    let z0 = Integrator::new(sys, ImplicitMidpoint, 0.1)
        .project_to_hidden(&State::from_slices(
            &[-0.78652612, -0.4043988],
            &[-0.3880746864163783, 0.2173391755798215],
        ))
        .unwrap();
    check("Hopf H=|p|²/2−γ·q", sys, z0);
}

#[test]
fn the_check_can_fail_off_the_tangent_space() {
    // SHAKE maps all of a fibre to one point, so DS kills the fibre
    // direction X_g, while ω(X_g, v) ≠ 0 for v ∉ TM: the defect is O(1).
    let sys = Pendulum::default();
    let z0 = sys.state(1.0, 0.5);
    let all: Vec<DVector<f64>> = (0..4)
        .map(|i| DVector::from_fn(4, |k, _| if k == i { 1.0 } else { 0.0 }))
        .collect();
    let s = defect(&sys, StormerVerlet, Method::Shake, &z0, &all);
    assert!(s > 0.1, "{s}");
}
