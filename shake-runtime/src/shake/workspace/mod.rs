//! SHAKE's buffers and the structure it precomputes once per system: the
//! band of its Jacobian (predicted from the declared pattern of g_z and the
//! Hessian's structure) and the band of N.

mod classical;

pub(crate) use classical::{packed_jacobian, Buffers};

use crate::fibre::FibreFlow;
use crate::linalg::Band;
use crate::system::ConstrainedSystem;

/// All buffers of a SHAKE/RATTLE step, allocated once.
///
/// Buffers that receive a system's output are written only by the system
/// (they are zeroed here, once), as the contract in `system` requires.
#[derive(Clone, Debug)]
pub(crate) struct Workspace {
    pub(crate) d: usize,
    pub(crate) m: usize,
    pub(crate) fibre: FibreFlow,
    // States.
    pub(crate) z0: Vec<f64>,
    pub(crate) y: Vec<f64>,
    pub(crate) z1: Vec<f64>,
    pub(crate) tv: Vec<f64>,
    /// The step's increment Δ = z1⁻ − z0 (and the base map's part of it).
    pub(crate) dz: Vec<f64>,
    pub(crate) db: Vec<f64>,
    // Multipliers.
    pub(crate) lambda: Vec<f64>,
    pub(crate) lambda_first: Vec<f64>,
    pub(crate) delta: Vec<f64>,
    pub(crate) sigma: Vec<f64>,
    // System outputs.
    pub(crate) g: Vec<f64>,
    pub(crate) g_z_y: Vec<f64>,
    pub(crate) g_z_1: Vec<f64>,
    pub(crate) hidden: Vec<f64>,
    /// N = {{H,g_i},g_j} and what its check keeps (`rattle`).
    pub(crate) n: NBuffers,
    // Our matrices: SHAKE's Jacobian, or N, factorised.
    pub(crate) jac: Vec<f64>,
    pub(crate) piv: Vec<usize>,
    // Projection onto M (initial data).
    pub(crate) gram: Vec<f64>,
    // SHAKE's structured Jacobian.
    /// The predicted band of SHAKE's Jacobian (full when a band does not
    /// pay, `Band::pays`, and below 12 constraints off the classical path,
    /// `predicted_band`).
    pub(crate) jac_band: Band,
    /// Columns evaluated together: j ≡ c (mod groups).
    pub(crate) groups: usize,
    /// The rows (i, k) of the macro's `JACOBIAN_PATTERN`, for sparse
    /// products with g_z.
    pub(crate) pattern: Vec<(usize, usize)>,
    pub(crate) piv_j: Vec<usize>,
    /// The band `jac` was factorised with.
    pub(crate) jac_factored: Band,
    /// The general path's difference quotients of its Jacobian.
    pub(crate) probe: Probe,
    pub(crate) jv: Vec<f64>,
    /// The classical path's buffers and structure (`classical`).
    pub(crate) classical: classical::Buffers,
    /// ‖∂g_i/∂z‖₁ where it was last measured (the state being checked, or
    /// the start of the step): the scale of the constraint tolerance.
    pub(crate) g_size: Vec<f64>,
    /// SHAKE's iterate (λ, z1⁻, Δ, g) before an extra iteration at the
    /// noise floor, to go back to when that iteration does not lower g.
    pub(crate) polish_keep: Vec<f64>,
    /// Which half of z each g_i reads (`tolerance::reads`).
    pub(crate) g_reads: Vec<u8>,
    /// Scratch of `rattle::nondegeneracy_terms`, sized on its first use
    /// (starting states only, never inside a step).
    pub(crate) terms: Vec<f64>,
}

/// N = {{H,g_i},g_j} at the state being checked, at the previous one, and
/// the buffers of its condition estimate.
#[derive(Clone, Debug)]
pub(crate) struct NBuffers {
    /// N, as the system writes it (the slice path's; the fixed-size step
    /// of 2 to 8 constraints reads N on the stack, `geoshake::classical::fixed_m`).
    pub(crate) mat: Vec<f64>,
    /// N at the previous checked state (the fold indicator of
    /// `Guard::check_n` compares the two); zero outside N's band.
    pub(crate) prev: Vec<f64>,
    /// The structural band of N (full when a band does not pay).
    pub(crate) band: Band,
    /// Hager's two vectors.
    pub(crate) s1: Vec<f64>,
    pub(crate) s2: Vec<f64>,
    /// The column of N⁻¹ that the last condition estimate ended on (its
    /// next start; `usize::MAX` for none).
    pub(crate) cond_column: usize,
}

/// The general SHAKE path's Jacobian by difference quotients (parent
/// module): the probed multipliers and what the step map gives at them.
#[derive(Clone, Debug)]
pub(crate) struct Probe {
    pub(crate) lambda: Vec<f64>,
    pub(crate) g: Vec<f64>,
    pub(crate) y: Vec<f64>,
    pub(crate) dz: Vec<f64>,
    pub(crate) z1: Vec<f64>,
    /// The scale of λ for difference quotients (adapted to the system on
    /// first use: the fibre flow should move z by about √ε_mach ‖z‖).
    pub(crate) lambda_scale: f64,
}

impl Workspace {
    /// The buffers for `sys`; `classical` says whether its steps take the
    /// classical path (`crate::shake::classical::classical`), where SHAKE's
    /// Jacobian −h G(q1) A G0ᵀ lies in its predicted band exactly.
    pub(crate) fn new<S: ConstrainedSystem>(sys: &S, classical: bool) -> Self {
        let d = sys.dof();
        let m = sys.constraint_count();
        let n = 2 * d;
        let jac_band = predicted_band(sys, classical);
        let groups = if jac_band == Band::full(m) {
            m
        } else {
            jac_band.lower + jac_band.upper + 1
        };
        Workspace {
            d,
            m,
            fibre: FibreFlow::new(sys),
            z0: vec![0.0; n],
            y: vec![0.0; n],
            z1: vec![0.0; n],
            tv: vec![0.0; n],
            dz: vec![0.0; n],
            db: vec![0.0; n],
            lambda: vec![0.0; m],
            lambda_first: vec![0.0; m],
            delta: vec![0.0; m],
            sigma: vec![0.0; m],
            g: vec![0.0; m],
            g_z_y: vec![0.0; m * n],
            g_z_1: vec![0.0; m * n],
            hidden: vec![0.0; m],
            n: NBuffers {
                mat: vec![0.0; m * m],
                prev: vec![0.0; m * m],
                band: structural_band_of_n(sys),
                s1: vec![0.0; m.max(1)],
                s2: vec![0.0; m.max(1)],
                cond_column: usize::MAX,
            },
            jac: vec![0.0; m * m],
            // Two spare slots: `lu_factor` records a band there (linalg).
            piv: vec![0; m + 2],
            gram: vec![0.0; m * m],
            jac_band,
            groups,
            pattern: sys
                .jacobian_pattern()
                .iter()
                .copied()
                .filter(|&(i, k)| i < m && k < n)
                .collect(),
            piv_j: vec![0; m.max(1)],
            jac_factored: jac_band,
            probe: Probe {
                lambda: vec![0.0; m],
                g: vec![0.0; m],
                y: vec![0.0; n],
                dz: vec![0.0; n],
                z1: vec![0.0; n],
                lambda_scale: 0.0,
            },
            jv: vec![0.0; m],
            classical: classical::Buffers::new(sys, jac_band, groups),
            g_size: vec![0.0; m],
            polish_keep: vec![0.0; 2 * m + 2 * n],
            g_reads: crate::tolerance::reads(sys.jacobian_pattern(), d, m),
            terms: Vec::new(),
        }
    }
}

/// A value no system computes: entries of a buffer still holding it after a
/// call were not written (finite, so that `+=` still changes it).
const UNWRITTEN: f64 = -7.291_538_450_712_967e-297;

/// The entries of a system function's output (length `len`) that it
/// writes at all, at either of two unrelated points. A system writes only
/// structurally nonzero entries (the contract of `system`), so an entry
/// still holding a sentinel is zero at every point; the second point
/// catches a hand-written function whose writes depend on the values,
/// which one evaluation would take for a narrower structure. (The bands
/// read from this decide what the banded LU reads: an entry missed here
/// would be dropped from N or SHAKE's Jacobian.)
fn written(len: usize, d: usize, eval: impl Fn(&[f64], &[f64], &mut [f64])) -> Vec<bool> {
    let other: Vec<f64> = (0..d)
        .map(|k| 0.3 + 0.6 * (0.7 * k as f64 + 1.1).sin())
        .collect();
    let mut seen = vec![false; len];
    let mut out = vec![UNWRITTEN; len];
    for point in [vec![0.5; d], other] {
        out.fill(UNWRITTEN);
        eval(&point, &point, &mut out);
        for (s, v) in seen.iter_mut().zip(&out) {
            *s |= v.to_bits() != UNWRITTEN.to_bits();
        }
    }
    seen
}

/// The band of N = {{H,g_i},g_j} that the system writes at all
/// ([`written`]). Full when the band does not pay.
fn structural_band_of_n<S: ConstrainedSystem>(sys: &S) -> Band {
    let (d, m) = (sys.dof(), sys.constraint_count());
    let full = Band::full(m);
    if m < 3 {
        return full;
    }
    let n_mat: Vec<f64> = written(m * m, d, |q, p, out| sys.nondegeneracy_matrix(q, p, out))
        .into_iter()
        .map(|w| if w { 1.0 } else { 0.0 })
        .collect();
    let band = Band::of(&n_mat, m);
    if band.pays(m) {
        band
    } else {
        full
    }
}

/// The band of SHAKE's Jacobian predicted from the structure of the system
/// (module docs): column j reaches the constraints that read a variable of
/// X_{g_j} or of J H_zz X_{g_j}. The pattern of H_zz is the set of entries
/// `hessian` writes (the contract of `system`: exactly the structurally
/// nonzero ones). On the classical path (`classical`) that is exactly the
/// band of −h G(q1) A G0ᵀ; on the general path it drops the O(h²) terms
/// of a base map that applies H_zz more than once (`shake`'s module docs,
/// "Structure: chains"), which pays only for large m: there a system of
/// fewer than 12 constraints keeps the full band, the exact Jacobian.
/// Fewer than 3 constraints always do.
fn predicted_band<S: ConstrainedSystem>(sys: &S, classical: bool) -> Band {
    let (d, m) = (sys.dof(), sys.constraint_count());
    let n = 2 * d;
    let full = Band::full(m);
    // (From two constraints on the classical path: a diagonal band, the
    // constraints decoupled, always pays, and takes SHAKE's fitted roots.)
    if m < 2 || (m < 12 && !classical) {
        return full;
    }
    let mut vars_of = vec![Vec::new(); m];
    let mut rows_of = vec![Vec::new(); n];
    for &(i, k) in sys.jacobian_pattern() {
        if i < m && k < n {
            vars_of[i].push(k);
            rows_of[k].push(i);
        }
    }
    let hz = written(n * n, d, |q, p, out| sys.hessian(q, p, out));
    let h_rows: Vec<Vec<usize>> = (0..n)
        .map(|c| (0..n).filter(|&r| hz[r + c * n]).collect())
        .collect();
    let swap = |k: usize| if k < d { k + d } else { k - d };
    let mut band = Band { lower: 0, upper: 0 };
    let mut seen = vec![usize::MAX; n];
    let mut reach = Vec::new();
    for j in 0..m {
        reach.clear();
        for &k in &vars_of[j] {
            let v = swap(k);
            for w in std::iter::once(v).chain(h_rows[v].iter().map(|&r| swap(r))) {
                if seen[w] != j {
                    seen[w] = j;
                    reach.push(w);
                }
            }
        }
        for &w in &reach {
            for &i in &rows_of[w] {
                if i > j {
                    band.lower = band.lower.max(i - j);
                } else {
                    band.upper = band.upper.max(j - i);
                }
            }
        }
    }
    if band.pays(m) {
        band
    } else {
        full
    }
}

#[cfg(test)]
mod tests {
    use super::written;

    #[test]
    fn a_write_that_depends_on_the_point_is_still_seen() {
        // Entry 2 written only where q0 ≠ 0.5, entry 0 always, entry 1 never.
        let w = written(3, 2, |q, _, out| {
            out[0] = 1.0;
            if q[0] != 0.5 {
                out[2] = 0.0;
            }
        });
        assert_eq!(w, [true, false, true]);
    }
}
