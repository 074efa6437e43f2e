//! The limit: RATTLE over Störmer–Verlet written by hand, straight-line,
//! for the planar pendulum and for hanging chains of N links: what a user
//! who writes the method for one system gets, and what the library's
//! per-step cost is measured against (`examples/overhead.rs`).
//!
//! Nothing here comes from the library (no trait, no model, no linear
//! algebra): the systems are written out again below, the multiplier of the
//! pendulum is the root of a quadratic, the chain's position stage is
//! Newton's method on the link lengths with its tridiagonal matrix solved
//! by the Thomas algorithm, and the velocity projection (linear in σ) is
//! one tridiagonal solve.
//!
//! The method (classical RATTLE, unit masses, H = |p|²/2 + γ Σ y_k):
//!
//! 1. p* = p − (h/2) ∇V(q),  q1 = q + h (p* − G(q)ᵀμ)  with g(q1) = 0;
//! 2. p½ = p* − G(q)ᵀμ,  p1 = p½ − (h/2) ∇V(q1);
//! 3. p1 ← p1 − G(q1)ᵀσ  with G(q1) p1 = 0,
//!
//! G = g_q. Newton on μ stops by the same rule as the library's iterations
//! (an update below 4ε of the unknown, or an update that no longer halves
//! once below 1e-6): the same steps to round-off.
#![allow(dead_code, clippy::needless_range_loop)]

/// The planar pendulum, H = |p|²/2 + γ q₂, g = |q|² − ℓ².
#[derive(Copy, Clone, Debug)]
pub struct LimitPendulum {
    pub length: f64,
    pub gravity: f64,
}

impl LimitPendulum {
    /// One RATTLE step in place.
    #[inline]
    pub fn step(&self, h: f64, q: &mut [f64; 2], p: &mut [f64; 2]) {
        let hh = 0.5 * h;
        let l2 = self.length * self.length;
        // Kick and drift without the constraint force.
        let ps = [p[0], p[1] - hh * self.gravity];
        let a = [q[0] + h * ps[0], q[1] + h * ps[1]];
        // q1 = a − s q with |q1|² = ℓ²: |q|² s² − 2 (a·q) s + |a|² − ℓ² = 0,
        // the root near 0 in the form without cancellation.
        let qq = q[0] * q[0] + q[1] * q[1];
        let b = a[0] * q[0] + a[1] * q[1];
        let c = a[0] * a[0] + a[1] * a[1] - l2;
        let s = c / (b + (b * b - qq * c).sqrt());
        let q1 = [a[0] - s * q[0], a[1] - s * q[1]];
        let k = s / h;
        let p1 = [ps[0] - k * q[0], ps[1] - k * q[1] - hh * self.gravity];
        // Velocity projection: p1 ← p1 − σ q1 with q1 · p1 = 0.
        let sigma = (q1[0] * p1[0] + q1[1] * p1[1]) / (q1[0] * q1[0] + q1[1] * q1[1]);
        *q = q1;
        *p = [p1[0] - sigma * q1[0], p1[1] - sigma * q1[1]];
    }

    /// H(q, p).
    pub fn energy(&self, q: &[f64; 2], p: &[f64; 2]) -> f64 {
        0.5 * (p[0] * p[0] + p[1] * p[1]) + self.gravity * q[1]
    }

    /// |g(q)| / ℓ².
    pub fn relative_g(&self, q: &[f64; 2]) -> f64 {
        let l2 = self.length * self.length;
        ((q[0] * q[0] + q[1] * q[1] - l2) / l2).abs()
    }
}

/// A hanging chain of N unit masses joined by rods of length ℓ, the first
/// anchored at the origin: q = (x₀, y₀, x₁, y₁, …),
/// g₀ = |q₀|² − ℓ², g_k = |q_k − q_{k−1}|² − ℓ².
#[derive(Clone, Debug)]
pub struct LimitChain<const N: usize> {
    pub length: f64,
    pub gravity: f64,
    // Scratch, kept between steps (no allocation per step).
    d0: [[f64; 2]; N],
    d1: [[f64; 2]; N],
    nu: [f64; N],
    r: [f64; N],
    lo: [f64; N],
    di: [f64; N],
    up: [f64; N],
}

/// The link vector k of the positions (or velocities) x.
#[inline(always)]
fn link(x: &[f64], k: usize) -> [f64; 2] {
    if k == 0 {
        [x[0], x[1]]
    } else {
        [x[2 * k] - x[2 * k - 2], x[2 * k + 1] - x[2 * k - 1]]
    }
}

#[inline(always)]
fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// Solves the tridiagonal system (lo, di, up) x = r in place (Thomas, no
/// pivoting: the chain's matrices are diagonally dominant); di and r are
/// overwritten, r holds x.
#[inline(always)]
fn thomas<const N: usize>(lo: &[f64; N], di: &mut [f64; N], up: &[f64; N], r: &mut [f64; N]) {
    for k in 1..N {
        let w = lo[k] / di[k - 1];
        di[k] -= w * up[k - 1];
        r[k] -= w * r[k - 1];
    }
    r[N - 1] /= di[N - 1];
    for k in (0..N - 1).rev() {
        r[k] = (r[k] - up[k] * r[k + 1]) / di[k];
    }
}

impl<const N: usize> LimitChain<N> {
    pub fn new(length: f64, gravity: f64) -> Self {
        LimitChain {
            length,
            gravity,
            d0: [[0.0; 2]; N],
            d1: [[0.0; 2]; N],
            nu: [0.0; N],
            r: [0.0; N],
            lo: [0.0; N],
            di: [0.0; N],
            up: [0.0; N],
        }
    }

    /// One RATTLE step in place (q and p of length 2N). Returns the Newton
    /// iterations of the position stage.
    pub fn step(&mut self, h: f64, q: &mut [f64], p: &mut [f64]) -> usize {
        let hh = 0.5 * h;
        let l2 = self.length * self.length;
        // p* = p − (h/2)∇V, a = q + h p* (kept in p and q for now).
        for k in 0..N {
            self.d0[k] = link(q, k);
        }
        for k in 0..N {
            p[2 * k + 1] -= hh * self.gravity;
            q[2 * k] += h * p[2 * k];
            q[2 * k + 1] += h * p[2 * k + 1];
            self.nu[k] = 0.0;
        }
        // Unknowns ν_k = 2hμ_k: particle j moves by −(ν_j d_j − ν_{j+1} d_{j+1}),
        // link k of q1 is D_k = A_k − c_k ν_k d_k + ν_{k+1} d_{k+1} + ν_{k−1} d_{k−1}
        // (c_0 = 1, c_k = 2). Newton: r_k = |D_k|² − ℓ².
        let mut iterations = 0;
        let mut prev = f64::INFINITY;
        loop {
            for k in 0..N {
                let a = link(q, k);
                let mut dx = a;
                let c = if k == 0 { 1.0 } else { 2.0 };
                dx[0] -= c * self.nu[k] * self.d0[k][0];
                dx[1] -= c * self.nu[k] * self.d0[k][1];
                if k + 1 < N {
                    dx[0] += self.nu[k + 1] * self.d0[k + 1][0];
                    dx[1] += self.nu[k + 1] * self.d0[k + 1][1];
                }
                if k > 0 {
                    dx[0] += self.nu[k - 1] * self.d0[k - 1][0];
                    dx[1] += self.nu[k - 1] * self.d0[k - 1][1];
                }
                self.d1[k] = dx;
                self.r[k] = dot(dx, dx) - l2;
                // ∂r_k/∂ν_j = 2 D_k · ∂D_k/∂ν_j.
                self.di[k] = -2.0 * c * dot(dx, self.d0[k]);
                self.up[k] = if k + 1 < N {
                    2.0 * dot(dx, self.d0[k + 1])
                } else {
                    0.0
                };
                self.lo[k] = if k > 0 {
                    2.0 * dot(dx, self.d0[k - 1])
                } else {
                    0.0
                };
            }
            thomas(&self.lo, &mut self.di, &self.up, &mut self.r);
            let (mut step, mut size) = (0.0f64, 0.0f64);
            for k in 0..N {
                self.nu[k] -= self.r[k];
                step = step.max(self.r[k].abs());
                size = size.max(self.nu[k].abs());
            }
            iterations += 1;
            if step <= 4.0 * f64::EPSILON * size
                || (step > 0.5 * prev && step <= 1e-6 * size.max(1.0))
                || iterations >= 50
            {
                break;
            }
            prev = step;
        }
        // Move the particles by −(ν_j d_j − ν_{j+1} d_{j+1}); p½ = that / h.
        let inv_h = 1.0 / h;
        for j in 0..N {
            let mut f = [self.nu[j] * self.d0[j][0], self.nu[j] * self.d0[j][1]];
            if j + 1 < N {
                f[0] -= self.nu[j + 1] * self.d0[j + 1][0];
                f[1] -= self.nu[j + 1] * self.d0[j + 1][1];
            }
            q[2 * j] -= f[0];
            q[2 * j + 1] -= f[1];
            p[2 * j] -= f[0] * inv_h;
            p[2 * j + 1] -= f[1] * inv_h + hh * self.gravity;
        }
        // Velocity projection: D_k · link_k(p − G(q1)ᵀσ) = 0, with τ = 2σ:
        // link_k(Gᵀσ) = c_k τ_k D_k − τ_{k+1} D_{k+1} − τ_{k−1} D_{k−1}.
        for k in 0..N {
            let dk = link(q, k);
            self.d1[k] = dk;
            let c = if k == 0 { 1.0 } else { 2.0 };
            self.r[k] = dot(dk, link(p, k));
            self.di[k] = c * dot(dk, dk);
            self.lo[k] = if k > 0 { -dot(dk, self.d1[k - 1]) } else { 0.0 };
            self.up[k] = 0.0;
        }
        for k in 0..N - 1 {
            self.up[k] = self.lo[k + 1];
        }
        thomas(&self.lo, &mut self.di, &self.up, &mut self.r);
        // Particle j gets −(τ_j D_j − τ_{j+1} D_{j+1}).
        for j in 0..N {
            let mut f = [self.r[j] * self.d1[j][0], self.r[j] * self.d1[j][1]];
            if j + 1 < N {
                f[0] -= self.r[j + 1] * self.d1[j + 1][0];
                f[1] -= self.r[j + 1] * self.d1[j + 1][1];
            }
            p[2 * j] -= f[0];
            p[2 * j + 1] -= f[1];
        }
        iterations
    }

    /// H(q, p).
    pub fn energy(&self, q: &[f64], p: &[f64]) -> f64 {
        (0..N)
            .map(|k| {
                0.5 * (p[2 * k] * p[2 * k] + p[2 * k + 1] * p[2 * k + 1])
                    + self.gravity * q[2 * k + 1]
            })
            .sum()
    }

    /// max_k |g_k(q)| / ℓ².
    pub fn relative_g(&self, q: &[f64]) -> f64 {
        let l2 = self.length * self.length;
        (0..N)
            .map(|k| {
                let d = link(q, k);
                ((dot(d, d) - l2) / l2).abs()
            })
            .fold(0.0, f64::max)
    }
}

/// A point of M^H for a chain of `n` links of length ℓ (the benches'
/// scene): link k at angle θ_k = 0.3 + 0.7 sin(1.3 k) from the downward
/// vertical, turning at ω_k = 0.5 cos(0.9 k) relative to the link before.
pub fn limit_chain_state(n: usize, length: f64) -> (Vec<f64>, Vec<f64>) {
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
    (q, p)
}
