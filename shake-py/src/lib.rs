//! `geoshake._geoshake`, the extension module behind the Python package `shake`:
//! systems declared from strings (`geoshake::declared`) or compiled
//! (`geoshake.models`), run by SHAKE or RATTLE over a base map, with NumPy
//! arrays out and every failure a Python exception that carries the partial
//! trajectory.

mod bonds;
mod forces;
mod models;
mod particles;
mod sampler;
mod thermostat;
mod whole;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

use geoshake::declared::{DeclareError, DeclaredSystem};
use geoshake::{
    BaseMap, ConstrainedSystem, Hamiltonian, ImplicitMidpoint, Integrator, Options, RunOutcome,
    State, StepError, Stop, StormerVerlet, SymplecticEuler,
};
use models::Model;
use numpy::ndarray::{Array1, Array2};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArrayDyn};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use whole::Whole;

create_exception!(
    geoshake,
    ShakeError,
    PyException,
    "Every error of shake. A run's errors carry `step`, `time`, `residual` (NaN when the error has none) and the partial trajectory (`trajectory`, `times`, `steps`, `lambda_`, `sigma`)."
);
create_exception!(
    geoshake,
    DeclarationError,
    ShakeError,
    "A declaration refused: `message`, and `line`, `column` (1-based) of the offending token in the string."
);
create_exception!(
    geoshake,
    ParameterError,
    ShakeError,
    "A parameter unknown, missing or given twice."
);
create_exception!(
    geoshake,
    InvalidInputError,
    ShakeError,
    "An unusable argument: h = 0 or not finite, a state of the wrong dimension, ..."
);
create_exception!(
    geoshake,
    NonFiniteError,
    ShakeError,
    "A state (given or computed) has a NaN or infinite entry."
);
create_exception!(
    geoshake,
    NewtonError,
    ShakeError,
    "A Newton iteration did not converge (`residual` is its last residual)."
);
create_exception!(
    geoshake,
    NondegeneracyError,
    ShakeError,
    "N = {{H,g_i},g_j} became singular or ill-conditioned (the paper's nondegeneracy assumption)."
);
create_exception!(
    geoshake,
    ComponentJumpError,
    ShakeError,
    "det N changed sign: the trajectory jumped to another component of M^H (Section 5.4.2)."
);
create_exception!(
    geoshake,
    FibreJumpError,
    ShakeError,
    "Newton along a fibre converged far from its linear prediction (a fold or another component)."
);
create_exception!(
    geoshake,
    NotOnConstraintError,
    ShakeError,
    "The initial state is not on M = {g = 0} (`residual` is |g|)."
);

/// A constrained Hamiltonian system: declared from a string
/// (`geoshake.declare`) or compiled (`geoshake.models`).
#[pyclass(frozen, module = "geoshake")]
struct System {
    model: Model,
    name: String,
    parameters: Vec<(String, f64)>,
    /// What rebuilds it ([`System::__reduce__`]): the declaration's source
    /// (None for a compiled model, found by `name`) and the parameters as
    /// they were given.
    source: Option<String>,
    given: Vec<(String, f64)>,
}

#[pymethods]
impl System {
    /// d, the number of coordinates (a state z = (q, p) has 2d entries).
    #[getter]
    fn dof(&self) -> usize {
        with_model!(&self.model, s => s.dof())
    }

    /// m, the number of constraints.
    #[getter]
    fn constraint_count(&self) -> usize {
        with_model!(&self.model, s => s.constraint_count())
    }

    /// The declared name.
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// How g depends on z: "none", "holonomic", "quadratic" or "general".
    #[getter]
    fn kind(&self) -> &'static str {
        match with_model!(&self.model, s => s.kind()) {
            geoshake::ConstraintKind::None => "none",
            geoshake::ConstraintKind::Holonomic => "holonomic",
            geoshake::ConstraintKind::Quadratic => "quadratic",
            geoshake::ConstraintKind::General => "general",
        }
    }

    /// True when the system is compiled (a `geoshake.models` class), False
    /// when declared from a string and interpreted.
    #[getter]
    fn compiled(&self) -> bool {
        !matches!(self.model, Model::Declared(_))
    }

    /// The parameters, by name.
    #[getter]
    fn parameters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in &self.parameters {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    /// The constraint names (`rod`, `link[3]`).
    #[getter]
    fn constraint_names(&self) -> Vec<String> {
        with_model!(&self.model, s => (0..s.constraint_count()).map(|i| s.constraint_name(i).to_string()).collect())
    }

    /// The names of z's 2d entries as declared (`theta`, `p_theta`;
    /// `q[0]` … for `dof q[d], p[d]`): the columns of `result.trajectory`.
    #[getter]
    fn variable_names(&self) -> Vec<String> {
        with_model!(&self.model, s => (0..2 * s.dof()).map(|k| s.variable_name(k).into_owned()).collect())
    }

    /// H(z) at a state z = (q, p) of length 2d.
    fn hamiltonian(&self, z: &Bound<'_, PyAny>) -> PyResult<f64> {
        let (q, p) = self.split(z)?;
        Ok(with_model!(&self.model, s => s.hamiltonian(&q, &p)))
    }

    /// g(z), the m constraints at z = (q, p).
    fn constraints<'py>(
        &self,
        py: Python<'py>,
        z: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (q, p) = self.split(z)?;
        let mut g = vec![0.0; self.constraint_count()];
        with_model!(&self.model, s => s.constraints(&q, &p, &mut g));
        Ok(g.into_pyarray(py))
    }

    /// The hidden constraints {g_i, H}(z).
    fn hidden_constraints<'py>(
        &self,
        py: Python<'py>,
        z: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (q, p) = self.split(z)?;
        let mut g = vec![0.0; self.constraint_count()];
        with_model!(&self.model, s => s.hidden_constraints(&q, &p, &mut g));
        Ok(g.into_pyarray(py))
    }

    /// Pickling (`pickle`, `multiprocessing`, `copy.deepcopy`): a system
    /// is rebuilt from its declaration or its model's name and the
    /// parameters as given, and so takes the same steps bit for bit.
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let given = PyDict::new(py);
        for (k, v) in &self.given {
            given.set_item(k, v)?;
        }
        reduce(
            py,
            "_rebuild_system",
            (self.source.as_deref(), self.name.as_str(), given),
        )
    }

    fn __repr__(&self) -> String {
        // (", length=1, gravity=9.81", or nothing without parameters.)
        let ps: String = self
            .parameters
            .iter()
            .map(|(k, v)| format!(", {k}={v}"))
            .collect();
        let how = if self.compiled() {
            "compiled"
        } else {
            "declared"
        };
        format!(
            "<geoshake.System {} ({how}, d={}, m={}{ps})>",
            self.name,
            self.dof(),
            self.constraint_count(),
        )
    }
}

impl System {
    fn split(&self, z: &Bound<'_, PyAny>) -> PyResult<(Vec<f64>, Vec<f64>)> {
        let d = self.dof();
        let (z, _) = real_array(z, "z", 1, 2 * d, Z)?;
        Ok((z[..d].to_vec(), z[d..].to_vec()))
    }
}

/// Declares a system from a string in the grammar of `constrained_system!`
/// (the `struct` with its body), with every parameter given by name.
///
/// The declaration goes through the macro's own checks (coisotropy,
/// nondegeneracy, ...); a refusal raises `DeclarationError` with the macro's
/// message and the line and column in the string.
#[pyfunction]
#[pyo3(signature = (source, **parameters))]
fn declare(source: &str, parameters: Option<&Bound<'_, PyDict>>) -> PyResult<System> {
    let given = keyword_parameters(parameters)?;
    let refs: Vec<(&str, f64)> = given.iter().map(|(k, v)| (k.as_str(), *v)).collect();
    let sys = DeclaredSystem::new(source, &refs).map_err(declare_error)?;
    let parameters = sys
        .parameter_names()
        .iter()
        .cloned()
        .zip(sys.parameters().iter().copied())
        .collect();
    Ok(System {
        name: sys.name().to_string(),
        parameters,
        model: Model::Declared(sys),
        source: Some(source.to_string()),
        given,
    })
}

/// What `__reduce__` returns for pickling: the extension module's
/// function `rebuild` (pickled by reference) and the arguments it takes.
pub(crate) fn reduce<'py, A: pyo3::IntoPyObjectExt<'py>>(
    py: Python<'py>,
    rebuild: &str,
    args: A,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let f = py.import("geoshake._geoshake")?.getattr(rebuild)?;
    let args = args.into_bound_py_any(py)?;
    Ok((f, args))
}

/// The inverse of [`System::__reduce__`]: the declaration `source` (or,
/// for None, the compiled model `name`) with the parameters `given`.
#[pyfunction]
fn _rebuild_system(
    source: Option<&str>,
    name: &str,
    given: &Bound<'_, PyDict>,
) -> PyResult<System> {
    match source {
        Some(source) => declare(source, Some(given)),
        None => model(name, Some(given)),
    }
}

/// The parameters given by keyword, as (name, value) pairs: each a real
/// number (a Python or NumPy int or float), else `ParameterError` naming
/// it; a bool is not taken for 0 or 1, and an int beyond f64's range is
/// refused, not an `OverflowError`. Whether a value is finite is the
/// declaration's (or the model's) check.
fn keyword_parameters(parameters: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<(String, f64)>> {
    let mut given = Vec::new();
    if let Some(ps) = parameters {
        for (k, v) in ps.iter() {
            let name: String = k.extract()?;
            let value = if v.is_instance_of::<pyo3::types::PyBool>() {
                None
            } else {
                v.extract::<f64>().ok()
            };
            let Some(value) = value else {
                let mut shown = v
                    .repr()
                    .map_or_else(|_| "that".to_string(), |r| r.to_string());
                if let Some((cut, _)) = shown.char_indices().nth(40) {
                    shown.truncate(cut);
                    shown.push('…');
                }
                return Err(ParameterError::new_err(format!(
                    "parameter `{name}` must be a real number within f64's range, not {shown}"
                )));
            };
            given.push((name, value));
        }
    }
    Ok(given)
}

/// A refused run-time declaration (dense or particles) as the package's
/// exception: the declaration itself is `DeclarationError` with `message`,
/// `line` and `column` (both None for a family shape the runtime has no
/// stencil for: the shape, not a token, is at fault), parameters are
/// `ParameterError`, and the tables and masses of a particle system are
/// `InvalidInputError`.
pub(crate) fn declare_error(e: DeclareError) -> PyErr {
    Python::attach(|py| {
        let (err, message, position) = match &e {
            DeclareError::Declaration(d) => (
                DeclarationError::new_err(d.to_string()),
                Some(d.message.clone()),
                Some((d.line, d.column)),
            ),
            DeclareError::Shape { .. } => (
                DeclarationError::new_err(e.to_string()),
                Some(e.to_string()),
                None,
            ),
            DeclareError::UnknownParameter { .. }
            | DeclareError::MissingParameter { .. }
            | DeclareError::DuplicateParameter { .. }
            | DeclareError::NonFiniteParameter { .. } => {
                (ParameterError::new_err(e.to_string()), None, None)
            }
            DeclareError::Tables { .. } | DeclareError::Topology(_) => {
                (InvalidInputError::new_err(e.to_string()), None, None)
            }
        };
        if let Some(message) = message {
            let v = err.value(py);
            let _ = v.setattr("message", message);
            let _ = v.setattr("line", position.map(|p| p.0));
            let _ = v.setattr("column", position.map(|p| p.1));
        }
        err
    })
}

/// A compiled model of `geoshake.models` by name, parameters by name.
#[pyfunction]
#[pyo3(signature = (name, **parameters))]
fn model(name: &str, parameters: Option<&Bound<'_, PyDict>>) -> PyResult<System> {
    let spec = models::MODELS
        .iter()
        .find(|m| m.0 == name)
        .ok_or_else(|| ParameterError::new_err(format!("no compiled model `{name}`")))?;
    let given = keyword_parameters(parameters)?;
    for (k, v) in &given {
        if !spec.1.contains(&k.as_str()) {
            return Err(ParameterError::new_err(format!(
                "unknown parameter `{k}`; {name}'s parameters are: {}",
                spec.1.join(", ")
            )));
        }
        // As a declaration refuses it: a NaN or infinite parameter would
        // only show later, as a state off M or a Newton failure.
        if !v.is_finite() {
            return Err(declare_error(DeclareError::NonFiniteParameter {
                name: k.clone(),
                value: *v,
            }));
        }
    }
    let get = |n: &str| given.iter().find(|g| g.0 == n).map(|g| g.1);
    let model = models::compiled(name, &get)
        .map_err(ParameterError::new_err)?
        .expect("listed in MODELS");
    Ok(System {
        model,
        name: name.to_string(),
        parameters: spec
            .1
            .iter()
            .map(|n| (n.to_string(), get(n).unwrap_or(f64::NAN)))
            .collect(),
        source: None,
        given,
    })
}

/// The compiled models and their parameter names.
#[pyfunction]
fn model_names() -> Vec<(String, Vec<String>)> {
    models::MODELS
        .iter()
        .map(|(n, ps)| (n.to_string(), ps.iter().map(|p| p.to_string()).collect()))
        .collect()
}

/// What a run returns: NumPy arrays.
#[pyclass(frozen, module = "geoshake", name = "Result")]
struct Result_ {
    /// The stored states, shape (n, 2d): q then p.
    #[pyo3(get)]
    trajectory: Py<PyArray2<f64>>,
    /// Their times, shape (n,).
    #[pyo3(get)]
    times: Py<PyArray1<f64>>,
    /// Their step indices, shape (n,).
    #[pyo3(get)]
    steps: Py<PyArray1<u64>>,
    /// λ of the SHAKE step leaving each stored state, shape (n, m) (NaN for
    /// the last state: no step leaves it). An impulse: for Störmer–Verlet
    /// λ = (h/2) λ_c with the DAE's multiplier λ_c.
    #[pyo3(get)]
    lambda_: Py<PyArray2<f64>>,
    /// σ of RATTLE's projection that gave each stored state, shape (n, m)
    /// (zero for SHAKE).
    #[pyo3(get)]
    sigma: Py<PyArray2<f64>>,
}

#[pymethods]
impl Result_ {
    fn __len__(&self, py: Python<'_>) -> usize {
        self.times.bind(py).len().unwrap_or(0)
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!("<geoshake.Result: {} states>", self.__len__(py))
    }

    /// Pickling: the arrays, as they are.
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let arrays = (
            &self.trajectory,
            &self.times,
            &self.steps,
            &self.lambda_,
            &self.sigma,
        );
        reduce(py, "_rebuild_result", arrays)
    }
}

/// The inverse of `Result.__reduce__`.
#[pyfunction]
fn _rebuild_result(
    trajectory: Py<PyArray2<f64>>,
    times: Py<PyArray1<f64>>,
    steps: Py<PyArray1<u64>>,
    lambda_: Py<PyArray2<f64>>,
    sigma: Py<PyArray2<f64>>,
) -> Result_ {
    Result_ {
        trajectory,
        times,
        steps,
        lambda_,
        sigma,
    }
}

/// A run's arrays, built without the GIL.
struct Arrays {
    trajectory: Array2<f64>,
    times: Array1<f64>,
    steps: Array1<u64>,
    lambda: Array2<f64>,
    sigma: Array2<f64>,
}

impl Arrays {
    fn of(out: &RunOutcome, d: usize, m: usize, multipliers: bool) -> Arrays {
        let t = &out.trajectory;
        let n = t.len();
        let mut z = Vec::with_capacity(n * 2 * d);
        for i in 0..n {
            z.extend_from_slice(t.q(i));
            z.extend_from_slice(t.p(i));
        }
        let (mut lam, mut sig) = (Vec::with_capacity(n * m), Vec::with_capacity(n * m));
        for i in 0..n {
            if multipliers && m > 0 {
                lam.extend_from_slice(t.lambda(i));
                sig.extend_from_slice(t.sigma(i));
            } else {
                lam.resize(lam.len() + m, f64::NAN);
                sig.resize(sig.len() + m, f64::NAN);
            }
        }
        Arrays {
            trajectory: Array2::from_shape_vec((n, 2 * d), z).expect("n·2d states"),
            times: Array1::from(t.times()),
            steps: Array1::from(t.steps()),
            lambda: Array2::from_shape_vec((n, m), lam).expect("n·m"),
            sigma: Array2::from_shape_vec((n, m), sig).expect("n·m"),
        }
    }

    fn into_py(self, py: Python<'_>) -> Result_ {
        Result_ {
            trajectory: self.trajectory.into_pyarray(py).unbind(),
            times: self.times.into_pyarray(py).unbind(),
            steps: self.steps.into_pyarray(py).unbind(),
            lambda_: self.lambda.into_pyarray(py).unbind(),
            sigma: self.sigma.into_pyarray(py).unbind(),
        }
    }
}

/// The Python exception for a run's error, with the partial run attached.
fn step_error(py: Python<'_>, e: &StepError, partial: Arrays) -> PyErr {
    let err = typed_error(py, e);
    let v = err.value(py);
    let r = partial.into_py(py);
    let _ = v.setattr("trajectory", r.trajectory);
    let _ = v.setattr("times", r.times);
    let _ = v.setattr("steps", r.steps);
    let _ = v.setattr("lambda_", r.lambda_);
    let _ = v.setattr("sigma", r.sigma);
    err
}

/// The subclass of `ShakeError` for a `StepError`, carrying `step`, `time`
/// and `residual` (NaN where the error has none).
fn typed_error(py: Python<'_>, e: &StepError) -> PyErr {
    let msg = e.to_string();
    let nan = f64::NAN;
    let (err, time, residual) = match e {
        // (Too many states for memory: the steps and stride asked for.)
        StepError::InvalidInput { .. }
        | StepError::Shape { .. }
        | StepError::Topology(_)
        | StepError::Solver { .. }
        | StepError::Unavailable { .. }
        | StepError::Storage { .. } => (InvalidInputError::new_err(msg), nan, nan),
        StepError::NonFinite { t, .. } => (NonFiniteError::new_err(msg), *t, nan),
        StepError::NewtonNotConverged { t, source, .. } | StepError::AtMember { t, source, .. } => {
            let r = match source {
                geoshake::SolveError::NotConverged { residual, .. } => *residual,
                _ => nan,
            };
            (NewtonError::new_err(msg), *t, r)
        }
        // SHAKE's matrix singular: the step's Newton iteration cannot go on.
        StepError::SingularShakeJacobian { t, .. } => (NewtonError::new_err(msg), *t, nan),
        StepError::NondegeneracyLost { t, .. }
        | StepError::SingularNondegeneracyMatrix { t, .. } => {
            (NondegeneracyError::new_err(msg), *t, nan)
        }
        StepError::ComponentJump { t, .. } => (ComponentJumpError::new_err(msg), *t, nan),
        StepError::FibreJump { t, .. } => (FibreJumpError::new_err(msg), *t, nan),
        // Only composed steps are checked by stepping back, and Python runs
        // single steps: the base class, with the time, should that change.
        StepError::BranchJump { t, .. } => (ShakeError::new_err(msg), *t, nan),
        StepError::NotOnConstraint { t, residual, .. } => {
            (NotOnConstraintError::new_err(msg), *t, *residual)
        }
    };
    let v = err.value(py);
    let _ = v.setattr("step", e.step());
    let _ = v.setattr("time", time);
    let _ = v.setattr("residual", residual);
    err
}

/// How to run: everything but the system and the initial states.
#[derive(Clone)]
struct Plan {
    h: f64,
    stop: Stop,
    stride: u64,
    rattle: bool,
    project: bool,
    multipliers: bool,
    options: Options,
}

/// One run, or the error of projecting the initial state.
fn run_one<S, B>(integ: &mut Integrator<S, B>, plan: &Plan, z0: &[f64]) -> RunOutcome
where
    S: ConstrainedSystem,
    B: BaseMap,
{
    let d = integ.system().dof();
    let mut z = State::from_slices(&z0[..d], &z0[d..]);
    if plan.project {
        let projected = if plan.rattle {
            integ.project_to_hidden(&z)
        } else {
            integ.project(&z)
        };
        match projected {
            Ok(p) => z = p,
            Err(e) => {
                return RunOutcome {
                    trajectory: Default::default(),
                    summary: Default::default(),
                    error: Some(e),
                }
            }
        }
    }
    integ.run(z, plan.stop).stride(plan.stride).execute()
}

fn integrator<S: ConstrainedSystem, B: BaseMap>(s: S, base: B, plan: &Plan) -> Integrator<S, B> {
    let i = Integrator::new(s, base, plan.h).with_options(plan.options);
    let i = if plan.rattle { i.rattle() } else { i.shake() };
    if plan.multipliers {
        i.with_diagnostics()
    } else {
        i
    }
}

/// Runs every initial state (rows of `z0s`) on all cores.
fn run_all(model: &Model, base: &str, plan: &Plan, z0s: &[Vec<f64>]) -> Vec<RunOutcome> {
    macro_rules! go {
        ($b:expr) => {
            with_model!(model, s => {
                let template = integrator(s.clone(), $b, plan);
                if z0s.len() == 1 {
                    vec![run_one(&mut template.clone(), plan, &z0s[0])]
                } else {
                    geoshake::ensemble(&template, z0s, |integ, _, z0| run_one(integ, plan, z0))
                }
            })
        };
    }
    match base {
        "midpoint" => go!(ImplicitMidpoint),
        "verlet" => go!(StormerVerlet),
        _ => go!(SymplecticEuler),
    }
}

#[allow(clippy::too_many_arguments)]
fn plan(
    system: &System,
    h: f64,
    steps: Option<Whole>,
    time: Option<f64>,
    method: &str,
    base: &str,
    stride: Whole,
    project: bool,
    multipliers: bool,
    constraint_tolerance: Option<f64>,
    newton_tolerance: Option<f64>,
    max_iterations: Option<Whole>,
) -> PyResult<Plan> {
    // (A run too long is refused by the runtime, as an error of the run
    // with its step and time.)
    let steps = steps.map(|n| n.within("steps", 0, u64::MAX)).transpose()?;
    let stride = stride.within("stride", 0, u64::MAX)?;
    let max_iterations = max_iterations
        .map(|n| n.budget("max_iterations"))
        .transpose()?;
    let stop = match (steps, time) {
        (Some(n), None) => Stop::Steps(n),
        (None, Some(t)) => Stop::Time(t),
        _ => {
            return Err(InvalidInputError::new_err(
                "give exactly one of steps= and time=",
            ))
        }
    };
    let rattle = match method {
        "rattle" => true,
        "shake" => false,
        _ => {
            return Err(InvalidInputError::new_err(format!(
                "method must be \"rattle\" or \"shake\", not {method:?}"
            )))
        }
    };
    if !matches!(base, "midpoint" | "verlet" | "euler") {
        return Err(InvalidInputError::new_err(format!(
            "base must be \"midpoint\", \"verlet\" or \"euler\", not {base:?}"
        )));
    }
    let _ = system;
    let mut options = Options::default();
    if let Some(t) = constraint_tolerance {
        options.constraint_tolerance = t;
    }
    if let Some(t) = newton_tolerance {
        // (Checked here to name the argument as Python knows it; the
        // runtime's own check names the Rust field.)
        let most = geoshake::validate::MAX_STEP_TOLERANCE;
        if !(0.0..=most).contains(&t) {
            return Err(InvalidInputError::new_err(format!(
                "invalid `newton_tolerance` = {t:e}: from 0 to {most:e} (Newton stops when an update is below this fraction of the multipliers)"
            )));
        }
        options.newton.step_tolerance = t;
    }
    if let Some(n) = max_iterations {
        options.newton.max_iterations = n;
    }
    Ok(Plan {
        h,
        stop,
        stride,
        rattle,
        project,
        multipliers,
        options,
    })
}

/// NumPy's refusal `e` of an argument as `InvalidInputError` with the
/// message `says` makes of it, unless `e` is not an `Exception`: a
/// `KeyboardInterrupt` (Ctrl-C, whose handler runs in whatever Python code
/// NumPy was executing) or a `SystemExit` goes on as it is, never turned
/// into a complaint about the input, nor lost.
pub(crate) fn refused(py: Python<'_>, e: PyErr, says: impl FnOnce(&PyErr) -> String) -> PyErr {
    if e.is_instance_of::<PyException>(py) {
        InvalidInputError::new_err(says(&e))
    } else {
        e
    }
}

/// A state's layout, for [`real_array`]'s messages.
const Z: &str = "q then p, 2d";

/// Runs `work` on a scoped thread, without the interpreter's lock, while
/// this thread takes the lock back every 50 ms to let Python see a signal:
/// when a handler raises (Ctrl-C's `KeyboardInterrupt`), `halt` is set for
/// `work` to stop at its next look, and the handler's exception is
/// returned beside `work`'s result. Returns as soon as `work` ends (a
/// sleep of 50 ms between looks would add 25 ms on average to every
/// call); a panic in `work` ends the wait too, and is the `Err` of its
/// result.
pub(crate) fn watching<T: Send>(
    py: Python<'_>,
    halt: &AtomicBool,
    work: impl FnOnce() -> T + Send,
) -> (std::thread::Result<T>, Option<PyErr>) {
    std::thread::scope(|scope| {
        let (done, finished) = mpsc::channel::<()>();
        let worker = scope.spawn(move || {
            let out = work();
            let _ = done.send(());
            out
        });
        let mut interrupt = None;
        let mut finished = finished;
        loop {
            if interrupt.is_none() {
                if let Err(e) = py.check_signals() {
                    halt.store(true, Ordering::Relaxed);
                    interrupt = Some(e);
                }
            }
            let (rx, seen) = py.detach(move || {
                let seen = finished.recv_timeout(Duration::from_millis(50));
                (finished, seen)
            });
            finished = rx;
            if !matches!(seen, Err(mpsc::RecvTimeoutError::Timeout)) {
                break;
            }
        }
        (worker.join(), interrupt)
    })
}

/// `obj` as real numbers in a float64 array of `ndim` dimensions, the last
/// of length `len` (`what` says which: "q then p, 2d" or "q, d"),
/// flattened row by row, with its number of rows. Anything NumPy reads as an array is taken (lists, integer arrays,
/// float32, big-endian, non-contiguous: converted); complex, boolean,
/// object or string data, or a wrong shape, is an `InvalidInputError` that
/// says what was expected and what was given.
fn real_array(
    obj: &Bound<'_, PyAny>,
    name: &str,
    ndim: usize,
    len: usize,
    what: &str,
) -> PyResult<(Vec<f64>, usize)> {
    let np = obj.py().import("numpy")?;
    // (A ragged list or an object NumPy cannot read raises ValueError or
    // TypeError there: the package's own error instead.)
    let a = np.call_method1("asarray", (obj,)).map_err(|e| {
        refused(obj.py(), e, |e| {
            format!(
                "{name} must be an array of real numbers ({what} = {len}): {}",
                e.value(obj.py())
            )
        })
    })?;
    let dtype = a.getattr("dtype")?;
    let kind: String = dtype.getattr("kind")?.extract()?;
    let shape: Vec<usize> = a.getattr("shape")?.extract()?;
    let want = match ndim {
        1 => format!("({len},)"),
        2 => format!("(k, {len})"),
        _ => format!("(…, {len})"),
    };
    if !matches!(kind.as_str(), "f" | "i" | "u") {
        return Err(InvalidInputError::new_err(format!(
            "{name} must hold real numbers (float64; integers are converted), not dtype {}: \
             an array of shape {want}, {what} = {len}",
            dtype.str()?
        )));
    }
    if shape.len() != ndim || shape.last() != Some(&len) {
        let given: Vec<String> = shape.iter().map(usize::to_string).collect();
        let comma = if shape.len() == 1 { "," } else { "" };
        return Err(InvalidInputError::new_err(format!(
            "{name} must have shape {want} ({what} = {len}), not ({}{comma})",
            given.join(", ")
        )));
    }
    let a = np.call_method1("ascontiguousarray", (a, "float64"))?;
    let a: PyReadonlyArrayDyn<'_, f64> = a.extract()?;
    let rows = if ndim == 1 { 1 } else { shape[0] };
    Ok((a.as_array().iter().copied().collect(), rows))
}

fn rows(system: &System, z: &[f64], n: usize) -> PyResult<Vec<Vec<f64>>> {
    let d2 = 2 * system.dof();
    if z.len() != n * d2 {
        return Err(InvalidInputError::new_err(format!(
            "states of {} have 2d = {d2} entries",
            system.name
        )));
    }
    Ok(z.chunks(d2.max(1)).map(<[f64]>::to_vec).collect())
}

/// Runs SHAKE or RATTLE from `z0` (length 2d: q then p) with step size `h`
/// for `steps` steps or until `time`, keeping every `stride`-th state.
///
/// `base` is the base map: "midpoint" (implicit midpoint), "verlet"
/// (Störmer–Verlet) or "euler" (symplectic Euler). With `project` the
/// initial state is first projected onto M^H (RATTLE) or M (SHAKE). With
/// `multipliers` the result carries λ and σ. A failure raises a subclass of
/// `ShakeError` carrying the step, time, residual and partial trajectory.
#[pyfunction]
#[pyo3(signature = (system, z0, h, *, steps=None, time=None, method="rattle", base="midpoint",
    stride=Whole::Fits(1), project=true, multipliers=true, constraint_tolerance=None, newton_tolerance=None,
    max_iterations=None))]
#[allow(clippy::too_many_arguments)]
fn run(
    py: Python<'_>,
    system: &System,
    z0: &Bound<'_, PyAny>,
    h: f64,
    steps: Option<Whole>,
    time: Option<f64>,
    method: &str,
    base: &str,
    stride: Whole,
    project: bool,
    multipliers: bool,
    constraint_tolerance: Option<f64>,
    newton_tolerance: Option<f64>,
    max_iterations: Option<Whole>,
) -> PyResult<Result_> {
    let plan = plan(
        system,
        h,
        steps,
        time,
        method,
        base,
        stride,
        project,
        multipliers,
        constraint_tolerance,
        newton_tolerance,
        max_iterations,
    )?;
    let (z0, _) = real_array(z0, "z0", 1, 2 * system.dof(), Z)?;
    let z0 = rows(system, &z0, 1)?;
    let (d, m) = (system.dof(), system.constraint_count());
    let mut outs = py.detach(|| run_all(&system.model, base, &plan, &z0));
    let out = outs.pop().expect("one run");
    let arrays = Arrays::of(&out, d, m, plan.multipliers);
    match &out.error {
        Some(e) => Err(step_error(py, e, arrays)),
        None => Ok(arrays.into_py(py)),
    }
}

/// Runs every row of `z0s` (shape (k, 2d)) as `run` does, in parallel on
/// all cores with the GIL released. Returns one `Result` per row, or, with
/// `errors="return"`, a failed member's `ShakeError` in its place (the
/// default, `errors="raise"`, raises the first failure).
#[pyfunction]
#[pyo3(signature = (system, z0s, h, *, steps=None, time=None, method="rattle", base="midpoint",
    stride=Whole::Fits(1), project=true, multipliers=true, constraint_tolerance=None, newton_tolerance=None,
    max_iterations=None, errors="raise"))]
#[allow(clippy::too_many_arguments)]
fn ensemble(
    py: Python<'_>,
    system: &System,
    z0s: &Bound<'_, PyAny>,
    h: f64,
    steps: Option<Whole>,
    time: Option<f64>,
    method: &str,
    base: &str,
    stride: Whole,
    project: bool,
    multipliers: bool,
    constraint_tolerance: Option<f64>,
    newton_tolerance: Option<f64>,
    max_iterations: Option<Whole>,
    errors: &str,
) -> PyResult<Vec<Py<PyAny>>> {
    let plan = plan(
        system,
        h,
        steps,
        time,
        method,
        base,
        stride,
        project,
        multipliers,
        constraint_tolerance,
        newton_tolerance,
        max_iterations,
    )?;
    if !matches!(errors, "raise" | "return") {
        return Err(InvalidInputError::new_err(format!(
            "errors must be \"raise\" or \"return\", not {errors:?}"
        )));
    }
    let (flat, k) = real_array(z0s, "z0s", 2, 2 * system.dof(), Z)?;
    let z0s = rows(system, &flat, k)?;
    let (d, m) = (system.dof(), system.constraint_count());
    let outs = py.detach(|| run_all(&system.model, base, &plan, &z0s));
    let mut results = Vec::with_capacity(k);
    for out in &outs {
        let arrays = Arrays::of(out, d, m, plan.multipliers);
        match &out.error {
            Some(e) => {
                let err = step_error(py, e, arrays);
                if errors == "return" {
                    results.push(err.value(py).clone().into_any().unbind());
                } else {
                    return Err(err);
                }
            }
            None => results.push(Py::new(py, arrays.into_py(py))?.into_any()),
        }
    }
    Ok(results)
}

#[pymodule]
fn _geoshake(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<System>()?;
    m.add_class::<Result_>()?;
    m.add_class::<bonds::Bonds>()?;
    m.add_class::<particles::DeclaredParticles>()?;
    m.add_class::<particles::ParticleRattle>()?;
    m.add_class::<particles::ParticleRun>()?;
    m.add_class::<particles::ConstraintForces>()?;
    m.add_class::<thermostat::Langevin>()?;
    m.add_function(wrap_pyfunction!(declare, m)?)?;
    m.add_function(wrap_pyfunction!(particles::declare_particles, m)?)?;
    m.add_function(wrap_pyfunction!(model, m)?)?;
    m.add_function(wrap_pyfunction!(_rebuild_system, m)?)?;
    m.add_function(wrap_pyfunction!(_rebuild_result, m)?)?;
    m.add_function(wrap_pyfunction!(particles::_rebuild_particle_run, m)?)?;
    m.add_function(wrap_pyfunction!(particles::_rebuild_constraint_forces, m)?)?;
    m.add_function(wrap_pyfunction!(thermostat::_rebuild_langevin, m)?)?;
    m.add_function(wrap_pyfunction!(model_names, m)?)?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(ensemble, m)?)?;
    m.add_function(wrap_pyfunction!(sampler::sample, m)?)?;
    m.add_function(wrap_pyfunction!(sampler::ess_bulk, m)?)?;
    m.add_function(wrap_pyfunction!(sampler::rhat, m)?)?;
    m.add("ShakeError", py.get_type::<ShakeError>())?;
    m.add("DeclarationError", py.get_type::<DeclarationError>())?;
    m.add("ParameterError", py.get_type::<ParameterError>())?;
    m.add("InvalidInputError", py.get_type::<InvalidInputError>())?;
    m.add("NonFiniteError", py.get_type::<NonFiniteError>())?;
    m.add("NewtonError", py.get_type::<NewtonError>())?;
    m.add("NondegeneracyError", py.get_type::<NondegeneracyError>())?;
    m.add("ComponentJumpError", py.get_type::<ComponentJumpError>())?;
    m.add("FibreJumpError", py.get_type::<FibreJumpError>())?;
    m.add(
        "NotOnConstraintError",
        py.get_type::<NotOnConstraintError>(),
    )?;
    Ok(())
}
