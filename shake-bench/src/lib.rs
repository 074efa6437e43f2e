//! The measurement programs are the bench targets in `benches/`; this
//! library is empty (a package needs a library or binary target to hold
//! its dependencies for them).
