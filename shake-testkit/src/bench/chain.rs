//! A hanging chain of N unit masses joined by rods of one length, the first
//! anchored at the origin, written by hand: the "physical limit" baseline of
//! the benchmarks for the chains that the benches also declare with
//! `constrained_system!`.
//!
//! q = (x₀, y₀, x₁, y₁, …), H = Σ_k |p_k|²/2 + γ y_k,
//! g₀ = |q₀|² − ℓ², g_k = |q_k − q_{k−1}|² − ℓ² (k ≥ 1). Straight-line loops
//! that write only the structurally nonzero entries (the contract of
//! `geoshake_runtime::system`), and the closed-form fibre flow.
#![allow(dead_code, clippy::needless_range_loop)]

use geoshake::{ClosedForm, ConstrainedSystem, ConstraintKind, Hamiltonian, State};

/// The chain of N links, written by hand.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct HandChain<const N: usize> {
    pub length: f64,
    pub gravity: f64,
}

/// The link vector d_k = q_k − q_{k−1} (q_{−1} = 0).
#[inline(always)]
fn link(q: &[f64], k: usize) -> (f64, f64) {
    if k == 0 {
        (q[0], q[1])
    } else {
        (q[2 * k] - q[2 * k - 2], q[2 * k + 1] - q[2 * k - 1])
    }
}

/// The longest chain with a pattern here.
pub const MAX_LINKS: usize = 256;

/// The sorted entries (i, k) of g_z for the longest chain: link k reads
/// particles k−1 and k. The pattern of a chain of N links is its first
/// 4N − 2 entries.
const PATTERN: [(usize, usize); 4 * MAX_LINKS] = {
    let mut out = [(0usize, 0usize); 4 * MAX_LINKS];
    let mut n = 0;
    let mut k = 0;
    while k < MAX_LINKS {
        if k > 0 {
            out[n] = (k, 2 * k - 2);
            out[n + 1] = (k, 2 * k - 1);
            n += 2;
        }
        out[n] = (k, 2 * k);
        out[n + 1] = (k, 2 * k + 1);
        n += 2;
        k += 1;
    }
    out
};

impl<const N: usize> HandChain<N> {
    /// The structurally nonzero entries of g_z, as a constant.
    pub const JACOBIAN_PATTERN: &'static [(usize, usize)] = PATTERN.split_at(4 * N - 2).0;
}

impl<const N: usize> Hamiltonian for HandChain<N> {
    fn dof(&self) -> usize {
        2 * N
    }
    fn separable(&self) -> bool {
        true
    }
    fn quadratic_kinetic(&self) -> bool {
        true
    }
    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        let mut e = 0.0;
        for k in 0..N {
            e += 0.5 * (p[2 * k] * p[2 * k] + p[2 * k + 1] * p[2 * k + 1])
                + self.gravity * q[2 * k + 1];
        }
        e
    }
    fn grad_q(&self, _q: &[f64], _p: &[f64], h_q: &mut [f64]) {
        for k in 0..N {
            h_q[2 * k + 1] = self.gravity;
        }
    }
    fn grad_p(&self, _q: &[f64], p: &[f64], h_p: &mut [f64]) {
        h_p[..2 * N].copy_from_slice(&p[..2 * N]);
    }
    fn hessian(&self, _q: &[f64], _p: &[f64], h_zz: &mut [f64]) {
        let (d, n) = (2 * N, 4 * N);
        for i in 0..d {
            h_zz[(d + i) + (d + i) * n] = 1.0;
        }
    }
}

impl<const N: usize> ConstrainedSystem for HandChain<N> {
    fn constraint_count(&self) -> usize {
        N
    }
    fn kind(&self) -> ConstraintKind {
        ConstraintKind::Holonomic
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        Self::JACOBIAN_PATTERN
    }
    fn constraint_name(&self, i: usize) -> &str {
        const NAMES: &[&str] = &["link"];
        NAMES[i]
    }

    fn constraints(&self, q: &[f64], _p: &[f64], g: &mut [f64]) {
        let l2 = self.length * self.length;
        for k in 0..N {
            let (dx, dy) = link(q, k);
            g[k] = dx * dx + dy * dy - l2;
        }
    }
    fn constraint_jacobian(&self, q: &[f64], _p: &[f64], g_z: &mut [f64]) {
        let m = N;
        for k in 0..N {
            let (dx, dy) = link(q, k);
            g_z[k + 2 * k * m] = 2.0 * dx;
            g_z[k + (2 * k + 1) * m] = 2.0 * dy;
            if k > 0 {
                g_z[k + (2 * k - 2) * m] = -2.0 * dx;
                g_z[k + (2 * k - 1) * m] = -2.0 * dy;
            }
        }
    }
    fn constraint_hessian(&self, _q: &[f64], _p: &[f64], lambda: &[f64], out: &mut [f64]) {
        let n = 4 * N;
        for k in 0..N {
            // Particle k is read by links k and k + 1.
            let next = if k + 1 < N { lambda[k + 1] } else { 0.0 };
            let diag = 2.0 * (lambda[k] + next);
            out[2 * k + 2 * k * n] = diag;
            out[(2 * k + 1) + (2 * k + 1) * n] = diag;
            if k > 0 {
                let off = -2.0 * lambda[k];
                out[2 * k + (2 * k - 2) * n] = off;
                out[(2 * k - 2) + 2 * k * n] = off;
                out[(2 * k + 1) + (2 * k - 1) * n] = off;
                out[(2 * k - 1) + (2 * k + 1) * n] = off;
            }
        }
    }
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        // {g_k, H} = ∇_q g_k · H_p = 2 d_k · (p_k − p_{k−1}).
        for k in 0..N {
            let (dx, dy) = link(q, k);
            let (vx, vy) = link(p, k);
            out[k] = 2.0 * (dx * vx + dy * vy);
        }
    }
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        let (m, d) = (N, 2 * N);
        for k in 0..N {
            let (dx, dy) = link(q, k);
            let (vx, vy) = link(p, k);
            out[k + 2 * k * m] = 2.0 * vx;
            out[k + (2 * k + 1) * m] = 2.0 * vy;
            out[k + (d + 2 * k) * m] = 2.0 * dx;
            out[k + (d + 2 * k + 1) * m] = 2.0 * dy;
            if k > 0 {
                out[k + (2 * k - 2) * m] = -2.0 * vx;
                out[k + (2 * k - 1) * m] = -2.0 * vy;
                out[k + (d + 2 * k - 2) * m] = -2.0 * dx;
                out[k + (d + 2 * k - 1) * m] = -2.0 * dy;
            }
        }
    }
    fn nondegeneracy_matrix(&self, q: &[f64], _p: &[f64], n: &mut [f64]) {
        // N = g_q g_qᵀ (unit masses): tridiagonal.
        let m = N;
        let mut prev = (0.0, 0.0);
        for k in 0..N {
            let (dx, dy) = link(q, k);
            let particles = if k == 0 { 1.0 } else { 2.0 };
            n[k + k * m] = 4.0 * particles * (dx * dx + dy * dy);
            if k > 0 {
                let off = -4.0 * (dx * prev.0 + dy * prev.1);
                n[k + (k - 1) * m] = off;
                n[(k - 1) + k * m] = off;
            }
            prev = (dx, dy);
        }
    }
    fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        // p ← p − g_qᵀλ: particle k feels links k (+) and k + 1 (−).
        for k in 0..N {
            let (dx, dy) = link(q, k);
            let a = 2.0 * lambda[k];
            p[2 * k] -= a * dx;
            p[2 * k + 1] -= a * dy;
            if k > 0 {
                p[2 * k - 2] += a * dx;
                p[2 * k - 1] += a * dy;
            }
        }
        ClosedForm::Applied
    }
}

/// A point of M^H for a chain of `n` links of length ℓ: link k at angle
/// θ_k = 0.3 + 0.7 sin(1.3 k) from the downward vertical, turning at
/// ω_k = 0.5 cos(0.9 k) relative to the link before (unit masses).
pub fn chain_state(n: usize, length: f64) -> State {
    let (mut q, mut p) = (vec![0.0; 2 * n], vec![0.0; 2 * n]);
    let (mut x, mut y, mut vx, mut vy) = (0.0, 0.0, 0.0, 0.0);
    for k in 0..n {
        let th = 0.3 + 0.7 * (1.3 * k as f64).sin();
        let om = 0.5 * (0.9 * k as f64).cos();
        x += length * th.sin();
        y -= length * th.cos();
        vx += length * om * th.cos();
        vy += length * om * th.sin();
        q[2 * k] = x;
        q[2 * k + 1] = y;
        p[2 * k] = vx;
        p[2 * k + 1] = vy;
    }
    State::from_slices(&q, &p)
}
