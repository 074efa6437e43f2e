//! trybuild UI tests: every `tests/ui/*.rs` is a declaration the macro must
//! refuse (one failure per file, with its `.stderr`), except `pass_*.rs`,
//! which must compile and run.

#[test]
fn ui() {
    let t = trybuild::TestCases::new();
    let mut files: Vec<_> = std::fs::read_dir("tests/ui")
        .expect("tests/ui")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "rs"))
        .collect();
    files.sort();
    for path in files {
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default();
        if name.starts_with("pass_") {
            t.pass(&path);
        } else {
            t.compile_fail(&path);
        }
    }
}
