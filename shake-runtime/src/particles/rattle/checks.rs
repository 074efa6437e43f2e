//! The checks of a [`Rattle`]'s inputs and results: arrays of the system's
//! n·D entries ([`StepError::Shape`]) and finite entries
//! ([`StepError::NonFinite`], named by their entry of z = (q, p)).

use rayon::prelude::*;

use super::{parallel, Rattle, PARALLEL_PARTICLES};
use crate::error::StepError;

impl Rattle {
    pub(in crate::particles) fn check_shape(&self, q: &[f64], p: &[f64]) -> Result<(), StepError> {
        self.check_lengths([("q", q.len()), ("p", p.len())])
    }

    /// `Ok` when every array, given by name and length, has the system's
    /// n·D entries, else [`StepError::Shape`] naming the first that does
    /// not.
    pub(in crate::particles) fn check_lengths<const K: usize>(
        &self,
        arrays: [(&'static str, usize); K],
    ) -> Result<(), StepError> {
        let expected = self.qn.len();
        match arrays.into_iter().find(|&(_, got)| got != expected) {
            Some((what, got)) => Err(StepError::Shape {
                what,
                got,
                expected,
            }),
            None => Ok(()),
        }
    }

    /// `Ok` when every entry of `v` is finite, else [`StepError::NonFinite`]
    /// at step k naming `what` and the entry of z = (q, p) it is (`v` holds
    /// q, or p or a force on p when `offset` = d).
    pub(in crate::particles) fn not_finite(
        step: u64,
        time: f64,
        what: &'static str,
        v: &[f64],
        offset: usize,
    ) -> Result<(), StepError> {
        let bad = |x: &f64| !x.is_finite();
        let first = if parallel(v.len()) {
            let n = PARALLEL_PARTICLES;
            let chunk = |(k, c): (usize, &[f64])| c.iter().position(bad).map(|e| k * n + e);
            v.par_chunks(n).enumerate().find_map_first(chunk)
        } else if crate::linalg::all_finite(v) {
            // (The common case in one pass without an exit per entry,
            // which vectorises; the entry is looked for only on failure.)
            None
        } else {
            v.iter().position(bad)
        };
        match first {
            Some(entry) => Err(StepError::NonFinite {
                what,
                step,
                t: time,
                entry: offset + entry,
            }),
            None => Ok(()),
        }
    }
}
