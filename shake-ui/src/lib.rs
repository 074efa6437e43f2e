//! Nothing to link: the package holds the macro's refusals as trybuild
//! cases (`tests/ui/*.rs`, each with the `.stderr` the macro must give), run
//! by `tests/refusals.rs`. The declarations the macro must accept are
//! ordinary tests in the facade's suite (`tests/suite/declarations.rs`).
