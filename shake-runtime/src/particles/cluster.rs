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

/// Largest number of constraints a cluster may have to be solved on its own.
pub(crate) const MAX_CLUSTER: usize = 12;
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
}

impl FamilyClusters {
    /// The number of clusters.
    pub(crate) fn len(&self) -> usize {
        self.member_start.len().saturating_sub(1)
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

/// Scratch for one cluster at a time, allocated once for the largest.
#[derive(Clone, Debug)]
pub struct ClusterScratch {
    x0: Vec<f64>,
    x: Vec<f64>,
    pl: Vec<f64>,
    wm: Vec<f64>,
    gr0: Vec<f64>,
    gr1: Vec<f64>,
    jac: Vec<f64>,
    g: Vec<f64>,
    nu: Vec<f64>,
    s2: Vec<f64>,
    xm: Vec<f64>,
}

impl ClusterScratch {
    pub(crate) fn new() -> Self {
        let c = MAX_CLUSTER;
        let x = MAX_CLUSTER_COORDS;
        let w = super::system::MAX_LOCAL;
        ClusterScratch {
            x0: vec![0.0; x],
            x: vec![0.0; x],
            pl: vec![0.0; x],
            wm: vec![0.0; x],
            gr0: vec![0.0; c * w],
            gr1: vec![0.0; c * w],
            jac: vec![0.0; c * c],
            g: vec![0.0; c],
            nu: vec![0.0; c],
            s2: vec![0.0; c],
            xm: vec![0.0; w],
        }
    }
    pub(crate) fn bytes(&self) -> usize {
        8 * (self.x0.len() * 4 + self.gr0.len() * 2 + self.jac.len() + self.g.len() * 3)
            + 8 * self.xm.len()
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

/// Σ over particles shared by members j and l of ∇_a g_j · W_a ∇_a g_l.
#[inline(always)]
fn coupling<S: Stencil>(sj: &[u8], gj: &[f64], sl: &[u8], gl: &[f64], wm: &[f64]) -> f64 {
    let d = S::DIM;
    let mut v = 0.0;
    for a in 0..S::ARITY {
        for b in 0..S::ARITY {
            if sj[a] == sl[b] {
                let mut dot = 0.0;
                for c in 0..d {
                    dot += gj[a * d + c] * gl[b * d + c];
                }
                v += wm[sj[a] as usize] * dot;
            }
        }
    }
    v
}

/// Solves J δ = b in place (b ← δ) for an n×n row-major J by Gaussian
/// elimination with partial pivoting. False when a pivot is zero or not
/// finite.
#[inline]
fn lu_solve(n: usize, jac: &mut [f64], b: &mut [f64]) -> bool {
    for k in 0..n {
        let mut piv = k;
        let mut best = jac[k * n + k].abs();
        for i in k + 1..n {
            let v = jac[i * n + k].abs();
            if v > best {
                best = v;
                piv = i;
            }
        }
        if !(best > 0.0 && best.is_finite()) {
            return false;
        }
        if piv != k {
            for c in 0..n {
                jac.swap(k * n + c, piv * n + c);
            }
            b.swap(k, piv);
        }
        let inv = 1.0 / jac[k * n + k];
        for i in k + 1..n {
            let f = jac[i * n + k] * inv;
            if f != 0.0 {
                for c in k + 1..n {
                    jac[i * n + c] -= f * jac[k * n + c];
                }
                b[i] -= f * b[k];
            }
        }
    }
    for k in (0..n).rev() {
        let mut s = b[k];
        for c in k + 1..n {
            s -= jac[k * n + c] * b[c];
        }
        b[k] = s / jac[k * n + k];
    }
    true
}

/// Solves N μ = b in place for symmetric positive definite N (row-major,
/// lower triangle used) by Cholesky. False when N is not numerically
/// positive definite.
#[inline]
fn cholesky_solve(n: usize, a: &mut [f64], b: &mut [f64]) -> bool {
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if !(d > 0.0 && d.is_finite()) {
            return false;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        let inv = 1.0 / d;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s * inv;
        }
    }
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= a[i * n + k] * b[k];
        }
        b[i] = s / a[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= a[k * n + i] * b[k];
        }
        b[i] = s / a[i * n + i];
    }
    true
}

/// The position stage on every cluster of one family: on entry `q` holds
/// q̃ = q0 + h M⁻¹ p̃ and `p` holds p̃ on the cluster's particles; on exit q1
/// with g(q1) = 0 to the tolerance, and p½ (when `inv_h` ≠ 0).
pub(crate) fn shake_clusters<S: Stencil>(
    stencil: &S,
    table: &Table,
    plan: &FamilyClusters,
    args: &ClusterArgs<'_>,
    w: &mut ClusterScratch,
    q: &mut [f64],
    p: &mut [f64],
    report: &mut ClusterReport,
) -> Result<(), ClusterFailure> {
    let (d, ar) = (S::DIM, S::ARITY);
    let wd = ar * d;
    let tol2 = args.tol * args.tol;
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
            w.x0[s * d..(s + 1) * d].copy_from_slice(&args.q0[i * d..(i + 1) * d]);
            w.x[s * d..(s + 1) * d].copy_from_slice(&q[i * d..(i + 1) * d]);
            w.wm[s] = args.inv_mass[i];
        }
        // G(x0) and the residual scales |∇g_j(x0)|² · extent_j(x0)².
        for j in 0..mc {
            let sj = &slots[j * ar..(j + 1) * ar];
            gather_member::<S>(sj, &w.x0, &mut w.xm);
            let gr = &mut w.gr0[j * wd..(j + 1) * wd];
            stencil.gradient(&w.xm[..wd], table.data(members[j] as usize), gr);
            let n2: f64 = gr.iter().map(|v| v * v).sum();
            w.s2[j] = (n2 * extent2::<S>(&w.xm[..wd])).max(f64::MIN_POSITIVE);
            w.nu[j] = 0.0;
        }
        let mut it = 0;
        loop {
            // g(x) and G(x) at the current iterate.
            let mut worst = 0.0f64;
            let mut worst_j = 0;
            let mut done = true;
            for j in 0..mc {
                let sj = &slots[j * ar..(j + 1) * ar];
                gather_member::<S>(sj, &w.x, &mut w.xm);
                let gr = &mut w.gr1[j * wd..(j + 1) * wd];
                let g = stencil.gradient(&w.xm[..wd], table.data(members[j] as usize), gr);
                w.g[j] = g;
                let r = g * g;
                if !(r <= tol2 * w.s2[j]) {
                    done = false;
                    if !g.is_finite() {
                        return Err(ClusterFailure {
                            member: members[j] as usize,
                            residual: f64::NAN,
                            iterations: it,
                            kind: FailureKind::NotFinite,
                        });
                    }
                }
                let rel = r / w.s2[j];
                if rel > worst {
                    worst = rel;
                    worst_j = j;
                }
            }
            if done {
                report.max_rel = report.max_rel.max(worst.sqrt());
                report.max_iter = report.max_iter.max(it);
                report.iterations += it as u64;
                break;
            }
            if it >= args.max_iter {
                return Err(ClusterFailure {
                    member: members[worst_j] as usize,
                    residual: worst.sqrt(),
                    iterations: it,
                    kind: FailureKind::NotConverged,
                });
            }
            // J = G(x) W G(x0)ᵀ, δ = J⁻¹ g.
            for j in 0..mc {
                let sj = &slots[j * ar..(j + 1) * ar];
                let gj = &w.gr1[j * wd..(j + 1) * wd];
                for l in 0..mc {
                    let sl = &slots[l * ar..(l + 1) * ar];
                    let gl = &w.gr0[l * wd..(l + 1) * wd];
                    w.jac[j * mc + l] = coupling::<S>(sj, gj, sl, gl, &w.wm);
                }
            }
            if !lu_solve(mc, &mut w.jac[..mc * mc], &mut w.g[..mc]) {
                return Err(ClusterFailure {
                    member: members[worst_j] as usize,
                    residual: worst.sqrt(),
                    iterations: it,
                    kind: FailureKind::SingularNewton,
                });
            }
            // x ← x − W G(x0)ᵀ δ, ν ← ν + δ.
            for l in 0..mc {
                let dl = w.g[l];
                w.nu[l] += dl;
                let sl = &slots[l * ar..(l + 1) * ar];
                let gl = &w.gr0[l * wd..(l + 1) * wd];
                for a in 0..ar {
                    let s = sl[a] as usize;
                    let f = w.wm[s] * dl;
                    for k in 0..d {
                        w.x[s * d + k] -= f * gl[a * d + k];
                    }
                }
            }
            it += 1;
        }
        for (s, &i) in parts.iter().enumerate() {
            let i = i as usize;
            q[i * d..(i + 1) * d].copy_from_slice(&w.x[s * d..(s + 1) * d]);
        }
        if args.inv_h != 0.0 {
            // p½ = p̃ − G(x0)ᵀ ν / h.
            for l in 0..mc {
                let f = w.nu[l] * args.inv_h;
                let sl = &slots[l * ar..(l + 1) * ar];
                let gl = &w.gr0[l * wd..(l + 1) * wd];
                for a in 0..ar {
                    let i = parts[sl[a] as usize] as usize;
                    for k in 0..d {
                        p[i * d + k] -= f * gl[a * d + k];
                    }
                }
            }
        }
    }
    Ok(())
}

/// The velocity stage (RATTLE's projection onto M^H along the fibre) on
/// every cluster of one family: p ← p − G(q)ᵀ μ with G(q) M⁻¹ p = 0.
pub(crate) fn project_clusters<S: Stencil>(
    stencil: &S,
    table: &Table,
    plan: &FamilyClusters,
    inv_mass: &[f64],
    w: &mut ClusterScratch,
    q: &[f64],
    p: &mut [f64],
    report: &mut ClusterReport,
) -> Result<(), ClusterFailure> {
    let (d, ar) = (S::DIM, S::ARITY);
    let wd = ar * d;
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
            w.x[s * d..(s + 1) * d].copy_from_slice(&q[i * d..(i + 1) * d]);
            w.pl[s * d..(s + 1) * d].copy_from_slice(&p[i * d..(i + 1) * d]);
            w.wm[s] = inv_mass[i];
        }
        for j in 0..mc {
            let sj = &slots[j * ar..(j + 1) * ar];
            gather_member::<S>(sj, &w.x, &mut w.xm);
            let gr = &mut w.gr1[j * wd..(j + 1) * wd];
            stencil.gradient(&w.xm[..wd], table.data(members[j] as usize), gr);
            // rhs_j = ∇g_j · W p.
            let mut r = 0.0;
            for a in 0..ar {
                let s = sj[a] as usize;
                let mut dot = 0.0;
                for k in 0..d {
                    dot += gr[a * d + k] * w.pl[s * d + k];
                }
                r += w.wm[s] * dot;
            }
            w.g[j] = r;
        }
        for j in 0..mc {
            let sj = &slots[j * ar..(j + 1) * ar];
            let gj = &w.gr1[j * wd..(j + 1) * wd];
            for l in 0..=j {
                let sl = &slots[l * ar..(l + 1) * ar];
                let gl = &w.gr1[l * wd..(l + 1) * wd];
                w.jac[j * mc + l] = coupling::<S>(sj, gj, sl, gl, &w.wm);
            }
        }
        if !cholesky_solve(mc, &mut w.jac[..mc * mc], &mut w.g[..mc]) {
            return Err(ClusterFailure {
                member: members[0] as usize,
                residual: f64::NAN,
                iterations: 0,
                kind: FailureKind::SingularN,
            });
        }
        for l in 0..mc {
            let mu = w.g[l];
            let sl = &slots[l * ar..(l + 1) * ar];
            let gl = &w.gr1[l * wd..(l + 1) * wd];
            for a in 0..ar {
                let s = sl[a] as usize;
                for k in 0..d {
                    w.pl[s * d + k] -= mu * gl[a * d + k];
                }
            }
        }
        // The hidden constraints after projection, relative to
        // |∇g_j| · |velocity of the member's particles|.
        for j in 0..mc {
            let sj = &slots[j * ar..(j + 1) * ar];
            let gr = &w.gr1[j * wd..(j + 1) * wd];
            let (mut r, mut v2, mut n2) = (0.0, 0.0, 0.0);
            for a in 0..ar {
                let s = sj[a] as usize;
                let mut dot = 0.0;
                for k in 0..d {
                    let v = w.wm[s] * w.pl[s * d + k];
                    dot += gr[a * d + k] * v;
                    v2 += v * v;
                    n2 += gr[a * d + k] * gr[a * d + k];
                }
                r += dot;
            }
            let rel = r.abs() / (n2 * v2).sqrt().max(f64::MIN_POSITIVE);
            report.max_hidden = report.max_hidden.max(rel);
        }
        for (s, &i) in parts.iter().enumerate() {
            let i = i as usize;
            p[i * d..(i + 1) * d].copy_from_slice(&w.pl[s * d..(s + 1) * d]);
        }
    }
    Ok(())
}
