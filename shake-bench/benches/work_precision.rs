//! Run time against error: for each scene with a reference solution, every
//! method over a range of step sizes, the global error at a fixed time
//! plotted against the run time (log-log), one curve per method.
//!
//!     cargo bench -p geoshake-bench --bench work_precision
//!
//! Writes `shake-bench/benches/results/work_precision_<scene>.{png,svg,csv}` and prints
//! the table. Methods: SHAKE and RATTLE over each base map (implicit
//! midpoint, Störmer–Verlet, symplectic Euler), and RATTLE composed to
//! orders 4, 6 and 8 over a symmetric base map. Errors: max-norm distance of
//! the state at T to the reference solution (order-12 extrapolation of the
//! index-reduced ODE on M^H, `shake-testkit/src/reference.rs`, itself accurate to
//! ~1e-13). SHAKE's states lie on M, not on M^H: its raw error is O(h)
//! along the fibre (RATTLE's is O(h²); Π of a SHAKE state *is* the RATTLE
//! state), so SHAKE's curves show the cost of not projecting. The run time
//! is the best of several repetitions of `Run::execute` that observes only
//! the final state (a RATTLE run then projects once).

use geoshake_testkit::{plot, reference};

use geoshake::{
    BaseMap, Composition, ConstrainedSystem, ImplicitMidpoint, Integrator, State, Stop,
    StormerVerlet, SymplecticEuler,
};
use nalgebra::DVector;
use plot::{Figure, Mark};
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// One measured point: step size, run time (s), error.
#[derive(Clone, Copy, Debug)]
struct Point {
    h: f64,
    seconds: f64,
    error: f64,
}

/// Runs `integ` from z0 to T with n steps, observing only the last state;
/// the best run time of up to 7 repetitions (until 50 ms are spent) and the
/// error against `reference`.
fn measure<S: ConstrainedSystem + Clone, B: BaseMap>(
    mut integ: Integrator<S, B>,
    z0: &State,
    n: u64,
    reference: &DVector<f64>,
) -> Option<(f64, f64)> {
    let mut best = f64::INFINITY;
    let mut last = None;
    let mut spent = 0.0;
    for _ in 0..7 {
        let mut end = None;
        let t = Instant::now();
        let out = integ
            .run(z0.clone(), Stop::Steps(n))
            .stride(n)
            .store(false)
            .observe(|k, _, z| {
                if k == n {
                    end = Some(z.clone());
                }
            })
            .execute();
        let dt = t.elapsed().as_secs_f64();
        if out.error.is_some() {
            return None;
        }
        best = best.min(dt);
        spent += dt;
        last = end;
        if spent > 0.05 {
            break;
        }
    }
    let z = last?.to_vector();
    Some((best, (z - reference).amax()))
}

/// The curves of one scene: (name, points).
type Curves = Vec<(String, Vec<Point>)>;

/// SHAKE and RATTLE over `base`, and RATTLE composed if `base` is symmetric.
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn methods<S: ConstrainedSystem + Clone, B: BaseMap>(
    curves: &mut Curves,
    sys: &S,
    base: B,
    z0: &State,
    t_end: f64,
    steps: &[u64],
    reference: &DVector<f64>,
    compose: bool,
) {
    let short = match B::NAME {
        "implicit midpoint" => "midpoint",
        "Störmer–Verlet" => "SV",
        _ => "Euler",
    };
    let mut variants: Vec<(String, Box<dyn Fn(f64) -> Integrator<S, B>>)> = Vec::new();
    let (s1, s2) = (sys.clone(), sys.clone());
    variants.push((
        format!("SHAKE {short}"),
        Box::new(move |h| Integrator::new(s1.clone(), base, h).shake()),
    ));
    variants.push((
        format!("RATTLE {short}"),
        Box::new(move |h| Integrator::new(s2.clone(), base, h).rattle()),
    ));
    if compose && B::SYMMETRIC {
        for (c, label) in [
            (Composition::TRIPLE_JUMP, "order 4"),
            (Composition::YOSHIDA_6, "order 6"),
            (Composition::MCLACHLAN_8, "order 8"),
        ] {
            let s = sys.clone();
            variants.push((
                format!("RATTLE {short} {label}"),
                Box::new(move |h| Integrator::new(s.clone(), base, h).rattle().composed(c)),
            ));
        }
    }
    for (name, make) in variants {
        let mut points = Vec::new();
        for &n in steps {
            let h = t_end / n as f64;
            if let Some((seconds, error)) = measure(make(h), z0, n, reference) {
                points.push(Point { h, seconds, error });
            }
        }
        curves.push((name, points));
    }
}

fn report(scene: &str, title: &str, curves: &Curves, out: &Path, table: &mut String) {
    let mut fig = Figure::new(title, "run time [s]", "global error at T (max norm)")
        .log_x()
        .log_y()
        .size(1000, 700)
        .legend_at(plotters::prelude::SeriesLabelPosition::LowerLeft);
    let _ = writeln!(table, "\n### {title}\n");
    let _ = writeln!(table, "| method | h | run time | error |");
    let _ = writeln!(table, "|---|---:|---:|---:|");
    for (name, points) in curves {
        let pts: Vec<(f64, f64)> = points
            .iter()
            .map(|p| (p.seconds, p.error.max(1e-16)))
            .collect();
        fig = fig.series(name, pts, Mark::LinePoints);
        for p in points {
            let _ = writeln!(
                table,
                "| {name} | {:.3e} | {:.3e} s | {:.2e} |",
                p.h, p.seconds, p.error
            );
        }
    }
    match fig.save(out, &format!("work_precision_{scene}")) {
        Ok(files) => {
            for f in files {
                eprintln!("wrote {}", f.display());
            }
        }
        Err(e) => eprintln!("could not write the {scene} figure: {e}"),
    }
}

fn main() {
    plot::init_fonts();
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/results");
    let mut table = String::new();
    let steps: Vec<u64> = (0..8).map(|k| 25u64 << k).collect();

    // The pendulum of Example 1.3, released at θ = 1 with ω = 0.5; T = 10.
    {
        let t_end = 10.0;
        let r = reference::PlanarPendulum::default();
        let z = r.state(1.0, 0.5);
        let (reference, err) = reference::reference_solution_auto(&r, &z, t_end, 1e-13);
        eprintln!("pendulum reference: error estimate {err:.1e}");
        let z0 = State::from_vector(&z);
        let sys = geoshake::models::Pendulum::new(1.0, 1.0);
        let steps: Vec<u64> = steps.iter().map(|n| n * 4).collect();
        let mut curves = Curves::new();
        methods(
            &mut curves,
            &sys,
            ImplicitMidpoint,
            &z0,
            t_end,
            &steps,
            &reference,
            false,
        );
        methods(
            &mut curves,
            &sys,
            StormerVerlet,
            &z0,
            t_end,
            &steps,
            &reference,
            true,
        );
        methods(
            &mut curves,
            &sys,
            SymplecticEuler,
            &z0,
            t_end,
            &steps,
            &reference,
            false,
        );
        report(
            "pendulum",
            "Pendulum (Example 1.3), T = 10: error against run time",
            &curves,
            &out,
            &mut table,
        );
    }

    // The Hopf constraint with gravity (Section 5.4.2), z_a brought onto the
    // unit M^H; T = 5.
    {
        let t_end = 5.0;
        let r = reference::HopfGravity::default();
        let za = [
            -0.78652612,
            -0.4043988,
            -0.3880746864163783,
            0.2173391755798215,
        ];
        let z = reference::hopf_onto_mh(&za, [0.0, -1.0], 1.0);
        let z = DVector::from_column_slice(&z);
        let (reference, err) = reference::reference_solution_auto(&r, &z, t_end, 1e-13);
        eprintln!("Hopf reference: error estimate {err:.1e}");
        let z0 = State::from_vector(&z);
        let sys = geoshake::models::HopfGravity::new(0.0, -1.0, 1.0);
        let mut curves = Curves::new();
        methods(
            &mut curves,
            &sys,
            ImplicitMidpoint,
            &z0,
            t_end,
            &steps,
            &reference,
            true,
        );
        methods(
            &mut curves,
            &sys,
            StormerVerlet,
            &z0,
            t_end,
            &steps,
            &reference,
            false,
        );
        methods(
            &mut curves,
            &sys,
            SymplecticEuler,
            &z0,
            t_end,
            &steps,
            &reference,
            false,
        );
        report(
            "hopf",
            "Hopf constraint with gravity (5.4.2), T = 5: error against run time",
            &curves,
            &out,
            &mut table,
        );
    }
    println!("{table}");
}
