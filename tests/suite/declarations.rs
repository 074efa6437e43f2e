//! Declarations the macro must accept: each compiles here and its test runs
//! what the declaration promises. They are not trybuild `pass` cases: one
//! such case makes trybuild `cargo build` its project's whole dependency
//! tree in debug, where the refusals (`shake-ui/tests/ui/`) need only
//! `cargo check`.

mod arm_24_rotations {
    use geoshake::constrained_system;

    // A 24-link planar arm with joint angles q[k], the direction (C_k, S_k) of
    // link k by the rotation recurrence (a DAG: each step uses the previous pair
    // twice) and the joints by x_k = x_{k-1} + l C_k; the tip held on x = ax.
    // It took 92 s to expand (the generated docs printed the DAG as a tree).
    constrained_system! {
        pub struct Arm {
            parameters { l, gravity, ax }
            dof q[24], p[24];
            let c0 = cos(q[0]); let s0 = sin(q[0]); let C0 = c0; let S0 = s0; let x0 = l * C0; let y0 = l * S0;
            let c1 = cos(q[1]); let s1 = sin(q[1]); let C1 = C0 * c1 - S0 * s1; let S1 = S0 * c1 + C0 * s1; let x1 = x0 + l * C1; let y1 = y0 + l * S1;
            let c2 = cos(q[2]); let s2 = sin(q[2]); let C2 = C1 * c2 - S1 * s2; let S2 = S1 * c2 + C1 * s2; let x2 = x1 + l * C2; let y2 = y1 + l * S2;
            let c3 = cos(q[3]); let s3 = sin(q[3]); let C3 = C2 * c3 - S2 * s3; let S3 = S2 * c3 + C2 * s3; let x3 = x2 + l * C3; let y3 = y2 + l * S3;
            let c4 = cos(q[4]); let s4 = sin(q[4]); let C4 = C3 * c4 - S3 * s4; let S4 = S3 * c4 + C3 * s4; let x4 = x3 + l * C4; let y4 = y3 + l * S4;
            let c5 = cos(q[5]); let s5 = sin(q[5]); let C5 = C4 * c5 - S4 * s5; let S5 = S4 * c5 + C4 * s5; let x5 = x4 + l * C5; let y5 = y4 + l * S5;
            let c6 = cos(q[6]); let s6 = sin(q[6]); let C6 = C5 * c6 - S5 * s6; let S6 = S5 * c6 + C5 * s6; let x6 = x5 + l * C6; let y6 = y5 + l * S6;
            let c7 = cos(q[7]); let s7 = sin(q[7]); let C7 = C6 * c7 - S6 * s7; let S7 = S6 * c7 + C6 * s7; let x7 = x6 + l * C7; let y7 = y6 + l * S7;
            let c8 = cos(q[8]); let s8 = sin(q[8]); let C8 = C7 * c8 - S7 * s8; let S8 = S7 * c8 + C7 * s8; let x8 = x7 + l * C8; let y8 = y7 + l * S8;
            let c9 = cos(q[9]); let s9 = sin(q[9]); let C9 = C8 * c9 - S8 * s9; let S9 = S8 * c9 + C8 * s9; let x9 = x8 + l * C9; let y9 = y8 + l * S9;
            let c10 = cos(q[10]); let s10 = sin(q[10]); let C10 = C9 * c10 - S9 * s10; let S10 = S9 * c10 + C9 * s10; let x10 = x9 + l * C10; let y10 = y9 + l * S10;
            let c11 = cos(q[11]); let s11 = sin(q[11]); let C11 = C10 * c11 - S10 * s11; let S11 = S10 * c11 + C10 * s11; let x11 = x10 + l * C11; let y11 = y10 + l * S11;
            let c12 = cos(q[12]); let s12 = sin(q[12]); let C12 = C11 * c12 - S11 * s12; let S12 = S11 * c12 + C11 * s12; let x12 = x11 + l * C12; let y12 = y11 + l * S12;
            let c13 = cos(q[13]); let s13 = sin(q[13]); let C13 = C12 * c13 - S12 * s13; let S13 = S12 * c13 + C12 * s13; let x13 = x12 + l * C13; let y13 = y12 + l * S13;
            let c14 = cos(q[14]); let s14 = sin(q[14]); let C14 = C13 * c14 - S13 * s14; let S14 = S13 * c14 + C13 * s14; let x14 = x13 + l * C14; let y14 = y13 + l * S14;
            let c15 = cos(q[15]); let s15 = sin(q[15]); let C15 = C14 * c15 - S14 * s15; let S15 = S14 * c15 + C14 * s15; let x15 = x14 + l * C15; let y15 = y14 + l * S15;
            let c16 = cos(q[16]); let s16 = sin(q[16]); let C16 = C15 * c16 - S15 * s16; let S16 = S15 * c16 + C15 * s16; let x16 = x15 + l * C16; let y16 = y15 + l * S16;
            let c17 = cos(q[17]); let s17 = sin(q[17]); let C17 = C16 * c17 - S16 * s17; let S17 = S16 * c17 + C16 * s17; let x17 = x16 + l * C17; let y17 = y16 + l * S17;
            let c18 = cos(q[18]); let s18 = sin(q[18]); let C18 = C17 * c18 - S17 * s18; let S18 = S17 * c18 + C17 * s18; let x18 = x17 + l * C18; let y18 = y17 + l * S18;
            let c19 = cos(q[19]); let s19 = sin(q[19]); let C19 = C18 * c19 - S18 * s19; let S19 = S18 * c19 + C18 * s19; let x19 = x18 + l * C19; let y19 = y18 + l * S19;
            let c20 = cos(q[20]); let s20 = sin(q[20]); let C20 = C19 * c20 - S19 * s20; let S20 = S19 * c20 + C19 * s20; let x20 = x19 + l * C20; let y20 = y19 + l * S20;
            let c21 = cos(q[21]); let s21 = sin(q[21]); let C21 = C20 * c21 - S20 * s21; let S21 = S20 * c21 + C20 * s21; let x21 = x20 + l * C21; let y21 = y20 + l * S21;
            let c22 = cos(q[22]); let s22 = sin(q[22]); let C22 = C21 * c22 - S21 * s22; let S22 = S21 * c22 + C21 * s22; let x22 = x21 + l * C22; let y22 = y21 + l * S22;
            let c23 = cos(q[23]); let s23 = sin(q[23]); let C23 = C22 * c23 - S22 * s23; let S23 = S22 * c23 + C22 * s23; let x23 = x22 + l * C23; let y23 = y22 + l * S23;
            hamiltonian = sum i in 0..24 { p[i]^2 / 2 } + gravity * (y0 + y1 + y2 + y3 + y4 + y5 + y6 + y7 + y8 + y9 + y10 + y11 + y12 + y13 + y14 + y15 + y16 + y17 + y18 + y19 + y20 + y21 + y22 + y23);
            constraints { tip: x23 - ax }
        }
    }

    #[test]
    fn arm_24_rotations() {
        use geoshake::ConstrainedSystem;
        let arm = Arm::new(1.0, 9.81, 3.0);
        // Straight along x: the tip is at x = 24, g = 24 - 3.
        let mut g = [0.0];
        arm.constraints(&[0.0; 24], &[0.0; 24], &mut g);
        assert!((g[0] - 21.0).abs() < 1e-12, "{}", g[0]);
    }
}

/// A chain of 64 links anchored at the origin: d = 128, m = 64.
mod chain_64 {
    use geoshake::{constrained_system, ConstrainedSystem, Hamiltonian};

    constrained_system! {
        pub struct Chain64 {
            parameters { mass, length, gravity }
            const N = 64;
            dof q[2*N], p[2*N];
            hamiltonian = sum i in 0..N { (p[2*i]^2 + p[2*i+1]^2) / (2*mass) + mass * gravity * q[2*i+1] };
            constraints {
                link[k in 0..N]: if k == 0 { q[0]^2 + q[1]^2 - length^2 }
                    else { (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 },
            }
        }
    }

    #[test]
    fn chain_64() {
        assert_eq!((Chain64::DOF, Chain64::CONSTRAINTS), (128, 64));
        let c = Chain64::new(1.0, 0.1, 9.81);
        assert_eq!((c.dof(), c.constraint_count()), (128, 64));
        assert_eq!(c.jacobian_pattern().len(), 2 + 4 * 63);
    }
}

/// {a, b} = q[0] = a: not identically zero, but zero on M. Accepted.
mod coisotropic_on_m_only {
    use geoshake::constrained_system;

    constrained_system! {
        pub struct OnM {
            dof q[2], p[2];
            hamiltonian = (p[0]^2 + p[1]^2 + q[0]^2 + q[1]^2) / 2;
            constraints {
                a: q[0],
                b: p[1] + q[0] * p[0],
            }
        }
    }

    #[test]
    fn coisotropic_on_m_only() {
        let _ = OnM::new();
    }
}

/// The paper's systems, each in a few lines.
mod paper_systems {
    use geoshake::{constrained_system, ConstrainedSystem, ConstraintKind};

    constrained_system! {
        /// Planar pendulum (Example 1.3).
        pub struct Pendulum {
            parameters { length, gravity }
            dof q[2], p[2];
            let r2 = q[0]^2 + q[1]^2;
            hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
            constraints { rod: r2 - length^2 }
        }
    }

    constrained_system! {
        /// The Hopf constraint without potential (Section 5.4.1).
        pub struct HopfFree {
            parameters { radius2 }
            dof q[2], p[2];
            hamiltonian = (p[0]^2 + p[1]^2) / 2;
            constraints { hopf: q[0]^2 + q[1]^2 + p[0]^2 + p[1]^2 - radius2 }
        }
    }

    constrained_system! {
        /// The Hopf constraint with a linear potential H = |p|²/2 − g·q (Section 5.4.2).
        pub struct HopfGravity {
            parameters { g0, g1, radius2 }
            dof q[2], p[2];
            hamiltonian = (p[0]^2 + p[1]^2) / 2 - (g0 * q[0] + g1 * q[1]);
            constraints { hopf: q[0]^2 + q[1]^2 + p[0]^2 + p[1]^2 - radius2 }
        }
    }

    constrained_system! {
        /// Index-1 constraints (Section 5.3): α = 0, H(q, p, β).
        pub struct IndexOne {
            coordinates q, alpha;
            momenta p, beta;
            hamiltonian = p^2 / 2 + q^2 / 2 + beta^2 / 2 + beta * q;
            constraints { alpha_zero: alpha }
        }
    }

    #[test]
    fn paper_systems() {
        let _ = (
            Pendulum::new(1.0, 9.81),
            HopfFree::new(1.0),
            HopfGravity::new(0.0, -1.0, 0.98),
            IndexOne::new(),
        );
        assert_eq!(
            HopfGravity::new(0.0, -1.0, 0.98).kind(),
            ConstraintKind::Quadratic
        );
        assert_eq!(IndexOne::new().kind(), ConstraintKind::Holonomic);
    }
}

/// Defaults for every parameter give `impl Default` (through `new`, so in
/// declaration order); integers, signs and exponents are read as f64.
mod parameter_defaults {
    use geoshake::constrained_system;

    constrained_system! {
        /// A pendulum in a field that may point up.
        pub struct Pendulum {
            parameters { length = 1.5, gravity = -9.81, mass = 2, tilt = 1e-3 }
            dof q[2], p[2];
            hamiltonian = (p[0]^2 + p[1]^2) / (2 * mass) + mass * gravity * (q[1] + tilt * q[0]);
            constraints { rod: q[0]^2 + q[1]^2 - length^2 }
        }
    }

    constrained_system! {
        /// Without defaults there is no `Default`; named fields still work.
        pub struct Plain {
            parameters { length, gravity }
            dof q[2], p[2];
            hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
            constraints { rod: q[0]^2 + q[1]^2 - length^2 }
        }
    }

    constrained_system! {
        /// The run-time (particles) form takes defaults too.
        pub struct Springs {
            parameters { stiffness = 100.0 }
            particles x[3];
            potential {
                spring[k in springs(a, b; rest)]: stiffness / 2 * (norm(x[a] - x[b]) - rest)^2,
            }
        }
    }

    #[test]
    fn parameter_defaults() {
        assert_eq!(Springs::default(), Springs::new(100.0));
        let p = Pendulum::default();
        assert_eq!(p, Pendulum::new(1.5, -9.81, 2.0, 1e-3));
        assert_eq!(
            (p.length, p.gravity, p.mass, p.tilt),
            (1.5, -9.81, 2.0, 0.001)
        );
        // Struct update syntax: change one parameter by name, keep the rest.
        let long = Pendulum {
            length: 3.0,
            ..Pendulum::default()
        };
        assert_eq!(long.gravity, -9.81);
        let plain = Plain {
            length: 1.0,
            gravity: 9.81,
        };
        assert_eq!(plain, Plain::new(1.0, 9.81));
    }
}

/// m = 0: a plain Hamiltonian system, with named coordinates and no parameters.
mod plain_hamiltonian {
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

    #[test]
    fn plain_hamiltonian() {
        let k = Kepler::new();
        assert_eq!(k.kind(), ConstraintKind::None);
        assert_eq!((Kepler::DOF, Kepler::CONSTRAINTS), (2, 0));
        let h = k.hamiltonian(&[1.0, 0.0], &[0.0, 1.0]);
        assert!((h + 0.5).abs() < 1e-15);
    }
}

mod shared_lets_dag {
    use geoshake::constrained_system;

    // 40 `let`s, each using the one before twice: a DAG of 40 nodes (a tree of 2^40)
    // must expand in time and memory linear in the DAG.
    constrained_system! {
        pub struct Dag {
            dof q[2], p[2];
            let a0 = q[0] + q[1];
            let a1 = sin(a0) * cos(a0);
            let a2 = sin(a1) * cos(a1);
            let a3 = sin(a2) * cos(a2);
            let a4 = sin(a3) * cos(a3);
            let a5 = sin(a4) * cos(a4);
            let a6 = sin(a5) * cos(a5);
            let a7 = sin(a6) * cos(a6);
            let a8 = sin(a7) * cos(a7);
            let a9 = sin(a8) * cos(a8);
            let a10 = sin(a9) * cos(a9);
            let a11 = sin(a10) * cos(a10);
            let a12 = sin(a11) * cos(a11);
            let a13 = sin(a12) * cos(a12);
            let a14 = sin(a13) * cos(a13);
            let a15 = sin(a14) * cos(a14);
            let a16 = sin(a15) * cos(a15);
            let a17 = sin(a16) * cos(a16);
            let a18 = sin(a17) * cos(a17);
            let a19 = sin(a18) * cos(a18);
            let a20 = sin(a19) * cos(a19);
            let a21 = sin(a20) * cos(a20);
            let a22 = sin(a21) * cos(a21);
            let a23 = sin(a22) * cos(a22);
            let a24 = sin(a23) * cos(a23);
            let a25 = sin(a24) * cos(a24);
            let a26 = sin(a25) * cos(a25);
            let a27 = sin(a26) * cos(a26);
            let a28 = sin(a27) * cos(a27);
            let a29 = sin(a28) * cos(a28);
            let a30 = sin(a29) * cos(a29);
            let a31 = sin(a30) * cos(a30);
            let a32 = sin(a31) * cos(a31);
            let a33 = sin(a32) * cos(a32);
            let a34 = sin(a33) * cos(a33);
            let a35 = sin(a34) * cos(a34);
            let a36 = sin(a35) * cos(a35);
            let a37 = sin(a36) * cos(a36);
            let a38 = sin(a37) * cos(a37);
            let a39 = sin(a38) * cos(a38);
            let a40 = sin(a39) * cos(a39);
            hamiltonian = (p[0]^2 + p[1]^2) / 2 + a40;
            constraints { rod: q[0]^2 + q[1]^2 - 1 }
        }
    }

    #[test]
    fn shared_lets_dag() {
        use geoshake::Hamiltonian;
        let s = Dag::new();
        // a_k = sin(a_{k-1}) cos(a_{k-1}) at q = (0.3, 0.4), evaluated by hand.
        let mut a: f64 = 0.7;
        for _ in 0..40 {
            a = a.sin() * a.cos();
        }
        let h = s.hamiltonian(&[0.3, 0.4], &[0.0, 0.0]);
        assert!((h - a).abs() <= 1e-15 * a.abs().max(1e-300), "{h} vs {a}");
    }
}

/// A chain with springs (a potential family) and rigid links (a constraint
/// family), both over run-time tables, with a parameter.
mod topology_spring_chain {
    use geoshake::constrained_system;
    use geoshake::runtime::particles::Stencil;

    constrained_system! {
        pub struct SpringChain {
            parameters { stiffness }
            particles x[3];
            potential {
                spring[k in springs(a, b; rest)]: stiffness / 2 * (norm(x[a] - x[b]) - rest)^2,
            }
            constraints {
                link[k in links(a, b; length)]: norm2(x[a] - x[b]) - length^2,
            }
        }
    }

    #[test]
    fn topology_spring_chain() {
        assert_eq!(SpringChainSpring::ARITY * SpringChainSpring::DIM, 6);
        let chain = SpringChain::new(100.0);
        assert_eq!(chain.spring_stencil().stiffness, 100.0);
        let (mut springs, mut links) = (SpringChain::springs_table(), SpringChain::links_table());
        for i in 0..9 {
            links.push(&[i, i + 1], &[1.0]).unwrap();
        }
        for i in 0..8 {
            springs.push(&[i, i + 2], &[1.5]).unwrap();
        }
        let system = chain.system(vec![1.0; 10], springs, links).unwrap();
        assert_eq!((system.particles(), system.constraints()), (10, 9));
        assert_eq!(system.potential_families()[0].name(), "spring");
    }
}

/// Rigid water over a run-time table: the declaration does not know n.
mod topology_water {
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

    #[test]
    fn topology_water() {
        assert_eq!(
            (WaterBond::ARITY, WaterBond::DIM, WaterBond::DATA),
            (2, 3, 1)
        );
        let mut bonds = Water::bonds_table();
        for m in 0..4 {
            let (o, h1, h2) = (3 * m, 3 * m + 1, 3 * m + 2);
            bonds.push(&[o, h1], &[1.0]).unwrap();
            bonds.push(&[o, h2], &[1.0]).unwrap();
            bonds.push(&[h1, h2], &[1.633]).unwrap();
        }
        let masses = (0..12)
            .map(|i| if i % 3 == 0 { 16.0 } else { 1.0 })
            .collect();
        let water = Water::new().system(masses, bonds).unwrap();
        assert_eq!((water.particles(), water.constraints()), (12, 12));
    }
}
