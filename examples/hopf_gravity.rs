//! The harmonic constraint with a linear potential, the paper's Section
//! 5.4.2: H = |p|²/2 − g·q with g = (0, −1) on |q|² + |p|² = r².
//!
//!     cargo run --release --example hopf_gravity
//!
//! Runs z_a of the paper's table (which lies on the sphere r² = 0.98, not 1)
//! with SHAKE and RATTLE over the midpoint rule, h = 0.1, and prints what
//! each keeps: |g| at round-off for both, {g,H} at round-off for RATTLE and
//! O(h) for SHAKE, the energy bounded. Then it starts on the other branch of
//! M^H through the same fibre, whose trajectory runs into a fold (case (iii)),
//! and shows the typed error the run stops with.

use geoshake::models::HopfGravity;
use geoshake::{ImplicitMidpoint, Integrator, Method, State, Stop};

fn main() {
    let z_a = [
        -0.78652612,
        -0.4043988,
        -0.3880746864163783,
        0.2173391755798215,
    ];
    let radius2: f64 = z_a.iter().map(|v| v * v).sum();
    let system = HopfGravity::new(0.0, -1.0, radius2);
    let start = State::from_slices(&z_a[..2], &z_a[2..]);
    let h = 0.1;
    println!("H = |p|²/2 + q₁ on |z|² = {radius2:.10} (the table's sphere), h = {h}, 10⁴ steps");
    for method in [Method::Shake, Method::Rattle] {
        let mut integ = Integrator::new(system, ImplicitMidpoint, h)
            .with_method(method)
            .with_diagnostics();
        let traj = integ
            .run(start.clone(), Stop::Steps(10_000))
            .execute()
            .into_result()
            .expect("z_a's trajectory stays away from the folds");
        let d = &traj.diagnostics;
        let max = |f: fn(&geoshake::DiagnosticRecord) -> f64| d.iter().map(f).fold(0.0, f64::max);
        let (e_min, e_max) = d.iter().fold((f64::MAX, f64::MIN), |(a, b), r| {
            (a.min(r.energy), b.max(r.energy))
        });
        println!(
            "{method:?}: max |g| = {:.1e}, max |{{g,H}}| = {:.1e}, energy in [{e_min:.5}, {e_max:.5}]",
            max(|r| r.constraint),
            max(|r| r.hidden_constraint),
        );
    }

    // The other critical point of H on z_a's fibre (a maximum, near the
    // fibre angle 2.2): rotate z_a along the fibre, then let the projection
    // onto M^H find the critical point.
    let (s, c) = 2.2f64.sin_cos();
    let turned = State::from_slices(
        &[z_a[0] * c + z_a[2] * s, z_a[1] * c + z_a[3] * s],
        &[-z_a[0] * s + z_a[2] * c, -z_a[1] * s + z_a[3] * c],
    );
    let mut rattle = Integrator::new(system, ImplicitMidpoint, h).rattle();
    let z = rattle
        .project(&turned)
        .expect("a critical point near the fibre angle 2.2");
    println!(
        "\nstart on the branch of maxima: q = {:?}, p = {:?}",
        z.q.as_slice(),
        z.p.as_slice()
    );
    let out = rattle.run(z, Stop::Steps(100)).execute();
    println!(
        "RATTLE kept {} states, up to t = {:.1}; the exact solution reaches a fold at t ≈ 2.08",
        out.trajectory.len(),
        out.trajectory.times().last().unwrap()
    );
    match out.error {
        Some(e) => println!("stopped: {e}"),
        None => println!("no error (unexpected: the solution ceases to exist at the fold)"),
    }
}
