//! The invariants of geometric SHAKE and RATTLE, run through one shared
//! driver for every base map on every test model (pendulum, non-separable
//! pendulum, spherical pendulum, double pendulum, Hopf constraint with both
//! Hamiltonians of Section 5.4, and the Hopf constraint with the runtime's
//! own linear and numerical fibre flows).
//!
//! Tolerances come from the theory: quantities that the methods keep exactly
//! (g after every step, {g,H} after RATTLE, Π∘Sᵏ = Π∘Rᵏ, R₋ₕ∘Rₕ = id,
//! S(F_μ z) = S(z)) are checked at round-off, i.e. a small multiple of ε
//! times the size of the state and the conditioning of the Newton matrices;
//! SHAKE's hidden residual is O(h), checked by halving h.

use crate::common;

use common::models::*;
use geoshake::{
    BaseMap, ConstrainedSystem, FibreFlow, ImplicitMidpoint, Integrator, Options, State, Stop,
    StormerVerlet, SymplecticEuler,
};

fn residuals<S: ConstrainedSystem>(sys: &S, z: &State) -> (f64, f64) {
    let m = sys.constraint_count();
    let (mut g, mut gh) = (vec![0.0; m], vec![0.0; m]);
    sys.constraints(z.q.as_slice(), z.p.as_slice(), &mut g);
    sys.hidden_constraints(z.q.as_slice(), z.p.as_slice(), &mut gh);
    let n = |v: &[f64]| v.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    (n(&g), n(&gh))
}

/// Round-off bound for |g| of O(1) constraints of O(1) states.
const TOL_G: f64 = 1e-14;
/// Round-off bound for |{g,H}| after RATTLE (one more derivative).
const TOL_HIDDEN: f64 = 1e-13;
/// Round-off bound for composite maps (tens of steps, Newton solves).
const TOL_MAP: f64 = 1e-12;

#[derive(Debug, Default)]
struct Measured {
    g_max: f64,
    hidden_rattle_max: f64,
    hidden_shake_max: f64,
    hidden_shake_ratio: f64,
    shake_vs_rattle: f64,
    lazy_vs_eager: f64,
    symmetry: f64,
    fibre_independence: f64,
}

/// The shared driver: everything that must hold for SHAKE and RATTLE over a
/// base map B on the system `sys` from z0 ∈ M^H with step h.
fn check_all<S: ConstrainedSystem + Clone, B: BaseMap>(
    name: &str,
    sys: S,
    base: B,
    z0: State,
    h: f64,
    steps: u64,
) {
    let mut out = Measured::default();
    let eager = Options {
        project_every_step: true,
        ..Options::default()
    };

    // RATTLE, projecting after every step.
    let mut rattle = Integrator::new(sys.clone(), base, h)
        .rattle()
        .with_options(eager);
    let r_traj = rattle
        .run(z0.clone(), Stop::Steps(steps))
        .execute()
        .into_result()
        .unwrap_or_else(|(_, e)| {
            panic!("{name}/{}: RATTLE failed: {e}", B::NAME);
        });
    for z in r_traj.states() {
        let (g, gh) = residuals(&sys, &z);
        out.g_max = out.g_max.max(g);
        out.hidden_rattle_max = out.hidden_rattle_max.max(gh);
    }

    // RATTLE as a run does it by default: SHAKE steps, Π only at outputs.
    let mut lazy = Integrator::new(sys.clone(), base, h).rattle();
    let l_traj = lazy
        .run(z0.clone(), Stop::Steps(steps))
        .stride(5)
        .execute()
        .into_result()
        .unwrap();
    for (k, z) in l_traj.steps().iter().zip(l_traj.states()) {
        out.lazy_vs_eager = out
            .lazy_vs_eager
            .max(z.distance(&r_traj.state(*k as usize)));
    }

    // SHAKE; Π ∘ Sᵏ = Π ∘ Rᵏ; the hidden residual is O(h).
    let shake_hidden = |hh: f64, n: u64| {
        let mut shake = Integrator::new(sys.clone(), base, hh).shake();
        let traj = shake
            .run(z0.clone(), Stop::Steps(n))
            .execute()
            .into_result()
            .unwrap();
        let mut hidden: f64 = 0.0;
        let mut g_max: f64 = 0.0;
        for z in traj.states().skip(1) {
            let (g, gh) = residuals(&sys, &z);
            g_max = g_max.max(g);
            hidden = hidden.max(gh);
        }
        (traj, hidden, g_max, shake)
    };
    let (s_traj, hidden_h, g_shake, mut shake) = shake_hidden(h, steps);
    out.g_max = out.g_max.max(g_shake);
    out.hidden_shake_max = hidden_h;
    for (k, z) in s_traj.states().enumerate() {
        let pz = shake.project(&z).unwrap();
        out.shake_vs_rattle = out.shake_vs_rattle.max(pz.distance(&r_traj.state(k)));
    }
    let (_, hidden_h2, _, _) = shake_hidden(h / 2.0, 2 * steps);
    out.hidden_shake_ratio = hidden_h / hidden_h2;

    // Symmetry of RATTLE over a symmetric base map: R_{−h}(R_h(z)) = z.
    if B::SYMMETRIC {
        let mut fwd = Integrator::new(sys.clone(), base, h).rattle();
        let mut bwd = Integrator::new(sys.clone(), base, -h).rattle();
        for z in r_traj.states().step_by(7) {
            let back = bwd.step(&fwd.step(&z).unwrap()).unwrap();
            out.symmetry = out.symmetry.max(back.distance(&z));
        }
    }

    // SHAKE gives the same z1⁻ from any start on the fibre of z0.
    let mut flow = FibreFlow::new(&sys);
    let s1 = shake.step(&z0).unwrap();
    for mu in [-0.05, 0.02, 0.1] {
        let lambda = vec![mu; sys.constraint_count()];
        let mut z = z0.clone();
        flow.apply(&sys, &lambda, z.q.as_mut_slice(), z.p.as_mut_slice())
            .unwrap();
        let s1b = shake.step(&z).unwrap();
        out.fibre_independence = out.fibre_independence.max(s1b.distance(&s1));
    }

    println!("{name:>24} / {:<18} {out:?}", B::NAME);
    assert!(
        out.g_max <= TOL_G,
        "{name}/{}: |g| = {:e}",
        B::NAME,
        out.g_max
    );
    assert!(
        out.hidden_rattle_max <= TOL_HIDDEN,
        "{name}/{}: |{{g,H}}| after RATTLE = {:e}",
        B::NAME,
        out.hidden_rattle_max
    );
    assert!(
        out.shake_vs_rattle <= TOL_MAP,
        "{name}/{}: Π∘Sᵏ vs Π∘Rᵏ = {:e}",
        B::NAME,
        out.shake_vs_rattle
    );
    assert!(
        out.lazy_vs_eager <= TOL_MAP,
        "{name}/{}: lazy vs eager RATTLE = {:e}",
        B::NAME,
        out.lazy_vs_eager
    );
    assert!(
        out.symmetry <= TOL_MAP,
        "{name}/{}: R₋ₕ∘Rₕ − id = {:e}",
        B::NAME,
        out.symmetry
    );
    assert!(
        out.fibre_independence <= TOL_MAP,
        "{name}/{}: S(F_μ z) − S(z) = {:e}",
        B::NAME,
        out.fibre_independence
    );
    // O(h): well above round-off, below a modest multiple of h, and it halves
    // with h (the ratio of first-order quantities is 2 up to O(h)).
    assert!(
        out.hidden_shake_max > 1e-6 * h && out.hidden_shake_max < 100.0 * h,
        "{name}/{}: SHAKE's |{{g,H}}| = {:e} is not O(h)",
        B::NAME,
        out.hidden_shake_max
    );
    assert!(
        (1.6..2.5).contains(&out.hidden_shake_ratio),
        "{name}/{}: SHAKE's hidden residual ratio under h → h/2 is {}",
        B::NAME,
        out.hidden_shake_ratio
    );
}

fn all_bases<S: ConstrainedSystem + Clone>(name: &str, sys: S, z0: State, h: f64, steps: u64) {
    check_all(name, sys.clone(), ImplicitMidpoint, z0.clone(), h, steps);
    check_all(name, sys.clone(), StormerVerlet, z0.clone(), h, steps);
    check_all(name, sys, SymplecticEuler, z0, h, steps);
}

#[test]
fn pendulum() {
    let sys = Pendulum::default();
    all_bases("pendulum", sys, sys.state(1.0, 0.5), 0.05, 60);
}

#[test]
fn pendulum_with_length_and_gravity() {
    let sys = Pendulum {
        gravity: 9.81,
        length: 2.0,
    };
    all_bases("pendulum ℓ=2 γ=9.81", sys, sys.state(2.5, 0.0), 0.02, 60);
}

#[test]
fn non_separable_pendulum() {
    let sys = NonSeparablePendulum::default();
    let z0 = Integrator::new(sys, ImplicitMidpoint, 0.1)
        .project_to_hidden(&State::from_slices(&[1f64.sin(), -1f64.cos()], &[0.3, 0.2]))
        .unwrap();
    all_bases("non-separable pendulum", sys, z0, 0.05, 60);
}

#[test]
fn spherical_pendulum() {
    let sys = SphericalPendulum::default();
    all_bases(
        "spherical pendulum",
        sys,
        sys.state(1.0, 0.3, 0.4, 0.8),
        0.05,
        60,
    );
}

#[test]
fn double_pendulum() {
    let sys = DoublePendulum {
        m2: 0.5,
        l2: 0.7,
        ..DoublePendulum::default()
    };
    all_bases(
        "double pendulum",
        sys,
        sys.state(0.5, 1.0, 0.3, -0.2),
        0.02,
        60,
    );
}

/// A point of the Hopf M^H for H = |p|²/2: q = a(cos φ, sin φ),
/// p = b(−sin φ, cos φ), a² + b² = 1 (component |q| > |p| for a > b).
fn hopf_free_point(a: f64, phi: f64) -> State {
    let b = (1.0 - a * a).sqrt();
    State::from_slices(
        &[a * phi.cos(), a * phi.sin()],
        &[-b * phi.sin(), b * phi.cos()],
    )
}

#[test]
fn hopf_free() {
    all_bases(
        "Hopf H=|p|²/2",
        Hopf::free(),
        hopf_free_point(0.8, 0.3),
        0.05,
        60,
    );
}

#[test]
fn hopf_free_other_component() {
    all_bases(
        "Hopf H=|p|²/2 (|q|<|p|)",
        Hopf::free(),
        hopf_free_point(0.55, 1.1),
        0.02,
        60,
    );
}

const PAPER_Z_A: [f64; 4] = [
    -0.78652612,
    -0.4043988,
    -0.3880746864163783,
    0.2173391755798215,
];

#[test]
fn hopf_gravity() {
    // The paper's z_a, brought onto the unit M^H (it lies on r² ≈ 0.98).
    let sys = Hopf::gravity();
    let z = PAPER_Z_A;
    let z0 = Integrator::new(sys, ImplicitMidpoint, 0.1)
        .project_to_hidden(&State::from_slices(&z[..2], &z[2..]))
        .unwrap();
    all_bases("Hopf H=|p|²/2−γ·q", sys, z0, 0.05, 60);
}

#[test]
fn hopf_gravity_on_the_papers_sphere() {
    let z = PAPER_Z_A;
    let radius2 = z.iter().map(|x| x * x).sum();
    let sys = Hopf {
        radius2,
        gravity: [0.0, -1.0],
    };
    all_bases(
        "Hopf γ, r²=0.98",
        sys,
        State::from_slices(&z[..2], &z[2..]),
        0.1,
        60,
    );
}

#[test]
fn hopf_with_the_runtimes_linear_flow() {
    let sys = NoClosedForm(Hopf::gravity());
    let z0 = Integrator::new(sys, ImplicitMidpoint, 0.1)
        .project_to_hidden(&State::from_slices(&PAPER_Z_A[..2], &PAPER_Z_A[2..]))
        .unwrap();
    all_bases("Hopf γ, expm fibre", sys, z0, 0.05, 40);
}

#[test]
fn hopf_with_a_numerical_fibre_flow() {
    let sys = AsGeneral(Hopf::gravity());
    let z0 = Integrator::new(sys, ImplicitMidpoint, 0.1)
        .project_to_hidden(&State::from_slices(&PAPER_Z_A[..2], &PAPER_Z_A[2..]))
        .unwrap();
    all_bases("Hopf γ, GBS fibre", sys, z0, 0.05, 40);
}

#[test]
fn pendulum_with_the_runtimes_kick() {
    let sys = NoClosedForm(DoublePendulum::default());
    all_bases(
        "double pendulum, g_q kick",
        sys,
        DoublePendulum::default().state(0.5, 1.0, 0.3, -0.2),
        0.02,
        40,
    );
}

#[test]
fn numerical_and_closed_form_fibre_flows_agree() {
    // Hopf: the runtime's exponential, its GBS integration and the closed
    // rotation z_k ↦ e^{−2iλ} z_k agree to round-off.
    let sys = Hopf::gravity();
    let (mut lin, mut generated) = (
        FibreFlow::new(&NoClosedForm(sys)),
        FibreFlow::new(&AsGeneral(sys)),
    );
    let mut closed = FibreFlow::new(&sys);
    for lambda in [-1.3, -0.2, 0.0, 1e-3, 0.4, 2.0] {
        let z = [0.3, -0.5, 0.6, 0.2];
        let (mut a, mut b, mut c) = (z, z, z);
        let (aq, ap) = a.split_at_mut(2);
        closed.apply(&sys, &[lambda], aq, ap).unwrap();
        let (bq, bp) = b.split_at_mut(2);
        lin.apply(&NoClosedForm(sys), &[lambda], bq, bp).unwrap();
        let (cq, cp) = c.split_at_mut(2);
        generated.apply(&AsGeneral(sys), &[lambda], cq, cp).unwrap();
        let (s, co) = (2.0 * lambda).sin_cos();
        let want = [
            co * z[0] + s * z[2],
            co * z[1] + s * z[3],
            -s * z[0] + co * z[2],
            -s * z[1] + co * z[3],
        ];
        for k in 0..4 {
            assert!(
                (a[k] - want[k]).abs() < 4e-16,
                "closed {lambda}: {a:?} {want:?}"
            );
            assert!(
                (b[k] - want[k]).abs() < 4e-15,
                "expm {lambda}: {b:?} {want:?}"
            );
            assert!(
                (c[k] - want[k]).abs() < 4e-15,
                "GBS {lambda}: {c:?} {want:?}"
            );
        }
    }
    // Double pendulum (m = 2): the runtime's kick equals the closed form.
    let dp = DoublePendulum::default();
    let z0 = dp.state(0.4, -0.3, 0.2, 0.1);
    let (mut a, mut b) = (z0.clone(), z0.clone());
    FibreFlow::new(&dp)
        .apply(&dp, &[0.3, -0.2], a.q.as_mut_slice(), a.p.as_mut_slice())
        .unwrap();
    FibreFlow::new(&NoClosedForm(dp))
        .apply(
            &NoClosedForm(dp),
            &[0.3, -0.2],
            b.q.as_mut_slice(),
            b.p.as_mut_slice(),
        )
        .unwrap();
    assert!(a.distance(&b) < 1e-15);
}

#[test]
fn unconstrained_systems_run_on_every_base_map() {
    // m = 0: SHAKE/RATTLE reduce to φ_h. A free particle in gravity (the
    // pendulum's H without its rod) is integrated exactly by all three maps
    // for q when the force is constant... only Störmer–Verlet and midpoint
    // are exact for this quadratic H; symplectic Euler is O(h).
    let sys = geoshake::Unconstrained(Pendulum::default());
    let z0 = State::from_slices(&[0.0, 0.0], &[1.0, 2.0]);
    let t = 1.0;
    let exact_q1 = 2.0 * t - 0.5 * t * t;
    for (name, q1) in [
        ("midpoint", run_free(sys, ImplicitMidpoint, &z0)),
        ("SV", run_free(sys, StormerVerlet, &z0)),
        ("Euler", run_free(sys, SymplecticEuler, &z0)),
    ] {
        let err = (q1 - exact_q1).abs();
        if name == "Euler" {
            assert!(err > 1e-3 && err < 0.1, "{name}: {err}");
        } else {
            assert!(err < 1e-13, "{name}: {err}");
        }
    }
}

fn run_free<B: BaseMap>(sys: geoshake::Unconstrained<Pendulum>, base: B, z0: &State) -> f64 {
    let mut integ = Integrator::new(sys, base, 0.01);
    let out = integ
        .run(z0.clone(), Stop::Time(1.0))
        .execute()
        .into_result()
        .unwrap();
    out.last().unwrap().q[1]
}
