//! Rigid water over a run-time table: the declaration does not know n.
use geoshake::constrained_system;
use geoshake::runtime::particles::Stencil;

constrained_system! {
    /// Rigid water: three distance constraints per molecule.
    pub struct Water {
        particles x[3];
        constraints {
            bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2,
        }
    }
}

fn main() {
    assert_eq!((WaterBond::ARITY, WaterBond::DIM, WaterBond::DATA), (2, 3, 1));
    let mut bonds = Water::bonds_table();
    for m in 0..4 {
        let (o, h1, h2) = (3 * m, 3 * m + 1, 3 * m + 2);
        bonds.push(&[o, h1], &[1.0]).unwrap();
        bonds.push(&[o, h2], &[1.0]).unwrap();
        bonds.push(&[h1, h2], &[1.633]).unwrap();
    }
    let masses = (0..12).map(|i| if i % 3 == 0 { 16.0 } else { 1.0 }).collect();
    let water = Water::new().system(masses, bonds).unwrap();
    assert_eq!((water.particles(), water.constraints()), (12, 12));
}
