//! How to write a base map: Yoshida's fourth-order triple jump of a
//! symmetric base map ψ_h, implemented in this file against the public API
//! only (the [`BaseMap`] trait and the types of its signatures), so that it
//! can be copied as it stands:
//!
//!   φ_h = ψ_{γ₁h} ∘ ψ_{γ₂h} ∘ ψ_{γ₁h},  γ₁ = 1/(2 − 2^{1/3}), γ₂ = 1 − 2γ₁
//!
//! (Yoshida 1990; Hairer, Lubich & Wanner, *Geometric Numerical
//! Integration*, II.4). A composition of symplectic maps is symplectic, the
//! symmetric composition of a symmetric map is symmetric, and the order
//! rises from 2 to 4.
//!
//! SHAKE and RATTLE take any [`BaseMap`] (the paper's Definitions 1.1 and
//! 1.2). The example prints, at T = 1:
//!
//! 1. φ_h alone (RATTLE with no constraint, `Unconstrained`) on the harmonic
//!    oscillator against its exact solution: order 4;
//! 2. RATTLE over φ_h for the planar pendulum against the angle ODE solved
//!    by RK4 at a tiny step, next to RATTLE over Störmer–Verlet: both order
//!    2, with the same error constant to three digits. The constraint step
//!    (λ, σ), not the base map, limits geometric RATTLE to order 2; a
//!    fourth-order method on M^H is RATTLE *composed* (Section 4,
//!    [`Composition`]), shown in the last column over φ_h.
//!
//! `tests/suite/custom_base_map.rs` includes this file and checks these orders
//! and the symplecticity of RATTLE over φ_h on M^H. The reference solutions
//! come from the workspace's test kit (`geoshake_testkit::reference`); the
//! base map needs nothing but `shake`.
//!
//! Run with `cargo run --release --example custom_base_map`.

use geoshake::models::Pendulum;
use geoshake::runtime::examples::HarmonicOscillator;
use geoshake::{
    BaseMap, Composition, Hamiltonian, Integrator, NewtonOptions, SolveError, State, Stop,
    StormerVerlet, Unconstrained,
};
use geoshake_testkit::reference::{pendulum_reference, pendulum_state};

/// Yoshida's triple jump of a symmetric base map ψ = `B`:
/// φ_h = ψ_{γ₁h} ∘ ψ_{γ₂h} ∘ ψ_{γ₁h}, with γ₁ = 1/(2 − 2^{1/3}) and
/// γ₂ = 1 − 2γ₁ (γ₂ < 0: the middle stage steps back).
///
/// The fractions solve 2γ₁ + γ₂ = 1 (consistency) and 2γ₁³ + γ₂³ = 0,
/// which cancels the h³ term of the local error when ψ is symmetric of
/// order 2. The composition is symmetric too, so its order is even: φ_h
/// has order 4.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct Yoshida4<B>(pub B);

/// The stage fractions γ₁ (first and last) and γ₂ (middle).
fn gammas() -> (f64, f64) {
    let g1 = 1.0 / (2.0 - 2f64.cbrt());
    (g1, 1.0 - 2.0 * g1)
}

/// One workspace of ψ per stage: the tangent map of φ_h is the product of
/// the stages' tangent maps, each taken at the point where that stage was
/// applied, so each stage keeps its own input and Newton matrices.
#[derive(Clone, Debug)]
pub struct Yoshida4Workspace<W> {
    stages: [W; 3],
}

impl<B: BaseMap> BaseMap for Yoshida4<B> {
    type Workspace = Yoshida4Workspace<B::Workspace>;
    const NAME: &'static str = "Yoshida 4 (triple jump)";
    /// Symmetric stage fractions: φ_{−h} = φ_h⁻¹ when ψ is symmetric.
    const SYMMETRIC: bool = B::SYMMETRIC;
    /// The triple jump raises the order of a symmetric map of order 2 to 4;
    /// of any other map it keeps the order.
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

    /// Explicit exactly when ψ is: the stages are ψ at other step sizes.
    fn explicit_for<S: Hamiltonian>(&self, sys: &S) -> bool {
        self.0.explicit_for(sys)
    }

    /// z ← ψ_{γ₁h}(ψ_{γ₂h}(ψ_{γ₁h}(z))), the stages' Newton iterations
    /// summed.
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

    /// Each stage linearised at its own input, with its own step γh.
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

    /// v ← Dφ_h(z₀) v = Dψ_{γ₁h}(z₂) Dψ_{γ₂h}(z₁) Dψ_{γ₁h}(z₀) v, z₁ and z₂
    /// the intermediate points: the first stage's tangent map acts first.
    fn apply_tangent(&self, h: f64, ws: &mut Self::Workspace, v: &mut [f64]) {
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

/// The global error at T = 1 of RATTLE over `base` with step `h`, composed
/// by `c`, for the pendulum swinging from θ = 1.
pub fn rattle_error<B: BaseMap>(base: B, c: Composition, h: f64) -> f64 {
    let (length, gravity, theta, omega, t) = (1.0, 9.81, 1.0, 0.0, 1.0);
    let sys = Pendulum::new(length, gravity);
    let z0 = pendulum_state(length, theta, omega);
    let mut integ = Integrator::new(sys, base, h).rattle().composed(c);
    let traj = integ
        .run(z0, Stop::Time(t))
        .stride(u64::MAX)
        .execute()
        .into_result()
        .expect("the pendulum swing runs");
    let last = traj.last().expect("the last state is stored");
    let (th, om) = pendulum_reference(gravity, length, theta, omega, t);
    last.distance(&pendulum_state(length, th, om))
}

/// The global error at T = 1 of `base` alone on q'' = −q from (1, 0)
/// (exact solution (cos t, −sin t)).
pub fn free_error<B: BaseMap>(base: B, h: f64) -> f64 {
    let mut integ = Integrator::new(Unconstrained(HarmonicOscillator), base, h);
    let traj = integ
        .run(State::from_slices(&[1.0], &[0.0]), Stop::Time(1.0))
        .stride(u64::MAX)
        .execute()
        .into_result()
        .expect("the oscillator runs");
    let last = traj.last().expect("the last state is stored");
    last.distance(&State::from_slices(&[1f64.cos()], &[-1f64.sin()]))
}

fn order(prev: Option<f64>, e: f64) -> String {
    prev.map(|a| format!("{:.2}", (a / e).log2()))
        .unwrap_or_default()
}

fn main() {
    println!("Global errors at T = 1 (orders from halving h):");
    println!(
        "{:>7}  {:>20}  {:>20}  {:>20}  {:>20}",
        "h", "φ_h alone (osc.)", "RATTLE/SV (pend.)", "RATTLE/φ_h (pend.)", "RATTLE/φ_h ∘ TJ"
    );
    let mut prev = [None; 4];
    for h in [0.1, 0.05, 0.025, 0.0125] {
        let e = [
            free_error(Yoshida4(StormerVerlet), h),
            rattle_error(StormerVerlet, Composition::SINGLE, h),
            rattle_error(Yoshida4(StormerVerlet), Composition::SINGLE, h),
            rattle_error(Yoshida4(StormerVerlet), Composition::TRIPLE_JUMP, h),
        ];
        let cells: Vec<String> = (0..4)
            .map(|i| format!("{:.3e} ({:>4})", e[i], order(prev[i], e[i])))
            .collect();
        println!(
            "{h:>7}  {:>20}  {:>20}  {:>20}  {:>20}",
            cells[0], cells[1], cells[2], cells[3]
        );
        prev = e.map(Some);
    }
}
