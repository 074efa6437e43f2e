//! Ensembles over MPI ranks (`--features mpi`), run for real: `mpirun` with
//! 1 and 2 ranks launches `examples/ensemble_mpi.rs` (built here with
//! cargo), whose `--check` compares every gathered outcome with
//! `run_ensemble` in one process, bit for bit.
//!
//! Without `mpirun` on the PATH the tests print why and pass, unless
//! `SHAKE_REQUIRE_MPI=1` (as `.ci/run` sets): then they fail.
#![cfg(feature = "mpi")]

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The example binary, built (once for all tests) in this test's profile.
fn example() -> PathBuf {
    static EXE: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    EXE.get_or_init(build_example).clone()
}

fn build_example() -> PathBuf {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    // With the features this test was built with: CI builds it beside the
    // arrow, plot and progress tests in one feature set, and the example
    // then reuses the runtime and facade compiled for them instead of
    // compiling them once more for `mpi` alone.
    let features = [
        ("mpi", cfg!(feature = "mpi")),
        ("arrow", cfg!(feature = "arrow")),
        ("plot", cfg!(feature = "plot")),
        ("progress", cfg!(feature = "progress")),
    ]
    .into_iter()
    .filter_map(|(name, on)| on.then_some(name))
    .collect::<Vec<&str>>()
    .join(",");
    let mut build = Command::new(cargo);
    build.current_dir(env!("CARGO_MANIFEST_DIR")).args([
        "build",
        "--features",
        features.as_str(),
        "--example",
        "ensemble_mpi",
    ]);
    if !cfg!(debug_assertions) {
        build.arg("--release");
    }
    let status = build.status().expect("cargo runs");
    assert!(status.success(), "building examples/ensemble_mpi.rs failed");
    // target/<profile>/deps/<this test> → target/<profile>/examples/…
    let exe = std::env::current_exe().unwrap();
    let profile_dir = exe.parent().and_then(Path::parent).unwrap();
    profile_dir.join("examples").join("ensemble_mpi")
}

/// `mpirun` and whether it is Open MPI's (which wants `--oversubscribe` to
/// start more ranks than cores, and consent to run as root).
fn mpirun() -> Option<bool> {
    match Command::new("mpirun").arg("--version").output() {
        Ok(out) if out.status.success() => {
            let v = String::from_utf8_lossy(&out.stdout).to_string()
                + &String::from_utf8_lossy(&out.stderr);
            Some(v.contains("Open MPI") || v.contains("OpenRTE"))
        }
        _ => {
            let msg = "mpirun not found: install Open MPI (Debian: openmpi-bin libopenmpi-dev)";
            assert!(
                std::env::var("SHAKE_REQUIRE_MPI").as_deref() != Ok("1"),
                "{msg}, required by SHAKE_REQUIRE_MPI=1"
            );
            println!("SKIPPED: {msg}");
            None
        }
    }
}

/// `mpirun -n ranks example args…`, with a time limit so that a hang in a
/// collective fails the test instead of stalling CI.
fn launch(open_mpi: bool, exe: &Path, ranks: usize, args: &[&str]) -> Output {
    let mut cmd = Command::new("mpirun");
    cmd.args(["-n", &ranks.to_string()]);
    if open_mpi {
        cmd.arg("--oversubscribe");
    }
    let child = cmd
        .arg(exe)
        .args(args)
        // Open MPI refuses root without both; CI containers run as root.
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mpirun starts");
    let id = child.id();
    let start = Instant::now();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(child.wait_with_output());
    });
    loop {
        if let Ok(out) = rx.try_recv() {
            let out = out.expect("mpirun output");
            println!(
                "$ mpirun -n {ranks} ensemble_mpi {}\n{}{}",
                args.join(" "),
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
            return out;
        }
        if start.elapsed() > Duration::from_secs(600) {
            let _ = Command::new("kill").arg(id.to_string()).status();
            panic!("mpirun -n {ranks} {args:?} did not finish in 600 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The `key=value` fields of the line starting with `prefix`.
fn fields(out: &Output, prefix: &str) -> Vec<(String, String)> {
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .find(|l| l.starts_with(prefix))
        .unwrap_or_else(|| panic!("no line `{prefix}…` in\n{text}"));
    line.split_whitespace()
        .filter_map(|f| f.split_once('='))
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect()
}

fn field(out: &Output, prefix: &str, key: &str) -> String {
    fields(out, prefix)
        .into_iter()
        .find(|(k, _)| k == key)
        .unwrap_or_else(|| panic!("no {key}= on the `{prefix}` line"))
        .1
}

fn stdout(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("shake-mpi-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

const ENSEMBLE: [&str; 8] = [
    "--members",
    "60",
    "--steps",
    "300",
    "--stride",
    "40",
    "--fail",
    "7,23,41",
];

/// Two ranks, one and two threads each: every gathered member equals the
/// one-process run_ensemble bit for bit (the example's --check), the three
/// injected failures come back with their errors (a NaN start at step 0,
/// a Newton failure at step 5 with its partial trajectory) and the other
/// 57 members are kept.
#[test]
fn two_ranks_equal_one_process_and_keep_the_failures() {
    let Some(open_mpi) = mpirun() else { return };
    let exe = example();
    for threads in ["1", "2"] {
        let mut args = ENSEMBLE.to_vec();
        args.extend(["--batch", "16", "--threads", threads, "--check"]);
        let out = launch(open_mpi, &exe, 2, &args);
        assert!(out.status.success(), "exit status {:?}", out.status);
        let text = stdout(&out);
        assert!(
            text.contains("check ok: 60 gathered members bit-identical"),
            "{text}"
        );
        assert!(text.contains(
            "member 7 failed as injected: non-finite value in the initial state at step 0"
        ));
        assert!(text.contains(
            "member 23 failed as injected: Newton did not converge in SHAKE (λ such that g(z1⁻) = 0) at step 5"
        ));
        assert!(text.contains("member 41 failed as injected"));
        let last = text.lines().last().unwrap();
        assert!(
            last.starts_with(&format!(
                "ensemble members=60 ok=57 failed=3 ranks=2 threads={threads} members_per_s="
            )),
            "{last}"
        );
    }
}

/// Particle runs over two ranks: boxes of rigid water, every gathered
/// member equal to the one-process run_ensemble bit for bit, the NaN
/// momentum failing at step 0 and the collapsed molecule at its first bond
/// in step 1 (its start state kept), the other members complete.
#[test]
fn water_boxes_on_two_ranks_equal_one_process_and_keep_the_failures() {
    let Some(open_mpi) = mpirun() else { return };
    let exe = example();
    let args = "--system water --waters 20 --members 12 --steps 50 --stride 10 \
                --fail 3,8 --batch 4 --threads 2 --check";
    let args: Vec<&str> = args.split_whitespace().collect();
    let out = launch(open_mpi, &exe, 2, &args);
    assert!(out.status.success(), "exit status {:?}", out.status);
    let text = stdout(&out);
    assert!(
        text.contains("check ok: 12 gathered members bit-identical"),
        "{text}"
    );
    assert!(text
        .contains("member 3 failed as injected: non-finite value in the initial state at step 0"));
    assert!(
        text.contains("member 8 failed as injected")
            && text.contains("(partial trajectory: 1 states)"),
        "{text}"
    );
    let last = text.lines().last().unwrap();
    assert!(
        last.starts_with("ensemble members=12 ok=10 failed=2 ranks=2 threads=2"),
        "{last}"
    );
}

/// An interrupted job resumed: the first job stops after 3 batches of 8 (a
/// wall-time limit) and its files are then torn as by a kill during a
/// write (half a manifest line, stray words after the last record); the
/// second job loads the 24 finished members, computes only the other 36,
/// and the whole ensemble still equals run_ensemble bit for bit; a third
/// job has nothing left to do. The store written by 2 ranks in two jobs is
/// byte for byte the one written by 1 rank in one job.
#[test]
fn an_interrupted_job_resumes_with_only_the_missing_members() {
    let Some(open_mpi) = mpirun() else { return };
    let exe = example();
    let (two, one) = (scratch("two"), scratch("one"));
    let store_args = |dir: &Path| {
        let mut a: Vec<String> = ENSEMBLE.iter().map(|s| s.to_string()).collect();
        a.extend(["--batch", "8", "--threads", "1", "--check", "--store"].map(String::from));
        a.push(dir.display().to_string());
        a
    };
    let run = |ranks, args: &[String]| {
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = launch(open_mpi, &exe, ranks, &refs);
        assert!(out.status.success(), "exit status {:?}", out.status);
        assert!(stdout(&out).contains("check ok"), "{}", stdout(&out));
        out
    };

    let mut first = store_args(&two);
    first.extend(["--max-batches".into(), "3".into()]);
    let out = run(2, &first);
    assert_eq!(field(&out, "computed=", "computed"), "24");
    assert_eq!(field(&out, "computed=", "pending"), "36");
    assert!(stdout(&out).contains("check ok: 24 gathered members"));

    // The kill: a manifest line cut before its newline, garbage after the
    // last record.
    use std::io::Write;
    let mut m = std::fs::OpenOptions::new()
        .append(true)
        .open(two.join("manifest.txt"))
        .unwrap();
    m.write_all(b"24 ok 9999").unwrap();
    let mut r = std::fs::OpenOptions::new()
        .append(true)
        .open(two.join("results.bin"))
        .unwrap();
    r.write_all(&[0xAB; 40]).unwrap();

    let out = run(2, &store_args(&two));
    assert_eq!(field(&out, "computed=", "resumed"), "24");
    assert_eq!(field(&out, "computed=", "computed"), "36");
    assert_eq!(field(&out, "computed=", "pending"), "0");
    assert!(stdout(&out).contains("check ok: 60 gathered members"));
    assert!(stdout(&out).contains("ensemble members=60 ok=57 failed=3 ranks=2"));

    let out = run(2, &store_args(&two));
    assert_eq!(field(&out, "computed=", "computed"), "0");
    assert_eq!(field(&out, "computed=", "resumed"), "60");
    assert!(stdout(&out).contains("check ok: 60 gathered members"));

    run(1, &store_args(&one));
    for file in ["manifest.txt", "results.bin"] {
        let (a, b) = (
            std::fs::read(two.join(file)).unwrap(),
            std::fs::read(one.join(file)).unwrap(),
        );
        assert!(
            a == b,
            "{file} differs between 2 ranks (resumed) and 1 rank"
        );
    }
    let manifest = std::fs::read_to_string(one.join("manifest.txt")).unwrap();
    assert_eq!(
        manifest.lines().filter(|l| l.contains(" failed ")).count(),
        3
    );
    std::fs::remove_dir_all(&two).unwrap();
    std::fs::remove_dir_all(&one).unwrap();
}
