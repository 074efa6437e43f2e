//! The buffers of the built-in base maps.

/// Buffers for a base map: the stage values of the last application (kept
/// for its tangent map and for warm starts), gradient and Hessian outputs
/// (zeroed once here, written only by the system), and Newton matrices.
///
/// ```
/// use geoshake_runtime::BaseMapWorkspace;
/// let ws = BaseMapWorkspace::new(2);
/// assert_eq!(ws.dof(), 2);
/// ```
#[derive(Clone, Debug)]
pub struct BaseMapWorkspace {
    pub(super) d: usize,
    /// The input point y = (q0, p0) of the last application.
    pub(super) y: Vec<f64>,
    /// The input point of the application before (for warm starts).
    pub(super) y_prev: Vec<f64>,
    /// Stage unknowns: midpoint m (2d); SV p½ then q1; Euler p1.
    pub(super) stage: Vec<f64>,
    pub(super) warm: bool,
    /// Whether the prepared tangent map is that of a separable H (no stage
    /// matrices to solve with).
    pub(super) tangent_separable: bool,
    // Outputs of the system, one buffer per use, written only by it.
    pub(super) h_q: Vec<f64>,
    pub(super) h_p: Vec<f64>,
    pub(super) h_p_a: Vec<f64>,
    pub(super) hess_a: Vec<f64>,
    pub(super) hess_b: Vec<f64>,
    // Our own matrices and vectors (fully overwritten before each use).
    pub(super) mat: Vec<f64>,
    pub(super) piv: Vec<usize>,
    pub(super) mat_b: Vec<f64>,
    pub(super) piv_b: Vec<usize>,
    pub(super) res: Vec<f64>,
    pub(super) tmp: Vec<f64>,
}

impl BaseMapWorkspace {
    /// Buffers for a system with `d` degrees of freedom.
    ///
    /// ```
    /// let ws = geoshake_runtime::BaseMapWorkspace::new(3);
    /// assert_eq!(ws.dof(), 3);
    /// ```
    pub fn new(d: usize) -> Self {
        let n = 2 * d;
        BaseMapWorkspace {
            d,
            y: vec![0.0; n],
            y_prev: vec![0.0; n],
            stage: vec![0.0; n],
            warm: false,
            tangent_separable: false,
            h_q: vec![0.0; d],
            h_p: vec![0.0; d],
            h_p_a: vec![0.0; d],
            hess_a: vec![0.0; n * n],
            hess_b: vec![0.0; n * n],
            mat: vec![0.0; n * n],
            piv: vec![0; n],
            mat_b: vec![0.0; n * n],
            piv_b: vec![0; n],
            res: vec![0.0; n],
            tmp: vec![0.0; n],
        }
    }

    /// The number d of degrees of freedom these buffers are for.
    ///
    /// ```
    /// assert_eq!(geoshake_runtime::BaseMapWorkspace::new(4).dof(), 4);
    /// ```
    pub fn dof(&self) -> usize {
        self.d
    }

    /// Forget the last stage values: the next application starts its
    /// Newton iteration from an explicit predictor instead.
    ///
    /// ```
    /// let mut ws = geoshake_runtime::BaseMapWorkspace::new(2);
    /// ws.reset_warm_start();
    /// ```
    pub fn reset_warm_start(&mut self) {
        self.warm = false;
    }

    /// Records the new input point and says whether the stored stage can be
    /// shifted to it as the initial guess.
    pub(super) fn begin(&mut self, q: &[f64], p: &[f64]) -> bool {
        let d = self.d;
        std::mem::swap(&mut self.y, &mut self.y_prev);
        self.y[..d].copy_from_slice(q);
        self.y[d..].copy_from_slice(p);
        self.warm
    }
}
