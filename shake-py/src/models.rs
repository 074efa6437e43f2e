//! The compiled systems `geoshake.models` offers: the facade's models
//! (`geoshake::models`) and the chains the benchmarks compare, each declared
//! with `constrained_system!` so its derivatives are straight-line code.

use geoshake::constrained_system;
pub use geoshake::models::{
    Chain8, DoublePendulum, HopfFree, HopfGravity, IndexOne, Pendulum, SphericalPendulum,
};

/// A planar chain of `$n` unit masses and rods, anchored at the origin (the
/// facade's `Chain8` with another N).
macro_rules! chain {
    ($name:ident, $n:literal, $doc:literal) => {
        constrained_system! {
            #[doc = $doc]
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

chain!(
    Chain4,
    4,
    "A planar chain of 4 unit masses and rods, anchored at the origin."
);
chain!(
    Chain16,
    16,
    "A planar chain of 16 unit masses and rods, anchored at the origin."
);
chain!(
    Chain64,
    64,
    "A planar chain of 64 unit masses and rods, anchored at the origin."
);

/// One system of any kind the package runs: declared from a string or
/// compiled. Every variant is `Send + Sync` (ensembles share it).
/// (One per Python `System`, never stored in bulk: the declared variant's
/// size does not matter.)
#[derive(Clone, Debug)]
#[allow(clippy::large_enum_variant)]
pub enum Model {
    Declared(geoshake::declared::DeclaredSystem),
    Pendulum(Pendulum),
    SphericalPendulum(SphericalPendulum),
    DoublePendulum(DoublePendulum),
    HopfFree(HopfFree),
    HopfGravity(HopfGravity),
    IndexOne(IndexOne),
    Chain4(Chain4),
    Chain8(Chain8),
    Chain16(Chain16),
    Chain64(Chain64),
}

/// Runs `$body` with `$s` bound to the concrete system inside `$model`.
#[macro_export]
macro_rules! with_model {
    ($model:expr, $s:ident => $body:expr) => {
        match $model {
            $crate::models::Model::Declared($s) => $body,
            $crate::models::Model::Pendulum($s) => $body,
            $crate::models::Model::SphericalPendulum($s) => $body,
            $crate::models::Model::DoublePendulum($s) => $body,
            $crate::models::Model::HopfFree($s) => $body,
            $crate::models::Model::HopfGravity($s) => $body,
            $crate::models::Model::IndexOne($s) => $body,
            $crate::models::Model::Chain4($s) => $body,
            $crate::models::Model::Chain8($s) => $body,
            $crate::models::Model::Chain16($s) => $body,
            $crate::models::Model::Chain64($s) => $body,
        }
    };
}

/// The compiled model `name` with its parameters by name (in the order of
/// its declaration), or `None` for an unknown name. Returns the model, its
/// parameter names and values.
pub fn compiled(name: &str, get: &dyn Fn(&str) -> Option<f64>) -> Result<Option<Model>, String> {
    let p = |n: &str| get(n).ok_or_else(|| format!("model {name} needs parameter `{n}`"));
    Ok(Some(match name {
        "Pendulum" => Model::Pendulum(Pendulum::new(p("length")?, p("gravity")?)),
        "SphericalPendulum" => {
            Model::SphericalPendulum(SphericalPendulum::new(p("length")?, p("gravity")?))
        }
        "DoublePendulum" => {
            Model::DoublePendulum(DoublePendulum::new(p("l1")?, p("l2")?, p("gravity")?))
        }
        "HopfFree" => Model::HopfFree(HopfFree::new(p("radius2")?)),
        "HopfGravity" => Model::HopfGravity(HopfGravity::new(p("g0")?, p("g1")?, p("radius2")?)),
        "IndexOne" => Model::IndexOne(IndexOne::new(p("coupling")?)),
        "Chain4" => Model::Chain4(Chain4::new(p("length")?, p("gravity")?)),
        "Chain8" => Model::Chain8(Chain8::new(p("length")?, p("gravity")?)),
        "Chain16" => Model::Chain16(Chain16::new(p("length")?, p("gravity")?)),
        "Chain64" => Model::Chain64(Chain64::new(p("length")?, p("gravity")?)),
        _ => return Ok(None),
    }))
}

/// The compiled models and their parameter names, for `geoshake.models`.
pub const MODELS: &[(&str, &[&str])] = &[
    ("Pendulum", &["length", "gravity"]),
    ("SphericalPendulum", &["length", "gravity"]),
    ("DoublePendulum", &["l1", "l2", "gravity"]),
    ("HopfFree", &["radius2"]),
    ("HopfGravity", &["g0", "g1", "radius2"]),
    ("IndexOne", &["coupling"]),
    ("Chain4", &["length", "gravity"]),
    ("Chain8", &["length", "gravity"]),
    ("Chain16", &["length", "gravity"]),
    ("Chain64", &["length", "gravity"]),
];
