//! `geoshake.declare_particles`: particle systems declared from a string
//! (`geoshake::declared::DeclaredParticles`: `particles x[D];` with
//! families over run-time tables), run by the particle path's RATTLE or
//! SHAKE (`geoshake::runtime::particles::Rattle`) on NumPy arrays of shape
//! (n, D).

use std::sync::Mutex;

use geoshake::declared::{DeclaredParticles as Declared, FamilyKind};
use geoshake::runtime::particles::{Method, Options, ParticleState, Rattle, Table, TopologyError};
use geoshake::{RunOutcome, Stop};
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::bonds::{error, topology};
use crate::{declare_error, keyword_parameters, real_array, InvalidInputError};

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
    /// A table missing, unknown or of the wrong shape, an index that is not
    /// a particle's, a member repeated, a mass not finite and positive, an
    /// h or a tolerance out of range raise `InvalidInputError`.
    #[pyo3(signature = (masses, tables, h, *, method="rattle", tolerance=None, max_iterations=None))]
    #[allow(clippy::too_many_arguments)]
    fn system(
        &self,
        py: Python<'_>,
        masses: &Bound<'_, PyAny>,
        tables: &Bound<'_, PyDict>,
        h: f64,
        method: &str,
        tolerance: Option<f64>,
        max_iterations: Option<usize>,
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
        let masses = vector(masses, "masses")?;
        let rows = self.tables(tables)?;
        let system = self.declared.system(masses, rows).map_err(declare_error)?;
        let defaults = Options::default();
        let options = Options {
            tol: tolerance.unwrap_or(defaults.tol),
            max_iter: max_iterations.unwrap_or(defaults.max_iter),
            method,
            ..defaults
        };
        let (particles, dim, constraints) =
            (system.particles(), system.dim(), system.constraints());
        let rattle = Rattle::new(system, h, options).map_err(|e| error(py, &e))?;
        Ok(ParticleRattle {
            rattle: Mutex::new(rattle),
            particles,
            dim,
            constraints,
            h,
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
            InvalidInputError::new_err(format!(
                "{name} must be a 1-D array of real numbers: {}",
                e.value(obj.py())
            ))
        })?;
    if shape.len() != 1 {
        return Err(InvalidInputError::new_err(format!(
            "{name} must be a 1-D array (one per particle), not of shape {shape:?}"
        )));
    }
    Ok(real_array(obj, name, 1, shape[0], "one per particle, n")?.0)
}

/// RATTLE or SHAKE on a declared particle system, on positions and momenta
/// of shape (n, D) (NumPy arrays; copies are returned, the arguments are
/// left as they are). Errors are the package's (`NonFiniteError`,
/// `NewtonError` with `member`, the constraint at fault, ...).
#[pyclass(frozen, module = "geoshake")]
pub(crate) struct ParticleRattle {
    rattle: Mutex<Rattle>,
    particles: usize,
    dim: usize,
    constraints: usize,
    h: f64,
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
    /// None, or the `ShakeError` (a subclass) of the step that failed.
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
        let mut rattle = self.rattle.lock().unwrap_or_else(|e| e.into_inner());
        let r: &mut Rattle = &mut rattle;
        py.detach(|| r.project(&mut state))
            .map_err(|e| error(py, &e))?;
        Ok(self.pair(py, &state))
    }

    /// One step from (q, p): returns the new arrays (q, p), or raises the
    /// step's error.
    fn step<'py>(
        &self,
        py: Python<'py>,
        q: &Bound<'py, PyAny>,
        p: &Bound<'py, PyAny>,
    ) -> PyResult<Pair<'py>> {
        let mut state = self.state(q, p)?;
        let mut rattle = self.rattle.lock().unwrap_or_else(|e| e.into_inner());
        let r: &mut Rattle = &mut rattle;
        py.detach(|| r.step(&mut state))
            .map_err(|e| error(py, &e))?;
        Ok(self.pair(py, &state))
    }

    /// `steps` steps from (q, p) at time `t0`, keeping every `stride`-th
    /// state (the first and the last always). The start is taken as given:
    /// bring it onto M and M^H with `project` first. A step that fails does
    /// not raise: the run returns the frames before it and the error in
    /// `error`.
    #[pyo3(signature = (q, p, steps, *, stride=1, t0=0.0))]
    fn run(
        &self,
        py: Python<'_>,
        q: &Bound<'_, PyAny>,
        p: &Bound<'_, PyAny>,
        steps: u64,
        stride: u64,
        t0: f64,
    ) -> PyResult<ParticleRun> {
        let state = self.state(q, p)?.with_time(t0);
        let mut rattle = self.rattle.lock().unwrap_or_else(|e| e.into_inner());
        let r: &mut Rattle = &mut rattle;
        let out = py.detach(|| r.run(&state, Stop::Steps(steps)).stride(stride).execute());
        Ok(self.frames(py, &out))
    }

    /// The kinetic energy Σ_a |p_a|² / (2 m_a) of momenta of shape (n, D).
    fn kinetic_energy(&self, p: &Bound<'_, PyAny>) -> PyResult<f64> {
        let (p, _) = self.array(p, "p")?;
        let rattle = self.rattle.lock().unwrap_or_else(|e| e.into_inner());
        Ok(rattle.system().kinetic_energy(&p))
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
    #[getter]
    fn solver(&self) -> &'static str {
        self.rattle
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .solver_name()
    }

    fn __repr__(&self) -> String {
        format!(
            "<geoshake.ParticleRattle: {} particles in R^{}, {} constraints, h={}, solver {}>",
            self.particles,
            self.dim,
            self.constraints,
            self.h,
            self.solver()
        )
    }
}

impl ParticleRattle {
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

    /// The run's frames as arrays, and its error (if any) as the package's
    /// exception instance.
    fn frames(&self, py: Python<'_>, out: &RunOutcome) -> ParticleRun {
        let t = &out.trajectory;
        let n = t.len();
        let shape = (n, self.particles, self.dim);
        let (mut q, mut p) = (
            Vec::with_capacity(n * self.particles * self.dim),
            Vec::with_capacity(n * self.particles * self.dim),
        );
        for i in 0..n {
            q.extend_from_slice(t.q(i));
            p.extend_from_slice(t.p(i));
        }
        ParticleRun {
            q: Array3::from_shape_vec(shape, q)
                .expect("frames·n·D")
                .into_pyarray(py)
                .unbind(),
            p: Array3::from_shape_vec(shape, p)
                .expect("frames·n·D")
                .into_pyarray(py)
                .unbind(),
            time: Array1::from(t.times()).into_pyarray(py).unbind(),
            step: Array1::from(t.steps()).into_pyarray(py).unbind(),
            error: out
                .error
                .as_ref()
                .map(|e| error(py, e).value(py).clone().into_any().unbind()),
        }
    }
}
