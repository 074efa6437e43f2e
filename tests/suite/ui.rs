//! trybuild UI tests: every `tests/ui/*.rs` is a declaration the macro must
//! refuse, one failure per file, with its `.stderr`. The declarations it must
//! accept are ordinary tests (`declarations.rs`): with only `compile_fail`
//! cases trybuild runs `cargo check`, with one `pass` case it builds every
//! dev-dependency in debug for its own project.

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
        t.compile_fail(&path);
    }
}
