//! Yoshida's fourth-order triple jump of a symmetric base map ψ_h,
//!
//!   φ_h = ψ_{γ₁h} ∘ ψ_{γ₂h} ∘ ψ_{γ₁h},  γ₁ = 1/(2 − 2^{1/3}), γ₂ = 1 − 2γ₁
//!
//! (Yoshida 1990; Hairer, Lubich & Wanner, *Geometric Numerical
//! Integration*, II.4), written against the runtime's public API only: the
//! proof that a [`BaseMap`] can be implemented outside the runtime crate
//! (issue 11). `examples/custom_base_map.rs` shows it, and
//! `tests/custom_base_map.rs` checks its order and symplecticity; both take
//! it from here. Also the pendulum reference both compare with.

use shake::{BaseMap, Hamiltonian, NewtonOptions, SolveError, State};

/// Yoshida's triple jump of a symmetric base map `B`.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct Yoshida4<B>(pub B);

/// The stage fractions γ₁ (first and last) and γ₂ (middle).
fn gammas() -> (f64, f64) {
    let g1 = 1.0 / (2.0 - 2f64.cbrt());
    (g1, 1.0 - 2.0 * g1)
}

/// One workspace of the inner map per stage (each stage's tangent map is
/// taken at its own input point).
#[derive(Clone, Debug)]
pub struct Yoshida4Workspace<W> {
    stages: [W; 3],
}

impl<B: BaseMap> BaseMap for Yoshida4<B> {
    type Workspace = Yoshida4Workspace<B::Workspace>;
    const NAME: &'static str = "Yoshida 4 (triple jump)";
    const SYMMETRIC: bool = B::SYMMETRIC;
    // The triple jump raises the order of a symmetric map of order 2 to 4.
    const ORDER: u32 = if B::SYMMETRIC && B::ORDER == 2 {
        4
    } else {
        B::ORDER
    };

    fn workspace(&self, d: usize) -> Self::Workspace {
        Yoshida4Workspace {
            stages: [
                self.0.workspace(d),
                self.0.workspace(d),
                self.0.workspace(d),
            ],
        }
    }

    fn explicit_for<S: Hamiltonian>(&self, sys: &S) -> bool {
        self.0.explicit_for(sys)
    }

    fn apply<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        q: &mut [f64],
        p: &mut [f64],
        ws: &mut Self::Workspace,
        opts: &NewtonOptions,
    ) -> Result<usize, SolveError> {
        let (g1, g2) = gammas();
        let mut iterations = 0;
        for (stage, gamma) in ws.stages.iter_mut().zip([g1, g2, g1]) {
            iterations += self.0.apply(sys, gamma * h, q, p, stage, opts)?;
        }
        Ok(iterations)
    }

    fn prepare_tangent<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        ws: &mut Self::Workspace,
    ) -> Result<(), SolveError> {
        let (g1, g2) = gammas();
        for (stage, gamma) in ws.stages.iter_mut().zip([g1, g2, g1]) {
            self.0.prepare_tangent(sys, gamma * h, stage)?;
        }
        Ok(())
    }

    fn apply_tangent(&self, h: f64, ws: &mut Self::Workspace, v: &mut [f64]) {
        // Dφ_h = Dψ_{γ₁h}(z₂) · Dψ_{γ₂h}(z₁) · Dψ_{γ₁h}(z₀): first stage first.
        let (g1, g2) = gammas();
        for (stage, gamma) in ws.stages.iter_mut().zip([g1, g2, g1]) {
            self.0.apply_tangent(gamma * h, stage, v);
        }
    }

    fn reset_warm_start(&self, ws: &mut Self::Workspace) {
        for stage in &mut ws.stages {
            self.0.reset_warm_start(stage);
        }
    }
}

/// The planar pendulum's angle θ'' = −(γ/ℓ) sin θ by classical RK4 with
/// 100 000 steps: an independent reference (global error ~1e-15 at T = 1).
pub fn pendulum_reference(gravity: f64, length: f64, theta: f64, omega: f64, t: f64) -> (f64, f64) {
    let f = |th: f64, om: f64| (om, -(gravity / length) * th.sin());
    let n = 100_000;
    let dt = t / n as f64;
    let (mut th, mut om) = (theta, omega);
    for _ in 0..n {
        let k1 = f(th, om);
        let k2 = f(th + 0.5 * dt * k1.0, om + 0.5 * dt * k1.1);
        let k3 = f(th + 0.5 * dt * k2.0, om + 0.5 * dt * k2.1);
        let k4 = f(th + dt * k3.0, om + dt * k3.1);
        th += dt / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
        om += dt / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
    }
    (th, om)
}

/// The pendulum state (q, p) at angle θ from the downward vertical and
/// angular velocity ω (unit mass).
pub fn pendulum_state(length: f64, theta: f64, omega: f64) -> State {
    let (s, c) = theta.sin_cos();
    State::from_slices(
        &[length * s, -length * c],
        &[length * omega * c, length * omega * s],
    )
}
