//! A trajectory through CSV and back: the same numbers bit for bit
//! (states, times, diagnostics, multipliers including the last state's NaN
//! λ), and every malformed file a typed error, never a panic.

use geoshake::examples::Pendulum;
use geoshake::io::CsvError;
use geoshake::{ImplicitMidpoint, Integrator, Stop, StormerVerlet, Trajectory};

fn to_csv(traj: &Trajectory) -> String {
    let mut out = Vec::new();
    traj.write_csv(&mut out).unwrap();
    String::from_utf8(out).unwrap()
}

use geoshake_testkit::same_bits::assert_same_bits;

#[test]
fn a_rattle_run_with_diagnostics_round_trips_bit_for_bit() {
    let p = Pendulum {
        gravity: 9.81,
        length: 1.3,
    };
    let mut integ = Integrator::new(p, StormerVerlet, 0.013)
        .with_diagnostics()
        .compensated(true);
    let z0 = integ.project_to_hidden(&p.state(2.0, 0.7)).unwrap();
    // 1001 steps with stride 10: the last state is off the stride.
    let traj = integ
        .run(z0, Stop::Steps(1001))
        .stride(10)
        .start_time(0.1)
        .execute()
        .into_result()
        .unwrap();
    assert_eq!(traj.step(traj.len() - 1), 1001);
    assert!(traj.lambda(traj.len() - 1)[0].is_nan());
    let text = to_csv(&traj);
    let back = Trajectory::read_csv(text.as_bytes()).unwrap();
    assert_same_bits(&traj, &back);
    // And once more: the text is a fixed point.
    assert_eq!(to_csv(&back), text);
}

#[test]
fn a_shake_run_without_diagnostics_round_trips() {
    let mut integ = Integrator::new(Pendulum::default(), ImplicitMidpoint, -0.05).shake();
    let traj = integ
        .run(Pendulum::default().state(0.3, -1.0), Stop::Steps(40))
        .execute()
        .into_result()
        .unwrap();
    let text = to_csv(&traj);
    assert_eq!(text.lines().nth(1), Some("t,step,q[0],q[1],p[0],p[1]"));
    assert_same_bits(&traj, &Trajectory::read_csv(text.as_bytes()).unwrap());
    assert_same_bits(
        &Trajectory::default(),
        &Trajectory::read_csv(to_csv(&Trajectory::default()).as_bytes()).unwrap(),
    );
}

#[test]
fn malformed_files_are_typed_errors() {
    let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).with_diagnostics();
    let traj = integ
        .run(Pendulum::default().state(0.5, 0.0), Stop::Steps(5))
        .execute()
        .trajectory;
    let text = to_csv(&traj);
    let read = |s: &str| Trajectory::read_csv(s.as_bytes());
    let lines: Vec<&str> = text.lines().collect();

    assert!(matches!(read(""), Err(CsvError::BadMetadata { .. })));
    assert!(matches!(
        read(&text.replacen("h=", "h=x", 1)),
        Err(CsvError::BadMetadata { .. })
    ));
    // A renamed coordinate is a name, read back as it is; a renamed
    // diagnostic or a multiplier of no constraint breaks the layout.
    assert_eq!(
        read(&text.replacen("q[1]", "y", 1))
            .unwrap()
            .variable_name(1),
        "y"
    );
    assert!(matches!(
        read(&text.replacen("energy", "energie", 1)),
        Err(CsvError::BadHeader { .. })
    ));
    assert!(matches!(
        read(&text.replacen("sigma[rod]", "sigma[pole]", 1)),
        Err(CsvError::BadHeader { .. })
    ));
    let mut bad_number = lines.clone();
    let row = lines[3].replacen(',', ",x", 2);
    bad_number[3] = &row;
    assert!(matches!(
        read(&bad_number.join("\n")),
        Err(CsvError::BadNumber { line: 4, .. })
    ));
    let mut short = lines.clone();
    let cut = &lines[4][..lines[4].rfind(',').unwrap()];
    short[4] = cut;
    assert!(matches!(
        read(&short.join("\n")),
        Err(CsvError::WrongColumnCount { line: 5, .. })
    ));
    // A row dropped: the steps no longer follow the stride.
    let mut gap = lines.clone();
    gap.remove(4);
    assert!(matches!(
        read(&gap.join("\n")),
        Err(CsvError::Inconsistent { line: 5, .. })
    ));
    // Every cut of the file reads or fails with a typed error; none panics.
    for k in 0..text.len() {
        let _ = read(&text[..k]);
    }
}

geoshake::constrained_system! {
    /// A pendulum whose pivot moves as y = a·cos(t), time the coordinate
    /// `t`: its name is also the file's time column.
    pub struct Driven {
        parameters { a }
        coordinates t, x, y;
        momenta p_t, p_x, p_y;
        hamiltonian = (p_x^2 + p_y^2) / 2 + y + p_t;
        constraints { rod: x^2 + (y - a * cos(t))^2 - 1 }
    }
}

#[test]
fn columns_carry_the_declared_names_and_read_back() {
    use geoshake::Hamiltonian;
    let sys = Driven { a: 0.1 };
    assert_eq!(
        (0..6).map(|k| sys.variable_name(k)).collect::<Vec<_>>(),
        ["t", "x", "y", "p_t", "p_x", "p_y"]
    );
    let mut integ = Integrator::new(sys, StormerVerlet, 0.05).with_diagnostics();
    let z0 = geoshake::State::from_slices(&[0.0, 0.6, 0.1 - 0.8], &[0.0, 0.0, 0.0]);
    let z0 = integ.project_to_hidden(&z0).unwrap();
    let traj = integ.run(z0, Stop::Steps(20)).execute().trajectory;
    let text = to_csv(&traj);
    // The coordinate `t` is written `q:t`, so that `t` stays the time.
    assert_eq!(
        text.lines().nth(1).unwrap(),
        "t,step,q:t,x,y,p_t,p_x,p_y,energy,constraint,hidden_constraint,\
         max_shake_iterations,max_base_iterations,rattle_iterations,max_lambda,\
         max_condition,lambda[rod],sigma[rod]"
    );
    let back = Trajectory::read_csv(text.as_bytes()).unwrap();
    assert_eq!(back, traj);
    // (equality compares numbers; the names are checked one by one)
    assert!((0..6).all(|k| back.variable_name(k) == traj.variable_name(k)));
    assert_eq!(
        (back.variable_name(0), back.constraint_name(0)),
        ("t".into(), "rod".into())
    );
}

#[test]
fn files_with_numbered_columns_and_no_d_still_read() {
    // The layout before the coordinates had names: no `d=` on the first
    // line, coordinates `q[i]`, multipliers `lambda[i]`.
    let old =
        "# shake trajectory v1 t0=0 h=0.5 stride=1 m=0\nt,step,q[0],q[1],p[0],p[1]\n0,0,1,2,3,4\n";
    let traj = Trajectory::read_csv(old.as_bytes()).unwrap();
    assert_eq!((traj.q(0), traj.p(0)), (&[1.0, 2.0][..], &[3.0, 4.0][..]));
    assert_eq!(traj.variable_name(3), "p[1]");
}
