//! What a run was: commit, date, machine, command line. Written at the head of
//! `claims.md` so that a table found later says where its numbers come from.
//!
//! Everything here degrades to a plain "unknown (why)" rather than failing: a
//! tarball without `.git`, a machine without `lscpu` or a clock before 1970
//! still get their table.

use std::process::Command;
use std::time::{SystemTime, UNIX_EPOCH};

/// The Markdown preamble of `claims.md`.
pub fn preamble(quick: bool, seconds: f64) -> String {
    let mode = if quick {
        "quick (`--quick`: shorter runs, fewer step sizes)"
    } else {
        "full (the default)"
    };
    format!(
        "# The paper's claims, measured\n\
         \n\
         McLachlan, Modin, Verdier and Wilkins, *Geometric generalisations of SHAKE and \
         RATTLE*, reproduced with shake.\n\
         \n\
         - commit: {commit}\n\
         - date: {date}\n\
         - machine: {machine}\n\
         - command: {command}\n\
         - run: {mode}, {seconds:.1} s wall time\n\
         \n\
         Column `#` is the claim's number in the README's table \"What the paper claims, \
         and what we measure\" (1–9). Conventions: z = (q, p), X_F = (F_p, −F_q), \
         {{F,G}} = F_q·G_p − F_p·G_q, q' = H_p + g_pᵀλ, p' = −H_q − g_qᵀλ; M = {{g = 0}}, \
         Mᴴ = {{g = 0, {{g,H}} = 0}}. Names such as `eq hopf_lambda` and `fig_fibres` are \
         the labels of the paper's equations and figures in its LaTeX source. A claim \
         passes when the measured value lies within the bound; the last-but-one column says where the bound comes from. The same \
         rows, unformatted, are in `claims.csv`; each figure's data is in the `.csv` next \
         to its `.png`.\n\
         \n",
        commit = commit(),
        date = utc_now(),
        machine = machine(),
        command = command_line(),
    )
}

/// The commit of the sources: `git rev-parse HEAD` in the crate's directory at
/// run time (with "+ uncommitted changes" when the tree is dirty), else the
/// `SHAKE_GIT_COMMIT` variable set when the scene was built, else unknown.
fn commit() -> String {
    let dir = env!("CARGO_MANIFEST_DIR");
    let git = |args: &[&str]| {
        Command::new("git")
            .arg("-C")
            .arg(dir)
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    if let Some(hash) = git(&["rev-parse", "HEAD"]).filter(|h| !h.is_empty()) {
        let dirty =
            git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty());
        return if dirty {
            format!("{hash} + uncommitted changes")
        } else {
            hash
        };
    }
    match option_env!("SHAKE_GIT_COMMIT") {
        Some(c) if !c.is_empty() => format!("{c} (from SHAKE_GIT_COMMIT at build time)"),
        _ => "unknown (not a git checkout, and SHAKE_GIT_COMMIT was not set at build time)"
            .to_string(),
    }
}

/// The CPU as `lscpu` names it and the number of cores the run could use.
fn machine() -> String {
    let threads = std::thread::available_parallelism().map_or(0, usize::from);
    let lscpu = Command::new("lscpu")
        .env("LC_ALL", "C")
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned());
    let field = |name: &str| {
        lscpu.as_deref().and_then(|t| {
            t.lines()
                .find_map(|l| l.strip_prefix(name))
                .map(|v| v.trim_start_matches(':').trim().to_string())
        })
    };
    // Fall back to /proc/cpuinfo where lscpu is missing (minimal containers).
    let model = field("Model name:").or_else(|| {
        std::fs::read_to_string("/proc/cpuinfo").ok().and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|v| v.trim().to_string())
        })
    });
    let model = model.unwrap_or_else(|| "unknown CPU".to_string());
    let cpus = field("CPU(s):").map_or(String::new(), |c| format!(", {c} CPU(s) in lscpu"));
    format!(
        "{model}{cpus}, {threads} usable by this run ({}, {})",
        std::env::consts::OS,
        std::env::consts::ARCH
    )
}

/// The command as typed, with its cargo equivalent when run through cargo.
fn command_line() -> String {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut cmd = String::from("cargo run --release -p geoshake-paper");
    if !args.is_empty() {
        cmd.push_str(" -- ");
        cmd.push_str(&args.join(" "));
    }
    let exe = std::env::args().next().unwrap_or_default();
    format!("`{cmd}` (executable `{exe}`)")
}

/// Now, as `YYYY-MM-DD HH:MM UTC` (no time-zone database needed).
fn utc_now() -> String {
    let Ok(d) = SystemTime::now().duration_since(UNIX_EPOCH) else {
        return "unknown (clock before 1970)".to_string();
    };
    let secs = d.as_secs() as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02} {:02}:{:02} UTC",
        rem / 3600,
        (rem % 3600) / 60
    )
}
