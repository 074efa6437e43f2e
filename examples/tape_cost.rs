//! What a run-time declaration costs per call: the tape interpreter of
//! `geoshake_symbolic::tape` against the straight-line code the macro compiles,
//! on the same systems (the pendulum and a chain of 16 links), function by
//! function, and whether they compute the same numbers.
//!
//! `cargo run --release --example tape_cost`

use geoshake::constrained_system;
use geoshake::runtime::ConstrainedSystem;
use geoshake_symbolic::tape::{Program, Tape};
use std::hint::black_box;
use std::time::Instant;

const PENDULUM: &str = "pub struct Pendulum {
    parameters { length, gravity }
    dof q[2], p[2];
    hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
    constraints { rod: q[0]^2 + q[1]^2 - length^2 }
}";

macro_rules! chain {
    ($n:literal) => {
        concat!(
            "pub struct Chain {
                parameters { length, gravity }
                const N = ", stringify!($n), ";
                dof q[2*N], p[2*N];
                hamiltonian = sum i in 0..N { (p[2*i]^2 + p[2*i+1]^2) / 2 + gravity * q[2*i+1] };
                constraints {
                    link[k in 0..N]: if k == 0 { q[0]^2 + q[1]^2 - length^2 }
                        else { (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 },
                }
            }"
        )
    };
}

constrained_system! {
    pub struct Chain16 {
        parameters { length, gravity }
        const N = 16;
        dof q[2*N], p[2*N];
        hamiltonian = sum i in 0..N { (p[2*i]^2 + p[2*i+1]^2) / 2 + gravity * q[2*i+1] };
        constraints {
            link[k in 0..N]: if k == 0 { q[0]^2 + q[1]^2 - length^2 }
                else { (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 },
        }
    }
}

/// ns per call of `f`, the best of five batches.
fn ns(mut f: impl FnMut()) -> f64 {
    let mut n = 1usize;
    loop {
        let t = Instant::now();
        for _ in 0..n {
            f();
        }
        if t.elapsed().as_secs_f64() > 0.02 {
            break;
        }
        n *= 2;
    }
    (0..5)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..n {
                f();
            }
            t.elapsed().as_secs_f64() * 1e9 / n as f64
        })
        .fold(f64::INFINITY, f64::min)
}

fn compare<S: ConstrainedSystem>(label: &str, src: &str, sys: &S, params: &[f64]) {
    let declared = geoshake_symbolic::declare(src).expect("declaration");
    let (s, d) = declared.analysis.values();
    let prog = Program::compile(s, d, params);
    let (dof, m) = (prog.dof(), prog.constraint_count());
    let n2 = 2 * dof;
    // A state off the constraint manifold, so no output is trivially zero.
    let q: Vec<f64> = (0..dof).map(|k| 0.3 + 0.1 * k as f64).collect();
    let p: Vec<f64> = (0..dof).map(|k| -0.2 + 0.07 * k as f64).collect();
    let lambda: Vec<f64> = (0..m).map(|i| 0.5 - 0.03 * i as f64).collect();

    type Compiled<'a, S> = Box<dyn Fn(&S, &mut [f64]) + 'a>;
    let rows: Vec<(&str, &Tape, usize, Compiled<S>)> = vec![
        (
            "H",
            &prog.hamiltonian,
            1,
            Box::new(|s: &S, o: &mut [f64]| o[0] = s.hamiltonian(&q, &p)),
        ),
        (
            "grad_q",
            &prog.grad_q,
            dof,
            Box::new(|s: &S, o: &mut [f64]| s.grad_q(&q, &p, o)),
        ),
        (
            "hessian",
            &prog.hessian,
            n2 * n2,
            Box::new(|s: &S, o: &mut [f64]| s.hessian(&q, &p, o)),
        ),
        (
            "g",
            &prog.constraints,
            m,
            Box::new(|s: &S, o: &mut [f64]| s.constraints(&q, &p, o)),
        ),
        (
            "g_z",
            &prog.jacobian,
            m * n2,
            Box::new(|s: &S, o: &mut [f64]| s.constraint_jacobian(&q, &p, o)),
        ),
        (
            "g_z packed",
            &prog.jacobian_values,
            prog.jacobian_pattern.len(),
            Box::new(|s: &S, o: &mut [f64]| {
                assert!(s.constraint_jacobian_values(&q, &p, o));
            }),
        ),
        (
            "Σλ∇²g",
            &prog.constraint_hessian,
            n2 * n2,
            Box::new(|s: &S, o: &mut [f64]| s.constraint_hessian(&q, &p, &lambda, o)),
        ),
        (
            "{g,H}",
            &prog.hidden,
            m,
            Box::new(|s: &S, o: &mut [f64]| s.hidden_constraints(&q, &p, o)),
        ),
        (
            "∂{g,H}",
            &prog.hidden_jacobian,
            m * n2,
            Box::new(|s: &S, o: &mut [f64]| s.hidden_constraint_jacobian(&q, &p, o)),
        ),
        (
            "N",
            &prog.nondegeneracy,
            m * m,
            Box::new(|s: &S, o: &mut [f64]| s.nondegeneracy_matrix(&q, &p, o)),
        ),
    ];
    for (name, tape, len, compiled) in rows {
        let (mut a, mut b) = (vec![0.0; len], vec![0.0; len]);
        compiled(sys, &mut a);
        prog.eval_into(tape, &q, &p, &lambda, &mut b);
        let same = a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits());
        let diff = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        let t_c = ns(|| compiled(black_box(sys), black_box(&mut a)));
        let t_t = ns(|| {
            prog.eval_into(
                black_box(tape),
                black_box(&q),
                &p,
                &lambda,
                black_box(&mut b),
            )
        });
        println!(
            "| {label} | {name} | {} | {t_c:.1} | {t_t:.1} | {:.1} | {} |",
            tape.len(),
            t_t / t_c,
            if same {
                "bit-identical".to_string()
            } else {
                format!("max diff {diff:.1e}")
            }
        );
    }
}

/// µs per RATTLE step (Störmer–Verlet, h = 0.01) from `z0`, the best of
/// three runs of `steps` steps.
fn step_cost<S: ConstrainedSystem + Clone>(sys: S, z0: &geoshake::State, steps: u64) -> f64 {
    let mut integ = geoshake::Integrator::new(sys, geoshake::StormerVerlet, 0.01).rattle();
    (0..3)
        .map(|_| {
            let t = Instant::now();
            let out = integ
                .run(z0.clone(), geoshake::Stop::Steps(steps))
                .stride(steps)
                .execute();
            assert!(out.error.is_none(), "{:?}", out.error);
            t.elapsed().as_secs_f64() * 1e6 / steps as f64
        })
        .fold(f64::INFINITY, f64::min)
}

fn steps_table() {
    use geoshake::declared::DeclaredSystem;
    let params = [("length", 1.0), ("gravity", 9.81)];
    println!();
    println!("| system | compiled (µs/step) | declared (µs/step) | ratio |");
    println!("|---|---:|---:|---:|");
    let z0 = geoshake::State::from_slices(&[1.0, 0.0], &[0.0, 0.0]);
    let a = step_cost(geoshake::models::Pendulum::new(1.0, 9.81), &z0, 20_000);
    let b = step_cost(DeclaredSystem::new(PENDULUM, &params).unwrap(), &z0, 20_000);
    println!("| pendulum | {a:.3} | {b:.3} | {:.1} |", b / a);
    let q: Vec<f64> = (0..16).flat_map(|k| [k as f64 + 1.0, 0.0]).collect();
    let z0 = geoshake::State::from_slices(&q, &[0.0; 32]);
    let a = step_cost(Chain16::new(1.0, 9.81), &z0, 2_000);
    let b = step_cost(
        DeclaredSystem::new(chain!(16), &params).unwrap(),
        &z0,
        2_000,
    );
    println!("| chain 16 | {a:.3} | {b:.3} | {:.1} |", b / a);
}

fn main() {
    println!("| system | function | tape ops | compiled (ns) | tape (ns) | ratio | values |");
    println!("|---|---|---:|---:|---:|---:|---|");
    compare(
        "pendulum",
        PENDULUM,
        &geoshake::models::Pendulum::new(1.0, 9.81),
        &[1.0, 9.81],
    );
    compare(
        "chain 16",
        chain!(16),
        &Chain16::new(1.0, 9.81),
        &[1.0, 9.81],
    );
    steps_table();
}
