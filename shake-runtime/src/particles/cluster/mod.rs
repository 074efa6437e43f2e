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

use super::family::{ClusterKernel, Family};
pub(crate) use super::plan::{
    Block, ClusterArgs, ClusterFailure, ClusterReport, FailureKind, FamilyClusters, MAX_CLUSTER,
    MAX_CLUSTER_COORDS,
};
use super::{Stencil, Table};
use crate::tolerance::HIDDEN_LIMIT;

/// Gathers member j's local coordinates (ARITY·D entries) from `x`.
#[inline(always)]
fn gather_member<S: Stencil>(slots: &[u8], x: &[f64], xm: &mut [f64]) {
    let d = S::DIM;
    for a in 0..S::ARITY {
        let s = slots[a] as usize * d;
        xm[a * d..(a + 1) * d].copy_from_slice(&x[s..s + d]);
    }
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

/// A cluster whose Newton iteration stopped unsolved
/// ([`Rate::NonFinite`](crate::newton::Rate) or `NotConverged`) at
/// `member`, with its residual after `iterations` updates.
#[cold]
fn unsolved(member: usize, residual: f64, iterations: usize) -> ClusterFailure {
    ClusterFailure {
        member,
        residual,
        iterations,
        kind: if residual.is_finite() {
            FailureKind::NotConverged
        } else {
            FailureKind::NotFinite
        },
    }
}

pub(crate) mod dense;
mod fixed;
mod general;
mod settle;

use dense::*;
use fixed::*;
use general::*;
pub(crate) use settle::all_triangles;

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
    let members = store.as_deref().map_or(0, <[f64]>::len);
    let r = if in_blocks(plan) {
        let solve = |b, q: &mut [f64], p: &mut [f64], s: Option<&mut [f64]>| {
            shake_block(stencil, table, plan, args, fuse, warm, b, q, p, s)
        };
        shake_split::<S, _>(&plan.blocks, q, p, store, &solve)
    } else {
        let all = whole(plan, q.len() / S::DIM.max(1), members);
        shake_block(stencil, table, plan, args, fuse, warm, all, q, p, store)
    }?;
    report.max_rel = report.max_rel.max(r.max_rel);
    report.max_hidden = report.max_hidden.max(r.max_hidden);
    report.max_iter = report.max_iter.max(r.max_iter);
    report.iterations += r.iterations;
    Ok(())
}

/// True when the family's blocks go to threads: it has several
/// (`FamilyClusters::detect_blocks`) and more than one thread is at hand.
fn in_blocks(plan: &FamilyClusters) -> bool {
    !plan.blocks.is_empty() && rayon::current_num_threads() > 1
}

/// Every cluster of the family as one block.
fn whole(plan: &FamilyClusters, particles: usize, members: usize) -> Block {
    Block {
        clusters: (0, plan.len()),
        particles: (0, particles),
        members: (0, members),
    }
}

/// `solve` on every block of `blocks`, halving the list on `rayon::join`:
/// `q`, `p` and `store` hold the entries of the list's particles and
/// members, and are cut where the second half's start, so that the two
/// halves write disjoint memory (and nothing is allocated). The reports
/// merge as on one thread (maxima and sums); a failure in the first half
/// wins, so the failure reported is the lowest cluster's, the one a
/// single thread would have stopped at. Which thread solves a cluster
/// changes none of its numbers.
fn shake_split<S: Stencil, F>(
    blocks: &[Block],
    q: &mut [f64],
    p: &mut [f64],
    store: Option<&mut [f64]>,
    solve: &F,
) -> Result<ClusterReport, ClusterFailure>
where
    F: Fn(
            Block,
            &mut [f64],
            &mut [f64],
            Option<&mut [f64]>,
        ) -> Result<ClusterReport, ClusterFailure>
        + Sync,
{
    if let [b] = blocks {
        return solve(*b, q, p, store);
    }
    let (first, second) = blocks.split_at(blocks.len() / 2);
    let d = S::DIM.max(1);
    let at = (second[0].particles.0 - first[0].particles.0) * d;
    let (q0, q1) = q.split_at_mut(at);
    let (p0, p1) = p.split_at_mut(at);
    let (s0, s1) = match store {
        Some(s) => {
            let (s0, s1) = s.split_at_mut(second[0].members.0 - first[0].members.0);
            (Some(s0), Some(s1))
        }
        None => (None, None),
    };
    let (a, b) = rayon::join(
        || shake_split::<S, F>(first, q0, p0, s0, solve),
        || shake_split::<S, F>(second, q1, p1, s1, solve),
    );
    let (a, b) = (a?, b?);
    Ok(ClusterReport {
        max_rel: a.max_rel.max(b.max_rel),
        max_hidden: a.max_hidden.max(b.max_hidden),
        max_iter: a.max_iter.max(b.max_iter),
        iterations: a.iterations + b.iterations,
    })
}

/// The position stage on the clusters of one block, `q`, `p` and `store`
/// holding the block's particles and members only.
#[allow(clippy::too_many_arguments)]
fn shake_block<S: Stencil>(
    stencil: &S,
    table: &Table,
    plan: &FamilyClusters,
    args: &ClusterArgs<'_>,
    fuse: bool,
    warm: bool,
    block: Block,
    q: &mut [f64],
    p: &mut [f64],
    store: Option<&mut [f64]>,
) -> Result<ClusterReport, ClusterFailure> {
    let mut w = Work {
        store,
        warm,
        base: block.particles.0,
        mbase: block.members.0,
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
    let cs = block.clusters.0..block.clusters.1;
    // Once per family: the fixed-size kernel when every cluster has a shape
    // it is instantiated for (NX = particles × DIM must be a literal).
    let fixed = plan.fixed.filter(|_| S::ARITY <= FX && S::DIM <= FX);
    // (A macro: the kernel's sizes are const generics, one arm per shape.)
    macro_rules! fixed {
        ($mc:literal, $np:literal, $nx:literal) => {
            Some(shake_fixed_all::<S, $mc, $np, $nx>(
                &mut w,
                st,
                tb,
                pl,
                a,
                fuse,
                cs.clone(),
                q,
                p,
            ))
        };
    }
    // A family of rigid triangles of distances in R³: closed form.
    let settle = plan.settle && S::DIM == 3 && S::ARITY == 2;
    let done = match (fixed, S::DIM) {
        _ if settle => Some(settle::shake_triangles::<S>(
            &mut w,
            st,
            tb,
            pl,
            a,
            fuse,
            cs.clone(),
            q,
            p,
        )),
        (Some((3, 3)), 3) => fixed!(3, 3, 9),
        (Some((2, 3)), 3) => fixed!(2, 3, 9),
        (Some((1, 2)), 3) => fixed!(1, 2, 6),
        (Some((3, 3)), 2) => fixed!(3, 3, 6),
        (Some((2, 3)), 2) => fixed!(2, 3, 6),
        (Some((1, 2)), 2) => fixed!(1, 2, 4),
        _ => None,
    };
    match done {
        Some(r) => r?,
        None => {
            for c in cs {
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
    Ok(ClusterReport {
        max_rel: w.max_rel,
        max_hidden: w.max_hidden,
        max_iter: w.max_it,
        iterations: w.iters,
    })
}

/// The velocity stage (RATTLE's projection onto M^H along the fibre) on
/// every cluster of one family: p ← p − G(q)ᵀ μ with G(q) M⁻¹ p = 0. A
/// hidden constraint left above `tolerance::HIDDEN_LIMIT` by the exact
/// solve, or NaN, means N is singular to working precision: a typed
/// failure, never a state off M^H returned as projected. Blocks run on
/// threads as in [`shake_clusters`].
pub(crate) fn project_clusters<S: Stencil>(
    stencil: &S,
    table: &Table,
    plan: &FamilyClusters,
    inv_mass: &[f64],
    q: &[f64],
    p: &mut [f64],
    report: &mut ClusterReport,
) -> Result<(), ClusterFailure> {
    let max_hidden = if in_blocks(plan) {
        let solve = |b, p: &mut [f64]| project_block(stencil, table, plan, inv_mass, q, b, p);
        project_split::<S, _>(&plan.blocks, p, &solve)
    } else {
        let all = whole(plan, p.len() / S::DIM.max(1), 0);
        project_block(stencil, table, plan, inv_mass, q, all, p)
    }?;
    report.max_hidden = report.max_hidden.max(max_hidden);
    Ok(())
}

/// [`shake_split`] for the velocity stage: `p` cut between the halves.
fn project_split<S: Stencil, F>(
    blocks: &[Block],
    p: &mut [f64],
    solve: &F,
) -> Result<f64, ClusterFailure>
where
    F: Fn(Block, &mut [f64]) -> Result<f64, ClusterFailure> + Sync,
{
    if let [b] = blocks {
        return solve(*b, p);
    }
    let (first, second) = blocks.split_at(blocks.len() / 2);
    let at = (second[0].particles.0 - first[0].particles.0) * S::DIM.max(1);
    let (p0, p1) = p.split_at_mut(at);
    let (a, b) = rayon::join(
        || project_split::<S, F>(first, p0, solve),
        || project_split::<S, F>(second, p1, solve),
    );
    Ok(a?.max(b?))
}

/// The velocity stage on the clusters of one block, `p` holding the
/// block's particles only; the largest hidden-constraint residual left.
fn project_block<S: Stencil>(
    stencil: &S,
    table: &Table,
    plan: &FamilyClusters,
    inv_mass: &[f64],
    q: &[f64],
    block: Block,
    p: &mut [f64],
) -> Result<f64, ClusterFailure> {
    if plan.settle && S::DIM == 3 && S::ARITY == 2 {
        return settle::project_triangles(plan, inv_mass, q, block, p);
    }
    let (d, ar) = (S::DIM, S::ARITY);
    let wd = ar * d;
    let base = block.particles.0;
    let mut l = Local::new();
    let mut max_hidden = 0.0f64;
    for c in block.clusters.0..block.clusters.1 {
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
            let (i, j) = (i as usize, i as usize - base);
            l.x[s * d..(s + 1) * d].copy_from_slice(&q[i * d..(i + 1) * d]);
            l.pl[s * d..(s + 1) * d].copy_from_slice(&p[j * d..(j + 1) * d]);
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
            let j = i as usize - base;
            p[j * d..(j + 1) * d].copy_from_slice(&l.pl[s * d..(s + 1) * d]);
        }
    }
    Ok(max_hidden)
}

/// The cluster kernels of a family, monomorphic in its stencil.
impl<S: Stencil> ClusterKernel for Family<S> {
    fn shake_clusters(
        &self,
        plan: &FamilyClusters,
        args: &ClusterArgs<'_>,
        fuse: bool,
        store: Option<&mut [f64]>,
        warm: bool,
        q: &mut [f64],
        p: &mut [f64],
        report: &mut ClusterReport,
    ) -> Result<(), ClusterFailure> {
        let (st, tb) = (&self.stencil, &self.table);
        shake_clusters(st, tb, plan, args, fuse, store, warm, q, p, report)
    }
    fn project_clusters(
        &self,
        plan: &FamilyClusters,
        inv_mass: &[f64],
        q: &[f64],
        p: &mut [f64],
        report: &mut ClusterReport,
    ) -> Result<(), ClusterFailure> {
        project_clusters(&self.stencil, &self.table, plan, inv_mass, q, p, report)
    }
    fn choose_kernel(&self, plan: &mut FamilyClusters) {
        plan.settle = S::DISTANCE && S::DIM == 3 && all_triangles(plan, S::ARITY);
    }
}
