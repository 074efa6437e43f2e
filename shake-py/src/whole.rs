//! Counts given from Python (steps, strides, chains, iteration budgets,
//! seeds): read as Python integers and checked against their range, so
//! that −1 or 2**70 is the package's error naming the argument, not the
//! `OverflowError` of a conversion to an unsigned Rust integer.
//!
//! An integer is what Python's `operator.index` takes: an `int`, or any
//! object with `__index__` (NumPy's `int64`, `uint32`, …, which a count
//! computed with NumPy is). A `bool` and a `float` are refused with a
//! `TypeError`, as `range(2.0)` is.

use pyo3::exceptions::PyTypeError;
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyFloat, PyInt};

use crate::InvalidInputError;

/// A Python integer argument as it came: one that fits in a u64, or the
/// text of one that does not. A float or a bool is refused as a TypeError.
pub(crate) enum Whole {
    Fits(u64),
    Outside(String),
}

impl<'py> FromPyObject<'_, 'py> for Whole {
    type Error = PyErr;

    fn extract(obj: Borrowed<'_, 'py, PyAny>) -> PyResult<Self> {
        let refused = || -> PyResult<PyErr> {
            Ok(PyTypeError::new_err(format!(
                "an integer is required, not {}",
                obj.get_type().name()?
            )))
        };
        if obj.is_instance_of::<PyBool>() || obj.is_instance_of::<PyFloat>() {
            return Err(refused()?);
        }
        // `operator.index(obj)`: the int itself, or what its type's
        // `__index__` gives (NumPy's integers); a type without one is not
        // an integer, and an exception `__index__` raises is passed on
        // (KeyboardInterrupt included), as operator.index passes it on.
        let int = if obj.is_instance_of::<PyInt>() {
            obj.to_owned()
        } else {
            let Ok(index) = obj.get_type().getattr(intern!(obj.py(), "__index__")) else {
                return Err(refused()?);
            };
            let i = index.call1((obj,))?;
            if !i.is_instance_of::<PyInt>() {
                return Err(PyTypeError::new_err(format!(
                    "__index__ returned non-int (type {})",
                    i.get_type().name()?
                )));
            }
            i
        };
        Ok(match int.extract::<u64>() {
            Ok(v) => Whole::Fits(v),
            Err(_) => Whole::Outside(int.str()?.to_string()),
        })
    }
}

impl Whole {
    /// The value, or `InvalidInputError` naming `what` when it is outside
    /// [lo, hi].
    pub(crate) fn within(self, what: &str, lo: u64, hi: u64) -> PyResult<u64> {
        let text = match self {
            Whole::Fits(v) if (lo..=hi).contains(&v) => return Ok(v),
            Whole::Fits(v) => v.to_string(),
            Whole::Outside(text) => text,
        };
        Err(InvalidInputError::new_err(format!(
            "invalid `{what}` = {text}: an integer from {lo} to {hi}"
        )))
    }

    /// `obj` read as a [`Whole`] within [lo, hi], with a wrong type also
    /// the package's `InvalidInputError` naming `what` (for the values
    /// whose documentation promises that error for anything invalid, as
    /// `Langevin`'s).
    pub(crate) fn read(obj: &Bound<'_, PyAny>, what: &str, lo: u64, hi: u64) -> PyResult<u64> {
        match obj.extract::<Whole>() {
            Ok(w) => w.within(what, lo, hi),
            Err(e) if e.is_instance_of::<PyTypeError>(obj.py()) => Err(InvalidInputError::new_err(
                format!("invalid `{what}`: {}", e.value(obj.py())),
            )),
            // (What `__index__` itself raised, KeyboardInterrupt included.)
            Err(e) => Err(e),
        }
    }

    /// A Newton iteration budget `what`: 1 to the runtime's
    /// [`MAX_ITERATIONS`](geoshake::validate::MAX_ITERATIONS).
    pub(crate) fn budget(self, what: &str) -> PyResult<usize> {
        let most = geoshake::validate::MAX_ITERATIONS as u64;
        Ok(self.within(what, 1, most)? as usize)
    }

    /// A particle run's number of steps: 0 to the runtime's
    /// [`MAX_STEPS`](geoshake::validate::MAX_STEPS), so that a run too
    /// long is refused here rather than returned empty with its error.
    pub(crate) fn steps(self) -> PyResult<u64> {
        self.within("steps", 0, geoshake::validate::MAX_STEPS)
            .map_err(|e| {
                Python::attach(|py| {
                    InvalidInputError::new_err(format!(
                        "{} = 2^53 (step indices beyond are not exact in f64)",
                        e.value(py)
                    ))
                })
            })
    }

    /// [`Whole::within`] as a `usize`.
    pub(crate) fn count(self, what: &str, lo: usize) -> PyResult<usize> {
        Ok(self.within(what, lo as u64, usize::MAX as u64)? as usize)
    }
}
