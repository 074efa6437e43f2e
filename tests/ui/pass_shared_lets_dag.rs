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

fn main() {
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
