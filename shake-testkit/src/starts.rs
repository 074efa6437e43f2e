//! Moving states on M for the tests that compare two ways of taking the
//! same steps (`tests/suite/fast_paths.rs`, `tests/suite/run_lane.rs`): generic
//! enough that no coordinate or velocity is zero by symmetry.

use geoshake::State;

/// On the rods of lengths 1 and 0.7 of the double pendulum
/// (`geoshake::models::DoublePendulum`), moving.
pub fn double_pendulum() -> State {
    let (t1, t2) = (0.7f64, -0.4f64);
    let (x1, y1) = (t1.sin(), -t1.cos());
    let (x2, y2) = (x1 + 0.7 * t2.sin(), y1 - 0.7 * t2.cos());
    State::from_slices(&[x1, y1, x2, y2], &[0.5, 0.2, -0.3, 0.8])
}

/// A chain of `links` unit links from the origin at varied angles, each
/// bob moving as its link's rotation and its predecessors' make it.
pub fn chain(links: usize) -> State {
    let (mut q, mut p) = (vec![0.0; 2 * links], vec![0.0; 2 * links]);
    let (mut x, mut y, mut vx, mut vy) = (0.0, 0.0, 0.0, 0.0);
    for k in 0..links {
        let (th, om) = (
            0.3 + 0.7 * (1.3 * k as f64).sin(),
            0.5 * (0.9 * k as f64).cos(),
        );
        x += th.sin();
        y -= th.cos();
        vx += om * th.cos();
        vy += om * th.sin();
        q[2 * k] = x;
        q[2 * k + 1] = y;
        p[2 * k] = vx;
        p[2 * k + 1] = vy;
    }
    State::from_slices(&q, &p)
}
