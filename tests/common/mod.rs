//! The test kit under the name the tests have always used (`common::models`,
//! …): the code lives in the `shake-testkit` crate.
#[allow(unused_imports)]
pub use shake_testkit::{alloc, models, reference};
