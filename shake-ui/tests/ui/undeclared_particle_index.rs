use geoshake::constrained_system;

// `c` is used as a particle but the table declares only `a` and `b`.
constrained_system! {
    pub struct Angles {
        particles x[3];
        constraints {
            angle[k in angles(a, b; cosine)]: dot(x[a] - x[b], x[c] - x[b]) - cosine,
        }
    }
}

fn main() {}
