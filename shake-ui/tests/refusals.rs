//! trybuild UI tests: every `tests/ui/*.rs` is a declaration the macro must
//! refuse, one failure per file, with its `.stderr`. With only
//! `compile_fail` cases trybuild runs `cargo check`, not a build.

#[test]
fn refusals() {
    let t = trybuild::TestCases::new();
    let mut files: Vec<_> = std::fs::read_dir("tests/ui")
        .expect("tests/ui")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "rs"))
        .collect();
    files.sort();
    for path in files {
        t.compile_fail(&path);
    }
}
