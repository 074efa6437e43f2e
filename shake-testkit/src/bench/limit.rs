//! The limit: RATTLE over Störmer–Verlet written by hand, straight-line,
//! for the planar pendulum and for hanging chains of N links: what a user
//! who writes the method for one system gets, and what the library's
//! per-step cost is measured against (`examples/overhead.rs`).
//!
//! Nothing here comes from the library (no trait, no model, no linear
//! algebra): the systems are written out again below, the multiplier of the
//! pendulum is the root of a quadratic, the chain's position stage is
//! simplified Newton on the link lengths with its tridiagonal matrix
//! factorised once per step (Thomas, reciprocal pivots), and the velocity
//! projection (linear in σ) is one tridiagonal solve. Sizes are const
//! generics, the state fixed-size arrays of particles.
//!
//! The method (classical RATTLE, unit masses, H = |p|²/2 + γ Σ y_k):
//!
//! 1. p* = p − (h/2) ∇V(q),  q1 = q + h (p* − G(q)ᵀμ)  with g(q1) = 0;
//! 2. p½ = p* − G(q)ᵀμ,  p1 = p½ − (h/2) ∇V(q1);
//! 3. p1 ← p1 − G(q1)ᵀσ  with G(q1) p1 = 0,
//!
//! G = g_q. Newton on μ stops by the library's classical rule (a residual
//! at g's round-off level and one confirming update, an update below 4ε of
//! the unknown, or an update that no longer halves once below 1e-6): the
//! same steps to round-off.
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
/// anchored at the origin: particle k at q[k] = (x_k, y_k),
/// g₀ = |q₀|² − ℓ², g_k = |q_k − q_{k−1}|² − ℓ².
///
/// The position stage is simplified (chord) Newton on the multipliers: the
/// tridiagonal Jacobian at ν = 0 is factorised once per step, with the
/// reciprocals of its pivots kept, and every update is one forward and one
/// backward sweep of multiplications. It stops as the library's classical
/// SHAKE does: once every |g_k(q1)| is below its round-off level
/// ε Σ_j |∂g_k/∂q_j| |q_j| (at q0), after one more (confirming) update,
/// or on an update below 4ε‖ν‖, or on stagnation below 1e-6.
#[derive(Clone, Debug)]
pub struct LimitChain<const N: usize> {
    pub length: f64,
    pub gravity: f64,
    // Scratch, kept between steps (no allocation per step).
    d0: [[f64; 2]; N],
    a: [[f64; 2]; N],
    nu: [f64; N],
    r: [f64; N],
    floor: [f64; N],
    // The factors of the Jacobian: multipliers of the forward sweep, the
    // reciprocal pivots and the upper diagonal.
    w: [f64; N],
    inv: [f64; N],
    up: [f64; N],
}

/// The link vector k of the particles x.
#[inline(always)]
fn link<const N: usize>(x: &[[f64; 2]; N], k: usize) -> [f64; 2] {
    if k == 0 {
        x[0]
    } else {
        [x[k][0] - x[k - 1][0], x[k][1] - x[k - 1][1]]
    }
}

#[inline(always)]
fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// Factorises the tridiagonal matrix (lo, di, up) without pivoting (the
/// chain's matrices are diagonally dominant): the forward sweep's
/// multipliers into `w`, the reciprocal pivots into `inv`.
#[inline(always)]
fn factor<const N: usize>(
    lo: &[f64; N],
    di: &[f64; N],
    up: &[f64; N],
    w: &mut [f64; N],
    inv: &mut [f64; N],
) {
    inv[0] = 1.0 / di[0];
    for k in 1..N {
        w[k] = lo[k] * inv[k - 1];
        inv[k] = 1.0 / (di[k] - w[k] * up[k - 1]);
    }
}

/// Solves with the factors of [`factor`], r in place.
#[inline(always)]
fn solve<const N: usize>(w: &[f64; N], inv: &[f64; N], up: &[f64; N], r: &mut [f64; N]) {
    for k in 1..N {
        r[k] -= w[k] * r[k - 1];
    }
    r[N - 1] *= inv[N - 1];
    for k in (0..N - 1).rev() {
        r[k] = (r[k] - up[k] * r[k + 1]) * inv[k];
    }
}

impl<const N: usize> LimitChain<N> {
    pub fn new(length: f64, gravity: f64) -> Self {
        LimitChain {
            length,
            gravity,
            d0: [[0.0; 2]; N],
            a: [[0.0; 2]; N],
            nu: [0.0; N],
            r: [0.0; N],
            floor: [0.0; N],
            w: [0.0; N],
            inv: [0.0; N],
            up: [0.0; N],
        }
    }

    /// Link k of q1(ν): A_k − c_k ν_k d_k + ν_{k+1} d_{k+1} + ν_{k−1} d_{k−1}
    /// (c_0 = 1, c_k = 2), with A = link of q + h p* and d = link of q0.
    #[inline(always)]
    fn moved(&self, k: usize) -> [f64; 2] {
        let (d, nu) = (&self.d0, &self.nu);
        let c = if k == 0 { nu[0] } else { 2.0 * nu[k] };
        let mut x = [self.a[k][0] - c * d[k][0], self.a[k][1] - c * d[k][1]];
        if k + 1 < N {
            x[0] += nu[k + 1] * d[k + 1][0];
            x[1] += nu[k + 1] * d[k + 1][1];
        }
        if k > 0 {
            x[0] += nu[k - 1] * d[k - 1][0];
            x[1] += nu[k - 1] * d[k - 1][1];
        }
        x
    }

    /// One RATTLE step in place. Returns the Newton updates of the position
    /// stage.
    pub fn step(&mut self, h: f64, q: &mut [[f64; 2]; N], p: &mut [[f64; 2]; N]) -> usize {
        let hh = 0.5 * h;
        let l2 = self.length * self.length;
        let eps2 = 2.0 * f64::EPSILON;
        // p* = p − (h/2)∇V; the links d of q0 and A of q + h p*, the
        // round-off level of g at q0, and the Jacobian at ν = 0:
        // ∂r_k/∂ν_j = 2 A_k · ∂A_k/∂ν_j.
        let (mut lo, mut di) = ([0.0; N], [0.0; N]);
        let mut prev_q = [0.0; 2];
        let mut prev_a = [0.0; 2];
        for k in 0..N {
            p[k][1] -= hh * self.gravity;
            let a = [q[k][0] + h * p[k][0], q[k][1] + h * p[k][1]];
            let d = [q[k][0] - prev_q[0], q[k][1] - prev_q[1]];
            self.d0[k] = d;
            self.a[k] = [a[0] - prev_a[0], a[1] - prev_a[1]];
            self.floor[k] = eps2
                * (d[0].abs() * (q[k][0].abs() + prev_q[0].abs())
                    + d[1].abs() * (q[k][1].abs() + prev_q[1].abs()));
            self.nu[k] = 0.0;
            prev_q = q[k];
            prev_a = a;
        }
        for k in 0..N {
            let ak = self.a[k];
            di[k] = if k == 0 {
                -2.0 * dot(ak, self.d0[0])
            } else {
                -4.0 * dot(ak, self.d0[k])
            };
            if k + 1 < N {
                self.up[k] = 2.0 * dot(ak, self.d0[k + 1]);
            }
            if k > 0 {
                lo[k] = 2.0 * dot(ak, self.d0[k - 1]);
            }
        }
        factor(&lo, &di, &self.up, &mut self.w, &mut self.inv);
        let mut iterations = 0;
        let mut prev = f64::INFINITY;
        loop {
            let mut at_floor = true;
            // After the first update, the Jacobian at ν1 (off the exact one
            // by O(‖ν − ν1‖), quadratically small): the contraction of the
            // updates that follow is then as fast as the library's.
            let refresh = iterations == 1;
            for k in 0..N {
                let x = self.moved(k);
                let r = dot(x, x) - l2;
                at_floor &= r.abs() <= self.floor[k];
                self.r[k] = r;
                if refresh {
                    di[k] = if k == 0 { -2.0 } else { -4.0 } * dot(x, self.d0[k]);
                    if k + 1 < N {
                        self.up[k] = 2.0 * dot(x, self.d0[k + 1]);
                    }
                    if k > 0 {
                        lo[k] = 2.0 * dot(x, self.d0[k - 1]);
                    }
                }
            }
            if at_floor && iterations == 0 {
                break;
            }
            if refresh && !at_floor {
                factor(&lo, &di, &self.up, &mut self.w, &mut self.inv);
            }
            solve(&self.w, &self.inv, &self.up, &mut self.r);
            let (mut step, mut size) = (0.0f64, 0.0f64);
            for k in 0..N {
                self.nu[k] -= self.r[k];
                step = step.max(self.r[k].abs());
                size = size.max(self.nu[k].abs());
            }
            iterations += 1;
            // At round-off the update just taken was the confirming one.
            if at_floor
                || step <= 4.0 * f64::EPSILON * size
                || (step > 0.5 * prev && step <= 1e-6 * size.max(1.0))
                || iterations >= 50
            {
                break;
            }
            prev = step;
        }
        // Particle j moves by −f_j, f_j = ν_j d_j − ν_{j+1} d_{j+1}; p½ = that / h.
        let inv_h = 1.0 / h;
        for j in 0..N {
            let mut f = [self.nu[j] * self.d0[j][0], self.nu[j] * self.d0[j][1]];
            if j + 1 < N {
                f[0] -= self.nu[j + 1] * self.d0[j + 1][0];
                f[1] -= self.nu[j + 1] * self.d0[j + 1][1];
            }
            q[j][0] += h * p[j][0] - f[0];
            q[j][1] += h * p[j][1] - f[1];
            p[j][0] -= f[0] * inv_h;
            p[j][1] -= f[1] * inv_h + hh * self.gravity;
        }
        // Velocity projection: D_k · link_k(p − G(q1)ᵀσ) = 0, with τ = 2σ:
        // link_k(Gᵀσ) = c_k τ_k D_k − τ_{k+1} D_{k+1} − τ_{k−1} D_{k−1}.
        let mut prev_d = [0.0; 2];
        for k in 0..N {
            let dk = link(q, k);
            self.d0[k] = dk;
            let c = if k == 0 { 1.0 } else { 2.0 };
            self.r[k] = dot(dk, link(p, k));
            di[k] = c * dot(dk, dk);
            lo[k] = -dot(dk, prev_d);
            if k > 0 {
                self.up[k - 1] = lo[k];
            }
            prev_d = dk;
        }
        factor(&lo, &di, &self.up, &mut self.w, &mut self.inv);
        solve(&self.w, &self.inv, &self.up, &mut self.r);
        // Particle j gets −(τ_j D_j − τ_{j+1} D_{j+1}).
        for j in 0..N {
            let mut f = [self.r[j] * self.d0[j][0], self.r[j] * self.d0[j][1]];
            if j + 1 < N {
                f[0] -= self.r[j + 1] * self.d0[j + 1][0];
                f[1] -= self.r[j + 1] * self.d0[j + 1][1];
            }
            p[j][0] -= f[0];
            p[j][1] -= f[1];
        }
        iterations
    }

    /// H(q, p).
    pub fn energy(&self, q: &[[f64; 2]; N], p: &[[f64; 2]; N]) -> f64 {
        (0..N)
            .map(|k| 0.5 * dot(p[k], p[k]) + self.gravity * q[k][1])
            .sum()
    }

    /// max_k |g_k(q)| / ℓ².
    pub fn relative_g(&self, q: &[[f64; 2]; N]) -> f64 {
        let l2 = self.length * self.length;
        (0..N)
            .map(|k| {
                let d = link(q, k);
                ((dot(d, d) - l2) / l2).abs()
            })
            .fold(0.0, f64::max)
    }
}

/// The coordinates x = (x₀, y₀, x₁, y₁, …) of N particles as pairs.
pub fn pairs<const N: usize>(x: &[f64]) -> [[f64; 2]; N] {
    let mut out = [[0.0; 2]; N];
    for (o, c) in out.iter_mut().zip(x.chunks_exact(2)) {
        *o = [c[0], c[1]];
    }
    out
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
