//! The progress bar on the per-step hook (`--features progress`): it
//! follows the run to its last step, and one bar serves runs in turn.
//! (Hidden bars: a test must not draw; what is checked is the state the
//! bar would show.)

use geoshake::examples::Pendulum;
use geoshake::prelude::*;
use geoshake::progress::Progress;

#[test]
fn the_bar_follows_each_run_to_its_end() {
    let p = Pendulum::default();
    let mut integ = Integrator::new(p, StormerVerlet, 0.01);
    let mut progress = Progress::hidden("pendulum");
    let out = integ
        .run(p.state(0.5, 0.0), Stop::Steps(12_345))
        .stride(1000)
        .on_step(progress.hook())
        .execute();
    assert!(out.error.is_none());
    let bar = progress.bar();
    assert_eq!((bar.length(), bar.position()), (Some(12_345), 12_345));
    assert!(bar.is_finished());
    assert_eq!(out.trajectory.len(), 14); // 0, 1000, …, 12000 and 12345

    // The same bar for a second, shorter run: length and position restart.
    let out = integ
        .run(p.state(0.2, 0.0), Stop::Time(3.0))
        .on_step(progress.hook())
        .execute();
    assert!(out.error.is_none());
    let bar = progress.bar();
    assert_eq!((bar.length(), bar.position()), (Some(300), 300));
}

#[test]
fn a_run_that_fails_before_its_first_step_leaves_the_bar_alone() {
    let p = Pendulum::default();
    let mut integ = Integrator::new(p, StormerVerlet, 0.01);
    let mut progress = Progress::hidden("pendulum");
    let out = integ
        .run(p.state(0.5, 0.0), Stop::Steps(10))
        .stride(0) // refused: InvalidInput
        .on_step(progress.hook())
        .execute();
    assert!(matches!(out.error, Some(StepError::InvalidInput { .. })));
    assert_eq!(progress.bar().position(), 0);
    assert!(!progress.bar().is_finished());
}

/// A particle run (1000 rigid waters) drives the same bar through the same
/// hook: the one driver runs both engines.
#[test]
fn the_bar_follows_a_particle_run() {
    use geoshake::particles::{generate, Options, Rattle};
    let (system, mut state) = generate::water(1000, 12345).unwrap();
    let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    rattle.project(&mut state).unwrap();
    generate::set_temperature(rattle.system(), &mut state, 300.0);
    let mut progress = Progress::hidden("water");
    let out = rattle
        .run(&state, Stop::Steps(40))
        .stride(40)
        .on_step(progress.hook())
        .execute();
    assert!(out.error.is_none(), "{:?}", out.error);
    let bar = progress.bar();
    assert_eq!((bar.length(), bar.position()), (Some(40), 40));
    assert!(bar.is_finished());
    assert_eq!(out.summary.steps, 40);
}
