//! A step allocates nothing: every buffer lives in the integrator's
//! workspace. Counted with a global allocator wrapper over many
//! `step_in_place` calls, for every base map and every kind of fibre flow
//! (closed form, the runtime's kick, matrix exponential, GBS integration).

use crate::common;

use common::alloc::allocations;
use common::models::*;
use geoshake::{
    BaseMap, Composition, ConstrainedSystem, ImplicitMidpoint, Integrator, State, StormerVerlet,
    SymplecticEuler,
};

fn allocations_per_100_steps<S: ConstrainedSystem + Clone, B: BaseMap>(
    sys: S,
    base: B,
    z0: State,
) -> usize {
    let mut integ = Integrator::new(sys, base, 0.01);
    let mut z = integ.project_to_hidden(&z0).unwrap();
    integ.step_in_place(&mut z).unwrap();
    let before = allocations();
    for _ in 0..100 {
        integ.step_in_place(&mut z).unwrap();
    }
    allocations() - before
}

fn every_base<S: ConstrainedSystem + Clone>(name: &str, sys: S, z0: State) {
    let counts = [
        allocations_per_100_steps(sys.clone(), ImplicitMidpoint, z0.clone()),
        allocations_per_100_steps(sys.clone(), StormerVerlet, z0.clone()),
        allocations_per_100_steps(sys, SymplecticEuler, z0),
    ];
    assert_eq!(
        counts,
        [0, 0, 0],
        "{name}: allocations in 100 steps (midpoint, SV, Euler)"
    );
}

#[test]
fn steps_do_not_allocate() {
    let hopf = State::from_slices(
        &[-0.78652612, -0.4043988],
        &[-0.3880746864163783, 0.2173391755798215],
    );
    every_base(
        "pendulum",
        Pendulum::default(),
        Pendulum::default().state(1.0, 0.5),
    );
    every_base(
        "non-separable",
        NonSeparablePendulum::default(),
        NonSeparablePendulum::default().state_on_mh(1.0, 0.5),
    );
    every_base(
        "double, kick",
        NoClosedForm(DoublePendulum::default()),
        DoublePendulum::default().state(0.5, 1.0, 0.3, -0.2),
    );
    // Declared with the macro: the fixed-size classical steps of one
    // (`geoshake::classical::fixed`) and of two to eight constraints (`fixed_m`).
    let declared = geoshake::models::Pendulum::new(1.0, 9.81);
    every_base(
        "declared pendulum",
        declared,
        Pendulum::default().state(1.0, 0.5),
    );
    let double = geoshake::models::DoublePendulum::new(1.0, 1.0, 9.81);
    every_base(
        "declared double pendulum",
        double,
        DoublePendulum::default().state(0.5, 1.0, 0.3, -0.2),
    );
    every_base("Hopf", Hopf::gravity(), hopf.clone());
    every_base("Hopf, expm", NoClosedForm(Hopf::gravity()), hopf.clone());
    every_base("Hopf, GBS", AsGeneral(Hopf::gravity()), hopf);
}

/// A composed step with its reverse check (`Options::reverse_tolerance`,
/// a second workspace made once, at the first step) allocates nothing per
/// step either.
#[test]
fn composed_steps_with_the_reverse_check_do_not_allocate() {
    let hopf = State::from_slices(
        &[-0.78652612, -0.4043988],
        &[-0.3880746864163783, 0.2173391755798215],
    );
    let count = |integ: &mut Integrator<Hopf, ImplicitMidpoint>| {
        let mut z = integ.project_to_hidden(&hopf).unwrap();
        integ.step_in_place(&mut z).unwrap();
        let before = allocations();
        for _ in 0..100 {
            integ.step_in_place(&mut z).unwrap();
        }
        allocations() - before
    };
    let mut integ =
        Integrator::new(Hopf::gravity(), ImplicitMidpoint, 0.01).composed(Composition::TRIPLE_JUMP);
    assert!(integ.options().reverse_tolerance.is_finite());
    assert_eq!(count(&mut integ), 0);
    let mut pendulum =
        Integrator::new(Pendulum::default(), StormerVerlet, 0.01).composed(Composition::YOSHIDA_6);
    let mut z = Pendulum::default().state(1.0, 0.5);
    pendulum.step_in_place(&mut z).unwrap();
    let before = allocations();
    for _ in 0..100 {
        pendulum.step_in_place(&mut z).unwrap();
    }
    assert_eq!(allocations() - before, 0);
}
