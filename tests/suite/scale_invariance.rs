//! Scale invariance and tiny steps.
//!
//! Rescaling lengths by L and time by T (q → Lq, t → Tt, p → (L/T)p for
//! these unit-mass systems, gravity γ → γL/T², rod lengths ℓ → Lℓ, h → Th)
//! maps the equations of motion, the constraint set M, the hidden constraint
//! set M^H and the fibres onto themselves, and every base map used here is
//! covariant under it (each is built from H's gradients, which scale the
//! same way). So SHAKE and RATTLE of the rescaled system give the rescaled
//! trajectory: for L and T powers of two every floating-point operation
//! scales exactly and only the stopping rules' absolute terms could differ,
//! so the bound is round-off: |q'/L − q| ≤ k·8ε·|q|∞ after k steps
//! (each step's Newton stops at an update ≤ 4ε relative, twice per step).
//! For other factors each operation rounds differently, by ε relative: the
//! same bound holds with the growth of a bounded interval's perturbations
//! (the runs are 50 steps of a libration, well inside its stability).
//!
//! Tiny steps: h = 1e-8 … 1e-12 are well-posed; a run must not refuse them
//! (no fibre jump, no non-convergence), and its states stay on M.

use crate::common;

use common::models::*;
use geoshake::{
    BaseMap, ConstrainedSystem, ImplicitMidpoint, Integrator, Method, State, Stop, StormerVerlet,
};

const STEPS: u64 = 50;

fn scaled(z: &State, l: f64, t: f64) -> State {
    State::new(z.q.clone() * l, z.p.clone() * (l / t))
}

fn compare<S: ConstrainedSystem + Clone, B: BaseMap>(
    what: &str,
    a: (S, State),
    b: (S, State),
    base: B,
    h: f64,
    (l, t): (f64, f64),
) {
    for method in [Method::Shake, Method::Rattle] {
        let ra = Integrator::new(a.0.clone(), base, h)
            .with_method(method)
            .run(a.1.clone(), Stop::Steps(STEPS))
            .execute()
            .into_result()
            .unwrap_or_else(|(_, e)| panic!("{what} {method:?}: {e}"));
        let rb = Integrator::new(b.0.clone(), base, t * h)
            .with_method(method)
            .run(b.1.clone(), Stop::Steps(STEPS))
            .execute()
            .into_result()
            .unwrap_or_else(|(_, e)| {
                panic!("{what} {method:?} scaled by L = {l:e}, T = {t:e}: {e}")
            });
        for k in 0..ra.len() {
            let (za, zb) = (ra.state(k), rb.state(k));
            let back = State::new(zb.q.clone() / l, zb.p.clone() * (t / l));
            let bound = (k as f64 + 1.0) * 8.0 * f64::EPSILON * za.q.amax().max(za.p.amax());
            let err = back.distance(&za);
            assert!(
                err <= bound,
                "{what} {method:?}, L = {l:e}, T = {t:e}, step {k}: {err:.2e} > {bound:.2e}"
            );
        }
    }
}

fn pendulum(l: f64, t: f64) {
    let a = Pendulum::default();
    let b = Pendulum {
        gravity: a.gravity * l / (t * t),
        length: a.length * l,
    };
    let z = a.state(0.8, 0.4);
    compare(
        "pendulum",
        (a, z.clone()),
        (b, scaled(&z, l, t)),
        StormerVerlet,
        0.05,
        (l, t),
    );
}

fn spherical(l: f64, t: f64) {
    let a = SphericalPendulum::default();
    let b = SphericalPendulum {
        gravity: a.gravity * l / (t * t),
        length: a.length * l,
    };
    let z = a.state(0.7, 0.2, 0.3, 0.9);
    compare(
        "spherical pendulum",
        (a, z.clone()),
        (b, scaled(&z, l, t)),
        ImplicitMidpoint,
        0.05,
        (l, t),
    );
}

fn chain(l: f64, t: f64) {
    let a = DoublePendulum::default();
    let b = DoublePendulum {
        l1: a.l1 * l,
        l2: a.l2 * l,
        gravity: a.gravity * l / (t * t),
        ..a
    };
    let z = a.state(0.5, -0.3, 0.2, 0.4);
    compare(
        "double pendulum",
        (a, z.clone()),
        (b, scaled(&z, l, t)),
        StormerVerlet,
        0.05,
        (l, t),
    );
}

#[test]
fn powers_of_two_rescale_exactly() {
    for (l, t) in [
        (2.0, 1.0),
        (0.25, 1.0),
        (1.0, 0.5),
        (8.0, 0.125),
        (1.0 / 64.0, 4.0),
    ] {
        pendulum(l, t);
        spherical(l, t);
        chain(l, t);
    }
}

#[test]
fn moderate_factors_rescale_to_round_off() {
    for (l, t) in [(3.0, 1.0), (0.1, 1.0), (1.0, 0.3), (7.0, 0.01)] {
        pendulum(l, t);
        spherical(l, t);
        chain(l, t);
    }
}

#[test]
fn long_length_scales_rescale_to_round_off() {
    for (l, t) in [(1e4, 1.0), (1e6, 1.0), (1e-4, 1.0)] {
        pendulum(l, t);
        spherical(l, t);
        chain(l, t);
    }
}

fn tiny<S: ConstrainedSystem + Clone>(what: &str, sys: S, z: State) {
    for h in [1e-8, 1e-9, 1e-10, 1e-11, 1e-12] {
        for method in [Method::Shake, Method::Rattle] {
            let out = Integrator::new(sys.clone(), StormerVerlet, h)
                .with_method(method)
                .run(z.clone(), Stop::Steps(20))
                .execute();
            assert!(
                out.error.is_none(),
                "{what} {method:?} h = {h:e}: {:?}",
                out.error
            );
            let zn = out.trajectory.last().unwrap();
            // O(h) motion (|X_H| < 10 here), plus for SHAKE a fibre
            // displacement of O(ε/h) per step: its λ solves g(φ_h(·)) = 0,
            // whose derivative in λ is O(h), so the round-off ε·|g|'s terms
            // in g moves λ by ε/h. RATTLE's projection removes it.
            let noise = if method == Method::Shake {
                10.0 * f64::EPSILON / h
            } else {
                0.0
            };
            assert!(
                zn.distance(&z) <= 20.0 * (10.0 * h + noise),
                "{what} {method:?} h = {h:e}: moved {:e}",
                zn.distance(&z)
            );
            let mut g = vec![0.0; sys.constraint_count()];
            sys.constraints(zn.q.as_slice(), zn.p.as_slice(), &mut g);
            assert!(
                g.iter().all(|x| x.abs() <= 1e-14),
                "{what} h = {h:e}: g = {g:?}"
            );
        }
    }
}

#[test]
fn tiny_steps_are_not_refused() {
    let p = Pendulum::default();
    tiny("pendulum", p, p.state(0.8, 0.4));
    let s = SphericalPendulum::default();
    tiny("spherical pendulum", s, s.state(0.7, 0.2, 0.3, 0.9));
    let c = DoublePendulum::default();
    tiny("double pendulum", c, c.state(0.5, -0.3, 0.2, 0.4));
}

geoshake::constrained_system! {
    /// A pendulum whose pivot is at (cx, 0).
    struct ShiftedPendulum {
        parameters { cx, length, gravity }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
        constraints { rod: (q[0] - cx)^2 + q[1]^2 - length^2 }
    }
}

/// Moving the origin far away changes neither what the constraint
/// tolerance accepts nor what runs: it is relative to g's own size,
/// (‖∂g/∂z‖₁/2)² ≈ ℓ², plus g's round-off at z, which a far origin does
/// raise (the points themselves are rounded to ε·|cx|). A state off the rod
/// by 1e-3 ℓ is refused at every shift; a state on it to round-off runs.
#[test]
fn a_far_origin_neither_loosens_nor_breaks_the_constraint_tolerance() {
    for cx in [0.0, 1e4, 1e8] {
        let sys = ShiftedPendulum::new(cx, 1.0, 9.81);
        let off = State::from_slices(&[cx + 1.0 + 1e-3, 0.0], &[0.0, 1.0]);
        let r = Integrator::new(sys, StormerVerlet, 0.01).step(&off);
        assert!(
            matches!(r, Err(geoshake::StepError::NotOnConstraint { .. })),
            "cx = {cx:e}: {r:?}"
        );
        let on = State::from_slices(&[cx + 0.6, -0.8], &[0.8, 0.6]);
        for method in [Method::Shake, Method::Rattle] {
            let out = Integrator::new(sys, StormerVerlet, 0.01)
                .with_method(method)
                .run(on.clone(), Stop::Steps(200))
                .execute();
            assert!(
                out.error.is_none(),
                "cx = {cx:e} {method:?}: {:?}",
                out.error
            );
            let last = out.trajectory.last().unwrap();
            let r = ((last.q[0] - cx).powi(2) + last.q[1].powi(2)).sqrt();
            // The rod's length to the rounding of q at this shift.
            assert!(
                (r - 1.0).abs() <= 1e-14 + 8.0 * f64::EPSILON * cx,
                "cx = {cx:e}: |q − c| = {r}"
            );
        }
    }
}
