//! The closed-form SHAKE and RATTLE steps of a rigid triangle: three
//! distance constraints g = |x_a − x_b|² − d_ab² among three particles in
//! R³, any lengths (a strict triangle) and any masses. The analytic
//! position solve is SETTLE's (Miyamoto & Kollman, J. Comput. Chem. 13,
//! 952 (1992)), written for a general triangle; the velocity solve is the
//! RATTLE projection with its 3×3 matrix inverted in closed form.
//!
//! The position stage, SETTLE's construction and why it solves SHAKE's
//! equations exactly, is in `position.rs`; the velocity stage in
//! `velocity.rs`; their arithmetic in `real.rs`. This module holds the
//! kernels over a family's triangles: gathering them, batching triangles
//! of one shape, and handing a triangle without a closed-form answer to
//! the Newton kernel.
//!
//! Both stages are straight-line code (a triangle without an answer is
//! flagged, not branched on), written once over [`Real`]: one triangle
//! (`f64`), or [`LANES`] consecutive triangles of one shape side by side
//! ([`Lanes`]), each lane bit for bit the triangle solved alone, so that
//! the square roots and divisions of several molecules overlap.

use super::*;
use crate::tolerance::{HIDDEN_LIMIT, ROUNDOFF_CAP};

mod position;
mod real;
#[cfg(test)]
mod tests;
mod velocity;

use position::*;
use real::*;
use velocity::*;

/// The pairs of local particles of a triangle, pair k = s0 + s1 − 1 for a
/// member on slots (s0, s1).
const PAIRS: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];

/// Whether every cluster of a family is a triangle: three members of two
/// particles each, on the three distinct pairs of the cluster's three
/// particles (`slots` of a plan whose shape is (3, 3) and arity 2).
pub(crate) fn all_triangles(plan: &FamilyClusters, arity: usize) -> bool {
    if plan.fixed != Some((3, 3)) || arity != 2 {
        return false;
    }
    plan.slots.chunks_exact(6).all(|s| {
        let mut seen = 0u8;
        for m in s.chunks_exact(2) {
            let (a, b) = (m[0].min(m[1]), m[0].max(m[1]));
            if a == b || b > 2 {
                return false;
            }
            seen |= 1 << (a + b - 1);
        }
        seen == 0b111
    })
}
/// For each pair k of a cluster, the member on it (its row in the table).
#[inline(always)]
fn pair_members(plan: &FamilyClusters, c: usize) -> [usize; 3] {
    // (One slice each, checked once, rather than one per member.)
    let (s, m) = (
        &plan.slots[6 * c..6 * c + 6],
        &plan.members[3 * c..3 * c + 3],
    );
    let mut on = [0usize; 3];
    for j in 0..3 {
        on[(s[2 * j] + s[2 * j + 1] - 1) as usize] = m[j] as usize;
    }
    on
}

/// A triangle as the kernel reads it: its cluster, particles, the member
/// on each pair, inverse masses and squared lengths.
#[derive(Clone, Copy, Debug)]
struct Read {
    c: usize,
    parts: [usize; 3],
    on: [usize; 3],
    w: V3,
    d2: V3,
}

#[inline(always)]
fn read(plan: &FamilyClusters, table: &Table, inv_mass: &[f64], c: usize) -> Read {
    let p = &plan.particles[3 * c..3 * c + 3];
    let parts = [p[0] as usize, p[1] as usize, p[2] as usize];
    let on = pair_members(plan, c);
    let d2 = |k: usize| {
        let l = table.data(on[k])[0];
        l * l
    };
    Read {
        c,
        parts,
        on,
        w: [inv_mass[parts[0]], inv_mass[parts[1]], inv_mass[parts[2]]],
        d2: [d2(0), d2(1), d2(2)],
    }
}

/// The coordinates of a batch's triangles in local order, particle i's
/// at v[3 (i − base)..].
#[inline(always)]
fn gather<T: Real>(v: &[f64], base: usize, batch: &[Read]) -> [V3<T>; 3] {
    let mut out = [[T::splat(0.0); 3]; 3];
    for (s, o) in out.iter_mut().enumerate() {
        // Each lane's particle sliced once: one bounds check for its three
        // coordinates, not one each. (References, not copies: numbers
        // copied to the stack and read back as vectors stalled on the
        // stores.)
        let mut at = [&[0.0; 3]; LANES];
        for (a, r) in at.iter_mut().zip(batch) {
            *a = particle(v, r.parts[s] - base);
        }
        for (c, o) in o.iter_mut().enumerate() {
            *o = T::from_fn(|l| at[l][c]);
        }
    }
    out
}

/// Particle j's coordinates in R³ (one bounds check).
#[inline(always)]
fn particle(v: &[f64], j: usize) -> &[f64; 3] {
    v[3 * j..3 * j + 3].first_chunk().expect("a slice of 3")
}

/// Particle j's coordinates in R³, to write (one bounds check).
#[inline(always)]
fn particle_mut(v: &mut [f64], j: usize) -> &mut [f64; 3] {
    v[3 * j..3 * j + 3].first_chunk_mut().expect("a slice of 3")
}

/// The position stage (`shake_fixed`'s contract, the stencil a distance)
/// of T::N triangles of one `shape`, side by side: closed form, and the
/// Newton kernel, in the clusters' order, for a triangle the closed form
/// has no answer for within the tolerance.
#[inline(always)]
fn shake_batch<S: Stencil, T: Real>(
    w: &mut Work<'_>,
    f: &mut Fixed<3, 9>,
    shape: &Shape,
    batch: &[Read],
    stencil: &S,
    table: &Table,
    plan: &FamilyClusters,
    args: &ClusterArgs<'_>,
    fuse: bool,
    q: &mut [f64],
    p: &mut [f64],
) -> Result<(), ClusterFailure> {
    debug_assert_eq!(batch.len(), T::N);
    let (x0, xt) = (gather(args.q0, 0, batch), gather(q, w.base, batch));
    let sol = solve(shape, &x0, &xt);
    // The common case first: every lane takes the closed form's answer as
    // it is, decided by a few comparisons of whole registers (sufficient
    // conditions for the per-lane judgement below to pass, each lane the
    // same answer; a NaN fails them and is judged lane by lane). Those on
    // x̃ first, so that x̃ is not held across the rest (the per-lane path
    // gathers it again).
    //
    // x̃ already within the tolerance (or the round-off of its
    // coordinates): Newton takes it as it is, with ν = 0. The closed form
    // would solve exactly for the rounding of x̃ instead, and where a
    // step's displacement is below the resolution of the positions (a box
    // far from the origin) turn that rounding into an impulse of order
    // m·ulp(x)/h on the momenta.
    let mut plain = beyond(&xt, shape.d2, args.tol.max(ROUNDOFF_CAP));
    plain = plain & near_branch(&sol.x1, &xt, shape.min_d2);
    let res = residuals(&sol.x1, shape.d2);
    // (The momenta gathered after the solve: not held across it.)
    let mut pl = gather(p, w.base, batch);
    let with_p = args.inv_h != 0.0;
    let wv = [
        T::splat(shape.w[0]),
        T::splat(shape.w[1]),
        T::splat(shape.w[2]),
    ];
    let mut projected = None;
    if with_p {
        // p½ = p̃ − G(x0)ᵀ ν / h, ∇_a g = 2 (x0_a − x0_b).
        let (two, inv_h) = (T::splat(2.0), T::splat(args.inv_h));
        for (k, &(i, j)) in PAIRS.iter().enumerate() {
            let e = sub(x0[i], x0[j]);
            let fk = two * sol.nu[k] * inv_h;
            for c in 0..3 {
                pl[i][c] = pl[i][c] - fk * e[c];
                pl[j][c] = pl[j][c] + fk * e[c];
            }
        }
        if fuse {
            projected = Some(project(&sol.x1, wv, &pl));
        }
    }
    let tol = T::splat(args.tol);
    plain = plain & res[0].le(tol) & res[1].le(tol) & res[2].le(tol) & sol.valid();
    let judged = projected.as_ref().map(Projected::plain);
    if let Some((ok, _)) = judged {
        plain = plain & ok;
    }
    if shape.ok && T::all(plain) {
        w.max_rel = w.max_rel.max(worst(&res).max_lane());
        if let Some((_, worst2)) = judged {
            w.max_hidden = w.max_hidden.max(worst2.max_lane().sqrt());
        }
        let out = projected.as_ref().map_or(&pl, |pr| &pr.p);
        let mut a = Answer::empty();
        a.set(&sol, with_p.then_some(out));
        for (l, r) in batch.iter().enumerate() {
            write(w, r, l, &a, q, p);
        }
        return Ok(());
    }
    // (x̃ as gathered above: no lane of the batch is written yet.)
    let xt = gather(q, w.base, batch);
    let (valid, near) = (sol.valid(), near_branch(&sol.x1, &xt, shape.min_d2));
    let res_t = residuals(&xt, shape.d2);
    let mut a = Answer::empty();
    for (l, r) in batch.iter().enumerate() {
        let (worst, _) = worst_of(&res, l);
        let met = worst <= args.tol || at_roundoff(&sol.x1, &res, l, args.tol);
        // (No floor above ROUNDOFF_CAP: an ordinary step's x̃, off by
        // O(h²), is decided without computing the floors.)
        let needed = worst_of(&res_t, l).0 > args.tol.max(ROUNDOFF_CAP)
            || !at_roundoff(&xt, &res_t, l, args.tol);
        if !(needed && shape.ok && T::holds(valid, l) && met && T::holds(near, l)) {
            shake_fixed::<S, 3, 3, 9>(w, f, r.c, stencil, table, plan, args, fuse, q, p)?;
            continue;
        }
        w.max_rel = w.max_rel.max(worst);
        let out = match &projected {
            Some(pr) => match pr.judge(l, &wv, &pl) {
                Some((h, _)) if h <= HIDDEN_LIMIT => {
                    w.max_hidden = w.max_hidden.max(h);
                    &pr.p
                }
                h => {
                    // (q and ν written first, as they were before the
                    // judgement.)
                    a.set(&sol, None);
                    write(w, r, l, &a, q, p);
                    return Err(ClusterFailure {
                        member: r.on[h.map_or(0, |h| h.1)],
                        residual: h.map_or(f64::NAN, |h| h.0),
                        iterations: 0,
                        kind: FailureKind::SingularN,
                    });
                }
            },
            None => &pl,
        };
        a.set(&sol, with_p.then_some(out));
        write(w, r, l, &a, q, p);
    }
    Ok(())
}

/// A batch's answer in lanes: x1, ν and (when the step has them) the
/// momenta, each register stored once, so that a lane is read from memory
/// (a lane taken out of a register by a run-time index went through
/// memory and blends for every number).
struct Answer {
    x1: [[[f64; LANES]; 3]; 3],
    nu: [[f64; LANES]; 3],
    /// The momenta, where `has_p` (a flag rather than an `Option`: filling
    /// an `Option` in place went through a copy of the whole array).
    p: [[[f64; LANES]; 3]; 3],
    has_p: bool,
}

impl Answer {
    /// An answer to fill ([`Answer::set`]).
    #[inline(always)]
    fn empty() -> Answer {
        Answer {
            x1: [[[0.0; LANES]; 3]; 3],
            nu: [[0.0; LANES]; 3],
            p: [[[0.0; LANES]; 3]; 3],
            has_p: false,
        }
    }

    /// The batch's x1, ν, and the momenta `p` where the step has them,
    /// stored in place (loops over fixed ranges rather than closures: a
    /// closure is not inlined into the kernel compiled for AVX).
    #[inline(always)]
    fn set<T: Real>(&mut self, sol: &Solution<T>, p: Option<&[V3<T>; 3]>) {
        for s in 0..3 {
            for c in 0..3 {
                sol.x1[s][c].store(&mut self.x1[s][c]);
            }
            sol.nu[s].store(&mut self.nu[s]);
        }
        self.has_p = p.is_some();
        if let Some(p) = p {
            for s in 0..3 {
                for c in 0..3 {
                    p[s][c].store(&mut self.p[s][c]);
                }
            }
        }
    }
}

/// Lane l's answer written back: x1 to q, ν to the store, and the momenta
/// (when the answer has them) to p.
#[inline(always)]
fn write(w: &mut Work<'_>, r: &Read, l: usize, a: &Answer, q: &mut [f64], p: &mut [f64]) {
    for s in 0..3 {
        let x = &a.x1[s];
        *particle_mut(q, r.parts[s] - w.base) = [x[0][l], x[1][l], x[2][l]];
    }
    if let Some(st) = w.store.as_deref_mut() {
        for k in 0..3 {
            st[r.on[k] - w.mbase] = a.nu[k][l];
        }
    }
    if a.has_p {
        let out = &a.p;
        for s in 0..3 {
            let v = &out[s];
            *particle_mut(p, r.parts[s] - w.base) = [v[0][l], v[1][l], v[2][l]];
        }
    }
}

/// The loop of [`shake_clusters`] over a family of triangles of distance
/// constraints in R³ ([`FamilyClusters::settle`]): [`LANES`] consecutive
/// triangles of one shape at a time, one at a time where the shape
/// changes or the block ends. On a CPU with AVX the batches are one AVX
/// register per number ([`Wide`]), else two SSE2 ones ([`Lanes`]): the
/// same operations, the same bits, fewer registers spilled.
#[inline(never)]
pub(super) fn shake_triangles<S: Stencil>(
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
    #[cfg(target_arch = "x86_64")]
    if has_avx() {
        // SAFETY: the CPU has AVX, the one feature `triangles_avx` enables.
        return unsafe { triangles_avx(w, stencil, table, plan, args, fuse, clusters, q, p) };
    }
    triangles::<S, Lanes>(w, stencil, table, plan, args, fuse, clusters, q, p)
}

/// [`triangles`] over [`Wide`], compiled for AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn triangles_avx<S: Stencil>(
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
    triangles::<S, Wide>(w, stencil, table, plan, args, fuse, clusters, q, p)
}

/// [`shake_triangles`]' loop, its batches of [`LANES`] triangles over `L`.
#[inline(always)]
fn triangles<S: Stencil, L: Real>(
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
    debug_assert!(S::DIM == 3 && S::ARITY == 2 && L::N == LANES);
    let mut f = Fixed {
        sl: [[usize::MAX; FX]; 3],
        wg0d: [[0.0; 9]; 3],
        grd: [[0.0; 9]; 3],
    };
    // The reference triangle of the last molecule: a box of one kind of
    // molecule builds it once.
    let mut shape: Option<Shape> = None;
    let mut c = clusters.start;
    // (Filled in place batch by batch: `[first; LANES]` copied the first
    // triangle into every lane before the others overwrote it.)
    let mut batch = None;
    while c < clusters.end {
        let first = read(plan, table, args.inv_mass, c);
        let sh = match &mut shape {
            Some(s) if s.is(first.w, first.d2) => s,
            s => s.insert(Shape::new(first.w, first.d2)),
        };
        if c + LANES <= clusters.end {
            let batch = batch.get_or_insert([first; LANES]);
            batch[0] = first;
            let mut same = true;
            for (l, b) in batch.iter_mut().enumerate().skip(1) {
                *b = read(plan, table, args.inv_mass, c + l);
                same &= sh.is(b.w, b.d2);
            }
            if same {
                let (st, tb) = (stencil, table);
                shake_batch::<S, L>(w, &mut f, sh, batch, st, tb, plan, args, fuse, q, p)?;
                c += LANES;
                continue;
            }
        }
        let (st, tb) = (stencil, table);
        shake_batch::<S, f64>(w, &mut f, sh, &[first], st, tb, plan, args, fuse, q, p)?;
        c += 1;
    }
    Ok(())
}

/// The velocity stage on the triangles of one block (`project_block`'s
/// contract): the largest hidden residual left.
pub(super) fn project_triangles(
    plan: &FamilyClusters,
    inv_mass: &[f64],
    q: &[f64],
    block: Block,
    p: &mut [f64],
) -> Result<f64, ClusterFailure> {
    let base = block.particles.0;
    let mut max_hidden = 0.0f64;
    for c in block.clusters.0..block.clusters.1 {
        let parts = &plan.particles[3 * c..3 * c + 3];
        let (mut x, mut pl, mut w) = ([[0.0; 3]; 3], [[0.0; 3]; 3], [0.0; 3]);
        for (s, &i) in parts.iter().enumerate() {
            let (i, j) = (i as usize, i as usize - base);
            x[s] = q[3 * i..3 * i + 3].try_into().unwrap();
            pl[s] = p[3 * j..3 * j + 3].try_into().unwrap();
            w[s] = inv_mass[i];
        }
        let out = project(&x, w, &pl);
        match out.judge(0, &w, &pl) {
            Some((h, _)) if h <= HIDDEN_LIMIT => max_hidden = max_hidden.max(h),
            h => {
                return Err(ClusterFailure {
                    member: pair_members(plan, c)[h.map_or(0, |h| h.1)],
                    residual: h.map_or(f64::NAN, |h| h.0),
                    iterations: 0,
                    kind: FailureKind::SingularN,
                })
            }
        }
        for (s, &i) in parts.iter().enumerate() {
            let j = i as usize - base;
            p[3 * j..3 * j + 3].copy_from_slice(&out.p[s]);
        }
    }
    Ok(max_hidden)
}
