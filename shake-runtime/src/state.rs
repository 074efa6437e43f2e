//! A point z = (q, p) of phase space R^{2d}.

use nalgebra::DVector;

/// A phase-space point z = (q, p), with q, p ∈ R^d as nalgebra vectors.
///
/// ```
/// use shake_runtime::State;
/// let z = State::from_slices(&[1.0, 0.0], &[0.0, 0.5]);
/// assert_eq!(z.dof(), 2);
/// assert_eq!(z.p[1], 0.5);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    /// Positions q ∈ R^d.
    pub q: DVector<f64>,
    /// Momenta p ∈ R^d.
    pub p: DVector<f64>,
}

impl State {
    /// A state from its two halves (of equal length).
    ///
    /// ```
    /// use shake_runtime::{State, nalgebra::DVector};
    /// let z = State::new(DVector::from_vec(vec![1.0]), DVector::from_vec(vec![2.0]));
    /// assert_eq!(z.q[0], 1.0);
    /// ```
    pub fn new(q: DVector<f64>, p: DVector<f64>) -> Self {
        assert_eq!(q.len(), p.len(), "q and p must have the same length");
        State { q, p }
    }

    /// A state copied from two slices of equal length.
    ///
    /// ```
    /// let z = shake_runtime::State::from_slices(&[0.0, -1.0], &[1.0, 0.0]);
    /// assert_eq!(z.q[1], -1.0);
    /// ```
    pub fn from_slices(q: &[f64], p: &[f64]) -> Self {
        State::new(DVector::from_column_slice(q), DVector::from_column_slice(p))
    }

    /// The origin of R^{2d}.
    ///
    /// ```
    /// assert_eq!(shake_runtime::State::zeros(3).q.len(), 3);
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
    /// assert_eq!(shake_runtime::State::zeros(2).dof(), 2);
    /// ```
    pub fn dof(&self) -> usize {
        self.q.len()
    }

    /// z = (q, p) as one vector of length 2d.
    ///
    /// ```
    /// let z = shake_runtime::State::from_slices(&[1.0], &[2.0]).to_vector();
    /// assert_eq!(z.as_slice(), &[1.0, 2.0]);
    /// ```
    pub fn to_vector(&self) -> DVector<f64> {
        let d = self.dof();
        DVector::from_fn(2 * d, |i, _| if i < d { self.q[i] } else { self.p[i - d] })
    }

    /// The state with z = (q, p) given as one vector of even length.
    ///
    /// ```
    /// use shake_runtime::{State, nalgebra::DVector};
    /// let z = State::from_vector(&DVector::from_vec(vec![1.0, 2.0]));
    /// assert_eq!((z.q[0], z.p[0]), (1.0, 2.0));
    /// ```
    pub fn from_vector(z: &DVector<f64>) -> Self {
        assert!(z.len() & 1 == 0, "z must have even length 2d");
        let d = z.len() / 2;
        State::from_slices(&z.as_slice()[..d], &z.as_slice()[d..])
    }

    /// True when every entry is finite.
    ///
    /// ```
    /// assert!(!shake_runtime::State::from_slices(&[f64::NAN], &[0.0]).is_finite());
    /// ```
    pub fn is_finite(&self) -> bool {
        self.q.iter().chain(self.p.iter()).all(|x| x.is_finite())
    }

    /// max(‖q − q'‖∞, ‖p − p'‖∞).
    ///
    /// ```
    /// use shake_runtime::State;
    /// let a = State::from_slices(&[1.0], &[0.0]);
    /// let b = State::from_slices(&[1.0], &[1e-3]);
    /// assert_eq!(a.distance(&b), 1e-3);
    /// ```
    pub fn distance(&self, other: &State) -> f64 {
        (&self.q - &other.q).amax().max((&self.p - &other.p).amax())
    }
}
