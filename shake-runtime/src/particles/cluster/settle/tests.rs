//! Tests of the closed forms of a rigid triangle: SETTLE's answer solves
//! SHAKE's equations, the projection leaves every bond rigid, a batch
//! solves each triangle as alone, and the detection of triangles.

use super::*;

/// A small deterministic generator (xorshift*), uniform in [−1, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let r = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d);
        (r >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
    fn v3(&mut self, s: f64) -> V3 {
        [s * self.next(), s * self.next(), s * self.next()]
    }
}

/// One triangle's inputs in local order.
#[derive(Clone, Copy, Debug)]
struct Triangle {
    w: V3,
    d2: V3,
    x0: [V3; 3],
    xt: [V3; 3],
}

/// x1 and ν of one triangle solved alone.
struct Solved {
    x1: [V3; 3],
    nu: V3,
}

impl Triangle {
    fn solve(&self) -> Option<Solved> {
        let shape = Shape::new(self.w, self.d2);
        let s = solve(&shape, &self.x0, &self.xt);
        (shape.ok && s.valid()).then_some(Solved { x1: s.x1, nu: s.nu })
    }
}

/// One triangle's projection, in place: its judgement.
fn project1(x: &[V3; 3], w: V3, p: &mut [V3; 3]) -> Option<(f64, usize)> {
    let out = project(x, w, p);
    let judged = out.judge(0, &w, p);
    *p = out.p;
    judged
}

/// A triangle of the given lengths (pairs (0,1), (0,2), (1,2)) placed
/// at random about `at`, and x̃ = x0 + `kick` · random.
fn triangle(rng: &mut Rng, w: V3, d: V3, at: V3, kick: f64) -> Triangle {
    let px = (d[0] * d[0] + d[1] * d[1] - d[2] * d[2]) / (2.0 * d[0]);
    let py = (d[1] * d[1] - px * px).sqrt();
    let body = [[0.0, 0.0, 0.0], [d[0], 0.0, 0.0], [px, py, 0.0]];
    // A random rotation: Gram–Schmidt of two random vectors.
    let u = rng.v3(1.0);
    let u = scale(1.0 / dot(u, u).sqrt(), u);
    let v = rng.v3(1.0);
    let v = sub(v, scale(dot(u, v), u));
    let v = scale(1.0 / dot(v, v).sqrt(), v);
    let z = cross(u, v);
    let x0 = body.map(|b| {
        let mut x = at;
        for k in 0..3 {
            x[k] += b[0] * u[k] + b[1] * v[k] + b[2] * z[k];
        }
        x
    });
    let xt = x0.map(|x| {
        let r = rng.v3(kick);
        [x[0] + r[0], x[1] + r[1], x[2] + r[2]]
    });
    Triangle {
        w,
        d2: d.map(|d| d * d),
        x0,
        xt,
    }
}

/// The SHAKE equations themselves: x1 = x̃ − W G(x0)ᵀ ν (each
/// coordinate to a few ulps of the positions, times the condition of
/// recovering ν from Δ, here O(1)) and g(x1) = 0 (to a few ε, relative).
fn check_shake_equations(t: &Triangle, s: &Solved) {
    let size = t.xt.iter().flatten().fold(1.0f64, |m, v| m.max(v.abs()));
    let mut back = t.xt;
    for (k, &(i, j)) in PAIRS.iter().enumerate() {
        let e = sub(t.x0[i], t.x0[j]);
        for c in 0..3 {
            back[i][c] -= t.w[i] * 2.0 * s.nu[k] * e[c];
            back[j][c] += t.w[j] * 2.0 * s.nu[k] * e[c];
        }
    }
    for a in 0..3 {
        for c in 0..3 {
            let err = (back[a][c] - s.x1[a][c]).abs();
            assert!(err <= 64.0 * f64::EPSILON * size, "{err:e} at {a},{c}");
        }
    }
    let worst = residuals(&s.x1, t.d2).into_iter().fold(0.0, f64::max);
    assert!(worst <= 16.0 * f64::EPSILON * size, "residual {worst:e}");
}

#[test]
fn the_closed_form_solves_the_shake_equations() {
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    // Water (O, H, H: 1.0, 1.0, 1.633) and a scalene triangle with
    // masses 40 to 1, near the origin and far from it.
    let cases = [
        ([1.0 / 15.9994, 1.0 / 1.008, 1.0 / 1.008], [1.0, 1.0, 1.633]),
        ([1.0 / 7.0, 1.0 / 0.3, 1.0 / 12.0], [1.0, 1.3, 0.8]),
        ([1.0, 1.0 / 40.0, 1.0], [2.0, 1.1, 1.5]),
    ];
    for (w, d) in cases {
        for at in [[0.0; 3], [1e3, -2e3, 5e2]] {
            for kick in [1e-4, 1e-2, 0.1] {
                for _ in 0..20 {
                    let t = triangle(&mut rng, w, d, at, kick);
                    let s = t.solve().expect("a small step has a closed form");
                    check_shake_equations(&t, &s);
                }
            }
        }
    }
}

#[test]
fn the_closed_form_refuses_what_it_cannot_solve() {
    let mut rng = Rng(7);
    let (w, d) = ([1.0, 0.5, 0.25], [1.0, 1.2, 0.9]);
    // A collinear old triangle (the pair forces span too little).
    let mut t = triangle(&mut rng, w, d, [0.0; 3], 1e-2);
    t.x0[2] = [2.0 * t.x0[1][0], 2.0 * t.x0[1][1], 2.0 * t.x0[1][2]];
    t.x0[0] = [0.0; 3];
    assert!(t.solve().is_none());
    // A reference that is no strict triangle.
    let mut t = triangle(&mut rng, w, d, [0.0; 3], 1e-2);
    t.d2 = [1.0, 4.0, 1.0];
    assert!(t.solve().is_none());
    // A step far too large to meet the lengths on this branch.
    let t = triangle(&mut rng, w, d, [0.0; 3], 1e-2);
    let mut far = t;
    far.xt[0][0] += 50.0 * (t.x0[1][1] - t.x0[0][1]);
    far.xt[0][1] += 50.0 * (t.x0[2][2] - t.x0[0][2]);
    far.xt[2] = [far.xt[2][0], far.xt[2][1], far.xt[2][2] + 40.0];
    if let Some(s) = far.solve() {
        // (If a branch exists it must be a solution.)
        check_shake_equations(&far, &s);
    }
    // NaN anywhere.
    let mut t = triangle(&mut rng, w, d, [0.0; 3], 1e-2);
    t.xt[1][2] = f64::NAN;
    assert!(t.solve().is_none());
}

#[test]
fn the_projection_leaves_every_bond_rigid() {
    let mut rng = Rng(11);
    for (w, d) in [
        ([1.0 / 16.0, 1.0, 1.0], [1.0, 1.0, 1.633]),
        ([0.1, 3.0, 0.7], [1.0, 1.3, 0.8]),
    ] {
        for _ in 0..50 {
            let t = triangle(&mut rng, w, d, [0.0; 3], 0.0);
            let mut p = [rng.v3(3.0), rng.v3(3.0), rng.v3(3.0)];
            let p_in = p;
            let (h, _) = project1(&t.x0, w, &mut p).unwrap();
            assert!(h <= 16.0 * f64::EPSILON, "hidden {h:e}");
            // The change is G(x)ᵀ μ: no net force.
            for c in 0..3 {
                let f: f64 = (0..3).map(|a| p[a][c] - p_in[a][c]).sum();
                assert!(f.abs() <= 64.0 * f64::EPSILON * 9.0, "net force {f:e}");
            }
        }
    }
    // Collapsed positions: N singular.
    let x = [[0.0; 3], [0.0; 3], [0.0; 3]];
    let mut p = [[1.0; 3]; 3];
    assert!(project1(&x, [1.0; 3], &mut p).is_none());
}

/// A triangle solved in a batch is solved bit for bit as alone: the
/// threads' blocks may cut the batches anywhere.
#[test]
fn a_batch_solves_each_triangle_as_alone() {
    batch_as_alone::<Lanes>();
    #[cfg(target_arch = "x86_64")]
    if has_avx() {
        batch_as_alone::<Wide>();
    }
}

fn batch_as_alone<L: Real>() {
    let mut rng = Rng(5);
    let (w, d) = ([1.0 / 15.9994, 1.0 / 1.008, 1.0 / 1.008], [1.0, 1.0, 1.633]);
    let shape = Shape::new(w, d.map(|d| d * d));
    let ts: Vec<Triangle> = (0..LANES)
        .map(|_| triangle(&mut rng, w, d, [3.0, 1.0, 2.0], 0.05))
        .collect();
    let ps: Vec<[V3; 3]> = (0..LANES)
        .map(|_| [rng.v3(1.0), rng.v3(1.0), rng.v3(1.0)])
        .collect();
    let gather = |v: &dyn Fn(usize) -> [V3; 3]| {
        [0, 1, 2].map(|s| [0, 1, 2].map(|c| L::from_fn(|l| v(l)[s][c])))
    };
    let x0 = gather(&|l| ts[l].x0);
    let xt = gather(&|l| ts[l].xt);
    let p = gather(&|l| ps[l]);
    let many = solve(&shape, &x0, &xt);
    let wl = w.map(L::splat);
    let many_p = project(&many.x1, wl, &p);
    for (l, t) in ts.iter().enumerate() {
        let one = solve(&shape, &t.x0, &t.xt);
        assert!(one.valid() && L::holds(many.valid(), l));
        let one_p = project(&one.x1, w, &ps[l]);
        for s in 0..3 {
            assert_eq!(one.nu[s].to_bits(), many.nu[s].lane(l).to_bits());
            for c in 0..3 {
                assert_eq!(one.x1[s][c].to_bits(), many.x1[s][c].lane(l).to_bits());
                assert_eq!(one_p.p[s][c].to_bits(), many_p.p[s][c].lane(l).to_bits());
            }
        }
        assert_eq!(one_p.judge(0, &w, &ps[l]), many_p.judge(l, &wl, &p));
    }
}

#[test]
fn triangles_are_the_three_pairs_of_three_particles() {
    let plan = |slots: Vec<u8>| FamilyClusters {
        fixed: Some((3, 3)),
        slots,
        ..Default::default()
    };
    assert!(all_triangles(&plan(vec![0, 1, 0, 2, 1, 2]), 2));
    assert!(all_triangles(
        &plan(vec![2, 1, 1, 0, 0, 2, 0, 1, 2, 0, 2, 1]),
        2
    ));
    // A pair twice, a particle with itself, the wrong arity or shape.
    assert!(!all_triangles(&plan(vec![0, 1, 1, 0, 1, 2]), 2));
    assert!(!all_triangles(&plan(vec![0, 0, 0, 2, 1, 2]), 2));
    assert!(!all_triangles(&plan(vec![0, 1, 0, 2, 1, 2]), 3));
    let mut p = plan(vec![0, 1, 0, 2, 1, 2]);
    p.fixed = Some((2, 3));
    assert!(!all_triangles(&p, 2));
}

/// [`Lanes`]' and [`Wide`]'s comparisons, finiteness, |x|, −x and max are f64's on every
/// lane, NaN, infinities and signed zeros included: the batch's decisions
/// are the lane's own.
#[test]
fn lanes_compare_as_f64() {
    compare_as_f64::<Lanes>();
    #[cfg(target_arch = "x86_64")]
    if has_avx() {
        compare_as_f64::<Wide>();
    }
}

fn compare_as_f64<L: Real>() {
    let v = [
        0.0,
        -0.0,
        1.0,
        -1.0,
        1e-300,
        f64::MAX,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NAN,
    ];
    let n = v.len();
    for i in 0..n {
        for j in 0..n {
            let (x, y) = (|l: usize| v[(i + l) % n], |l: usize| v[(j + 3 * l) % n]);
            let (a, b) = (L::from_fn(x), L::from_fn(y));
            let (lt, le, fin) = (a.lt(b), a.le(b), a.finite());
            let mut all = true;
            for l in 0..LANES {
                let (x, y) = (x(l), y(l));
                assert_eq!(L::holds(lt, l), x < y);
                assert_eq!(L::holds(le, l), x <= y);
                assert_eq!(L::holds(lt | le, l), x <= y);
                assert_eq!(L::holds(lt & le, l), x < y);
                assert_eq!(L::holds(fin, l), x.is_finite());
                assert_eq!(a.lane(l).to_bits(), x.to_bits());
                let mut stored = [0.0; LANES];
                a.store(&mut stored);
                assert_eq!(stored[l].to_bits(), x.to_bits());
                assert_eq!(a.abs().lane(l).to_bits(), x.abs().to_bits());
                assert_eq!((-a).lane(l).to_bits(), (-x).to_bits());
                if !x.is_nan() && !y.is_nan() {
                    assert_eq!(a.max(b).lane(l), x.max(y));
                }
                all &= x <= y;
            }
            assert_eq!(L::all(le), all);
        }
    }
}

/// [`beyond`] passes a lane only where some [`residuals`] is above the
/// threshold, so that the batch's fast path decides x̃ as the per-lane
/// judgement does: triangles whose residuals lie within ±10⁻⁹ (relative)
/// of the threshold, at scales from 10⁻¹⁶⁰ (products below f64's normal
/// range) to 10¹⁵⁴ (2|e|² overflows), and NaN; and it misses no lane whose
/// residual is clearly (2⁻³⁰ relative) above it.
#[test]
fn beyond_passes_only_residuals_above_the_threshold() {
    beyond_as_residuals::<f64>();
    beyond_as_residuals::<Lanes>();
    #[cfg(target_arch = "x86_64")]
    if has_avx() {
        beyond_as_residuals::<Wide>();
    }
}

fn beyond_as_residuals<L: Real>() {
    let mut rng = Rng(11);
    let (mut passed, mut below) = (0, 0);
    for trial in 0..20_000 {
        let thr = if trial % 2 == 0 { 1e-12 } else { ROUNDOFF_CAP };
        let scale = 10f64.powf(-160.0 + 314.0 * (0.5 + 0.5 * rng.next()));
        let x: Vec<[V3; 3]> = (0..L::N)
            .map(|_| [rng.v3(scale), rng.v3(scale), rng.v3(scale)])
            .collect();
        // d² = l² (1 − 2 thr (1 + δ)) on each pair of the first lane: the
        // residual is thr (1 + δ) up to rounding; NaN now and then.
        let mut d2 = [0.0; 3];
        for (k, &(i, j)) in PAIRS.iter().enumerate() {
            let e = sub(x[0][i], x[0][j]);
            let delta = 1e-9 * rng.next();
            d2[k] = dot(e, e) * (1.0 - 2.0 * thr * (1.0 + delta));
        }
        if trial % 97 == 0 {
            d2[1] = f64::NAN;
        }
        let xl = [0, 1, 2].map(|s| [0, 1, 2].map(|c| L::from_fn(|l| x[l][s][c])));
        let (fast, res) = (beyond(&xl, d2, thr), residuals(&xl, d2));
        for l in 0..L::N {
            let worst = (0..3).map(|k| res[k].lane(l)).fold(0.0, f64::max);
            if L::holds(fast, l) {
                passed += 1;
                assert!(worst > thr, "{worst:e} passed at {thr:e}");
            } else if worst > thr * (1.0 + 2f64.powi(-30)) && worst.is_finite() {
                // Only where 2|e|² overflows, or thr·2|e|² is below the
                // normal range (its rounding then coarser than 2⁻⁴⁰), may a
                // clear residual be missed.
                let edge = (0..3).any(|k| {
                    let (i, j) = PAIRS[k];
                    let e = sub(x[l][i], x[l][j]);
                    let b = 2.0 * dot(e, e);
                    !b.is_finite() || thr * b < f64::MIN_POSITIVE
                });
                assert!(edge, "{worst:e} missed at {thr:e}");
            } else if worst <= thr {
                below += 1;
            }
        }
    }
    // Both sides of the threshold were met.
    assert!(passed > 1000 && below > 1000, "{passed} {below}");
}
