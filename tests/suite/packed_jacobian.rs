//! `constrained_system!` also writes the nonzeros of g_z packed in the
//! order of its pattern (`ConstrainedSystem::constraint_jacobian_values`),
//! and the classical path reads G from them instead of from the dense
//! m × 2d g_z, whose nonzeros lie a column apart (on a 256-link chain the
//! dense buffers are 2 MB each). Checked here:
//!
//! - the packed values are the dense entries, to the bit, for holonomic and
//!   momentum-dependent constraints, at random points, for the macro's code
//!   and for a run-time declaration (`geoshake::declared`, which provides
//!   them too);
//! - a run that reads G out of the dense g_z (`DenseJacobian`, a wrapper
//!   without the packed values) is the same run, to the bit, on the slice
//!   path (16 links) and against the fixed-size step (4 links).

use geoshake::declared::DeclaredSystem;
use geoshake::{
    constrained_system, ConstrainedSystem, Integrator, Options, State, Stop, StormerVerlet,
};
use geoshake_testkit::bench::systems::{Chain16, Chain4};
use geoshake_testkit::models::DenseJacobian;

constrained_system! {
    /// A constraint on positions and momenta together (g_z has entries in
    /// both halves).
    struct Mixed {
        parameters { c }
        dof q[3], p[3];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2) / 2 + q[2];
        constraints {
            sphere: (q[0] - c)^2 + q[1]^2 + p[0]^2 + p[1]^2 - 1,
            stretch: q[2] * p[2] - c,
        }
    }
}

constrained_system! {
    /// A 4-link chain whose kinetic energy couples neighbouring masses (a
    /// constant, non-diagonal mass matrix): SHAKE's Jacobian then comes from
    /// column groups through `grad_p`, not from the list of terms.
    struct CoupledChain4 {
        parameters { c }
        const N = 4;
        dof q[2*N], p[2*N];
        hamiltonian = sum i in 0..N { (p[2*i]^2 + p[2*i+1]^2) / 2 + 9.81 * q[2*i+1] }
            + sum i in 1..N { c * (p[2*i] * p[2*i-2] + p[2*i+1] * p[2*i-1]) };
        constraints {
            link[k in 0..N]: if k == 0 { q[0]^2 + q[1]^2 - 1 }
                else { (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - 1 },
        }
    }
}

/// A point of R^{2d} from a linear congruential sequence (any point will
/// do: the check is of two codes for the same numbers).
fn point(seed: &mut u64, d: usize) -> (Vec<f64>, Vec<f64>) {
    let mut next = || {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) * 4.0 - 2.0
    };
    let q = (0..d).map(|_| next()).collect();
    let p = (0..d).map(|_| next()).collect();
    (q, p)
}

/// Packed and dense g_z at 100 random points: the same bits, entry by
/// entry of the pattern.
fn packed_is_dense<S: ConstrainedSystem>(sys: &S) -> usize {
    let (d, m) = (sys.dof(), sys.constraint_count());
    let pattern = sys.jacobian_pattern();
    let mut seed = 7;
    let mut checked = 0;
    for _ in 0..100 {
        let (q, p) = point(&mut seed, d);
        let mut dense = vec![0.0; m * 2 * d];
        sys.constraint_jacobian(&q, &p, &mut dense);
        let mut packed = vec![f64::NAN; pattern.len()];
        assert!(sys.constraint_jacobian_values(&q, &p, &mut packed));
        for (e, &(i, k)) in pattern.iter().enumerate() {
            assert_eq!(
                packed[e].to_bits(),
                dense[i + k * m].to_bits(),
                "entry {e} = ({i}, {k})"
            );
            checked += 1;
        }
    }
    checked
}

#[test]
fn the_packed_values_are_the_dense_entries() {
    let momenta = Mixed::new(0.3)
        .jacobian_pattern()
        .iter()
        .filter(|&&(_, k)| k >= 3)
        .count();
    assert!(momenta > 0, "Mixed must have entries in g_p");
    let counts = [
        packed_is_dense(&Chain4::new(1.0, 9.81)),
        packed_is_dense(&Chain16::new(1.0, 9.81)),
        packed_is_dense(&Mixed::new(0.3)),
        packed_is_dense(&geoshake::models::Pendulum::new(1.0, 9.81)),
        packed_is_dense(&geoshake::models::DoublePendulum::new(1.0, 0.7, 9.81)),
    ];
    // 4 entries per link but the first (2), 2 per rod for the pendulums.
    assert_eq!(counts[0], 100 * (4 * 4 - 2));
    assert_eq!(counts[1], 100 * (4 * 16 - 2));
    assert!(counts[2] > 0 && counts[3] == 200 && counts[4] == 600);
    // A run-time declaration of the 16-link chain, and of Mixed.
    assert_eq!(packed_is_dense(&declared_chain16()), counts[1]);
    assert_eq!(packed_is_dense(&declared_mixed()), counts[2]);
    // A slice of the wrong length: refused, not a panic.
    let mut short = [f64::NAN; 3];
    let chain = Chain4::new(1.0, 9.81);
    assert!(!chain.constraint_jacobian_values(&[0.0; 8], &[0.0; 8], &mut short));
    assert!(!declared_chain16().constraint_jacobian_values(&[0.0; 32], &[0.0; 32], &mut short));
    assert!(short.iter().all(|x| x.is_nan()), "left untouched");
    // A hand-written system provides none: the runtime reads g_z.
    let hand = geoshake_testkit::models::SphericalPendulum::default();
    let mut out = [f64::NAN; 3];
    assert!(!hand.constraint_jacobian_values(&[0.0, 0.0, -1.0], &[0.0; 3], &mut out));
    assert!(out.iter().all(|x| x.is_nan()), "left untouched");
}

/// The 16-link chain, declared at run time.
fn declared_chain16() -> DeclaredSystem {
    let src = "
    struct Chain16 {
        parameters { length, gravity }
        const N = 16;
        dof q[2*N], p[2*N];
        hamiltonian = sum i in 0..N { (p[2*i]^2 + p[2*i+1]^2) / 2 + gravity * q[2*i+1] };
        constraints {
            link[k in 0..N]: if k == 0 { q[0]^2 + q[1]^2 - length^2 }
                else { (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 },
        }
    }";
    DeclaredSystem::new(src, &[("length", 1.0), ("gravity", 9.81)]).unwrap()
}

/// `Mixed`, declared at run time.
fn declared_mixed() -> DeclaredSystem {
    let src = "
    struct Mixed {
        parameters { c }
        dof q[3], p[3];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2) / 2 + q[2];
        constraints {
            sphere: (q[0] - c)^2 + q[1]^2 + p[0]^2 + p[1]^2 - 1,
            stretch: q[2] * p[2] - c,
        }
    }";
    DeclaredSystem::new(src, &[("c", 0.3)]).unwrap()
}

/// A chain of n links at angles 0.3 + 0.7 sin(1.3 k) from the vertical,
/// at rest, then projected onto M^H.
fn chain_start(n: usize) -> State {
    let mut q = vec![0.0; 2 * n];
    let (mut x, mut y) = (0.0, 0.0);
    for k in 0..n {
        let a: f64 = 0.3 + 0.7 * (1.3 * k as f64).sin();
        x += a.sin();
        y -= a.cos();
        q[2 * k] = x;
        q[2 * k + 1] = y;
    }
    let p: Vec<f64> = (0..2 * n).map(|i| 0.1 * (i as f64).cos()).collect();
    State::from_slices(&q, &p)
}

/// Runs `packed` and `dense` (the same system, the second without packed
/// values) from the same state, lazily and eagerly projected, and returns
/// how many stored states were compared; every one must be the same bits.
fn same_runs<S: ConstrainedSystem + Clone>(packed: S, n: usize) -> usize {
    let dense = DenseJacobian(packed.clone());
    let mut compared = 0;
    for every in [false, true] {
        let opts = Options {
            project_every_step: every,
            ..Options::default()
        };
        let mut a = Integrator::new(packed.clone(), StormerVerlet, 0.01)
            .rattle()
            .with_options(opts);
        let mut b = Integrator::new(dense.clone(), StormerVerlet, 0.01)
            .rattle()
            .with_options(opts);
        let z0 = a.project_to_hidden(&chain_start(n)).unwrap();
        let ra = a.run(z0.clone(), Stop::Steps(400)).execute();
        let rb = b.run(z0, Stop::Steps(400)).execute();
        assert!(
            ra.error.is_none() && rb.error.is_none(),
            "{:?} {:?}",
            ra.error,
            rb.error
        );
        assert_eq!(ra.trajectory.len(), rb.trajectory.len());
        for k in 0..ra.trajectory.len() {
            let (za, zb) = (ra.trajectory.state(k), rb.trajectory.state(k));
            for (x, y) in
                za.q.iter()
                    .chain(za.p.iter())
                    .zip(zb.q.iter().chain(zb.p.iter()))
            {
                assert_eq!(x.to_bits(), y.to_bits(), "state {k} (every step: {every})");
            }
            compared += 1;
        }
    }
    compared
}

#[test]
fn reading_g_from_the_dense_g_z_gives_the_same_run() {
    // 16 links: the slice path on both sides.
    assert_eq!(same_runs(Chain16::new(1.0, 9.81), 16), 2 * 401);
    // 4 links: the fixed-size step (packed) against the slice path (dense).
    assert_eq!(same_runs(Chain4::new(1.0, 9.81), 4), 2 * 401);
    // A coupled mass matrix: SHAKE's Jacobian from the column groups,
    // packed (the fixed-size step the macro emits for m = 4) against dense
    // (the wrapper forwards no fixed-size step: the slice path).
    assert_eq!(same_runs(CoupledChain4::new(0.2), 4), 2 * 401);
    // Declared at run time: the tape's packed values against its g_z.
    assert_eq!(same_runs(declared_chain16(), 16), 2 * 401);
}
