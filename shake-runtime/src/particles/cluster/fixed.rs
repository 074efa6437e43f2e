//! The fixed-size kernel for families of uniform small shape (rigid water:
//! 3 constraints on 3 particles in 3-D): sizes are const generics, so every
//! loop is unrolled and every array lives in registers or L1.

use super::*;
use crate::newton::{Rate, Residuals};
use crate::particles::stencil::{member_at_roundoff, member_scale};
use crate::tolerance::{relative_dot_after, HIDDEN_LIMIT};

/// Largest ARITY and DIM of a stencil the fixed-size kernel takes.
pub(super) const FX: usize = 3;

/// Gathers member coordinates (slots `sl`, ARITY·DIM entries) from the
/// dense local copy `x` (NX = particles × DIM entries) into `xm`.
#[inline(always)]
pub(super) fn gather_fixed<S: Stencil, const NX: usize>(
    sl: &[usize; FX],
    x: &[f64; NX],
    xm: &mut [f64; 9],
) {
    let d = S::DIM;
    for a in 0..S::ARITY {
        for k in 0..d {
            xm[a * d + k] = x[sl[a] * d + k];
        }
    }
}

/// Σ over member j's block `a` (ARITY·DIM entries, its particles `sl`) of
/// a · w · b with b a dense local vector and w the per-coordinate inverse
/// masses (`None`: 1).
#[inline(always)]
pub(super) fn dot_block<S: Stencil, const NX: usize>(
    sl: &[usize; FX],
    a: &[f64; 9],
    w: Option<&[f64; NX]>,
    b: &[f64; NX],
) -> f64 {
    let d = S::DIM;
    let mut s = 0.0;
    for t in 0..S::ARITY {
        for k in 0..d {
            let i = sl[t] * d + k;
            let v = a[t * d + k] * b[i];
            s += match w {
                Some(w) => v * w[i],
                None => v,
            };
        }
    }
    s
}

/// y ← y − f · a on member j's particles (`a` its block).
#[inline(always)]
pub(super) fn axpy_block<S: Stencil, const NX: usize>(
    sl: &[usize; FX],
    f: f64,
    a: &[f64; 9],
    y: &mut [f64; NX],
) {
    let d = S::DIM;
    for t in 0..S::ARITY {
        for k in 0..d {
            y[sl[t] * d + k] -= f * a[t * d + k];
        }
    }
}

/// Scatters a member block into a dense local row (the row's other
/// entries are left as they are: zero, set once per family).
#[inline(always)]
pub(super) fn scatter_block<S: Stencil, const NX: usize>(
    sl: &[usize; FX],
    a: &[f64; 9],
    row: &mut [f64; NX],
) {
    let d = S::DIM;
    for t in 0..S::ARITY {
        for k in 0..d {
            row[sl[t] * d + k] = a[t * d + k];
        }
    }
}

/// The stack buffers of [`shake_fixed`], set up once per family.
pub(super) struct Fixed<const MC: usize, const NX: usize> {
    /// The slots of the previous cluster: the dense rows are zero off
    /// them, so they are cleared only when the slots change.
    pub(super) sl: [[usize; FX]; MC],
    /// W G(x0), dense rows.
    pub(super) wg0d: [[f64; NX]; MC],
    /// G(x1), dense rows (velocity stage).
    pub(super) grd: [[f64; NX]; MC],
}

/// [`shake_one`] for a family whose clusters all have MC constraints on NP
/// particles (NX = NP · DIM local coordinates): the same exact Newton and
/// the same fused velocity stage, with every size a compile-time constant,
/// all loops unrolled, the cluster's slots read once and clamped to < NP
/// (no bounds checks inside). The member blocks of G stay compact (ARITY ·
/// DIM entries, written by the stencil in place); the blocks they are
/// paired with in J = G(x) W G(x0)ᵀ and N = G W Gᵀ are scattered once per
/// cluster into dense rows, so each entry of J or N is one short dot
/// product with no slot comparisons. Agrees with [`shake_one`] to
/// round-off (only the order of the sums differs).
#[inline(always)]
pub(super) fn shake_fixed<S: Stencil, const MC: usize, const NP: usize, const NX: usize>(
    w: &mut Work<'_>,
    f: &mut Fixed<MC, NX>,
    c: usize,
    stencil: &S,
    table: &Table,
    plan: &FamilyClusters,
    args: &ClusterArgs<'_>,
    fuse: bool,
    q: &mut [f64],
    p: &mut [f64],
) -> Result<(), ClusterFailure> {
    let (d, ar) = (S::DIM, S::ARITY);
    let wd = ar * d;
    debug_assert!(MC <= 3 && NX == NP * d && ar <= FX && d <= FX);
    let (m0, p0) = (c * MC, c * NP);
    let members: &[u32; MC] = plan.members[m0..m0 + MC].try_into().unwrap();
    let parts: &[u32; NP] = plan.particles[p0..p0 + NP].try_into().unwrap();
    let slots = &plan.slots[m0 * ar..(m0 + MC) * ar];
    let mut sl = [[0usize; FX]; MC];
    let mut changed = false;
    for j in 0..MC {
        for a in 0..ar {
            sl[j][a] = (slots[j * ar + a] as usize).min(NP - 1);
            changed |= sl[j][a] != f.sl[j][a];
        }
    }
    // (An unrolled comparison: `sl != f.sl` became a call to memcmp.)
    if changed {
        f.sl = sl;
        f.wg0d = [[0.0; NX]; MC];
        f.grd = [[0.0; NX]; MC];
    }
    let (mut x0, mut x, mut pl, mut wx) = ([0.0; NX], [0.0; NX], [0.0; NX], [0.0; NX]);
    for s in 0..NP {
        let (i, j) = (parts[s] as usize, parts[s] as usize - w.base);
        let (a0, aq, ap) = (&args.q0[i * d..], &q[j * d..], &p[j * d..]);
        let wi = args.inv_mass[i];
        for k in 0..d {
            x0[s * d + k] = a0[k];
            x[s * d + k] = aq[k];
            pl[s * d + k] = ap[k];
            wx[s * d + k] = wi;
        }
    }
    let mut data = [&[][..]; MC];
    for j in 0..MC {
        data[j] = table.data(members[j] as usize);
    }
    // G(x0) and W G(x0) (member blocks, and W G(x0) as dense rows).
    let mut g0 = [[0.0; 9]; MC];
    let mut wg0 = [[0.0; 9]; MC];
    let mut xm = [0.0; 9];
    for j in 0..MC {
        gather_fixed::<S, NX>(&sl[j], &x0, &mut xm);
        stencil.gradient(&xm[..wd], data[j], &mut g0[j][..wd]);
        for t in 0..ar {
            for k in 0..d {
                wg0[j][t * d + k] = wx[sl[j][t] * d + k] * g0[j][t * d + k];
            }
        }
        scatter_block::<S, NX>(&sl[j], &wg0[j], &mut f.wg0d[j]);
    }
    // 1 / (|∇g_j| · extent_j) at the iterate the gradients were last
    // evaluated at (`tolerance::inverse_scale`), that iterate's member
    // coordinates and extent².
    let mut inv_s = [0.0; MC];
    let mut at_s = [[0.0; 9]; MC];
    let mut e2_s = [0.0; MC];
    let mut nu = [0.0; MC];
    if let (true, Some(st)) = (w.warm, w.store.as_deref()) {
        for m in 0..MC {
            nu[m] = st[members[m] as usize - w.mbase];
            axpy_block::<S, NX>(&sl[m], nu[m], &wg0[m], &mut x);
        }
    }
    let mut gr = [[0.0; 9]; MC];
    let mut gv = [0.0; MC];
    let mut jinv = [0.0; 9];
    let mut it = 0;
    let mut need_jac = true;
    let mut rate = Residuals::new(args.max_iter);
    // The residual is judged against the scale at the iterate judged, never
    // at x0 alone: from far off M, x0's scale is the far point's and would
    // pass a result still off M. The scale is taken on the first pass and
    // kept while no member moves by 1 % of its extent (for a distance, |∇g|
    // and the extent then change by less than 3 %, which the 0.97 below
    // covers; a step moves O(h²)); a pass that meets the tolerance after a
    // larger move takes the scale again, at once when the pass has the
    // gradients, else on one more pass that evaluates them.
    let mut rescale = true;
    loop {
        let fresh = need_jac || fuse;
        let mut worst = 0.0f64;
        let mut worst_j = 0;
        for j in 0..MC {
            gather_fixed::<S, NX>(&sl[j], &x, &mut xm);
            let g = if fresh {
                stencil.gradient(&xm[..wd], data[j], &mut gr[j][..wd])
            } else {
                stencil.value(&xm[..wd], data[j])
            };
            if rescale {
                // (`rescale` is set only with `need_jac`: G is fresh.)
                (inv_s[j], e2_s[j]) = member_scale::<S>(&gr[j][..wd], &xm[..wd]);
                at_s[j] = xm;
            }
            gv[j] = g;
            let r = g.abs() * inv_s[j];
            if crate::tolerance::worse(r, worst) {
                worst = r;
                worst_j = j;
            }
        }
        if worst <= args.tol {
            let mut still = |j: usize| {
                gather_fixed::<S, NX>(&sl[j], &x, &mut xm);
                let d2: f64 = (0..wd).map(|k| (xm[k] - at_s[j][k]).powi(2)).sum();
                d2 <= 1e-4 * e2_s[j]
            };
            let judged = rescale || (worst <= 0.97 * args.tol && (0..MC).all(&mut still));
            if !judged && !fresh {
                (need_jac, rescale) = (true, true);
                continue;
            }
            if !judged {
                // The gradients of this iterate are in hand: its scale.
                (worst, worst_j) = (0.0, 0);
                for j in 0..MC {
                    gather_fixed::<S, NX>(&sl[j], &x, &mut xm);
                    (inv_s[j], e2_s[j]) = member_scale::<S>(&gr[j][..wd], &xm[..wd]);
                    at_s[j] = xm;
                    let r = gv[j].abs() * inv_s[j];
                    if crate::tolerance::worse(r, worst) {
                        (worst, worst_j) = (r, j);
                    }
                }
            }
            if worst <= args.tol {
                w.max_rel = w.max_rel.max(worst);
                w.max_it = w.max_it.max(it);
                w.iters += it as u64;
                break;
            }
        }
        rescale = false;
        let failed = || unsolved(members[worst_j] as usize, worst, it);
        // A stall is judged at this iterate's own scale (the kept one may
        // be a far start's), and reported so.
        let mut at_own = worst;
        let at_roundoff = || {
            let (mut xs, mut gs) = ([0.0; 9], [0.0; 9]);
            let mut all = true;
            at_own = 0.0;
            for j in 0..MC {
                gather_fixed::<S, NX>(&sl[j], &x, &mut xs);
                let (within, r) =
                    member_at_roundoff(stencil, &xs[..wd], data[j], &mut gs[..wd], args.tol);
                all &= within;
                if crate::tolerance::worse(r, at_own) {
                    at_own = r;
                }
            }
            all
        };
        let judged = rate.judge(worst, it, at_roundoff);
        if judged == Rate::RoundOff {
            let worst = at_own;
            w.max_rel = w.max_rel.max(worst);
            w.max_it = w.max_it.max(it);
            w.iters += it as u64;
            break;
        }
        let slow = judged.slow().ok_or_else(failed)?;
        // A slow contraction with a kept Jacobian: the one at this iterate.
        if !need_jac && slow {
            for j in 0..MC {
                gather_fixed::<S, NX>(&sl[j], &x, &mut xm);
                stencil.gradient(&xm[..wd], data[j], &mut gr[j][..wd]);
            }
            need_jac = true;
        }
        if need_jac {
            for j in 0..MC {
                for m in 0..MC {
                    jinv[j * MC + m] = dot_block::<S, NX>(&sl[j], &gr[j], None, &f.wg0d[m]);
                }
            }
            if !small_inverse(MC, &mut jinv[..MC * MC], false) {
                return Err(ClusterFailure {
                    member: members[worst_j] as usize,
                    residual: worst,
                    iterations: it,
                    kind: FailureKind::SingularNewton,
                });
            }
            need_jac = fuse;
        }
        small_apply(MC, &jinv[..MC * MC], &mut gv[..MC]);
        for m in 0..MC {
            nu[m] += gv[m];
            axpy_block::<S, NX>(&sl[m], gv[m], &wg0[m], &mut x);
        }
        it += 1;
    }
    for s in 0..NP {
        let j = parts[s] as usize - w.base;
        q[j * d..j * d + d].copy_from_slice(&x[s * d..s * d + d]);
    }
    if let Some(st) = w.store.as_deref_mut() {
        for m in 0..MC {
            st[members[m] as usize - w.mbase] = nu[m];
        }
    }
    if args.inv_h == 0.0 {
        return Ok(());
    }
    // p½ = p̃ − G(x0)ᵀ ν / h.
    for m in 0..MC {
        axpy_block::<S, NX>(&sl[m], nu[m] * args.inv_h, &g0[m], &mut pl);
    }
    if fuse {
        // Velocity stage with G(x1) (the last iterate's blocks in `gr`):
        // N μ = G W p, p ← p − Gᵀ μ.
        let mut n = [0.0; 9];
        let mut r = [0.0; MC];
        for l in 0..MC {
            scatter_block::<S, NX>(&sl[l], &gr[l], &mut f.grd[l]);
        }
        for j in 0..MC {
            r[j] = dot_block::<S, NX>(&sl[j], &gr[j], Some(&wx), &pl);
            for l in 0..=j {
                let v = dot_block::<S, NX>(&sl[j], &gr[j], Some(&wx), &f.grd[l]);
                n[j * MC + l] = v;
                n[l * MC + j] = v;
            }
        }
        if !small_inverse(MC, &mut n[..MC * MC], true) {
            return Err(ClusterFailure {
                member: members[0] as usize,
                residual: f64::NAN,
                iterations: it,
                kind: FailureKind::SingularN,
            });
        }
        small_apply(MC, &n[..MC * MC], &mut r[..MC]);
        for l in 0..MC {
            axpy_block::<S, NX>(&sl[l], r[l], &gr[l], &mut pl);
        }
        // Hidden constraints after projection, relative to |∇g_j| ·
        // |velocity of the member's particles| after the projection, or if
        // that fails before it (`relative_dot_after`): above round-off
        // after an exact solve (or NaN), N is singular to working
        // precision.
        let mut worst = 0.0f64;
        let mut worst_j = 0;
        for j in 0..MC {
            let mut v = [0.0; 9];
            for t in 0..ar {
                for k in 0..d {
                    let i = sl[j][t] * d + k;
                    v[t * d + k] = wx[i] * pl[i];
                }
            }
            let mut rel = relative_dot_after(&gr[j][..wd], &v[..wd], 0.0);
            if !(rel <= HIDDEN_LIMIT) {
                // p′ = p1 + Gᵀ μ, rebuilt for the rare member whose
                // velocity the projection cancelled.
                let mut before = pl;
                for l in 0..MC {
                    axpy_block::<S, NX>(&sl[l], -r[l], &gr[l], &mut before);
                }
                let mut b0 = 0.0;
                for t in 0..ar {
                    for k in 0..d {
                        let i = sl[j][t] * d + k;
                        b0 += (wx[i] * before[i]).powi(2);
                    }
                }
                rel = relative_dot_after(&gr[j][..wd], &v[..wd], b0);
            }
            if crate::tolerance::worse(rel, worst) {
                worst = rel;
                worst_j = j;
            }
        }
        if !(worst <= HIDDEN_LIMIT) {
            return Err(ClusterFailure {
                member: members[worst_j] as usize,
                residual: worst,
                iterations: it,
                kind: FailureKind::SingularN,
            });
        }
        w.max_hidden = w.max_hidden.max(worst);
    }
    for s in 0..NP {
        let j = parts[s] as usize - w.base;
        p[j * d..j * d + d].copy_from_slice(&pl[s * d..s * d + d]);
    }
    Ok(())
}

/// The loop of [`shake_clusters`] over a family of uniform shape.
#[inline(never)]
pub(super) fn shake_fixed_all<S: Stencil, const MC: usize, const NP: usize, const NX: usize>(
    w: &mut Work<'_>,
    stencil: &S,
    table: &Table,
    plan: &FamilyClusters,
    args: &ClusterArgs<'_>,
    fuse: bool,
    clusters: std::ops::Range<usize>,
    q: &mut [f64],
    p: &mut [f64],
) -> Result<(), ClusterFailure> {
    let mut f = Fixed {
        sl: [[usize::MAX; FX]; MC],
        wg0d: [[0.0; NX]; MC],
        grd: [[0.0; NX]; MC],
    };
    for c in clusters {
        shake_fixed::<S, MC, NP, NX>(w, &mut f, c, stencil, table, plan, args, fuse, q, p)?;
    }
    Ok(())
}
