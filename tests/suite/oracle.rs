//! Oracle tests: every derivative `constrained_system!` generates is checked
//! against forward-mode automatic differentiation (num-dual's hyper-dual
//! numbers) of the same H and g written by hand, at random points.
//!
//! From the hand-written H and g_i the oracle takes values, gradients and
//! Hessians (HyperDual64, one evaluation per pair of variables), and builds
//! from them, with the project's convention {F,G} = F_q·G_p − F_p·G_q:
//! the hidden constraints {g_i,H}, their gradients
//! ∂_c{g_i,H} = Σ_k g_{i,q_k c} H_{p_k} + g_{i,q_k} H_{p_k c} − g_{i,p_k c} H_{q_k} − g_{i,p_k} H_{q_k c},
//! and N_ij = {{H,g_i},g_j} = −Σ_k ∂_{q_k}{g_i,H} ∂_{p_k}g_j − ∂_{p_k}{g_i,H} ∂_{q_k}g_j.
//!
//! Output buffers are pre-filled with NaN: an entry the generated code does
//! not write stays NaN, which checks the "only structurally nonzero entries"
//! contract (an entry the oracle finds nonzero must be written) and, for
//! g_z, that the written entries are exactly `JACOBIAN_PATTERN`.

use geoshake::{constrained_system, ConstrainedSystem, ConstraintKind, Hamiltonian};
use num_dual::{DualNum, HyperDual64};

/// Relative tolerance of the comparison.
const RTOL: f64 = 1e-12;

/// A system written by hand, generically over dual numbers.
trait Model: ConstrainedSystem {
    fn h<T: DualNum<Primitive = f64> + Copy>(&self, z: &[T]) -> T;
    fn g<T: DualNum<Primitive = f64> + Copy>(&self, z: &[T]) -> Vec<T>;
    /// A random state at which to compare (inside the domain of H and g).
    fn point(&self, rng: &mut Rng) -> Vec<f64> {
        (0..2 * self.dof())
            .map(|_| rng.uniform(-1.0, 1.0))
            .collect()
    }
}

/// splitmix64: deterministic and dependency-free.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
    fn uniform(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.next()
    }
}

/// Value, gradient and Hessian of each component of `f` at `z`.
struct Derivs {
    val: Vec<f64>,
    grad: Vec<Vec<f64>>,
    hess: Vec<Vec<Vec<f64>>>,
}

fn derivs(z: &[f64], f: impl Fn(&[HyperDual64]) -> Vec<HyperDual64>) -> Derivs {
    let n = z.len();
    let base: Vec<HyperDual64> = z.iter().map(|x| HyperDual64::from_re(*x)).collect();
    let val: Vec<f64> = f(&base).iter().map(|v| v.re).collect();
    let k = val.len();
    let mut grad = vec![vec![0.0; n]; k];
    let mut hess = vec![vec![vec![0.0; n]; n]; k];
    for a in 0..n {
        for b in a..n {
            let mut x = base.clone();
            x[a].eps1 = 1.0;
            x[b].eps2 += 1.0;
            for (i, r) in f(&x).iter().enumerate() {
                if b == a {
                    grad[i][a] = r.eps1;
                }
                hess[i][a][b] = r.eps1eps2;
                hess[i][b][a] = r.eps1eps2;
            }
        }
    }
    Derivs { val, grad, hess }
}

/// Compares generated (NaN = not written) with reference entries. The
/// absolute floor `RTOL · scale`, scale = the largest |entry| of the output,
/// is for entries that are small by cancellation: both sides form them as
/// sums of products of O(scale) terms, so their rounding error is a few ulps
/// of `scale`, not of the entry.
fn compare(what: &str, generated: &[f64], reference: &[f64]) {
    assert_eq!(generated.len(), reference.len(), "{what}: length");
    let scale = reference.iter().fold(1e-300f64, |s, x| s.max(x.abs()));
    for (k, (g, r)) in generated.iter().zip(reference).enumerate() {
        if g.is_nan() {
            assert!(
                *r == 0.0,
                "{what}[{k}]: not written, but the oracle gives {r:e}"
            );
            continue;
        }
        let err = (g - r).abs();
        assert!(
            err <= RTOL * r.abs().max(scale),
            "{what}[{k}]: generated {g:e}, oracle {r:e} (error {err:e}, scale {scale:e})"
        );
    }
}

fn nan(n: usize) -> Vec<f64> {
    vec![f64::NAN; n]
}

/// Runs every generated method against the oracle at `points` random states.
fn check_model<S: Model>(sys: &S, seed: u64, points: usize) {
    let d = sys.dof();
    let n2 = 2 * d;
    let m = sys.constraint_count();
    let mut rng = Rng(seed);
    for _ in 0..points {
        let z = sys.point(&mut rng);
        let (q, p) = z.split_at(d);
        let hd = derivs(&z, |x| vec![sys.h(x)]);
        let gd = derivs(&z, |x| sys.g(x));
        let (h, hg, hh) = (hd.val[0], &hd.grad[0], &hd.hess[0]);

        compare("H", &[sys.hamiltonian(q, p)], &[h]);
        let (mut hq, mut hp) = (nan(d), nan(d));
        sys.grad_q(q, p, &mut hq);
        sys.grad_p(q, p, &mut hp);
        compare("H_q", &hq, &hg[..d]);
        compare("H_p", &hp, &hg[d..]);
        let (mut hq2, mut hp2) = (nan(d), nan(d));
        sys.gradient(q, p, &mut hq2, &mut hp2);
        compare("gradient H_q", &hq2, &hg[..d]);
        compare("gradient H_p", &hp2, &hg[d..]);
        let mut hzz = nan(n2 * n2);
        sys.hessian(q, p, &mut hzz);
        let reference: Vec<f64> = (0..n2 * n2).map(|k| hh[k % n2][k / n2]).collect();
        compare("H_zz", &hzz, &reference);

        let mut g = nan(m);
        sys.constraints(q, p, &mut g);
        compare("g", &g, &gd.val);
        let mut gz = nan(m * n2);
        sys.constraint_jacobian(q, p, &mut gz);
        let reference: Vec<f64> = (0..m * n2)
            .map(|k| gd.grad[k % m.max(1)][k / m.max(1)])
            .collect();
        compare("g_z", &gz, &reference);
        let written: Vec<(usize, usize)> = (0..n2)
            .flat_map(|k| (0..m).map(move |i| (i, k)))
            .filter(|(i, k)| !gz[i + k * m].is_nan())
            .collect();
        let mut written = written;
        written.sort_unstable();
        assert_eq!(
            written,
            sys.jacobian_pattern(),
            "g_z writes exactly JACOBIAN_PATTERN"
        );

        let lambda: Vec<f64> = (0..m).map(|_| rng.uniform(-1.0, 1.0)).collect();
        let mut gh = nan(n2 * n2);
        sys.constraint_hessian(q, p, &lambda, &mut gh);
        let reference: Vec<f64> = (0..n2 * n2)
            .map(|k| (0..m).map(|i| lambda[i] * gd.hess[i][k % n2][k / n2]).sum())
            .collect();
        compare("Σλ∇²g", &gh, &reference);

        // Hidden constraints, their gradients, N.
        let bracket = |fq: &dyn Fn(usize) -> f64, fp: &dyn Fn(usize) -> f64, g: &[f64]| -> f64 {
            (0..d).map(|k| fq(k) * g[d + k] - fp(k) * g[k]).sum()
        };
        let hidden: Vec<f64> = (0..m)
            .map(|i| bracket(&|k| gd.grad[i][k], &|k| gd.grad[i][d + k], hg))
            .collect();
        let mut out = nan(m);
        sys.hidden_constraints(q, p, &mut out);
        compare("{g_i,H}", &out, &hidden);
        let hidden_z: Vec<Vec<f64>> = (0..m)
            .map(|i| {
                let (gi, gh) = (&gd.grad[i], &gd.hess[i]);
                (0..n2)
                    .map(|c| {
                        (0..d)
                            .map(|k| {
                                gh[k][c] * hg[d + k] + gi[k] * hh[d + k][c]
                                    - gh[d + k][c] * hg[k]
                                    - gi[d + k] * hh[k][c]
                            })
                            .sum()
                    })
                    .collect()
            })
            .collect();
        let mut out = nan(m * n2);
        sys.hidden_constraint_jacobian(q, p, &mut out);
        let reference: Vec<f64> = (0..m * n2)
            .map(|k| hidden_z[k % m.max(1)][k / m.max(1)])
            .collect();
        compare("∇{g_i,H}", &out, &reference);
        let mut n = nan(m * m);
        sys.nondegeneracy_matrix(q, p, &mut n);
        let reference: Vec<f64> = (0..m * m)
            .map(|k| {
                let (i, j) = (k % m, k / m);
                -bracket(&|c| hidden_z[i][c], &|c| hidden_z[i][d + c], &gd.grad[j])
            })
            .collect();
        compare("N", &n, &reference);

        // The closed-form fibre flow of holonomic constraints.
        let (mut q1, mut p1) = (q.to_vec(), p.to_vec());
        let closed = sys.fibre_flow(&lambda, &mut q1, &mut p1).applied();
        assert_eq!(
            closed,
            sys.kind().is_holonomic(),
            "closed-form fibre flow iff holonomic"
        );
        if closed {
            let reference: Vec<f64> = (0..d)
                .map(|k| p[k] - (0..m).map(|i| lambda[i] * gd.grad[i][k]).sum::<f64>())
                .collect();
            assert_eq!(q1, q, "the fibre flow of holonomic constraints keeps q");
            compare("fibre flow p", &p1, &reference);
        }
    }
}

// ---------------------------------------------------------------- systems

constrained_system! {
    /// Planar pendulum (the paper's Example 1.3).
    pub struct Pendulum {
        parameters { length, gravity }
        dof q[2], p[2];
        let r2 = q[0]^2 + q[1]^2;
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
        constraints {
            rod: r2 - length^2,
        }
    }
}

impl Model for Pendulum {
    fn h<T: DualNum<Primitive = f64> + Copy>(&self, z: &[T]) -> T {
        (z[2] * z[2] + z[3] * z[3]) * 0.5 + z[1] * self.gravity
    }
    fn g<T: DualNum<Primitive = f64> + Copy>(&self, z: &[T]) -> Vec<T> {
        vec![z[0] * z[0] + z[1] * z[1] - self.length * self.length]
    }
}

constrained_system! {
    /// Spherical pendulum of mass `mass`.
    pub struct Spherical {
        parameters { mass, length, gravity }
        coordinates x, y, z;
        momenta px, py, pz;
        hamiltonian = (px^2 + py^2 + pz^2) / (2 * mass) + mass * gravity * z;
        constraints {
            sphere: sqrt(x^2 + y^2 + z^2) - length,
        }
    }
}

impl Model for Spherical {
    fn h<T: DualNum<Primitive = f64> + Copy>(&self, z: &[T]) -> T {
        (z[3] * z[3] + z[4] * z[4] + z[5] * z[5]) / (2.0 * self.mass)
            + z[2] * (self.mass * self.gravity)
    }
    fn g<T: DualNum<Primitive = f64> + Copy>(&self, z: &[T]) -> Vec<T> {
        vec![(z[0] * z[0] + z[1] * z[1] + z[2] * z[2]).sqrt() - self.length]
    }
}

constrained_system! {
    /// The Hopf (harmonic) constraint with a linear potential (Section 5.4.2).
    pub struct HopfGravity {
        parameters { g0, g1, radius2 }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 - (g0 * q[0] + g1 * q[1]);
        constraints {
            hopf: q[0]^2 + q[1]^2 + p[0]^2 + p[1]^2 - radius2,
        }
    }
}

impl Model for HopfGravity {
    fn h<T: DualNum<Primitive = f64> + Copy>(&self, z: &[T]) -> T {
        (z[2] * z[2] + z[3] * z[3]) * 0.5 - (z[0] * self.g0 + z[1] * self.g1)
    }
    fn g<T: DualNum<Primitive = f64> + Copy>(&self, z: &[T]) -> Vec<T> {
        vec![z[0] * z[0] + z[1] * z[1] + z[2] * z[2] + z[3] * z[3] - self.radius2]
    }
}

constrained_system! {
    /// A planar chain of 8 links anchored at the origin.
    pub struct Chain8 {
        parameters { mass, length, gravity }
        const N = 8;
        dof q[2*N], p[2*N];
        hamiltonian = sum i in 0..N { (p[2*i]^2 + p[2*i+1]^2) / (2*mass) + mass * gravity * q[2*i+1] };
        constraints {
            link[k in 0..N]: if k == 0 { q[0]^2 + q[1]^2 - length^2 }
                else { (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 },
        }
    }
}

impl Model for Chain8 {
    fn h<T: DualNum<Primitive = f64> + Copy>(&self, z: &[T]) -> T {
        let mut h = T::from(0.0);
        for i in 0..8 {
            let (px, py) = (z[16 + 2 * i], z[16 + 2 * i + 1]);
            h +=
                (px * px + py * py) / (2.0 * self.mass) + z[2 * i + 1] * (self.mass * self.gravity);
        }
        h
    }
    fn g<T: DualNum<Primitive = f64> + Copy>(&self, z: &[T]) -> Vec<T> {
        (0..8)
            .map(|k| {
                let (dx, dy) = if k == 0 {
                    (z[0], z[1])
                } else {
                    (z[2 * k] - z[2 * k - 2], z[2 * k + 1] - z[2 * k - 1])
                };
                dx * dx + dy * dy - self.length * self.length
            })
            .collect()
    }
}

constrained_system! {
    /// Momentum-dependent constraints with a non-separable H: {a, b} = a
    /// vanishes on M without vanishing identically (coisotropic on M only).
    pub struct MomentumDependent {
        parameters { c }
        coordinates x, y, w;
        momenta px, py, pw;
        let kinetic = (px^2 + py^2 + pw^2) / 2;
        hamiltonian = kinetic + sqrt(1 + y^2) + ln(2 + w^2) * tan(x / 4) + exp(-x) * py * y
            + c * cos(w) * sin(y) * pw + x^2 / 2;
        constraints {
            a: x,
            b: py + x * px + exp(w) * pw^3 / 3 - c,
        }
    }
}

impl Model for MomentumDependent {
    fn h<T: DualNum<Primitive = f64> + Copy>(&self, z: &[T]) -> T {
        let (x, y, w, px, py, pw) = (z[0], z[1], z[2], z[3], z[4], z[5]);
        (px * px + py * py + pw * pw) * 0.5
            + (y * y + 1.0).sqrt()
            + (w * w + 2.0).ln() * (x / 4.0).tan()
            + (-x).exp() * py * y
            + w.cos() * y.sin() * pw * self.c
            + x * x * 0.5
    }
    fn g<T: DualNum<Primitive = f64> + Copy>(&self, z: &[T]) -> Vec<T> {
        let (x, w, px, py, pw) = (z[0], z[2], z[3], z[4], z[5]);
        vec![x, py + x * px + w.exp() * pw.powi(3) / 3.0 - self.c]
    }
}

constrained_system! {
    /// The index-1 example of the paper's Section 5.3: z = (q, α; p, β),
    /// constraint α = 0, H = H(q, p, β) with H_ββ ≠ 0.
    pub struct IndexOne {
        parameters { k }
        coordinates q, alpha;
        momenta p, beta;
        hamiltonian = p^2 / 2 + k * q^2 / 2 + beta^2 / 2 + beta * q * p + beta^4 / 4;
        constraints {
            alpha_zero: alpha,
        }
    }
}

impl Model for IndexOne {
    fn h<T: DualNum<Primitive = f64> + Copy>(&self, z: &[T]) -> T {
        let (q, p, beta) = (z[0], z[2], z[3]);
        p * p * 0.5
            + q * q * (self.k * 0.5)
            + beta * beta * 0.5
            + beta * q * p
            + beta.powi(4) * 0.25
    }
    fn g<T: DualNum<Primitive = f64> + Copy>(&self, z: &[T]) -> Vec<T> {
        vec![z[1]]
    }
}

// ---------------------------------------------------------------- tests

#[test]
fn pendulum() {
    let sys = Pendulum::new(1.3, 9.81);
    check_model(&sys, 1, 20);
    assert_eq!(sys.kind(), ConstraintKind::Holonomic);
    assert_eq!((sys.separable(), sys.quadratic_kinetic()), (true, true));
    assert_eq!(sys.jacobian_pattern(), &[(0, 0), (0, 1)]);
}

#[test]
fn spherical_pendulum() {
    let sys = Spherical::new(2.0, 1.5, 9.81);
    check_model(&sys, 2, 20);
    assert_eq!(sys.kind(), ConstraintKind::Holonomic);
    assert_eq!((sys.separable(), sys.quadratic_kinetic()), (true, true));
    assert_eq!(sys.jacobian_pattern(), &[(0, 0), (0, 1), (0, 2)]);
}

#[test]
fn hopf_with_gravity() {
    let sys = HopfGravity::new(0.0, -1.0, 0.98);
    check_model(&sys, 3, 20);
    check_model(&HopfGravity::new(0.3, -1.0, 1.0), 4, 20);
    assert_eq!(sys.kind(), ConstraintKind::Quadratic);
    assert_eq!((sys.separable(), sys.quadratic_kinetic()), (true, true));
    assert_eq!(sys.jacobian_pattern(), &[(0, 0), (0, 1), (0, 2), (0, 3)]);
}

#[test]
fn chain_of_8_links() {
    let sys = Chain8::new(1.2, 0.5, 9.81);
    check_model(&sys, 5, 5);
    assert_eq!(sys.kind(), ConstraintKind::Holonomic);
    assert_eq!((sys.separable(), sys.quadratic_kinetic()), (true, true));
    // Link k touches masses k−1 and k: a banded pattern.
    let mut expected = vec![(0, 0), (0, 1)];
    for k in 1..8 {
        expected.extend([(k, 2 * k - 2), (k, 2 * k - 1), (k, 2 * k), (k, 2 * k + 1)]);
    }
    assert_eq!(sys.jacobian_pattern(), &expected[..]);
}

#[test]
fn momentum_dependent_constraints() {
    let sys = MomentumDependent::new(0.7);
    check_model(&sys, 6, 20);
    assert_eq!(sys.kind(), ConstraintKind::General);
    assert_eq!((sys.separable(), sys.quadratic_kinetic()), (false, false));
    assert_eq!(
        sys.jacobian_pattern(),
        &[(0, 0), (1, 0), (1, 2), (1, 3), (1, 4), (1, 5)]
    );
}

#[test]
fn index_one() {
    let sys = IndexOne::new(2.0);
    check_model(&sys, 7, 20);
    assert_eq!(sys.kind(), ConstraintKind::Holonomic);
    assert_eq!((sys.separable(),), (false,));
    assert_eq!(sys.jacobian_pattern(), &[(0, 1)]);
}
