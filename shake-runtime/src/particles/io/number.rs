//! Numbers in text, both ways: written so that reading them back gives the
//! same f64 bit for bit, and read with the line they came from.

use super::FileError;
use std::fmt::Write as _;
use std::path::Path;

/// Appends `x` in its shortest decimal form that parses back to the same
/// f64 (Rust's `{}` and `{:e}` both are): plain for 10⁻⁴ ≤ |x| < 10¹⁵ and
/// for 0, scientific otherwise, so that no number runs to hundreds of
/// digits, and an integral value as `20.0`. C's strtod, Python's float
/// and NumPy read every form.
pub(crate) fn push_f64(out: &mut String, x: f64) {
    let a = x.abs();
    if a == 0.0 || (1e-4..1e15).contains(&a) || !x.is_finite() {
        let start = out.len();
        let _ = write!(out, "{x}");
        // An integral value keeps a decimal point: extended XYZ readers
        // (ASE) type `Time=20` as an integer, `Time=20.0` as a float.
        if x.is_finite() && !out[start..].contains('.') {
            out.push_str(".0");
        }
    } else {
        let _ = write!(out, "{x:e}");
    }
}

/// `tok` as a `T`, or a [`FileError::Number`] naming the line and what was
/// expected.
pub(crate) fn parse<T: std::str::FromStr>(
    file: &Path,
    line: usize,
    tok: Option<&str>,
    expected: &str,
) -> Result<T, FileError> {
    tok.and_then(|s| s.parse().ok())
        .ok_or_else(|| FileError::Number {
            file: file.to_path_buf(),
            line,
            expected: expected.to_string(),
            found: tok.unwrap_or("").to_string(),
        })
}

#[cfg(test)]
mod tests {
    use super::push_f64;

    #[test]
    fn round_trip_bit_for_bit() {
        let xs = [
            0.0,
            -0.0,
            1.0,
            0.1,
            1.0 / 3.0,
            -2.5e-300,
            f64::MIN_POSITIVE,
            5e-324,
            f64::MAX,
            123_456_789.123_456_79,
            1e15,
            9.99e-5,
        ];
        for x in xs {
            let mut s = String::new();
            push_f64(&mut s, x);
            let y: f64 = s.parse().unwrap();
            assert_eq!(x.to_bits(), y.to_bits(), "{x:e} written as {s}");
            assert!(s.len() < 30, "{s}");
        }
    }
}
