//! The base map written outside the runtime in `examples/custom_base_map.rs`
//! (Yoshida's triple jump of Störmer–Verlet, against the public API only),
//! taken from the example's own file, passes the checks of the built-in
//! maps:
//!
//! - order: the map alone has order 4 on the harmonic oscillator (exact
//!   solution); RATTLE over it has order 2 on the pendulum (the fibre step
//!   limits geometric RATTLE to 2, as for the built-in maps), and RATTLE over
//!   it composed by the triple jump has order 4 (reference: the angle ODE by
//!   RK4 at a tiny step, independent code). Observed orders log2(e(h)/e(h/2))
//!   over h = 0.05, 0.025, 0.0125, accepted within ±0.15 as in
//!   `tests/suite/runtime_convergence.rs`;
//! - symplecticity (Proposition 4.4, Corollary 4.6): ω(DR u, DR v) = ω(u, v)
//!   on TM^H for RATTLE, ω preserved on TM for SHAKE, by sixth-order central
//!   differences with δ = 1e-3 (accurate to ~1e-11; checked at 1e-9, as in
//!   `tests/suite/runtime_symplectic.rs`).

// The example as a module: its base map and the error drivers whose table
// it prints, so that what it shows is what is checked here. Its `main` and
// table formatting are not called.
#[allow(dead_code)]
#[path = "../../examples/custom_base_map.rs"]
mod example;

use example::{free_error, rattle_error, Yoshida4};
use geoshake::models::Pendulum;
use geoshake::runtime::examples::HarmonicOscillator;
use geoshake::{
    Composition, ConstrainedSystem, Integrator, Method, Options, State, StormerVerlet,
    Unconstrained,
};
use geoshake_testkit::reference::pendulum_state;
use nalgebra::{DMatrix, DVector};

const STEPS: [f64; 3] = [0.05, 0.025, 0.0125];

fn orders(e: &[f64]) -> Vec<f64> {
    e.windows(2).map(|w| (w[0] / w[1]).log2()).collect()
}

fn assert_order(name: &str, e: &[f64], expected: f64) {
    let o = orders(e);
    println!("{name}: errors {e:?}, orders {o:.3?}");
    assert!(
        o.iter().all(|x| (x - expected).abs() < 0.15),
        "{name}: observed orders {o:?}, expected {expected}"
    );
}

#[test]
fn the_map_alone_has_order_4() {
    let integ = Integrator::new(
        Unconstrained(HarmonicOscillator),
        Yoshida4(StormerVerlet),
        0.1,
    );
    assert_eq!(integ.order(), 4);
    let e: Vec<f64> = STEPS
        .iter()
        .map(|&h| free_error(Yoshida4(StormerVerlet), h))
        .collect();
    assert_order("φ_h on q'' = −q", &e, 4.0);
}

/// Global error at T = 1 of RATTLE over Yoshida4(SV) composed by `c`, for
/// the pendulum swinging from θ = 1 (the example's column).
fn pendulum_errors(c: Composition, expected_order: u32) -> Vec<f64> {
    let integ = Integrator::new(Pendulum::new(1.0, 9.81), Yoshida4(StormerVerlet), 0.1)
        .rattle()
        .composed(c);
    assert_eq!(integ.order(), expected_order);
    STEPS
        .iter()
        .map(|&h| rattle_error(Yoshida4(StormerVerlet), c, h))
        .collect()
}

#[test]
fn rattle_over_it_has_order_2_and_composed_order_4() {
    assert_order(
        "RATTLE over φ_h",
        &pendulum_errors(Composition::SINGLE, 2),
        2.0,
    );
    assert_order(
        "RATTLE over φ_h, triple jump",
        &pendulum_errors(Composition::TRIPLE_JUMP, 4),
        4.0,
    );
}

const DELTA: f64 = 1e-3;
const TOL: f64 = 1e-9;

fn omega(u: &DVector<f64>, v: &DVector<f64>) -> f64 {
    let d = u.len() / 2;
    (0..d).map(|k| u[k] * v[d + k] - u[d + k] * v[k]).sum()
}

/// Orthonormal basis of ker A.
fn kernel(a: &DMatrix<f64>) -> Vec<DVector<f64>> {
    let eig = (a.transpose() * a).symmetric_eigen();
    (0..a.ncols())
        .filter(|&i| eig.eigenvalues[i].abs() < 1e-10)
        .map(|i| eig.eigenvectors.column(i).into_owned())
        .collect()
}

/// Max |ω(DΦ u_i, DΦ u_j) − ω(u_i, u_j)| over the basis `tangent`, Φ one
/// step of `method` over Yoshida4(SV), DΦ by sixth-order differences.
fn defect(method: Method, z0: &State, tangent: &[DVector<f64>]) -> f64 {
    let opts = Options {
        constraint_tolerance: 0.1,
        ..Options::default()
    };
    let mut integ = Integrator::new(Pendulum::new(1.0, 9.81), Yoshida4(StormerVerlet), 0.1)
        .with_method(method)
        .with_options(opts);
    let z = z0.to_vector();
    let mut image = |u: &DVector<f64>| {
        let mut f = |s: f64| {
            integ
                .step(&State::from_vector(&(&z + u * (s * DELTA))))
                .unwrap()
                .to_vector()
        };
        (f(-3.0) * -1.0 + f(-2.0) * 9.0 - f(-1.0) * 45.0 + f(1.0) * 45.0 - f(2.0) * 9.0 + f(3.0))
            / (60.0 * DELTA)
    };
    let images: Vec<_> = tangent.iter().map(&mut image).collect();
    let mut worst: f64 = 0.0;
    for i in 0..tangent.len() {
        for j in i + 1..tangent.len() {
            let w = omega(&images[i], &images[j]) - omega(&tangent[i], &tangent[j]);
            worst = worst.max(w.abs());
        }
    }
    worst
}

#[test]
fn shake_and_rattle_over_it_are_symplectic() {
    let sys = Pendulum::new(1.0, 9.81);
    let z0 = pendulum_state(1.0, 0.7, 1.3);
    let (q, p) = (z0.q.as_slice(), z0.p.as_slice());
    let (mut gz, mut hz) = ([0.0; 4], [0.0; 4]);
    sys.constraint_jacobian(q, p, &mut gz);
    sys.hidden_constraint_jacobian(q, p, &mut hz);
    let gz = DMatrix::from_column_slice(1, 4, &gz);
    let both = DMatrix::from_fn(2, 4, |i, j| if i == 0 { gz[(0, j)] } else { hz[j] });
    let tm = kernel(&gz);
    let tmh = kernel(&both);
    assert_eq!((tm.len(), tmh.len()), (3, 2));
    let s = defect(Method::Shake, &z0, &tm);
    let r = defect(Method::Rattle, &z0, &tmh);
    println!("SHAKE on TM: {s:.1e}   RATTLE on TM^H: {r:.1e}");
    assert!(s < TOL, "SHAKE over Yoshida4 not presymplectic: {s:e}");
    assert!(r < TOL, "RATTLE over Yoshida4 not symplectic on M^H: {r:e}");
    // The check can fail: a generic pair off TM is not preserved by SHAKE.
    let off = [
        DVector::from_vec(vec![1.0, 0.0, 0.0, 0.0]),
        DVector::from_vec(vec![0.0, 0.0, 1.0, 0.0]),
    ];
    assert!(defect(Method::Shake, &z0, &off) > 1e-3);
}
