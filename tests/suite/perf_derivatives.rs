//! No derivative is evaluated that the chosen method does not use. A
//! counting wrapper around a generated system counts every call of every
//! trait method during a run (after the integrator's setup), and the test
//! states which are zero:
//!
//! - SHAKE with explicit Störmer–Verlet on a separable H and holonomic g
//!   (the classical SHAKE): gradients, g, G = g_z (at most three times a
//!   step: at the start and for SHAKE's Jacobian), the closed-form fibre
//!   flow and N (the nondegeneracy check) only — no Hessian of H, no
//!   Σλ∇²g, no hidden constraint or its Jacobian — but for the one check
//!   of the first input's N against the size of its terms.
//! - RATTLE adds {g, H} (its projection).
//! - Nobody ever evaluates the Jacobian of the hidden constraints.
//!
//! Counted through `step_in_place`. Runs take the same SHAKE step in
//! increment form with Kahan's carry, so the counts hold for runs too
//! (BENCHMARKS.md, section 4.1).
//!
//! Run with `--nocapture` to see the table of counts.

use geoshake::models::{Chain8, Pendulum};
use geoshake::{
    BaseMap, ClosedForm, ConstrainedSystem, ConstraintKind, Hamiltonian, ImplicitMidpoint,
    Integrator, State, StormerVerlet,
};
use std::cell::Cell;

#[derive(Clone, Default)]
struct Counts {
    h: Cell<usize>,
    grad: Cell<usize>,
    hessian: Cell<usize>,
    g: Cell<usize>,
    g_z: Cell<usize>,
    g_hess: Cell<usize>,
    hidden: Cell<usize>,
    hidden_z: Cell<usize>,
    n: Cell<usize>,
    fibre: Cell<usize>,
}

impl Counts {
    fn row(&self) -> [usize; 10] {
        [
            self.h.get(),
            self.grad.get(),
            self.hessian.get(),
            self.g.get(),
            self.g_z.get(),
            self.g_hess.get(),
            self.hidden.get(),
            self.hidden_z.get(),
            self.n.get(),
            self.fibre.get(),
        ]
    }
    fn reset(&self) {
        for c in [
            &self.h,
            &self.grad,
            &self.hessian,
            &self.g,
            &self.g_z,
            &self.g_hess,
            &self.hidden,
            &self.hidden_z,
            &self.n,
            &self.fibre,
        ] {
            c.set(0);
        }
    }
}

fn bump(c: &Cell<usize>) {
    c.set(c.get() + 1);
}

/// Delegates to `S` and counts the calls (shared counters: clones of the
/// integrator's system count into the same cells).
#[derive(Clone)]
struct Counting<'a, S> {
    sys: S,
    counts: &'a Counts,
}

impl<S: ConstrainedSystem> Hamiltonian for Counting<'_, S> {
    fn dof(&self) -> usize {
        self.sys.dof()
    }
    fn separable(&self) -> bool {
        self.sys.separable()
    }
    fn quadratic_kinetic(&self) -> bool {
        self.sys.quadratic_kinetic()
    }
    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        bump(&self.counts.h);
        self.sys.hamiltonian(q, p)
    }
    fn grad_q(&self, q: &[f64], p: &[f64], h_q: &mut [f64]) {
        bump(&self.counts.grad);
        self.sys.grad_q(q, p, h_q)
    }
    fn grad_p(&self, q: &[f64], p: &[f64], h_p: &mut [f64]) {
        bump(&self.counts.grad);
        self.sys.grad_p(q, p, h_p)
    }
    fn gradient(&self, q: &[f64], p: &[f64], h_q: &mut [f64], h_p: &mut [f64]) {
        bump(&self.counts.grad);
        self.sys.gradient(q, p, h_q, h_p)
    }
    fn hessian(&self, q: &[f64], p: &[f64], h_zz: &mut [f64]) {
        bump(&self.counts.hessian);
        self.sys.hessian(q, p, h_zz)
    }
}

impl<S: ConstrainedSystem> ConstrainedSystem for Counting<'_, S> {
    fn constraint_count(&self) -> usize {
        self.sys.constraint_count()
    }
    fn kind(&self) -> ConstraintKind {
        self.sys.kind()
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        self.sys.jacobian_pattern()
    }
    fn constraint_name(&self, i: usize) -> &str {
        self.sys.constraint_name(i)
    }
    fn constraints(&self, q: &[f64], p: &[f64], g: &mut [f64]) {
        bump(&self.counts.g);
        self.sys.constraints(q, p, g)
    }
    fn constraint_jacobian(&self, q: &[f64], p: &[f64], g_z: &mut [f64]) {
        bump(&self.counts.g_z);
        self.sys.constraint_jacobian(q, p, g_z)
    }
    fn constraint_hessian(&self, q: &[f64], p: &[f64], lambda: &[f64], out: &mut [f64]) {
        bump(&self.counts.g_hess);
        self.sys.constraint_hessian(q, p, lambda, out)
    }
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        bump(&self.counts.hidden);
        self.sys.hidden_constraints(q, p, out)
    }
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        bump(&self.counts.hidden_z);
        self.sys.hidden_constraint_jacobian(q, p, out)
    }
    fn nondegeneracy_matrix(&self, q: &[f64], p: &[f64], n: &mut [f64]) {
        bump(&self.counts.n);
        self.sys.nondegeneracy_matrix(q, p, n)
    }
    fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        bump(&self.counts.fibre);
        self.sys.fibre_flow(lambda, q, p)
    }
}

const STEPS: u64 = 1000;

/// The counts of STEPS calls of `step_in_place` (RATTLE projects every
/// step; each call checks N at its result, and at its input unless the
/// input is the result of the call before).
fn counts<S: ConstrainedSystem + Clone, B: BaseMap>(
    name: &str,
    sys: S,
    base: B,
    rattle: bool,
    z0: &State,
) -> [usize; 10] {
    let counts = Counts::default();
    let wrapped = Counting {
        sys,
        counts: &counts,
    };
    let integ = Integrator::new(wrapped, base, 0.01);
    let mut integ = if rattle {
        integ.rattle()
    } else {
        integ.shake()
    };
    let mut z = integ.project_to_hidden(z0).unwrap();
    counts.reset();
    for _ in 0..STEPS {
        integ.step_in_place(&mut z).unwrap();
    }
    let row = counts.row();
    println!(
        "| {name} | {} | {} | {} |",
        B::NAME,
        if rattle { "RATTLE" } else { "SHAKE" },
        row.iter()
            .map(|c| c.to_string())
            .collect::<Vec<_>>()
            .join(" | ")
    );
    row
}

#[test]
fn the_classical_shake_evaluates_no_second_derivative_and_no_jacobian() {
    println!("| system | base map | method | H | ∇H | H_zz | g | g_z | Σλ∇²g | {{g,H}} | ∇{{g,H}} | N | fibre flow |");
    println!("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let pendulum = State::from_slices(&[0.8, -0.6], &[0.3, 0.4]);
    let mut q = vec![0.0; 16];
    for k in 0..8 {
        let (x0, y0) = if k == 0 {
            (0.0, 0.0)
        } else {
            (q[2 * k - 2], q[2 * k - 1])
        };
        q[2 * k] = x0 + (0.3 + 0.1 * k as f64).sin();
        q[2 * k + 1] = y0 - (0.3 + 0.1 * k as f64).cos();
    }
    let chain = State::from_slices(&q, &[0.0; 16]);
    let p = Pendulum::new(1.0, 1.0);
    let c = Chain8::new(1.0, 1.0);
    // [h, grad, hessian, g, g_z, g_hess, hidden, hidden_z, n, fibre]
    for (name, m, row) in [
        (
            "pendulum",
            1,
            counts("pendulum", p, StormerVerlet, false, &pendulum),
        ),
        (
            "chain of 8",
            8,
            counts("chain of 8", c, StormerVerlet, false, &chain),
        ),
    ] {
        // The first call checks its input's N against the size of N's
        // terms (`rattle::nondegeneracy_terms`): one H_zz and m Σλ∇²g, at
        // the start only, never inside a step.
        assert_eq!(
            row[2], 1,
            "{name}: Hessian of H evaluated by classical SHAKE"
        );
        // g_z at the start of a step and at the iterate where the
        // (analytic, banded) Jacobian −h G(q1) A G(q0)ᵀ is formed: usually
        // twice per step, never per residual.
        assert!(
            row[4] as u64 <= 3 * STEPS,
            "{name}: g_z evaluated {} times by classical SHAKE",
            row[4]
        );
        assert_eq!(row[5], m, "{name}: Σλ∇²g evaluated by classical SHAKE");
        assert_eq!(row[6], 0, "{name}: {{g,H}} evaluated by SHAKE");
        assert_eq!(row[7], 0, "{name}: ∇{{g,H}} evaluated");
        // N once per step, at its result: the input of each call but the
        // first is the result of the one before, already checked (+1: the
        // first call checks its input).
        assert_eq!(row[8] as u64, STEPS + 1, "{name}: N evaluations");
        assert!(row[9] > 0, "{name}: the closed-form fibre flow is used");
    }
    for (name, m, row) in [
        (
            "pendulum",
            1,
            counts("pendulum", p, StormerVerlet, true, &pendulum),
        ),
        (
            "chain of 8",
            8,
            counts("chain of 8", c, StormerVerlet, true, &chain),
        ),
    ] {
        assert_eq!((row[2], row[5], row[7]), (1, m, 0), "{name}: RATTLE, SV");
        assert!(
            row[4] as u64 <= 3 * STEPS,
            "{name}: RATTLE, SV: g_z {}",
            row[4]
        );
        assert!(row[6] >= STEPS as usize, "{name}: {{g,H}} {}", row[6]);
    }
    // The midpoint rule needs the Hessian of H (its stage Newton and the
    // tangent map), but still no ∇{g,H}.
    let row = counts("pendulum", p, ImplicitMidpoint, true, &pendulum);
    assert_eq!(row[7], 0);
    assert!(row[2] > 0);
}
