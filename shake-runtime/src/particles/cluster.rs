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

/// LU factorisation with partial pivoting of an n×n row-major matrix, in
/// place. False when a pivot is zero or not finite.
#[inline(always)]
fn lu_factor(n: usize, a: &mut [f64], piv: &mut [usize], dinv: &mut [f64]) -> bool {
    for k in 0..n {
        let mut p = k;
        let mut best = a[k * n + k].abs();
        for i in k + 1..n {
            let v = a[i * n + k].abs();
            if v > best {
                best = v;
                p = i;
            }
        }
        piv[k] = p;
        if !(best > 0.0 && best.is_finite()) {
            return false;
        }
        if p != k {
            for c in 0..n {
                a.swap(k * n + c, p * n + c);
            }
        }
        let inv = 1.0 / a[k * n + k];
        dinv[k] = inv;
        for i in k + 1..n {
            let f = a[i * n + k] * inv;
            a[i * n + k] = f;
            for c in k + 1..n {
                a[i * n + c] -= f * a[k * n + c];
            }
        }
    }
    true
}

/// b ← A⁻¹ b with the factors of [`lu_factor`] (divisions replaced by the
/// stored inverse pivots: they sat on the critical path).
#[inline(always)]
fn lu_solve(n: usize, a: &[f64], piv: &[usize], dinv: &[f64], b: &mut [f64]) {
    // The factorisation swapped whole rows (multipliers included), so
    // P A = L U with P all the swaps in order: apply P first.
    for k in 0..n {
        if piv[k] != k {
            b.swap(k, piv[k]);
        }
    }
    for k in 0..n {
        let bk = b[k];
        for i in k + 1..n {
            b[i] -= a[i * n + k] * bk;
        }
    }
    for k in (0..n).rev() {
        let mut s = b[k];
        for c in k + 1..n {
            s -= a[k * n + c] * b[c];
        }
        b[k] = s * dinv[k];
    }
}

/// Solves N μ = b in place for symmetric positive definite N (row-major,
/// lower triangle used) by Cholesky. False when N is not numerically
/// positive definite.
#[inline(always)]
fn cholesky_solve(n: usize, a: &mut [f64], b: &mut [f64]) -> bool {
    let mut dinv = [0.0; MAX_CLUSTER];
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
        dinv[j] = inv;
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
        b[i] = s * dinv[i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= a[k * n + i] * b[k];
        }
        b[i] = s * dinv[i];
    }
    true
}

/// For n ≤ 3: a ← a⁻¹ (row-major, in place) by the adjugate: one division
/// and independent products, where LU or Cholesky would chain n divisions
/// or square roots (the latency that bounds a water's step). False when
/// det a is zero or not finite, or (with `spd`) not positive.
#[inline(always)]
fn small_inverse(n: usize, a: &mut [f64], spd: bool) -> bool {
    let ok = |det: f64| det.is_finite() && if spd { det > 0.0 } else { det != 0.0 };
    match n {
        1 => {
            let det = a[0];
            if !ok(det) {
                return false;
            }
            a[0] = 1.0 / det;
        }
        2 => {
            let (p, q, r, t) = (a[0], a[1], a[2], a[3]);
            let det = p * t - q * r;
            if !ok(det) {
                return false;
            }
            let i = 1.0 / det;
            a[0] = t * i;
            a[1] = -q * i;
            a[2] = -r * i;
            a[3] = p * i;
        }
        _ => {
            let m = [a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8]];
            let c00 = m[4] * m[8] - m[5] * m[7];
            let c01 = m[5] * m[6] - m[3] * m[8];
            let c02 = m[3] * m[7] - m[4] * m[6];
            let det = m[0] * c00 + m[1] * c01 + m[2] * c02;
            if !ok(det) {
                return false;
            }
            let i = 1.0 / det;
            a[0] = c00 * i;
            a[1] = (m[2] * m[7] - m[1] * m[8]) * i;
            a[2] = (m[1] * m[5] - m[2] * m[4]) * i;
            a[3] = c01 * i;
            a[4] = (m[0] * m[8] - m[2] * m[6]) * i;
            a[5] = (m[2] * m[3] - m[0] * m[5]) * i;
            a[6] = c02 * i;
            a[7] = (m[1] * m[6] - m[0] * m[7]) * i;
            a[8] = (m[0] * m[4] - m[1] * m[3]) * i;
        }
    }
    true
}

/// b ← a b for a small n×n row-major a.
#[inline(always)]
fn small_apply(n: usize, a: &[f64], b: &mut [f64]) {
    let mut out = [0.0; 3];
    for i in 0..n {
        let mut s = 0.0;
        for j in 0..n {
            s += a[i * n + j] * b[j];
        }
        out[i] = s;
    }
    b[..n].copy_from_slice(&out[..n]);
}

const ML: usize = super::system::MAX_LOCAL;

/// One cluster's local copy: coordinates, momenta, inverse masses, and the
/// member blocks of G. Stack arrays, set up once per family per stage.
struct Local {
    x: [f64; MAX_CLUSTER_COORDS],
    pl: [f64; MAX_CLUSTER_COORDS],
    wm: [f64; MAX_CLUSTER_COORDS],
    gr: [f64; MAX_CLUSTER * ML],
    xm: [f64; ML],
    n: [f64; MAX_CLUSTER * MAX_CLUSTER],
    g: [f64; MAX_CLUSTER],
}

impl Local {
    fn new() -> Self {
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
    fn project<S: Stencil>(&mut self, mc: usize, slots: &[u8]) -> Option<f64> {
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
        // |∇g_j| · |velocity of the member's particles| (squared).
        let mut worst = 0.0f64;
        for j in 0..mc {
            let sj = &slots[j * ar..(j + 1) * ar];
            let gj = &self.gr[j * wd..(j + 1) * wd];
            let (mut r, mut v2, mut n2) = (0.0, 0.0, 0.0);
            for a in 0..ar {
                let s = sj[a] as usize;
                for k in 0..d {
                    let v = self.wm[s] * self.pl[s * d + k];
                    r += gj[a * d + k] * v;
                    v2 += v * v;
                    n2 += gj[a * d + k] * gj[a * d + k];
                }
            }
            let rel = r * r / (n2 * v2).max(f64::MIN_POSITIVE);
            if !(rel <= worst) {
                worst = rel;
            }
        }
        Some(worst)
    }
}

/// Everything one cluster works on, on the stack, set up once per family
/// per stage and reused cluster after cluster.
struct Work<'a> {
    /// ν of every member of the family from the previous step (read when
    /// `warm`, written after each cluster converges).
    store: Option<&'a mut [f64]>,
    warm: bool,
    l: Local,
    wg0: [f64; MAX_CLUSTER * ML],
    lu: [f64; MAX_CLUSTER * MAX_CLUSTER],
    piv: [usize; MAX_CLUSTER],
    dinv: [f64; MAX_CLUSTER],
    nu: [f64; MAX_CLUSTER],
    s2: [f64; MAX_CLUSTER],
    x0: [f64; MAX_CLUSTER_COORDS],
    max_rel: f64,
    max_hidden: f64,
    max_it: usize,
    iters: u64,
}

/// One cluster of `mc` constraints. Always inlined, and called with `mc` a
/// literal for the common sizes, so every loop over the cluster's members
/// is unrolled and its bounds checks fold away.
#[inline(always)]
fn shake_one<S: Stencil>(
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
        l,
        wg0,
        lu,
        piv,
        dinv,
        nu,
        s2,
        x0,
        max_rel,
        max_hidden,
        max_it,
        iters,
    } = w;
    let (d, ar) = (S::DIM, S::ARITY);
    let wd = ar * d;
    let tol2 = args.tol * args.tol;
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
        let i = i as usize;
        x0[s * d..(s + 1) * d].copy_from_slice(&args.q0[i * d..(i + 1) * d]);
        l.x[s * d..(s + 1) * d].copy_from_slice(&q[i * d..(i + 1) * d]);
        l.pl[s * d..(s + 1) * d].copy_from_slice(&p[i * d..(i + 1) * d]);
        l.wm[s] = args.inv_mass[i];
    }
    // W G(x0) and the residual scales |∇g_j(x0)|² · extent_j(x0)².
    for j in 0..mc {
        let sj = &slots[j * ar..(j + 1) * ar];
        gather_member::<S>(sj, &x0[..], &mut l.xm);
        let gr = &mut wg0[j * wd..(j + 1) * wd];
        stencil.gradient(&l.xm[..wd], table.data(members[j] as usize), gr);
        let mut n2 = 0.0;
        for a in 0..ar {
            let w = l.wm[sj[a] as usize];
            for k in 0..d {
                let v = gr[a * d + k];
                n2 += v * v;
                gr[a * d + k] = w * v;
            }
        }
        // 1/scale², so the residual test multiplies.
        s2[j] = 1.0 / (n2 * extent2::<S>(&l.xm[..wd])).max(f64::MIN_POSITIVE);
        nu[j] = 0.0;
    }
    // Warm start: the previous step's ν (the constraint impulses change
    // slowly along a trajectory; for a free rigid rotor they are constant),
    // so Newton starts near the solution: x ← x̃ − W G(x0)ᵀ ν_prev.
    if let (true, Some(st)) = (*warm, store.as_deref()) {
        for m in 0..mc {
            let v = st[members[m] as usize];
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
    let mut prev = f64::INFINITY;
    loop {
        // g at the current iterate (and G when the Jacobian is due).
        let mut worst = 0.0f64;
        let mut worst_j = 0;
        for j in 0..mc {
            let sj = &slots[j * ar..(j + 1) * ar];
            gather_member::<S>(sj, &l.x, &mut l.xm);
            let data = table.data(members[j] as usize);
            // With `fuse`, G at every iterate: the last one is G(q1), which
            // the velocity stage needs (no separate evaluation at q1).
            let g = if need_jac || fuse {
                stencil.gradient(&l.xm[..wd], data, &mut l.gr[j * wd..(j + 1) * wd])
            } else {
                stencil.value(&l.xm[..wd], data)
            };
            l.g[j] = g;
            let r = g * g * s2[j];
            if !(r <= worst) {
                worst = r;
                worst_j = j;
            }
        }
        if worst <= tol2 {
            *max_rel = max_rel.max(worst);
            *max_it = (*max_it).max(it);
            *iters += it as u64;
            break;
        }
        if !worst.is_finite() || it >= args.max_iter {
            return Err(ClusterFailure {
                member: members[worst_j] as usize,
                residual: worst.sqrt(),
                iterations: it,
                kind: if worst.is_finite() {
                    FailureKind::NotConverged
                } else {
                    FailureKind::NotFinite
                },
            });
        }
        if !need_jac && worst > 0.25 * prev {
            // Poor contraction: the Jacobian at this iterate.
            for j in 0..if fuse { 0 } else { mc } {
                let sj = &slots[j * ar..(j + 1) * ar];
                gather_member::<S>(sj, &l.x, &mut l.xm);
                let data = table.data(members[j] as usize);
                stencil.gradient(&l.xm[..wd], data, &mut l.gr[j * wd..(j + 1) * wd]);
            }
            need_jac = true;
        }
        prev = worst;
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
                    residual: worst.sqrt(),
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
        let i = i as usize;
        q[i * d..(i + 1) * d].copy_from_slice(&l.x[s * d..(s + 1) * d]);
    }
    if let Some(st) = store.as_deref_mut() {
        for m in 0..mc {
            st[members[m] as usize] = nu[m];
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
            match l.project::<S>(mc, slots) {
                Some(h) => *max_hidden = max_hidden.max(h),
                None => {
                    return Err(ClusterFailure {
                        member: members[0] as usize,
                        residual: f64::NAN,
                        iterations: it,
                        kind: FailureKind::SingularN,
                    })
                }
            }
        }
        for (s, &i) in parts.iter().enumerate() {
            let i = i as usize;
            p[i * d..(i + 1) * d].copy_from_slice(&l.pl[s * d..(s + 1) * d]);
        }
    }
    Ok(())
}

/// Largest ARITY and DIM of a stencil the fixed-size kernel takes.
const FX: usize = 3;

/// Gathers member coordinates (slots `sl`, ARITY·DIM entries) from the
/// dense local copy `x` (NX = particles × DIM entries) into `xm`.
#[inline(always)]
fn gather_fixed<S: Stencil, const NX: usize>(sl: &[usize; FX], x: &[f64; NX], xm: &mut [f64; 9]) {
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
fn dot_block<S: Stencil, const NX: usize>(
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
fn axpy_block<S: Stencil, const NX: usize>(
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
fn scatter_block<S: Stencil, const NX: usize>(sl: &[usize; FX], a: &[f64; 9], row: &mut [f64; NX]) {
    let d = S::DIM;
    for t in 0..S::ARITY {
        for k in 0..d {
            row[sl[t] * d + k] = a[t * d + k];
        }
    }
}

/// The stack buffers of [`shake_fixed`], set up once per family.
struct Fixed<const MC: usize, const NX: usize> {
    /// The slots of the previous cluster: the dense rows are zero off
    /// them, so they are cleared only when the slots change.
    sl: [[usize; FX]; MC],
    /// W G(x0), dense rows.
    wg0d: [[f64; NX]; MC],
    /// G(x1), dense rows (velocity stage).
    grd: [[f64; NX]; MC],
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
fn shake_fixed<S: Stencil, const MC: usize, const NP: usize, const NX: usize>(
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
    let tol2 = args.tol * args.tol;
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
        let i = parts[s] as usize;
        let (a0, aq, ap) = (&args.q0[i * d..], &q[i * d..], &p[i * d..]);
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
    // G(x0) and W G(x0) (member blocks, and W G(x0) as dense rows), and the
    // residual scales 1 / (|∇g_j(x0)|² extent_j²).
    let mut g0 = [[0.0; 9]; MC];
    let mut wg0 = [[0.0; 9]; MC];
    let mut s2 = [0.0; MC];
    let mut xm = [0.0; 9];
    for j in 0..MC {
        gather_fixed::<S, NX>(&sl[j], &x0, &mut xm);
        stencil.gradient(&xm[..wd], data[j], &mut g0[j][..wd]);
        let mut n2 = 0.0;
        for t in 0..ar {
            for k in 0..d {
                let v = g0[j][t * d + k];
                n2 += v * v;
                wg0[j][t * d + k] = wx[sl[j][t] * d + k] * v;
            }
        }
        s2[j] = 1.0 / (n2 * extent2::<S>(&xm[..wd])).max(f64::MIN_POSITIVE);
        scatter_block::<S, NX>(&sl[j], &wg0[j], &mut f.wg0d[j]);
    }
    let mut nu = [0.0; MC];
    if let (true, Some(st)) = (w.warm, w.store.as_deref()) {
        for m in 0..MC {
            nu[m] = st[members[m] as usize];
            axpy_block::<S, NX>(&sl[m], nu[m], &wg0[m], &mut x);
        }
    }
    let mut gr = [[0.0; 9]; MC];
    let mut gv = [0.0; MC];
    let mut jinv = [0.0; 9];
    let mut it = 0;
    let mut need_jac = true;
    let mut prev = f64::INFINITY;
    loop {
        let mut worst = 0.0f64;
        let mut worst_j = 0;
        for j in 0..MC {
            gather_fixed::<S, NX>(&sl[j], &x, &mut xm);
            let g = if need_jac || fuse {
                stencil.gradient(&xm[..wd], data[j], &mut gr[j][..wd])
            } else {
                stencil.value(&xm[..wd], data[j])
            };
            gv[j] = g;
            let r = g * g * s2[j];
            if !(r <= worst) {
                worst = r;
                worst_j = j;
            }
        }
        if worst <= tol2 {
            w.max_rel = w.max_rel.max(worst);
            w.max_it = w.max_it.max(it);
            w.iters += it as u64;
            break;
        }
        if !worst.is_finite() || it >= args.max_iter {
            return Err(ClusterFailure {
                member: members[worst_j] as usize,
                residual: worst.sqrt(),
                iterations: it,
                kind: if worst.is_finite() {
                    FailureKind::NotConverged
                } else {
                    FailureKind::NotFinite
                },
            });
        }
        if !need_jac && worst > 0.25 * prev {
            for j in 0..MC {
                gather_fixed::<S, NX>(&sl[j], &x, &mut xm);
                stencil.gradient(&xm[..wd], data[j], &mut gr[j][..wd]);
            }
            need_jac = true;
        }
        prev = worst;
        if need_jac {
            for j in 0..MC {
                for m in 0..MC {
                    jinv[j * MC + m] = dot_block::<S, NX>(&sl[j], &gr[j], None, &f.wg0d[m]);
                }
            }
            if !small_inverse(MC, &mut jinv[..MC * MC], false) {
                return Err(ClusterFailure {
                    member: members[worst_j] as usize,
                    residual: worst.sqrt(),
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
        let i = parts[s] as usize;
        q[i * d..i * d + d].copy_from_slice(&x[s * d..s * d + d]);
    }
    if let Some(st) = w.store.as_deref_mut() {
        for m in 0..MC {
            st[members[m] as usize] = nu[m];
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
        // |velocity of the member's particles| (squared).
        let mut worst = 0.0f64;
        for j in 0..MC {
            let (mut rj, mut v2, mut n2) = (0.0, 0.0, 0.0);
            for t in 0..ar {
                for k in 0..d {
                    let i = sl[j][t] * d + k;
                    let v = wx[i] * pl[i];
                    let g = gr[j][t * d + k];
                    rj += g * v;
                    v2 += v * v;
                    n2 += g * g;
                }
            }
            let rel = rj * rj / (n2 * v2).max(f64::MIN_POSITIVE);
            if !(rel <= worst) {
                worst = rel;
            }
        }
        w.max_hidden = w.max_hidden.max(worst);
    }
    for s in 0..NP {
        let i = parts[s] as usize;
        p[i * d..i * d + d].copy_from_slice(&pl[s * d..s * d + d]);
    }
    Ok(())
}

/// The loop of [`shake_clusters`] over a family of uniform shape.
#[inline(never)]
fn shake_fixed_all<S: Stencil, const MC: usize, const NP: usize, const NX: usize>(
    w: &mut Work<'_>,
    stencil: &S,
    table: &Table,
    plan: &FamilyClusters,
    args: &ClusterArgs<'_>,
    fuse: bool,
    q: &mut [f64],
    p: &mut [f64],
) -> Result<(), ClusterFailure> {
    let mut f = Fixed {
        sl: [[usize::MAX; FX]; MC],
        wg0d: [[0.0; NX]; MC],
        grd: [[0.0; NX]; MC],
    };
    for c in 0..plan.len() {
        shake_fixed::<S, MC, NP, NX>(w, &mut f, c, stencil, table, plan, args, fuse, q, p)?;
    }
    Ok(())
}

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
        s2: [0.0; MAX_CLUSTER],
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
    report.max_rel = report.max_rel.max(w.max_rel.sqrt());
    report.max_hidden = report.max_hidden.max(w.max_hidden.sqrt());
    report.max_iter = report.max_iter.max(w.max_it);
    report.iterations += w.iters;
    Ok(())
}

/// The velocity stage (RATTLE's projection onto M^H along the fibre) on
/// every cluster of one family: p ← p − G(q)ᵀ μ with G(q) M⁻¹ p = 0.
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
            Some(h) => max_hidden = max_hidden.max(h),
            None => {
                return Err(ClusterFailure {
                    member: members[0] as usize,
                    residual: f64::NAN,
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
    report.max_hidden = report.max_hidden.max(max_hidden.sqrt());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A nonsymmetric matrix that needs pivoting, and an SPD one: each
    /// small solver against the residual of the system it solved.
    #[test]
    fn small_solvers_solve() {
        let a0 = [
            0.0, 2.0, 1.0, 3.0, //
            1.0, 1.0, 0.0, 2.0, //
            4.0, 0.5, 2.0, 1.0, //
            1.0, 3.0, 1.0, 0.0,
        ];
        let b0 = [1.0, -2.0, 0.5, 3.0];
        for n in 1..=4 {
            let mut a = [0.0; 16];
            for i in 0..n {
                for j in 0..n {
                    // Shift the diagonal for n = 1 (a00 = 0).
                    a[i * n + j] = a0[i * 4 + j] + if i == j { 0.25 } else { 0.0 };
                }
            }
            let orig = a;
            let mut x = b0;
            let (mut piv, mut dinv) = ([0; 4], [0.0; 4]);
            assert!(lu_factor(n, &mut a[..n * n], &mut piv, &mut dinv));
            lu_solve(n, &a[..n * n], &piv, &dinv, &mut x[..n]);
            let mut y = b0;
            let mut inv = orig;
            if n <= 3 {
                assert!(small_inverse(n, &mut inv[..n * n], false));
                small_apply(n, &inv[..n * n], &mut y[..n]);
            }
            for i in 0..n {
                let r: f64 = (0..n).map(|j| orig[i * n + j] * x[j]).sum::<f64>() - b0[i];
                assert!(r.abs() < 1e-14, "LU n={n} row {i}: {r:e}");
                if n <= 3 {
                    assert!((x[i] - y[i]).abs() < 1e-14, "inverse n={n}");
                }
            }
        }
        // SPD: Cholesky.
        let mut s = [4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0];
        let orig = s;
        let mut x = [1.0, 2.0, 3.0];
        assert!(cholesky_solve(3, &mut s, &mut x));
        for i in 0..3 {
            let r: f64 = (0..3).map(|j| orig[i * 3 + j] * x[j]).sum::<f64>() - [1.0, 2.0, 3.0][i];
            assert!(r.abs() < 1e-14);
        }
    }
}
