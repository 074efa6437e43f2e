//! Counts given from Python (steps, strides, chains, iteration budgets):
//! read as Python ints and checked against their range, so that −1 or
//! 2**70 is the package's error naming the argument, not the
//! `OverflowError` of a conversion to an unsigned Rust integer.

use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyInt};

use crate::InvalidInputError;

/// A Python int argument as it came: one that fits in a u64, or the text
/// of one that does not. A float or a bool is refused as a TypeError.
pub(crate) enum Whole {
    Fits(u64),
    Outside(String),
}

impl<'py> FromPyObject<'_, 'py> for Whole {
    type Error = PyErr;

    fn extract(obj: Borrowed<'_, 'py, PyAny>) -> PyResult<Self> {
        if obj.is_instance_of::<PyBool>() || !obj.is_instance_of::<PyInt>() {
            return Err(PyTypeError::new_err(format!(
                "an integer is required, not {}",
                obj.get_type().name()?
            )));
        }
        Ok(match obj.extract::<u64>() {
            Ok(v) => Whole::Fits(v),
            Err(_) => Whole::Outside(obj.str()?.to_string()),
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

    /// [`Whole::within`] as a `usize`.
    pub(crate) fn count(self, what: &str, lo: usize) -> PyResult<usize> {
        Ok(self.within(what, lo as u64, usize::MAX as u64)? as usize)
    }
}
