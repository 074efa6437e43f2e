//! SPC/E water's non-bonded forces, written as a user of `geoshake` writes
//! the force field they bring ([`ForceField`]): charges and Lennard-Jones
//! between molecules, a cut-off, periodic boundaries and a cell list.
//! `examples/water_md/main.rs` runs it; `tests/suite/water_md.rs` checks it
//! (it includes this file).
//!
//! The model (Berendsen, Grigera, Straatsma 1987), in LAMMPS `real` units
//! (Å, kcal/mol, charges in e): q_O = −0.8476, q_H = +0.4238, Lennard-Jones
//! between oxygens only (σ = 3.166 Å, ε = 0.1553 kcal/mol), no interaction
//! within a molecule (its geometry is held by the constraints). Atoms are
//! O, H1, H2 per molecule, as `generate::water` lays them out: atom a is an
//! oxygen when a mod 3 = 0 and belongs to molecule ⌊a/3⌋.
//!
//! Both pair potentials are *shifted-force* at the cut-off r_c: with u the
//! bare potential,
//!
//!   V(r) = u(r) − u(r_c) − (r − r_c) u′(r_c)  for r < r_c,  0 beyond,
//!
//! so V and the force −V′ are continuous and vanish at r_c. For Coulomb,
//! u = k q_i q_j / r gives V = k q_i q_j [1/r − 1/r_c + (r − r_c)/r_c²] and
//! −V′ = k q_i q_j [1/r² − 1/r_c²]. Only V″ jumps at r_c: a force that jumps
//! there (plain truncation, or shifting V alone) would kick every pair that
//! crosses r_c and make the energy of a Störmer–Verlet run drift, while a
//! continuous force keeps its error O(h²) and bounded.
//!
//! Periodic boundaries with the minimum image: coordinates are wrapped into
//! the box, and each pair is taken at its nearest image, d = x_i − x_j
//! with every component in [−L/2, L/2] (the cell list gets it by shifting
//! a neighbour cell across the boundary by ±L). Only the nearest image
//! lies within r_c when r_c ≤ L/2 on every side ([`Spce::new`] refuses a
//! smaller box).
//!
//! The pairs within r_c come from a cell list rebuilt at every call: the
//! box is cut into ⌊L/r_c⌋ cells per side (each at least r_c wide), so a
//! pair within r_c lies in one cell or in two neighbouring ones. Each cell
//! meets itself and 13 of its 26 neighbours (one of every ± pair of
//! offsets); with at least 3 cells per side the 26 are distinct and every
//! pair of cells is visited once. With fewer, neighbours coincide, and the
//! field loops over all pairs instead. Rebuilding costs O(n), a small part
//! of the pair loop, and needs no skin or displacement check.

use geoshake::runtime::particles::generate::{KB, MVV2E};
use geoshake::runtime::particles::ForceField;

/// Coulomb's constant k = 1/(4π ε₀) in kcal·Å/(mol·e²) (LAMMPS `real`).
pub const COULOMB: f64 = 332.06371;
/// The oxygen's charge, e.
pub const Q_O: f64 = -0.8476;
/// A hydrogen's charge, e.
pub const Q_H: f64 = 0.4238;
/// Lennard-Jones σ between oxygens, Å.
pub const SIGMA: f64 = 3.166;
/// Lennard-Jones ε between oxygens, kcal/mol.
pub const EPSILON: f64 = 0.1553;

/// The 13 neighbour offsets (dx, dy, dz) ∈ {−1, 0, 1}³ that are
/// lexicographically positive: of every offset and its opposite, one.
const HALF_SHELL: [[isize; 3]; 13] = [
    [0, 0, 1],
    [0, 1, -1],
    [0, 1, 0],
    [0, 1, 1],
    [1, -1, -1],
    [1, -1, 0],
    [1, -1, 1],
    [1, 0, -1],
    [1, 0, 0],
    [1, 0, 1],
    [1, 1, -1],
    [1, 1, 0],
    [1, 1, 1],
];

/// The SPC/E force field in a periodic box with a cut-off: energies in
/// kcal/mol and forces in kcal/mol/Å from [`energy_forces`](Self::energy_forces);
/// as a [`ForceField`] in the integrator's units, g/mol·Å²/fs²
/// (1 kcal/mol = 1/`MVV2E` of them).
#[derive(Clone)]
pub struct Spce {
    box_len: [f64; 3],
    cutoff: f64,
    inv_cutoff: f64,
    /// Cells per side; all pairs when a side has fewer than 3.
    cells: [usize; 3],
    /// k q_i q_j by kind (0 oxygen, 1 hydrogen).
    kqq: [[f64; 2]; 2],
    /// The shifted-force Lennard-Jones constants: u(r_c) and −u′(r_c).
    lj_at_cut: f64,
    lj_force_at_cut: f64,
    // Work arrays, kept between calls: atoms sorted by cell, their wrapped
    // positions and the forces on them in that order; wrapped positions
    // with their cells in atom order.
    start: Vec<usize>,
    atom: Vec<usize>,
    x: Vec<[f64; 3]>,
    wrapped: Vec<([f64; 3], usize)>,
    f: Vec<[f64; 3]>,
    /// Σ_pairs 2 tr ∇²φ of the last call, kcal/mol/Å² (see
    /// [`translational_terms`](Spce::translational_terms)).
    laplacian: f64,
}

impl Spce {
    /// The field in the box [L_x, L_y, L_z] (Å) with cut-off r_c (Å).
    /// Refuses r_c not finite or ≤ 0, and a side not finite or shorter
    /// than 2 r_c (the minimum image would miss pairs).
    pub fn new(box_len: [f64; 3], cutoff: f64) -> Result<Self, String> {
        if !(cutoff.is_finite() && cutoff > 0.0) {
            return Err(format!(
                "the cut-off must be finite and positive, not {cutoff}"
            ));
        }
        if let Some(l) = box_len
            .iter()
            .find(|&&l| !l.is_finite() || l < 2.0 * cutoff)
        {
            return Err(format!(
                "a box side of {l:.3} Å: the minimum image needs finite sides of \
                 at least twice the cut-off, 2 × {cutoff} Å"
            ));
        }
        let cells = box_len.map(|l| (l / cutoff).floor() as usize);
        let (sr6, rc) = ((SIGMA / cutoff).powi(6), cutoff);
        let q = [Q_O, Q_H];
        Ok(Spce {
            box_len,
            cutoff,
            inv_cutoff: 1.0 / cutoff,
            cells,
            kqq: [0, 1].map(|i| [0, 1].map(|j| COULOMB * q[i] * q[j])),
            lj_at_cut: 4.0 * EPSILON * (sr6 * sr6 - sr6),
            lj_force_at_cut: 24.0 * EPSILON * (2.0 * sr6 * sr6 - sr6) / rc,
            start: Vec::new(),
            atom: Vec::new(),
            x: Vec::new(),
            wrapped: Vec::new(),
            f: Vec::new(),
            laplacian: 0.0,
        })
    }

    /// The cells per side, or `None` when the field loops over all pairs
    /// (a side with fewer than 3).
    pub fn cells(&self) -> Option<[usize; 3]> {
        self.cells.iter().all(|&n| n >= 3).then_some(self.cells)
    }

    /// V(q) in kcal/mol, with the forces −∇V (kcal/mol/Å) added into `f`:
    /// by the cell list when there are at least 3 cells per side, else by
    /// all pairs. `q` and `f` hold x_a's coordinate c at `3 a + c`.
    // (This and the next are what tests/suite/water_md.rs checks; the run
    // reaches the same code through `ForceField`.)
    #[allow(dead_code)]
    pub fn energy_forces(&mut self, q: &[f64], f: &mut [f64]) -> f64 {
        self.compute(q, f, 1.0, self.cells().is_some())
    }

    /// As [`energy_forces`](Self::energy_forces), always over all pairs:
    /// the reference the cell list is tested against.
    #[allow(dead_code)]
    pub fn energy_forces_all_pairs(&mut self, q: &[f64], f: &mut [f64]) -> f64 {
        self.compute(q, f, 1.0, false)
    }

    /// The two sums of the translational configurational temperature at q,
    /// in kcal/mol/Å units: Σ_i |F_i|² over the molecules, F_i the total
    /// force on molecule i (kcal²/mol²/Å²), and Σ_i ∇²_{R_i} V, the
    /// Laplacian of V in molecule i's centre of mass moved rigidly
    /// (kcal/mol/Å²).
    ///
    /// Why they estimate the temperature: rigid molecules' configurations
    /// are their centres R_i and orientations, and the measure constrained
    /// dynamics samples at temperature T (the Boltzmann factor e^{−V/k_B T}
    /// times M's surface measure, whose density det(G M⁻¹ Gᵀ)^{1/2} is
    /// constant for rigid molecules) is flat in each R_i. Integrating by
    /// parts in R_i (V periodic, so no boundary term):
    ///
    ///   ⟨|∇_{R_i} V|²⟩ = k_B T ⟨∇²_{R_i} V⟩,  ∇_{R_i} V = −F_i,
    ///
    /// so k_B T = ⟨Σ_i |F_i|²⟩ / ⟨Σ_i ∇²_{R_i} V⟩ (Jepps, Ayton and Evans,
    /// Phys. Rev. E 62, 4757 (2000), with the vector field B = ∇_R V). For
    /// pair terms φ_ab(|x_a − x_b|) between molecules, moving i rigidly
    /// moves each of its atoms by the same vector, so ∇²_{R_i} V =
    /// Σ_{a∈i} Σ_{b∉i} tr ∇²φ_ab and Σ_i ∇²_{R_i} V = 2 Σ_pairs (φ″ + 2φ′/r).
    /// The identity needs V ∈ C¹ with φ″ piecewise continuous: the
    /// shifted-force cut-off is exactly that (φ′(r_c) = 0, φ″ jumps).
    #[allow(dead_code)]
    pub fn translational_terms(&mut self, q: &[f64]) -> (f64, f64) {
        let mut f = vec![0.0; q.len()];
        self.energy_forces(q, &mut f);
        let force_squared = f
            .chunks_exact(9)
            .map(|m| {
                let s = [0, 1, 2].map(|c| m[c] + m[3 + c] + m[6 + c]);
                dot(s, s)
            })
            .sum();
        (force_squared, self.laplacian)
    }

    /// V and −∇V, both times `scale`, the forces added into `f`; Σ_pairs
    /// 2 tr ∇²φ (unscaled) into `self.laplacian`.
    fn compute(&mut self, q: &[f64], f: &mut [f64], scale: f64, cells: bool) -> f64 {
        assert!(
            q.len().is_multiple_of(9) && f.len() == q.len(),
            "q and f hold 3 coordinates of 3 atoms per molecule"
        );
        let n = q.len() / 3;
        self.laplacian = 0.0;
        let v = if cells {
            self.sort_into_cells(q);
            self.cell_pairs()
        } else {
            let l = self.box_len;
            self.atom.clear();
            self.atom.extend(0..n);
            self.x.clear();
            self.x.extend((0..n).map(|a| wrap(l, &q[3 * a..3 * a + 3])));
            self.all_pairs()
        };
        for (k, &a) in self.atom.iter().enumerate() {
            for c in 0..3 {
                f[3 * a + c] += scale * self.f[k][c];
            }
        }
        scale * v
    }

    /// Counting sort of the atoms by cell: cell c holds the atoms
    /// `atom[start[c]..start[c + 1]]`, at `x[start[c]..start[c + 1]]`.
    fn sort_into_cells(&mut self, q: &[f64]) {
        let n = q.len() / 3;
        let [nx, ny, nz] = self.cells;
        let mut wrapped = std::mem::take(&mut self.wrapped);
        wrapped.clear();
        wrapped.extend((0..n).map(|a| {
            let x = wrap(self.box_len, &q[3 * a..3 * a + 3]);
            // (x_c/L_c·m may round up to m for x_c just below L_c.)
            let k = |c: usize, m: usize| ((x[c] / self.box_len[c] * m as f64) as usize).min(m - 1);
            (x, (k(0, nx) * ny + k(1, ny)) * nz + k(2, nz))
        }));
        let cells = nx * ny * nz;
        let start = &mut self.start;
        start.clear();
        start.resize(cells + 1, 0);
        // start[c] counts up to the end of cell c, then counts down to its
        // beginning as the cell is filled from its end.
        for &(_, c) in &wrapped {
            start[c] += 1;
        }
        for c in 1..=cells {
            start[c] += start[c - 1];
        }
        self.atom.resize(n, 0);
        self.x.resize(n, [0.0; 3]);
        for (a, &(x, c)) in wrapped.iter().enumerate().rev() {
            start[c] -= 1;
            self.atom[start[c]] = a;
            self.x[start[c]] = x;
        }
        self.wrapped = wrapped;
    }

    /// V over the pairs of the cell list, forces into `self.f` (in cell
    /// order).
    fn cell_pairs(&mut self) -> f64 {
        let [nx, ny, nz] = self.cells;
        let (l, rc2) = (self.box_len, self.cutoff * self.cutoff);
        let mut f = std::mem::take(&mut self.f);
        f.clear();
        f.resize(self.atom.len(), [0.0; 3]);
        let mut v = 0.0;
        for ix in 0..nx {
            for iy in 0..ny {
                for iz in 0..nz {
                    let home = (ix * ny + iy) * nz + iz;
                    let (c0, c1) = (self.start[home], self.start[home + 1]);
                    for i in c0..c1 {
                        for j in i + 1..c1 {
                            let d = sub(self.x[i], self.x[j]);
                            let r2 = dot(d, d);
                            if r2 < rc2 {
                                v += self.pair(i, j, d, r2, &mut f);
                            }
                        }
                    }
                    for o in &HALF_SHELL {
                        // The neighbour's indices, and the shift ±L that
                        // brings its image beside this cell where an
                        // offset leaves the box.
                        let mut k = [0; 3];
                        let mut shift = [0.0; 3];
                        for (s, (i, m)) in [(ix, nx), (iy, ny), (iz, nz)].into_iter().enumerate() {
                            let t = i as isize + o[s];
                            k[s] = t.rem_euclid(m as isize) as usize;
                            shift[s] = l[s] * t.div_euclid(m as isize) as f64;
                        }
                        let near = (k[0] * ny + k[1]) * nz + k[2];
                        let (d0, d1) = (self.start[near], self.start[near + 1]);
                        for i in c0..c1 {
                            // x_i − (x_j + shift) = (x_i − shift) − x_j.
                            let xi = sub(self.x[i], shift);
                            for j in d0..d1 {
                                let d = sub(xi, self.x[j]);
                                let r2 = dot(d, d);
                                if r2 < rc2 {
                                    v += self.pair(i, j, d, r2, &mut f);
                                }
                            }
                        }
                    }
                }
            }
        }
        self.f = f;
        v
    }

    /// V over all pairs with the minimum image, forces into `self.f`.
    fn all_pairs(&mut self) -> f64 {
        let n = self.atom.len();
        let (l, rc2) = (self.box_len, self.cutoff * self.cutoff);
        let mut f = std::mem::take(&mut self.f);
        f.clear();
        f.resize(n, [0.0; 3]);
        let mut v = 0.0;
        for i in 0..n {
            for j in i + 1..n {
                let mut d = sub(self.x[i], self.x[j]);
                for c in 0..3 {
                    // Both wrapped into [0, L), so d_c ∈ (−L, L) and
                    // 2 d_c / L truncates to the one shift, −1, 0 or 1,
                    // that brings d_c into [−L/2, L/2] (a conversion, not
                    // a branch the processor would mispredict).
                    d[c] -= l[c] * ((2.0 * d[c] / l[c]) as i32) as f64;
                }
                let r2 = dot(d, d);
                if r2 < rc2 {
                    v += self.pair(i, j, d, r2, &mut f);
                }
            }
        }
        self.f = f;
        v
    }

    /// The pair (i, j) of the sorted arrays at separation d = x_i − x_j,
    /// r² = |d|² < r_c²: its energy, with its forces added into `f[i]` and
    /// `f[j]` and 2 tr ∇²φ = 2 (φ″ + 2φ′/r) into `self.laplacian`. Zero
    /// within a molecule.
    #[inline]
    fn pair(&mut self, i: usize, j: usize, d: [f64; 3], r2: f64, f: &mut [[f64; 3]]) -> f64 {
        let (a, b) = (self.atom[i], self.atom[j]);
        if a / 3 == b / 3 {
            return 0.0;
        }
        let (r, rc, inv_rc) = (r2.sqrt(), self.cutoff, self.inv_cutoff);
        // One division per pair: the rest are products.
        let inv_r = 1.0 / r;
        let inv_r2 = inv_r * inv_r;
        let kqq = self.kqq[usize::from(a % 3 != 0)][usize::from(b % 3 != 0)];
        // V and −V′(r)/r, the factor of d in the force on i.
        let mut v = kqq * (inv_r - inv_rc + (r - rc) * inv_rc * inv_rc);
        let mut s = kqq * (inv_r2 - inv_rc * inv_rc) * inv_r;
        // Coulomb's tr ∇²φ: φ″ = 2k q_i q_j/r³ and 2φ′/r = 2k q_i q_j
        // (−1/r³ + 1/(r r_c²)), the 1/r³ cancelling (1/r is harmonic).
        let mut trace = 2.0 * kqq * inv_r * inv_rc * inv_rc;
        if a % 3 == 0 && b % 3 == 0 {
            let sr2 = SIGMA * SIGMA * inv_r2;
            let sr6 = sr2 * sr2 * sr2;
            v += 4.0 * EPSILON * (sr6 * sr6 - sr6) - self.lj_at_cut
                + (r - rc) * self.lj_force_at_cut;
            let lj_s =
                (24.0 * EPSILON * (2.0 * sr6 * sr6 - sr6) * inv_r - self.lj_force_at_cut) * inv_r;
            s += lj_s;
            // φ″ = u″ = 4ε(156 (σ/r)¹² − 42 (σ/r)⁶)/r², and 2φ′/r = −2s.
            trace += 4.0 * EPSILON * (156.0 * sr6 * sr6 - 42.0 * sr6) * inv_r2 - 2.0 * lj_s;
        }
        self.laplacian += 2.0 * trace;
        for c in 0..3 {
            f[i][c] += s * d[c];
            f[j][c] -= s * d[c];
        }
        v
    }
}

/// The temperature ⟨Σ|F_i|²⟩ / (k_B ⟨Σ∇²V⟩) of samples of
/// [`Spce::translational_terms`] (K), and its standard error from the
/// spread of the same ratio over 10 consecutive batches (NaN with fewer
/// than 20 samples): batches much longer than the samples' correlation time
/// are nearly independent, so the 10 batch ratios scatter like 10
/// independent draws.
#[allow(dead_code)]
pub fn configurational_temperature(samples: &[(f64, f64)]) -> (f64, f64) {
    let ratio = |s: &[(f64, f64)]| {
        let (f2, lap) = s
            .iter()
            .fold((0.0, 0.0), |(a, b), &(f2, lap)| (a + f2, b + lap));
        f2 / lap / KB
    };
    let t = ratio(samples);
    if samples.len() < 20 {
        return (t, f64::NAN);
    }
    let batches: Vec<f64> = samples
        .chunks(samples.len() / 10)
        .take(10)
        .map(ratio)
        .collect();
    let mean = batches.iter().sum::<f64>() / 10.0;
    let var = batches.iter().map(|b| (b - mean).powi(2)).sum::<f64>() / 9.0;
    (t, (var / 10.0).sqrt())
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// x wrapped into [0, L) on every side of the box `l`.
fn wrap(l: [f64; 3], x: &[f64]) -> [f64; 3] {
    [0, 1, 2].map(|c| {
        let w = x[c] - l[c] * (x[c] / l[c]).floor();
        // A coordinate just below a multiple of L rounds to exactly L.
        if w >= l[c] {
            w - l[c]
        } else {
            w
        }
    })
}

/// The integrator's units: V in g/mol·Å²/fs² (kcal/mol / `MVV2E`), forces
/// in g/mol·Å/fs².
impl ForceField for Spce {
    fn forces(&mut self, q: &[f64], f: &mut [f64]) -> f64 {
        self.compute(q, f, 1.0 / MVV2E, self.cells().is_some())
    }
}
