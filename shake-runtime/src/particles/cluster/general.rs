//! The general per-cluster kernel: any stencil shape up to
//! [`MAX_CLUSTER`] constraints and [`MAX_CLUSTER_COORDS`] local coordinates,
//! each cluster gathered into a local copy and solved by exact Newton.

use super::*;
use crate::newton::{Rate, Residuals};
use crate::particles::stencil::{member_at_roundoff, member_scale};
use crate::tolerance::{relative_dot_after, HIDDEN_LIMIT};

pub(super) const ML: usize = crate::particles::family::MAX_LOCAL;

/// One cluster's local copy: coordinates, momenta, inverse masses, and the
/// member blocks of G. Stack arrays, set up once per family per stage.
pub(super) struct Local {
    pub(super) x: [f64; MAX_CLUSTER_COORDS],
    pub(super) pl: [f64; MAX_CLUSTER_COORDS],
    pub(super) wm: [f64; MAX_CLUSTER_COORDS],
    pub(super) gr: [f64; MAX_CLUSTER * ML],
    pub(super) xm: [f64; ML],
    pub(super) n: [f64; MAX_CLUSTER * MAX_CLUSTER],
    pub(super) g: [f64; MAX_CLUSTER],
}

impl Local {
    pub(super) fn new() -> Self {
        Local {
            x: [0.0; MAX_CLUSTER_COORDS],
            pl: [0.0; MAX_CLUSTER_COORDS],
            wm: [0.0; MAX_CLUSTER_COORDS],
            gr: [0.0; MAX_CLUSTER * ML],
            xm: [0.0; ML],
            n: [0.0; MAX_CLUSTER * MAX_CLUSTER],
            g: [0.0; MAX_CLUSTER],
        }
    }

    /// The velocity stage on the local copy: pl ← pl − G(x)ᵀ μ with
    /// G(x) W pl = 0 (G(x) in `gr`). Returns the largest squared relative
    /// hidden residual after projection, or None if N is not positive
    /// definite.
    #[inline(always)]
    pub(super) fn project<S: Stencil>(&mut self, mc: usize, slots: &[u8]) -> Option<f64> {
        let (d, ar) = (S::DIM, S::ARITY);
        let wd = ar * d;
        for j in 0..mc {
            let sj = &slots[j * ar..(j + 1) * ar];
            let gj = &self.gr[j * wd..(j + 1) * wd];
            let mut r = 0.0;
            for a in 0..ar {
                let s = sj[a] as usize;
                let w = self.wm[s];
                for k in 0..d {
                    r += w * gj[a * d + k] * self.pl[s * d + k];
                }
            }
            self.g[j] = r;
            for l in 0..=j {
                let sl = &slots[l * ar..(l + 1) * ar];
                let gl = &self.gr[l * wd..(l + 1) * wd];
                let mut v = 0.0;
                for a in 0..ar {
                    for b in 0..ar {
                        if sj[a] == sl[b] {
                            let w = self.wm[sj[a] as usize];
                            for k in 0..d {
                                v += w * gj[a * d + k] * gl[b * d + k];
                            }
                        }
                    }
                }
                self.n[j * mc + l] = v;
            }
        }
        if mc <= 3 {
            for j in 0..mc {
                for l in j + 1..mc {
                    self.n[j * mc + l] = self.n[l * mc + j];
                }
            }
            if !small_inverse(mc, &mut self.n[..mc * mc], true) {
                return None;
            }
            small_apply(mc, &self.n[..mc * mc], &mut self.g[..mc]);
        } else if !cholesky_solve(mc, &mut self.n[..mc * mc], &mut self.g[..mc]) {
            return None;
        }
        // |W p′|² over each member's particles, before the projection.
        let mut before = [0.0; MAX_CLUSTER];
        for (j, b) in before.iter_mut().enumerate().take(mc) {
            let sj = &slots[j * ar..(j + 1) * ar];
            for &s in sj {
                let s = s as usize;
                for k in 0..d {
                    *b += (self.wm[s] * self.pl[s * d + k]).powi(2);
                }
            }
        }
        for l in 0..mc {
            let mu = self.g[l];
            let sl = &slots[l * ar..(l + 1) * ar];
            let gl = &self.gr[l * wd..(l + 1) * wd];
            for a in 0..ar {
                let s = sl[a] as usize;
                for k in 0..d {
                    self.pl[s * d + k] -= mu * gl[a * d + k];
                }
            }
        }
        // The hidden constraints after projection, relative to
        // |∇g_j| · |velocity of the member's particles| after the
        // projection, or if that fails before it (`relative_dot_after`).
        let mut worst = 0.0f64;
        for j in 0..mc {
            let sj = &slots[j * ar..(j + 1) * ar];
            let gj = &self.gr[j * wd..(j + 1) * wd];
            let mut v = [0.0; ML];
            for a in 0..ar {
                let s = sj[a] as usize;
                for k in 0..d {
                    v[a * d + k] = self.wm[s] * self.pl[s * d + k];
                }
            }
            let mut rel = relative_dot_after(gj, &v[..wd], 0.0);
            if !(rel <= HIDDEN_LIMIT) {
                rel = relative_dot_after(gj, &v[..wd], before[j]);
            }
            if crate::tolerance::worse(rel, worst) {
                worst = rel;
            }
        }
        Some(worst)
    }
}

/// Everything one cluster works on, on the stack, set up once per family
/// per stage and reused cluster after cluster.
pub(super) struct Work<'a> {
    /// ν of every member of the family from the previous step (read when
    /// `warm`, written after each cluster converges).
    pub(super) store: Option<&'a mut [f64]>,
    pub(super) warm: bool,
    /// The first particle and member of the block: `q`, `p` and `store`
    /// hold the block's entries only (q[(i − base)·D..] is particle i's).
    pub(super) base: usize,
    pub(super) mbase: usize,
    pub(super) l: Local,
    pub(super) wg0: [f64; MAX_CLUSTER * ML],
    pub(super) lu: [f64; MAX_CLUSTER * MAX_CLUSTER],
    pub(super) piv: [usize; MAX_CLUSTER],
    pub(super) dinv: [f64; MAX_CLUSTER],
    pub(super) nu: [f64; MAX_CLUSTER],
    /// 1 / (|∇g_j| · extent_j) at the iterate G was last evaluated at.
    pub(super) inv_s: [f64; MAX_CLUSTER],
    pub(super) x0: [f64; MAX_CLUSTER_COORDS],
    pub(super) max_rel: f64,
    pub(super) max_hidden: f64,
    pub(super) max_it: usize,
    pub(super) iters: u64,
}

/// One cluster of `mc` constraints. Always inlined, and called with `mc` a
/// literal for the common sizes, so every loop over the cluster's members
/// is unrolled and its bounds checks fold away.
#[inline(always)]
pub(super) fn shake_one<S: Stencil>(
    w: &mut Work<'_>,
    mc: usize,
    c: usize,
    stencil: &S,
    table: &Table,
    plan: &FamilyClusters,
    args: &ClusterArgs<'_>,
    fuse: bool,
    q: &mut [f64],
    p: &mut [f64],
) -> Result<(), ClusterFailure> {
    let Work {
        store,
        warm,
        base,
        mbase,
        l,
        wg0,
        lu,
        piv,
        dinv,
        nu,
        inv_s,
        x0,
        max_rel,
        max_hidden,
        max_it,
        iters,
    } = w;
    let (d, ar) = (S::DIM, S::ARITY);
    let wd = ar * d;
    let (m0, m1) = (
        plan.member_start[c] as usize,
        plan.member_start[c + 1] as usize,
    );
    let (p0, p1) = (
        plan.particle_start[c] as usize,
        plan.particle_start[c + 1] as usize,
    );
    let members = &plan.members[m0..m1];
    let parts = &plan.particles[p0..p1];
    let slots = &plan.slots[m0 * ar..m1 * ar];
    debug_assert_eq!(mc, members.len());
    for (s, &i) in parts.iter().enumerate() {
        let (i, j) = (i as usize, i as usize - *base);
        x0[s * d..(s + 1) * d].copy_from_slice(&args.q0[i * d..(i + 1) * d]);
        l.x[s * d..(s + 1) * d].copy_from_slice(&q[j * d..(j + 1) * d]);
        l.pl[s * d..(s + 1) * d].copy_from_slice(&p[j * d..(j + 1) * d]);
        l.wm[s] = args.inv_mass[i];
    }
    // W G(x0).
    for j in 0..mc {
        let sj = &slots[j * ar..(j + 1) * ar];
        gather_member::<S>(sj, &x0[..], &mut l.xm);
        let gr = &mut wg0[j * wd..(j + 1) * wd];
        stencil.gradient(&l.xm[..wd], table.data(members[j] as usize), gr);
        for a in 0..ar {
            let w = l.wm[sj[a] as usize];
            for k in 0..d {
                gr[a * d + k] *= w;
            }
        }
        nu[j] = 0.0;
    }
    // Warm start: the previous step's ν (the constraint impulses change
    // slowly along a trajectory; for a free rigid rotor they are constant),
    // so Newton starts near the solution: x ← x̃ − W G(x0)ᵀ ν_prev.
    if let (true, Some(st)) = (*warm, store.as_deref()) {
        for m in 0..mc {
            let v = st[members[m] as usize - *mbase];
            nu[m] = v;
            let sm = &slots[m * ar..(m + 1) * ar];
            let vm = &wg0[m * wd..(m + 1) * wd];
            for a in 0..ar {
                let s = sm[a] as usize;
                for k in 0..d {
                    l.x[s * d + k] -= v * vm[a * d + k];
                }
            }
        }
    }
    let mut it = 0;
    let mut need_jac = true;
    let mut rate = Residuals::new(args.max_iter);
    loop {
        // g at the current iterate (and G when the Jacobian is due). The
        // residual is judged against the scale at this iterate, never at
        // x0 alone: from far off M, x0's scale is the far point's and would
        // pass a result still off M. A pass on a stale scale (no gradient
        // here) is confirmed by one pass with the gradients at this iterate.
        let fresh = need_jac || fuse;
        let mut worst = 0.0f64;
        let mut worst_j = 0;
        for j in 0..mc {
            let sj = &slots[j * ar..(j + 1) * ar];
            gather_member::<S>(sj, &l.x, &mut l.xm);
            let data = table.data(members[j] as usize);
            // With `fuse`, G at every iterate: the last one is G(q1), which
            // the velocity stage needs (no separate evaluation at q1).
            let g = if fresh {
                let gj = &mut l.gr[j * wd..(j + 1) * wd];
                let g = stencil.gradient(&l.xm[..wd], data, gj);
                inv_s[j] = member_scale::<S>(gj, &l.xm[..wd]).0;
                g
            } else {
                stencil.value(&l.xm[..wd], data)
            };
            l.g[j] = g;
            let r = g.abs() * inv_s[j];
            if crate::tolerance::worse(r, worst) {
                worst = r;
                worst_j = j;
            }
        }
        if worst <= args.tol {
            if !fresh {
                need_jac = true;
                continue;
            }
            *max_rel = max_rel.max(worst);
            *max_it = (*max_it).max(it);
            *iters += it as u64;
            break;
        }
        let failed = || unsolved(members[worst_j] as usize, worst, it);
        // A stall is judged at this iterate's own scale (the kept one may
        // be a far start's), and reported so.
        let mut at_own = worst;
        let at_roundoff = || {
            let (mut xs, mut gs) = ([0.0; ML], [0.0; ML]);
            let mut all = true;
            at_own = 0.0;
            for j in 0..mc {
                gather_member::<S>(&slots[j * ar..(j + 1) * ar], &l.x, &mut xs);
                let data = table.data(members[j] as usize);
                let (within, r) =
                    member_at_roundoff(stencil, &xs[..wd], data, &mut gs[..wd], args.tol);
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
            *max_rel = max_rel.max(worst);
            *max_it = (*max_it).max(it);
            *iters += it as u64;
            break;
        }
        let slow = judged.slow().ok_or_else(failed)?;
        if !need_jac && slow {
            // A slow contraction with a kept Jacobian: the one at this
            // iterate.
            for j in 0..if fuse { 0 } else { mc } {
                let sj = &slots[j * ar..(j + 1) * ar];
                gather_member::<S>(sj, &l.x, &mut l.xm);
                let data = table.data(members[j] as usize);
                stencil.gradient(&l.xm[..wd], data, &mut l.gr[j * wd..(j + 1) * wd]);
            }
            need_jac = true;
        }
        if need_jac {
            // J = G(x) W G(x0)ᵀ.
            for j in 0..mc {
                let sj = &slots[j * ar..(j + 1) * ar];
                let gj = &l.gr[j * wd..(j + 1) * wd];
                for m in 0..mc {
                    let sm = &slots[m * ar..(m + 1) * ar];
                    let vm = &wg0[m * wd..(m + 1) * wd];
                    lu[j * mc + m] = coupling_w::<S>(sj, gj, sm, vm);
                }
            }
            let ok = if mc <= 3 {
                small_inverse(mc, &mut lu[..mc * mc], false)
            } else {
                lu_factor(mc, &mut lu[..mc * mc], &mut piv[..mc], &mut dinv[..mc])
            };
            if !ok {
                return Err(ClusterFailure {
                    member: members[worst_j] as usize,
                    residual: worst,
                    iterations: it,
                    kind: FailureKind::SingularNewton,
                });
            }
            // With `fuse` G is evaluated at every iterate anyway: use it
            // (exact Newton, quadratic convergence).
            need_jac = fuse;
        }
        if mc <= 3 {
            small_apply(mc, &lu[..mc * mc], &mut l.g[..mc]);
        } else {
            lu_solve(mc, &lu[..mc * mc], &piv[..mc], &dinv[..mc], &mut l.g[..mc]);
        }
        // x ← x − W G(x0)ᵀ δ, ν ← ν + δ.
        for m in 0..mc {
            let dl = l.g[m];
            nu[m] += dl;
            let sm = &slots[m * ar..(m + 1) * ar];
            let vm = &wg0[m * wd..(m + 1) * wd];
            for a in 0..ar {
                let s = sm[a] as usize;
                for k in 0..d {
                    l.x[s * d + k] -= dl * vm[a * d + k];
                }
            }
        }
        it += 1;
    }
    for (s, &i) in parts.iter().enumerate() {
        let j = i as usize - *base;
        q[j * d..(j + 1) * d].copy_from_slice(&l.x[s * d..(s + 1) * d]);
    }
    if let Some(st) = store.as_deref_mut() {
        for m in 0..mc {
            st[members[m] as usize - *mbase] = nu[m];
        }
    }
    if args.inv_h != 0.0 {
        // p½ = p̃ − G(x0)ᵀ ν / h (wg0 holds W G(x0): divide W out).
        for m in 0..mc {
            let f = nu[m] * args.inv_h;
            let sm = &slots[m * ar..(m + 1) * ar];
            let vm = &wg0[m * wd..(m + 1) * wd];
            for a in 0..ar {
                let s = sm[a] as usize;
                let fm = f / l.wm[s];
                for k in 0..d {
                    l.pl[s * d + k] -= fm * vm[a * d + k];
                }
            }
        }
        if fuse {
            // Above round-off after an exact solve (or NaN), N is singular
            // to working precision.
            match l.project::<S>(mc, slots) {
                Some(h) if h <= HIDDEN_LIMIT => *max_hidden = max_hidden.max(h),
                h => {
                    return Err(ClusterFailure {
                        member: members[0] as usize,
                        residual: h.unwrap_or(f64::NAN),
                        iterations: it,
                        kind: FailureKind::SingularN,
                    })
                }
            }
        }
        for (s, &i) in parts.iter().enumerate() {
            let j = i as usize - *base;
            p[j * d..(j + 1) * d].copy_from_slice(&l.pl[s * d..(s + 1) * d]);
        }
    }
    Ok(())
}
