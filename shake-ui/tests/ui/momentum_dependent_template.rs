use geoshake::constrained_system;

// A run-time family must be holonomic: this template uses momenta.
constrained_system! {
    pub struct Tethered {
        particles x[3];
        constraints {
            tether[k in tethers(a, b; length)]: dot(x[a] - x[b], p[a] - p[b]),
        }
    }
}

fn main() {}
