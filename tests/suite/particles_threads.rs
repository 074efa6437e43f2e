//! The cluster path on threads: a box large enough to be cut into blocks
//! of clusters (and its passes over every particle into chunks) takes the
//! same steps, bit for bit, in a pool of one thread and of two or three,
//! with and without a potential (the fused and the two-pass velocity
//! stage, the fixed-size and the general kernel), and fails at the same
//! member with the same error.

use geoshake::runtime::particles::stencils::LinearField;
use geoshake::runtime::particles::{
    generate, Options, ParticleState, ParticleSystem, Rattle, Table,
};
use geoshake::runtime::rayon::ThreadPoolBuilder;
use geoshake::runtime::{RunOutcome, StepError, Stop};
use geoshake_testkit::same_bits::assert_same_bits;

/// 3000 waters: 9000 particles (above the 8192 of a chunk of the passes
/// over every particle) and 3000 clusters (several blocks of 256).
const WATERS: usize = 3000;

fn water(potential: bool) -> (ParticleSystem, ParticleState) {
    let (system, state) = generate::water(WATERS, 5).unwrap();
    if !potential {
        return (system, state);
    }
    let mut field = Table::new(1, 3);
    for (a, &m) in system.masses().iter().enumerate() {
        field.push(&[a], &[1e-4 * m, 0.0, 2e-4 * m]).unwrap();
    }
    let system = system
        .with_potential("field", LinearField::<3>, field)
        .unwrap();
    (system, state)
}

/// The run of `steps` steps (every state stored) in a pool of `threads`,
/// on the general cluster kernel when `general` (else the fixed-size one).
fn run_on(threads: usize, potential: bool, general: bool, steps: u64) -> (RunOutcome, usize) {
    let pool = ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let (system, mut state) = water(potential);
        let mut r = Rattle::new(system, 2.0, Options::default()).unwrap();
        if general {
            r.use_general_cluster_kernel();
        }
        r.project(&mut state).unwrap();
        generate::set_temperature(r.system(), &mut state, 300.0);
        (
            r.run(&state, Stop::Steps(steps)).execute(),
            r.cluster_blocks(),
        )
    })
}

fn same_steps_on_any_number_of_threads(potential: bool, general: bool) {
    let (one, blocks) = run_on(1, potential, general, 20);
    assert!(
        blocks > 1,
        "the box must be cut for the test to test anything"
    );
    assert!(one.error.is_none(), "{:?}", one.error);
    for threads in [2, 3] {
        let (many, _) = run_on(threads, potential, general, 20);
        assert_same_run(&one, &many);
    }
}

/// Two runs that took the same steps: the same states and reports, bit
/// for bit.
fn assert_same_run(one: &RunOutcome, many: &RunOutcome) {
    assert!(many.error.is_none(), "{:?}", many.error);
    assert_same_bits(&one.trajectory, &many.trajectory);
    let (a, b) = (&one.summary, &many.summary);
    assert_eq!(a.newton_iterations, b.newton_iterations);
    assert_eq!(a.max_newton_iterations, b.max_newton_iterations);
    assert_eq!(
        a.max_residual.map(f64::to_bits),
        b.max_residual.map(f64::to_bits)
    );
    assert_eq!(
        a.max_hidden.map(f64::to_bits),
        b.max_hidden.map(f64::to_bits)
    );
}

#[test]
fn free_water_takes_the_same_steps_on_one_two_and_three_threads() {
    same_steps_on_any_number_of_threads(false, false);
    same_steps_on_any_number_of_threads(false, true);
}

#[test]
fn water_in_a_field_takes_the_same_steps_on_one_two_and_three_threads() {
    same_steps_on_any_number_of_threads(true, false);
    same_steps_on_any_number_of_threads(true, true);
}

/// Two molecules collapsed to a point (their constraint gradients vanish:
/// Newton's matrix is zero), in different blocks: every pool reports the
/// first, as one thread meets it first.
#[test]
fn a_failure_is_reported_at_the_same_member_on_any_number_of_threads() {
    let fail = |threads: usize| {
        let pool = ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (system, mut state) = water(false);
            let mut r = Rattle::new(system, 2.0, Options::default()).unwrap();
            r.project(&mut state).unwrap();
            generate::set_temperature(r.system(), &mut state, 300.0);
            let q = state.q_mut();
            for molecule in [2500, 700] {
                let o = 9 * molecule;
                let (oxygen, rest) = q[o..o + 9].split_at_mut(3);
                rest[..3].copy_from_slice(oxygen);
                rest[3..].copy_from_slice(oxygen);
            }
            r.step(&mut state).unwrap_err()
        })
    };
    let one = fail(1);
    match &one {
        StepError::AtMember { member, .. } => assert_eq!(member / 3, 700, "{one}"),
        e => panic!("expected a failure at a member, got {e}"),
    }
    for threads in [2, 3] {
        assert_eq!(fail(threads).to_string(), one.to_string());
    }
}

/// 10⁵ links: above the band solver's partition (2¹⁶ rows) and many
/// chunks of the coupled path's passes (8192 members or particles).
const LINKS: usize = 100_000;

/// The chain run of `steps` steps in a pool of `threads`.
fn chain_on(threads: usize, steps: u64) -> RunOutcome {
    let pool = ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let (system, mut state) = generate::chain(LINKS, 11).unwrap();
        let mut r = Rattle::new(system, 2.0, Options::default()).unwrap();
        assert_eq!(r.solver_name(), "band");
        r.project(&mut state).unwrap();
        generate::set_temperature(r.system(), &mut state, 300.0);
        r.run(&state, Stop::Steps(steps)).execute()
    })
}

/// The coupled path (a long chain: its passes over the members and the
/// particles, the assembly of N and the partitioned band Cholesky) takes
/// the same steps, bit for bit, on one, two and three threads.
#[test]
fn a_long_chain_takes_the_same_steps_on_one_two_and_three_threads() {
    let one = chain_on(1, 4);
    assert!(one.error.is_none(), "{:?}", one.error);
    for threads in [2, 3] {
        assert_same_run(&one, &chain_on(threads, 4));
    }
}
