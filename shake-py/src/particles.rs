//! `geoshake.declare_particles`: particle systems declared from a string
//! (`geoshake::declared::DeclaredParticles`: `particles x[D];` with
//! families over run-time tables), run by the particle path's RATTLE or
//! SHAKE (`geoshake::runtime::particles::Rattle`) on NumPy arrays of shape
//! (n, D).

use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard, TryLockError};

use geoshake::declared::{DeclaredParticles as Declared, FamilyKind};
use geoshake::runtime::particles::{
    ConstraintForces as Forces, Method, Options, ParticleState, Rattle, Table, TopologyError,
};
use geoshake::{RunOutcome, StepError, StepEvent, Stop};
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3};
use pyo3::exceptions::{PyException, PyMemoryError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::bonds::{error, topology};
use crate::forces::{self, type_name, PyForces};
use crate::thermostat::Langevin;
use crate::whole::Whole;
use crate::{
    declare_error, keyword_parameters, real_array, refused, watching, InvalidInputError,
    NonFiniteError,
};

/// Declares a particle system from a string in the grammar of
/// `constrained_system!` (a `struct` with `particles x[D];` and families
/// `name[k in table(a, b; data)]: template` over run-time tables), with
/// every parameter given by name.
///
/// The declaration goes through the macro's own front end and checks; a
/// refusal raises `DeclarationError` with the macro's message and its line
/// and column in the string.
#[pyfunction]
#[pyo3(signature = (source, **parameters))]
pub(crate) fn declare_particles(
    source: &str,
    parameters: Option<&Bound<'_, PyDict>>,
) -> PyResult<DeclaredParticles> {
    let given = keyword_parameters(parameters)?;
    let refs: Vec<(&str, f64)> = given.iter().map(|(k, v)| (k.as_str(), *v)).collect();
    let declared = Declared::new(source, &refs).map_err(declare_error)?;
    Ok(DeclaredParticles { declared })
}

/// A particle system declared from a string: its families and the tables
/// they read, waiting for the masses and the tables' rows.
#[pyclass(frozen, module = "geoshake")]
pub(crate) struct DeclaredParticles {
    declared: Declared,
}

#[pymethods]
impl DeclaredParticles {
    /// The declared struct name.
    #[getter]
    fn name(&self) -> &str {
        self.declared.name()
    }

    /// D, the dimension of each particle's position.
    #[getter]
    fn dim(&self) -> usize {
        self.declared.dim()
    }

    /// The parameters, by name.
    #[getter]
    fn parameters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in self
            .declared
            .parameter_names()
            .iter()
            .zip(self.declared.parameters())
        {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    /// The families in declaration order, each a dict: `name`, `kind`
    /// ("constraint" or "potential"), `table` (the name `system` takes its
    /// rows under), `arity` (particle indices per row) and `data` (numbers
    /// per row).
    #[getter]
    fn families<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.declared
            .families()
            .iter()
            .map(|f| {
                let d = PyDict::new(py);
                d.set_item("name", &f.name)?;
                let kind = match f.kind {
                    FamilyKind::Constraint => "constraint",
                    FamilyKind::Potential => "potential",
                };
                d.set_item("kind", kind)?;
                d.set_item("table", &f.table)?;
                d.set_item("arity", f.arity)?;
                d.set_item("data", f.data)?;
                Ok(d)
            })
            .collect()
    }

    /// The system of n = len(`masses`) particles with `tables`, a dict
    /// {table name: rows}, one entry per family: each row holds the
    /// family's particle indices (whole numbers, 0-based) then its numbers,
    /// an array of shape (k, arity + data). Returns its integrator with step
    /// size `h`: `method` "rattle" or "shake", `tolerance` every
    /// constraint's relative residual at the end of a step (default 1e-12,
    /// in [4ε, 1)), `max_iterations` Newton's budget per step (default 50).
    ///
    /// `forces`, a callable `forces(q) -> (V, F)` with q and F of shape
    /// (n, D) and V a float, adds an external potential V_ext(q) with its
    /// forces F = −∇V_ext(q) to the declared potential families:
    /// H = Σ |p_a|²/(2 m_a) + Σ_fam V_fam + V_ext. It is called once per
    /// step (at the step's new positions) and once when a run starts.
    ///
    /// `thermostat`, a `geoshake.Langevin`, makes every step a g-BAOAB
    /// Langevin step at its k_B T (RATTLE only).
    ///
    /// A table missing, unknown or of the wrong shape, an index that is not
    /// a particle's, a member repeated, a mass not finite and positive, an
    /// h or a tolerance out of range, `forces` not callable, `thermostat`
    /// not a `Langevin` or given to SHAKE raise `InvalidInputError`.
    #[pyo3(signature = (masses, tables, h, *, method="rattle", tolerance=None, max_iterations=None,
        forces=None, thermostat=None))]
    #[allow(clippy::too_many_arguments)]
    fn system(
        &self,
        py: Python<'_>,
        masses: &Bound<'_, PyAny>,
        tables: &Bound<'_, PyDict>,
        h: f64,
        method: &str,
        tolerance: Option<f64>,
        max_iterations: Option<Whole>,
        forces: Option<&Bound<'_, PyAny>>,
        thermostat: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<ParticleRattle> {
        let method = match method {
            "rattle" => Method::Rattle,
            "shake" => Method::Shake,
            _ => {
                return Err(InvalidInputError::new_err(format!(
                    "method must be \"rattle\" or \"shake\", not {method:?}"
                )))
            }
        };
        let thermostat = match thermostat {
            None => None,
            Some(t) => Some(
                t.cast::<Langevin>()
                    .map_err(|_| {
                        InvalidInputError::new_err(format!(
                            "thermostat must be a geoshake.Langevin or None, not {}",
                            type_name(t)
                        ))
                    })?
                    .get()
                    .clone(),
            ),
        };
        let masses = vector(masses, "masses")?;
        let rows = self.tables(tables)?;
        let system = self.declared.system(masses, rows).map_err(declare_error)?;
        let id = NEXT_ID.fetch_add(1, Ordering::Relaxed);
        let system = match forces {
            None => system,
            Some(f) => {
                let field = PyForces::new(f, system.particles(), system.dim(), id)?;
                system.with_forces(field)
            }
        };
        let defaults = Options::default();
        let options = Options {
            tol: tolerance.unwrap_or(defaults.tol),
            max_iter: match max_iterations {
                Some(n) => n.budget("max_iterations")?,
                None => defaults.max_iter,
            },
            method,
            ..defaults
        };
        let (particles, dim, constraints) =
            (system.particles(), system.dim(), system.constraints());
        let mut rattle = Rattle::new(system, h, options).map_err(|e| error(py, &e))?;
        rattle
            .set_thermostat(thermostat.as_ref().map(|t| t.inner))
            .map_err(|e| error(py, &e))?;
        Ok(ParticleRattle {
            solver: Mutex::new(Solver { rattle, last: None }),
            id,
            particles,
            dim,
            constraints,
            h,
            thermostat,
        })
    }

    fn __repr__(&self) -> String {
        let tables: Vec<&str> = self
            .declared
            .families()
            .iter()
            .map(|f| f.table.as_str())
            .collect();
        format!(
            "<geoshake.DeclaredParticles {} (R^{}, tables: {})>",
            self.declared.name(),
            self.declared.dim(),
            tables.join(", ")
        )
    }
}

impl DeclaredParticles {
    /// One `Table` per family, in declaration order, from the dict.
    fn tables(&self, given: &Bound<'_, PyDict>) -> PyResult<Vec<Table>> {
        let families = self.declared.families();
        let names: Vec<&str> = families.iter().map(|f| f.table.as_str()).collect();
        for key in given.keys() {
            let key: String = key.extract()?;
            if !names.contains(&key.as_str()) {
                return Err(InvalidInputError::new_err(format!(
                    "no table `{key}` in {}; its tables are: {}",
                    self.declared.name(),
                    names.join(", ")
                )));
            }
        }
        let mut out = Vec::with_capacity(families.len());
        for f in families {
            let rows = given.get_item(&f.table)?.ok_or_else(|| {
                InvalidInputError::new_err(format!(
                    "table `{}` (of family `{}`) is not given",
                    f.table, f.name
                ))
            })?;
            let width = f.arity + f.data;
            let what = format!("{} particle indices then {} numbers", f.arity, f.data);
            let (flat, k) = real_array(&rows, &f.table, 2, width, &what)?;
            let mut table = Table::with_capacity(f.arity, f.data, k);
            let mut particles = vec![0usize; f.arity];
            for (r, row) in flat.chunks(width.max(1)).take(k).enumerate() {
                for (i, &x) in particles.iter_mut().zip(&row[..f.arity]) {
                    // (Exact for every index below 2⁵³; indices are u32.)
                    if !(x >= 0.0 && x.fract() == 0.0 && x <= u32::MAX as f64) {
                        return Err(InvalidInputError::new_err(format!(
                            "table `{}`, row {r}: particle index {x} is not a whole number \
                             in 0..2³²",
                            f.table
                        )));
                    }
                    *i = x as usize;
                }
                table
                    .push(&particles, &row[f.arity..])
                    .map_err(|e| topology(of_family(e, &f.name)))?;
            }
            out.push(table);
        }
        Ok(out)
    }
}

/// A row's refusal by `Table::push` (which does not know its family) with
/// the family named, as the runtime's own refusals of a system name it.
fn of_family(mut e: TopologyError, name: &str) -> TopologyError {
    match &mut e {
        TopologyError::RowShape { family, .. }
        | TopologyError::RepeatedParticle { family, .. }
        | TopologyError::DanglingParticle { family, .. }
        | TopologyError::BadValue { family, .. } => *family = name.to_string(),
        _ => {}
    }
    e
}

/// A 1-D array of real numbers of any length.
fn vector(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<f64>> {
    let np = obj.py().import("numpy")?;
    let shape: Vec<usize> = np
        .call_method1("shape", (obj,))
        .and_then(|s| s.extract())
        .map_err(|e| {
            refused(obj.py(), e, |e| {
                format!(
                    "{name} must be a 1-D array of real numbers: {}",
                    e.value(obj.py())
                )
            })
        })?;
    if shape.len() != 1 {
        return Err(InvalidInputError::new_err(format!(
            "{name} must be a 1-D array (one per particle), not of shape {shape:?}"
        )));
    }
    Ok(real_array(obj, name, 1, shape[0], "one per particle, n")?.0)
}

/// The source of `ParticleRattle::id`.
static NEXT_ID: AtomicUsize = AtomicUsize::new(1);

/// RATTLE or SHAKE on a declared particle system, on positions and momenta
/// of shape (n, D) (NumPy arrays; copies are returned, the arguments are
/// left as they are). Errors are the package's (`NonFiniteError`,
/// `NewtonError` with `member`, the constraint at fault, ...); an
/// exception of the forces callable is raised as it was raised.
#[pyclass(frozen, module = "geoshake")]
pub(crate) struct ParticleRattle {
    solver: Mutex<Solver>,
    /// Tells this solver's forces callable apart from others' (a callable
    /// may run another system, not the one that called it).
    id: usize,
    particles: usize,
    dim: usize,
    constraints: usize,
    h: f64,
    thermostat: Option<Langevin>,
}

/// The solver and the last state its `step` made: given back to `step`,
/// that state goes on with its step count (the thermostat's noise is a
/// function of it) and its caches (the forces at q, the multipliers the
/// constraint forces are read from), which arrays from Python do not carry.
struct Solver {
    rattle: Rattle,
    last: Option<ParticleState>,
}

/// True when `a` and `b` hold the same numbers, bit for bit.
fn same(a: &ParticleState, b: &ParticleState) -> bool {
    let bits = |x: &[f64], y: &[f64]| x.iter().zip(y).all(|(x, y)| x.to_bits() == y.to_bits());
    bits(a.q(), b.q()) && bits(a.p(), b.p())
}

/// The arguments of `run` and `ensemble` that no state can make right,
/// refused before any work: a run of them would be an empty run carrying
/// an error that a caller who does not look at `error` never sees.
fn run_arguments(steps: Whole, stride: Whole, t0: f64) -> PyResult<(u64, u64)> {
    let steps = steps.steps()?;
    let stride = stride.within("stride", 0, u64::MAX)?;
    if stride == 0 {
        return Err(InvalidInputError::new_err(
            "stride must be at least 1 (1 keeps every frame), not 0",
        ));
    }
    if !t0.is_finite() {
        return Err(InvalidInputError::new_err(format!(
            "t0 must be finite, not {t0}"
        )));
    }
    Ok((steps, stride))
}

/// The exception for an error `e` of a step or a run on this thread: the
/// forces callable's own if it raised (the step's `NonFiniteError` only
/// followed from it; a note on the exception names the step), else the
/// package's.
fn failure(py: Python<'_>, e: &StepError) -> PyErr {
    match forces::take_raised() {
        Some(raised) => noted(py, raised, e),
        None => error(py, e),
    }
}

/// The exception of a step's error `e` on another thread, which `raised`
/// there: the forces callable's own, else the package's.
fn raised_or(py: Python<'_>, raised: Option<PyErr>, e: &StepError) -> PyErr {
    match raised {
        Some(raised) => noted(py, raised, e),
        None => error(py, e),
    }
}

/// A run's `on_step`: stop when `halt` is set (Ctrl-C, seen by
/// [`watching`]).
fn halted(halt: &AtomicBool) -> ControlFlow<()> {
    if halt.load(Ordering::Relaxed) {
        ControlFlow::Break(())
    } else {
        ControlFlow::Continue(())
    }
}

fn panicked() -> PyErr {
    InvalidInputError::new_err("the run's thread panicked")
}

/// A run's error, to keep in its `ParticleRun`; raised instead when it is
/// not an `Exception` (a `KeyboardInterrupt` or `SystemExit` the forces
/// callable let through: the user asked to stop, not the run to fail).
fn interrupted(py: Python<'_>, error: Option<PyErr>) -> PyResult<Option<PyErr>> {
    match error {
        Some(e) if !e.is_instance_of::<PyException>(py) => Err(e),
        error => Ok(error),
    }
}

/// The forces callable's exception, with a note (Python ≥ 3.11) of the
/// step it stopped.
fn noted(py: Python<'_>, raised: PyErr, e: &StepError) -> PyErr {
    let note = format!(
        "raised by the forces callable in step {} (t = {})",
        e.step(),
        e.time().unwrap_or(f64::NAN)
    );
    let _ = raised.value(py).call_method1("add_note", (note,));
    raised
}

/// A particle run: frames of shape (frames, n, D), their times and steps,
/// and `error`, None or the exception that ended the run early (the frames
/// before it are kept).
#[pyclass(frozen, module = "geoshake")]
pub(crate) struct ParticleRun {
    /// Positions, shape (frames, n, D).
    #[pyo3(get)]
    q: Py<PyArray3<f64>>,
    /// Momenta, shape (frames, n, D).
    #[pyo3(get)]
    p: Py<PyArray3<f64>>,
    /// Times, shape (frames,).
    #[pyo3(get)]
    time: Py<PyArray1<f64>>,
    /// Step indices, shape (frames,).
    #[pyo3(get)]
    step: Py<PyArray1<u64>>,
    /// None, or the `ShakeError` (a subclass) of the step that failed, or
    /// the exception the forces callable raised in it.
    #[pyo3(get)]
    error: Option<Py<PyAny>>,
}

#[pymethods]
impl ParticleRun {
    fn __len__(&self, py: Python<'_>) -> usize {
        self.time.bind(py).len().unwrap_or(0)
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let how = match &self.error {
            None => "complete".to_string(),
            Some(e) => format!(
                "stopped by {}",
                e.bind(py)
                    .get_type()
                    .name()
                    .map_or_else(|_| "an error".into(), |n| n.to_string())
            ),
        };
        format!("<geoshake.ParticleRun: {} frames, {how}>", self.__len__(py))
    }

    /// Pickling: the arrays and the error, as they are.
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let fields = (&self.q, &self.p, &self.time, &self.step, &self.error);
        crate::reduce(py, "_rebuild_particle_run", fields)
    }
}

/// The inverse of `ParticleRun.__reduce__`.
#[pyfunction]
pub(crate) fn _rebuild_particle_run(
    q: Py<PyArray3<f64>>,
    p: Py<PyArray3<f64>>,
    time: Py<PyArray1<f64>>,
    step: Py<PyArray1<u64>>,
    error: Option<Py<PyAny>>,
) -> ParticleRun {
    ParticleRun {
        q,
        p,
        time,
        step,
        error,
    }
}

/// The constraint forces of one step, their multipliers and their virial
/// (`ParticleRattle.constraint_forces`).
///
/// The position stage of the step from q0 moves the unconstrained update by
/// the constraint forces f_c = −Σ_k Λ_k ∇g_k(q0), acting at the start of
/// the step (q0, at time t − h), so that
/// q1 = q0 + h M⁻¹ p0 + (h²/2) M⁻¹ (F(q0) + f_c) with F = −∇V. The virial
/// is W = Σ_a x_a ⊗ f_{c,a} at x = q0 (W / volume is the constraints' part
/// of the pressure tensor, as LAMMPS' `fix shake` reports it). For a
/// distance family g_k = |x_a − x_b|² − l_k², the bond's tension is
/// 2 Λ_k l_k (positive when it pulls the two particles together) and
/// tr W = −Σ_k 2 Λ_k l_k².
#[pyclass(frozen, module = "geoshake")]
pub(crate) struct ConstraintForces {
    /// f_c, shape (n, D).
    #[pyo3(get)]
    forces: Py<PyArray2<f64>>,
    /// W = Σ_a x_a ⊗ f_{c,a}, shape (D, D): `virial[r, c]` = Σ_a x_{a,r} f_{c,a,c}.
    #[pyo3(get)]
    virial: Py<PyArray2<f64>>,
    /// Λ_k of every constraint, shape (m,): families in declaration order,
    /// each family's members in the order of its table.
    #[pyo3(get)]
    multipliers: Py<PyArray1<f64>>,
    /// The time of q0, where the forces act: the state's time − h.
    #[pyo3(get)]
    time: f64,
}

#[pymethods]
impl ConstraintForces {
    fn __repr__(&self) -> String {
        format!("<geoshake.ConstraintForces at t = {}>", self.time)
    }

    /// Pickling: the arrays and the time, as they are.
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let fields = (&self.forces, &self.virial, &self.multipliers, self.time);
        crate::reduce(py, "_rebuild_constraint_forces", fields)
    }
}

/// The inverse of `ConstraintForces.__reduce__`.
#[pyfunction]
pub(crate) fn _rebuild_constraint_forces(
    forces: Py<PyArray2<f64>>,
    virial: Py<PyArray2<f64>>,
    multipliers: Py<PyArray1<f64>>,
    time: f64,
) -> ConstraintForces {
    ConstraintForces {
        forces,
        virial,
        multipliers,
        time,
    }
}

/// Positions and momenta, each of shape (n, D).
type Pair<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>);

#[pymethods]
impl ParticleRattle {
    /// Brings (q, p) onto M (every constraint holds) and then onto M^H
    /// (momenta tangent to the constraints): returns new arrays (q, p).
    fn project<'py>(
        &self,
        py: Python<'py>,
        q: &Bound<'py, PyAny>,
        p: &Bound<'py, PyAny>,
    ) -> PyResult<Pair<'py>> {
        let mut state = self.state(q, p)?;
        let mut solver = self.solver(py)?;
        let r = &mut solver.rattle;
        forces::take_raised();
        py.detach(|| r.project(&mut state))
            .map_err(|e| failure(py, &e))?;
        Ok(self.pair(py, &state))
    }

    /// One step from (q, p): returns the new arrays (q, p), or raises the
    /// step's error (the forces callable's own exception if it raised).
    ///
    /// The step count goes on from call to call (with a thermostat, the
    /// noise of step k is a function of the seed and k, so no step's noise
    /// is drawn twice, whatever arrays each call is given: positions
    /// wrapped into a box, or a retry after a failed step, which counts
    /// as not taken). Given back the arrays its last call returned (the
    /// same numbers), a step also reuses the forces already computed
    /// there, and `constraint_forces` answers for the step that made them.
    fn step<'py>(
        &self,
        py: Python<'py>,
        q: &Bound<'py, PyAny>,
        p: &Bound<'py, PyAny>,
    ) -> PyResult<Pair<'py>> {
        let given = self.state(q, p)?;
        let mut solver = self.solver(py)?;
        let Solver { rattle, last } = &mut *solver;
        let mut state = match last.take() {
            Some(s) if same(&s, &given) => s,
            // Other numbers (positions wrapped into a box, another
            // replica): a new state for the caches, but the step count
            // goes on, so that a thermostat never draws one step's noise
            // twice.
            Some(mut s) => {
                s.q_mut().copy_from_slice(given.q());
                s.p_mut().copy_from_slice(given.p());
                s
            }
            None => given,
        };
        forces::take_raised();
        let taken = py.detach(|| rattle.step(&mut state));
        // A failed step leaves the state as it was: kept, count and all,
        // for a retry.
        let out = taken.map(|_| self.pair(py, &state));
        *last = Some(state);
        out.map_err(|e| failure(py, &e))
    }

    /// `steps` steps from (q, p) at time `t0`, keeping every `stride`-th
    /// state (the first and the last always). The start is taken as given:
    /// bring it onto M and M^H with `project` first. A step that fails does
    /// not raise: the run returns the frames before it and the error in
    /// `error` (the forces callable's own exception if it raised).
    ///
    /// With a thermostat, the noise of step k of a run is a function of
    /// the seed and k (counted from the run's start): a run continued from
    /// another's last frame needs another seed (`Langevin.member`) not to
    /// repeat the first run's noise.
    #[pyo3(signature = (q, p, steps, *, stride=Whole::Fits(1), t0=0.0))]
    fn run(
        &self,
        py: Python<'_>,
        q: &Bound<'_, PyAny>,
        p: &Bound<'_, PyAny>,
        steps: Whole,
        stride: Whole,
        t0: f64,
    ) -> PyResult<ParticleRun> {
        let (steps, stride) = run_arguments(steps, stride, t0)?;
        let state = self.state(q, p)?.with_time(t0);
        let mut solver = self.solver(py)?;
        let r = &mut solver.rattle;
        let halt = AtomicBool::new(false);
        let (taken, interrupt) = watching(py, &halt, || {
            forces::take_raised();
            let mut look = |_: &StepEvent| halted(&halt);
            let run = r.run(&state, Stop::Steps(steps)).stride(stride);
            let out = run.on_step(&mut look).execute();
            (out, forces::take_raised())
        });
        let (out, raised) = taken.map_err(|_| panicked())?;
        if let Some(e) = interrupt {
            return Err(self.with_frames(py, e, out)?);
        }
        let error = out.error.as_ref().map(|e| raised_or(py, raised, e));
        match interrupted(py, error)? {
            Some(e) if matches!(out.error, Some(StepError::Storage { .. })) => Err(e),
            error => self.frames(py, out, error),
        }
    }

    /// Runs every member (qs[i], ps[i]) as `run` does, in parallel on all
    /// cores with the interpreter released; qs and ps have shape
    /// (members, n, D). Returns one `ParticleRun` per member, in order:
    /// member i is bit for bit the `run` of (qs[i], ps[i]), whatever the
    /// number of threads, and a member that fails keeps its frames up to
    /// the failure and its `error` while the others run on.
    ///
    /// With a thermostat, member i has its own noise: it runs with
    /// `thermostat.member(i)` (member 0 with the thermostat itself). A
    /// forces callable is called from several threads, one call at a time
    /// (under the interpreter's lock).
    #[pyo3(signature = (qs, ps, steps, *, stride=Whole::Fits(1), t0=0.0))]
    fn ensemble(
        &self,
        py: Python<'_>,
        qs: &Bound<'_, PyAny>,
        ps: &Bound<'_, PyAny>,
        steps: Whole,
        stride: Whole,
        t0: f64,
    ) -> PyResult<Vec<ParticleRun>> {
        let (steps, stride) = run_arguments(steps, stride, t0)?;
        let qs = self.members(qs, "qs")?;
        let ps = self.members(ps, "ps")?;
        if qs.len() != ps.len() {
            return Err(InvalidInputError::new_err(format!(
                "qs and ps must have the same number of members, not {} and {}",
                qs.len(),
                ps.len()
            )));
        }
        let starts: Vec<ParticleState> = qs
            .into_iter()
            .zip(ps)
            .map(|(q, p)| ParticleState::new(q, p).with_time(t0))
            .collect();
        let solver = self.solver(py)?;
        let template = &solver.rattle;
        let thermostat = self.thermostat.as_ref();
        let halt = AtomicBool::new(false);
        let (outs, interrupt) = watching(py, &halt, || {
            geoshake::ensemble(template, &starts, |copy, i, start| {
                forces::take_raised();
                let member = thermostat.map(|t| t.for_member(i as u64).inner);
                let mut look = |_: &StepEvent| halted(&halt);
                let out = match copy.set_thermostat(member) {
                    Ok(()) => {
                        let run = copy.member_run(start, Stop::Steps(steps)).stride(stride);
                        run.on_step(&mut look).execute()
                    }
                    Err(e) => RunOutcome {
                        trajectory: Default::default(),
                        summary: Default::default(),
                        error: Some(e),
                    },
                };
                (out, forces::take_raised())
            })
        });
        let outs = outs.map_err(|_| panicked())?;
        if let Some(e) = interrupt {
            let runs: Vec<ParticleRun> = outs
                .into_iter()
                .map(|(out, _)| self.frames(py, out, None))
                .collect::<PyResult<_>>()?;
            let _ = e.value(py).setattr("runs", runs);
            return Err(e);
        }
        // Every member stores as many frames: one that does not fit is
        // the arguments' fault, not a member's.
        let storage = outs.iter().find_map(|(o, _)| {
            o.error
                .as_ref()
                .filter(|e| matches!(e, StepError::Storage { .. }))
        });
        if let Some(e) = storage {
            return Err(error(py, e));
        }
        outs.into_iter()
            .map(|(out, raised)| {
                let error = out.error.as_ref().map(|e| raised_or(py, raised, e));
                self.frames(py, out, interrupted(py, error)?)
            })
            .collect()
    }

    /// The kinetic energy Σ_a |p_a|² / (2 m_a) of momenta of shape (n, D).
    fn kinetic_energy(&self, py: Python<'_>, p: &Bound<'_, PyAny>) -> PyResult<f64> {
        let (p, _) = self.array(p, "p")?;
        let solver = self.solver(py)?;
        let t = solver.rattle.system().kinetic_energy(&p);
        if !t.is_finite() {
            return Err(NonFiniteError::new_err(format!(
                "the kinetic energy of p is {t}: p holds a number that is not finite, or \
                 momenta whose squares overflow"
            )));
        }
        Ok(t)
    }

    /// The potential energy V(q) = Σ_fam V_fam(q) + V_ext(q) of positions
    /// of shape (n, D): the declared potential families and the forces
    /// callable's V (0 without either). Raises the callable's exception if
    /// it raises, `NonFiniteError` for forces or a V not finite.
    fn potential_energy(&self, py: Python<'_>, q: &Bound<'_, PyAny>) -> PyResult<f64> {
        let (q, _) = self.array(q, "q")?;
        if let Some(x) = q.iter().find(|x| !x.is_finite()) {
            return Err(NonFiniteError::new_err(format!(
                "q must be finite, not {x}"
            )));
        }
        let state = ParticleState::new(q, vec![0.0; self.particles * self.dim]);
        let mut solver = self.solver(py)?;
        let r = &mut solver.rattle;
        forces::take_raised();
        py.detach(|| r.potential_energy(&state))
            .map_err(|e| failure(py, &e))
    }

    /// The constraint forces, their multipliers and their virial
    /// (`ConstraintForces`) of the RATTLE or SHAKE step that made (q, p):
    /// (q, p) must be what the last `step` returned (the multipliers are
    /// that step's; none is solved for). Raises `InvalidInputError` for
    /// any other state (initial data, a projection, a run's frame, a
    /// thermostatted step: a g-BAOAB step spreads the constraint forces
    /// over its drifts and has no single f_c at q0).
    fn constraint_forces(
        &self,
        py: Python<'_>,
        q: &Bound<'_, PyAny>,
        p: &Bound<'_, PyAny>,
    ) -> PyResult<ConstraintForces> {
        let given = self.state(q, p)?;
        let solver = self.solver(py)?;
        let state = match &solver.last {
            Some(s) if same(s, &given) => s,
            _ => &given,
        };
        let mut fc = Forces::new(solver.rattle.system());
        solver
            .rattle
            .constraint_forces(state, &mut fc)
            .map_err(|e| error(py, &e))?;
        let d = self.dim;
        Ok(ConstraintForces {
            forces: Array2::from_shape_vec((self.particles, d), fc.forces)
                .expect("n·D forces")
                .into_pyarray(py)
                .unbind(),
            virial: Array2::from_shape_vec((d, d), fc.virial)
                .expect("D·D virial")
                .into_pyarray(py)
                .unbind(),
            multipliers: Array1::from(fc.multipliers).into_pyarray(py).unbind(),
            time: fc.time,
        })
    }

    /// The thermostat (a `geoshake.Langevin`), or None.
    #[getter]
    fn thermostat(&self) -> Option<Langevin> {
        self.thermostat.clone()
    }

    /// n, the number of particles.
    #[getter]
    fn particles(&self) -> usize {
        self.particles
    }

    /// D, each particle's dimension.
    #[getter]
    fn dim(&self) -> usize {
        self.dim
    }

    /// m, the number of constraints (every family's members).
    #[getter]
    fn constraints(&self) -> usize {
        self.constraints
    }

    /// The step size.
    #[getter]
    fn h(&self) -> f64 {
        self.h
    }

    /// "clusters", "band" or "sparse": the solver chosen for the
    /// constraints' graph.
    #[getter(solver)]
    fn solver_name(&self, py: Python<'_>) -> PyResult<&'static str> {
        Ok(self.solver(py)?.rattle.solver_name())
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        Ok(format!(
            "<geoshake.ParticleRattle: {} particles in R^{}, {} constraints, h={}, solver {}>",
            self.particles,
            self.dim,
            self.constraints,
            self.h,
            self.solver_name(py)?
        ))
    }
}

impl ParticleRattle {
    /// The solver, waiting for another thread's call to end; refused to a
    /// call from this solver's own forces callable, which the call that
    /// holds the solver is waiting for.
    fn solver(&self, py: Python<'_>) -> PyResult<MutexGuard<'_, Solver>> {
        loop {
            match self.solver.try_lock() {
                Ok(s) => return Ok(s),
                Err(TryLockError::Poisoned(s)) => return Ok(s.into_inner()),
                Err(TryLockError::WouldBlock) => {
                    if forces::calling(self.id) {
                        return Err(InvalidInputError::new_err(
                            "the forces callable of this ParticleRattle cannot use it: the step \
                             that called the callable holds it (declare a second system for the \
                             callable to use)",
                        ));
                    }
                    // (Without the interpreter: the holder may be waiting
                    // for it to call its forces callable. A short sleep,
                    // not a spin: the holder may run for minutes.)
                    py.detach(|| std::thread::sleep(std::time::Duration::from_micros(200)));
                }
            }
        }
    }

    /// An (n, D) array, flattened particle by particle.
    fn array(&self, obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<f64>, usize)> {
        let (flat, rows) = real_array(obj, name, 2, self.dim, "a row per particle, D")?;
        if rows != self.particles {
            return Err(InvalidInputError::new_err(format!(
                "{name} must have shape ({}, {}): a row per particle, not {rows} rows",
                self.particles, self.dim
            )));
        }
        Ok((flat, rows))
    }

    /// A (members, n, D) array, one flat (n·D) vector per member: read
    /// once (by `real_array`), so that an object whose `__array__` answers
    /// differently on a second call cannot give the shape of one answer
    /// and the numbers of another.
    fn members(&self, obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<Vec<f64>>> {
        let (n, d) = (self.particles, self.dim);
        let (flat, members) = real_array(obj, name, 3, d, "D")?;
        let size = n * d;
        if flat.len() != members * size {
            return Err(InvalidInputError::new_err(format!(
                "{name} must have shape (members, {n}, {d}): a state of n = {n} particles in \
                 R^{d} per member, not ({members}, {}, {d})",
                flat.len() / (members * d).max(1)
            )));
        }
        if size == 0 {
            return Ok(vec![Vec::new(); members]);
        }
        Ok(flat.chunks_exact(size).map(<[f64]>::to_vec).collect())
    }

    fn state(&self, q: &Bound<'_, PyAny>, p: &Bound<'_, PyAny>) -> PyResult<ParticleState> {
        Ok(ParticleState::new(
            self.array(q, "q")?.0,
            self.array(p, "p")?.0,
        ))
    }

    fn pair<'py>(&self, py: Python<'py>, state: &ParticleState) -> Pair<'py> {
        let shape = (self.particles, self.dim);
        let q = Array2::from_shape_vec(shape, state.q().to_vec()).expect("n·D positions");
        let p = Array2::from_shape_vec(shape, state.p().to_vec()).expect("n·D momenta");
        (q.into_pyarray(py), p.into_pyarray(py))
    }

    /// `interrupt` (Ctrl-C during a run) with the run's frames up to it
    /// as its attribute `run`: stopped on request, nothing computed is
    /// lost.
    fn with_frames(&self, py: Python<'_>, interrupt: PyErr, out: RunOutcome) -> PyResult<PyErr> {
        let run = self.frames(py, out, None)?;
        let _ = interrupt.value(py).setattr("run", run);
        Ok(interrupt)
    }

    /// The run's frames as arrays, with `error`, the exception of its
    /// error (if any).
    ///
    /// The trajectory holds each frame's q then p; the arrays want all q,
    /// then all p. The p are copied out and the q packed in place, so a
    /// long run needs 1.5 times its frames at once, not twice, and a copy
    /// that does not fit raises `MemoryError` instead of aborting.
    fn frames(
        &self,
        py: Python<'_>,
        out: RunOutcome,
        error: Option<PyErr>,
    ) -> PyResult<ParticleRun> {
        let t = out.trajectory;
        let n = t.len();
        let (time, step) = (t.times(), t.steps());
        let size = self.particles * self.dim;
        let mut q = t.into_states();
        let mut p = Vec::new();
        if p.try_reserve_exact(n * size).is_err() {
            return Err(PyMemoryError::new_err(format!(
                "the run's {n} frames were computed, but their momenta ({} bytes) do not fit \
                 beside them in memory: keep fewer frames (a larger stride)",
                8 * n * size
            )));
        }
        for i in 0..n {
            p.extend_from_slice(&q[(2 * i + 1) * size..(2 * i + 2) * size]);
        }
        for i in 1..n {
            q.copy_within(2 * i * size..(2 * i + 1) * size, i * size);
        }
        q.truncate(n * size);
        q.shrink_to_fit();
        let shape = (n, self.particles, self.dim);
        let array = |v: Vec<f64>| {
            Array3::from_shape_vec(shape, v)
                .expect("frames·n·D")
                .into_pyarray(py)
                .unbind()
        };
        Ok(ParticleRun {
            q: array(q),
            p: array(p),
            time: Array1::from(time).into_pyarray(py).unbind(),
            step: Array1::from(step).into_pyarray(py).unbind(),
            error: error.map(|e| e.value(py).clone().into_any().unbind()),
        })
    }
}
