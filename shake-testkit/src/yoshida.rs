//! Yoshida's fourth-order triple jump of a symmetric base map ψ_h,
//!
//!   φ_h = ψ_{γ₁h} ∘ ψ_{γ₂h} ∘ ψ_{γ₁h},  γ₁ = 1/(2 − 2^{1/3}), γ₂ = 1 − 2γ₁
//!
//! (Yoshida 1990; Hairer, Lubich & Wanner, *Geometric Numerical
//! Integration*, II.4), written against the runtime's public API only: the
//! proof that a [`BaseMap`] can be implemented outside the runtime crate
//! (issue 11). `examples/custom_base_map.rs` shows it, and
//! `tests/custom_base_map.rs` checks its order and symplecticity; both take
//! it from here.

use shake::{BaseMap, Hamiltonian, NewtonOptions, SolveError};

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
