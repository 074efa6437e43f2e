//! A non-autonomous system: Kapitza's pendulum, whose pivot is shaken up and
//! down fast enough that the upside-down position becomes stable.
//!
//!     cargo run --release --example forced_pendulum
//!
//! shake integrates autonomous Hamiltonians. A time-dependent one enters
//! through *extended phase space*: time becomes the coordinate q₀ = t with
//! conjugate momentum p₀ = p_t, and H̃(q, p) = H(q, p, t) + p_t. Then
//! t' = ∂H̃/∂p_t = 1, p_t' = −∂H/∂t (so −p_t is the energy, changed by the
//! work the forcing does), and the rest of the equations are those of H.
//! A constraint that depends on time, here the rod to a moving pivot
//!
//!   g = x² + (y − a cos ωt)² − L² = 0,
//!
//! is an ordinary holonomic constraint in the extended q = (t, x, y), and
//! SHAKE and RATTLE apply as they are (N = {{H̃,g},g} = 4L² ≠ 0 on M).
//!
//! With L = g = 1, a = 0.1 and ω = 30 (a²ω² = 9 > 2gL, Kapitza's condition)
//! the pendulum started 0.3 rad from upright swings about the top; with the
//! pivot still (a = 0) the same start falls over. The program prints both,
//! and how well RATTLE keeps g, {g,H̃} and H̃.
use geoshake::prelude::*;

constrained_system! {
    /// A planar pendulum (unit mass, rod `length`) whose pivot moves as
    /// y = amplitude·cos(omega·t): time is the coordinate `t`, `p_t` its
    /// conjugate momentum.
    pub struct KapitzaPendulum {
        parameters { length, gravity, amplitude, omega }
        coordinates t, x, y;
        momenta p_t, p_x, p_y;
        hamiltonian = (p_x^2 + p_y^2) / 2 + gravity * y + p_t;
        constraints { rod: x^2 + (y - amplitude * cos(omega * t))^2 - length^2 }
    }
}

/// The angle from the downward vertical, measured at the pivot.
fn angle(sys: &KapitzaPendulum, z: &State) -> f64 {
    let pivot = sys.amplitude * (sys.omega * z.q[0]).cos();
    z.q[1].atan2(pivot - z.q[2])
}

/// Upright minus 0.3 rad, at rest, at t = 0 (the pivot is at rest then too).
fn start(sys: &KapitzaPendulum) -> State {
    let theta = std::f64::consts::PI - 0.3;
    let (x, y) = (
        sys.length * theta.sin(),
        sys.amplitude - sys.length * theta.cos(),
    );
    let energy = sys.gravity * y;
    State::from_slices(&[0.0, x, y], &[-energy, 0.0, 0.0])
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (h, t_end) = (0.002, 20.0);
    let steps = (t_end / h) as u64;
    println!("Kapitza's pendulum, RATTLE over Störmer–Verlet, h = {h}, T = {t_end}");
    println!("angle from the downward vertical (π = upright), every 2 time units:\n");
    println!("| t | shaken pivot (a = 0.1, ω = 30) | still pivot (a = 0) |");
    println!("|---|---|---|");
    let mut runs = Vec::new();
    for amplitude in [0.1, 0.0] {
        let sys = KapitzaPendulum::new(1.0, 1.0, amplitude, 30.0);
        let mut rattle = Integrator::new(sys, StormerVerlet, h)
            .rattle()
            .with_diagnostics();
        let z0 = rattle.project_to_hidden(&start(&sys))?;
        let e0 = sys.hamiltonian(z0.q.as_slice(), z0.p.as_slice());
        let traj = rattle
            .run(z0, Stop::Steps(steps))
            .stride(100)
            .execute()
            .into_result()
            .map_err(|(_, e)| e)?;
        runs.push((sys, e0, traj));
    }
    let (shaken, still) = (&runs[0], &runs[1]);
    for k in (0..shaken.2.len()).step_by(10) {
        // Unwrapped into (0, 2π) so that upright reads π on either side.
        let wrap = |a: f64| a.rem_euclid(std::f64::consts::TAU);
        println!(
            "| {:4.1} | {:.3} | {:.3} |",
            shaken.2.q(k)[0],
            wrap(angle(&shaken.0, &shaken.2.state(k))),
            wrap(angle(&still.0, &still.2.state(k))),
        );
    }
    for (name, (sys, e0, traj)) in [("shaken", shaken), ("still", still)] {
        let from_top = traj
            .states()
            .map(|z| {
                (angle(sys, &z).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI).abs()
            })
            .fold(0.0, f64::max);
        let g = traj
            .diagnostics
            .iter()
            .map(|d| d.constraint)
            .fold(0.0, f64::max);
        let hidden = traj
            .diagnostics
            .iter()
            .map(|d| d.hidden_constraint)
            .fold(0.0, f64::max);
        let dh = traj
            .states()
            .map(|z| (sys.hamiltonian(z.q.as_slice(), z.p.as_slice()) - e0).abs())
            .fold(0.0, f64::max);
        let work = -traj.p(traj.len() - 1)[0] - (-traj.p(0)[0]);
        println!(
            "\n{name} pivot: largest distance from upright {from_top:.3} rad; \
             max |g| {g:.1e}, max |{{g,H̃}}| {hidden:.1e}, max |H̃ − H̃(0)| {dh:.1e}; \
             energy gained from the pivot over the run {work:+.4}"
        );
    }
    Ok(())
}
