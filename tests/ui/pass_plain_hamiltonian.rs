//! m = 0: a plain Hamiltonian system, with named coordinates and no parameters.
use geoshake::{constrained_system, ConstrainedSystem, ConstraintKind, Hamiltonian};

constrained_system! {
    /// The Kepler problem.
    pub(crate) struct Kepler {
        coordinates x, y;
        momenta px, py;
        let r = sqrt(x^2 + y^2);
        hamiltonian = (px^2 + py^2) / 2 - 1 / r;
    }
}

fn main() {
    let k = Kepler::new();
    assert_eq!(k.kind(), ConstraintKind::None);
    assert_eq!((Kepler::DOF, Kepler::CONSTRAINTS), (2, 0));
    let h = k.hamiltonian(&[1.0, 0.0], &[0.0, 1.0]);
    assert!((h + 0.5).abs() < 1e-15);
}
