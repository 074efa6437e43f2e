//! Two molecules whose constraints form connected clusters, the case
//! LAMMPS' `fix shake` refuses ("Shake clusters are connected") and `fix
//! rattle` with it: a benzene-like ring (a cycle in the constraint graph)
//! and a branched united-atom alkane (a tree with branch points of degree
//! three). Each is rigid where real molecules are stiff and free where
//! they are soft: bonds and angles are distance constraints, torsions and
//! the ring's puckering are not.
//!
//! Units: LAMMPS `real` (g/mol, Å, fs; energies in g/mol·(Å/fs)², kcal/mol
//! after multiplying by `generate::MVV2E`).

use geoshake::runtime::particles::generate::{SplitMix64, MVV2E};
use geoshake::runtime::particles::stencils::{Distance, Spring};
use geoshake::runtime::particles::{ParticleState, ParticleSystem, Table, TopologyError};

/// Carbon and hydrogen masses (g/mol), and a CH₃/CH₂/CH united atom's.
const M_C: f64 = 12.011;
const M_H: f64 = 1.008;
const M_CH: f64 = 14.027;
/// Aromatic C–C and C–H bond lengths, Å; an alkane's C–C.
const R_CC: f64 = 1.39;
const R_CH: f64 = 1.09;
const R_ALKANE: f64 = 1.54;
/// Stiffness of the springs across the ring that keep it flat, kcal/mol/Å².
const K_FLAT: f64 = 40.0;

/// One molecule: masses, coordinates (about its centre), the constrained
/// pairs and the springs (pair, k, r0), in the molecule's own numbering.
pub struct Molecule {
    pub masses: Vec<f64>,
    pub q: Vec<[f64; 3]>,
    pub bonds: Vec<[usize; 2]>,
    pub springs: Vec<([usize; 2], f64)>,
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt()
}

/// A flat hexagon of six carbons, each with its hydrogen pointing out.
/// Constrained: the 6 C–C and 6 C–H bonds, the C–C distances across the
/// three alternate carbons 0, 2, 4 (a rigid triangle, with carbons 1, 3, 5
/// on it as hinged "ears"), and each H's distance to the next carbon
/// (fixing its C–C–H angle): 21 constraints, independent while the ring is
/// in one piece (in the flat ring they are the 21 in-plane internal
/// coordinates), which leaves the 9 out-of-plane hinges free. The C–C
/// distances across the ring (1–4) are springs with rest length the flat
/// ring's: they keep it nearly flat, as its π system does.
pub fn benzene() -> Molecule {
    let mut q = Vec::with_capacity(12);
    for r in [R_CC, R_CC + R_CH] {
        for k in 0..6 {
            let a = k as f64 * std::f64::consts::FRAC_PI_3;
            q.push([r * a.cos(), r * a.sin(), 0.0]);
        }
    }
    let mut bonds = Vec::new();
    for k in 0..6 {
        bonds.push([k, (k + 1) % 6]); // C–C
        bonds.push([k, k + 6]); // C–H
        bonds.push([k + 6, (k + 1) % 6]); // H to the next carbon: the angle
    }
    bonds.extend([[0, 2], [2, 4], [4, 0]]);
    let springs = (0..3).map(|k| ([k, k + 3], K_FLAT / MVV2E)).collect();
    let mut masses = vec![M_C; 6];
    masses.extend([M_H; 6]);
    Molecule {
        masses,
        q,
        bonds,
        springs,
    }
}

/// 3-ethyl-2-methylpentane's carbon skeleton without hydrogens (united
/// atoms), a tree: backbone 0–1–2–3–4, a methyl 5 on carbon 1, an ethyl
/// 6–7 on carbon 3. Every bond and every bond angle (the distance between
/// two neighbours of a carbon) is constrained: 7 + 8 = 15 constraints on
/// 8 atoms, in one cluster; the three torsions about 1–2, 2–3 and 3–6 are
/// free. The bond directions are a regular tetrahedron's, so every angle
/// is 109.47°.
pub fn branched() -> Molecule {
    let s = 1.0 / 3f64.sqrt();
    let t = [[s, s, s], [s, -s, -s], [-s, s, -s], [-s, -s, s]];
    let neg = |v: [f64; 3]| [-v[0], -v[1], -v[2]];
    let at = |from: [f64; 3], dir: [f64; 3]| {
        [
            from[0] + R_ALKANE * dir[0],
            from[1] + R_ALKANE * dir[1],
            from[2] + R_ALKANE * dir[2],
        ]
    };
    let c1 = [0.0; 3];
    let c0 = at(c1, t[0]);
    let c2 = at(c1, t[1]);
    let c5 = at(c1, t[2]);
    let c3 = at(c2, neg(t[0]));
    let c4 = at(c3, t[1]);
    let c6 = at(c3, t[2]);
    let c7 = at(c6, neg(t[0]));
    let q = vec![c0, c1, c2, c3, c4, c5, c6, c7];
    let tree: [[usize; 2]; 7] = [[0, 1], [1, 2], [2, 3], [3, 4], [1, 5], [3, 6], [6, 7]];
    let mut bonds = tree.to_vec();
    // Angles: every pair of neighbours of each atom.
    for centre in 0..8 {
        let nb: Vec<usize> = tree
            .iter()
            .filter_map(|&[a, b]| match () {
                _ if a == centre => Some(b),
                _ if b == centre => Some(a),
                _ => None,
            })
            .collect();
        for i in 0..nb.len() {
            for j in i + 1..nb.len() {
                bonds.push([nb[i], nb[j]]);
            }
        }
    }
    Molecule {
        masses: vec![M_CH; 8],
        q,
        bonds,
        springs: Vec::new(),
    }
}

/// A random rotation (a uniform unit quaternion).
fn rotation(rng: &mut SplitMix64) -> [[f64; 3]; 3] {
    let mut w = [rng.normal(), rng.normal(), rng.normal(), rng.normal()];
    let n = w.iter().map(|x| x * x).sum::<f64>().sqrt();
    w.iter_mut().for_each(|x| *x /= n);
    let [a, b, c, d] = w;
    [
        [
            a * a + b * b - c * c - d * d,
            2.0 * (b * c - a * d),
            2.0 * (b * d + a * c),
        ],
        [
            2.0 * (b * c + a * d),
            a * a - b * b + c * c - d * d,
            2.0 * (c * d - a * b),
        ],
        [
            2.0 * (b * d - a * c),
            2.0 * (c * d + a * b),
            a * a - b * b - c * c + d * d,
        ],
    ]
}

/// `n_rings` benzene-like rings and `n_branched` branched alkanes, each
/// randomly oriented on a cubic lattice of spacing 12 Å (they do not
/// interact: add forces with `ParticleSystem::with_forces`), with thermal
/// momenta to be projected and scaled. Constraint lengths are the built
/// geometry's own, so the positions are on M to round-off. Returns the
/// system, the state and the index of each molecule's first atom (and one
/// past the last).
pub fn mixture(
    n_rings: usize,
    n_branched: usize,
    seed: u64,
) -> Result<(ParticleSystem, ParticleState, Vec<usize>), TopologyError> {
    let mut rng = SplitMix64::new(seed);
    let kinds: Vec<Molecule> = (0..n_rings)
        .map(|_| benzene())
        .chain((0..n_branched).map(|_| branched()))
        .collect();
    let side = ((kinds.len() as f64).cbrt().ceil() as usize).max(1);
    let (mut masses, mut q, mut starts) = (Vec::new(), Vec::new(), vec![0]);
    let mut bonds = Table::new(2, 1);
    let mut springs = Table::new(2, 2);
    for (i, mol) in kinds.iter().enumerate() {
        let base = masses.len();
        let r = rotation(&mut rng);
        let centre = [
            (i % side) as f64,
            ((i / side) % side) as f64,
            (i / side / side) as f64,
        ];
        let x: Vec<[f64; 3]> = mol
            .q
            .iter()
            .map(|a| {
                let mut y = [0.0; 3];
                for (c, (yi, row)) in y.iter_mut().zip(&r).enumerate() {
                    *yi = 12.0 * centre[c] + (0..3).map(|k| row[k] * a[k]).sum::<f64>();
                }
                y
            })
            .collect();
        for &[a, b] in &mol.bonds {
            bonds.push(&[base + a, base + b], &[dist(x[a], x[b])])?;
        }
        for &([a, b], k) in &mol.springs {
            springs.push(&[base + a, base + b], &[k, dist(x[a], x[b])])?;
        }
        masses.extend_from_slice(&mol.masses);
        q.extend(x.iter().flatten());
        starts.push(masses.len());
    }
    let kt = 1.0;
    let p = masses
        .iter()
        .flat_map(|m: &f64| {
            let s = (m * kt).sqrt();
            [s * rng.normal(), s * rng.normal(), s * rng.normal()]
        })
        .collect();
    let mut system =
        ParticleSystem::new(3, masses)?.with_constraints("bond", Distance::<3>, bonds)?;
    if !springs.is_empty() {
        system = system.with_potential("flat", Spring::<3>, springs)?;
    }
    Ok((system, ParticleState::new(q, p), starts))
}
