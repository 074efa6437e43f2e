//! Rings and branched molecules (the constraint clusters LAMMPS' `fix
//! shake` refuses) under (g-)BAOAB: each kind of molecule reaches the
//! target kinetic temperature with the 3n − m degrees of freedom its
//! constraints leave, and the bonds stay at the solver's tolerance.
//!
//! Each molecule's time average is an independent sample (the molecules do
//! not interact), so the standard error of a kind's mean is their spread
//! over √(molecules); the gate is 5 standard errors (a false failure about
//! once in 10⁶; the seeds are fixed, so a run is deterministic), with
//! nothing for BAOAB's O(h²) bias in the kinetic energy, which is below
//! 0.1 % at h = 1 fs with the hydrogens' bonds constrained.

use geoshake::runtime::particles::generate::{self, KB, MVV2E};
use geoshake::runtime::particles::{Langevin, Options, Rattle};
use geoshake::runtime::Stop;

#[path = "../../examples/rings/molecules.rs"]
#[allow(dead_code)]
mod molecules;

/// (mean, standard error) of independent samples.
fn mean_se(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let v = x.iter().map(|y| (y - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (v / n).sqrt())
}

fn reaches_the_temperature(substeps: usize, seed: u64) {
    let (kinds, each) = (2, 60);
    let (system, mut state, starts) = molecules::mixture(each, each, seed).unwrap();
    let masses = system.masses().to_vec();
    let mut rattle = Rattle::new(system, 1.0, Options::default()).unwrap();
    rattle.project(&mut state).unwrap();
    generate::set_temperature(rattle.system(), &mut state, 100.0);
    let kelvin = 300.0;
    let kt = KB * kelvin / MVV2E;
    // γ = 20/ps: a molecule's kinetic energy decorrelates in ~50 steps.
    let th = Langevin::new(2e-2, kt, seed)
        .unwrap()
        .geodesic(substeps)
        .unwrap();
    rattle.set_thermostat(Some(th)).unwrap();
    assert!(rattle.run_in_place(&mut state, 400).error.is_none());
    let steps = 1600;
    let mut kinetic = vec![0.0; kinds * each];
    let mut last = Vec::new();
    let out = rattle
        .run(&state, Stop::Steps(steps))
        .store(false)
        .observe(|k, _, z| {
            if k == steps {
                last = z.q.as_slice().to_vec();
            }
            if k > 0 {
                let p = z.p.as_slice();
                for (j, e) in kinetic.iter_mut().enumerate() {
                    *e += (3 * starts[j]..3 * starts[j + 1])
                        .map(|c| p[c] * p[c] / (2.0 * masses[c / 3]))
                        .sum::<f64>();
                }
            }
        })
        .execute();
    assert!(out.error.is_none(), "{:?}", out.error);
    assert!(out.summary.max_residual.unwrap() <= 1e-10);
    assert!(out.summary.max_hidden.unwrap() <= 1e-12);
    let bonds = rattle.system().constraint_families()[0].table();
    assert!(generate::max_rel_length_error(bonds, 3, &last) <= 1e-10);
    // Rings: 12 atoms, 21 constraints; branched: 8 atoms, 15.
    for (kind, dof) in [(0, 36.0 - 21.0), (1, 24.0 - 15.0)] {
        let t: Vec<f64> = kinetic[kind * each..(kind + 1) * each]
            .iter()
            .map(|e| 2.0 * e / steps as f64 / (dof * kt) * kelvin)
            .collect();
        let (m, se) = mean_se(&t);
        assert!(
            (m - kelvin).abs() < 5.0 * se,
            "kind {kind}: T = {m} ± {se} K"
        );
        // The gate is narrow enough to see a count of degrees of freedom
        // off by one (a 6.7 % shift for the ring, 11 % for the branched
        // molecule): 5 standard errors stay below 6.5 %.
        assert!(se < 0.013 * kelvin, "kind {kind}: standard error {se} K");
    }
}

#[test]
fn rings_and_branched_molecules_reach_the_temperature_under_geodesic_baoab() {
    reaches_the_temperature(2, 11);
}

#[test]
fn rings_and_branched_molecules_reach_the_temperature_under_baoab() {
    reaches_the_temperature(1, 12);
}

#[test]
fn the_ring_is_one_cluster_with_a_cycle_and_the_branched_molecule_a_tree() {
    let ring = molecules::benzene();
    let tree = molecules::branched();
    // Edges − vertices + components: the cycle rank of the constraint
    // graph over atoms (a tree has none).
    let cycles = |m: &molecules::Molecule| m.bonds.len() as i64 - m.masses.len() as i64 + 1;
    assert!(cycles(&ring) > 0);
    assert_eq!((ring.bonds.len(), tree.bonds.len()), (21, 15));
    // The branched molecule's bonds (the first 7) form a tree, its two
    // branch points have three neighbours each.
    let mut degree = [0; 8];
    for &[a, b] in &tree.bonds[..7] {
        degree[a] += 1;
        degree[b] += 1;
    }
    assert_eq!(degree.iter().filter(|&&d| d == 3).count(), 2);
    // Both project and step: N is nonsingular on their configurations.
    let (system, mut state, _) = molecules::mixture(3, 3, 1).unwrap();
    let mut rattle = Rattle::new(system, 1.0, Options::default()).unwrap();
    rattle.project(&mut state).unwrap();
    generate::set_temperature(rattle.system(), &mut state, 300.0);
    assert!(rattle.run_in_place(&mut state, 200).error.is_none());
}
