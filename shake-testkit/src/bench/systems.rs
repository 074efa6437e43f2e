//! The benchmark scenes, each three ways: declared with
//! `constrained_system!` (the pendulums and Hopf from `geoshake::models`, the
//! chains below), written by hand (`geoshake_testkit::models` and
//! `chain.rs`), and written once generically for num-dual (`dual.rs`).
#![allow(dead_code, clippy::needless_range_loop)]

use super::dual::Generic;
use geoshake::{constrained_system, ConstraintKind};
use num_dual::DualNum;

// ---------------------------------------------------------------------------
// Chains declared with the macro (the pattern of geoshake::models::Chain8).
// ---------------------------------------------------------------------------

macro_rules! chain {
    ($name:ident, $n:literal) => {
        constrained_system! {
            /// A hanging chain of unit masses joined by rods of one length,
            /// the first anchored at the origin.
            pub struct $name {
                parameters { length, gravity }
                const N = $n;
                dof q[2*N], p[2*N];
                hamiltonian = sum i in 0..N { (p[2*i]^2 + p[2*i+1]^2) / 2 + gravity * q[2*i+1] };
                constraints {
                    link[k in 0..N]: if k == 0 { q[0]^2 + q[1]^2 - length^2 }
                        else { (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 },
                }
            }
        }
    };
}

chain!(Chain4, 4);
chain!(Chain16, 16);
chain!(Chain64, 64);
chain!(Chain256, 256);

// ---------------------------------------------------------------------------
// The same H and g, written once for num-dual.
// ---------------------------------------------------------------------------

fn c<T: DualNum<Primitive = f64> + Copy>(x: f64) -> T {
    T::from(x)
}

/// Planar pendulum, H = |p|²/2 + γ q₂, g = |q|² − ℓ².
#[derive(Copy, Clone, Debug)]
pub struct PendulumG {
    pub length: f64,
    pub gravity: f64,
}

impl Generic for PendulumG {
    const DOF: usize = 2;
    const CONSTRAINTS: usize = 1;
    const KIND: ConstraintKind = ConstraintKind::Holonomic;
    const SEPARABLE: bool = true;
    const PATTERN: &'static [(usize, usize)] = geoshake::models::Pendulum::JACOBIAN_PATTERN;
    fn h<T: DualNum<Primitive = f64> + Copy>(&self, q: &[T], p: &[T]) -> T {
        (p[0] * p[0] + p[1] * p[1]) * c::<T>(0.5) + q[1] * c::<T>(self.gravity)
    }
    fn g<T: DualNum<Primitive = f64> + Copy>(&self, q: &[T], _p: &[T], out: &mut [T]) {
        out[0] = q[0] * q[0] + q[1] * q[1] - c::<T>(self.length * self.length);
    }
}

/// Spherical pendulum, H = |p|²/2 + γ q₃, g = |q|² − ℓ².
#[derive(Copy, Clone, Debug)]
pub struct SphericalG {
    pub length: f64,
    pub gravity: f64,
}

impl Generic for SphericalG {
    const DOF: usize = 3;
    const CONSTRAINTS: usize = 1;
    const KIND: ConstraintKind = ConstraintKind::Holonomic;
    const SEPARABLE: bool = true;
    const PATTERN: &'static [(usize, usize)] =
        geoshake::models::SphericalPendulum::JACOBIAN_PATTERN;
    fn h<T: DualNum<Primitive = f64> + Copy>(&self, q: &[T], p: &[T]) -> T {
        (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]) * c::<T>(0.5) + q[2] * c::<T>(self.gravity)
    }
    fn g<T: DualNum<Primitive = f64> + Copy>(&self, q: &[T], _p: &[T], out: &mut [T]) {
        out[0] = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] - c::<T>(self.length * self.length);
    }
}

/// The Hopf constraint with gravity (Section 5.4.2):
/// H = |p|²/2 − γ·q, g = |q|² + |p|² − r².
#[derive(Copy, Clone, Debug)]
pub struct HopfG {
    pub gravity: [f64; 2],
    pub radius2: f64,
}

impl Generic for HopfG {
    const DOF: usize = 2;
    const CONSTRAINTS: usize = 1;
    const KIND: ConstraintKind = ConstraintKind::Quadratic;
    const SEPARABLE: bool = true;
    const PATTERN: &'static [(usize, usize)] = geoshake::models::HopfGravity::JACOBIAN_PATTERN;
    fn h<T: DualNum<Primitive = f64> + Copy>(&self, q: &[T], p: &[T]) -> T {
        (p[0] * p[0] + p[1] * p[1]) * c::<T>(0.5)
            - q[0] * c::<T>(self.gravity[0])
            - q[1] * c::<T>(self.gravity[1])
    }
    fn g<T: DualNum<Primitive = f64> + Copy>(&self, q: &[T], p: &[T], out: &mut [T]) {
        out[0] = q[0] * q[0] + q[1] * q[1] + p[0] * p[0] + p[1] * p[1] - c::<T>(self.radius2);
    }
}

/// The chain of N links.
#[derive(Copy, Clone, Debug)]
pub struct ChainG<const N: usize> {
    pub length: f64,
    pub gravity: f64,
}

impl<const N: usize> Generic for ChainG<N> {
    const DOF: usize = 2 * N;
    const CONSTRAINTS: usize = N;
    const KIND: ConstraintKind = ConstraintKind::Holonomic;
    const SEPARABLE: bool = true;
    const PATTERN: &'static [(usize, usize)] = super::chain::HandChain::<N>::JACOBIAN_PATTERN;
    fn h<T: DualNum<Primitive = f64> + Copy>(&self, q: &[T], p: &[T]) -> T {
        let mut e = T::from(0.0);
        for k in 0..N {
            e += (p[2 * k] * p[2 * k] + p[2 * k + 1] * p[2 * k + 1]) * c::<T>(0.5)
                + q[2 * k + 1] * c::<T>(self.gravity);
        }
        e
    }
    fn g<T: DualNum<Primitive = f64> + Copy>(&self, q: &[T], _p: &[T], out: &mut [T]) {
        let l2 = c::<T>(self.length * self.length);
        out[0] = q[0] * q[0] + q[1] * q[1] - l2;
        for k in 1..N {
            let dx = q[2 * k] - q[2 * k - 2];
            let dy = q[2 * k + 1] - q[2 * k - 1];
            out[k] = dx * dx + dy * dy - l2;
        }
    }
}
