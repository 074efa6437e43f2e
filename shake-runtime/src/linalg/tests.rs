//! Tests of the dense and banded kernels against direct computations.

use super::*;

#[test]
fn lu_solves_and_transposed_solves() {
    // A = [[2, 1, 0], [1, 3, 1], [0, 1, 0.5]] column-major.
    let a0 = [2.0, 1.0, 0.0, 1.0, 3.0, 1.0, 0.0, 1.0, 0.5];
    let mut lu = a0;
    let mut piv = [0; 3];
    lu_factor(&mut lu, 3, &mut piv).unwrap();
    let x_true = [1.0, -2.0, 0.5];
    for transpose in [false, true] {
        let mut b = [0.0; 3];
        for i in 0..3 {
            for j in 0..3 {
                let aij = if transpose {
                    a0[j + i * 3]
                } else {
                    a0[i + j * 3]
                };
                b[i] += aij * x_true[j];
            }
        }
        if transpose {
            lu_solve_transpose(&lu, 3, &piv, &mut b);
        } else {
            lu_solve(&lu, 3, &piv, &mut b);
        }
        for i in 0..3 {
            assert!((b[i] - x_true[i]).abs() < 1e-14);
        }
    }
    // det = 2(1.5 - 1) - 1(0.5 - 0) = 0.5
    assert!((lu_det(&lu, 3, &piv) - 0.5).abs() < 1e-14);
    let mut x = [0.0; 3];
    let mut z = [0.0; 3];
    let est = inverse_norm1_estimate(&lu, 3, &piv, &mut x, &mut z);
    // A⁻¹ = [[1, -1, 2], [-1, 2, -4], [2, -4, 10]]: ‖A⁻¹‖₁ = 16.
    assert!((est - 16.0).abs() < 1e-12, "{est}");
}

/// A random-looking n×n matrix with the given band, diagonally weak so
/// that partial pivoting actually swaps rows.
fn banded(n: usize, band: Band) -> Vec<f64> {
    let mut a = vec![0.0; n * n];
    let mut x = 0.3f64;
    for j in 0..n {
        for i in j.saturating_sub(band.upper)..=(j + band.lower).min(n - 1) {
            x = (x * 3.7 + 0.11).fract();
            a[i + j * n] = x - 0.5 + if i == j { 0.05 } else { 0.0 };
        }
    }
    a
}

#[test]
fn banded_lu_agrees_with_dense_lu() {
    let n = 40;
    for band in [
        Band { lower: 1, upper: 1 },
        Band { lower: 2, upper: 0 },
        Band { lower: 0, upper: 3 },
        Band { lower: 3, upper: 2 },
    ] {
        let a0 = banded(n, band);
        assert_eq!(Band::of(&a0, n), band);
        let x_true: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        // b = A x and c = Aᵀ x.
        let mut b = vec![0.0; n];
        let mut c = vec![0.0; n];
        for i in 0..n {
            for j in 0..n {
                b[i] += a0[i + j * n] * x_true[j];
                c[i] += a0[j + i * n] * x_true[j];
            }
        }
        let mut dense = a0.clone();
        let mut piv_d = vec![0; n];
        lu_factor(&mut dense, n, &mut piv_d).unwrap();
        let mut lu = a0.clone();
        let mut piv = vec![0; n + 2];
        lu_factor(&mut lu, n, &mut piv).unwrap();
        assert_eq!(recorded_band(&piv, n), Some(band), "auto-detected band");
        let (mut xb, mut xc) = (b.clone(), c.clone());
        lu_solve(&lu, n, &piv, &mut xb);
        lu_solve_transpose(&lu, n, &piv, &mut xc);
        // Against the dense solves (these random matrices can be badly
        // conditioned, so x_true itself is only the scale).
        let (mut db, mut dc) = (b.clone(), c.clone());
        lu_solve(&dense, n, &piv_d, &mut db);
        lu_solve_transpose(&dense, n, &piv_d, &mut dc);
        let scale = norm_inf(&db).max(norm_inf(&dc));
        for i in 0..n {
            assert!((xb[i] - db[i]).abs() < 1e-9 * scale, "{band:?} {i}");
            assert!((xc[i] - dc[i]).abs() < 1e-9 * scale, "{band:?} {i}");
        }
        // Residuals of the banded solves.
        for i in 0..n {
            let (mut rb, mut rc) = (-b[i], -c[i]);
            for j in 0..n {
                rb += a0[i + j * n] * xb[j];
                rc += a0[j + i * n] * xc[j];
            }
            assert!(
                rb.abs() < 1e-10 * scale && rc.abs() < 1e-10 * scale,
                "{band:?} {i}"
            );
        }
        let (dd, db) = (lu_det(&dense, n, &piv_d), lu_det(&lu, n, &piv));
        assert!((dd - db).abs() <= 1e-10 * dd.abs(), "{dd} {db}");
        let (mut s1, mut s2) = (vec![0.0; n], vec![0.0; n]);
        let ed = inverse_norm1_estimate(&dense, n, &piv_d, &mut s1, &mut s2);
        let eb = inverse_norm1_estimate(&lu, n, &piv, &mut s1, &mut s2);
        assert!((ed - eb).abs() <= 1e-8 * ed, "{ed} {eb}");
    }
}

#[test]
fn singular_is_reported() {
    let mut a = [1.0, 2.0, 2.0, 4.0];
    let mut piv = [0; 2];
    assert_eq!(lu_factor(&mut a, 2, &mut piv), Err(Singular));
}

#[test]
fn expm_of_a_generator_of_rotations() {
    let theta = 7.3;
    let mut a = [0.0, theta, -theta, 0.0];
    let (mut t1, mut t2, mut t3) = ([0.0; 4], [0.0; 4], [0.0; 4]);
    expm(&mut a, 2, &mut t1, &mut t2, &mut t3);
    let (c, s) = (theta.cos(), theta.sin());
    let want = [c, s, -s, c];
    for i in 0..4 {
        assert!((a[i] - want[i]).abs() < 1e-14, "{a:?} {want:?}");
    }
}

#[test]
fn the_tridiagonal_kernels_give_the_general_kernels_bits() {
    let band = Band { lower: 1, upper: 1 };
    for n in [1, 2, 3, 16, 41] {
        // `banded` pivots in about half of the columns; the diagonally
        // dominant variant never does; the third has ties (|below| =
        // |diagonal|: no interchange), exact zeros off the diagonal and
        // −0.0 in the fill (row k, column k + 2), whose sign the factors
        // keep.
        for variant in 0..3 {
            let dominant = variant == 1;
            let mut a = banded(n, band);
            if dominant {
                for j in 0..n {
                    a[j + j * n] += 4.0;
                }
            }
            if variant == 2 {
                for j in 0..n {
                    if j + 1 < n {
                        a[j + 1 + j * n] = if j % 3 == 0 { -a[j + j * n] } else { 0.0 };
                    }
                    if j + 2 < n {
                        a[j + (j + 2) * n] = -0.0;
                    }
                }
            }
            let (mut lu_w, mut piv_w) = (a.clone(), vec![0; n]);
            band_lu_factor_w(&mut lu_w, n, 1, 2, &mut piv_w).unwrap();
            let (mut lu_t, mut piv_t) = (a.clone(), vec![0; n]);
            band_lu_factor(&mut lu_t, n, band, &mut piv_t).unwrap();
            assert_eq!(piv_t, piv_w, "n {n}");
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&lu_t), bits(&lu_w), "n {n}");
            if variant == 0 && n >= 16 {
                assert!(
                    piv_w.iter().enumerate().any(|(k, p)| *p != k),
                    "n {n} pivots"
                );
            }
            let b0: Vec<f64> = (0..n).map(|i| (i as f64 * 0.7).sin() + 0.1).collect();
            let (mut x_w, mut x_t) = (b0.clone(), b0.clone());
            band_lu_solve_w(&lu_w, n, 1, 2, &piv_w, &mut x_w);
            band_lu_solve(&lu_t, n, band, &piv_t, &mut x_t);
            assert_eq!(bits(&x_t), bits(&x_w), "solve n {n}");
            let (mut y_w, mut y_t) = (b0.clone(), b0.clone());
            band_lu_solve_transpose_w(&lu_w, n, 1, 2, &piv_w, &mut y_w);
            band_lu_solve_transpose(&lu_t, n, band, &piv_t, &mut y_t);
            assert_eq!(bits(&y_t), bits(&y_w), "transposed solve n {n}");
            // And both solve the system (the kernels' agreement is not
            // agreement on a wrong answer).
            for i in 0..n {
                let (mut r, mut rt) = (-b0[i], -b0[i]);
                for j in i.saturating_sub(1)..(i + 2).min(n) {
                    r += a[i + j * n] * x_t[j];
                    rt += a[j + i * n] * y_t[j];
                }
                assert!(
                    r.abs() < 1e-10 && rt.abs() < 1e-10,
                    "n {n} row {i}: {r} {rt}"
                );
            }
        }
    }
    // A zero column is refused, and so is a non-finite pivot, in the first
    // column and in the last; the two kernels agree on each.
    let cases: [(&[usize], f64); 4] = [
        (&[0, 1], 0.0),
        (&[0], f64::NAN),
        (&[7, 8], 0.0),
        (&[8], f64::INFINITY),
    ];
    for (at, v) in cases {
        let mut z = vec![1.0, 0.5, 0.0, 0.5, 1.0, 0.5, 0.0, 0.5, 1.0];
        for &i in at {
            z[i] = v;
        }
        let mut piv = vec![0; 3];
        let (mut w, mut piv_w) = (z.clone(), vec![0; 3]);
        let general = band_lu_factor_w(&mut w, 3, 1, 2, &mut piv_w);
        assert_eq!(general, Err(Singular), "{at:?} {v}");
        assert_eq!(
            band_lu_factor(&mut z, 3, band, &mut piv),
            general,
            "{at:?} {v}"
        );
    }
}

#[test]
fn small_banded_kernels_give_the_run_time_size_bits() {
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    for n in 2..=9 {
        let band = Band::full(n);
        let a = banded(n, band);
        let (mut lu, mut piv) = (a.clone(), vec![0; n]);
        band_lu_factor(&mut lu, n, band, &mut piv).unwrap();
        let n_rt = std::hint::black_box(n);
        let (mut lu_r, mut piv_r) = (a.clone(), vec![0; n]);
        band_lu_factor_w(&mut lu_r, n_rt, n_rt - 1, 2 * n_rt - 2, &mut piv_r).unwrap();
        assert_eq!((bits(&lu), &piv), (bits(&lu_r), &piv_r), "n {n}");
        let b0: Vec<f64> = (0..n).map(|i| 0.5 - 0.2 * i as f64).collect();
        let (mut x, mut x_r) = (b0.clone(), b0.clone());
        band_lu_solve(&lu, n, band, &piv, &mut x);
        band_lu_solve_w(&lu_r, n_rt, n_rt - 1, 2 * n_rt - 2, &piv_r, &mut x_r);
        assert_eq!(bits(&x), bits(&x_r), "solve n {n}");
        let (mut y, mut y_r) = (b0.clone(), b0.clone());
        band_lu_solve_transpose(&lu, n, band, &piv, &mut y);
        band_lu_solve_transpose_w(&lu_r, n_rt, n_rt - 1, 2 * n_rt - 2, &piv_r, &mut y_r);
        assert_eq!(bits(&y), bits(&y_r), "transposed solve n {n}");
    }
}

#[test]
fn norm_inf_and_all_finite_in_lanes_agree_with_one_pass() {
    let serial = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for n in 0..13 {
        let mut v: Vec<f64> = (0..n)
            .map(|i| ((i * 7 % 5) as f64 - 2.0) * 1.5f64.powi(i as i32))
            .collect();
        assert_eq!(norm_inf(&v).to_bits(), serial(&v).to_bits(), "n {n}");
        assert!(all_finite(&v));
        for k in 0..n {
            // NaN is skipped by both (and found by all_finite); an infinity
            // is the norm wherever it sits.
            let keep = v[k];
            v[k] = f64::NAN;
            assert_eq!(
                norm_inf(&v).to_bits(),
                serial(&v).to_bits(),
                "n {n} NaN at {k}"
            );
            assert!(!all_finite(&v), "n {n} NaN at {k}");
            v[k] = -f64::INFINITY;
            assert_eq!(norm_inf(&v), f64::INFINITY, "n {n} inf at {k}");
            assert!(!all_finite(&v));
            v[k] = keep;
        }
    }
}

#[test]
fn small_kernels_of_every_size_solve_and_give_the_run_time_size_bits() {
    for n in 1..=10 {
        let a = banded(n, Band::full(n));
        let b0: Vec<f64> = (0..n).map(|i| 1.0 - 0.3 * i as f64).collect();
        // The dense path (`lu_factor` without spare pivot slots) and the
        // banded one with a full band.
        let (mut lu, mut piv) = (a.clone(), vec![0; n]);
        lu_factor(&mut lu, n, &mut piv).unwrap();
        let (mut lu_b, mut piv_b) = (a.clone(), vec![0; n]);
        band_lu_factor(&mut lu_b, n, Band::full(n), &mut piv_b).unwrap();
        let (mut lu_r, mut piv_r) = (a.clone(), vec![0; n]);
        // The same kernels at a size the compiler does not know.
        let n_rt = std::hint::black_box(n);
        dense_lu_factor(&mut lu_r, n_rt, &mut piv_r).unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&lu), bits(&lu_r), "n {n}");
        for transpose in [false, true] {
            let (mut x, mut xb, mut xr) = (b0.clone(), b0.clone(), b0.clone());
            if transpose {
                lu_solve_transpose(&lu, n, &piv, &mut x);
                band_lu_solve_transpose(&lu_b, n, Band::full(n), &piv_b, &mut xb);
                dense_lu_solve_transpose(&lu_r, n_rt, &piv_r, &mut xr);
            } else {
                lu_solve(&lu, n, &piv, &mut x);
                band_lu_solve(&lu_b, n, Band::full(n), &piv_b, &mut xb);
                dense_lu_solve(&lu_r, n_rt, &piv_r, &mut xr);
            }
            assert_eq!(bits(&x), bits(&xr), "n {n} transpose {transpose}");
            for (x, name) in [(&x, "dense"), (&xb, "banded")] {
                for i in 0..n {
                    let mut r = -b0[i];
                    for j in 0..n {
                        let aij = if transpose {
                            a[j + i * n]
                        } else {
                            a[i + j * n]
                        };
                        r += aij * x[j];
                    }
                    assert!(
                        r.abs() < 1e-10,
                        "{name} n {n} transpose {transpose} row {i}: {r}"
                    );
                }
            }
        }
    }
}
