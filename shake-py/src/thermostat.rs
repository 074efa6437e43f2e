//! `geoshake.Langevin`: the particle path's Langevin thermostat (g-BAOAB,
//! `geoshake::runtime::particles::Langevin`) as a value given to
//! `DeclaredParticles.system(..., thermostat=)`.

use geoshake::runtime::particles::{Langevin as Thermostat, MAX_SUBSTEPS};
use pyo3::prelude::*;

use crate::bonds::error;
use crate::forces::type_name;
use crate::whole::Whole;
use crate::InvalidInputError;

/// The increment between members' seeds: SplitMix64's, the odd integer
/// nearest 2⁶⁴/φ, so that the seeds s, s + γ, s + 2γ, … of an ensemble's
/// members differ in many bits and the noise hashed from them is
/// independent (the noise of step k hashes the seed with k: members whose
/// seeds were s, s + 1, … would differ in the last bits only).
const MEMBER_STRIDE: u64 = 0x9e37_79b9_7f4a_7c15;

/// A Langevin thermostat for the particle path:
///
///   dp = −∇V dt − γ p dt + √(2 γ k_B T) M^{1/2} dW
///
/// on the constraint manifold, integrated by BAOAB with RATTLE's drifts
/// (g-BAOAB with `substeps` K > 1: each drift is K RATTLE substeps of the
/// free flow), so that (q, p) samples exp(−H / k_B T) restricted to T*M.
///
/// `friction` γ ≥ 0 is per unit of time (γ = 0: Hamiltonian flow split
/// into kicks and drifts), `kT` = k_B T ≥ 0 is in the units of H (for
/// masses in g/mol, lengths in Å and times in fs, as LAMMPS' `real` units:
/// k_B T = 0.0019872067 · T / 48.88821291², T in kelvin), `seed`
/// a whole number in [0, 2⁶⁴) and `substeps` K in 1..=2²⁰. The noise of
/// step k is a function of the seed, k and the coordinate only, so a run
/// is reproducible bit for bit. Anything else raises `InvalidInputError`.
#[pyclass(frozen, module = "geoshake", name = "Langevin")]
#[derive(Clone)]
pub(crate) struct Langevin {
    pub(crate) inner: Thermostat,
}

/// `obj` as a float, or `InvalidInputError` naming the argument.
fn real(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<f64> {
    obj.extract().map_err(|_| {
        InvalidInputError::new_err(format!(
            "{name} must be a real number, not {}",
            type_name(obj)
        ))
    })
}

#[pymethods]
impl Langevin {
    #[new]
    #[pyo3(signature = (friction, kT, seed=None, *, substeps=None))]
    #[allow(non_snake_case)]
    fn new(
        py: Python<'_>,
        friction: &Bound<'_, PyAny>,
        kT: &Bound<'_, PyAny>,
        seed: Option<&Bound<'_, PyAny>>,
        substeps: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let gamma = real(friction, "friction")?;
        let kt = real(kT, "kT")?;
        let seed = match seed {
            Some(s) => Whole::read(s, "seed", 0, u64::MAX)?,
            None => 0,
        };
        let substeps = match substeps {
            Some(k) => Whole::read(k, "substeps", 1, MAX_SUBSTEPS as u64)? as usize,
            None => 1,
        };
        let inner = Thermostat::new(gamma, kt, seed)
            .and_then(|t| t.geodesic(substeps))
            .map_err(|e| error(py, &e))?;
        Ok(Langevin { inner })
    }

    /// γ, per unit of time.
    #[getter]
    fn friction(&self) -> f64 {
        self.inner.friction()
    }

    /// k_B T, in the units of H.
    #[getter]
    #[allow(non_snake_case)]
    fn kT(&self) -> f64 {
        self.inner.kt()
    }

    /// The noise's seed.
    #[getter]
    fn seed(&self) -> u64 {
        self.inner.seed()
    }

    /// K, the RATTLE substeps of each drift.
    #[getter]
    fn substeps(&self) -> usize {
        self.inner.substeps()
    }

    /// The thermostat of member `i` of an ensemble: the same friction, k_B T
    /// and substeps, with the seed s + i·0x9E3779B97F4A7C15 (mod 2⁶⁴).
    /// `member(0)` is this thermostat; member i of `ParticleRattle.ensemble`
    /// runs the steps of `run` on a system given `member(i)`.
    fn member(&self, i: &Bound<'_, PyAny>) -> PyResult<Langevin> {
        let i = Whole::read(i, "i", 0, u64::MAX)?;
        Ok(self.for_member(i))
    }

    /// Pickling (every protocol): the constructor's arguments, so that a
    /// thermostat sent to another process draws the same noise.
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let args = (self.friction(), self.kT(), self.seed(), self.substeps());
        crate::reduce(py, "_rebuild_langevin", args)
    }

    fn __repr__(&self) -> String {
        format!(
            "geoshake.Langevin(friction={:?}, kT={:?}, seed={}, substeps={})",
            self.friction(),
            self.kT(),
            self.seed(),
            self.substeps()
        )
    }

    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other
            .cast::<Langevin>()
            .is_ok_and(|o| o.get().inner == self.inner)
    }
}

impl Langevin {
    /// Member i's thermostat (see `member`).
    pub(crate) fn for_member(&self, i: u64) -> Langevin {
        let seed = self
            .inner
            .seed()
            .wrapping_add(i.wrapping_mul(MEMBER_STRIDE));
        let inner = Thermostat::new(self.inner.friction(), self.inner.kt(), seed)
            .and_then(|t| t.geodesic(self.inner.substeps()))
            .expect("the parameters of a thermostat already made");
        Langevin { inner }
    }
}

/// The inverse of `Langevin.__reduce__`: `Langevin(friction, kT, seed,
/// substeps=substeps)`, with its checks.
#[pyfunction]
#[allow(non_snake_case)]
pub(crate) fn _rebuild_langevin(
    py: Python<'_>,
    friction: &Bound<'_, PyAny>,
    kT: &Bound<'_, PyAny>,
    seed: &Bound<'_, PyAny>,
    substeps: &Bound<'_, PyAny>,
) -> PyResult<Langevin> {
    Langevin::new(py, friction, kT, Some(seed), Some(substeps))
}
