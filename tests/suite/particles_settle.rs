//! Rigid triangles of distance constraints in closed form (SETTLE for any
//! triangle and masses) against the Newton kernel that solves the same
//! SHAKE and RATTLE equations: the same steps to round-off on water and
//! on a scalene triangle of unequal masses, bonds at round-off after every
//! step, the choice of kernel made from the stencil's declaration, and a
//! triangle that cannot be solved failing as Newton fails.

use geoshake::runtime::particles::{
    generate,
    stencils::{Distance, LinearField},
    Options, ParticleState, ParticleSystem, Rattle, Stencil, Table,
};
use geoshake::runtime::StepError;

const EPS: f64 = f64::EPSILON;

/// Newton solved to round-off: the last iterate of a quadratically
/// convergent Newton from a residual ≤ 1e-14 (which it reaches from
/// ~1e-7) is off the solution by the rounding of the iterate alone.
const TIGHT: f64 = 1e-14;

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// The largest | |x_a − x_b| − l | / l over every member of every family.
fn bond_error(system: &ParticleSystem, q: &[f64]) -> f64 {
    let mut worst = 0.0f64;
    for fam in system.constraint_families() {
        let t = fam.table();
        for k in 0..t.len() {
            let (a, b) = (t.particles(k)[0] as usize, t.particles(k)[1] as usize);
            let r: f64 = (0..3)
                .map(|c| (q[3 * a + c] - q[3 * b + c]).powi(2))
                .sum::<f64>()
                .sqrt();
            let l = t.data(k)[0];
            worst = worst.max(((r - l) / l).abs());
        }
    }
    worst
}

/// Two solvers of `system` (closed form, Newton), from one state on M^H
/// (projected by Newton), at `kelvin` when given.
fn pair(
    system: impl Fn() -> (ParticleSystem, ParticleState),
    h: f64,
    tol: f64,
    kelvin: Option<f64>,
) -> (Rattle, Rattle, ParticleState) {
    let options = Options {
        tol,
        ..Options::default()
    };
    let (s, mut state) = system();
    let closed = Rattle::new(s, h, options).unwrap();
    assert!(closed.closed_form_clusters());
    let mut newton = Rattle::new(system().0, h, options).unwrap();
    newton.use_newton_cluster_kernel();
    assert!(!newton.closed_form_clusters());
    newton.project(&mut state).unwrap();
    if let Some(kelvin) = kelvin {
        generate::set_temperature(newton.system(), &mut state, kelvin);
    }
    (closed, newton, state)
}

/// Steps both solvers from `state` and compares every step. The
/// difference of one step is the rounding of the two solves: positions to
/// a few ulps of |q| times the condition of the 3×3 SHAKE Jacobian (≲ 10
/// for these triangles), so 64 ε |q|; momenta p½ = p̃ − G(q0)ᵀ ν / h carry
/// m/h times that, and the projection adds a few ε |p|. Over a run the
/// differences of the steps add up (free rigid bodies do not amplify them
/// exponentially over so few steps), so the bound grows with k.
fn same_steps(closed: &mut Rattle, newton: &mut Rattle, state: &ParticleState, steps: u64) {
    let (mut a, mut b) = (state.clone(), state.clone());
    let h = closed.step_size();
    let m_max = max_abs(closed.system().masses());
    let (mut worst_q, mut worst_p) = (0.0f64, 0.0f64);
    for k in 1..=steps {
        let ia = closed.step(&mut a).unwrap();
        let ib = newton.step(&mut b).unwrap();
        assert_eq!(ia.shake_iterations, 0, "the closed form does not iterate");
        assert!(ib.shake_iterations >= 1);
        let (qs, ps) = (max_abs(b.q()), max_abs(b.p()));
        let bq = 64.0 * EPS * qs * k as f64;
        let bp = 64.0 * EPS * (qs * m_max / h + ps) * k as f64;
        for (i, (x, y)) in a.q().iter().zip(b.q()).enumerate() {
            assert!(
                (x - y).abs() <= bq,
                "step {k}, q[{i}]: {x} vs {y} (bound {bq:e})"
            );
            worst_q = worst_q.max((x - y).abs() / (EPS * qs));
        }
        for (i, (x, y)) in a.p().iter().zip(b.p()).enumerate() {
            assert!(
                (x - y).abs() <= bp,
                "step {k}, p[{i}]: {x} vs {y} (bound {bp:e})"
            );
            worst_p = worst_p.max((x - y).abs() / (EPS * (qs * m_max / h + ps)));
        }
        assert!(bond_error(closed.system(), a.q()) <= 1e-12);
    }
    eprintln!("closed form vs Newton over {steps} steps: q {worst_q:.1} ε|q|, p {worst_p:.1} ε(|q|m/h + |p|)");
}

#[test]
fn closed_form_and_newton_take_the_same_steps_on_water() {
    let (mut closed, mut newton, state) =
        pair(|| generate::water(125, 3).unwrap(), 2.0, TIGHT, Some(300.0));
    same_steps(&mut closed, &mut newton, &state, 20);
}

/// n scalene triangles (lengths 1.0, 1.3, 0.8; masses 7, 0.3, 12), their
/// members listed in a different order and orientation in every
/// triangle, randomly oriented at random places in a box of 20, random
/// momenta; with `field`, a uniform field too (the velocity stage is then
/// a pass of its own).
fn scalene<S: Stencil + 'static>(
    stencil: S,
    n: usize,
    field: bool,
) -> (ParticleSystem, ParticleState) {
    let d = [1.0, 1.3, 0.8];
    let masses = [7.0, 0.3, 12.0];
    let orders: [[(usize, usize, usize); 3]; 3] = [
        [(0, 1, 0), (0, 2, 1), (1, 2, 2)],
        [(2, 1, 2), (0, 2, 1), (1, 0, 0)],
        [(2, 0, 1), (1, 2, 2), (0, 1, 0)],
    ];
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut rnd = move || {
        seed ^= seed >> 12;
        seed ^= seed << 25;
        seed ^= seed >> 27;
        (seed.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    };
    let px = (d[0] * d[0] + d[1] * d[1] - d[2] * d[2]) / (2.0 * d[0]);
    let py = f64::sqrt(d[1] * d[1] - px * px);
    let body = [[0.0, 0.0], [d[0], 0.0], [px, py]];
    let (mut q, mut p, mut m) = (Vec::new(), Vec::new(), Vec::new());
    let mut bonds = Table::new(2, 1);
    let mut gravity = Table::new(1, 3);
    for t in 0..n {
        let u: [f64; 3] = std::array::from_fn(|_| rnd());
        let nu = u.iter().map(|x| x * x).sum::<f64>().sqrt();
        let u = u.map(|x| x / nu);
        let v: [f64; 3] = std::array::from_fn(|_| rnd());
        let uv: f64 = (0..3).map(|c| u[c] * v[c]).sum();
        let v: [f64; 3] = std::array::from_fn(|c| v[c] - uv * u[c]);
        let nv = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let v = v.map(|x| x / nv);
        let at: [f64; 3] = std::array::from_fn(|_| 10.0 + 10.0 * rnd());
        for (a, b) in body.iter().enumerate() {
            for c in 0..3 {
                q.push(at[c] + b[0] * u[c] + b[1] * v[c]);
                p.push(masses[a] * 0.2 * rnd());
            }
            m.push(masses[a]);
            gravity
                .push(&[3 * t + a], &[0.0, 0.0, 1e-3 * masses[a]])
                .unwrap();
        }
        for &(i, j, k) in &orders[t % 3] {
            bonds.push(&[3 * t + i, 3 * t + j], &[d[k]]).unwrap();
        }
    }
    let mut system = ParticleSystem::new(3, m)
        .unwrap()
        .with_constraints("triangle", stencil, bonds)
        .unwrap();
    if field {
        system = system
            .with_potential("field", LinearField::<3>, gravity)
            .unwrap();
    }
    (system, ParticleState::new(q, p))
}

#[test]
fn closed_form_and_newton_take_the_same_steps_on_a_scalene_triangle_of_unequal_masses() {
    for field in [false, true] {
        let (mut closed, mut newton, state) =
            pair(|| scalene(Distance::<3>, 40, field), 0.5, TIGHT, None);
        // Velocities up to 0.2 at h = 0.5: moves of up to 10 % of a bond
        // per step, not a vanishing step.
        same_steps(&mut closed, &mut newton, &state, 20);
    }
}

#[test]
fn bonds_are_at_round_off_after_every_step() {
    let (system, mut state) = generate::water(1000, 1).unwrap();
    let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    assert!(rattle.closed_form_clusters());
    rattle.project(&mut state).unwrap();
    generate::set_temperature(rattle.system(), &mut state, 300.0);
    let mut worst = 0.0f64;
    for _ in 0..50 {
        let info = rattle.step(&mut state).unwrap();
        let e = bond_error(rattle.system(), state.q());
        assert!(e <= 1e-12, "bond error {e:e}");
        assert!(info.residual.unwrap() <= 1e-12, "{info:?}");
        assert!(info.hidden.unwrap() <= 1e-12, "{info:?}");
        worst = worst.max(e);
    }
    eprintln!("largest relative bond error over 50 steps: {worst:e}");
}

/// A distance written by a user, declared as such, and the same function
/// not declared: the declaration alone chooses the closed form.
struct MyBond<const DECLARED: bool>;

impl<const DECLARED: bool> Stencil for MyBond<DECLARED> {
    const ARITY: usize = 2;
    const DIM: usize = 3;
    const DATA: usize = 1;
    const DISTANCE: bool = DECLARED;
    fn value(&self, x: &[f64], c: &[f64]) -> f64 {
        (0..3).map(|k| (x[k] - x[3 + k]).powi(2)).sum::<f64>() - c[0] * c[0]
    }
    fn gradient(&self, x: &[f64], c: &[f64], g: &mut [f64]) -> f64 {
        for k in 0..3 {
            let r = x[k] - x[3 + k];
            g[k] = 2.0 * r;
            g[3 + k] = -2.0 * r;
        }
        self.value(x, c)
    }
}

#[test]
fn a_declared_distance_gets_the_closed_form_and_an_undeclared_one_newton() {
    let (s, _) = scalene(MyBond::<true>, 3, false);
    assert!(Rattle::new(s, 0.5, Options::default())
        .unwrap()
        .closed_form_clusters());
    let (s, _) = scalene(MyBond::<false>, 3, false);
    assert!(!Rattle::new(s, 0.5, Options::default())
        .unwrap()
        .closed_form_clusters());
    // Two bonds of a triangle are no triangle: Newton.
    let mut bonds = Table::new(2, 1);
    bonds.push(&[0, 1], &[1.0]).unwrap();
    bonds.push(&[1, 2], &[1.0]).unwrap();
    let s = ParticleSystem::new(3, vec![1.0; 3])
        .unwrap()
        .with_constraints("bent", Distance::<3>, bonds)
        .unwrap();
    assert!(!Rattle::new(s, 0.5, Options::default())
        .unwrap()
        .closed_form_clusters());
}

/// The error of a step of each solver from `state`, with its message.
fn both_fail(closed: &mut Rattle, newton: &mut Rattle, state: &ParticleState) -> StepError {
    let (mut a, mut b) = (state.clone(), state.clone());
    let ea = closed.step(&mut a).unwrap_err();
    let eb = newton.step(&mut b).unwrap_err();
    assert_eq!(format!("{ea:?}"), format!("{eb:?}"));
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(
        bits(a.q()),
        bits(state.q()),
        "a failed step leaves the state"
    );
    ea
}

/// One triangle on particles of masses 2, 1, 3 with the given lengths of
/// the pairs (0,1), (0,2), (1,2), and the closed form and Newton for it.
fn one_triangle(lengths: [f64; 3]) -> (Rattle, Rattle) {
    let system = || {
        let mut bonds = Table::new(2, 1);
        bonds.push(&[0, 1], &[lengths[0]]).unwrap();
        bonds.push(&[0, 2], &[lengths[1]]).unwrap();
        bonds.push(&[1, 2], &[lengths[2]]).unwrap();
        ParticleSystem::new(3, vec![2.0, 1.0, 3.0])
            .unwrap()
            .with_constraints("triangle", Distance::<3>, bonds)
            .unwrap()
    };
    let closed = Rattle::new(system(), 0.1, Options::default()).unwrap();
    assert!(closed.closed_form_clusters());
    let mut newton = Rattle::new(system(), 0.1, Options::default()).unwrap();
    newton.use_newton_cluster_kernel();
    (closed, newton)
}

#[test]
fn a_triangle_that_cannot_be_solved_fails_as_newton_fails() {
    // A collapsed triangle: lengths (1, 2, 1), the particles on a line
    // (on M), moving across it. G(q0) has rank 2: the forces along the
    // line cannot undo the motion across it, and there is no solution.
    let (mut closed, mut newton) = one_triangle([1.0, 2.0, 1.0]);
    let line = ParticleState::new(
        vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0],
        vec![0.0, 0.3, 0.0, 0.0, 0.0, 0.1, 0.0, -0.2, 0.0],
    );
    let e = both_fail(&mut closed, &mut newton, &line);
    assert!(matches!(e, StepError::AtMember { .. }), "{e:?}");
    // A proper triangle collapsed to a line or to a point, projected onto
    // M (x̃ = q0): the old bonds span a line or nothing.
    let (mut closed, mut newton) = one_triangle([1.0, 1.2, 0.9]);
    for q in [
        vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0],
        vec![0.5; 9],
    ] {
        let start = ParticleState::new(q, vec![0.0; 9]);
        let (mut a, mut b) = (start.clone(), start.clone());
        let ea = closed.project(&mut a).unwrap_err();
        let eb = newton.project(&mut b).unwrap_err();
        assert_eq!(format!("{ea:?}"), format!("{eb:?}"));
        assert!(matches!(ea, StepError::AtMember { .. }), "{ea:?}");
    }
    // NaN in a position.
    let (mut closed, mut newton) = one_triangle([1.0, 1.2, 0.9]);
    let mut q = vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    q[6] = 0.0;
    q[7] = 0.9;
    q[8] = f64::NAN;
    let nan = ParticleState::new(q, vec![0.0; 9]);
    both_fail(&mut closed, &mut newton, &nan);
}

/// One step of one triangle (lengths taken from `q`, on M) by the closed
/// form and by Newton at tol 1e-14, from the same state: the same x1 to
/// 64 ε |q| (see [`same_steps`]).
fn one_step_agrees(masses: [f64; 3], q: [f64; 9], p: [f64; 9], h: f64) {
    let len = |a: usize, b: usize| {
        (0..3)
            .map(|c| (q[3 * a + c] - q[3 * b + c]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let system = || {
        let mut bonds = Table::new(2, 1);
        for (a, b) in [(0, 1), (0, 2), (1, 2)] {
            bonds.push(&[a, b], &[len(a, b)]).unwrap();
        }
        ParticleSystem::new(3, masses.to_vec())
            .unwrap()
            .with_constraints("triangle", Distance::<3>, bonds)
            .unwrap()
    };
    let options = Options {
        tol: TIGHT,
        ..Options::default()
    };
    let mut closed = Rattle::new(system(), h, options).unwrap();
    let mut newton = Rattle::new(system(), h, options).unwrap();
    newton.use_newton_cluster_kernel();
    let (mut a, mut b) = (
        ParticleState::new(q.to_vec(), p.to_vec()),
        ParticleState::new(q.to_vec(), p.to_vec()),
    );
    closed.step(&mut a).unwrap();
    newton.step(&mut b).unwrap();
    let bound = 64.0 * EPS * max_abs(b.q());
    for (i, (x, y)) in a.q().iter().zip(b.q()).enumerate() {
        assert!(
            (x - y).abs() <= bound,
            "q[{i}]: {x} vs {y} (bound {bound:e})"
        );
    }
}

/// A large step of a light, flat triangle: the torque equation's branch
/// nearest θ = 0 is another SHAKE root than the one Newton reaches from x̃
/// (x1 apart by ~0.15); such a correction (beyond an eighth of the
/// shortest length) goes to Newton.
#[test]
fn a_large_step_takes_newtons_root() {
    one_step_agrees(
        [0.07228188738328177, 2.125253064589869, 0.045000519529077694],
        [
            -0.49074217624733685,
            0.577875995747042,
            0.6921001298265925,
            -0.8040992118262135,
            -0.258750446376377,
            -0.30056162837400857,
            -0.44924615918385435,
            -1.1421204390598918,
            -0.985153408720042,
        ],
        [
            -0.1843436215520919,
            -0.24642343249551954,
            0.2359847594874155,
            7.114971092189642,
            3.0625558905878356,
            3.5407088698836273,
            -0.12131311230156414,
            0.12548191667210604,
            0.03069608011634044,
        ],
        0.1,
    );
}

/// Masses 10⁶ apart: the rigid placement would leave the light particle
/// ~ε √(10⁶) |x| out of the old plane (Newton: on it); such a triangle
/// goes to Newton.
#[test]
fn extreme_mass_ratios_take_newtons_step() {
    let q = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.4, 0.7, 0.0];
    let p = [0.01, -0.02, 0.03, 0.0, 0.0, 0.0, -0.02, 0.01, 0.015];
    for masses in [[1.0, 1e-6, 1.0], [1e-6, 1.0, 1e6]] {
        let p: Vec<f64> = p
            .iter()
            .enumerate()
            .map(|(i, v)| v * masses[i / 3])
            .collect();
        one_step_agrees(masses, q, p.try_into().unwrap(), 0.1);
    }
}
