//! Index-1 constraints, Section 5.3 (claim 6 in the README's table).
//!
//! On the extended space (q, α, p, β) with the holonomic constraint α = 0,
//! midpoint SHAKE moves along the fibre (β ↦ β − λ) and then applies the
//! midpoint rule, with λ chosen so that α₁ = 0, i.e. 0 = H_β at the midpoint.
//! The paper shows this is the midpoint rule applied directly to the index-1
//! system q' = H_p, p' = −H_q, 0 = H_β. The reference solves that directly
//! (`reference::index1_midpoint_step`, Newton on (q1, p1, β̄) with num-dual
//! derivatives), sharing no code with shake.

use geoshake::models::IndexOne;
use geoshake::{ImplicitMidpoint, Integrator, State};
use nalgebra::DVector;

use crate::claims::{Bound, Claims};
use crate::plot::PlotResult;
use crate::reference as r;
use crate::Ctx;

const EPS: f64 = f64::EPSILON;

pub fn run(ctx: &Ctx, claims: &mut Claims) -> PlotResult<()> {
    let c = 0.8;
    let h = 0.1;
    let n = if ctx.quick { 100 } else { 1000 };
    let ex = r::Index1Example { coupling: c };
    let (q0, p0) = (DVector::from_element(1, 0.8), DVector::from_element(1, 0.3));
    // Any β will do for SHAKE (it only fixes a point of the fibre); start on M^H.
    let b0 = r::index1_beta(&ex, &q0, &p0, &DVector::zeros(1));
    let mut shake = Integrator::new(IndexOne::new(c), ImplicitMidpoint, h).shake();
    let mut z = State::from_slices(&[q0[0], 0.0], &[p0[0], b0[0]]);
    let (mut step_qp, mut step_beta) = (0.0f64, 0.0f64);
    let (mut qr, mut pr) = (q0.clone(), p0.clone());
    let mut beta_guess = b0.clone();
    for _ in 0..n {
        let (q, p) = (
            DVector::from_element(1, z.q[0]),
            DVector::from_element(1, z.p[0]),
        );
        // One step of each from the same (q, p): the maps themselves.
        let (q1, p1, beta_bar) = r::index1_midpoint_step(&ex, &q, &p, &beta_guess, h);
        z = shake.step(&z)?;
        step_qp = step_qp
            .max((z.q[0] - q1[0]).abs())
            .max((z.p[0] - p1[0]).abs());
        step_beta = step_beta.max((z.p[1] - beta_bar[0]).abs());
        // And whole trajectories of the reference, from the start.
        let (q1r, p1r, _) = r::index1_midpoint_step(&ex, &qr, &pr, &beta_guess, h);
        (qr, pr) = (q1r, p1r);
        beta_guess = beta_bar;
    }
    claims.check(
        "6",
        "index 1: midpoint SHAKE on (q,α,p,β) = midpoint rule on q' = H_p, p' = −H_q, 0 = H_β (one step)",
        &format!("max over {n} steps of |(q1,p1) − (q1,p1)_direct|"),
        step_qp,
        Bound::AtMost(50.0 * EPS),
        "the same equations solved to round-off (50 ε)",
    );
    claims.check(
        "6",
        "index 1: SHAKE's β in z1⁻ is the midpoint value β̄ solving 0 = H_β(q̄, p̄, β̄)",
        &format!("max over {n} steps of |β(z1⁻) − β̄|"),
        step_beta,
        Bound::AtMost(50.0 * EPS),
        "round-off (50 ε)",
    );
    let traj = (z.q[0] - qr[0]).abs().max((z.p[0] - pr[0]).abs());
    claims.check(
        "6",
        "index 1: whole trajectories of the two methods agree",
        &format!("|(q_n, p_n) − direct| after n = {n} steps"),
        traj,
        Bound::AtMost(n as f64 * 10.0 * EPS),
        "round-off accumulated over n steps (n · 10 ε)",
    );
    Ok(())
}
