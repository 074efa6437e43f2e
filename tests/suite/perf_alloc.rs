//! No heap allocation per step, through a whole run: a run of 10 000 steps
//! allocates exactly as much as a run of 100 steps (its trajectory, the
//! states it stores, the observer's needs), for generated systems, every
//! base map, SHAKE and RATTLE. Counted with a global allocator wrapper, as
//! in `runtime_alloc.rs` (which counts single `step_in_place` calls).

use crate::common;

use common::alloc::allocations;
use geoshake::models::{Chain8, HopfGravity, Pendulum};
use geoshake::{
    BaseMap, ConstrainedSystem, ImplicitMidpoint, Integrator, State, Stop, StormerVerlet,
    SymplecticEuler,
};

/// Allocations of one run of `steps` steps that stores its first and last
/// state only (stride = steps).
fn run_allocations<S: ConstrainedSystem + Clone, B: BaseMap>(
    integ: &mut Integrator<S, B>,
    z0: &State,
    steps: u64,
) -> usize {
    let before = allocations();
    let out = integ
        .run(z0.clone(), Stop::Steps(steps))
        .stride(steps)
        .execute();
    assert!(out.error.is_none(), "{:?}", out.error);
    allocations() - before
}

fn check<S: ConstrainedSystem + Clone, B: BaseMap>(name: &str, sys: S, base: B, z0: &State) {
    for rattle in [false, true] {
        let integ = Integrator::new(sys.clone(), base, 0.01);
        let mut integ = if rattle {
            integ.rattle()
        } else {
            integ.shake()
        };
        let z0 = integ.project_to_hidden(z0).unwrap();
        // Warm up once (first-use adaptations in the workspace).
        run_allocations(&mut integ, &z0, 10);
        let short = run_allocations(&mut integ, &z0, 100);
        let long = run_allocations(&mut integ, &z0, 10_000);
        assert_eq!(
            short,
            long,
            "{name} / {} / {}: allocations of a run of 100 steps and of 10 000 steps",
            B::NAME,
            if rattle { "RATTLE" } else { "SHAKE" }
        );
    }
}

#[test]
fn a_run_allocates_nothing_per_step() {
    let pendulum = State::from_slices(&[0.8, -0.6], &[0.3, 0.4]);
    let hopf = State::from_slices(
        &[-0.78652612, -0.4043988],
        &[-0.3880746864163783, 0.2173391755798215],
    );
    let mut chain_q = vec![0.0; 16];
    for k in 0..8 {
        let th = 0.3 + 0.1 * k as f64;
        let (x0, y0) = if k == 0 {
            (0.0, 0.0)
        } else {
            (chain_q[2 * k - 2], chain_q[2 * k - 1])
        };
        chain_q[2 * k] = x0 + th.sin();
        chain_q[2 * k + 1] = y0 - th.cos();
    }
    let chain = State::from_slices(&chain_q, &[0.0; 16]);
    let p = Pendulum::new(1.0, 1.0);
    check("pendulum", p, StormerVerlet, &pendulum);
    check("pendulum", p, ImplicitMidpoint, &pendulum);
    check("pendulum", p, SymplecticEuler, &pendulum);
    let h = HopfGravity::new(0.0, -1.0, 1.0);
    check("Hopf", h, ImplicitMidpoint, &hopf);
    check("Hopf", h, StormerVerlet, &hopf);
    let c = Chain8::new(1.0, 1.0);
    check("chain of 8", c, StormerVerlet, &chain);
    check("chain of 8", c, ImplicitMidpoint, &chain);
}
