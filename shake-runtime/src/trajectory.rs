//! The stored states of a run, in one contiguous buffer.
//!
//! A run stores the states at steps 0, s, 2s, … (s the stride) and at most
//! one more at the end (the last step when it is off the stride, or the
//! last good state of a run that failed). So the step indices and the times
//! t0 + k h need not be stored: they are computed from t0, h, s and that
//! one extra index, exactly as the driver computes them. What is stored per
//! state is z = (q, p) itself, 2d numbers back to back in one `Vec<f64>`:
//! 16·2d bytes and nothing else (a pendulum state, d = 2, takes 32 bytes;
//! as separate heap vectors it took about 140).

use crate::diagnostics::DiagnosticRecord;
use crate::error::StepError;
use crate::state::State;
use crate::system::ConstrainedSystem;
use crate::tolerance::{check_run, stored_states};
use std::borrow::Cow;
use std::num::NonZeroU64;
use std::sync::Arc;

/// The stored states of a run: state `i` at step [`step(i)`](Self::step),
/// time [`time(i)`](Self::time), with `diagnostics[i]` when diagnostics are
/// on.
///
/// ```
/// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
/// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
/// let z0 = State::from_slices(&[0.0, -1.0], &[0.5, 0.0]);
/// let traj = integ.run(z0, Stop::Steps(4)).execute().trajectory;
/// assert_eq!(traj.steps(), vec![0, 1, 2, 3, 4]);
/// assert_eq!(traj.len(), 5);
/// assert_eq!(traj.q(0), &[0.0, -1.0]);
/// assert_eq!(traj.state(0).p[0], 0.5);
/// ```
#[derive(Clone, Debug)]
pub struct Trajectory {
    /// d: each state is 2d numbers, q then p.
    dof: usize,
    /// The states, back to back.
    data: Vec<f64>,
    t0: f64,
    h: f64,
    stride: u64,
    /// States at steps 0, s, 2s, …
    regular: usize,
    /// One last state off the stride, at this step.
    extra: Option<u64>,
    /// Diagnostics, one per state, when enabled (empty otherwise).
    pub diagnostics: Vec<DiagnosticRecord>,
    /// m, the number of constraints (the multipliers per record are 2m).
    constraints: usize,
    /// With the diagnostics: per record λ (m numbers) then σ (m numbers).
    multipliers: Vec<f64>,
    /// The declared names of z's entries and of the constraints (`None`:
    /// numbered, `q[k]`, `p[k]` and the constraint's index).
    names: Option<Arc<Names>>,
}

/// What a trajectory calls its columns: the 2d entries of z = (q, p) and
/// the m constraints, as the system declared them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Names {
    pub(crate) variables: Vec<String>,
    pub(crate) constraints: Vec<String>,
}

impl Names {
    /// The names `sys` declares.
    pub(crate) fn of<S: ConstrainedSystem>(sys: &S) -> Self {
        Names {
            variables: (0..2 * sys.dof())
                .map(|k| sys.variable_name(k).into_owned())
                .collect(),
            constraints: (0..sys.constraint_count())
                .map(|i| sys.constraint_name(i).to_owned())
                .collect(),
        }
    }
}

/// Equal when every number is; the multipliers compare bit for bit (the
/// last state's λ is NaN, see [`Trajectory::lambda`]). The names are labels
/// and are not compared: a trajectory loaded from an ensemble store, which
/// keeps numbers only, equals the run that wrote it (compare
/// [`Trajectory::variable_name`] to check names).
impl PartialEq for Trajectory {
    fn eq(&self, other: &Self) -> bool {
        self.dof == other.dof
            && self.data == other.data
            && self.t0.to_bits() == other.t0.to_bits()
            && self.h.to_bits() == other.h.to_bits()
            && self.stride == other.stride
            && self.regular == other.regular
            && self.extra == other.extra
            && self.diagnostics == other.diagnostics
            && self.constraints == other.constraints
            && self.multipliers.len() == other.multipliers.len()
            && self
                .multipliers
                .iter()
                .zip(&other.multipliers)
                .all(|(a, b)| a.to_bits() == b.to_bits())
    }
}

/// No state, d = 0, t0 = 0, h = 0, stride 1 (the stride a run clamps to).
impl Default for Trajectory {
    fn default() -> Self {
        Trajectory::new(0, 0.0, 0.0, 1, 0)
    }
}

impl Trajectory {
    /// An empty trajectory of a run with d degrees of freedom, start time
    /// t0, step size h and stride s, with room for `capacity` states.
    pub(crate) fn new(dof: usize, t0: f64, h: f64, stride: u64, capacity: usize) -> Self {
        Trajectory {
            dof,
            data: Vec::with_capacity(2 * dof * capacity),
            t0,
            h,
            stride: stride.max(1),
            regular: 0,
            extra: None,
            diagnostics: Vec::new(),
            constraints: 0,
            multipliers: Vec::new(),
            names: None,
        }
    }

    /// The empty trajectory of a run of `n` steps of size h from t0 with
    /// stride s, of states with d = `dof` coordinates and columns called
    /// `names`, with the multipliers of `diagnostics` = Some(m)
    /// constraints, after the checks of the run's extent the particle path
    /// makes too: the start time, the number of steps and the last time
    /// t0 + n·h together ([`StepError::InvalidInput`]: every time the run
    /// stores is then finite), and, when it stores, exactly its states
    /// (0, s, 2s, … and the last; a failing run stores at most its last
    /// good state off the stride, never more) counted without overflow and
    /// reserved ([`StepError::Storage`]): what cannot be stored is refused
    /// before the first step, not an abort of the process when the buffer
    /// grows. `stride` is at least 1 (the driver refuses 0 before).
    pub(crate) fn for_run(
        (dof, names): (usize, Option<Names>),
        diagnostics: Option<usize>,
        t0: f64,
        h: f64,
        n: u64,
        stride: u64,
        store: bool,
    ) -> Result<Self, StepError> {
        check_run(t0, h, 0, n).map_err(|l| StepError::InvalidInput {
            what: l.what(),
            value: l.value(),
        })?;
        let mut traj = Trajectory::new(dof, t0, h, stride, 0);
        if let Some(names) = names {
            traj.set_names(names);
        }
        if let Some(m) = diagnostics {
            traj.set_constraints(m);
        }
        if store {
            let s = NonZeroU64::new(stride).unwrap_or(NonZeroU64::MIN);
            let states = stored_states(0, n, s, true);
            let keep = diagnostics.is_some();
            if states.is_none_or(|k| traj.try_reserve(k, keep).is_err()) {
                let states = states.unwrap_or(u64::MAX);
                return Err(StepError::Storage {
                    step: 0,
                    states,
                    dof,
                });
            }
        }
        Ok(traj)
    }

    /// Names the columns as `names` does.
    pub(crate) fn set_names(&mut self, names: Names) {
        self.names = Some(Arc::new(names));
    }

    /// The declared name of z_k, the k-th entry of the states' z = (q, p)
    /// ([`Hamiltonian::variable_name`](crate::Hamiltonian::variable_name)
    /// of the system that ran): `q[k]` or `p[k−d]` when the trajectory was
    /// not made by a run (a default, or a file written without names).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, Stop, examples::Pendulum};
    /// let mut i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let traj = i.run(Pendulum::default().state(0.5, 0.0), Stop::Steps(1)).execute().trajectory;
    /// assert_eq!(traj.variable_name(1), "q[1]");
    /// ```
    pub fn variable_name(&self, k: usize) -> Cow<'_, str> {
        match &self.names {
            Some(n) if k < n.variables.len() => n.variables[k].as_str().into(),
            _ if k < self.dof => format!("q[{k}]").into(),
            _ => format!("p[{}]", k - self.dof).into(),
        }
    }

    /// The declared name of constraint i (its index, `0`, `1`, …, when the
    /// trajectory was not made by a run).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, Stop, examples::Pendulum};
    /// let mut i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).with_diagnostics();
    /// let traj = i.run(Pendulum::default().state(0.5, 0.0), Stop::Steps(1)).execute().trajectory;
    /// assert_eq!(traj.constraint_name(0), "rod");
    /// ```
    pub fn constraint_name(&self, i: usize) -> Cow<'_, str> {
        match &self.names {
            Some(n) if i < n.constraints.len() => n.constraints[i].as_str().into(),
            _ => i.to_string().into(),
        }
    }

    /// m, the number of constraints whose multipliers the diagnostics hold.
    pub(crate) fn set_constraints(&mut self, m: usize) {
        self.constraints = m;
    }

    /// The number m of constraints, i.e. of multipliers λ (and of σ) per
    /// diagnostic record (0 when the run had no diagnostics).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, Stop, examples::Pendulum};
    /// let mut i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).with_diagnostics();
    /// let traj = i.run(Pendulum::default().state(0.5, 0.0), Stop::Steps(2)).execute().trajectory;
    /// assert_eq!(traj.constraints(), 1);
    /// ```
    pub fn constraints(&self) -> usize {
        self.constraints
    }

    /// Room for `states` more states, and with `diagnostics` for their
    /// records and multipliers (set the constraints first): `Err` when a
    /// size overflows a machine word or the allocator refuses.
    fn try_reserve(&mut self, states: u64, diagnostics: bool) -> Result<(), ()> {
        let states = usize::try_from(states).map_err(|_| ())?;
        let numbers = states.checked_mul(2 * self.dof).ok_or(())?;
        self.data.try_reserve_exact(numbers).map_err(|_| ())?;
        if diagnostics {
            let multipliers = states.checked_mul(2 * self.constraints).ok_or(())?;
            self.diagnostics.try_reserve_exact(states).map_err(|_| ())?;
            self.multipliers
                .try_reserve_exact(multipliers)
                .map_err(|_| ())?;
        }
        Ok(())
    }

    /// Appends the multipliers of the next diagnostic record: λ unknown
    /// yet (NaN until the step leaving the state fills it in), then σ
    /// (zeros for SHAKE, `None`).
    pub(crate) fn push_multipliers(&mut self, sigma: Option<&[f64]>) {
        let m = self.constraints;
        self.multipliers.extend(std::iter::repeat_n(f64::NAN, m));
        match sigma {
            Some(s) => self.multipliers.extend_from_slice(&s[..m]),
            None => self.multipliers.extend(std::iter::repeat_n(0.0, m)),
        }
    }

    /// λ (to fill in) and σ of the last diagnostic record.
    pub(crate) fn last_multipliers_mut(&mut self) -> Option<(&mut [f64], &[f64])> {
        let m = self.constraints;
        let n = self.multipliers.len();
        if m == 0 || n < 2 * m {
            return None;
        }
        let (lambda, sigma) = self.multipliers[n - 2 * m..].split_at_mut(m);
        Some((lambda, sigma))
    }

    /// Replaces every multiplier (unpacking): λ then σ per record.
    pub(crate) fn set_multipliers(&mut self, m: usize, words: Vec<f64>) {
        self.constraints = m;
        self.multipliers = words;
    }

    /// Every multiplier, record after record (λ then σ, m each).
    pub(crate) fn multiplier_words(&self) -> &[f64] {
        &self.multipliers
    }

    /// λ at diagnostic record `i` (panics when `i` is out of range or the
    /// run had no diagnostics): the fibre parameters of the SHAKE step
    /// *leaving* the state, y = exp(Σ λ_j X_{g_j})(z), as RATTLE takes it
    /// from the state on M^H (the first substep of a composed step). The
    /// library's λ is the fibre parameter itself, an impulse: for holonomic
    /// g and Störmer–Verlet the step's first half kick is
    /// p ← p − (h/2)(H_q + g_qᵀ λ_c) with the paper's λ_c (Section 5.1.3),
    /// so λ = (h/2) λ_c. No step leaves the last state of a run: its λ is
    /// NaN, never a made-up number.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut i = Integrator::new(Pendulum::default(), StormerVerlet, 0.01).with_diagnostics();
    /// // At rest at the bottom the rod pulls up: λ > 0 (p ← p − 2λq, q = (0, −1)).
    /// let traj = i.run(State::from_slices(&[0.0, -1.0], &[0.0, 0.0]), Stop::Steps(3)).execute().trajectory;
    /// assert!(traj.lambda(0)[0] > 0.0);
    /// assert!(traj.lambda(3)[0].is_nan());
    /// ```
    pub fn lambda(&self, i: usize) -> &[f64] {
        let m = self.constraints;
        &self.multipliers[2 * m * i..2 * m * i + m]
    }

    /// σ at diagnostic record `i` (panics when out of range): the fibre
    /// parameters of RATTLE's projection Π onto M^H that gave this state,
    /// exp(Σ σ_j X_{g_j})(z⁻) ∈ M^H, z⁻ the SHAKE state of the step
    /// arriving (0 for SHAKE, which does not project). For holonomic g and
    /// Störmer–Verlet this is the step's last half kick,
    /// p ← p − (h/2)(H_q + g_qᵀ μ_c) at the new q, so σ = (h/2) μ_c.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut i = Integrator::new(Pendulum::default(), StormerVerlet, 0.01).with_diagnostics();
    /// let traj = i.run(State::from_slices(&[0.0, -1.0], &[0.0, 0.0]), Stop::Steps(3)).execute().trajectory;
    /// assert!(traj.sigma(1)[0] > 0.0);
    /// ```
    pub fn sigma(&self, i: usize) -> &[f64] {
        let m = self.constraints;
        &self.multipliers[2 * m * i + m..2 * m * (i + 1)]
    }

    /// The constraint force at stored state `i`, f = −g_q(q)ᵀ λ_c, one
    /// number per coordinate, in the paper's sign convention
    /// (q' = H_p + g_pᵀλ, p' = −H_q − g_qᵀλ), written into `force`
    /// (length d). The multiplier is the whole impulse the constraints give
    /// at this q divided by h: λ_c = (σ + λ)/h, the last half kick of the
    /// step arriving plus the first half kick of the step leaving
    /// (for SHAKE σ = 0 and λ is all of it). Each half alone is off the
    /// exact multiplier by O(h), with opposite signs; the symmetric sum is
    /// O(h²) for a symmetric second-order base map (Störmer–Verlet,
    /// implicit midpoint): `tests/suite/constraint_forces.rs` shows the error
    /// ratio 4 when h is halved on the pendulum. g_q is evaluated with the
    /// system's `constraint_jacobian` at the stored state (for constraints
    /// that depend on p, −g_qᵀλ_c is the force on p and g_pᵀλ_c the
    /// correction of q'). Returns `false` (and leaves `force` as NaN) at
    /// the first state, where no step arrives (only the half kick λ
    /// leaving it is known; 2λ/h is then the O(h) estimate), and at the
    /// last, where no step leaves (λ is NaN).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let pendulum = Pendulum { gravity: 9.81, length: 1.0 };
    /// let mut i = Integrator::new(pendulum, StormerVerlet, 1e-3).with_diagnostics();
    /// // At rest at the bottom: the tension is m g = 9.81, pointing up.
    /// let traj = i.run(State::from_slices(&[0.0, -1.0], &[0.0, 0.0]), Stop::Steps(2)).execute().trajectory;
    /// let mut f = [0.0; 2];
    /// assert!(!traj.constraint_force(&pendulum, 0, &mut f)); // no step arrives
    /// assert!(traj.constraint_force(&pendulum, 1, &mut f));
    /// assert!(f[0].abs() < 1e-12 && (f[1] - 9.81).abs() < 1e-4);
    /// ```
    pub fn constraint_force<S: crate::ConstrainedSystem>(
        &self,
        system: &S,
        i: usize,
        force: &mut [f64],
    ) -> bool {
        let (d, m) = (self.dof, self.constraints);
        assert_eq!(force.len(), d, "force has one entry per coordinate");
        let (lambda, sigma) = (self.lambda(i), self.sigma(i));
        if i == 0 || !lambda.iter().chain(sigma).all(|x| x.is_finite()) {
            force.fill(f64::NAN);
            return false;
        }
        let mut g_z = vec![0.0; m * 2 * d];
        system.constraint_jacobian(self.q(i), self.p(i), &mut g_z);
        force.fill(0.0);
        for j in 0..m {
            let c = (lambda[j] + sigma[j]) / self.h;
            for k in 0..d {
                force[k] -= g_z[j + k * m] * c;
            }
        }
        true
    }

    /// (d, t0, h, stride): what, with the stored step indices, fixes every
    /// state's place and time (for packing a trajectory into flat words and
    /// back).
    pub(crate) fn layout(&self) -> (usize, f64, f64, u64) {
        (self.dof, self.t0, self.h, self.stride)
    }

    /// Appends the state (q, p) at step k: the next multiple of the stride,
    /// or the one last state off it.
    pub(crate) fn push(&mut self, k: u64, q: &[f64], p: &[f64]) {
        debug_assert!(
            self.extra.is_none(),
            "nothing is stored after the extra state"
        );
        if k == self.regular as u64 * self.stride {
            self.regular += 1;
        } else {
            self.extra = Some(k);
        }
        self.data.extend_from_slice(q);
        self.data.extend_from_slice(p);
    }

    /// The stored states back to back, each q then p (2d numbers), taken
    /// out of the trajectory without a copy: for a caller that lays them
    /// out anew and cannot afford two copies of a long run at once.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let z0 = State::from_slices(&[0.0, -1.0], &[0.5, 0.0]);
    /// let traj = integ.run(z0, Stop::Steps(2)).execute().trajectory;
    /// let (q1, p1) = (traj.q(1).to_vec(), traj.p(1).to_vec());
    /// let words = traj.into_states();
    /// assert_eq!(words.len(), 3 * 4);
    /// assert_eq!((&words[4..6], &words[6..8]), (&q1[..], &p1[..]));
    /// ```
    pub fn into_states(self) -> Vec<f64> {
        self.data
    }

    /// Number of stored states.
    ///
    /// ```
    /// assert_eq!(geoshake_runtime::Trajectory::default().len(), 0);
    /// ```
    pub fn len(&self) -> usize {
        self.regular + usize::from(self.extra.is_some())
    }

    /// True when nothing was stored.
    ///
    /// ```
    /// assert!(geoshake_runtime::Trajectory::default().is_empty());
    /// ```
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The step index of state `i` (panics when `i ≥ len()`).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let z0 = State::from_slices(&[0.0, -1.0], &[0.5, 0.0]);
    /// let traj = integ.run(z0, Stop::Steps(7)).stride(3).execute().trajectory;
    /// assert_eq!(traj.step(3), 7);
    /// ```
    pub fn step(&self, i: usize) -> u64 {
        assert!(i < self.len(), "state {i} of {}", self.len());
        if i < self.regular {
            i as u64 * self.stride
        } else {
            self.extra.expect("the extra state")
        }
    }

    /// The step indices of all stored states.
    ///
    /// ```
    /// assert!(geoshake_runtime::Trajectory::default().steps().is_empty());
    /// ```
    pub fn steps(&self) -> Vec<u64> {
        (0..self.len()).map(|i| self.step(i)).collect()
    }

    /// The time t0 + k h of state `i`, k its step index.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.5);
    /// let z0 = State::from_slices(&[0.0, -1.0], &[0.5, 0.0]);
    /// let traj = integ.run(z0, Stop::Steps(2)).start_time(1.0).execute().trajectory;
    /// assert_eq!(traj.time(2), 2.0);
    /// ```
    pub fn time(&self, i: usize) -> f64 {
        self.t0 + self.step(i) as f64 * self.h
    }

    /// The times of all stored states.
    ///
    /// ```
    /// assert!(geoshake_runtime::Trajectory::default().times().is_empty());
    /// ```
    pub fn times(&self) -> Vec<f64> {
        (0..self.len()).map(|i| self.time(i)).collect()
    }

    /// The positions q of state `i`, a view into the buffer.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let traj = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(1)).execute().trajectory;
    /// assert_eq!(traj.q(0), &[0.0, -1.0]);
    /// ```
    pub fn q(&self, i: usize) -> &[f64] {
        assert!(i < self.len(), "state {i} of {}", self.len());
        let n = 2 * self.dof;
        &self.data[i * n..i * n + self.dof]
    }

    /// The momenta p of state `i`, a view into the buffer.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let traj = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(1)).execute().trajectory;
    /// assert_eq!(traj.p(0), &[0.5, 0.0]);
    /// ```
    pub fn p(&self, i: usize) -> &[f64] {
        assert!(i < self.len(), "state {i} of {}", self.len());
        let n = 2 * self.dof;
        &self.data[i * n + self.dof..(i + 1) * n]
    }

    /// State `i` as an owned [`State`] (a copy).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let z0 = State::from_slices(&[0.0, -1.0], &[0.5, 0.0]);
    /// let traj = integ.run(z0.clone(), Stop::Steps(1)).execute().trajectory;
    /// assert_eq!(traj.state(0), z0);
    /// ```
    pub fn state(&self, i: usize) -> State {
        State::from_slices(self.q(i), self.p(i))
    }

    /// The last stored state (a copy).
    ///
    /// ```
    /// assert!(geoshake_runtime::Trajectory::default().last().is_none());
    /// ```
    pub fn last(&self) -> Option<State> {
        self.len().checked_sub(1).map(|i| self.state(i))
    }

    /// Every stored state in order (copies).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let traj = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(3)).execute().trajectory;
    /// assert_eq!(traj.states().count(), 4);
    /// ```
    pub fn states(&self) -> impl ExactSizeIterator<Item = State> + '_ {
        (0..self.len()).map(|i| self.state(i))
    }

    /// The bytes the stored states hold (the buffer's capacity; step
    /// indices and times take none).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let traj = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(9)).execute().trajectory;
    /// assert_eq!(traj.state_bytes(), 10 * 32);
    /// ```
    pub fn state_bytes(&self) -> usize {
        self.data.capacity() * std::mem::size_of::<f64>()
    }
}
