use geoshake::constrained_system;

// x[a] - x[b] + x[b] - x[a] cancels: the gradient is identically zero.
constrained_system! {
    pub struct Nothing {
        particles x[3];
        constraints {
            none[k in pairs(a, b; length)]: norm2(x[a] - x[b] + x[b] - x[a]) - length^2,
        }
    }
}

fn main() {}
