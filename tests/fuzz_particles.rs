//! Fuzzing the particle path (`geoshake::runtime::particles`) with hostile
//! values: the topology (dimers, chains, waters, rings, triangles with
//! lengths such as 1, 1, 2; indices out of range, self-bonds, duplicate
//! members, a stencil of the wrong dimension, a mass list of the wrong
//! length), the masses and bond lengths (0, negative, NaN, ±∞, 10^±300,
//! subnormal), the state (on M, near, far, zero, non-finite, wrong
//! lengths), h, the start time, the stop rule, the stride, the options
//! (tolerance, iteration budget, SHAKE or RATTLE, every solver), a Langevin
//! thermostat and an external force, over every entry point: `step`,
//! `project`, `run`, `run_in_place`, `shake_positions`, `project_momenta`,
//! `constraint_forces` and `potential_energy`.
//!
//! Every case must end in one of two ways:
//! - `Ok`, with finite numbers, every bond of a state the call put on M
//!   within | |r| − |l| | / |l| ≤ 2·max(tol, floor) + 16ε of its length
//!   (the solvers' residual |g| / (|∇g| · extent) is that ratio to first
//!   order, measured at the state returned: `tolerance::inverse_scale`;
//!   floor = min(4ε ‖(x_i, x_j)‖ / extent, √ε), the round-off of the
//!   bond's coordinates, at which a stalled solve is accepted:
//!   `tolerance::roundoff_floor`), for RATTLE and
//!   the projections the hidden constraint |∇g · M⁻¹p| within 4·√ε of
//!   |∇g| times the larger of the member's velocity |M⁻¹p| returned and
//!   the one given, or for a step the one its velocity stage started from
//!   (the limit `tolerance::HIDDEN_LIMIT` puts on the exact solve of N,
//!   with the velocity it started from as its scale; momenta near the
//!   subnormal range are not judged), and every time t0 + k·h;
//! - a typed error (`TopologyError` when the system is declared,
//!   `StepError` after) with a consistent partial trajectory: an error at
//!   step k carries t0 + k·h and the last stored state is step k − 1;
//!   `shake_positions`, `project_momenta` and `step` leave their input as
//!   it was.
//!
//! Anything else is a *silent* wrong number, a *panic* or a *hang*
//! (the driver in `common::fuzz`, as for `tests/fuzz_api.rs`).
//!
//! Modes: `fuzz_particles_ci` runs [`CI_CASES`] cases in the ordinary test
//! run; `fuzz_particles_long` (ignored) runs `SHAKE_FUZZ_CASES` cases
//! (default 10⁵):
//! `SHAKE_FUZZ_CASES=100000 cargo test --release --test fuzz_particles -- --ignored --nocapture`.
//! The seed is `SHAKE_FUZZ_SEED` (default 13).

// A NaN must fail every bound: the negated comparisons are the point.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use geoshake_testkit as common;

use common::fuzz::{
    assert_clean, env_u64, fuzz_cases, hostile, judge_end, step_error_kind, Verdict,
};
use geoshake::runtime::particles::{
    stencils::Distance, ConstraintForces, Langevin, Method, Options, ParticleState, ParticleSystem,
    Rattle, SolverChoice, Table, TopologyError,
};
use geoshake::{StepError, Stop};
use proptest::prelude::*;
use std::time::Duration;

/// Cases of the CI run.
const CI_CASES: u64 = 10_000;
/// The systems have at most a few dozen particles and runs at most a few
/// hundred steps: an answer takes milliseconds.
const DEADLINE: Duration = Duration::from_secs(5);
/// `tolerance::HIDDEN_LIMIT`, √ε.
const HIDDEN_LIMIT: f64 = 1.4901161193847656e-8;

// ---------------------------------------------------------------------------
// Cases
// ---------------------------------------------------------------------------

#[derive(Clone, Debug)]
enum Shape {
    Dimers(usize),
    Chain(usize),
    /// Rigid waters: O–H, O–H, H–H.
    Waters(usize),
    Ring(usize),
    /// A triangle with the given side lengths (1, 1, 2 is degenerate); its
    /// start is an equilateral triangle of side 1.
    Triangle(f64, f64, f64),
}

#[derive(Clone, Debug)]
enum Corrupt {
    None,
    /// A bond to particle n + k.
    OutOfRange(usize),
    SelfBond,
    Duplicate,
    /// `Distance<2>` on particles in R³ or the other way round.
    WrongDim,
    /// The mass list one particle short or one too long.
    MassCount(bool),
    /// One bond's length replaced.
    Length(f64),
    /// One particle's mass replaced.
    Mass(f64),
}

#[derive(Clone, Debug)]
enum Start {
    /// The geometry the bond lengths were measured from.
    OnM,
    /// Moved by a relative amount in a seeded direction.
    Near(f64),
    /// Every position times 10³ or 10⁶.
    Far(f64),
    Zero,
    /// One entry of z = (q, p) replaced.
    NonFinite(usize, f64),
    /// q and p lengthened (or shortened) by these many entries.
    WrongLength(i8, i8),
}

#[derive(Clone, Debug)]
enum StopRule {
    Steps(u64),
    /// n steps' worth of time, perturbed relatively by δ.
    NearSteps(u64, f64),
    Time(f64),
}

#[derive(Clone, Debug)]
enum Op {
    Step(u8),
    Project,
    Run {
        stop: StopRule,
        stride: u64,
        t0: f64,
    },
    RunInPlace(u64),
    /// New positions q + ε·|q|∞·(seeded direction).
    ShakePositions(f64),
    ProjectMomenta,
    /// A step, then its constraint forces and virial.
    ConstraintForces,
    PotentialEnergy,
}

#[derive(Clone, Debug)]
struct Thermostat {
    gamma: f64,
    kt: f64,
    seed: u64,
    substeps: usize,
}

#[derive(Clone, Debug)]
struct Case {
    dim: usize,
    shape: Shape,
    corrupt: Corrupt,
    /// Every bond length (and position) scaled by this.
    scale: f64,
    heavy: f64,
    light: f64,
    h: f64,
    options: Options,
    thermostat: Option<Thermostat>,
    /// A uniform external field along the last axis.
    field: Option<f64>,
    momentum: f64,
    seed: u64,
    start: Start,
    /// Project the start before the operation (an error there is its
    /// verdict).
    project_first: bool,
    op: Op,
}

fn shape_strategy() -> impl Strategy<Value = Shape> {
    let tri = || {
        prop_oneof![
            3 => Just(1.0),
            1 => Just(2.0),
            1 => hostile(0.5..2.0),
        ]
    };
    prop_oneof![
        (1usize..4).prop_map(Shape::Dimers),
        (1usize..12).prop_map(Shape::Chain),
        (1usize..4).prop_map(Shape::Waters),
        (3usize..10).prop_map(Shape::Ring),
        (tri(), tri(), tri()).prop_map(|(a, b, c)| Shape::Triangle(a, b, c)),
    ]
}

fn corrupt_strategy() -> impl Strategy<Value = Corrupt> {
    prop_oneof![
        12 => Just(Corrupt::None),
        1 => (0usize..3).prop_map(Corrupt::OutOfRange),
        1 => Just(Corrupt::SelfBond),
        1 => Just(Corrupt::Duplicate),
        1 => Just(Corrupt::WrongDim),
        1 => any::<bool>().prop_map(Corrupt::MassCount),
        2 => hostile(0.5..2.0).prop_map(Corrupt::Length),
        2 => hostile(0.5..20.0).prop_map(Corrupt::Mass),
    ]
}

fn start_strategy() -> impl Strategy<Value = Start> {
    prop_oneof![
        8 => Just(Start::OnM),
        3 => hostile(1e-12..1e-3).prop_map(Start::Near),
        1 => prop::sample::select(vec![1e3, 1e6]).prop_map(Start::Far),
        1 => Just(Start::Zero),
        1 => (0usize..64, prop::sample::select(vec![f64::NAN, f64::INFINITY, -f64::INFINITY]))
            .prop_map(|(i, x)| Start::NonFinite(i, x)),
        1 => (-2i8..3, -2i8..3).prop_map(|(a, b)| Start::WrongLength(a, b)),
    ]
}

fn options_strategy() -> impl Strategy<Value = Options> {
    (
        prop::bool::weighted(0.3),
        hostile(1e-13..1e-8),
        prop_oneof![
            6 => Just(50usize),
            1 => 0usize..4,
            1 => Just(10_000usize),
            1 => Just(10_001usize),
            1 => Just(usize::MAX),
        ],
        prop::bool::weighted(0.2),
        prop::sample::select(vec![
            SolverChoice::Auto,
            SolverChoice::Clusters,
            SolverChoice::Band,
            SolverChoice::Sparse,
        ]),
    )
        .prop_map(|(default, tol, max_iter, shake, solver)| {
            let method = if shake { Method::Shake } else { Method::Rattle };
            if default {
                return Options {
                    method,
                    solver,
                    ..Options::default()
                };
            }
            Options {
                tol,
                max_iter,
                method,
                solver,
            }
        })
}

fn thermostat_strategy() -> impl Strategy<Value = Option<Thermostat>> {
    prop::option::weighted(
        0.15,
        (
            hostile(0.0..1.0),
            hostile(0.0..1.0),
            any::<u64>(),
            prop_oneof![4 => 1usize..4, 1 => Just(0usize), 1 => Just((1usize << 20) + 1)],
        )
            .prop_map(|(gamma, kt, seed, substeps)| Thermostat {
                gamma,
                kt,
                seed,
                substeps,
            }),
    )
}

fn op_strategy() -> impl Strategy<Value = Op> {
    let stop = prop_oneof![
        3 => (0u64..30).prop_map(StopRule::Steps),
        1 => prop::sample::select(vec![u64::MAX, (1 << 53) + 1]).prop_map(StopRule::Steps),
        2 => (0u64..30, hostile(-1e-10..1e-10)).prop_map(|(n, d)| StopRule::NearSteps(n, d)),
        1 => hostile(-3.0..3.0).prop_map(StopRule::Time),
    ];
    prop_oneof![
        3 => (1u8..5).prop_map(Op::Step),
        2 => Just(Op::Project),
        4 => (
            stop,
            prop_oneof![4 => Just(1u64), 2 => 2u64..5, 1 => Just(0u64), 1 => Just(u64::MAX)],
            prop_oneof![3 => Just(0.0), 1 => hostile(-1e3..1e3)],
        )
            .prop_map(|(stop, stride, t0)| Op::Run { stop, stride, t0 }),
        1 => prop_oneof![4 => 0u64..20, 1 => Just(u64::MAX)].prop_map(Op::RunInPlace),
        2 => hostile(1e-8..1e-2).prop_map(Op::ShakePositions),
        2 => Just(Op::ProjectMomenta),
        1 => Just(Op::ConstraintForces),
        1 => Just(Op::PotentialEnergy),
    ]
}

fn case_strategy() -> impl Strategy<Value = Case> {
    (
        (
            prop::sample::select(vec![3usize, 3, 2]),
            shape_strategy(),
            corrupt_strategy(),
            hostile(0.5..2.0),
            hostile(10.0..20.0),
            hostile(0.5..2.0),
        ),
        (
            prop_oneof![
                6 => 0.005f64..0.2,
                2 => hostile(1e-14..1e-6),
                2 => hostile(-1e3..1e3),
            ],
            options_strategy(),
            thermostat_strategy(),
            prop::option::weighted(0.2, hostile(-1.0..1.0)),
        ),
        (
            hostile(0.0..1.0),
            any::<u64>(),
            start_strategy(),
            prop::bool::weighted(0.5),
            op_strategy(),
        ),
    )
        .prop_map(
            |(
                (dim, shape, corrupt, scale, heavy, light),
                (h, options, thermostat, field),
                (momentum, seed, start, project_first, op),
            )| Case {
                dim,
                shape,
                corrupt,
                scale,
                heavy,
                light,
                h,
                options,
                thermostat,
                field,
                momentum,
                seed,
                start,
                project_first,
                op,
            },
        )
}

// ---------------------------------------------------------------------------
// Systems and states
// ---------------------------------------------------------------------------

/// A fixed LCG: directions need only be arbitrary.
struct Lcg(u64);

impl Lcg {
    fn uniform(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }
    fn unit(&mut self, d: usize) -> Vec<f64> {
        let v: Vec<f64> = (0..d).map(|_| self.uniform()).collect();
        let n = v.iter().map(|a| a * a).sum::<f64>().sqrt().max(1e-300);
        v.into_iter().map(|a| a / n).collect()
    }
}

/// Particles, masses, bonds (i, j, l) and the positions the lengths were
/// measured from (before corruption).
struct Built {
    dim: usize,
    masses: Vec<f64>,
    bonds: Vec<(usize, usize, f64)>,
    q: Vec<f64>,
    p: Vec<f64>,
}

fn dist(q: &[f64], d: usize, i: usize, j: usize) -> f64 {
    (0..d)
        .map(|c| (q[i * d + c] - q[j * d + c]).powi(2))
        .sum::<f64>()
        .sqrt()
}

fn build(case: &Case) -> Built {
    let d = case.dim;
    let mut rng = Lcg(case.seed | 1);
    let mut q: Vec<f64> = Vec::new();
    let mut masses: Vec<f64> = Vec::new();
    let mut bonds: Vec<(usize, usize, f64)> = Vec::new();
    let s = case.scale;
    let add = |q: &mut Vec<f64>, x: Vec<f64>| q.extend(x);
    match case.shape {
        Shape::Dimers(k) => {
            for a in 0..k {
                let o: Vec<f64> = (0..d).map(|c| s * (3.0 * a as f64 + c as f64)).collect();
                let u = rng.unit(d);
                add(&mut q, o.clone());
                add(&mut q, o.iter().zip(&u).map(|(o, u)| o + s * u).collect());
                masses.extend([case.heavy, case.light]);
                bonds.push((2 * a, 2 * a + 1, 0.0));
            }
        }
        Shape::Chain(links) => {
            let mut x = vec![0.0; d];
            add(&mut q, x.clone());
            masses.push(case.heavy);
            for a in 0..links {
                let u = rng.unit(d);
                x.iter_mut().zip(&u).for_each(|(x, u)| *x += s * u);
                add(&mut q, x.clone());
                masses.push(if a % 2 == 0 { case.light } else { case.heavy });
                bonds.push((a, a + 1, 0.0));
            }
        }
        Shape::Waters(k) => {
            for w in 0..k {
                let o: Vec<f64> = (0..d).map(|c| s * (4.0 * w as f64 + c as f64)).collect();
                let (a, b) = (rng.unit(d), rng.unit(d));
                add(&mut q, o.clone());
                add(&mut q, o.iter().zip(&a).map(|(o, u)| o + s * u).collect());
                add(&mut q, o.iter().zip(&b).map(|(o, u)| o + s * u).collect());
                masses.extend([case.heavy, case.light, case.light]);
                let n = 3 * w;
                bonds.extend([(n, n + 1, 0.0), (n, n + 2, 0.0), (n + 1, n + 2, 0.0)]);
            }
        }
        Shape::Ring(k) => {
            for a in 0..k {
                let phi = 2.0 * std::f64::consts::PI * a as f64 / k as f64;
                let mut x = vec![0.0; d];
                x[0] = s * phi.cos();
                x[1] = s * phi.sin();
                if d > 2 {
                    x[2] = 0.1 * s * rng.uniform();
                }
                add(&mut q, x);
                masses.push(if a % 2 == 0 { case.heavy } else { case.light });
                bonds.push((a, (a + 1) % k, 0.0));
            }
        }
        Shape::Triangle(..) => {
            let r = 3f64.sqrt() / 2.0;
            for (x, y) in [(0.0, 0.0), (s, 0.0), (0.5 * s, r * s)] {
                let mut v = vec![0.0; d];
                v[0] = x;
                v[1] = y;
                add(&mut q, v);
            }
            masses.extend([case.heavy, case.light, case.light]);
            bonds.extend([(0, 1, 0.0), (1, 2, 0.0), (0, 2, 0.0)]);
        }
    }
    for b in bonds.iter_mut() {
        b.2 = dist(&q, d, b.0, b.1);
    }
    if let Shape::Triangle(a, b, c) = case.shape {
        for (bond, l) in bonds.iter_mut().zip([a, b, c]) {
            bond.2 = s * l;
        }
    }
    let n = masses.len();
    let p: Vec<f64> = (0..n * d)
        .map(|_| case.momentum * 2.0 * rng.uniform())
        .collect();
    match case.corrupt {
        Corrupt::OutOfRange(k) => bonds.push((0, n + k, s)),
        Corrupt::SelfBond => bonds.push((1, 1, s)),
        Corrupt::Duplicate => bonds.push(bonds[0]),
        Corrupt::Length(l) => {
            let i = (case.seed % bonds.len() as u64) as usize;
            bonds[i].2 = l;
        }
        Corrupt::Mass(m) => {
            let i = (case.seed % n as u64) as usize;
            masses[i] = m;
        }
        Corrupt::MassCount(longer) => {
            if longer {
                masses.push(1.0);
            } else {
                masses.pop();
            }
        }
        Corrupt::None | Corrupt::WrongDim => {}
    }
    Built {
        dim: d,
        masses,
        bonds,
        q,
        p,
    }
}

fn system(case: &Case, b: &Built) -> Result<ParticleSystem, TopologyError> {
    let mut table = Table::new(2, 1);
    for &(i, j, l) in &b.bonds {
        table.push(&[i, j], &[l])?;
    }
    let sys = ParticleSystem::new(b.dim, b.masses.clone())?;
    let wrong = matches!(case.corrupt, Corrupt::WrongDim);
    let sys = match (b.dim == 3) != wrong {
        true => sys.with_constraints("bond", Distance::<3>, table)?,
        false => sys.with_constraints("bond", Distance::<2>, table)?,
    };
    Ok(match case.field {
        None => sys,
        Some(g) => {
            let (d, masses) = (b.dim, b.masses.clone());
            // V = g Σ_a m_a x_a[D−1], F = −∇V.
            sys.with_forces(move |q: &[f64], f: &mut [f64]| {
                let mut v = 0.0;
                for (a, m) in masses.iter().enumerate().take(q.len() / d) {
                    f[a * d + d - 1] -= g * m;
                    v += g * m * q[a * d + d - 1];
                }
                v
            })
        }
    })
}

fn start(case: &Case, b: &Built) -> ParticleState {
    let (mut q, mut p) = (b.q.clone(), b.p.clone());
    match case.start {
        Start::OnM => {}
        Start::Near(eps) => {
            let scale = q.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            let dir = Lcg(case.seed ^ 0x5555).unit(q.len());
            q.iter_mut()
                .zip(&dir)
                .for_each(|(q, u)| *q += eps * scale * u);
        }
        Start::Far(f) => q.iter_mut().for_each(|q| *q *= f),
        Start::Zero => {
            q.fill(0.0);
            p.fill(0.0);
        }
        Start::NonFinite(i, x) => {
            let i = i % (q.len() + p.len());
            if i < q.len() {
                q[i] = x;
            } else {
                p[i - q.len()] = x;
            }
        }
        Start::WrongLength(a, c) => {
            let resize = |v: &mut Vec<f64>, k: i8| {
                let n = (v.len() as isize + k as isize).max(0) as usize;
                v.resize(n, 0.5);
            };
            resize(&mut q, a);
            resize(&mut p, c);
        }
    }
    ParticleState::new(q, p)
}

// ---------------------------------------------------------------------------
// The contract
// ---------------------------------------------------------------------------

/// The same numbers bit for bit (NaN included), step and time.
fn same(a: &ParticleState, b: &ParticleState) -> bool {
    let bits = |x: &[f64], y: &[f64]| {
        x.len() == y.len() && x.iter().zip(y).all(|(x, y)| x.to_bits() == y.to_bits())
    };
    bits(a.q(), b.q())
        && bits(a.p(), b.p())
        && a.step() == b.step()
        && a.time().to_bits() == b.time().to_bits()
}

fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// `None` when every bond of q is within 2·max(tol, floor) + 16ε of its
/// length (relative; floor the round-off of its coordinates, see the
/// module docs), else which is not.
fn off_m(b: &Built, tol: f64, q: &[f64]) -> Option<String> {
    if !finite(q) {
        return Some("non-finite positions".into());
    }
    let d = b.dim;
    for &(i, j, l) in &b.bonds {
        // Relative to the length, computed apart so that nothing
        // overflows: | |r| − |l| | / |l|.
        let r = dist(q, d, i, j);
        let l = l.abs();
        let rel = if l == 0.0 && r == 0.0 {
            0.0
        } else {
            (r - l).abs() / l
        };
        // The coordinates' round-off: 4ε ‖(x_i, x_j)‖ / extent, extent =
        // |r| / √2 for a pair, at most √ε (as `tolerance::roundoff_floor`).
        let n2: f64 = (0..d)
            .map(|c| q[i * d + c].powi(2) + q[j * d + c].powi(2))
            .sum();
        let floor = (4.0 * f64::EPSILON * (2.0 * n2).sqrt() / r).min(f64::EPSILON.sqrt());
        let floor = if floor.is_nan() { 0.0 } else { floor };
        if !(rel <= 2.0 * tol.max(floor) + 16.0 * f64::EPSILON) {
            return Some(format!(
                "bond ({i}, {j}) of length {l:e}: | |r| − l | / l = {rel:.2e} > 2·max(tol, floor), tol = {tol:e}, floor = {floor:e}"
            ));
        }
    }
    None
}

/// The member's velocities (v_i, v_j), each momentum scaled by `s` first.
fn velocities(b: &Built, p: &[f64], i: usize, j: usize, s: f64) -> Vec<f64> {
    let d = b.dim;
    (0..d)
        .map(|c| p[i * d + c] / s / b.masses[i])
        .chain((0..d).map(|c| p[j * d + c] / s / b.masses[j]))
        .collect()
}

/// `None` when every bond's hidden constraint, relative to its scale as
/// the solvers measure it, |∇g · M⁻¹p| / (|∇g| · max(|M⁻¹p|, |M⁻¹p_in|))
/// over the member's particles, is within 4√ε, else which bond is not.
/// `p_in` is the velocity the call started from. Momenta within 2⁵² of
/// the subnormal range hold too few bits for a relative test (5e-324 has
/// one), and velocities that overflow are not judged (the momenta
/// themselves are checked finite).
fn off_hidden(b: &Built, q: &[f64], p: &[f64], p_in: &[f64]) -> Option<String> {
    if !finite(p) {
        return Some("non-finite momenta".into());
    }
    let d = b.dim;
    let pmax = p
        .iter()
        .chain(p_in.iter().filter(|x| x.is_finite()))
        .fold(0.0f64, |m, x| m.max(x.abs()));
    if pmax < f64::MIN_POSITIVE / f64::EPSILON {
        return None;
    }
    let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
    for &(i, j, _) in &b.bonds {
        let r: Vec<f64> = (0..d).map(|c| q[i * d + c] - q[j * d + c]).collect();
        let rn = norm(&r);
        let v = velocities(b, p, i, j, pmax);
        let scale = if p_in.len() == p.len() && finite(p_in) {
            norm(&v).max(norm(&velocities(b, p_in, i, j, pmax)))
        } else {
            norm(&v)
        };
        if !(rn > 0.0 && scale > 0.0 && scale.is_finite() && rn.is_finite()) {
            continue;
        }
        // ∇g = 2(r, −r): |∇g · (v_i, v_j)| / |∇g| = |r · (v_i − v_j)| / (√2 |r|).
        let dot: f64 = (0..d).map(|c| r[c] / rn * (v[c] - v[d + c])).sum();
        let rel = dot.abs() / (std::f64::consts::SQRT_2 * scale);
        if !(rel <= 4.0 * HIDDEN_LIMIT) {
            return Some(format!("bond ({i}, {j}): hidden residual {rel:.2e} > 4√ε"));
        }
    }
    None
}

/// The momenta p′ the velocity stage of a step from q0 to q1 started from
/// (its scale): p½ = M (q1 − q0) / h less the closing kick of the field.
fn p_before_velocity_stage(case: &Case, b: &Built, q0: &[f64], q1: &[f64]) -> Vec<f64> {
    let d = b.dim;
    if q0.len() != q1.len() || b.masses.len() * d != q1.len() {
        return Vec::new();
    }
    let g = case.field.unwrap_or(0.0);
    (0..q1.len())
        .map(|i| {
            let m = b.masses[i / d];
            let kick = if i % d == d - 1 {
                0.5 * case.h * g * m
            } else {
                0.0
            };
            m * (q1[i] - q0[i]) / case.h - kick
        })
        .collect()
}

/// [`off_hidden`] against the larger of the starting velocities: the
/// state's before the call, p′ of a step from `q0` rebuilt from the
/// positions, and, when those do not hold it, p′ rebuilt from the step's
/// multipliers (`p_prime`, asked for only then).
///
/// M (q1 − q0) / h loses p′ wherever a particle's displacement h M⁻¹p′ is
/// below the rounding of its position (a hydrogen of 1e45 moves 1e-43 in a
/// step, q1 = q0 in f64) or M (q1 − q0) overflows (a mass of f64::MAX): the
/// rebuilt scale is then the velocity before the step, and a projection
/// that cancelled a velocity the position stage had just given (a bond of
/// a corrupted length pulled in at the first step) read as 1 where the
/// solver's contract, relative to the velocity it started from, holds.
fn off_hidden_after_step(
    case: &Case,
    b: &Built,
    q0: &[f64],
    q: &[f64],
    p: &[f64],
    p_in: &[f64],
    p_prime: impl FnOnce() -> Option<Vec<f64>>,
) -> Option<String> {
    let why = off_hidden(b, q, p, p_in)?;
    let p1 = p_before_velocity_stage(case, b, q0, q);
    let why = if p1.len() == p.len() && finite(&p1) {
        off_hidden(b, q, p, &p1)?
    } else {
        why
    };
    match p_prime() {
        Some(p1) if p1.len() == p.len() && finite(&p1) => off_hidden(b, q, p, &p1),
        _ => Some(why),
    }
}

/// p′ = p0 − (h/2) ∇V(q0) + (h/2) f_c − (h/2) ∇V(q1) of the step from
/// `before` that made `z` (the last state `rattle` made), from its
/// constraint forces f_c = −G(q0)ᵀ Λ: the momenta its velocity stage
/// started from, whatever the positions can show of them. `None` where the
/// solver has no multipliers for `z` (a thermostat) or they overflow.
fn p_prime_from_multipliers(
    case: &Case,
    b: &Built,
    rattle: &Rattle,
    before: &ParticleState,
    z: &ParticleState,
) -> Option<Vec<f64>> {
    let mut fc = ConstraintForces::new(rattle.system());
    rattle.constraint_forces(z, &mut fc).ok()?;
    let (d, h, g) = (b.dim, case.h, case.field.unwrap_or(0.0));
    let p0 = before.p();
    (p0.len() == fc.forces.len() && b.masses.len() * d == p0.len()).then_some(())?;
    Some(
        (0..p0.len())
            .map(|i| {
                let kick = if i % d == d - 1 {
                    h * g * b.masses[i / d]
                } else {
                    0.0
                };
                p0[i] + 0.5 * h * fc.forces[i] - kick
            })
            .collect(),
    )
}

/// p′ of step `k` of a run from `start` whose state at step k is (q, p):
/// the steps replayed one by one on a new solver, which must reach the
/// same state bit for bit (`None` if not, or with a thermostat); from the
/// multipliers ([`p_prime_from_multipliers`]), or where Λ = 2ν/h²
/// overflows (h of 1e-251) from the positions of step k − 1, which a run
/// stored with a stride does not hold.
fn replay_p_prime(
    case: &Case,
    b: &Built,
    start: &ParticleState,
    k: u64,
    (q, p): (&[f64], &[f64]),
) -> Option<Vec<f64>> {
    if case.thermostat.is_some() || k <= start.step() {
        return None;
    }
    let mut rattle = Rattle::new(system(case, b).ok()?, case.h, case.options).ok()?;
    let mut z = start.clone();
    while z.step() + 1 < k {
        rattle.step(&mut z).ok()?;
    }
    let before = z.clone();
    rattle.step(&mut z).ok()?;
    let bits = |x: &[f64], y: &[f64]| {
        x.len() == y.len() && x.iter().zip(y).all(|(x, y)| x.to_bits() == y.to_bits())
    };
    (bits(z.q(), q) && bits(z.p(), p)).then_some(())?;
    p_prime_from_multipliers(case, b, &rattle, &before, &z)
        .or_else(|| Some(p_before_velocity_stage(case, b, before.q(), z.q())))
}

fn hidden_applies(case: &Case) -> bool {
    case.options.method == Method::Rattle
}

/// A state a step returned: finite, on M, on M^H for RATTLE, at t0 + k·h.
/// `p_prime`: p′ of the step that made `z` from the solver's multipliers
/// ([`off_hidden_after_step`]).
fn judge_state(
    case: &Case,
    b: &Built,
    z: &ParticleState,
    before: &ParticleState,
    t0: f64,
    p_prime: impl FnOnce() -> Option<Vec<f64>>,
) -> Verdict {
    if let Some(why) = off_m(b, case.options.tol, z.q()) {
        return Verdict::Silent(format!("Ok but {why}"));
    }
    if hidden_applies(case)
        && let Some(why) =
            off_hidden_after_step(case, b, before.q(), z.q(), z.p(), before.p(), p_prime)
    {
        return Verdict::Silent(format!("Ok but {why}"));
    }
    if !finite(z.p()) {
        return Verdict::Silent("Ok but non-finite momenta".into());
    }
    let t = t0 + z.step() as f64 * case.h;
    if z.time() != t {
        return Verdict::Silent(format!(
            "step {} at t = {} ≠ t0 + k·h = {t}",
            z.step(),
            z.time()
        ));
    }
    Verdict::Ok
}

fn typed(e: &StepError) -> Verdict {
    Verdict::Typed(step_error_kind(e))
}

fn topology_kind(e: &TopologyError) -> &'static str {
    match e {
        TopologyError::RowShape { .. } => "Topology/RowShape",
        TopologyError::RepeatedParticle { .. } => "Topology/RepeatedParticle",
        TopologyError::DanglingParticle { .. } => "Topology/DanglingParticle",
        TopologyError::DuplicateMember { .. } => "Topology/DuplicateMember",
        TopologyError::BadValue { .. } => "Topology/BadValue",
        TopologyError::TooManyConstraints { .. } => "Topology/TooManyConstraints",
        TopologyError::Dimension { .. } => "Topology/Dimension",
    }
}

fn run_case(case: &Case) -> Verdict {
    let b = build(case);
    let sys = match system(case, &b) {
        Ok(s) => s,
        Err(e) => return Verdict::Typed(topology_kind(&e)),
    };
    let mut rattle = match Rattle::new(sys, case.h, case.options) {
        Ok(r) => r,
        Err(e) => return typed(&e),
    };
    if let Some(th) = &case.thermostat {
        let l = Langevin::new(th.gamma, th.kt, th.seed).and_then(|l| l.geodesic(th.substeps));
        if let Err(e) = l.and_then(|l| rattle.set_thermostat(Some(l))) {
            return typed(&e);
        }
    }
    let mut z = start(case, &b);
    if case.project_first {
        let p_in = z.p().to_vec();
        if let Err(e) = rattle.project(&mut z) {
            return typed(&e);
        }
        if let Some(why) = off_m(&b, case.options.tol, z.q()) {
            return Verdict::Silent(format!("project: Ok but {why}"));
        }
        if let Some(why) = off_hidden(&b, z.q(), z.p(), &p_in) {
            return Verdict::Silent(format!("project: Ok but {why}"));
        }
    }
    let tol = case.options.tol;
    match &case.op {
        Op::Step(n) => {
            for _ in 0..*n {
                let before = z.clone();
                match rattle.step(&mut z) {
                    Ok(_) => {
                        let v = judge_state(case, &b, &z, &before, 0.0, || {
                            p_prime_from_multipliers(case, &b, &rattle, &before, &z)
                        });
                        if !matches!(v, Verdict::Ok) {
                            return v;
                        }
                    }
                    Err(e) => {
                        if !same(&z, &before) {
                            return Verdict::Silent(format!(
                                "step failed ({e}) but moved the state"
                            ));
                        }
                        return typed(&e);
                    }
                }
            }
            Verdict::Ok
        }
        Op::Project => {
            let p_in = z.p().to_vec();
            match rattle.project(&mut z) {
                Err(e) => typed(&e),
                Ok(_) => {
                    match off_m(&b, tol, z.q()).or_else(|| off_hidden(&b, z.q(), z.p(), &p_in)) {
                        None => Verdict::Ok,
                        Some(why) => Verdict::Silent(format!("project: Ok but {why}")),
                    }
                }
            }
        }
        Op::Run { stop, stride, t0 } => judge_run(case, &b, &mut rattle, z, stop, *stride, *t0),
        Op::RunInPlace(steps) => {
            let before = z.clone();
            let out = rattle.run_in_place(&mut z, *steps);
            match &out.error {
                None => {
                    if z.step() != before.step() + steps {
                        return Verdict::Silent(format!(
                            "run_in_place({steps}) Ok but the state is at step {}",
                            z.step()
                        ));
                    }
                    if *steps == 0 {
                        return Verdict::Ok;
                    }
                    judge_state(case, &b, &z, &before, 0.0, || {
                        replay_p_prime(case, &b, &before, z.step(), (z.q(), z.p()))
                    })
                }
                Some(e) => {
                    // The state is the last good one: step k − 1.
                    let k = e.step();
                    if k >= 1 && z.step() + 1 != k && !same(&z, &before) {
                        return Verdict::Silent(format!(
                            "run_in_place failed at step {k} ({e}) but left the state at step {}",
                            z.step()
                        ));
                    }
                    if z.step() > 0
                        && let Verdict::Silent(why) =
                            judge_state(case, &b, &z, &before, 0.0, || {
                                replay_p_prime(case, &b, &before, z.step(), (z.q(), z.p()))
                            })
                    {
                        return Verdict::Silent(format!("run_in_place's last good state: {why}"));
                    }
                    typed(e)
                }
            }
        }
        Op::ShakePositions(eps) => {
            let q0 = z.q().to_vec();
            let scale = q0.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            let dir = Lcg(case.seed ^ 0x7777).unit(q0.len().max(1));
            let mut x: Vec<f64> = q0
                .iter()
                .zip(dir.iter().cycle())
                .map(|(q, u)| q + eps * scale * u)
                .collect();
            let given = x.clone();
            match rattle.shake_positions(&q0, &mut x) {
                Err(e) => {
                    if !(x
                        .iter()
                        .zip(&given)
                        .all(|(a, b)| a.to_bits() == b.to_bits()))
                    {
                        return Verdict::Silent(format!(
                            "shake_positions failed ({e}) but changed x"
                        ));
                    }
                    typed(&e)
                }
                Ok(_) => match off_m(&b, tol, &x) {
                    None => Verdict::Ok,
                    Some(why) => Verdict::Silent(format!("shake_positions: Ok but {why}")),
                },
            }
        }
        Op::ProjectMomenta => {
            let q = z.q().to_vec();
            let mut p = z.p().to_vec();
            let given = p.clone();
            match rattle.project_momenta(&q, &mut p) {
                Err(e) => {
                    if !(p
                        .iter()
                        .zip(&given)
                        .all(|(a, b)| a.to_bits() == b.to_bits()))
                    {
                        return Verdict::Silent(format!(
                            "project_momenta failed ({e}) but changed p"
                        ));
                    }
                    typed(&e)
                }
                Ok(_) => match off_hidden(&b, &q, &p, &given) {
                    None => Verdict::Ok,
                    Some(why) => Verdict::Silent(format!("project_momenta: Ok but {why}")),
                },
            }
        }
        Op::ConstraintForces => {
            let before = z.clone();
            if let Err(e) = rattle.step(&mut z) {
                return typed(&e);
            }
            if let Verdict::Silent(why) = judge_state(case, &b, &z, &before, 0.0, || {
                p_prime_from_multipliers(case, &b, &rattle, &before, &z)
            }) {
                return Verdict::Silent(why);
            }
            let mut out = ConstraintForces::new(rattle.system());
            match rattle.constraint_forces(&z, &mut out) {
                Err(e) => typed(&e),
                Ok(()) => {
                    if !(finite(&out.multipliers) && finite(&out.forces) && finite(&out.virial)) {
                        Verdict::Silent(format!(
                            "constraint_forces: Ok but non-finite (h = {:e}, multipliers {:?})",
                            case.h, out.multipliers
                        ))
                    } else if out.step != z.step() || out.time != z.time() - case.h {
                        Verdict::Silent(format!(
                            "constraint_forces: step {} at t = {}, the state's step {} at {}",
                            out.step,
                            out.time,
                            z.step(),
                            z.time()
                        ))
                    } else {
                        Verdict::Ok
                    }
                }
            }
        }
        Op::PotentialEnergy => match rattle.potential_energy(&z) {
            Err(e) => typed(&e),
            Ok(v) if v.is_finite() => Verdict::Ok,
            Ok(v) => Verdict::Silent(format!("potential_energy: Ok({v})")),
        },
    }
}

fn judge_run(
    case: &Case,
    b: &Built,
    rattle: &mut Rattle,
    z: ParticleState,
    stop: &StopRule,
    stride: u64,
    t0: f64,
) -> Verdict {
    let h = case.h;
    let z = z.with_time(t0);
    let stop = match *stop {
        StopRule::Steps(n) => Stop::Steps(n),
        StopRule::NearSteps(n, d) => Stop::Time(t0 + n as f64 * h * (1.0 + d)),
        StopRule::Time(t) => Stop::Time(t),
    };
    // A valid run of more than 2·10³ steps (a tiny h and an ordinary stop
    // time) is a long run, not a hostile input: cut to its last digits.
    let stop = match stop {
        Stop::Time(t) => {
            let n = (t - t0) / h;
            if n > 2e3 && n <= 9007199254740992.0 {
                Stop::Steps(n as u64 % 100)
            } else {
                Stop::Time(t)
            }
        }
        s => s,
    };
    let p_in = z.p().to_vec();
    let q_in = z.q().to_vec();
    let out = rattle.run(&z, stop).stride(stride).execute();
    let traj = &out.trajectory;
    for i in 0..traj.len() {
        let s = traj.state(i);
        let (q, p) = (s.q.as_slice(), s.p.as_slice());
        let k = traj.step(i);
        if k == 0 {
            // The start, stored as given.
            if q != q_in.as_slice() || p != p_in.as_slice() {
                return Verdict::Silent("the stored start is not the state given".into());
            }
        } else {
            if let Some(why) = off_m(b, case.options.tol, q) {
                return Verdict::Silent(format!("stored state {i} (step {k}) {why}"));
            }
            if hidden_applies(case) {
                // p′ of the step from the stored state before, when it is
                // the step before.
                let q0 = match i.checked_sub(1) {
                    Some(j) if traj.step(j) + 1 == k => traj.state(j).q.as_slice().to_vec(),
                    _ => Vec::new(),
                };
                let replay = || replay_p_prime(case, b, &z, k, (q, p));
                if let Some(why) = off_hidden_after_step(case, b, &q0, q, p, &p_in, replay) {
                    return Verdict::Silent(format!("stored state {i} (step {k}) {why}"));
                }
            }
            if !finite(p) {
                return Verdict::Silent(format!("stored state {i} (step {k}) non-finite momenta"));
            }
        }
        let t = t0 + k as f64 * h;
        if traj.time(i) != t {
            return Verdict::Silent(format!(
                "step {k} stored at t = {} ≠ t0 + k·h = {t}",
                traj.time(i)
            ));
        }
    }
    judge_end(traj, out.error.as_ref(), t0, h)
}

// ---------------------------------------------------------------------------
// Modes
// ---------------------------------------------------------------------------

fn fuzz(cases: u64, seed: u64) -> common::fuzz::Counts {
    common::fuzz::fuzz(
        "fuzz_particles",
        case_strategy(),
        run_case,
        DEADLINE,
        cases,
        seed,
    )
}

#[test]
fn fuzz_particles_ci() {
    let c = fuzz(
        env_u64("SHAKE_FUZZ_CI_CASES", CI_CASES),
        env_u64("SHAKE_FUZZ_SEED", 13),
    );
    assert_clean(&c);
}

#[test]
#[ignore = "long mode: SHAKE_FUZZ_CASES (default 10^5) cases"]
fn fuzz_particles_long() {
    let c = fuzz(
        env_u64("SHAKE_FUZZ_CASES", 100_000),
        env_u64("SHAKE_FUZZ_SEED", 13),
    );
    assert_clean(&c);
}

/// Every solver with masses and lengths at the ends of f64's range: each
/// ends in a verdict.
#[test]
fn extreme_masses_and_lengths_end_in_a_verdict() {
    let mut cases = Vec::new();
    let base = fuzz_particles_base();
    for x in [
        f64::MAX,
        1e300,
        1e-300,
        5e-324,
        f64::MIN_POSITIVE,
        0.0,
        -1.0,
    ] {
        for solver in [
            SolverChoice::Clusters,
            SolverChoice::Band,
            SolverChoice::Sparse,
        ] {
            for (corrupt, scale) in [
                (Corrupt::Mass(x), 1.0),
                (Corrupt::Length(x), 1.0),
                (Corrupt::None, x),
            ] {
                for op in [
                    Op::Project,
                    Op::Step(2),
                    Op::ProjectMomenta,
                    Op::ShakePositions(1e-3),
                ] {
                    cases.push(Case {
                        corrupt: corrupt.clone(),
                        scale,
                        options: Options {
                            solver,
                            ..Options::default()
                        },
                        op: op.clone(),
                        ..base.clone()
                    });
                }
            }
        }
    }
    let c = fuzz_cases(cases, run_case, DEADLINE);
    assert_clean(&c);
}

/// A water of unit masses and lengths, projected, one step.
fn fuzz_particles_base() -> Case {
    Case {
        dim: 3,
        shape: Shape::Waters(2),
        corrupt: Corrupt::None,
        scale: 1.0,
        heavy: 16.0,
        light: 1.0,
        h: 0.01,
        options: Options::default(),
        thermostat: None,
        field: None,
        momentum: 0.5,
        seed: 7,
        start: Start::OnM,
        project_first: true,
        op: Op::Step(1),
    }
}

/// The long mode's one silent case (seed 13): three waters 10³⁶ long,
/// g-BAOAB with h = 174, two steps ended Ok off M^H.
#[test]
fn far_waters_under_gbaoab_stay_on_the_hidden_constraint() {
    let case = Case {
        dim: 3,
        shape: Shape::Waters(3),
        corrupt: Corrupt::None,
        scale: 1e36,
        heavy: 11.069991475799686,
        light: 1.1961177588703842,
        h: 173.87024515336688,
        options: Options {
            tol: 4.129817275533618e-9,
            max_iter: 50,
            method: Method::Rattle,
            solver: SolverChoice::Auto,
        },
        thermostat: Some(Thermostat {
            gamma: 0.7157016263007963,
            kt: 0.37846856651616984,
            seed: 2665054945816401417,
            substeps: 3,
        }),
        field: None,
        momentum: 0.2995537186487692,
        seed: 12191772520418331612,
        start: Start::OnM,
        project_first: false,
        op: Op::Step(2),
    };
    let c = fuzz_cases(vec![case], run_case, DEADLINE);
    assert_clean(&c);
}
