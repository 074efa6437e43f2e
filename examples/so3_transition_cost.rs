//! What one constrained-HMC transition on SO(3) costs when the target is
//! declared from a string (the tape), as `examples/sampler.py` declares
//! its matrix Fisher target: one chain of `sample` with that script's
//! settings (warm-up 500, 1000 draws, L = 10, seed 1), static or dynamic.
//! Meant to be counted by callgrind, which does not depend on the load:
//!
//! ```text
//! cargo build --release --example so3_transition_cost
//! valgrind --tool=callgrind target/release/examples/so3_transition_cost static
//! ```
//!
//! Prints the transitions, the steps taken, the draws' rejections by the
//! reverse check and by a failed solve, and a checksum of the draws
//! (FNV-1a over their bits, acceptance probabilities and step counts), so
//! that two builds can be compared for bit-identical chains; instructions
//! per transition are callgrind's total over the transitions printed (the
//! declaration itself costs about 1 % of a run). Arguments:
//! `static|dynamic [warmup draws [variant]]`, the variant `tape` (the
//! default) or `compiled` (the same system from `constrained_system!`,
//! the sampler example's `Rotation`). `TAPES=1` prints the size of each
//! tape; `STEP_TOLERANCE=1e-9` sets the solves' Newton step tolerance
//! (`SamplerOptions::newton`; the default is round-off).

use geoshake::declared::DeclaredSystem;
use geoshake::sampler::{sample, SamplerOptions, Samples};
use geoshake::NewtonOptions;

#[path = "sampler/targets.rs"]
#[allow(dead_code)]
mod targets;

/// `targets::Rotation` as `examples/sampler.py` declares it.
const ROTATION: &str = "struct Rotation {
    parameters { kappa }
    dof q[9], p[9];
    hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2 + p[3]^2 + p[4]^2 + p[5]^2
        + p[6]^2 + p[7]^2 + p[8]^2) / 2 - kappa * (q[0] + q[4] + q[8]);
    constraints {
        c00: q[0]^2 + q[3]^2 + q[6]^2 - 1,
        c11: q[1]^2 + q[4]^2 + q[7]^2 - 1,
        c22: q[2]^2 + q[5]^2 + q[8]^2 - 1,
        c01: q[0] * q[1] + q[3] * q[4] + q[6] * q[7],
        c02: q[0] * q[2] + q[3] * q[5] + q[6] * q[8],
        c12: q[1] * q[2] + q[4] * q[5] + q[7] * q[8],
    }
}";

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dynamic = match args.first().map(String::as_str) {
        None | Some("static") => false,
        Some("dynamic") => true,
        Some(other) => panic!("static or dynamic, not {other}"),
    };
    let number = |i: usize, default: usize| args.get(i).map_or(default, |s| s.parse().unwrap());
    let (warmup, draws) = (number(1, 500), number(2, 1000));
    let variant = args.get(3).map_or("tape", String::as_str);
    let q0 = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    let opts = SamplerOptions {
        chains: 1,
        draws,
        warmup,
        steps: 10,
        max_tree_depth: dynamic.then_some(10),
        seed: 1,
        newton: NewtonOptions {
            step_tolerance: std::env::var("STEP_TOLERANCE")
                .map_or(NewtonOptions::default().step_tolerance, |s| {
                    s.parse().unwrap()
                }),
            ..NewtonOptions::default()
        },
        ..SamplerOptions::default()
    };
    let s: Samples = if variant == "compiled" {
        sample(&targets::Rotation { kappa: 1.0 }, &[q0], &opts).unwrap()
    } else {
        let system = DeclaredSystem::new(ROTATION, &[("kappa", 1.0)]).unwrap();
        if std::env::var_os("TAPES").is_some() {
            let pr = system.program();
            for (n, t) in [
                ("g", &pr.constraints),
                ("jv", &pr.jacobian_values),
                ("N", &pr.nondegeneracy),
                ("hidden", &pr.hidden),
                ("gq", &pr.grad_q),
                ("kick", pr.kick.as_ref().unwrap()),
                ("hess_g", &pr.constraint_hessian),
            ] {
                eprintln!("tape {n} ops={} outs={}", t.len(), t.outputs().count());
            }
        }
        sample(&system, &[q0], &opts).unwrap()
    };
    let mut hash = 0xcbf2_9ce4_8422_2325u64;
    let mut mix = |x: u64| {
        hash ^= x;
        hash = hash.wrapping_mul(0x0100_0000_01b3);
    };
    s.positions.iter().for_each(|x| mix(x.to_bits()));
    s.acceptance_probability
        .iter()
        .for_each(|x| mix(x.to_bits()));
    s.steps.iter().for_each(|&n| mix(n as u64));
    let steps: usize = s.steps.iter().sum();
    let accepted = s.accepted.iter().filter(|&&a| a).count();
    let rejected = s.rejections(0);
    println!(
        "so3 integration={} transitions={} draw_steps={steps} accepted={accepted} step_size={:e} checksum={hash:016x} rejected_reverse={} rejected_newton={}",
        if dynamic { "dynamic" } else { "static" },
        warmup + draws,
        s.step_size[0],
        rejected.reverse,
        rejected.newton,
    );
}
