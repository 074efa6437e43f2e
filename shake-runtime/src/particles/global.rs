//! The coupled path of [`Rattle`](super::Rattle) (chains, general constraint
//! graphs): one simplified Newton over every constraint, with the factor of
//! N(q0) = G(q0) M⁻¹ G(q0)ᵀ assembled from the stencils' gradients and
//! factorised by the banded or sparse [`SpdSolver`].
//!
//! On systems of more than one chunk ([`PARALLEL_PARTICLES`]) of members,
//! particles or entries of N, every pass goes to threads in chunks of that
//! fixed size, and each number is computed by the operations, in the
//! order, of the serial pass: the member passes (values, gradients,
//! hidden constraints) write disjoint members; the maxima are exact in any
//! order; the assembly of N sums each entry's terms in one place (its
//! terms sorted by entry, in their serial order); the scatters
//! out ← out − W Gᵀ x are gathers, each particle subtracting the terms of
//! the constraints touching it in ascending order, the order in which the
//! serial scatter over the members reaches it. So the bits do not depend
//! on the number of threads, and are the serial pass's; the band solver's
//! partition for large m ([`BandCholesky`](crate::solver::BandCholesky))
//! depends on m and the bandwidth only.

use super::graph::{self, Numbering};
use super::plan::{parallel, ClusterArgs, PARALLEL_PARTICLES};
use super::ParticleSystem;
use crate::error::{SolveError, Stage, StepError};
use crate::newton::{Rate, Residuals};
use crate::report::StepInfo;
use crate::solver::SpdSolver;
use crate::tolerance::roundoff_floor;
use rayon::prelude::*;

/// The coupled path (chains, general graphs): one simplified Newton over
/// every constraint with the factor of N(q0).
#[derive(Clone)]
pub(super) struct Global {
    pub(super) solver: SpdSolver,
    /// Assembly of N from gradients: entry `pos[e]` gains
    /// `W_{part[e]}` ∇_a g_x · ∇_a g_y with the two gradient blocks at
    /// `ga[e]`, `gb[e]`. Sorted by `pos` (stably: each entry's terms in
    /// the order of the particles), so that a chunk of entries owns a
    /// range of terms.
    pub(super) pos: Vec<u32>,
    pub(super) ga: Vec<u32>,
    pub(super) gb: Vec<u32>,
    pub(super) part: Vec<u32>,
    /// For every particle i, `touch_start[i]..touch_start[i + 1]` into
    /// `touch_c` (the constraints touching i, ascending) and `touch_g`
    /// (where i's block of that constraint's gradient starts): the
    /// scatters as gathers.
    pub(super) touch_start: Vec<u32>,
    pub(super) touch_c: Vec<u32>,
    pub(super) touch_g: Vec<u32>,
    pub(super) grad0: Vec<f64>,
    pub(super) grad1: Vec<f64>,
    /// 1 / (|∇g| · extent) of every member at q0 and at q1
    /// (`tolerance::inverse_scale`).
    pub(super) scale0: Vec<f64>,
    pub(super) scale1: Vec<f64>,
    pub(super) g: Vec<f64>,
    pub(super) nu: Vec<f64>,
    pub(super) delta: Vec<f64>,
    /// |M⁻¹ p|² over each member's particles before the velocity stage.
    pub(super) before: Vec<f64>,
    /// N's factor holds N(q) of the state with this stamp (0: none).
    pub(super) factor_stamp: u64,
}

impl Global {
    pub(super) fn new(
        system: &ParticleSystem,
        num: &Numbering,
        comps: &graph::Components,
        solver: SpdSolver,
    ) -> Self {
        let d = system.dim();
        let m = system.constraints();
        let fams = system.constraint_families();
        // Where particle i sits in constraint c's row, and c's gradient block.
        let block = |c: usize, i: u32| -> u32 {
            let (f, k) = num.locate(c);
            let t = fams[f].table();
            let a = t
                .particles(k)
                .iter()
                .position(|&j| j == i)
                .expect("touching");
            (num.grad_offsets[f] + (k * t.arity() + a) * d) as u32
        };
        let (mut pos, mut ga, mut gb, mut part) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for i in 0..system.particles() {
            let cs = &comps.touch[comps.touch_start[i]..comps.touch_start[i + 1]];
            for (a, &x) in cs.iter().enumerate() {
                for &y in &cs[..=a] {
                    let (x, y) = (x as usize, y as usize);
                    let (r, c) = (x.max(y), x.min(y));
                    pos.push(solver.position(r, c) as u32);
                    ga.push(block(x, i as u32));
                    gb.push(block(y, i as u32));
                    part.push(i as u32);
                }
            }
        }
        // Stable: an entry's terms keep their order (that of the particles).
        let mut order: Vec<u32> = (0..pos.len() as u32).collect();
        order.sort_by_key(|&e| pos[e as usize]);
        let permute = |v: &[u32]| -> Vec<u32> { order.iter().map(|&e| v[e as usize]).collect() };
        let (pos, ga, gb, part) = (permute(&pos), permute(&ga), permute(&gb), permute(&part));
        let touch_start = comps.touch_start.iter().map(|&t| t as u32).collect();
        let touch_c = comps.touch.clone();
        let mut touch_g = Vec::with_capacity(touch_c.len());
        for i in 0..system.particles() {
            let cs = &comps.touch[comps.touch_start[i]..comps.touch_start[i + 1]];
            touch_g.extend(cs.iter().map(|&c| block(c as usize, i as u32)));
        }
        let ng = *num.grad_offsets.last().unwrap();
        Global {
            solver,
            pos,
            ga,
            gb,
            part,
            touch_start,
            touch_c,
            touch_g,
            grad0: vec![0.0; ng],
            grad1: vec![0.0; ng],
            scale0: vec![0.0; m],
            scale1: vec![0.0; m],
            g: vec![0.0; m],
            nu: vec![0.0; m],
            delta: vec![0.0; m],
            before: vec![0.0; m],
            factor_stamp: 0,
        }
    }

    pub(super) fn bytes(&self) -> usize {
        self.solver.bytes()
            + 4 * (self.pos.capacity()
                + self.ga.capacity()
                + self.gb.capacity()
                + self.part.capacity()
                + self.touch_start.capacity()
                + self.touch_c.capacity()
                + self.touch_g.capacity())
            + 8 * (self.grad0.capacity()
                + self.grad1.capacity()
                + self.scale0.capacity()
                + self.scale1.capacity()
                + self.g.capacity()
                + self.nu.capacity()
                + self.delta.capacity()
                + self.before.capacity())
    }

    /// Gradients and scales at q into (grad, scale); every family.
    pub(super) fn gradients(
        system: &ParticleSystem,
        num: &Numbering,
        q: &[f64],
        g: &mut [f64],
        grad: &mut [f64],
        scale: &mut [f64],
    ) {
        for (f, fam) in system.constraint_families().iter().enumerate() {
            let (c0, c1) = (num.offsets[f], num.offsets[f + 1]);
            let (g0, g1) = (num.grad_offsets[f], num.grad_offsets[f + 1]);
            let (g, grad, scale) = (&mut g[c0..c1], &mut grad[g0..g1], &mut scale[c0..c1]);
            if parallel(c1 - c0) {
                let (n, w) = (PARALLEL_PARTICLES, fam.table().arity() * system.dim());
                g.par_chunks_mut(n)
                    .zip(grad.par_chunks_mut(n * w))
                    .zip(scale.par_chunks_mut(n))
                    .enumerate()
                    .for_each(|(j, ((g, grad), s))| {
                        fam.gradients_from(q, j * n, g, grad, Some(s));
                    });
            } else {
                fam.gradients_scaled(q, g, grad, scale);
            }
        }
    }

    /// g(q) into `g`, every family.
    fn values(system: &ParticleSystem, num: &Numbering, q: &[f64], g: &mut [f64]) {
        for (f, fam) in system.constraint_families().iter().enumerate() {
            let g = &mut g[num.offsets[f]..num.offsets[f + 1]];
            if parallel(g.len()) {
                let n = PARALLEL_PARTICLES;
                g.par_chunks_mut(n)
                    .enumerate()
                    .for_each(|(j, g)| fam.values_from(q, j * n, g));
            } else {
                fam.values(q, g);
            }
        }
    }

    /// N = G W Gᵀ from `grad`, factorised.
    pub(super) fn assemble_factor(
        &mut self,
        d: usize,
        inv_m: &[f64],
        which: u8,
    ) -> Result<(), usize> {
        let grad = if which == 0 { &self.grad0 } else { &self.grad1 };
        let (pos, ga, gb, part) = (&self.pos, &self.ga, &self.gb, &self.part);
        // The terms e of a range of entries, added in their order.
        let add = |v: &mut [f64], first: usize, terms: std::ops::Range<usize>| {
            let (ga, gb, part) = (&ga[terms.clone()], &gb[terms.clone()], &part[terms.clone()]);
            for (((&p, &a), &b), &i) in pos[terms].iter().zip(ga).zip(gb).zip(part) {
                let (a, b) = (a as usize, b as usize);
                let mut dot = 0.0;
                for c in 0..d {
                    dot += grad[a + c] * grad[b + c];
                }
                v[p as usize - first] += inv_m[i as usize] * dot;
            }
        };
        let v = self.solver.values_mut();
        if parallel(v.len()) {
            let n = PARALLEL_PARTICLES;
            v.par_chunks_mut(n).enumerate().for_each(|(j, v)| {
                let at = |p: usize| pos.partition_point(|&q| (q as usize) < p);
                v.fill(0.0);
                add(v, j * n, at(j * n)..at(j * n + v.len()));
            });
        } else {
            v.fill(0.0);
            add(v, 0, 0..pos.len());
        }
        self.solver.factor()
    }

    /// out ← out − factor · W^w Gᵀ x, family by family (monomorphic loops),
    /// or on threads particle by particle ([`gather`](Self::gather)).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn scatter(
        &self,
        system: &ParticleSystem,
        num: &Numbering,
        grad: &[f64],
        x: &[f64],
        weighted: bool,
        out: &mut [f64],
        factor: f64,
    ) {
        let inv_m = system.inverse_masses();
        if parallel(inv_m.len()) {
            self.gather(system.dim(), inv_m, grad, x, weighted, out, factor);
            return;
        }
        for (f, fam) in system.constraint_families().iter().enumerate() {
            let (c0, c1) = (num.offsets[f], num.offsets[f + 1]);
            let (g0, g1) = (num.grad_offsets[f], num.grad_offsets[f + 1]);
            fam.scatter(&grad[g0..g1], &x[c0..c1], inv_m, weighted, factor, out);
        }
    }

    /// out ← out − factor · W^w Gᵀ x on threads, in chunks of particles:
    /// particle i's entries lose the terms x_c ∇_i g_c of the constraints
    /// c touching it in ascending order, the order of the serial scatter
    /// (the same products, subtracted in the same order: the same bits).
    #[allow(clippy::too_many_arguments)]
    fn gather(
        &self,
        d: usize,
        inv_m: &[f64],
        grad: &[f64],
        x: &[f64],
        weighted: bool,
        out: &mut [f64],
        factor: f64,
    ) {
        let n = PARALLEL_PARTICLES;
        let (start, tc, tg) = (&self.touch_start, &self.touch_c, &self.touch_g);
        out.par_chunks_mut(n * d).enumerate().for_each(|(j, out)| {
            for (l, o) in out.chunks_exact_mut(d).enumerate() {
                let i = j * n + l;
                for t in start[i] as usize..start[i + 1] as usize {
                    let xk = x[tc[t] as usize] * factor;
                    let s = if weighted { xk * inv_m[i] } else { xk };
                    let gk = &grad[tg[t] as usize..tg[t] as usize + d];
                    for (o, g) in o.iter_mut().zip(gk) {
                        *o -= s * g;
                    }
                }
            }
        });
    }

    pub(super) fn singular(
        system: &ParticleSystem,
        num: &Numbering,
        pivot: usize,
        stage: Stage,
        iterations: usize,
        k: u64,
        time: f64,
    ) -> StepError {
        // The sparse solver's pivot is in its own order; name a member of
        // the system anyway (the pivot's constraint in natural order).
        let c = pivot.min(system.constraints().saturating_sub(1));
        num.error_at(
            system,
            c,
            stage,
            k,
            time,
            SolveError::Singular { iterations },
        )
    }

    #[allow(clippy::too_many_arguments)]
    pub(super) fn position_stage(
        &mut self,
        system: &ParticleSystem,
        num: &Numbering,
        args: &ClusterArgs<'_>,
        reuse: bool,
        qn: &mut [f64],
        pn: &mut [f64],
        k: u64,
        time: f64,
        report: &mut StepInfo,
    ) -> Result<(), StepError> {
        // Newton along the fibre from a step, or the projection of initial
        // data onto M (no 1/h: no momenta to update).
        let stage = if args.inv_h != 0.0 {
            Stage::Shake
        } else {
            Stage::ProjectionOntoM
        };
        let d = system.dim();
        let inv_m = system.inverse_masses();
        if !reuse {
            Self::gradients(
                system,
                num,
                args.q0,
                &mut self.g,
                &mut self.grad0,
                &mut self.scale0,
            );
            self.assemble_factor(d, inv_m, 0)
                .map_err(|p| Self::singular(system, num, p, stage, 0, k, time))?;
        }
        if reuse && args.inv_h != 0.0 {
            // Warm start along a trajectory: the previous step's ν.
            self.scatter(system, num, &self.grad0, &self.nu, true, qn, 1.0);
        } else {
            self.nu.fill(0.0);
        }
        let mut it = 0;
        let mut rate = Residuals::new(args.max_iter);
        loop {
            Self::values(system, num, qn, &mut self.g);
            let worst = if parallel(self.g.len()) {
                let n = PARALLEL_PARTICLES;
                let g = self.g.par_chunks(n).zip(self.scale0.par_chunks(n));
                g.map(|(g, s)| largest_relative(g, s))
                    .reduce(|| 0.0, larger_or_nan)
            } else {
                largest_relative(&self.g, &self.scale0)
            };
            if worst <= args.tol {
                report.residual = Some(worst);
                report.shake_iterations = it;
                report.shake_iterations_total = it as u64;
                break;
            }
            // N(q0) is kept whatever the contraction: a fresh factor is a
            // factorisation of the whole system, and the contraction per
            // iteration is O(h²|v|²/l²) from the predictor.
            let at_roundoff = || {
                Self::within_roundoff(
                    system,
                    num,
                    qn,
                    &self.g,
                    &self.grad0,
                    &self.scale0,
                    args.tol,
                )
            };
            let source = match rate.judge(worst, it, at_roundoff) {
                Rate::RoundOff => {
                    report.residual = Some(worst);
                    report.shake_iterations = it;
                    report.shake_iterations_total = it as u64;
                    break;
                }
                Rate::Fast | Rate::Slow => None,
                Rate::NonFinite => Some(SolveError::NonFinite { iterations: it }),
                Rate::NotConverged => Some(SolveError::NotConverged {
                    iterations: it,
                    residual: worst,
                }),
            };
            if let Some(source) = source {
                let worst_c = where_largest(&self.g, &self.scale0, worst);
                return Err(num.error_at(system, worst_c, stage, k, time, source));
            }
            // g is re-evaluated next iteration: solve in its buffer.
            std::mem::swap(&mut self.delta, &mut self.g);
            self.solver.solve(&mut self.delta);
            for (n, dl) in self.nu.iter_mut().zip(&self.delta) {
                *n += dl;
            }
            // G(q0) recomputed, not streamed from grad0 (see scatter_at);
            // on threads into grad1 (free until the velocity stage), with
            // g (re-evaluated next iteration) for the values, then
            // gathered.
            let inv_m = system.inverse_masses();
            if parallel(inv_m.len()) {
                for (f, fam) in system.constraint_families().iter().enumerate() {
                    let (c0, c1) = (num.offsets[f], num.offsets[f + 1]);
                    let (g0, g1) = (num.grad_offsets[f], num.grad_offsets[f + 1]);
                    let (n, w) = (PARALLEL_PARTICLES, fam.table().arity() * d);
                    let g = self.g[c0..c1].par_chunks_mut(n);
                    g.zip(self.grad1[g0..g1].par_chunks_mut(n * w))
                        .enumerate()
                        .for_each(|(j, (g, grad))| {
                            fam.gradients_from(args.q0, j * n, g, grad, None);
                        });
                }
                self.gather(d, inv_m, &self.grad1, &self.delta, true, qn, 1.0);
            } else {
                for (f, fam) in system.constraint_families().iter().enumerate() {
                    let (c0, c1) = (num.offsets[f], num.offsets[f + 1]);
                    fam.scatter_at(args.q0, &self.delta[c0..c1], inv_m, true, 1.0, qn);
                }
            }
            it += 1;
        }
        if args.inv_h != 0.0 {
            self.scatter(system, num, &self.grad0, &self.nu, false, pn, args.inv_h);
        }
        Ok(())
    }

    #[allow(clippy::too_many_arguments)]
    pub(super) fn velocity_stage(
        &mut self,
        system: &ParticleSystem,
        num: &Numbering,
        q1: &[f64],
        pn: &mut [f64],
        position_tol: Option<f64>,
        k: u64,
        time: f64,
        report: &mut StepInfo,
    ) -> Result<(), StepError> {
        let d = system.dim();
        let inv_m = system.inverse_masses();
        Self::gradients(
            system,
            num,
            q1,
            &mut self.g,
            &mut self.grad1,
            &mut self.scale1,
        );
        self.assemble_factor(d, inv_m, 1)
            .map_err(|p| Self::singular(system, num, p, Stage::Rattle, 0, k, time))?;
        self.hidden(system, num, pn, false);
        self.solver.solve(&mut self.delta);
        self.scatter(system, num, &self.grad1, &self.delta, false, pn, 1.0);
        // The position stage's result judged at its own scale (its test
        // used q0's, which from far off M is the far point's): g(q1) and
        // the scales at q1 are in hand from the gradients above.
        if let Some(tol) = position_tol {
            self.judge_at_q1(system, num, q1, tol, report.shake_iterations, k, time)?;
        }
        // The hidden residual after projection, relative per member: above
        // round-off after an exact solve (or NaN), N is singular to
        // working precision.
        let worst = self.hidden(system, num, pn, true);
        if !(worst <= crate::tolerance::HIDDEN_LIMIT) {
            return Err(Self::singular(system, num, 0, Stage::Rattle, 0, k, time));
        }
        report.hidden = Some(worst);
        // grad1/scale1 (at q1) become the next step's grad0/scale0.
        std::mem::swap(&mut self.grad0, &mut self.grad1);
        std::mem::swap(&mut self.scale0, &mut self.scale1);
        Ok(())
    }

    /// The position stage's result q1 judged at its own scale: g(q1) and
    /// |∇g(q1)| · extent(q1) evaluated (into `g`, `grad1`, `scale1`), then
    /// [`judge_at_q1`](Self::judge_at_q1). For a position stage that no
    /// velocity stage follows (`Rattle::shake_positions`): the stage's own
    /// test uses q0's scale, which for old positions off M is not q1's.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn confirm_positions(
        &mut self,
        system: &ParticleSystem,
        num: &Numbering,
        q1: &[f64],
        tol: f64,
        iterations: usize,
        k: u64,
        time: f64,
    ) -> Result<(), StepError> {
        Self::gradients(
            system,
            num,
            q1,
            &mut self.g,
            &mut self.grad1,
            &mut self.scale1,
        );
        self.judge_at_q1(system, num, q1, tol, iterations, k, time)
    }

    /// Whether every member's residual |g_k| · scale_k is within `tol` or
    /// the round-off floor of its coordinates in q,
    /// ε‖x‖ / extent = ε‖x‖ · |∇g_k| · scale_k (`tolerance::roundoff_floor`),
    /// with g, the gradients and the scales taken at one point.
    #[allow(clippy::too_many_arguments)]
    fn within_roundoff(
        system: &ParticleSystem,
        num: &Numbering,
        q: &[f64],
        g: &[f64],
        grad: &[f64],
        scale: &[f64],
        tol: f64,
    ) -> bool {
        let d = system.dim();
        system
            .constraint_families()
            .iter()
            .enumerate()
            .all(|(f, fam)| {
                let t = fam.table();
                let (c0, g0, w) = (num.offsets[f], num.grad_offsets[f], t.arity() * d);
                (0..t.len()).all(|k| {
                    let n2: f64 = t
                        .particles(k)
                        .iter()
                        .flat_map(|&a| &q[a as usize * d..a as usize * d + d])
                        .map(|v| v * v)
                        .sum();
                    let gk = &grad[g0 + k * w..g0 + (k + 1) * w];
                    let s = scale[c0 + k];
                    let e2 = 1.0 / (gk.iter().map(|v| v * v).sum::<f64>() * s * s);
                    g[c0 + k].abs() * s <= tol.max(roundoff_floor(n2, e2))
                })
            })
    }

    /// `NotConverged` (stage SHAKE) at the worst member unless every
    /// |g_k(q1)| · scale1_k is within tol or its round-off floor; `g`,
    /// `grad1` and `scale1` hold q1's.
    #[allow(clippy::too_many_arguments)]
    fn judge_at_q1(
        &self,
        system: &ParticleSystem,
        num: &Numbering,
        q1: &[f64],
        tol: f64,
        iterations: usize,
        k: u64,
        time: f64,
    ) -> Result<(), StepError> {
        let mut worst_g = 0.0f64;
        let mut worst_c = 0;
        for (c, (&g, &s)) in self.g.iter().zip(&self.scale1).enumerate() {
            let r = g.abs() * s;
            if crate::tolerance::worse(r, worst_g) {
                worst_g = r;
                worst_c = c;
            }
        }
        if !(worst_g <= tol)
            && !Self::within_roundoff(system, num, q1, &self.g, &self.grad1, &self.scale1, tol)
        {
            let source = SolveError::NotConverged {
                iterations,
                residual: worst_g,
            };
            return Err(num.error_at(system, worst_c, Stage::Shake, k, time, source));
        }
        Ok(())
    }

    /// delta ← G(q1) W p (grad1); with `ratio`, the largest relative hidden
    /// residual (NaN if any member's is).
    pub(super) fn hidden(
        &mut self,
        system: &ParticleSystem,
        num: &Numbering,
        p: &[f64],
        ratio: bool,
    ) -> f64 {
        let inv_m = system.inverse_masses();
        let mut worst = 0.0f64;
        for (f, fam) in system.constraint_families().iter().enumerate() {
            let (c0, c1) = (num.offsets[f], num.offsets[f + 1]);
            let (g0, g1) = (num.grad_offsets[f], num.grad_offsets[f + 1]);
            let (grad, out) = (&self.grad1[g0..g1], &mut self.delta[c0..c1]);
            let before = &mut self.before[c0..c1];
            let w = if parallel(c1 - c0) {
                let (n, wd) = (PARALLEL_PARTICLES, fam.table().arity() * system.dim());
                let chunks = grad.par_chunks(n * wd).zip(out.par_chunks_mut(n));
                chunks
                    .zip(before.par_chunks_mut(n))
                    .enumerate()
                    .map(|(j, ((grad, out), before))| {
                        fam.hidden_from(grad, inv_m, p, j * n, out, before, ratio)
                    })
                    .reduce(
                        || 0.0,
                        |a, b| if crate::tolerance::worse(b, a) { b } else { a },
                    )
            } else {
                fam.hidden(grad, inv_m, p, out, before, ratio)
            };
            // (`f64::max` would drop a NaN: a non-finite residual must fail.)
            if crate::tolerance::worse(w, worst) {
                worst = w;
            }
        }
        worst
    }
}

/// The largest relative residual |g_c| · scale_c over the constraints (0
/// for none), NaN if any is: |g| / scale, not g² / scale², since squares
/// underflow at length scales below ~1e-77 and Newton would "converge" at
/// once; below ~1e-150 the scale is ∞ (`inverse_scale`), not judged, a
/// non-finite residual. A max and a flag, which vectorise: which
/// constraint it is, only a failure asks ([`where_largest`]).
#[inline]
fn largest_relative(g: &[f64], scale: &[f64]) -> f64 {
    let (mut worst, mut nan) = (0.0f64, false);
    for (&g, &s) in g.iter().zip(scale) {
        let r = g.abs() * s;
        nan |= r.is_nan();
        worst = worst.max(r);
    }
    if nan {
        f64::NAN
    } else {
        worst
    }
}

/// The larger of two [`largest_relative`]s of parts, NaN if either is:
/// the whole's, in any order.
fn larger_or_nan(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// The constraint [`largest_relative`] found `worst` at: the first NaN,
/// else the first at that value (as a running maximum over the
/// constraints in order, `tolerance::worse`, would keep it).
#[cold]
fn where_largest(g: &[f64], scale: &[f64], worst: f64) -> usize {
    let r = |(&g, &s): (&f64, &f64)| g.abs() * s;
    let mut rs = g.iter().zip(scale).map(r);
    let found = if worst.is_nan() {
        rs.position(|r| r.is_nan())
    } else {
        rs.position(|r| r == worst)
    };
    found.unwrap_or(0)
}
