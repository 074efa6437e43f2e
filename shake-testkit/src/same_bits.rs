//! Bit-for-bit equality of two trajectories, for the file round trips
//! (tests/suite/trajectory_csv.rs, tests/trajectory_arrow.rs).

use geoshake::Trajectory;

/// Bit-for-bit equality of everything a trajectory exposes (NaN equals
/// NaN of the same bits; 0.0 and -0.0 differ).
pub fn assert_same_bits(a: &Trajectory, b: &Trajectory) {
    assert_eq!(a.len(), b.len());
    assert_eq!(a.diagnostics.len(), b.diagnostics.len());
    let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    for i in 0..a.len() {
        assert_eq!(a.step(i), b.step(i));
        assert_eq!(a.time(i).to_bits(), b.time(i).to_bits());
        assert_eq!(bits(a.q(i)), bits(b.q(i)), "q of state {i}");
        assert_eq!(bits(a.p(i)), bits(b.p(i)), "p of state {i}");
    }
    for i in 0..a.diagnostics.len() {
        let (x, y) = (&a.diagnostics[i], &b.diagnostics[i]);
        assert_eq!(x.energy.to_bits(), y.energy.to_bits());
        assert_eq!(x.constraint.to_bits(), y.constraint.to_bits());
        assert_eq!(x.hidden_constraint.to_bits(), y.hidden_constraint.to_bits());
        assert_eq!(x.max_lambda.to_bits(), y.max_lambda.to_bits());
        assert_eq!(x.max_condition.to_bits(), y.max_condition.to_bits());
        assert_eq!(bits(a.lambda(i)), bits(b.lambda(i)));
        assert_eq!(bits(a.sigma(i)), bits(b.sigma(i)));
    }
    assert_eq!(a, b);
}
