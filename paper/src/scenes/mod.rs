//! The scenes, in the paper's order. Each is `fn(&Ctx, &mut Claims) -> PlotResult<()>`:
//! it runs its systems, draws its figures into `ctx.out`, and checks its claims.

use crate::claims::Claims;
use crate::plot::PlotResult;
use crate::Ctx;

mod convergence;
mod failing;
mod hopf_free;
mod hopf_gravity;
mod index_one;
mod pendulum;
mod util;

/// A scene: runs, draws, checks.
pub type Scene = fn(&Ctx, &mut Claims) -> PlotResult<()>;

/// Every scene with its name, in the order they run.
pub const ALL: &[(&str, Scene)] = &[
    ("pendulum (Example 1.3, 5.1.3)", pendulum::run),
    ("convergence orders (Prop 4.2, 4.5)", convergence::run),
    ("failing nondegeneracy (5.2)", failing::run),
    ("index-1 constraints (5.3)", index_one::run),
    ("harmonic constraint, H = |p|²/2 (5.4.1)", hopf_free::run),
    (
        "harmonic constraint with gravity (5.4.2)",
        hopf_gravity::run,
    ),
];
