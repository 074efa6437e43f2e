use geoshake::constrained_system;

constrained_system! {
    pub struct Nothing {
        dof q[1], p[1];
    }
}

fn main() {}
