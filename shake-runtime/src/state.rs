//! A point z = (q, p) of phase space R^{2d}.

use nalgebra::DVector;

/// A phase-space point z = (q, p), with q, p ∈ R^d as nalgebra vectors.
///
/// ```
/// use geoshake_runtime::State;
/// let z = State::from_slices(&[1.0, 0.0], &[0.0, 0.5]);
/// assert_eq!(z.dof(), 2);
/// assert_eq!(z.p[1], 0.5);
/// ```
#[derive(Debug, PartialEq)]
pub struct State {
    /// Positions q ∈ R^d.
    pub q: DVector<f64>,
    /// Momenta p ∈ R^d.
    pub p: DVector<f64>,
}

impl Clone for State {
    fn clone(&self) -> Self {
        State {
            q: self.q.clone(),
            p: self.p.clone(),
        }
    }

    /// Copies into the vectors already held when their lengths match
    /// (the derived `clone_from` allocates two new ones): the sampler
    /// copies states at every step.
    ///
    /// ```
    /// use geoshake_runtime::State;
    /// let mut z = State::zeros(2);
    /// z.clone_from(&State::from_slices(&[1.0, 2.0], &[3.0, 4.0]));
    /// assert_eq!(z.p[1], 4.0);
    /// z.clone_from(&State::zeros(3));
    /// assert_eq!(z.dof(), 3);
    /// ```
    fn clone_from(&mut self, other: &Self) {
        if self.q.len() == other.q.len() && self.p.len() == other.p.len() {
            self.q.copy_from(&other.q);
            self.p.copy_from(&other.p);
        } else {
            *self = other.clone();
        }
    }
}

/// Why numbers given for a [`State`] do not make one: z = (q, p) needs
/// q and p of the same length d.
///
/// ```
/// use geoshake_runtime::{State, StateError};
/// let e = State::try_from_slices(&[1.0], &[1.0, 2.0]).unwrap_err();
/// assert_eq!(e, StateError::LengthMismatch { q: 1, p: 2 });
/// assert_eq!(e.to_string(), "q has 1 entries and p has 2: a state needs both of length d");
/// ```
#[derive(Copy, Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum StateError {
    /// q and p have different lengths.
    #[error("q has {q} entries and p has {p}: a state needs both of length d")]
    LengthMismatch {
        /// q's length.
        q: usize,
        /// p's length.
        p: usize,
    },
    /// z = (q, p) as one vector has an odd length.
    #[error("z has {len} entries: z = (q, p) needs an even number 2d")]
    OddLength {
        /// z's length.
        len: usize,
    },
}

impl State {
    /// A state from its two halves (of equal length).
    ///
    /// # Panics
    ///
    /// When q and p have different lengths (a programmer's error when the
    /// lengths are fixed in the code); for lengths that come from data use
    /// [`try_new`](Self::try_new), which returns a [`StateError`].
    ///
    /// ```
    /// use geoshake_runtime::{State, nalgebra::DVector};
    /// let z = State::new(DVector::from_vec(vec![1.0]), DVector::from_vec(vec![2.0]));
    /// assert_eq!(z.q[0], 1.0);
    /// ```
    pub fn new(q: DVector<f64>, p: DVector<f64>) -> Self {
        assert_eq!(q.len(), p.len(), "q and p must have the same length");
        State { q, p }
    }

    /// [`new`](Self::new) without the panic: q and p of different lengths
    /// are [`StateError::LengthMismatch`].
    ///
    /// ```
    /// use geoshake_runtime::{State, StateError, nalgebra::DVector};
    /// let q = DVector::from_vec(vec![1.0]);
    /// let z = State::try_new(q.clone(), DVector::from_vec(vec![2.0])).unwrap();
    /// assert_eq!(z.p[0], 2.0);
    /// let e = State::try_new(q, DVector::zeros(3)).unwrap_err();
    /// assert_eq!(e, StateError::LengthMismatch { q: 1, p: 3 });
    /// ```
    pub fn try_new(q: DVector<f64>, p: DVector<f64>) -> Result<Self, StateError> {
        if q.len() != p.len() {
            return Err(StateError::LengthMismatch {
                q: q.len(),
                p: p.len(),
            });
        }
        Ok(State { q, p })
    }

    /// A state copied from two slices of equal length.
    ///
    /// # Panics
    ///
    /// When the slices have different lengths; for slices that come from
    /// data use [`try_from_slices`](Self::try_from_slices).
    ///
    /// ```
    /// let z = geoshake_runtime::State::from_slices(&[0.0, -1.0], &[1.0, 0.0]);
    /// assert_eq!(z.q[1], -1.0);
    /// ```
    pub fn from_slices(q: &[f64], p: &[f64]) -> Self {
        State::new(DVector::from_column_slice(q), DVector::from_column_slice(p))
    }

    /// [`from_slices`](Self::from_slices) without the panic: slices of
    /// different lengths are [`StateError::LengthMismatch`] (checked
    /// before anything is copied).
    ///
    /// ```
    /// use geoshake_runtime::{State, StateError};
    /// let z = State::try_from_slices(&[0.0, -1.0], &[1.0, 0.0]).unwrap();
    /// assert_eq!(z.q[1], -1.0);
    /// assert_eq!(
    ///     State::try_from_slices(&[1.0], &[1.0, 2.0]),
    ///     Err(StateError::LengthMismatch { q: 1, p: 2 })
    /// );
    /// ```
    pub fn try_from_slices(q: &[f64], p: &[f64]) -> Result<Self, StateError> {
        if q.len() != p.len() {
            return Err(StateError::LengthMismatch {
                q: q.len(),
                p: p.len(),
            });
        }
        Ok(State::from_slices(q, p))
    }

    /// The origin of R^{2d}.
    ///
    /// ```
    /// assert_eq!(geoshake_runtime::State::zeros(3).q.len(), 3);
    /// ```
    pub fn zeros(d: usize) -> Self {
        State {
            q: DVector::zeros(d),
            p: DVector::zeros(d),
        }
    }

    /// The number d of degrees of freedom.
    ///
    /// ```
    /// assert_eq!(geoshake_runtime::State::zeros(2).dof(), 2);
    /// ```
    pub fn dof(&self) -> usize {
        self.q.len()
    }

    /// z = (q, p) as one vector of length 2d.
    ///
    /// ```
    /// let z = geoshake_runtime::State::from_slices(&[1.0], &[2.0]).to_vector();
    /// assert_eq!(z.as_slice(), &[1.0, 2.0]);
    /// ```
    pub fn to_vector(&self) -> DVector<f64> {
        let d = self.dof();
        DVector::from_fn(2 * d, |i, _| if i < d { self.q[i] } else { self.p[i - d] })
    }

    /// The state with z = (q, p) given as one vector of even length.
    ///
    /// # Panics
    ///
    /// When z has an odd length; for a z that comes from data use
    /// [`try_from_vector`](Self::try_from_vector).
    ///
    /// ```
    /// use geoshake_runtime::{State, nalgebra::DVector};
    /// let z = State::from_vector(&DVector::from_vec(vec![1.0, 2.0]));
    /// assert_eq!((z.q[0], z.p[0]), (1.0, 2.0));
    /// ```
    pub fn from_vector(z: &DVector<f64>) -> Self {
        assert!(z.len() & 1 == 0, "z must have even length 2d");
        let d = z.len() / 2;
        State::from_slices(&z.as_slice()[..d], &z.as_slice()[d..])
    }

    /// [`from_vector`](Self::from_vector) without the panic: an odd length
    /// is [`StateError::OddLength`].
    ///
    /// ```
    /// use geoshake_runtime::{State, StateError, nalgebra::DVector};
    /// let z = State::try_from_vector(&DVector::from_vec(vec![1.0, 2.0])).unwrap();
    /// assert_eq!((z.q[0], z.p[0]), (1.0, 2.0));
    /// let odd = DVector::from_vec(vec![1.0, 2.0, 3.0]);
    /// assert_eq!(State::try_from_vector(&odd), Err(StateError::OddLength { len: 3 }));
    /// ```
    pub fn try_from_vector(z: &DVector<f64>) -> Result<Self, StateError> {
        if !z.len().is_multiple_of(2) {
            return Err(StateError::OddLength { len: z.len() });
        }
        Ok(State::from_vector(z))
    }

    /// True when every entry is finite.
    ///
    /// ```
    /// assert!(!geoshake_runtime::State::from_slices(&[f64::NAN], &[0.0]).is_finite());
    /// ```
    pub fn is_finite(&self) -> bool {
        self.q.iter().chain(self.p.iter()).all(|x| x.is_finite())
    }

    /// max(‖q − q'‖∞, ‖p − p'‖∞).
    ///
    /// ```
    /// use geoshake_runtime::State;
    /// let a = State::from_slices(&[1.0], &[0.0]);
    /// let b = State::from_slices(&[1.0], &[1e-3]);
    /// assert_eq!(a.distance(&b), 1e-3);
    /// ```
    pub fn distance(&self, other: &State) -> f64 {
        (&self.q - &other.q).amax().max((&self.p - &other.p).amax())
    }
}
