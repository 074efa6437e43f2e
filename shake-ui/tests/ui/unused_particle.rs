use geoshake::constrained_system;

// The table names three particles but the template only moves two.
constrained_system! {
    pub struct Triangle {
        particles x[2];
        constraints {
            side[k in sides(a, b, c; length)]: norm2(x[a] - x[b]) - length^2,
        }
    }
}

fn main() {}
