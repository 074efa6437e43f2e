//! Tables from criterion's estimates of the current run
//! (`<target>/criterion/<group>/<id>/new/estimates.json`, median point
//! estimates), printed as markdown.
#![allow(dead_code)]

use std::path::PathBuf;

/// criterion's output directory (it follows `CARGO_TARGET_DIR`; the
/// workspace's `target/` otherwise, one level above this crate).
pub fn criterion_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target"));
    target.join("criterion")
}

/// The median of benchmark `group/id` in seconds, if it ran.
pub fn median(group: &str, id: &str) -> Option<f64> {
    let path = criterion_dir()
        .join(group)
        .join(id.replace('/', "_"))
        .join("new/estimates.json");
    let text = std::fs::read_to_string(path).ok()?;
    let at = text.find("\"median\"")?;
    let rest = &text[at..];
    let at = rest.find("\"point_estimate\":")? + "\"point_estimate\":".len();
    let num: String = rest[at..]
        .chars()
        .take_while(|ch| ch.is_ascii_digit() || matches!(ch, '.' | 'e' | 'E' | '-' | '+'))
        .collect();
    num.parse::<f64>().ok().map(|ns| ns * 1e-9)
}

/// A duration in the unit that suits it.
pub fn fmt_time(s: f64) -> String {
    if s < 1e-6 {
        format!("{:.0} ns", s * 1e9)
    } else if s < 1e-3 {
        format!("{:.2} µs", s * 1e6)
    } else {
        format!("{:.2} ms", s * 1e3)
    }
}

fn cell(x: Option<f64>) -> String {
    x.map(fmt_time).unwrap_or_else(|| "—".into())
}

fn ratio(a: Option<f64>, b: Option<f64>) -> String {
    match (a, b) {
        (Some(a), Some(b)) => format!("{:.2}", a / b),
        _ => "—".into(),
    }
}

/// One table per method: hand, generated, num-dual and the two ratios.
pub fn step_cost_tables(groups: &[&str]) {
    for method in ["shake", "rattle"] {
        println!("\n### One {} step (median)\n", method.to_uppercase());
        println!("| scene | hand-written | generated | num-dual | generated / hand | num-dual / generated |");
        println!("|---|---:|---:|---:|---:|---:|");
        for g in groups {
            let hand = median(g, &format!("{method}/hand"));
            let generated = median(g, &format!("{method}/generated"));
            let dual = median(g, &format!("{method}/num-dual"));
            if hand.is_none() && generated.is_none() {
                continue;
            }
            println!(
                "| {g} | {} | {} | {} | {} | {} |",
                cell(hand),
                cell(generated),
                cell(dual),
                ratio(generated, hand),
                ratio(dual, generated)
            );
        }
    }
}
