//! Forces the user brings from Python: a callable `forces(q) -> (V, F)` as
//! the particle path's `ForceField`, called with the interpreter attached
//! from inside a step that runs without it.
//!
//! A `ForceField` returns V(q) and has no error channel. When the callable
//! raises, or returns something that is not a pair (V, F) with F of shape
//! (n, D), its exception is kept on the calling thread (`take_raised`) and
//! the forces are NaN: the step's own finiteness check then stops it where
//! it stands, the trajectory so far kept, and the binding raises the
//! user's exception in place of the `NonFiniteError` the step reports.

use std::cell::RefCell;
use std::sync::Arc;

use geoshake::runtime::particles::ForceField;
use numpy::ndarray::Array2;
use numpy::IntoPyArray;
use pyo3::prelude::*;

use crate::{real_array, InvalidInputError};

thread_local! {
    /// The first exception of a forces callable on this thread since the
    /// last `take_raised`. Per thread: an ensemble's members run on
    /// several threads, each member's steps on one.
    static RAISED: RefCell<Option<PyErr>> = const { RefCell::new(None) };
    /// The solvers (by `PyForces::owner`) whose callable this thread is
    /// running, innermost last: a callable that calls back into the solver
    /// that called it would wait for itself.
    static CALLING: RefCell<Vec<usize>> = const { RefCell::new(Vec::new()) };
}

/// The exception a forces callable raised on this thread since the last
/// call, if any (and forgets it).
pub(crate) fn take_raised() -> Option<PyErr> {
    RAISED.with(|r| r.borrow_mut().take())
}

/// True when this thread is inside the forces callable of solver `owner`.
pub(crate) fn calling(owner: usize) -> bool {
    CALLING.with(|c| c.borrow().contains(&owner))
}

/// A Python callable `forces(q) -> (V, F)` as a `ForceField`: q is handed
/// over as a new float64 array of shape (n, D), F is read as one of the
/// same shape (anything `numpy.asarray` takes) and added to the forces, V
/// is returned.
///
/// `Clone` shares the callable: every copy of the solver (one per thread
/// of an ensemble) calls the same Python object, under the interpreter's
/// lock, so a callable whose result depends only on q gives every copy the
/// same steps.
#[derive(Clone)]
pub(crate) struct PyForces {
    callable: Arc<Py<PyAny>>,
    particles: usize,
    dim: usize,
    /// The solver this field belongs to (`ParticleRattle::id`).
    owner: usize,
}

impl PyForces {
    /// `callable` for n = `particles` particles in R^`dim`; refuses
    /// anything not callable.
    pub(crate) fn new(
        callable: &Bound<'_, PyAny>,
        particles: usize,
        dim: usize,
        owner: usize,
    ) -> PyResult<Self> {
        if !callable.is_callable() {
            return Err(InvalidInputError::new_err(format!(
                "forces must be a callable forces(q) -> (V, F), not {}",
                type_name(callable)
            )));
        }
        Ok(PyForces {
            callable: Arc::new(callable.clone().unbind()),
            particles,
            dim,
            owner,
        })
    }

    /// Calls the callable at q and adds its F into `f`: V, or the
    /// callable's exception, or an `InvalidInputError` saying what it
    /// returned instead of (V, F).
    fn call(&self, py: Python<'_>, q: &[f64], f: &mut [f64]) -> PyResult<f64> {
        let (n, d) = (self.particles, self.dim);
        let q = Array2::from_shape_vec((n, d), q.to_vec())
            .expect("q has n·D entries")
            .into_pyarray(py);
        let out = self.callable.bind(py).call1((q,))?;
        let pair = out.extract::<(Bound<'_, PyAny>, Bound<'_, PyAny>)>();
        let (v, forces) = pair.map_err(|_| {
            InvalidInputError::new_err(format!(
                "forces(q) must return a tuple (V, F): V a float, F of shape ({n}, {d}); \
                 it returned {}",
                type_name(&out)
            ))
        })?;
        let v: f64 = v.extract().map_err(|_| {
            InvalidInputError::new_err(format!(
                "forces(q) must return (V, F) with V a float, not {}",
                type_name(&v)
            ))
        })?;
        let name = "F of forces(q)";
        let (flat, rows) = real_array(&forces, name, 2, d, "a row per particle, D")?;
        if rows != n {
            return Err(InvalidInputError::new_err(format!(
                "{name} must have shape ({n}, {d}): a row per particle, not {rows} rows"
            )));
        }
        for (f, x) in f.iter_mut().zip(&flat) {
            *f += x;
        }
        Ok(v)
    }
}

impl ForceField for PyForces {
    fn forces(&mut self, q: &[f64], f: &mut [f64]) -> f64 {
        CALLING.with(|c| c.borrow_mut().push(self.owner));
        let result = Python::attach(|py| self.call(py, q, f));
        CALLING.with(|c| c.borrow_mut().pop());
        match result {
            Ok(v) => v,
            Err(e) => {
                RAISED.with(|r| {
                    r.borrow_mut().get_or_insert(e);
                });
                // NaN forces: the step's check of ∇V stops the step.
                f.fill(f64::NAN);
                f64::NAN
            }
        }
    }
}

/// The Python type name of `obj`, for messages.
pub(crate) fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map_or_else(|_| "an object".into(), |n| n.to_string())
}
