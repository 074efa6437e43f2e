//! The SPC/E force field of `examples/water_md` (included from
//! `examples/water_md/spce.rs`) and a run with it: its forces are −∇V, its
//! cell list finds the pairs all-pairs finds, and RATTLE with it keeps H
//! within its O(h²) fluctuation and the bonds at the solver's tolerance.

use geoshake::runtime::particles::generate::{self, SplitMix64, KB, MVV2E};
use geoshake::runtime::particles::{Langevin, Options, ParticleState, Rattle};

#[path = "../../examples/water_md/spce.rs"]
mod spce;
use spce::Spce;

/// The lattice of `generate::water(n, seed)` with every atom moved by up
/// to 0.1 Å along each axis (off the lattice's symmetries and off rigid
/// geometry: the field does not care), and every fifth molecule moved by a
/// whole box vector (the field must see the same periodic system).
fn disordered_box(n: usize, seed: u64) -> (Vec<f64>, [f64; 3]) {
    let (_, state) = generate::water(n, seed).unwrap();
    let l = generate::water_box(n);
    let mut rng = SplitMix64::new(seed ^ 0x5eed);
    let mut q = state.q().to_vec();
    for (k, x) in q.iter_mut().enumerate() {
        *x += 0.2 * (rng.uniform() - 0.5);
        let (molecule, c) = (k / 9, k % 3);
        if molecule % 5 == 0 {
            *x += [1.0, -1.0, 2.0][c] * l[c];
        }
    }
    (q, l)
}

/// V(q) and −∇V(q) by `energy_forces`, in kcal/mol and kcal/mol/Å.
fn field(spce: &mut Spce, q: &[f64]) -> (f64, Vec<f64>) {
    let mut f = vec![0.0; q.len()];
    let v = spce.energy_forces(q, &mut f);
    (v, f)
}

/// The root mean square of the entries of `f`.
fn rms(f: &[f64]) -> f64 {
    (f.iter().map(|x| x * x).sum::<f64>() / f.len() as f64).sqrt()
}

/// The largest |F_c − (V(q − δe_c) − V(q + δe_c))/(2δ)| over 24 random
/// coordinates c, relative to the RMS force, δ = 10⁻⁵ Å.
fn central_difference_error(spce: &mut Spce, q: &[f64], seed: u64) -> f64 {
    const DELTA: f64 = 1e-6;
    let (_, f) = field(spce, q);
    let mut rng = SplitMix64::new(seed);
    let mut worst = 0.0f64;
    let mut x = q.to_vec();
    for _ in 0..24 {
        let c = (rng.next_u64() % q.len() as u64) as usize;
        x[c] = q[c] + DELTA;
        let up = field(spce, &x).0;
        x[c] = q[c] - DELTA;
        let down = field(spce, &x).0;
        x[c] = q[c];
        let fd = (down - up) / (2.0 * DELTA);
        worst = worst.max((fd - f[c]).abs());
    }
    worst / rms(&f)
}

/// F = −∇V to 10⁻⁶ of the RMS force (≈ 9 kcal/mol/Å here), on the all-pairs
/// and the cell-list path. The central difference's own errors at
/// δ = 10⁻⁵ Å: truncation δ²/6·|∂³V|, with |∂³V| ≤ 6 k|q_i q_j|/r⁴ ≲ 10³
/// kcal/mol/Å³ for the closest intermolecular pairs (r ≳ 0.8 Å), ≲ 2·10⁻⁸
/// kcal/mol/Å; the round-off of V (a sum over ~10⁵ pairs) divided by δ;
/// and, where a pair crosses r_c within δ, V″'s jump J there (V is only
/// C¹): an error up to J·δ/4, J = 2k|q_i q_j|/r_c³ ≤ 0.65 kcal/mol/Å² for
/// O–O at 9 Å, 1.6·10⁻⁶ kcal/mol/Å or 2·10⁻⁷ of the RMS force. Measured:
/// 9·10⁻⁹ and 4·10⁻⁹ kcal/mol/Å, 10⁻⁹ and 5·10⁻¹⁰ of the RMS force (no
/// crossing among the coordinates drawn). A force with its sign flipped
/// misses by 5, one without its shift −k q_i q_j/r_c² by 1.
#[test]
fn the_forces_are_minus_the_gradient_of_v() {
    // 216 waters: all pairs at r_c = 9 Å (2 cells per side), the cell list
    // at r_c = 6 Å (3 per side).
    let (q, l) = disordered_box(216, 11);
    for (cutoff, cells) in [(9.0, None), (6.0, Some([3, 3, 3]))] {
        let mut spce = Spce::new(l, cutoff).unwrap();
        assert_eq!(spce.cells(), cells);
        let err = central_difference_error(&mut spce, &q, 5);
        assert!(err < 1e-6, "r_c = {cutoff}: relative error {err:.3e}");
    }
}

/// The cell list and all pairs add the same pair terms (the same pairs
/// within r_c, and separations equal but for the rounding of the image
/// shift) in different orders: V and F agree to round-off, 10⁻¹² relative
/// (measured 1.4–4.4·10⁻¹⁵ for V and 0.9–1.4·10⁻¹⁴ of the RMS force for
/// F), on cubic and non-cubic cell grids, with molecules given outside the
/// box.
#[test]
fn the_cell_list_finds_the_pairs_all_pairs_finds() {
    // 3, 4 and 3×5×5 cells per side at r_c = 6 Å.
    for (n, cells) in [(216, [3, 3, 3]), (512, [4, 4, 4]), (600, [3, 5, 5])] {
        let (q, l) = disordered_box(n, 3);
        let mut spce = Spce::new(l, 6.0).unwrap();
        assert_eq!(spce.cells(), Some(cells), "{n} waters");
        let (v, f) = field(&mut spce, &q);
        let mut reference = vec![0.0; q.len()];
        let v_ref = spce.energy_forces_all_pairs(&q, &mut reference);
        let dv = ((v - v_ref) / v_ref).abs();
        let df = f
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
            / rms(&reference);
        assert!(
            dv < 1e-12 && df < 1e-12,
            "{n} waters: dV {dv:.3e}, dF {df:.3e}"
        );
    }
}

/// The waters of the run: 216 (a box of 18.6 Å, at least 2 r_c).
const WATERS: usize = 216;

/// RATTLE at step h with the field at r_c = 9 Å (all pairs: 2 cells per
/// side).
fn water_rattle(h: f64) -> Rattle {
    let (system, _) = generate::water(WATERS, 2024).unwrap();
    let spce = Spce::new(generate::water_box(WATERS), 9.0).unwrap();
    Rattle::new(system.with_forces(spce), h, Options::default()).unwrap()
}

/// Liquid water at 300 K: the lattice, projected and brought into the
/// liquid as the example does (0.6 ps of 2 fs with the momenta rescaled to
/// 300 K every 10 steps).
fn liquid() -> ParticleState {
    let (_, mut state) = generate::water(WATERS, 2024).unwrap();
    let mut rattle = water_rattle(2.0);
    rattle.project(&mut state).unwrap();
    for _ in 0..30 {
        generate::set_temperature(rattle.system(), &mut state, 300.0);
        assert!(rattle.run_in_place(&mut state, 10).error.is_none());
    }
    generate::set_temperature(rattle.system(), &mut state, 300.0);
    ParticleState::new(state.q().to_vec(), state.p().to_vec())
}

/// `steps` steps of h from `start`: the largest |H − H0| / (dof·k_B·300 K)
/// (dof = 3N − m − 3), the largest relative bond-length error and the
/// largest solver residual.
fn nve(h: f64, steps: u64, start: &ParticleState) -> (f64, f64, f64) {
    let mut rattle = water_rattle(h);
    let system = rattle.system();
    let dof = (3 * system.particles() - system.constraints() - 3) as f64;
    let energy = |r: &mut Rattle, s: &ParticleState| {
        (r.potential_energy(s).unwrap() + r.system().kinetic_energy(s.p())) * MVV2E
    };
    let mut state = start.clone();
    let h0 = energy(&mut rattle, &state);
    let (mut worst_h, mut worst_bond, mut worst_residual) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..steps {
        let out = rattle.run_in_place(&mut state, 1);
        assert!(out.error.is_none(), "{:?}", out.error);
        worst_residual = worst_residual.max(out.summary.max_residual.unwrap());
        let table = rattle.system().constraint_families()[0].table();
        worst_bond = worst_bond.max(generate::max_rel_length_error(table, 3, state.q()));
        worst_h = worst_h.max((energy(&mut rattle, &state) - h0).abs());
    }
    (worst_h / (dof * KB * 300.0), worst_bond, worst_residual)
}

/// 0.4 ps of liquid water, at h = 2 fs and at h = 1 fs from the same state.
///
/// Störmer–Verlet (RATTLE) conserves a modified energy H̃ = H + O(h²) up to
/// exponentially small terms, so H − H0 stays O(h²) and does not drift. Its
/// size: a harmonic mode of frequency ω and energy E oscillates between H̃
/// and H̃ − E·(ωh)²/4; water's fastest rigid motions, the librations
/// (500–900 cm⁻¹, ω ≈ 0.1–0.17 fs⁻¹), give (ωh)²/4 ≈ 1–3·10⁻² at 2 fs.
/// With `dof` modes of energy k_B T at independent phases, the RMS of
/// H − H̃ about its mean, over dof·k_B·T, is (ωh)²/4 / (2√(2 dof)) ≈
/// 1.3–2.8·10⁻⁴ (dof = 1293). H − H0 is the difference of two such values
/// (RMS √2 times larger), and its largest over 200 steps a few RMS: at the
/// estimate's top, 3·√2·2.8·10⁻⁴ ≈ 1.2·10⁻³. Measured: RMS 1.5·10⁻⁴,
/// largest 4.5·10⁻⁴. The bound 2·10⁻³ is 1.7 times the estimate's largest
/// and 4.5 times the measured one. Halving h divides |H − H0| by 4
/// (measured 3.8, and 4.0 from 1 to 0.5 fs); the window [2.5, 6] leaves
/// room for the sampling noise of a maximum over 200 and 400 steps of
/// trajectories that part within the run.
///
/// Either bound fails for a force that is not −∇V or not continuous: with
/// the sign of the forces flipped the run breaks down, without the force
/// shift −k q_i q_j/r_c² |H − H0| reaches 8·10⁻², and with V shifted alone
/// (V continuous, the force jumping at r_c, which the central differences
/// pass) 2·10⁻².
///
/// The bonds stay within the solver's tolerance (10⁻¹⁰): it stops when
/// |r² − l²|/(2r²) ≤ tol, which is |r − l|/l to a relative O(tol); the
/// factor 1 + 10⁻⁶ covers that and the round-off of the two measures.
#[test]
fn a_water_run_conserves_h_to_its_h2_fluctuation_and_keeps_the_bonds() {
    let start = liquid();
    let (e2, bond, residual) = nve(2.0, 200, &start);
    let tol = Options::default().tol;
    assert!(residual <= tol, "solver residual {residual:.3e}");
    assert!(bond <= tol * (1.0 + 1e-6), "bond-length error {bond:.3e}");
    assert!(e2 < 2e-3, "|H − H0| = {e2:.3e} dof·k_B·T at h = 2 fs");
    let (e1, _, _) = nve(1.0, 400, &start);
    let ratio = e2 / e1;
    assert!(
        (2.5..6.0).contains(&ratio),
        "|H − H0| {e2:.3e} at 2 fs, {e1:.3e} at 1 fs: ratio {ratio:.2}, not ≈ 4"
    );
}

/// Σ_i ∇²_{R_i} V of `translational_terms` against central differences of
/// the molecules' total forces: moving molecule i rigidly by ±δ along
/// axis c changes F_i by ∓δ ∂²V/∂R_{ic}², so
/// ∇²_{R_i} V ≈ −Σ_c (F_ic(R_i + δe_c) − F_ic(R_i − δe_c)) / (2δ),
/// summed over all molecules (216 waters, the cell list at r_c = 6 Å,
/// δ = 10⁻⁶ Å). The differences' errors: truncation δ²/6 |∂⁴V| ≲ 10⁻⁸
/// kcal/mol/Å² per close pair; the forces' round-off (sums of a few
/// hundred pair forces of up to ~10² kcal/mol/Å) over δ, up to 10⁻⁶ per
/// difference and ~10⁻⁴ over the 1944 differences, against a sum of
/// 1.2·10⁴ kcal/mol/Å²: ≲ 10⁻⁸ relative. A pair within δ of r_c,
/// where φ″ jumps by up to 2k|q_i q_j|/r_c³ ≈ 2 kcal/mol/Å², would add up
/// to half that jump (10⁻⁴ relative); at δ = 10⁻⁶ Å about 0.04 such pairs
/// are expected, and this box (a fixed seed) has none. The bound 10⁻⁷
/// relative is 10 times the round-off's estimate. Measured 1.2·10⁻¹⁰ (δ = 10⁻⁷:
/// 2.8·10⁻⁹, the round-off's 1/δ). Without the factor 2 for the pair's
/// second molecule the sum misses by 50 %, without the Lennard-Jones φ″
/// by 110 %; Σ|F_i|² is checked against the forces of `energy_forces`.
#[test]
fn the_translational_laplacian_is_the_divergence_of_the_molecular_forces() {
    const DELTA: f64 = 1e-6;
    let (q, l) = disordered_box(216, 7);
    let mut spce = Spce::new(l, 6.0).unwrap();
    let (force_squared, laplacian) = spce.translational_terms(&q);
    let molecule_force = |spce: &mut Spce, x: &[f64], i: usize| {
        let (_, f) = field(spce, x);
        [0, 1, 2].map(|c| f[9 * i + c] + f[9 * i + 3 + c] + f[9 * i + 6 + c])
    };
    let (_, f) = field(&mut spce, &q);
    let mut direct = 0.0;
    let mut differences = 0.0;
    let mut x = q.clone();
    for i in 0..q.len() / 9 {
        let fi = [0, 1, 2].map(|c| f[9 * i + c] + f[9 * i + 3 + c] + f[9 * i + 6 + c]);
        direct += fi.iter().map(|v| v * v).sum::<f64>();
        for c in 0..3 {
            let moved = |x: &mut [f64], by: f64| {
                for a in 0..3 {
                    x[9 * i + 3 * a + c] = q[9 * i + 3 * a + c] + by;
                }
            };
            moved(&mut x, DELTA);
            let up = molecule_force(&mut spce, &x, i)[c];
            moved(&mut x, -DELTA);
            let down = molecule_force(&mut spce, &x, i)[c];
            moved(&mut x, 0.0);
            differences -= (up - down) / (2.0 * DELTA);
        }
    }
    assert_eq!(x, q);
    let err = ((laplacian - differences) / differences).abs();
    assert!(
        err < 1e-7,
        "Σ∇²V = {laplacian:.6e}, by differences {differences:.6e}: relative error {err:.3e}"
    );
    assert!(((force_squared - direct) / direct).abs() < 1e-12);
}

/// Liquid water under geodesic BAOAB at T = 360 K (from liquid at 300 K)
/// reaches T in its configurations, measured by the translational
/// configurational temperature (`Spce::translational_terms`), which sees
/// only positions: the thermostat acts on the momenta, and the forces and
/// constraints must carry its temperature into the configurations.
/// 0.6 ps to equilibrate at γ = 5/ps (three relaxation times of the
/// kinetic energy), then 2000 steps of 2 fs sampled every 10. The
/// estimate's standard error comes from 10 batch means of 20 samples
/// (0.4 ps each, longer than the ~0.1 ps decay of the forces' correlation
/// in liquid water); the test allows 4 standard errors (for a t
/// distribution with 9 degrees of freedom, 0.3 % of runs outside by
/// chance; the run is seeded, so this is one fixed draw) plus 1 % of T for
/// the integrator's O(h²) configurational bias, which the example does not
/// show at that size (`water_md --waters 216 --steps 10000 --thermostat
/// gbaoab`: 300.4 ± 2.8 K at 300 K over 20 ps). Measured: 358.3 ± 3.7 K.
/// A box left at the start temperature, 300 K, would be 16 standard errors
/// off.
#[test]
fn langevin_water_has_the_configurational_temperature_of_its_thermostat() {
    const KELVIN: f64 = 360.0;
    let mut state = liquid();
    let mut rattle = water_rattle(2.0);
    let langevin = Langevin::new(5e-3, KB * KELVIN / MVV2E, 17)
        .and_then(|l| l.geodesic(2))
        .unwrap();
    rattle.set_thermostat(Some(langevin)).unwrap();
    assert!(rattle.run_in_place(&mut state, 300).error.is_none());
    let mut probe = Spce::new(generate::water_box(WATERS), 9.0).unwrap();
    let mut samples = Vec::new();
    for _ in 0..200 {
        assert!(rattle.run_in_place(&mut state, 10).error.is_none());
        samples.push(probe.translational_terms(state.q()));
    }
    let (t, se) = spce::configurational_temperature(&samples);
    assert!(
        (t - KELVIN).abs() < 4.0 * se + 0.01 * KELVIN,
        "configurational temperature {t:.2} K ± {se:.2} K (target {KELVIN} K)"
    );
}
