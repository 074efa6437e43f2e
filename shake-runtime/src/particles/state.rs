//! A state of a particle system.

/// Positions and momenta of n particles in R^D (`q[a * D + c]`), with the
/// step count and time.
///
/// The state also carries a stamp that ties it to the solver that produced
/// it, so that the next step can reuse the forces ∇V(q) and the factor of
/// N(q) computed at its end. [`q_mut`](Self::q_mut) and
/// [`p_mut`](Self::p_mut) clear the stamp: a state changed by hand is
/// treated as new.
///
/// ```
/// use geoshake_runtime::particles::ParticleState;
/// let s = ParticleState::new(vec![0.0; 6], vec![1.0; 6]).with_time(5.0);
/// assert_eq!((s.step(), s.time(), s.q().len()), (0, 5.0, 6));
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct ParticleState {
    pub(crate) q: Vec<f64>,
    pub(crate) p: Vec<f64>,
    pub(crate) t0: f64,
    pub(crate) time: f64,
    pub(crate) step: u64,
    pub(crate) stamp: u64,
}

impl ParticleState {
    /// A state at step 0, time 0.
    pub fn new(q: Vec<f64>, p: Vec<f64>) -> Self {
        ParticleState {
            q,
            p,
            t0: 0.0,
            time: 0.0,
            step: 0,
            stamp: 0,
        }
    }

    /// The same state at step 0 and time t0 (the run's start). A t0 that
    /// is NaN or infinite is refused by [`Rattle::step`](super::Rattle::step)
    /// and [`Rattle::run`](super::Rattle::run) (the times t0 + k·h they
    /// stamp would be NaN or ∞).
    pub fn with_time(mut self, t0: f64) -> Self {
        self.t0 = t0;
        self.time = t0;
        self.step = 0;
        self
    }

    /// Positions.
    pub fn q(&self) -> &[f64] {
        &self.q
    }

    /// Momenta.
    pub fn p(&self) -> &[f64] {
        &self.p
    }

    /// Positions, for changes by hand (the state counts as new).
    pub fn q_mut(&mut self) -> &mut [f64] {
        self.stamp = 0;
        &mut self.q
    }

    /// Momenta, for changes by hand (the state counts as new).
    pub fn p_mut(&mut self) -> &mut [f64] {
        self.stamp = 0;
        &mut self.p
    }

    /// Steps taken since the start (step k is at t0 + k·h).
    pub fn step(&self) -> u64 {
        self.step
    }

    /// t0 + k·h.
    pub fn time(&self) -> f64 {
        self.time
    }

    /// The start time t0.
    pub fn start_time(&self) -> f64 {
        self.t0
    }

    /// Bytes held (the two arrays).
    pub fn bytes(&self) -> usize {
        (self.q.capacity() + self.p.capacity()) * 8
    }
}
