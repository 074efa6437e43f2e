//! Generators of the benchmark systems, with the geometry and set-up of
//! the LAMMPS recipe (`shared/peers/lammps/gen_data.py`), in LAMMPS `real`
//! units: masses in g/mol, lengths in Å, times in fs, momenta in
//! g/mol·Å/fs, energies in g/mol·Å²/fs² (1 g/mol·Å²/fs² =
//! [`MVV2E`] kcal/mol = 48.88821291² kcal/mol, i.e. 1 kcal/mol =
//! 4.184·10⁻⁴ g/mol·Å²/fs²).
//!
//! Random numbers come from [`SplitMix64`] (no dependency); the streams
//! differ from NumPy's, so the boxes are statistically, not bitwise, those
//! of `gen_data.py`.
//!
//! The generators wrap nothing: the runs here are free flight (no forces
//! between molecules), and over 1000 steps of 2 fs a water moves ~10 Å,
//! which the unwrapped coordinates carry without loss. The water lattice
//! does fill a periodic box, [`water_box`], for forces that need one
//! (a force field with the minimum image wraps the coordinates itself).

use super::stencils::{Distance, Spring};
use super::{ParticleState, ParticleSystem, Table, TopologyError};

/// LAMMPS `real` units: g/mol·(Å/fs)² in kcal/mol.
pub const MVV2E: f64 = 48.88821291 * 48.88821291;
/// Boltzmann's constant in kcal/mol/K (LAMMPS `real`).
pub const KB: f64 = 0.0019872067;
/// O–H bond length of SPC/E, Å.
pub const R_OH: f64 = 1.0;
/// H–O–H angle of SPC/E, degrees.
pub const THETA_HOH: f64 = 109.47;
/// Oxygen and hydrogen masses, g/mol.
pub const M_O: f64 = 15.9994;
/// Hydrogen mass, g/mol.
pub const M_H: f64 = 1.008;
/// Liquid water density, molecules per Å³ (0.998 g/cm³).
pub const WATER_DENSITY: f64 = 33.37e-3;
/// Bead mass of the chains (a CH₂ unit), g/mol.
pub const BEAD_MASS: f64 = 14.027;
/// Bond length of the chains, Å.
pub const BOND: f64 = 1.5;

/// splitmix64 (Steele, Lea, Flood 2014) with Box–Muller normals: small,
/// seeded, good enough for initial conditions.
///
/// ```
/// use geoshake_runtime::particles::generate::SplitMix64;
/// let mut r = SplitMix64::new(1);
/// let u = r.uniform();
/// assert!((0.0..1.0).contains(&u));
/// ```
#[derive(Clone, Debug)]
pub struct SplitMix64 {
    state: u64,
    spare: Option<f64>,
}

impl SplitMix64 {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        SplitMix64 {
            state: seed,
            spare: None,
        }
    }
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1) with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    /// A standard normal (Box–Muller, the second value kept for the next call).
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let t = 2.0 * std::f64::consts::PI * u2;
        self.spare = Some(r * t.sin());
        r * t.cos()
    }
    /// A uniformly distributed unit vector in R³.
    pub fn unit3(&mut self) -> [f64; 3] {
        loop {
            let v = [self.normal(), self.normal(), self.normal()];
            let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if n > 1e-12 {
                return [v[0] / n, v[1] / n, v[2] / n];
            }
        }
    }
}

/// n = nx·ny·nz with the three as close as possible (gen_data.py's factor3).
fn factor3(n: usize) -> [usize; 3] {
    let mut best = (usize::MAX, [n, 1, 1]);
    for nx in 1..=n {
        if !n.is_multiple_of(nx) {
            continue;
        }
        for ny in 1..=n / nx {
            if !(n / nx).is_multiple_of(ny) {
                continue;
            }
            let nz = n / nx / ny;
            let key = nx.max(ny).max(nz) - nx.min(ny).min(nz);
            if key < best.0 {
                best = (key, [nx, ny, nz]);
            }
        }
    }
    best.1
}

/// Maxwell–Boltzmann momenta at unit temperature (p_c ~ N(0, m)), with the
/// centre-of-mass motion removed. Not yet tangent to the constraints: use
/// [`Rattle::project`](super::Rattle::project), then [`set_temperature`].
fn thermal_momenta(rng: &mut SplitMix64, masses: &[f64]) -> Vec<f64> {
    let n = masses.len();
    let mut p = vec![0.0; 3 * n];
    let mut total = [0.0; 3];
    for (a, &m) in masses.iter().enumerate() {
        for c in 0..3 {
            // v ~ N(0, 1/m) as gen_data.py draws it; p = m v.
            let v = rng.normal() / m.sqrt();
            p[3 * a + c] = m * v;
            total[c] += m * v;
        }
    }
    let mtot: f64 = masses.iter().sum();
    for (a, &m) in masses.iter().enumerate() {
        for c in 0..3 {
            p[3 * a + c] -= m * total[c] / mtot;
        }
    }
    p
}

/// The periodic box [nx·a, ny·a, nz·a] (Å) that the lattice of
/// [`water`]`(n, _)` fills: nx·ny·nz = n with the three as close as
/// possible, and a = (1/[`WATER_DENSITY`])^(1/3), so that the box holds
/// liquid water's density. The oxygens sit at the cell centres
/// ((i + ½)·a, …); the hydrogens, 1 Å away, may lie outside it.
///
/// ```
/// use geoshake_runtime::particles::generate;
/// let [lx, ly, lz] = generate::water_box(1000);
/// assert!(lx == ly && ly == lz && (lx - 31.06).abs() < 0.01);
/// let n = 1000.0 / (lx * ly * lz);
/// assert!((n - generate::WATER_DENSITY).abs() < 1e-12);
/// ```
pub fn water_box(n: usize) -> [f64; 3] {
    let a = (1.0 / WATER_DENSITY).cbrt();
    factor3(n.max(1)).map(|k| k as f64 * a)
}

/// A box of n rigid SPC/E-geometry waters (O–H 1.0 Å, H–O–H 109.47°) on a
/// simple cubic lattice at 33.37·10⁻³ molecules/Å³ filling the periodic
/// box [`water_box`]`(n)`, random orientations;
/// one constraint family `bond` of 3n distance constraints (O–H1, O–H2,
/// H1–H2, the last at 2 R sin(θ/2), LAMMPS' `shake ... b 1 a 1`).
/// Particles are O, H1, H2 per molecule. Momenta are Maxwell–Boltzmann in
/// shape only (v ~ N(0, 1/m) in Å/fs, as LAMMPS' `gen_data.py` draws them:
/// about 10⁶ K, far too fast for a step of 2 fs) and not yet projected:
/// use [`Rattle::project`](super::Rattle::project), then
/// [`set_temperature`].
///
/// ```
/// let (sys, st) = geoshake_runtime::particles::generate::water(10, 3).unwrap();
/// assert_eq!((sys.particles(), sys.constraints(), st.q().len()), (30, 30, 90));
/// ```
pub fn water(n: usize, seed: u64) -> Result<(ParticleSystem, ParticleState), TopologyError> {
    let mut rng = SplitMix64::new(seed);
    let [nx, ny, nz] = factor3(n.max(1));
    let a = (1.0 / WATER_DENSITY).cbrt();
    let th = THETA_HOH.to_radians();
    let (c, s) = ((th / 2.0).cos(), (th / 2.0).sin());
    let mut q = Vec::with_capacity(9 * n);
    let mut masses = Vec::with_capacity(3 * n);
    let mut bonds = Table::with_capacity(2, 1, 3 * n);
    let hh = 2.0 * R_OH * s;
    let mut k = 0;
    for ix in 0..nx {
        for iy in 0..ny {
            for iz in 0..nz {
                if k == n {
                    break;
                }
                let o = [
                    (ix as f64 + 0.5) * a,
                    (iy as f64 + 0.5) * a,
                    (iz as f64 + 0.5) * a,
                ];
                let u = rng.unit3();
                let mut w = rng.unit3();
                let wu: f64 = (0..3).map(|i| w[i] * u[i]).sum();
                for i in 0..3 {
                    w[i] -= wu * u[i];
                }
                let wn = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
                for wi in &mut w {
                    *wi /= wn;
                }
                q.extend_from_slice(&o);
                for sign in [1.0, -1.0] {
                    for i in 0..3 {
                        q.push(o[i] + R_OH * (c * u[i] + sign * s * w[i]));
                    }
                }
                masses.extend_from_slice(&[M_O, M_H, M_H]);
                let b = 3 * k;
                bonds.push(&[b, b + 1], &[R_OH])?;
                bonds.push(&[b, b + 2], &[R_OH])?;
                bonds.push(&[b + 1, b + 2], &[hh])?;
                k += 1;
            }
        }
    }
    let p = thermal_momenta(&mut rng, &masses);
    let system = ParticleSystem::new(3, masses)?.with_constraints("bond", Distance::<3>, bonds)?;
    Ok((system, ParticleState::new(q, p)))
}

/// A freely jointed chain of `links` + 1 beads (mass 14.027 g/mol), a random
/// walk of bond 1.5 Å, every bond constrained (family `bond`, member k joins
/// beads k and k + 1). Momenta as for [`water`]: scale them with
/// [`set_temperature`] after projecting.
///
/// ```
/// let (sys, _) = geoshake_runtime::particles::generate::chain(10, 3).unwrap();
/// assert_eq!((sys.particles(), sys.constraints()), (11, 10));
/// ```
pub fn chain(links: usize, seed: u64) -> Result<(ParticleSystem, ParticleState), TopologyError> {
    let (system, state, _) = chain_parts(links, seed)?;
    Ok((system, state))
}

/// The chain of [`chain`] with harmonic springs between next-nearest
/// neighbours (beads k, k + 2; k = 300 kcal/mol/Å², r₀ the initial
/// distance, so the chain starts at rest in V and the forces grow with the
/// thermal motion), family `bend`.
///
/// ```
/// let (sys, _) = geoshake_runtime::particles::generate::chain_with_springs(10, 3).unwrap();
/// assert_eq!(sys.potential_families().len(), 1);
/// ```
pub fn chain_with_springs(
    links: usize,
    seed: u64,
) -> Result<(ParticleSystem, ParticleState), TopologyError> {
    let (system, state, n) = chain_parts(links, seed)?;
    let mut springs = Table::with_capacity(2, 2, n.saturating_sub(2));
    let k = 300.0 / MVV2E;
    let q = state.q();
    for i in 0..n.saturating_sub(2) {
        let r0 = (0..3)
            .map(|c| (q[3 * i + c] - q[3 * (i + 2) + c]).powi(2))
            .sum::<f64>()
            .sqrt();
        springs.push(&[i, i + 2], &[k, r0])?;
    }
    Ok((system.with_potential("bend", Spring::<3>, springs)?, state))
}

fn chain_parts(
    links: usize,
    seed: u64,
) -> Result<(ParticleSystem, ParticleState, usize), TopologyError> {
    let mut rng = SplitMix64::new(seed);
    let n = links + 1;
    let mut q = Vec::with_capacity(3 * n);
    q.extend_from_slice(&[0.0; 3]);
    let mut bonds = Table::with_capacity(2, 1, links);
    for k in 0..links {
        let u = rng.unit3();
        for i in 0..3 {
            let x = q[3 * k + i] + BOND * u[i];
            q.push(x);
        }
        bonds.push(&[k, k + 1], &[BOND])?;
    }
    let masses = vec![BEAD_MASS; n];
    let p = thermal_momenta(&mut rng, &masses);
    let system = ParticleSystem::new(3, masses)?.with_constraints("bond", Distance::<3>, bonds)?;
    Ok((system, ParticleState::new(q, p), n))
}

/// Scales the momenta to temperature T (K) with the degrees of freedom
/// LAMMPS' `compute temp` counts for a constrained system: 3n − 3 − m.
/// Scaling keeps G M⁻¹ p = 0, so it may follow the projection.
///
/// ```
/// use geoshake_runtime::particles::generate;
/// let (sys, mut st) = generate::water(10, 3).unwrap();
/// generate::set_temperature(&sys, &mut st, 300.0);
/// assert!((generate::temperature(&sys, &st) - 300.0).abs() < 1e-9);
/// ```
pub fn set_temperature(system: &ParticleSystem, state: &mut ParticleState, kelvin: f64) {
    let t = temperature(system, state);
    if t > 0.0 {
        let f = (kelvin / t).sqrt();
        for p in state.p_mut() {
            *p *= f;
        }
    }
}

/// The kinetic temperature 2 KE / (dof · k_B), dof = n·D − D − m.
pub fn temperature(system: &ParticleSystem, state: &ParticleState) -> f64 {
    let d = system.dim();
    let mut two_ke = 0.0;
    for (a, w) in system.inverse_masses().iter().enumerate() {
        for c in 0..d {
            let p = state.p[a * d + c];
            two_ke += p * p * w;
        }
    }
    let dof = (system.particles() * d) as f64 - d as f64 - system.constraints() as f64;
    two_ke * MVV2E / (dof * KB)
}

/// The largest relative bond-length error | |x_a − x_b| − l | / l over the
/// distance constraints of a family whose rows are (a, b; l): what LAMMPS
/// reports, measured from the state alone (not from the solver's residual).
///
/// ```
/// use geoshake_runtime::particles::generate;
/// let (sys, st) = generate::chain(10, 3).unwrap();
/// let t = sys.constraint_families()[0].table();
/// assert!(generate::max_rel_length_error(t, 3, st.q()) < 1e-15);
/// ```
pub fn max_rel_length_error(table: &Table, dim: usize, q: &[f64]) -> f64 {
    let mut worst = 0.0f64;
    for k in 0..table.len() {
        let ij = table.particles(k);
        let (i, j) = (ij[0] as usize * dim, ij[1] as usize * dim);
        let mut s = 0.0;
        for c in 0..dim {
            let r = q[i + c] - q[j + c];
            s += r * r;
        }
        let l = table.data(k)[0];
        let e = ((s.sqrt() - l) / l).abs();
        if crate::tolerance::worse(e, worst) {
            worst = e;
        }
    }
    worst
}
