//! A large-system step allocates nothing: every buffer is made by
//! `Rattle::new` (cluster, band and sparse paths, with and without forces).

use crate::common;

use common::alloc::allocations;
use geoshake::runtime::particles::{
    generate, Options, ParticleState, ParticleSystem, Rattle, SolverChoice,
};

fn allocations_per_50_steps(
    system: ParticleSystem,
    mut state: ParticleState,
    solver: SolverChoice,
) -> usize {
    let options = Options {
        solver,
        ..Options::default()
    };
    let mut r = Rattle::new(system, 2.0, options).unwrap();
    r.project(&mut state).unwrap();
    generate::set_temperature(r.system(), &mut state, 300.0);
    r.step(&mut state).unwrap();
    let before = allocations();
    for _ in 0..50 {
        r.step(&mut state).unwrap();
    }
    allocations() - before
}

#[test]
fn steps_do_not_allocate() {
    let (w, ws) = generate::water(20, 1).unwrap();
    assert_eq!(
        allocations_per_50_steps(w, ws, SolverChoice::Auto),
        0,
        "clusters"
    );
    let (c, cs) = generate::chain(30, 1).unwrap();
    assert_eq!(
        allocations_per_50_steps(c, cs, SolverChoice::Auto),
        0,
        "band"
    );
    let (c, cs) = generate::chain(30, 1).unwrap();
    assert_eq!(
        allocations_per_50_steps(c, cs, SolverChoice::Sparse),
        0,
        "sparse"
    );
    // Clusters with a potential: the separate velocity stage.
    let (w, ws) = generate::water(20, 1).unwrap();
    let mut field = geoshake::runtime::particles::Table::new(1, 3);
    for a in 0..w.particles() {
        field.push(&[a], &[0.0, 0.0, 1e-4]).unwrap();
    }
    let w = w
        .with_potential(
            "field",
            geoshake::runtime::particles::stencils::LinearField::<3>,
            field,
        )
        .unwrap();
    assert_eq!(
        allocations_per_50_steps(w, ws, SolverChoice::Auto),
        0,
        "clusters with forces"
    );
    let (c, cs) = generate::chain_with_springs(30, 1).unwrap();
    assert_eq!(
        allocations_per_50_steps(c, cs, SolverChoice::Auto),
        0,
        "band with forces"
    );
}
