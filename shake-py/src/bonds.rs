//! `geoshake.Bonds`: distance constraints between atoms, solved on NumPy
//! arrays in place for an integrator that moves the atoms itself (ASE's
//! dynamics, through `geoshake.ase.FixBondLengths`). The solver is the
//! particle path's (`Rattle::shake_positions`, `Rattle::project_momenta`).

use std::sync::Mutex;

use geoshake::runtime::particles::{
    stencils::Distance, Options, ParticleSystem, Rattle, Table, TopologyError,
};
use geoshake::{StepError, StepInfo};
use numpy::{PyArray2, PyArrayMethods, PyReadonlyArray2, PyReadwriteArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::whole::Whole;
use crate::{refused, typed_error, InvalidInputError};

/// The name of the bonds' family, in errors.
const FAMILY: &str = "bond";

/// Distance constraints |x_a − x_b| = l between atoms in R³ with masses:
/// SHAKE's position stage and RATTLE's velocity stage on NumPy arrays of
/// shape (n, 3), changed in place, solved to a relative tolerance on every
/// bond by Newton on each independent cluster (rigid molecules) or on the
/// coupled graph.
#[pyclass(frozen, module = "geoshake")]
pub(crate) struct Bonds {
    rattle: Mutex<Rattle>,
    atoms: usize,
    constraints: usize,
}

pub(crate) fn topology(e: TopologyError) -> PyErr {
    InvalidInputError::new_err(e.to_string())
}

/// An (n, 3) float64 array read as one slice: taken as it is when it is
/// C-contiguous float64, converted (a copy) otherwise.
fn positions<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    atoms: usize,
) -> PyResult<PyReadonlyArray2<'py, f64>> {
    // (`try_readonly`: an array borrowed for writing is refused, never a
    // panic.)
    let given = obj
        .cast::<PyArray2<f64>>()
        .ok()
        .and_then(|a| a.try_readonly().ok());
    let a = match given {
        Some(a) if a.is_c_contiguous() => a,
        _ => {
            let np = obj.py().import("numpy")?;
            let converted = np
                .call_method1("ascontiguousarray", (obj, "float64"))
                .map_err(|e| {
                    refused(obj.py(), e, |e| {
                        format!(
                            "{name} must be an array of real numbers of shape ({atoms}, 3): {}",
                            e.value(obj.py())
                        )
                    })
                })?;
            let converted = converted.cast_into::<PyArray2<f64>>().map_err(|e| {
                let ndim = e.into_inner().getattr("ndim");
                InvalidInputError::new_err(format!(
                    "{name} must be an array of shape ({atoms}, 3), not of {} dimensions",
                    ndim.and_then(|d| d.extract::<usize>()).unwrap_or(0)
                ))
            })?;
            converted
                .try_readonly()
                .map_err(|e| InvalidInputError::new_err(format!("{name} cannot be read: {e}")))?
        }
    };
    if a.shape() != [atoms, 3] {
        return Err(InvalidInputError::new_err(format!(
            "{name} must have shape ({atoms}, 3), not {:?}",
            a.shape()
        )));
    }
    Ok(a)
}

/// The array changed in place: it must be a writable C-contiguous float64
/// NumPy array of shape (n, 3) (a copy would not be seen by the caller).
fn in_place<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    atoms: usize,
) -> PyResult<PyReadwriteArray2<'py, f64>> {
    let wrong = |why: String| {
        InvalidInputError::new_err(format!(
            "{name} is changed in place: it must be a writable, C-contiguous float64 NumPy \
             array of shape ({atoms}, 3), and not the same array as the other argument ({why})"
        ))
    };
    let a = obj
        .cast::<PyArray2<f64>>()
        .map_err(|e| wrong(e.to_string()))?
        .try_readwrite()
        .map_err(|e| wrong(e.to_string()))?;
    if !a.is_c_contiguous() || a.shape() != [atoms, 3] {
        return Err(wrong(format!(
            "shape {:?}, C-contiguous {}",
            a.shape(),
            a.is_c_contiguous()
        )));
    }
    Ok(a)
}

#[pymethods]
impl Bonds {
    /// `masses`: n positive masses; `pairs`: (m, 2) atom indices; `lengths`:
    /// m bond lengths; `tolerance`: every bond's relative error
    /// | |x_a − x_b| − l | / l at the end, in [4ε, 1); `max_iterations`:
    /// Newton's budget per call (per cluster), in 1..=10000. A pair naming
    /// an atom that does not exist or twice, the same bond twice, a mass
    /// or length not finite and positive, or a molecule with more bonds
    /// than coordinates raise `InvalidInputError`.
    #[new]
    #[pyo3(signature = (masses, pairs, lengths, *, tolerance=1e-13, max_iterations=Whole::Fits(50)))]
    fn new(
        py: Python<'_>,
        masses: Vec<f64>,
        pairs: Vec<[i64; 2]>,
        lengths: Vec<f64>,
        tolerance: f64,
        max_iterations: Whole,
    ) -> PyResult<Self> {
        let max_iterations = max_iterations.budget("max_iterations")?;
        if pairs.len() != lengths.len() {
            return Err(InvalidInputError::new_err(format!(
                "{} pairs but {} lengths",
                pairs.len(),
                lengths.len()
            )));
        }
        let mut table = Table::with_capacity(2, 1, pairs.len());
        for (k, (ab, &l)) in pairs.iter().zip(&lengths).enumerate() {
            if !(l.is_finite() && l > 0.0) {
                return Err(InvalidInputError::new_err(format!(
                    "bond {k}: length {l} must be finite and positive"
                )));
            }
            let ij = ab.map(|i| usize::try_from(i).unwrap_or(usize::MAX));
            if ij.contains(&usize::MAX) {
                return Err(InvalidInputError::new_err(format!(
                    "bond {k}: atom indices {ab:?} must be non-negative"
                )));
            }
            table
                .push(&ij, &[l])
                .map_err(|e| topology(e.in_family("bond")))?;
        }
        let atoms = masses.len();
        let constraints = pairs.len();
        let system = ParticleSystem::new(3, masses)
            .and_then(|s| s.with_constraints(FAMILY, Distance::<3>, table))
            .map_err(topology)?;
        let options = Options {
            tol: tolerance,
            max_iter: max_iterations,
            ..Options::default()
        };
        // The step size plays no part in the two calls.
        let rattle = Rattle::new(system, 1.0, options).map_err(|e| typed_error(py, &e))?;
        Ok(Bonds {
            rattle: Mutex::new(rattle),
            atoms,
            constraints,
        })
    }

    /// SHAKE's position stage: `x` (new positions, unconstrained) becomes
    /// x − M⁻¹ G(q0)ᵀ ν with every bond at its length, moved along the
    /// bonds of the old positions `q0`. Returns the largest relative bond
    /// error left. On error `x` is unchanged.
    fn shake_positions(
        &self,
        py: Python<'_>,
        q0: &Bound<'_, PyAny>,
        x: &Bound<'_, PyAny>,
    ) -> PyResult<f64> {
        let info = self.solve(py, ("q0", q0), ("x", x), Rattle::shake_positions)?;
        Ok(info.residual.unwrap_or(f64::NAN))
    }

    /// RATTLE's velocity stage: `p` (momenta, or forces) becomes
    /// p − G(q)ᵀ μ with every bond's relative velocity across it, G(q) M⁻¹ p
    /// = 0, at the positions `q` (on the constraints or not). Returns the
    /// largest relative residual left. On error `p` is unchanged.
    fn project_momenta(
        &self,
        py: Python<'_>,
        q: &Bound<'_, PyAny>,
        p: &Bound<'_, PyAny>,
    ) -> PyResult<f64> {
        let info = self.solve(py, ("q", q), ("p", p), Rattle::project_momenta)?;
        Ok(info.hidden.unwrap_or(f64::NAN))
    }

    /// n, the number of atoms.
    #[getter]
    fn atoms(&self) -> usize {
        self.atoms
    }

    /// m, the number of bonds.
    fn __len__(&self) -> usize {
        self.constraints
    }

    /// "clusters", "band" or "sparse": the solver chosen for the bonds'
    /// graph.
    #[getter]
    fn solver(&self) -> &'static str {
        self.rattle
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .solver_name()
    }

    fn __repr__(&self) -> String {
        format!(
            "<geoshake.Bonds: {} bonds between {} atoms, solver {}>",
            self.constraints,
            self.atoms,
            self.solver()
        )
    }
}

/// `Rattle::shake_positions` or `Rattle::project_momenta`.
type Stage = fn(&mut Rattle, &[f64], &mut [f64]) -> Result<StepInfo, StepError>;

impl Bonds {
    /// `stage(rattle, read, written)` on the two arrays, without the GIL.
    fn solve(
        &self,
        py: Python<'_>,
        (read_name, read): (&str, &Bound<'_, PyAny>),
        (written_name, written): (&str, &Bound<'_, PyAny>),
        stage: Stage,
    ) -> PyResult<StepInfo> {
        let read = positions(read, read_name, self.atoms)?;
        let mut written = in_place(written, written_name, self.atoms)?;
        let read = read.as_slice().expect("C-contiguous");
        let written = written.as_slice_mut().expect("C-contiguous");
        let mut guard = self.rattle.lock().unwrap_or_else(|e| e.into_inner());
        let rattle: &mut Rattle = &mut guard;
        py.detach(|| stage(rattle, read, written))
            .map_err(|e| error(py, &e))
    }
}

/// A solver error as the package's exception, with the constraint at
/// fault when there is one: `family` (its declared name; `"bond"` for
/// `Bonds`) and `member` (the row of its table, of `pairs` for `Bonds`),
/// both None otherwise.
pub(crate) fn error(py: Python<'_>, e: &StepError) -> PyErr {
    let err = typed_error(py, e);
    let (family, member) = match e {
        StepError::AtMember { family, member, .. } => (Some(family.as_str()), Some(*member)),
        _ => (None, None),
    };
    let _ = err.value(py).setattr("family", family);
    let _ = err.value(py).setattr("member", member);
    err
}
