//! A box of rigid waters declared with `constrained_system!` runs through the
//! large-system RATTLE exactly as the runtime's hand-written distance
//! stencil does: the generated stencil is a drop-in for the hand-written one
//! on the whole path (topology checks, cluster solver, driver).

use geoshake::constrained_system;
use geoshake::runtime::particles::{generate, Options, ParticleState, Rattle};

constrained_system! {
    /// Rigid water: three distance constraints per molecule.
    pub struct Water {
        particles x[3];
        constraints {
            bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2,
        }
    }
}

#[test]
fn macro_water_takes_the_hand_written_steps() {
    let (hand, z0) = generate::water(200, 7).unwrap();
    let table = hand.constraint_families()[0].table().clone();
    let declared = Water::new()
        .system(hand.masses().to_vec(), table)
        .expect("the generator's topology is valid");
    let steps = 200;
    let h = 2.0;
    let mut ends = Vec::new();
    for system in [hand, declared] {
        let mut rattle = Rattle::new(system, h, Options::default()).unwrap();
        // The hand-written stencil's triangles would be solved in closed
        // form (exact to round-off), the declared one's by Newton (to the
        // tolerance): the same kernel for both, so that only the stencils
        // differ.
        rattle.use_newton_cluster_kernel();
        let mut z = ParticleState::new(z0.q().to_vec(), z0.p().to_vec());
        rattle.project(&mut z).unwrap();
        // Maxwell–Boltzmann at 300 K, as the LAMMPS recipe (real units).
        generate::set_temperature(rattle.system(), &mut z, 300.0);
        let out = rattle.run_in_place(&mut z, steps);
        assert!(out.error.is_none(), "{:?}", out.error);
        assert!(out.summary.max_residual.unwrap() <= Options::default().tol);
        ends.push(z);
    }
    // Both evaluate |x_a − x_b|² − l² on the difference, possibly with other
    // rounding: a step differs by O(ε|x|), and a free rigid body is not
    // chaotic, so after n steps the states differ by at most ~n·ε·|x|
    // (|x| ≲ 30 Å here): 200 · 2.2e-16 · 30 ≈ 1.3e-12 Å.
    let scale = ends[0].q().iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let bound = steps as f64 * f64::EPSILON * scale;
    let dq = ends[0]
        .q()
        .iter()
        .zip(ends[1].q())
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    let dp = ends[0]
        .p()
        .iter()
        .zip(ends[1].p())
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    let pscale = ends[0].p().iter().fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(dq <= bound, "positions differ by {dq:.2e} > {bound:.2e}");
    assert!(
        dp <= steps as f64 * f64::EPSILON * pscale * 10.0,
        "momenta differ by {dp:.2e}"
    );
}
