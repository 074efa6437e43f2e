//! `geoshake.sample`: constrained Hamiltonian Monte Carlo on M (the
//! runtime's `sampler`: RATTLE over Störmer–Verlet, the reversibility check
//! and the Metropolis test) for a declared or compiled system, with the
//! draws as NumPy arrays of shape (chains, draws, d).

use std::sync::atomic::AtomicBool;

use geoshake::runtime::sampler::{self, Density, SamplerError, SamplerOptions, Samples};
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::IntoPyArray;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::whole::Whole;
use crate::{real_array, refused, typed_error, watching, with_model, InvalidInputError, System};

/// The Python exception for a sampler's refusal: a start off M is the
/// engine's error for it (`NotOnConstraintError`, `NonFiniteError`, ...,
/// with its step, time and residual) under the sampler's message, which
/// names the chain; every other refusal is an `InvalidInputError`.
fn error(py: Python<'_>, e: &SamplerError) -> PyErr {
    match e {
        SamplerError::StartOffManifold { source, .. } => {
            let err = typed_error(py, source);
            let _ = err.value(py).setattr("args", (e.to_string(),));
            err
        }
        // The one option whose Python name is not the Rust field's.
        SamplerError::InvalidOption {
            what: "newton.step_tolerance",
            value,
            why,
        } => InvalidInputError::new_err(
            SamplerError::InvalidOption {
                what: "newton_tolerance",
                value: *value,
                why,
            }
            .to_string(),
        ),
        _ => InvalidInputError::new_err(e.to_string()),
    }
}

/// Draws from the density π = e^{−U} on M = {q : g(q) = 0}, with respect to
/// the surface (Hausdorff) measure of M, for a system declared as
/// H = |p|²/2 + U(q) with holonomic constraints g(q).
///
/// `q0` is one start (length d) for every chain, or one per chain (shape
/// (chains, d)); each must lie on M. Each transition draws p ~ N(0, I) on
/// the cotangent space, takes `steps` RATTLE steps of size `step_size` (or,
/// with `max_tree_depth=k`, a dynamic number: multinomial HMC with the
/// no-U-turn criterion, its trajectory doubled at most k times)
/// (adapted in warm-up towards `target_acceptance`, None keeps it, while
/// holding proposals lost to failed solves to `target_failure_rate`), checks
/// every step by stepping back (`reverse_tolerance`) and applies the
/// Metropolis test. A failed solve or check rejects the proposal (counted
/// by kind in `rejection`), never raises. Chains run in parallel with the
/// GIL released; each chain's draws depend on `seed` and its index only.
/// Ctrl-C stops every chain at the end of its current transition (a tree
/// of depth 20 at a tiny step is 10⁶ steps: seconds) and raises
/// KeyboardInterrupt.
///
/// Returns a dict of NumPy arrays: `positions` (chains, draws, d),
/// `accepted`, `acceptance_probability`, `energy`, `steps` (chains,
/// draws), `rejection` (chains, draws) of str ("" when accepted), and
/// `step_size` (chains,); and per coordinate `mean`, `mcse`, `rhat`,
/// `ess_bulk`, `ess_tail` (d,). For ArviZ: `arviz.from_dict(posterior={"q":
/// s["positions"]}, sample_stats={"energy": s["energy"]})`.
///
/// `density` says what e^{−U} is a density of: "hausdorff" (the default)
/// with respect to the surface measure of M; "ambient" a density on R^d
/// conditioned on g(q) = 0, which by the co-area formula is
/// e^{−U}/√det(g_q g_qᵀ) on M: the sampler adds ½ log det(g_q g_qᵀ) to U
/// (and to `energy`), as mici's `dens_wrt_hausdorff=False`. Any other value
/// raises `InvalidInputError`.
///
/// `newton_tolerance` stops each step's solves once Newton's update of
/// the multipliers is below that fraction of them (default None: at
/// round-off, 4ε), as mici stops its projections at ‖Δq‖∞ < 1e-8: a
/// value from 4ε to 1e-9, fewer updates per step, each step exact only to
/// that tolerance (docs/sampler.md).
#[pyfunction]
#[pyo3(signature = (system, q0, *, chains=Whole::Fits(4), draws=Whole::Fits(1000),
    warmup=Whole::Fits(1000), steps=Whole::Fits(10), max_tree_depth=None, step_size=0.1,
    target_acceptance=Some(0.8), target_failure_rate=0.01, step_size_jitter=0.2, reverse_tolerance=1e-8,
    seed=Whole::Fits(0), density="hausdorff", newton_tolerance=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn sample<'py>(
    py: Python<'py>,
    system: &System,
    q0: &Bound<'py, PyAny>,
    chains: Whole,
    draws: Whole,
    warmup: Whole,
    steps: Whole,
    max_tree_depth: Option<Whole>,
    step_size: f64,
    target_acceptance: Option<f64>,
    target_failure_rate: f64,
    step_size_jitter: f64,
    reverse_tolerance: f64,
    seed: Whole,
    density: &str,
    newton_tolerance: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let chains = chains.count("chains", 0)?;
    let draws = draws.count("draws", 0)?;
    let warmup = warmup.count("warmup", 0)?;
    let steps = steps.count("steps", 0)?;
    let seed = seed.within("seed", 0, u64::MAX)?;
    let max_tree_depth = max_tree_depth
        .map(|k| k.within("max_tree_depth", 1, 20).map(|k| k as u32))
        .transpose()?;
    let density = match density {
        "hausdorff" => Density::Hausdorff,
        "ambient" => Density::Ambient,
        other => {
            return Err(InvalidInputError::new_err(format!(
                "density must be \"hausdorff\" or \"ambient\", not {other:?}"
            )))
        }
    };
    let d = system.dof();
    // (Anything np.ndim cannot read is refused by `real_array` below, with
    // its message; but a Ctrl-C that arrives while np.ndim runs must stop
    // the call here, not be dropped with the error and leave the chains to
    // run their whole warm-up.)
    let ndim: usize = match q0
        .py()
        .import("numpy")?
        .call_method1("ndim", (q0,))
        .and_then(|n| n.extract())
    {
        Ok(n) => n,
        Err(e) if e.is_instance_of::<PyException>(py) => 1,
        Err(e) => return Err(e),
    };
    let (flat, _) = real_array(q0, "q0", if ndim == 2 { 2 } else { 1 }, d, "q, d")?;
    let starts: Vec<&[f64]> = flat.chunks(d.max(1)).collect();
    let mut options = SamplerOptions {
        chains,
        draws,
        warmup,
        steps,
        max_tree_depth,
        step_size,
        step_size_jitter,
        target_acceptance,
        target_failure_rate,
        reverse_tolerance,
        seed,
        density,
        ..SamplerOptions::default()
    };
    if let Some(t) = newton_tolerance {
        options.newton.step_tolerance = t;
    }
    // The chains stop at their next look when Ctrl-C arrives.
    let stop = AtomicBool::new(false);
    let (samples, interrupt) = watching(
        py,
        &stop,
        || with_model!(&system.model, s => sampler::sample_until(s, &starts, &options, &stop)),
    );
    if let Some(e) = interrupt {
        return Err(e);
    }
    let samples = samples
        .map_err(|_| InvalidInputError::new_err("the sampler's thread panicked"))?
        .map_err(|e| error(py, &e))?;
    arrays(py, &samples)
}

/// The draws and their summary as a dict of NumPy arrays.
fn arrays<'py>(py: Python<'py>, s: &Samples) -> PyResult<Bound<'py, PyDict>> {
    let (c, n, d) = (s.chains, s.draws, s.dim);
    let shape = |v: Vec<f64>| Array2::from_shape_vec((c, n), v).expect("chains × draws");
    let out = PyDict::new(py);
    let positions =
        Array3::from_shape_vec((c, n, d), s.positions.clone()).expect("chains × draws × d");
    out.set_item("positions", positions.into_pyarray(py))?;
    let accepted = Array2::from_shape_vec((c, n), s.accepted.clone()).expect("chains × draws");
    out.set_item("accepted", accepted.into_pyarray(py))?;
    out.set_item(
        "acceptance_probability",
        shape(s.acceptance_probability.clone()).into_pyarray(py),
    )?;
    out.set_item("energy", shape(s.energy.clone()).into_pyarray(py))?;
    let taken: Vec<u64> = s.steps.iter().map(|&k| k as u64).collect();
    let taken = Array2::from_shape_vec((c, n), taken).expect("chains × draws");
    out.set_item("steps", taken.into_pyarray(py))?;
    let why: Vec<&str> = s
        .rejection
        .iter()
        .map(|r| r.map_or("", |r| r.name()))
        .collect();
    let why = py
        .import("numpy")?
        .call_method1("array", (why,))?
        .call_method1("reshape", ((c, n),))?;
    out.set_item("rejection", why)?;
    out.set_item(
        "step_size",
        Array1::from(s.step_size.clone()).into_pyarray(py),
    )?;
    let summary = s.summary();
    let column = |f: fn(&sampler::Estimate) -> f64| {
        Array1::from_iter(summary.coordinates.iter().map(f)).into_pyarray(py)
    };
    out.set_item("mean", column(|e| e.mean))?;
    out.set_item("mcse", column(|e| e.mcse))?;
    out.set_item("rhat", column(|e| e.rhat))?;
    out.set_item("ess_bulk", column(|e| e.ess_bulk))?;
    out.set_item("ess_tail", column(|e| e.ess_tail))?;
    Ok(out)
}

/// `x` as (chains, draws) rows of a float64 array.
fn chains_of(x: &Bound<'_, PyAny>) -> PyResult<Vec<Vec<f64>>> {
    let shape: Vec<usize> = x
        .py()
        .import("numpy")?
        .call_method1("shape", (x,))
        .and_then(|s| s.extract())
        .map_err(|e| refused(x.py(), e, |e| format!("x must be an array: {e}")))?;
    if shape.len() != 2 {
        return Err(InvalidInputError::new_err(format!(
            "x must have shape (chains, draws), not {shape:?}"
        )));
    }
    let (flat, rows) = real_array(x, "x", 2, shape[1], "draws")?;
    Ok(flat
        .chunks(shape[1].max(1))
        .take(rows)
        .map(<[f64]>::to_vec)
        .collect())
}

/// The bulk effective sample size of a scalar quantity `x` of shape
/// (chains, draws): rank-normalised split chains (Vehtari et al. 2021), the
/// estimator `sample` reports. NaN for fewer than 4 draws per chain.
#[pyfunction]
pub(crate) fn ess_bulk(x: &Bound<'_, PyAny>) -> PyResult<f64> {
    Ok(sampler::ess_bulk(&chains_of(x)?))
}

/// The rank-normalised split-R̂ of `x` of shape (chains, draws) (Vehtari et
/// al. 2021), as `sample` reports it.
#[pyfunction]
pub(crate) fn rhat(x: &Bound<'_, PyAny>) -> PyResult<f64> {
    Ok(sampler::rhat(&chains_of(x)?))
}
