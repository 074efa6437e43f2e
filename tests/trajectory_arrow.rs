//! A trajectory through Arrow IPC (Feather v2) and back (`--features
//! arrow`): the same numbers bit for bit as in memory and as through the
//! CSV (states, times, diagnostics, multipliers including the last state's
//! NaN λ), the CSV's column names, and every damaged file a typed error,
//! never a panic.

use geoshake::examples::Pendulum;
use geoshake::io_arrow::ArrowIoError;
use geoshake::{ImplicitMidpoint, Integrator, Stop, StormerVerlet, Trajectory};
use std::io::Cursor;

fn to_arrow(traj: &Trajectory) -> Vec<u8> {
    let mut out = Vec::new();
    traj.write_arrow(&mut out).unwrap();
    out
}

fn read(bytes: &[u8]) -> Result<Trajectory, ArrowIoError> {
    Trajectory::read_arrow(Cursor::new(bytes))
}

use geoshake_testkit::same_bits::assert_same_bits;

fn rattle_run() -> Trajectory {
    let p = Pendulum {
        gravity: 9.81,
        length: 1.3,
    };
    let mut integ = Integrator::new(p, StormerVerlet, 0.013)
        .with_diagnostics()
        .compensated(true);
    let z0 = integ.project_to_hidden(&p.state(2.0, 0.7)).unwrap();
    // 1001 steps with stride 10: the last state is off the stride.
    integ
        .run(z0, Stop::Steps(1001))
        .stride(10)
        .start_time(0.1)
        .execute()
        .into_result()
        .unwrap()
}

#[test]
fn a_rattle_run_with_diagnostics_round_trips_bit_for_bit() {
    let traj = rattle_run();
    assert_eq!(traj.step(traj.len() - 1), 1001);
    assert!(traj.lambda(traj.len() - 1)[0].is_nan());
    let bytes = to_arrow(&traj);
    let back = read(&bytes).unwrap();
    assert_same_bits(&traj, &back);
    // The same trajectory as the CSV gives, and a fixed point.
    let mut csv = Vec::new();
    traj.write_csv(&mut csv).unwrap();
    assert_same_bits(&Trajectory::read_csv(csv.as_slice()).unwrap(), &back);
    assert_eq!(to_arrow(&back), bytes);
    // Through a file on disk too (left in the temporary directory, where
    // pyarrow or pandas can open it: `pd.read_feather(path)`).
    let path = std::env::temp_dir().join("shake_trajectory_arrow_test.arrow");
    traj.write_arrow(std::fs::File::create(&path).unwrap())
        .unwrap();
    let file = std::fs::File::open(&path).unwrap();
    assert_same_bits(&traj, &Trajectory::read_arrow(file).unwrap());
}

#[test]
fn the_columns_are_named_as_in_the_csv() {
    let traj = rattle_run();
    let mut csv = Vec::new();
    traj.write_csv(&mut csv).unwrap();
    let csv = String::from_utf8(csv).unwrap();
    let header = csv.lines().nth(1).unwrap();
    // Field names are stored as plain UTF-8 in the IPC schema (their
    // order is checked in io_arrow's unit tests, which can read a schema).
    let bytes = to_arrow(&traj);
    for name in header.split(',') {
        assert!(
            bytes.windows(name.len()).any(|w| w == name.as_bytes()),
            "column {name}"
        );
    }
}

#[test]
fn a_shake_run_without_diagnostics_and_an_empty_one_round_trip() {
    let mut integ = Integrator::new(Pendulum::default(), ImplicitMidpoint, -0.05).shake();
    let traj = integ
        .run(Pendulum::default().state(0.3, -1.0), Stop::Steps(40))
        .execute()
        .into_result()
        .unwrap();
    assert_same_bits(&traj, &read(&to_arrow(&traj)).unwrap());
    assert_same_bits(
        &Trajectory::default(),
        &read(&to_arrow(&Trajectory::default())).unwrap(),
    );
}

/// Every occurrence of `from` replaced by `to` (the same length), so the
/// file's offsets stay valid.
fn patched(bytes: &[u8], from: &str, to: &str) -> Vec<u8> {
    assert_eq!(from.len(), to.len());
    let mut out = bytes.to_vec();
    let mut hits = 0;
    for k in 0..out.len().saturating_sub(from.len() - 1) {
        if &out[k..k + from.len()] == from.as_bytes() {
            out[k..k + from.len()].copy_from_slice(to.as_bytes());
            hits += 1;
        }
    }
    assert!(hits > 0, "{from} not in the file");
    out
}

#[test]
fn damaged_files_are_typed_errors() {
    let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).with_diagnostics();
    let traj = integ
        .run(Pendulum::default().state(0.5, 0.0), Stop::Steps(5))
        .execute()
        .trajectory;
    let bytes = to_arrow(&traj);
    assert!(matches!(read(b""), Err(ArrowIoError::Arrow(_))));
    assert!(matches!(read(b"t,step\n"), Err(ArrowIoError::Arrow(_))));
    assert!(matches!(
        read(&patched(&bytes, "trajectory v1", "trajectory v9")),
        Err(ArrowIoError::BadMetadata {
            key: "shake.format",
            ..
        })
    ));
    assert!(matches!(
        read(&patched(&bytes, "shake.stride", "shake.strida")),
        Err(ArrowIoError::BadMetadata {
            key: "shake.stride",
            found: None
        })
    ));
    // A renamed coordinate is a name, read back as it is; a renamed
    // diagnostic breaks the layout.
    assert_eq!(
        read(&patched(&bytes, "q[1]", "y[1]"))
            .unwrap()
            .variable_name(1),
        "y[1]"
    );
    assert!(matches!(
        read(&patched(&bytes, "energy", "energx")),
        Err(ArrowIoError::BadSchema { .. })
    ));
    // Every cut of the file reads or fails with a typed error; none panics.
    for k in 0..bytes.len() {
        let _ = read(&bytes[..k]);
    }
}

#[test]
fn columns_carry_the_declared_names_and_read_back() {
    use geoshake::models::IndexOne;
    let sys = IndexOne { coupling: 0.5 };
    let mut integ = Integrator::new(sys, StormerVerlet, 0.05).with_diagnostics();
    let z0 = geoshake::State::from_slices(&[0.5, 0.0], &[0.1, 0.0]);
    let z0 = integ.project_to_hidden(&z0).unwrap();
    let traj = integ.run(z0, Stop::Steps(10)).execute().trajectory;
    let mut file = Vec::new();
    traj.write_arrow(&mut file).unwrap();
    let back = Trajectory::read_arrow(std::io::Cursor::new(file)).unwrap();
    assert_eq!(back, traj);
    let names: Vec<_> = (0..4).map(|k| back.variable_name(k).into_owned()).collect();
    assert_eq!(names, ["q", "alpha", "p", "beta"]);
    assert_eq!(back.constraint_name(0), "alpha_zero");
}

/// A particle run is the engine's run: 1000 rigid waters (9000
/// coordinates, numbered columns) through Arrow and back bit for bit, and
/// equal to the same trajectory through the CSV.
#[test]
fn a_water_box_run_round_trips_bit_for_bit() {
    use geoshake::particles::{generate, Options, Rattle};
    let (system, mut state) = generate::water(1000, 12345).unwrap();
    let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    rattle.project(&mut state).unwrap();
    generate::set_temperature(rattle.system(), &mut state, 300.0);
    let traj = rattle
        .run(&state, Stop::Steps(15))
        .stride(10)
        .execute()
        .into_result()
        .unwrap();
    assert_eq!((traj.steps(), traj.q(0).len()), (vec![0, 10, 15], 9000));
    let back = read(&to_arrow(&traj)).unwrap();
    assert_same_bits(&back, &traj);
    assert_eq!(back.variable_name(9000), "p[0]");
    let mut csv = Vec::new();
    traj.write_csv(&mut csv).unwrap();
    assert_same_bits(&Trajectory::read_csv(&csv[..]).unwrap(), &back);
}
