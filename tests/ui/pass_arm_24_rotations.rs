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

fn main() {
    use geoshake::ConstrainedSystem;
    let arm = Arm::new(1.0, 9.81, 3.0);
    // Straight along x: the tip is at x = 24, g = 24 - 3.
    let mut g = [0.0];
    arm.constraints(&[0.0; 24], &[0.0; 24], &mut g);
    assert!((g[0] - 21.0).abs() < 1e-12, "{}", g[0]);
}
