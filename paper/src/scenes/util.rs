//! Small measurements shared by the scenes.

use geoshake::State;
use nalgebra::{DMatrix, DVector};

/// z = (q, p) as one vector.
pub fn z_of(s: &State) -> DVector<f64> {
    s.to_vector()
}

/// The state of a vector z = (q, p).
pub fn state_of(z: &DVector<f64>) -> State {
    State::from_vector(z)
}

/// ω(u, v) = Σ_k (u_q,k v_p,k − u_p,k v_q,k), the canonical symplectic form.
pub fn omega(u: &DVector<f64>, v: &DVector<f64>) -> f64 {
    let d = u.len() / 2;
    (0..d).map(|k| u[k] * v[d + k] - u[d + k] * v[k]).sum()
}

/// The component of w orthogonal to the given gradients: a tangent vector
/// of the level set they define.
pub fn tangent(grads: &[DVector<f64>], w: &DVector<f64>) -> DVector<f64> {
    let n = w.len();
    let k = grads.len();
    let g = DMatrix::from_fn(k, n, |i, j| grads[i][j]);
    let gram = &g * g.transpose();
    let coef = gram
        .lu()
        .solve(&(&g * w))
        .expect("the constraint gradients are independent at a regular point");
    w - g.transpose() * coef
}

/// The slope of log(err) against log(h) by least squares: the observed order.
pub fn observed_order(hs: &[f64], errs: &[f64]) -> f64 {
    let xs: Vec<f64> = hs.iter().map(|h| h.ln()).collect();
    let ys: Vec<f64> = errs.iter().map(|e| e.ln()).collect();
    let n = xs.len() as f64;
    let (mx, my) = (xs.iter().sum::<f64>() / n, ys.iter().sum::<f64>() / n);
    let sxy: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = xs.iter().map(|x| (x - mx) * (x - mx)).sum();
    sxy / sxx
}

/// Fourth-order central difference of a map along a curve through z:
/// D(F∘c)(0) ≈ (−F(c(2δ)) + 8F(c(δ)) − 8F(c(−δ)) + F(c(−2δ))) / 12δ,
/// truncation O(δ⁴), round-off O(ε/δ).
pub fn derivative_along<F>(mut f_of_c: F, delta: f64) -> Result<DVector<f64>, String>
where
    F: FnMut(f64) -> Result<DVector<f64>, String>,
{
    let a = f_of_c(2.0 * delta)?;
    let b = f_of_c(delta)?;
    let c = f_of_c(-delta)?;
    let d = f_of_c(-2.0 * delta)?;
    Ok((-a + b * 8.0 - c * 8.0 + d) / (12.0 * delta))
}

/// max |E − E0| over the first and over the last tenth of an energy record:
/// for a method without drift the two are alike.
pub fn energy_windows(energy: &[f64]) -> (f64, f64) {
    let e0 = energy[0];
    let w = (energy.len() / 10).max(1);
    let dev = |s: &[f64]| s.iter().map(|e| (e - e0).abs()).fold(0.0, f64::max);
    (dev(&energy[..w]), dev(&energy[energy.len() - w..]))
}
