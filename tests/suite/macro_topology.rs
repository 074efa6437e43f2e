//! Families over run-time tables, declared with `constrained_system!`: the
//! generated stencils against independent hand-written formulas, and the
//! generated `system(..)` against the runtime's topology checks.
//!
//! The reference for each template is written by hand, generically over
//! num-dual's dual numbers: its value is an independent evaluation of the
//! same formula, and one dual evaluation per local coordinate gives the exact
//! gradient (forward-mode automatic differentiation, no truncation error).
//! Generated and reference may differ only by round-off: the macro's
//! canonical form reorders and expands the arithmetic.

use geoshake::constrained_system;
use geoshake::runtime::particles::{Stencil, Table, TopologyError};
use num_dual::{Dual64, DualNum};

constrained_system! {
    /// Rigid water: three distance constraints per molecule.
    pub struct Water {
        particles x[3];
        constraints {
            bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2,
        }
    }
}

constrained_system! {
    /// A chain: springs between next-nearest neighbours, rigid links.
    pub struct SpringChain {
        parameters { stiffness }
        particles x[3];
        potential {
            spring[k in springs(a, b; rest)]: stiffness / 2 * (norm(x[a] - x[b]) - rest)^2,
        }
        constraints {
            link[k in links(a, b; length)]: norm2(x[a] - x[b]) - length^2,
        }
    }
}

constrained_system! {
    /// The rest of the template grammar: components, `sum`, `dot`, `cross`,
    /// three- and four-particle families, a family without data.
    pub struct Molecule {
        parameters { gravity, bend }
        particles x[3];
        potential {
            weight[k in atoms(a; mass)]: gravity * mass * x[a][2],
            angle[k in angles(a, b, c; cosine)]:
                bend / 2 * (dot(x[a] - x[b], x[c] - x[b]) / (norm(x[a] - x[b]) * norm(x[c] - x[b])) - cosine)^2,
        }
        constraints {
            planar[k in quads(a, b, c, d)]: dot(cross(x[b] - x[a], x[c] - x[a]), x[d] - x[a]),
            level[k in pairs(a, b)]: sum i in 0..2 { x[a][i] * x[b][i] } - 1,
        }
    }
}

/// splitmix64: deterministic and dependency-free.
struct Rng(u64);
impl Rng {
    fn uniform(&mut self, a: f64, b: f64) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        a + (b - a) * ((z >> 11) as f64 / (1u64 << 53) as f64)
    }
}

fn sub<T: DualNum<Primitive = f64> + Copy>(x: &[T], a: usize, b: usize) -> [T; 3] {
    [
        x[3 * a] - x[3 * b],
        x[3 * a + 1] - x[3 * b + 1],
        x[3 * a + 2] - x[3 * b + 2],
    ]
}

fn dot3<T: DualNum<Primitive = f64> + Copy>(u: [T; 3], v: [T; 3]) -> T {
    u[0] * v[0] + u[1] * v[1] + u[2] * v[2]
}

/// Round-off: the generated code expands and reorders what the reference
/// computes factored; at coordinates of size ~1 that costs a few ulps of the
/// largest intermediate (~10), far below 1e-12.
const TOL: f64 = 1e-12;

/// Compares `stencil` with the hand-written `reference` at `points` random
/// local coordinates (in [-1, 1]^W, shifted by `offset` per particle to
/// keep the reference's domain) and data `c`.
fn compare<S: Stencil>(
    stencil: &S,
    c: &[f64],
    offset: impl Fn(usize) -> f64,
    reference: impl Fn(&[Dual64], &[f64]) -> Dual64,
) {
    let w = S::ARITY * S::DIM;
    let mut rng = Rng(0x5eed ^ w as u64);
    for _ in 0..50 {
        let x: Vec<f64> = (0..w)
            .map(|l| offset(l / S::DIM) + rng.uniform(-1.0, 1.0))
            .collect();
        let v = stencil.value(&x, c);
        let mut grad = vec![f64::NAN; w];
        let vg = stencil.gradient(&x, c, &mut grad);
        let re: Vec<Dual64> = x.iter().map(|&xi| Dual64::from_re(xi)).collect();
        let v_ref = reference(&re, c).re;
        let scale = 1.0 + v_ref.abs();
        assert!(
            (v - v_ref).abs() <= TOL * scale,
            "value {v} vs {v_ref} at {x:?}"
        );
        assert_eq!(v, vg, "value() and gradient() disagree at {x:?}");
        for l in 0..w {
            let mut xd = re.clone();
            xd[l].eps = 1.0;
            let d_ref = reference(&xd, c).eps;
            assert!(
                (grad[l] - d_ref).abs() <= TOL * (1.0 + d_ref.abs()),
                "∂/∂x_{l}: {} vs {d_ref} at {x:?}",
                grad[l]
            );
        }
    }
}

#[test]
fn water_bond_matches_the_hand_written_distance() {
    assert_eq!(
        (WaterBond::ARITY, WaterBond::DIM, WaterBond::DATA),
        (2, 3, 1)
    );
    compare(
        &Water::new().bond_stencil(),
        &[0.9572],
        |_| 0.0,
        |x, c| {
            let r = sub(x, 0, 1);
            dot3(r, r) - c[0] * c[0]
        },
    );
}

#[test]
fn spring_chain_stencils_match_the_hand_written_formulas() {
    let chain = SpringChain::new(37.5);
    compare(
        &chain.spring_stencil(),
        &[1.25],
        |a| 3.0 * a as f64, // |x_a − x_b| ≥ 1: norm is smooth there
        |x, c| {
            let r = sub(x, 0, 1);
            let d = dot3(r, r).sqrt() - c[0];
            d * d * 37.5 / 2.0
        },
    );
    compare(
        &chain.link_stencil(),
        &[0.5],
        |_| 0.0,
        |x, c| {
            let r = sub(x, 0, 1);
            dot3(r, r) - c[0] * c[0]
        },
    );
}

#[test]
fn molecule_stencils_match_the_hand_written_formulas() {
    let (gravity, bend) = (9.81, 4.5);
    let m = Molecule::new(gravity, bend);
    assert_eq!(
        (
            MoleculePlanar::ARITY,
            MoleculePlanar::DATA,
            MoleculeAngle::ARITY
        ),
        (4, 0, 3)
    );
    compare(
        &m.weight_stencil(),
        &[2.5],
        |_| 0.0,
        |x, c| x[2] * gravity * c[0],
    );
    compare(
        &m.angle_stencil(),
        &[-0.3],
        |a| 2.0 * a as f64,
        |x, c| {
            let (u, v) = (sub(x, 0, 1), sub(x, 2, 1));
            let cos = dot3(u, v) / (dot3(u, u).sqrt() * dot3(v, v).sqrt());
            let d = cos - c[0];
            d * d * bend / 2.0
        },
    );
    compare(
        &m.planar_stencil(),
        &[],
        |_| 0.0,
        |x, _| {
            let (u, v, w) = (sub(x, 1, 0), sub(x, 2, 0), sub(x, 3, 0));
            let n = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            dot3(n, w)
        },
    );
    compare(
        &m.level_stencil(),
        &[],
        |_| 0.0,
        |x, _| x[0] * x[3] + x[1] * x[4] - 1.0,
    );
}

/// n rigid waters on a line, bonds O–H1, O–H2, H1–H2.
fn water_tables(n: usize) -> (Vec<f64>, Table) {
    let mut bonds = Water::bonds_table();
    for m in 0..n {
        let (o, h1, h2) = (3 * m, 3 * m + 1, 3 * m + 2);
        bonds.push(&[o, h1], &[1.0]).unwrap();
        bonds.push(&[o, h2], &[1.0]).unwrap();
        bonds.push(&[h1, h2], &[1.633]).unwrap();
    }
    let masses = (0..3 * n)
        .map(|i| if i % 3 == 0 { 15.9994 } else { 1.008 })
        .collect();
    (masses, bonds)
}

#[test]
fn system_builds_with_the_right_counts_and_evaluates_every_member() {
    let n = 50;
    let (masses, bonds) = water_tables(n);
    let water = Water::new().system(masses, bonds.clone()).unwrap();
    assert_eq!(
        (water.dim(), water.particles(), water.constraints()),
        (3, 3 * n, 3 * n)
    );
    // Each member's value through the system (gather by the table) is the
    // hand-written distance of its own particles.
    let mut rng = Rng(7);
    let q: Vec<f64> = (0..9 * n).map(|_| rng.uniform(-2.0, 2.0)).collect();
    let fam = &water.constraint_families()[0];
    assert_eq!(fam.name(), "bond");
    let mut g = vec![f64::NAN; 3 * n];
    fam.values(&q, &mut g);
    for (k, gk) in g.iter().enumerate() {
        let p = bonds.particles(k);
        let (a, b) = (p[0] as usize, p[1] as usize);
        let r2: f64 = (0..3).map(|c| (q[3 * a + c] - q[3 * b + c]).powi(2)).sum();
        let l = bonds.data(k)[0];
        assert!((gk - (r2 - l * l)).abs() <= TOL * (1.0 + r2), "member {k}");
    }

    let chain = SpringChain::new(10.0);
    let (mut springs, mut links) = (SpringChain::springs_table(), SpringChain::links_table());
    for i in 0..19 {
        links.push(&[i, i + 1], &[1.0]).unwrap();
    }
    for i in 0..18 {
        springs.push(&[i, i + 2], &[1.8]).unwrap();
    }
    let system = chain.system(vec![1.0; 20], springs, links).unwrap();
    assert_eq!((system.particles(), system.constraints()), (20, 19));
    assert_eq!(system.potential_families().len(), 1);
    assert_eq!(system.potential_families()[0].name(), "spring");
    assert_eq!(system.constraint_families()[0].name(), "link");
}

#[test]
fn a_dangling_index_is_a_topology_error_naming_the_family() {
    let (masses, mut bonds) = water_tables(2);
    bonds.push(&[5, 6], &[1.0]).unwrap(); // particle 6 of 6 does not exist
    let e = Water::new().system(masses, bonds).err().expect("refused");
    assert_eq!(
        e,
        TopologyError::DanglingParticle {
            family: "bond".into(),
            member: 6,
            particle: 6,
            particles: 6
        }
    );
    assert!(e.to_string().contains("`bond`"), "{e}");

    // The potential family of the chain is named in its own errors too.
    let mut springs = SpringChain::springs_table();
    springs.push(&[0, 9], &[1.0]).unwrap();
    let e = SpringChain::new(1.0)
        .system(vec![1.0; 3], springs, SpringChain::links_table())
        .err()
        .expect("refused");
    assert!(
        matches!(&e, TopologyError::DanglingParticle { family, member: 0, particle: 9, .. } if family == "spring"),
        "{e}"
    );
    // A table of another family's shape is refused.
    let e = SpringChain::new(1.0)
        .system(vec![1.0; 3], Table::new(3, 1), SpringChain::links_table())
        .err()
        .expect("refused");
    assert!(matches!(e, TopologyError::RowShape { .. }), "{e}");
}

/// Far from the origin the emitted value must not cancel: the template is
/// emitted as written, |x_a − x_b|² − l², not expanded into
/// x_a² − 2x_a·x_b + x_b² − l², which at |x| ~ 10³ loses ~ε|x|² ≈ 10⁻¹⁰ of
/// a unit bond's g. Near each other x_a − x_b is exact in floating point
/// (Sterbenz), so the written form is off by a few roundings of numbers of
/// size l² only, wherever the pair is.
#[test]
fn values_far_from_the_origin_do_not_cancel() {
    let bond = Water::new().bond_stencil();
    let link = SpringChain::new(1.0).link_stencil();
    let mut rng = Rng(11);
    for t in [0.0, 1e3, 1e5, -3.0e6] {
        for _ in 0..20 {
            let l = rng.uniform(0.9, 1.1);
            let a: Vec<f64> = (0..3).map(|_| t + rng.uniform(-1.0, 1.0)).collect();
            let b: Vec<f64> = a.iter().map(|ac| ac + rng.uniform(-0.6, 0.6)).collect();
            let x = [a[0], a[1], a[2], b[0], b[1], b[2]];
            let r: Vec<f64> = (0..3).map(|c| a[c] - b[c]).collect(); // exact
            let r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
            let g_ref = r2 - l * l;
            let bound = 8.0 * f64::EPSILON * (r2 + l * l);
            let mut grad = [0.0; 6];
            for g in [
                bond.value(&x, &[l]),
                bond.gradient(&x, &[l], &mut grad),
                link.value(&x, &[l]),
            ] {
                assert!(
                    (g - g_ref).abs() <= bound,
                    "translated by {t}: g = {g:e}, reference {g_ref:e}"
                );
            }
            for c in 0..3 {
                assert!((grad[c] - 2.0 * r[c]).abs() <= 4.0 * f64::EPSILON * r[c].abs().max(1.0));
                assert_eq!(grad[c], -grad[3 + c]);
            }
        }
    }
}

/// The same for a spring's force, s(|r| − r₀) r/|r|: the gradient is taken
/// of the template as written, so |r| is not rebuilt from an expanded |r|²
/// (which far out loses ~ε|x|²/|r|² of the force, 10⁻¹⁰ at |x| ~ 10³).
/// A few roundings of the hand-written formula: 16 ε relative.
#[test]
fn spring_forces_far_from_the_origin_do_not_cancel() {
    let s = 37.5;
    let spring = SpringChain::new(s).spring_stencil();
    let mut rng = Rng(13);
    for t in [0.0, 1e3, 1e5, -3.0e6] {
        for _ in 0..20 {
            let rest = rng.uniform(0.9, 1.1);
            let a: Vec<f64> = (0..3).map(|_| t + rng.uniform(-1.0, 1.0)).collect();
            let b: Vec<f64> = a.iter().map(|ac| ac + rng.uniform(-0.9, 0.9)).collect();
            let x = [a[0], a[1], a[2], b[0], b[1], b[2]];
            let r: Vec<f64> = (0..3).map(|c| a[c] - b[c]).collect(); // exact
            let n = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
            let mut grad = [0.0; 6];
            let v = spring.gradient(&x, &[rest], &mut grad);
            let v_ref = s / 2.0 * (n - rest) * (n - rest);
            assert!(
                (v - v_ref).abs() <= 16.0 * f64::EPSILON * s * (n + rest).powi(2),
                "{t}: V {v:e} vs {v_ref:e}"
            );
            let f = s * (n - rest) / n;
            let scale = s * (n + rest);
            for c in 0..3 {
                let g_ref = f * r[c];
                assert!(
                    (grad[c] - g_ref).abs() <= 16.0 * f64::EPSILON * scale,
                    "{t}: {} vs {g_ref:e}",
                    grad[c]
                );
                assert!(
                    (grad[3 + c] + g_ref).abs() <= 16.0 * f64::EPSILON * scale,
                    "{t}"
                );
            }
        }
    }
}
