//! Each fast path takes the same steps as the general path, to round-off
//! (no timing here; `examples/overhead.rs` times them):
//!
//! - the classical SHAKE/RATTLE step (holonomic g, separable H with
//!   quadratic T, Störmer–Verlet or symplectic Euler: Newton on the
//!   positions alone with the analytic Jacobian, the closed-form root for
//!   one constraint, the projection by one solve with the factors of the
//!   step's nondegeneracy check) against `fast_paths(false)` (difference-
//!   quotient Jacobian of the full residual, Newton projection);
//! - explicit Störmer–Verlet against the generalised (implicit)
//!   Störmer–Verlet of the same H declared non-separable, whose stage
//!   equations are solved by Newton;
//! - a lazily projected run (stored states projected with the factors of N
//!   the step already made) against the general run.

use geoshake::{
    BaseMap, ClosedForm, ConstrainedSystem, ConstraintKind, Hamiltonian, Integrator, State, Stop,
    StormerVerlet, SymplecticEuler,
};

const EPS: f64 = f64::EPSILON;

/// Two solutions of the same equations to round-off. SHAKE's λ is found
/// from g(q1(λ)) = 0 to g's round-off; the generated g of a distance
/// constraint is a polynomial in q whose terms are of size |q|² (the
/// squares are expanded), so that round-off is ε|q|², and the momenta
/// inherit λ's error through p½ = (q1 − q0)/h: they agree to about
/// ε|q|²/h, the positions to ε|q|².
fn tolerance(z: &State, h: f64) -> f64 {
    let scale = z.q.amax().max(z.p.amax()).max(1.0);
    8.0 * EPS * scale * scale / h.abs().min(1.0)
}

geoshake::constrained_system! {
    /// Two rods of lengths 1 and 0.7 as in the double pendulum, with a
    /// kinetic energy that couples the two masses' momenta (a constant,
    /// non-diagonal mass matrix: SHAKE's Jacobian by column groups).
    struct CoupledRods {
        parameters { c }
        dof q[4], p[4];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2 + p[3]^2) / 2 + c * (p[0] * p[2] + p[1] * p[3])
            + 9.81 * (q[1] + q[3]);
        constraints {
            rod1: q[0]^2 + q[1]^2 - 1,
            rod2: (q[2] - q[0])^2 + (q[3] - q[1])^2 - 0.49,
        }
    }
}

fn double_start() -> State {
    geoshake_testkit::starts::double_pendulum()
}

fn pendulum_start() -> State {
    State::from_slices(&[0.8, -0.6], &[0.9, 1.2])
}

/// A chain of 8 links at varied angles, moving.
fn chain_start() -> State {
    geoshake_testkit::starts::chain(8)
}

/// The bands the steps above are factorised in: a chain of 8 links takes
/// tridiagonal kernels for SHAKE's Jacobian and N on the classical path
/// (so `the_fixed_size_step_is_the_slice_step` compares the banded stack
/// step with the banded slice step), and keeps the exact full Jacobian on
/// the general path, where the predicted band would drop O(h²) terms.
#[test]
fn small_chains_are_banded_where_the_band_is_exact() {
    let chain = geoshake::models::Chain8::new(1.0, 1.0);
    let sv = Integrator::new(chain, StormerVerlet, 0.01);
    assert_eq!(sv.newton_bands(), [(1, 1), (1, 1)]);
    let euler = Integrator::new(chain, SymplecticEuler, 0.01);
    assert_eq!(euler.newton_bands(), [(1, 1), (1, 1)]);
    let midpoint = Integrator::new(chain, geoshake::ImplicitMidpoint, 0.01);
    assert_eq!(midpoint.newton_bands(), [(7, 7), (1, 1)]);
    // Two constraints: the full band is the only one.
    let double = geoshake::models::DoublePendulum::new(1.0, 0.7, 9.81);
    let i = Integrator::new(double, StormerVerlet, 0.01);
    assert_eq!(i.newton_bands(), [(1, 1), (1, 1)]);
}

/// From each state of a fast trajectory, one step each way; the worst
/// difference over the tolerance.
fn compare_steps<S: ConstrainedSystem + Clone, B: BaseMap, T: ConstrainedSystem + Clone>(
    fast: S,
    general: T,
    general_fast_paths: bool,
    base: B,
    rattle: bool,
    z0: &State,
    h: f64,
) -> f64 {
    let f = Integrator::new(fast, base, h);
    let mut f = if rattle { f.rattle() } else { f.shake() };
    let g = Integrator::new(general, base, h).fast_paths(general_fast_paths);
    let mut g = if rattle { g.rattle() } else { g.shake() };
    let mut z = f.project_to_hidden(z0).unwrap();
    let mut worst = 0.0f64;
    for _ in 0..200 {
        let zg = g.step(&z).unwrap();
        f.step_in_place(&mut z).unwrap();
        worst = worst.max(zg.distance(&z) / tolerance(&z, h));
    }
    worst
}

#[test]
fn the_classical_step_is_the_general_step() {
    let pend = geoshake::models::Pendulum::new(1.0, 9.81);
    let chain = geoshake::models::Chain8::new(1.0, 1.0);
    for rattle in [false, true] {
        for h in [0.01, 0.05] {
            let cases = [
                (
                    "pendulum SV",
                    compare_steps(
                        pend,
                        pend,
                        false,
                        StormerVerlet,
                        rattle,
                        &pendulum_start(),
                        h,
                    ),
                ),
                (
                    "pendulum Euler",
                    compare_steps(
                        pend,
                        pend,
                        false,
                        SymplecticEuler,
                        rattle,
                        &pendulum_start(),
                        h,
                    ),
                ),
                (
                    "chain SV",
                    compare_steps(
                        chain,
                        chain,
                        false,
                        StormerVerlet,
                        rattle,
                        &chain_start(),
                        h,
                    ),
                ),
                (
                    "chain Euler",
                    compare_steps(
                        chain,
                        chain,
                        false,
                        SymplecticEuler,
                        rattle,
                        &chain_start(),
                        h,
                    ),
                ),
            ];
            for (name, worst) in cases {
                println!("{name}, rattle {rattle}, h {h}: worst / tolerance {worst:.3}");
                assert!(worst <= 1.0, "{name}, rattle {rattle}, h {h}: {worst}");
            }
        }
    }
}

geoshake::constrained_system! {
    /// A pendulum whose rod bends with its angle, g cubic in q: SHAKE's
    /// residual along its line is no quadratic, and Newton solves it.
    struct CubicRod {
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + 9.81 * q[1];
        constraints { rod: q[0]^2 + q[1]^2 + q[0]^3 / 10 - 1 }
    }
}

/// One constraint of degree ≤ 2 (a distance) takes the closed-form root of
/// SHAKE's quadratic as its first iterate, on the fixed-size and on the
/// slice path with the same operations (the same bits), where a Newton
/// update and the quadratic fitted through a second residual took two. A
/// cubic g has no closed form and iterates on both paths.
#[test]
fn one_distance_constraint_is_solved_in_closed_form() {
    let pend = geoshake::models::Pendulum::new(1.0, 9.81);
    let sphere = geoshake::models::SphericalPendulum::new(1.3, 9.81);
    let double = geoshake::models::DoublePendulum::new(1.0, 0.7, 9.81);
    assert!(pend.quadratic_constraints() && sphere.quadratic_constraints());
    assert!(double.quadratic_constraints());
    assert!(!CubicRod::new().quadratic_constraints());
    let x: f64 = 0.6;
    let y = -(1.0 - x * x - x.powi(3) / 10.0).sqrt();
    let cubic_start = State::from_slices(&[x, y], &[1.0, 0.3]);
    let sphere_start = State::from_slices(&[0.6, 0.3, -(1.69f64 - 0.45).sqrt()], &[0.4, -0.9, 0.0]);
    /// SHAKE's updates per step over 100 steps, fixed-size and slice path.
    fn updates<S: ConstrainedSystem + Clone>(sys: S, z0: &State, h: f64) -> Vec<[usize; 2]> {
        let make = |fixed| {
            Integrator::new(sys.clone(), StormerVerlet, h)
                .fixed_size(fixed)
                .rattle()
        };
        let (mut f, mut s) = (make(true), make(false));
        let mut zf = f.project_to_hidden(z0).unwrap();
        let mut zs = zf.clone();
        (0..100)
            .map(|_| {
                let a = f.step_in_place(&mut zf).unwrap().shake_iterations;
                let b = s.step_in_place(&mut zs).unwrap().shake_iterations;
                let worst = zf.distance(&zs) / (8.0 * tolerance(&zf, h));
                assert!(worst <= 1.0, "h {h}: {worst}");
                if sys.quadratic_constraints() {
                    assert_eq!(zf, zs, "h {h}: the same operations");
                }
                [a, b]
            })
            .collect()
    }
    for h in [0.01, 0.05] {
        for (name, steps) in [
            ("pendulum", updates(pend, &pendulum_start(), h)),
            ("sphere", updates(sphere, &sphere_start, h)),
        ] {
            // The root is the first iterate; a residual a rounding above
            // g's floor at it takes one more update.
            let one = steps.iter().filter(|s| s[0] == 1).count();
            println!("{name}, h {h}: {one} of 100 steps in one update");
            assert!(steps.iter().all(|&[a, b]| a == b), "{name}, h {h}");
            assert!(one >= 90, "{name}, h {h}: {one}");
        }
        let cubic = updates(CubicRod::new(), &cubic_start, h);
        assert!(cubic.iter().all(|&[a, b]| a >= 2 && b >= 2), "h {h}");
    }
}

geoshake::constrained_system! {
    /// Two unit circles in R⁴ coupled through the potential only: SHAKE's
    /// Jacobian is diagonal (each g_i reads its own plane), the
    /// constraints are decoupled.
    struct TwoCircles {
        parameters { kappa }
        dof q[4], p[4];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2 + p[3]^2) / 2
            - kappa * (q[0] * q[2] + q[1] * q[3]);
        constraints { first: q[0]^2 + q[1]^2 - 1, second: q[2]^2 + q[3]^2 - 1 }
    }
}

/// Decoupled distance constraints each take the root of their own exact
/// quadratic (fitted through the first Newton iterate), on both paths with
/// the same operations: at h|p| ≈ 0.3, where the frozen Jacobian
/// contracts by about 0.2 an update and the step took 13 to 20 updates,
/// it takes three (Newton's, the roots, the confirming one), or four
/// where the roots' residual is a rounding above g's floor.
#[test]
fn decoupled_distance_constraints_take_their_fitted_roots() {
    let start = State::from_slices(&[1.0, 0.0, 0.0, 1.0], &[0.3, 1.2, -0.8, 0.5]);
    for h in [0.1, 0.23, 0.4] {
        let make = |fixed| {
            Integrator::new(TwoCircles::new(1.5), StormerVerlet, h)
                .fixed_size(fixed)
                .rattle()
        };
        let (mut f, mut s) = (make(true), make(false));
        let mut zf = f.project_to_hidden(&start).unwrap();
        let mut zs = zf.clone();
        let mut three = 0;
        for k in 0..100 {
            let a = f.step_in_place(&mut zf).unwrap().shake_iterations;
            let b = s.step_in_place(&mut zs).unwrap().shake_iterations;
            assert_eq!(zf, zs, "h {h}, step {k}: the same operations");
            assert_eq!(a, b, "h {h}, step {k}");
            assert!(a <= 4, "h {h}, step {k}: {a} updates");
            three += usize::from(a <= 3);
        }
        println!("h {h}: {three} of 100 steps in three updates or fewer");
        assert!(three >= 90, "h {h}: {three}");
    }
}

/// A lazily projected run with a stride (the steps that end on a stored
/// state also make its Π, the others do not) and diagnostics (σ of each
/// stored state) takes the same bits on the fixed-size and the slice path
/// (one constraint of degree 2, two, eight).
#[test]
fn a_lazy_run_with_a_stride_shows_the_slice_path_states() {
    let run = |sys: &dyn Fn(bool) -> geoshake::RunOutcome| (sys(true), sys(false));
    let double = geoshake::models::DoublePendulum::new(1.0, 0.7, 9.81);
    let chain = geoshake::models::Chain8::new(1.0, 1.0);
    let pend = geoshake::models::Pendulum::new(1.0, 9.81);
    fn go<S: ConstrainedSystem + Clone>(sys: &S, z0: &State, fixed: bool) -> geoshake::RunOutcome {
        let mut i = Integrator::new(sys.clone(), StormerVerlet, 0.01)
            .fixed_size(fixed)
            .rattle()
            .with_diagnostics();
        let z0 = i.project_to_hidden(z0).unwrap();
        i.run(z0, Stop::Steps(200)).stride(7).execute()
    }
    let cases = [
        ("double pendulum", run(&|f| go(&double, &double_start(), f))),
        ("chain of 8", run(&|f| go(&chain, &chain_start(), f))),
        ("pendulum", run(&|f| go(&pend, &pendulum_start(), f))),
    ];
    for (name, (a, b)) in cases {
        assert!(a.error.is_none() && b.error.is_none(), "{name}");
        let (ta, tb) = (&a.trajectory, &b.trajectory);
        assert_eq!(ta.len(), tb.len(), "{name}");
        assert_eq!(ta.len(), 200 / 7 + 2, "{name}");
        for k in 0..ta.len() {
            let (za, zb) = (ta.state(k), tb.state(k));
            assert_eq!(za, zb, "{name}, state {k}");
            // (The last record's λ is NaN: no step leaves it.)
            let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(ta.sigma(k)), bits(tb.sigma(k)), "{name}, σ {k}");
            assert_eq!(bits(ta.lambda(k)), bits(tb.lambda(k)), "{name}, λ {k}");
        }
    }
}

/// The same system declared non-separable: Störmer–Verlet becomes the
/// generalised method whose stage equations Newton solves (and the
/// classical path does not apply).
#[derive(Copy, Clone, Debug)]
struct NonSeparable<S>(S);

impl<S: Hamiltonian> Hamiltonian for NonSeparable<S> {
    fn dof(&self) -> usize {
        self.0.dof()
    }
    fn separable(&self) -> bool {
        false
    }
    fn quadratic_kinetic(&self) -> bool {
        false
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
    fn hessian(&self, q: &[f64], p: &[f64], h_zz: &mut [f64]) {
        self.0.hessian(q, p, h_zz)
    }
}

impl<S: ConstrainedSystem> ConstrainedSystem for NonSeparable<S> {
    fn constraint_count(&self) -> usize {
        self.0.constraint_count()
    }
    fn kind(&self) -> ConstraintKind {
        self.0.kind()
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        self.0.jacobian_pattern()
    }
    fn constraint_name(&self, i: usize) -> &str {
        self.0.constraint_name(i)
    }
    fn constraints(&self, q: &[f64], p: &[f64], g: &mut [f64]) {
        self.0.constraints(q, p, g)
    }
    fn constraint_jacobian(&self, q: &[f64], p: &[f64], g_z: &mut [f64]) {
        self.0.constraint_jacobian(q, p, g_z)
    }
    fn constraint_hessian(&self, q: &[f64], p: &[f64], l: &[f64], out: &mut [f64]) {
        self.0.constraint_hessian(q, p, l, out)
    }
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        self.0.hidden_constraints(q, p, out)
    }
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        self.0.hidden_constraint_jacobian(q, p, out)
    }
    fn nondegeneracy_matrix(&self, q: &[f64], p: &[f64], n: &mut [f64]) {
        self.0.nondegeneracy_matrix(q, p, n)
    }
    fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        self.0.fibre_flow(lambda, q, p)
    }
}

#[test]
fn explicit_stormer_verlet_is_the_generalised_method() {
    let pend = geoshake::models::Pendulum::new(1.0, 9.81);
    let chain = geoshake::models::Chain8::new(1.0, 1.0);
    for rattle in [false, true] {
        let cases = [
            (
                "pendulum",
                compare_steps(
                    pend,
                    NonSeparable(pend),
                    true,
                    StormerVerlet,
                    rattle,
                    &pendulum_start(),
                    0.01,
                ),
            ),
            (
                "chain",
                compare_steps(
                    chain,
                    NonSeparable(chain),
                    true,
                    StormerVerlet,
                    rattle,
                    &chain_start(),
                    0.01,
                ),
            ),
        ];
        for (name, worst) in cases {
            println!(
                "{name} explicit vs generalised SV, rattle {rattle}: worst / tolerance {worst:.3}"
            );
            assert!(worst <= 1.0, "{name}, rattle {rattle}: {worst}");
        }
    }
}

#[test]
fn a_lazily_projected_run_is_the_general_run() {
    let chain = geoshake::models::Chain8::new(1.0, 1.0);
    let h = 0.01;
    for stride in [1, 7] {
        let mut fast = Integrator::new(chain, StormerVerlet, h).rattle();
        let mut general = Integrator::new(chain, StormerVerlet, h)
            .rattle()
            .fast_paths(false);
        let z0 = fast.project_to_hidden(&chain_start()).unwrap();
        let a = fast
            .run(z0.clone(), Stop::Steps(300))
            .stride(stride)
            .execute();
        let b = general.run(z0, Stop::Steps(300)).stride(stride).execute();
        let (a, b) = (a.into_result().unwrap(), b.into_result().unwrap());
        assert_eq!(a.steps(), b.steps());
        // Over 300 steps round-off differences grow with the flow's
        // sensitivity (the chain is chaotic): compare per stored state
        // with a bound that grows linearly in the step count.
        for i in 0..a.len() {
            let (za, zb) = (a.state(i), b.state(i));
            let bound = tolerance(&za, h) * (1.0 + a.step(i) as f64);
            assert!(
                za.distance(&zb) <= bound,
                "stride {stride}, state {i}: {:e}",
                za.distance(&zb)
            );
        }
    }
}

/// A system of one constraint declared with `constrained_system!` steps on
/// stack arrays of its own size (`geoshake::classical::fixed`); the same classical
/// step on the workspace's vectors (`fixed_size(false)`) is the reference.
/// Single steps from the states of a run, whole runs (Kahan's carry, lazy
/// and per-step projection), and the failure of a step too large to
/// converge: the same states to round-off, the same error at the same step.
#[test]
fn the_fixed_size_step_is_the_slice_step() {
    let pend = geoshake::models::Pendulum::new(1.0, 9.81);
    let sphere = geoshake::models::SphericalPendulum::new(1.3, 9.81);
    let sphere_start = State::from_slices(&[0.6, 0.3, -(1.69f64 - 0.45).sqrt()], &[0.4, -0.9, 0.0]);
    fn both<S: ConstrainedSystem + Clone, B: BaseMap>(
        sys: S,
        base: B,
        rattle: bool,
        z0: &State,
        h: f64,
    ) -> f64 {
        let make = |fixed: bool| {
            let i = Integrator::new(sys.clone(), base, h).fixed_size(fixed);
            if rattle {
                i.rattle()
            } else {
                i.shake()
            }
        };
        let (mut f, mut s) = (make(true), make(false));
        let mut z = f.project_to_hidden(z0).unwrap();
        let mut worst = 0.0f64;
        for _ in 0..200 {
            let zs = s.step(&z).unwrap();
            f.step_in_place(&mut z).unwrap();
            worst = worst.max(zs.distance(&z) / tolerance(&z, h));
        }
        // Whole runs, projected lazily (the default) and every step.
        for every in [false, true] {
            let opts = geoshake::Options {
                project_every_step: every,
                ..geoshake::Options::default()
            };
            let (mut f, mut s) = (
                make(true).with_options(opts),
                make(false).with_options(opts),
            );
            let z0 = f.project_to_hidden(z0).unwrap();
            let a = f.run(z0.clone(), Stop::Steps(300)).execute();
            let b = s.run(z0, Stop::Steps(300)).execute();
            assert!(a.error.is_none() && b.error.is_none());
            assert_eq!(a.trajectory.len(), b.trajectory.len());
            for k in 0..a.trajectory.len() {
                let (za, zb) = (a.trajectory.state(k), b.trajectory.state(k));
                // Round-off grows along a run like the trajectories'
                // own divergence; 300 steps of these pendulums stay
                // within a few times the one-step tolerance.
                worst = worst.max(za.distance(&zb) / (8.0 * tolerance(&za, h)));
            }
        }
        worst
    }
    for rattle in [false, true] {
        for h in [0.01, 0.05] {
            let cases = [
                (
                    "pendulum SV",
                    both(pend, StormerVerlet, rattle, &pendulum_start(), h),
                ),
                (
                    "pendulum Euler",
                    both(pend, SymplecticEuler, rattle, &pendulum_start(), h),
                ),
                (
                    "sphere SV",
                    both(sphere, StormerVerlet, rattle, &sphere_start, h),
                ),
                (
                    "sphere Euler",
                    both(sphere, SymplecticEuler, rattle, &sphere_start, h),
                ),
            ];
            for (name, worst) in cases {
                println!("{name}, rattle {rattle}, h {h}: worst / tolerance {worst:.3}");
                assert!(worst <= 1.0, "{name}, rattle {rattle}, h {h}: {worst}");
            }
            // Two to eight constraints (`geoshake::classical::fixed_m`): the
            // diagonal mass matrix's list of Jacobian terms, and a coupled
            // one's column groups.
            let double = geoshake::models::DoublePendulum::new(1.0, 0.7, 9.81);
            let coupled = CoupledRods::new(0.3);
            let chain = geoshake::models::Chain8::new(1.0, 1.0);
            let cases = [
                (
                    "double pendulum SV",
                    both(double, StormerVerlet, rattle, &double_start(), h),
                ),
                (
                    "coupled rods SV",
                    both(coupled, StormerVerlet, rattle, &double_start(), h),
                ),
                (
                    "coupled rods Euler",
                    both(coupled, SymplecticEuler, rattle, &double_start(), h),
                ),
                (
                    "chain of 8 SV",
                    both(chain, StormerVerlet, rattle, &chain_start(), h),
                ),
            ];
            // The same operations in the same order: the same bits.
            for (name, worst) in cases {
                println!("{name}, rattle {rattle}, h {h}: worst / tolerance {worst:.3}");
                assert!(worst == 0.0, "{name}, rattle {rattle}, h {h}: {worst}");
            }
        }
    }
    // A step far outside Newton's basin fails the same way on both.
    for h in [3.0, 40.0] {
        let run = |fixed: bool| {
            Integrator::new(pend, StormerVerlet, h)
                .fixed_size(fixed)
                .run(pendulum_start(), Stop::Steps(20))
                .execute()
        };
        let (a, b) = (run(true), run(false));
        let (ea, eb) = (a.error.expect("fails"), b.error.expect("fails"));
        println!("h {h}: {ea}");
        assert_eq!(
            std::mem::discriminant(&ea),
            std::mem::discriminant(&eb),
            "{ea} / {eb}"
        );
        assert_eq!((ea.step(), ea.time()), (eb.step(), eb.time()));
        assert_eq!(a.trajectory.len(), b.trajectory.len());
    }
    // The same for two constraints (`fixed_m`) and for eight (the banded
    // kernels, SHAKE's Jacobian and N on the stack against the slice
    // path's), with the multipliers the failed step leaves.
    let double = geoshake::models::DoublePendulum::new(1.0, 0.7, 9.81);
    fails_alike("double pendulum", double, &double_start(), [2.0, 40.0]);
    let chain = geoshake::models::Chain8::new(1.0, 1.0);
    fails_alike("chain of 8", chain, &chain_start(), [2.0, 40.0]);
}

/// Runs from `z0` far outside Newton's basin (step sizes `hs`) fail with
/// the same error at the same step on the fixed-size and the slice path,
/// and leave the same multipliers.
fn fails_alike<S: ConstrainedSystem + Clone>(name: &str, sys: S, z0: &State, hs: [f64; 2]) {
    for h in hs {
        let go = |fixed: bool| {
            let mut i = Integrator::new(sys.clone(), StormerVerlet, h).fixed_size(fixed);
            let out = i.run(z0.clone(), Stop::Steps(20)).execute();
            (out, i.last_multipliers().to_vec())
        };
        let ((a, la), (b, lb)) = (go(true), go(false));
        let (ea, eb) = (a.error.expect("fails"), b.error.expect("fails"));
        println!("{name}, h {h}: {ea}");
        assert_eq!(format!("{ea:?}"), format!("{eb:?}"));
        assert_eq!(a.trajectory.len(), b.trajectory.len());
        assert_eq!(la, lb, "λ left by the failed step");
    }
}
