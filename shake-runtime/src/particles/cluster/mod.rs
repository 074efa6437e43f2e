#![allow(clippy::too_many_arguments)]
//! Independent small clusters (rigid waters, small molecules): each cluster's
//! SHAKE equation solved to convergence by exact Newton on its own, then its
//! RATTLE projection by one small Cholesky solve, while its few numbers stay
//! in L1.
//!
//! For a cluster with constraints g_1..g_c on particles P (local coordinates
//! x ∈ R^{|P|·D}, inverse masses W):
//!
//! - position stage: x(ν) = x̃ − W G(x0)ᵀ ν, solve g(x(ν)) = 0 by Newton with
//!   the exact c×c Jacobian J = G(x) W G(x0)ᵀ (LU with partial pivoting),
//!   then p½ = p̃ − G(x0)ᵀ ν / h (ν = h λ, λ the classical multiplier of the
//!   paper's Section 5.1.3);
//! - velocity stage: p1 = p′ − G(x1)ᵀ μ with N μ = G(x1) W p′,
//!   N = G(x1) W G(x1)ᵀ symmetric positive definite (Cholesky).
//!
//! The kernels are generic over the [`Stencil`], so each family's loop over
//! its clusters is monomorphic: no dynamic call per member.

use super::{Stencil, Table};
use crate::tolerance::HIDDEN_LIMIT;

/// Largest number of constraints a cluster may have to be solved on its
/// own: the order of the small dense solvers' matrices.
pub(crate) const MAX_CLUSTER: usize = dense::CAPACITY;
/// Largest number of local coordinates (particles × D) of such a cluster.
pub(crate) const MAX_CLUSTER_COORDS: usize = 96;

/// The clusters of one family: each a connected set of the family's
/// members, with the particles they touch. Built once, by the symbolic
/// phase of [`Rattle::new`](super::Rattle::new).
#[derive(Clone, Debug, Default)]
pub struct FamilyClusters {
    /// Member rows, cluster after cluster.
    pub(crate) members: Vec<u32>,
    /// Start of cluster c in `members` (one more entry than clusters).
    pub(crate) member_start: Vec<u32>,
    /// Particles, cluster after cluster.
    pub(crate) particles: Vec<u32>,
    /// Start of cluster c in `particles`.
    pub(crate) particle_start: Vec<u32>,
    /// For every entry of `members`, the local slot (index into the
    /// cluster's particles) of each of the member's ARITY particles.
    pub(crate) slots: Vec<u8>,
    /// `Some((constraints, particles))` when every cluster has that shape
    /// and it has a fixed-size kernel ([`shake_fixed`]); set by
    /// [`FamilyClusters::detect_shape`].
    pub(crate) fixed: Option<(u8, u8)>,
}

impl FamilyClusters {
    /// The number of clusters.
    pub(crate) fn len(&self) -> usize {
        self.member_start.len().saturating_sub(1)
    }
    /// Sets [`FamilyClusters::fixed`] when every cluster has the same
    /// number of constraints and of particles, of a shape the fixed-size
    /// kernel is instantiated for (rigid water: 3 constraints on 3
    /// particles). The stencil's ARITY and DIM are checked at dispatch.
    pub(crate) fn detect_shape(&mut self) {
        self.fixed = None;
        let n = self.len();
        if n == 0 {
            return;
        }
        let mc = self.member_start[1] - self.member_start[0];
        let np = self.particle_start[1] - self.particle_start[0];
        if !matches!((mc, np), (1, 2) | (2, 3) | (3, 3)) {
            return;
        }
        let uniform = (0..n).all(|c| {
            self.member_start[c + 1] - self.member_start[c] == mc
                && self.particle_start[c + 1] - self.particle_start[c] == np
        });
        if uniform {
            self.fixed = Some((mc as u8, np as u8));
        }
    }
    /// Bytes held.
    pub(crate) fn bytes(&self) -> usize {
        (self.members.capacity()
            + self.member_start.capacity()
            + self.particles.capacity()
            + self.particle_start.capacity())
            * 4
            + self.slots.capacity()
    }
}

/// The inputs of the position stage shared by every cluster.
#[derive(Clone, Copy, Debug)]
pub struct ClusterArgs<'a> {
    /// q0 (the start of the step).
    pub(crate) q0: &'a [f64],
    /// 1/m_a per particle.
    pub(crate) inv_mass: &'a [f64],
    /// 1/h: p½ = p̃ − G(q0)ᵀ ν / h; 0 leaves p alone (projection onto M).
    pub(crate) inv_h: f64,
    /// Relative tolerance on every constraint.
    pub(crate) tol: f64,
    /// Newton iteration budget per cluster.
    pub(crate) max_iter: usize,
}

/// What the clusters of a family measured in one stage.
#[derive(Clone, Copy, Debug, Default)]
pub struct ClusterReport {
    /// Largest relative residual |g_k| / (|∇g_k| · extent_k) at the end.
    pub(crate) max_rel: f64,
    /// Largest relative hidden-constraint residual after projection.
    pub(crate) max_hidden: f64,
    /// Largest Newton iteration count of one cluster.
    pub(crate) max_iter: usize,
    /// Newton iterations summed over clusters.
    pub(crate) iterations: u64,
}

/// Why a cluster failed (the caller adds step, time and family).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterFailure {
    /// The member at fault (row of the family's table).
    pub(crate) member: usize,
    /// Its relative residual.
    pub(crate) residual: f64,
    /// Iterations done.
    pub(crate) iterations: usize,
    /// What went wrong.
    pub(crate) kind: FailureKind,
}

/// The kind of a cluster failure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum FailureKind {
    NotConverged,
    SingularNewton,
    SingularN,
    NotFinite,
}

/// Gathers member j's local coordinates (ARITY·D entries) from `x`.
#[inline(always)]
fn gather_member<S: Stencil>(slots: &[u8], x: &[f64], xm: &mut [f64]) {
    let d = S::DIM;
    for a in 0..S::ARITY {
        let s = slots[a] as usize * d;
        xm[a * d..(a + 1) * d].copy_from_slice(&x[s..s + d]);
    }
}

/// Squared extent of a member: Σ_a |x_a − x̄|² over its particles (|x_a|²
/// for a single-particle member, whose constraint refers to the origin).
#[inline(always)]
pub(crate) fn extent2<S: Stencil>(xm: &[f64]) -> f64 {
    let (d, ar) = (S::DIM, S::ARITY);
    if ar == 1 {
        return xm[..d].iter().map(|v| v * v).sum();
    }
    let mut e = 0.0;
    for c in 0..d {
        let mut mean = 0.0;
        for a in 0..ar {
            mean += xm[a * d + c];
        }
        mean /= ar as f64;
        for a in 0..ar {
            let r = xm[a * d + c] - mean;
            e += r * r;
        }
    }
    e
}

/// Σ over particles shared by members j and l of ∇_a g_j · v_a, with v the
/// (already mass-weighted) block of member l.
#[inline(always)]
fn coupling_w<S: Stencil>(sj: &[u8], gj: &[f64], sl: &[u8], vl: &[f64]) -> f64 {
    let d = S::DIM;
    let mut v = 0.0;
    for a in 0..S::ARITY {
        for b in 0..S::ARITY {
            if sj[a] == sl[b] {
                for c in 0..d {
                    v += gj[a * d + c] * vl[b * d + c];
                }
            }
        }
    }
    v
}

mod dense;
mod fixed;
mod general;

use dense::*;
use fixed::*;
use general::*;

/// The position stage on every cluster of one family: on entry `q` holds
/// q̃ = q0 + h M⁻¹ p̃ and `p` holds p̃ on the cluster's particles; on exit q1
/// with g(q1) = 0 to the tolerance, and p½ (when `inv_h` ≠ 0). With
/// `fuse` (no potential: p′ = p½), the velocity stage follows on the same
/// local copy, while it is in L1.
///
/// Newton's matrix is the Jacobian G(x) W G(x0)ᵀ. Without `fuse` it is
/// evaluated at the predictor x̃ and factorised once (a simplified Newton:
/// x1 − x̃ = O(h²|v|²), so the contraction per iteration is about
/// (h|v|/l)²), and re-evaluated at the current iterate when an iteration
/// contracts by less than ½. With `fuse`, G is evaluated at every iterate
/// anyway (the last one serves the velocity stage), so Newton is exact.
pub(crate) fn shake_clusters<S: Stencil>(
    stencil: &S,
    table: &Table,
    plan: &FamilyClusters,
    args: &ClusterArgs<'_>,
    fuse: bool,
    store: Option<&mut [f64]>,
    warm: bool,
    q: &mut [f64],
    p: &mut [f64],
    report: &mut ClusterReport,
) -> Result<(), ClusterFailure> {
    let mut w = Work {
        store,
        warm,
        l: Local::new(),
        wg0: [0.0; MAX_CLUSTER * ML],
        lu: [0.0; MAX_CLUSTER * MAX_CLUSTER],
        piv: [0; MAX_CLUSTER],
        dinv: [0.0; MAX_CLUSTER],
        nu: [0.0; MAX_CLUSTER],
        inv_s: [0.0; MAX_CLUSTER],
        x0: [0.0; MAX_CLUSTER_COORDS],
        max_rel: 0.0,
        max_hidden: 0.0,
        max_it: 0,
        iters: 0,
    };
    let (st, tb, pl, a) = (stencil, table, plan, args);
    // Once per family: the fixed-size kernel when every cluster has a shape
    // it is instantiated for (NX = particles × DIM must be a literal).
    let fixed = plan.fixed.filter(|_| S::ARITY <= FX && S::DIM <= FX);
    let done = match (fixed, S::DIM) {
        (Some((3, 3)), 3) => Some(shake_fixed_all::<S, 3, 3, 9>(
            &mut w, st, tb, pl, a, fuse, q, p,
        )),
        (Some((2, 3)), 3) => Some(shake_fixed_all::<S, 2, 3, 9>(
            &mut w, st, tb, pl, a, fuse, q, p,
        )),
        (Some((1, 2)), 3) => Some(shake_fixed_all::<S, 1, 2, 6>(
            &mut w, st, tb, pl, a, fuse, q, p,
        )),
        (Some((3, 3)), 2) => Some(shake_fixed_all::<S, 3, 3, 6>(
            &mut w, st, tb, pl, a, fuse, q, p,
        )),
        (Some((2, 3)), 2) => Some(shake_fixed_all::<S, 2, 3, 6>(
            &mut w, st, tb, pl, a, fuse, q, p,
        )),
        (Some((1, 2)), 2) => Some(shake_fixed_all::<S, 1, 2, 4>(
            &mut w, st, tb, pl, a, fuse, q, p,
        )),
        _ => None,
    };
    match done {
        Some(r) => r?,
        None => {
            for c in 0..plan.len() {
                let mc = (plan.member_start[c + 1] - plan.member_start[c]) as usize;
                match mc {
                    1 => shake_one(&mut w, 1, c, st, tb, pl, a, fuse, q, p),
                    2 => shake_one(&mut w, 2, c, st, tb, pl, a, fuse, q, p),
                    3 => shake_one(&mut w, 3, c, st, tb, pl, a, fuse, q, p),
                    4 => shake_one(&mut w, 4, c, st, tb, pl, a, fuse, q, p),
                    _ => shake_one(&mut w, mc, c, st, tb, pl, a, fuse, q, p),
                }?;
            }
        }
    }
    report.max_rel = report.max_rel.max(w.max_rel);
    report.max_hidden = report.max_hidden.max(w.max_hidden);
    report.max_iter = report.max_iter.max(w.max_it);
    report.iterations += w.iters;
    Ok(())
}

/// The velocity stage (RATTLE's projection onto M^H along the fibre) on
/// every cluster of one family: p ← p − G(q)ᵀ μ with G(q) M⁻¹ p = 0. A
/// hidden constraint left above `tolerance::HIDDEN_LIMIT` by the exact
/// solve, or NaN, means N is singular to working precision: a typed
/// failure, never a state off M^H returned as projected.
pub(crate) fn project_clusters<S: Stencil>(
    stencil: &S,
    table: &Table,
    plan: &FamilyClusters,
    inv_mass: &[f64],
    q: &[f64],
    p: &mut [f64],
    report: &mut ClusterReport,
) -> Result<(), ClusterFailure> {
    let (d, ar) = (S::DIM, S::ARITY);
    let wd = ar * d;
    let mut l = Local::new();
    let mut max_hidden = 0.0f64;
    for c in 0..plan.len() {
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
        let mc = members.len();
        for (s, &i) in parts.iter().enumerate() {
            let i = i as usize;
            l.x[s * d..(s + 1) * d].copy_from_slice(&q[i * d..(i + 1) * d]);
            l.pl[s * d..(s + 1) * d].copy_from_slice(&p[i * d..(i + 1) * d]);
            l.wm[s] = inv_mass[i];
        }
        for j in 0..mc {
            let sj = &slots[j * ar..(j + 1) * ar];
            gather_member::<S>(sj, &l.x, &mut l.xm);
            let data = table.data(members[j] as usize);
            stencil.gradient(&l.xm[..wd], data, &mut l.gr[j * wd..(j + 1) * wd]);
        }
        match l.project::<S>(mc, slots) {
            Some(h) if h <= HIDDEN_LIMIT => max_hidden = max_hidden.max(h),
            h => {
                return Err(ClusterFailure {
                    member: members[0] as usize,
                    residual: h.unwrap_or(f64::NAN),
                    iterations: 0,
                    kind: FailureKind::SingularN,
                })
            }
        }
        for (s, &i) in parts.iter().enumerate() {
            let i = i as usize;
            p[i * d..(i + 1) * d].copy_from_slice(&l.pl[s * d..(s + 1) * d]);
        }
    }
    report.max_hidden = report.max_hidden.max(max_hidden);
    Ok(())
}
