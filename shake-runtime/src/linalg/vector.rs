//! Reductions and copies over workspace vectors, written so that they
//! vectorise (or, for a band's few entries, avoid a library call).

/// Largest absolute entry of a slice (NaN entries are skipped, as by
/// `f64::max`).
///
/// Four running maxima instead of one: a single one chains every entry's
/// `max` on the previous one's latency, and `max` is exact in any order,
/// so the lanes give the same number and vectorise.
#[inline]
pub(crate) fn norm_inf(v: &[f64]) -> f64 {
    let mut lanes = [0.0f64; 4];
    let chunks = v.chunks_exact(4);
    let rest = chunks.remainder();
    for c in chunks {
        for (l, x) in lanes.iter_mut().zip(c) {
            *l = l.max(x.abs());
        }
    }
    for x in rest {
        lanes[0] = lanes[0].max(x.abs());
    }
    lanes[0].max(lanes[1]).max(lanes[2].max(lanes[3]))
}

/// `v.fill(0.0)` for the few entries of a band's column: up to eight
/// stores written out, where `fill` would call `memset` (whose call costs
/// more than the stores in a narrow band, once per column and step).
#[inline(always)]
pub(crate) fn zero_short(v: &mut [f64]) {
    if v.len() > 8 {
        return v.fill(0.0);
    }
    for i in 0..8 {
        if i < v.len() {
            v[i] = 0.0;
        }
    }
}

/// Whether every entry is finite. (Without short-circuiting: a flag that
/// every entry `and`s into vectorises, and a run's vectors are finite.)
#[inline]
pub(crate) fn all_finite(v: &[f64]) -> bool {
    v.iter().fold(true, |ok, x| ok & x.is_finite())
}
