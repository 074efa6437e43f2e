//! Checks of the hand-written models of `common/models.rs`, which are the
//! runtime's test systems and the benchmarks' hand-written baseline:
//! every derivative against a fourth-order central difference of the level
//! below (accuracy ~1e-9 with δ = 1e-3 for these polynomial/trigonometric
//! functions; checked at 1e-7), the brackets against their definitions, and
//! the storage contract (only pattern entries written, fibre flow = kick).

use crate::common;

use common::models::*;
use geoshake::{ConstrainedSystem, FibreFlow};

const DELTA: f64 = 1e-3;
const TOL: f64 = 1e-7;

/// d/dz_k of a vector function at z by a fourth-order central difference.
fn fd(f: &mut dyn FnMut(&[f64]) -> Vec<f64>, z: &[f64], k: usize) -> Vec<f64> {
    let at = |s: f64| {
        let mut w = z.to_vec();
        w[k] += s * DELTA;
        w
    };
    let (a, b, c, d) = (f(&at(-2.0)), f(&at(-1.0)), f(&at(1.0)), f(&at(2.0)));
    (0..a.len())
        .map(|i| (a[i] - 8.0 * b[i] + 8.0 * c[i] - d[i]) / (12.0 * DELTA))
        .collect()
}

fn check_model<S: ConstrainedSystem + Clone>(name: &str, sys: &S, z: &[f64]) {
    let (d, m) = (sys.dof(), sys.constraint_count());
    let n = 2 * d;
    let split = |w: &[f64]| (w[..d].to_vec(), w[d..].to_vec());
    let grad = |w: &[f64]| {
        let (q, p) = split(w);
        let (mut hq, mut hp) = (vec![0.0; d], vec![0.0; d]);
        sys.grad_q(&q, &p, &mut hq);
        sys.grad_p(&q, &p, &mut hp);
        [hq, hp].concat()
    };
    let g = |w: &[f64]| {
        let (q, p) = split(w);
        let mut out = vec![0.0; m];
        sys.constraints(&q, &p, &mut out);
        out
    };
    let gz = |w: &[f64]| {
        let (q, p) = split(w);
        let mut out = vec![0.0; m * n];
        sys.constraint_jacobian(&q, &p, &mut out);
        out
    };
    let hidden = |w: &[f64]| {
        let (q, p) = split(w);
        let mut out = vec![0.0; m];
        sys.hidden_constraints(&q, &p, &mut out);
        out
    };
    let (q, p) = split(z);
    let close = |what: &str, a: f64, b: f64| {
        assert!(
            (a - b).abs() <= TOL * (1.0 + b.abs()),
            "{name}: {what}: {a} vs {b}"
        );
    };
    // ∇H, H_zz.
    let g0 = grad(z);
    let mut hzz = vec![0.0; n * n];
    sys.hessian(&q, &p, &mut hzz);
    for k in 0..n {
        let dh = fd(&mut |w| vec![sys.hamiltonian(&w[..d], &w[d..])], z, k);
        close(&format!("∇H[{k}]"), g0[k], dh[0]);
        let col = fd(&mut |w| grad(w), z, k);
        for i in 0..n {
            close(&format!("H_zz[{i},{k}]"), hzz[i + k * n], col[i]);
        }
    }
    // g_z, Σλ∇²g, hidden constraints, their Jacobian, N.
    let j0 = gz(z);
    let lambda: Vec<f64> = (0..m).map(|i| 0.7 - 0.4 * i as f64).collect();
    let mut lh = vec![0.0; n * n];
    sys.constraint_hessian(&q, &p, &lambda, &mut lh);
    let mut hj = vec![0.0; m * n];
    sys.hidden_constraint_jacobian(&q, &p, &mut hj);
    let mut nm = vec![0.0; m * m];
    sys.nondegeneracy_matrix(&q, &p, &mut nm);
    let h0 = hidden(z);
    for i in 0..m {
        // {g_i, H} = g_q·H_p − g_p·H_q.
        let bracket: f64 = (0..d)
            .map(|k| j0[i + k * m] * g0[d + k] - j0[i + (d + k) * m] * g0[k])
            .sum();
        close(&format!("{{g_{i},H}}"), h0[i], bracket);
        for j in 0..m {
            // N_ij = {{H,g_i},g_j} = −d{g_i,H}·X_{g_j}, X_g = (g_p, −g_q).
            let v: f64 = (0..d)
                .map(|k| hj[i + k * m] * j0[j + (d + k) * m] - hj[i + (d + k) * m] * j0[j + k * m])
                .sum();
            close(&format!("N[{i},{j}]"), nm[i + j * m], -v);
        }
    }
    for k in 0..n {
        let dg = fd(&mut |w| g(w), z, k);
        let dj = fd(&mut |w| gz(w), z, k);
        let dhid = fd(&mut |w| hidden(w), z, k);
        for i in 0..m {
            close(&format!("g_z[{i},{k}]"), j0[i + k * m], dg[i]);
            close(&format!("hidden_jac[{i},{k}]"), hj[i + k * m], dhid[i]);
        }
        for r in 0..n {
            let want: f64 = (0..m).map(|i| lambda[i] * dj[i + r * m]).sum();
            close(&format!("Σλ∇²g[{r},{k}]"), lh[r + k * n], want);
        }
    }
    // Only the declared pattern of g_z is written.
    let mut sentinel = vec![f64::NAN; m * n];
    sys.constraint_jacobian(&q, &p, &mut sentinel);
    for i in 0..m {
        for k in 0..n {
            let declared = sys.jacobian_pattern().contains(&(i, k));
            assert_eq!(
                !sentinel[i + k * m].is_nan(),
                declared,
                "{name}: g_z[{i},{k}] vs JACOBIAN_PATTERN"
            );
        }
    }
    // The closed-form fibre flow is the flow of Σλ X_g: compare with the
    // runtime's own (kick or matrix exponential) on the same system.
    let (mut qa, mut pa) = (q.clone(), p.clone());
    assert!(
        sys.fibre_flow(&lambda, &mut qa, &mut pa).applied(),
        "{name}: no closed form"
    );
    let wrapped = NoClosedForm(sys.clone());
    let (mut qb, mut pb) = (q.clone(), p.clone());
    FibreFlow::new(&wrapped)
        .apply(&wrapped, &lambda, &mut qb, &mut pb)
        .unwrap();
    for k in 0..d {
        assert!(
            (qa[k] - qb[k]).abs() < 1e-14 && (pa[k] - pb[k]).abs() < 1e-14,
            "{name}: fibre flow"
        );
    }
}

#[test]
fn pendulum() {
    check_model(
        "pendulum",
        &Pendulum {
            gravity: 9.81,
            length: 2.0,
        },
        &[1.1, -1.6, 0.3, -0.7],
    );
}

#[test]
fn non_separable_pendulum() {
    check_model(
        "non-separable",
        &NonSeparablePendulum::default(),
        &[0.6, -0.8, 0.5, 0.2],
    );
}

#[test]
fn spherical_pendulum() {
    check_model(
        "spherical",
        &SphericalPendulum::default(),
        &[0.3, -0.5, -0.8, 0.4, 0.1, -0.6],
    );
}

#[test]
fn double_pendulum() {
    let sys = DoublePendulum {
        l1: 1.2,
        l2: 0.7,
        m1: 2.0,
        m2: 0.5,
        gravity: 9.81,
    };
    check_model("double", &sys, &[0.5, -1.0, 0.9, -1.4, 0.3, 0.2, -0.4, 0.6]);
}

#[test]
fn hopf() {
    check_model("Hopf free", &Hopf::free(), &[0.3, -0.5, 0.6, 0.2]);
    check_model("Hopf gravity", &Hopf::gravity(), &[0.3, -0.5, 0.6, 0.2]);
}

#[test]
fn failing_systems() {
    check_model("index five", &IndexFive, &[0.3, -0.5, 0.6, 0.2]);
    check_model("flat fibres", &FlatFibres, &[0.3, -0.5, 0.6, 0.2]);
    check_model("sign change", &SignChange, &[0.3, -0.5, 0.6, 0.2]);
}
