//! A momentum-dependent system with two constraints (m = 2): a Hopf
//! constraint |q_a|² + |p_a|² = r_a on each of two planes, the planes
//! coupled through the potential k·q₀q₂. The constraints read disjoint
//! variables, so {g_a, g_b} = 0 exactly (coisotropic), and the coupling
//! makes N = {{H,g_i},g_j} a full 2×2 matrix (N_ab = 4k p₀p₂).
//!
//! Checked against independent references:
//! - with k = 0 the system is two Hopf systems with gravity: the m = 2 run
//!   must be the pair of m = 1 runs (the paper's Section 5.4 scene, whose
//!   accuracy `tests/suite/paper_hopf.rs` checks against its own reference),
//!   step by step, to round-off;
//! - with k ≠ 0: every state on M and M^H to round-off; the global error
//!   at T = 1 against a reference computed by the triple jump (order 4) at
//!   h/8 falls by 4 per halving of h (RATTLE's order 2); the energy error
//!   too; one step taken back with −h returns (symmetry, Section 4).

use geoshake::{
    constrained_system, Composition, ConstrainedSystem, Hamiltonian, ImplicitMidpoint, Integrator,
    State, Stop, StormerVerlet,
};

constrained_system! {
    /// Two Hopf constraints on two planes, coupled by k·q₀q₂.
    pub struct HopfPair {
        parameters { k, ga, gb, ra, rb }
        dof q[4], p[4];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2 + p[3]^2) / 2 - ga * q[1] - gb * q[3] + k * q[0] * q[2];
        constraints {
            plane_a: q[0]^2 + q[1]^2 + p[0]^2 + p[1]^2 - ra,
            plane_b: q[2]^2 + q[3]^2 + p[2]^2 + p[3]^2 - rb,
        }
    }
}

constrained_system! {
    /// One Hopf constraint with gravity g along q₁.
    pub struct HopfOne {
        parameters { g, r }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 - g * q[1];
        constraints { sphere: q[0]^2 + q[1]^2 + p[0]^2 + p[1]^2 - r }
    }
}

const GA: f64 = 1.0;
const GB: f64 = 0.7;
const RA: f64 = 1.0;
const RB: f64 = 0.8;

fn pair(k: f64) -> HopfPair {
    HopfPair {
        k,
        ga: GA,
        gb: GB,
        ra: RA,
        rb: RB,
    }
}

/// A point of M^H near a guess on each sphere (the guesses lie off the
/// exceptional fibres |q| = |p|).
fn start(k: f64) -> State {
    let guess = State::from_slices(&[0.8, -0.3, 0.2, -0.7], &[0.3, 0.35, 0.4, 0.25]);
    let z = Integrator::new(pair(k), ImplicitMidpoint, 0.1)
        .project_to_hidden(&guess)
        .expect("the guess projects onto M^H");
    let mut g = [0.0; 2];
    pair(k).constraints(z.q.as_slice(), z.p.as_slice(), &mut g);
    assert!(g.iter().all(|x| x.abs() < 1e-14), "{g:?}");
    z
}

fn residuals(sys: &HopfPair, z: &State) -> (f64, f64) {
    let (mut g, mut gh) = ([0.0; 2], [0.0; 2]);
    sys.constraints(z.q.as_slice(), z.p.as_slice(), &mut g);
    sys.hidden_constraints(z.q.as_slice(), z.p.as_slice(), &mut gh);
    let m = |v: [f64; 2]| v[0].abs().max(v[1].abs());
    (m(g), m(gh))
}

#[test]
fn uncoupled_the_pair_is_two_single_hopf_runs() {
    let z0 = start(0.0);
    let n = 400;
    for h in [0.05, -0.02] {
        let both = Integrator::new(pair(0.0), ImplicitMidpoint, h)
            .run(z0.clone(), Stop::Steps(n))
            .execute();
        assert!(both.error.is_none(), "{:?}", both.error);
        let one = |g: f64, r: f64, i: usize| {
            let z = State::from_slices(&z0.q.as_slice()[i..i + 2], &z0.p.as_slice()[i..i + 2]);
            let out = Integrator::new(HopfOne { g, r }, ImplicitMidpoint, h)
                .run(z, Stop::Steps(n))
                .execute();
            assert!(out.error.is_none(), "{:?}", out.error);
            out.trajectory
        };
        let (a, b) = (one(GA, RA, 0), one(GB, RB, 2));
        let mut worst: f64 = 0.0;
        for (k, z) in both.trajectory.states().enumerate() {
            let (za, zb) = (a.state(k), b.state(k));
            for i in 0..2 {
                worst = worst
                    .max((z.q[i] - za.q[i]).abs())
                    .max((z.p[i] - za.p[i]).abs())
                    .max((z.q[2 + i] - zb.q[i]).abs())
                    .max((z.p[2 + i] - zb.p[i]).abs());
            }
        }
        // Both solve the same equations to round-off; their Newton
        // iterations differ (one 2×2 block-diagonal system against two
        // scalar ones), so the states agree to a few ε per step.
        println!("k = 0, h = {h}: pair against two single runs {worst:e}");
        assert!(worst <= 1e-13 * n as f64, "h = {h}: {worst:e}");
    }
}

/// max over the run of |g|, |{g,H}|, |H − H₀|, and the state at T.
fn coupled_run(h: f64, c: Composition, t: f64) -> (f64, f64, f64, State) {
    let sys = pair(0.3);
    let z0 = start(0.3);
    let h0 = sys.hamiltonian(z0.q.as_slice(), z0.p.as_slice());
    let n = (t / h).round() as u64;
    let out = Integrator::new(sys, StormerVerlet, h)
        .composed(c)
        .run(z0, Stop::Steps(n))
        .execute();
    assert!(out.error.is_none(), "h = {h}: {:?}", out.error);
    let (mut g, mut gh, mut de) = (0.0f64, 0.0f64, 0.0f64);
    for z in out.trajectory.states() {
        let (a, b) = residuals(&sys, &z);
        g = g.max(a);
        gh = gh.max(b);
        de = de.max((sys.hamiltonian(z.q.as_slice(), z.p.as_slice()) - h0).abs());
    }
    let last = out.trajectory.state(out.trajectory.len() - 1);
    (g, gh, de, last)
}

#[test]
fn coupled_rattle_stays_on_m_and_m_h_and_has_order_two() {
    let t = 1.0;
    let reference = coupled_run(0.0025, Composition::TRIPLE_JUMP, t).3;
    let mut errors = Vec::new();
    let mut energies = Vec::new();
    for h in [0.04, 0.02, 0.01] {
        let (g, gh, de, z) = coupled_run(h, Composition::SINGLE, t);
        // Round-off: the states are O(1).
        assert!(
            g <= 1e-14 && gh <= 1e-13,
            "h = {h}: |g| = {g:e}, |{{g,H}}| = {gh:e}"
        );
        errors.push(z.distance(&reference));
        energies.push(de);
    }
    println!("k = 0.3: errors at T = 1 {errors:?}, energy errors {energies:?}");
    for w in errors.windows(2).chain(energies.windows(2)) {
        let order = (w[0] / w[1]).log2();
        assert!(
            (1.8..=2.2).contains(&order),
            "orders: errors {errors:?}, energy {energies:?}"
        );
    }
}

#[test]
fn coupled_rattle_is_symmetric() {
    let z0 = start(0.3);
    for base_is_midpoint in [false, true] {
        for h in [0.1, 0.02] {
            let (z1, back) = if base_is_midpoint {
                let z1 = Integrator::new(pair(0.3), ImplicitMidpoint, h)
                    .step(&z0)
                    .unwrap();
                let back = Integrator::new(pair(0.3), ImplicitMidpoint, -h)
                    .step(&z1)
                    .unwrap();
                (z1, back)
            } else {
                let z1 = Integrator::new(pair(0.3), StormerVerlet, h)
                    .step(&z0)
                    .unwrap();
                let back = Integrator::new(pair(0.3), StormerVerlet, -h)
                    .step(&z1)
                    .unwrap();
                (z1, back)
            };
            println!("h = {h}: R₋ₕ∘Rₕ misses by {:e}", back.distance(&z0));
            assert!(z1.distance(&z0) > 1e-3, "the step moved");
            assert!(
                back.distance(&z0) <= 1e-14,
                "h = {h}: {:e}",
                back.distance(&z0)
            );
        }
    }
}
