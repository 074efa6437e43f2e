//! The num-dual baseline: a system whose derivatives are computed at run
//! time by forward-mode automatic differentiation (num-dual 0.15) of H and g
//! written once, generically over the scalar type, and run through the same
//! driver as the generated and the hand-written code.
//!
//! The AD is used as one would use it carefully by hand: gradients and
//! Jacobians by one pass of dual numbers per variable; second derivatives
//! by hyper-dual numbers, one pass per needed pair of directions —
//! N_ij = {{H,g_i},g_j} from the directional second derivatives
//! (J∇H)ᵀ∇²g_i(J∇g_j) and (J∇g_i)ᵀ∇²H(J∇g_j) rather than from full
//! Hessians. Buffers are allocated once (no allocation per call). What AD
//! cannot know is the sparsity: every entry of every output is computed and
//! written.
#![allow(dead_code, clippy::needless_range_loop)]

use geoshake::{ConstrainedSystem, ConstraintKind, Hamiltonian};
use num_dual::{Dual64, DualNum, HyperDual64};
use std::cell::RefCell;

/// H and g written once, generically.
pub trait Generic {
    const DOF: usize;
    const CONSTRAINTS: usize;
    const KIND: ConstraintKind;
    const SEPARABLE: bool;
    const PATTERN: &'static [(usize, usize)];
    fn h<T: DualNum<Primitive = f64> + Copy>(&self, q: &[T], p: &[T]) -> T;
    fn g<T: DualNum<Primitive = f64> + Copy>(&self, q: &[T], p: &[T], out: &mut [T]);
}

/// A [`Generic`] system differentiated by num-dual at run time.
pub struct Ad<G> {
    pub sys: G,
    scratch: RefCell<Scratch>,
}

struct Scratch {
    zd: Vec<Dual64>,
    gd: Vec<Dual64>,
    zh: Vec<HyperDual64>,
    gh: Vec<HyperDual64>,
    /// J∇H and J∇g_j (column j), for the brackets.
    xh: Vec<f64>,
    xg: Vec<f64>,
    grad: Vec<f64>,
    gz: Vec<f64>,
}

impl<G: Generic> Ad<G> {
    pub fn new(sys: G) -> Self {
        let (n, m) = (2 * G::DOF, G::CONSTRAINTS);
        Ad {
            sys,
            scratch: RefCell::new(Scratch {
                zd: vec![Dual64::from(0.0); n],
                gd: vec![Dual64::from(0.0); m],
                zh: vec![HyperDual64::from(0.0); n],
                gh: vec![HyperDual64::from(0.0); m],
                xh: vec![0.0; n],
                xg: vec![0.0; n * m],
                grad: vec![0.0; n],
                gz: vec![0.0; n * m],
            }),
        }
    }
}

impl<G: Generic + Clone> Clone for Ad<G> {
    fn clone(&self) -> Self {
        Ad::new(self.sys.clone())
    }
}

/// v ← J∇F = (F_p, −F_q) from ∇F = (F_q, F_p).
fn j_grad(grad: &[f64], v: &mut [f64]) {
    let d = grad.len() / 2;
    for k in 0..d {
        v[k] = grad[d + k];
        v[d + k] = -grad[k];
    }
}

impl<G: Generic> Ad<G> {
    /// ∇H at z = (q, p) into `s.grad`: one dual pass per variable.
    fn grad_h(&self, s: &mut Scratch, q: &[f64], p: &[f64]) {
        let d = G::DOF;
        for k in 0..d {
            s.zd[k] = Dual64::from(q[k]);
            s.zd[d + k] = Dual64::from(p[k]);
        }
        for k in 0..2 * d {
            s.zd[k].eps = 1.0;
            let (zq, zp) = s.zd.split_at(d);
            s.grad[k] = self.sys.h(zq, zp).eps;
            s.zd[k].eps = 0.0;
        }
    }

    /// g_z (m × 2d, column-major): one dual pass per variable, all g_i.
    fn jac_g(&self, s: &mut Scratch, q: &[f64], p: &[f64], out: &mut [f64]) {
        let (d, m) = (G::DOF, G::CONSTRAINTS);
        for k in 0..d {
            s.zd[k] = Dual64::from(q[k]);
            s.zd[d + k] = Dual64::from(p[k]);
        }
        for k in 0..2 * d {
            s.zd[k].eps = 1.0;
            let (zq, zp) = s.zd.split_at(d);
            self.sys.g(zq, zp, &mut s.gd);
            for i in 0..m {
                out[i + k * m] = s.gd[i].eps;
            }
            s.zd[k].eps = 0.0;
        }
    }
}

/// Sets the hyper-dual point z + ε₁u + ε₂v, z = (q, p).
fn seed(zh: &mut [HyperDual64], q: &[f64], p: &[f64], u: &[f64], v: &[f64]) {
    let d = q.len();
    for k in 0..2 * d {
        let re = if k < d { q[k] } else { p[k - d] };
        zh[k] = HyperDual64::new(re, u[k], v[k], 0.0);
    }
}

impl<G: Generic> Hamiltonian for Ad<G> {
    fn dof(&self) -> usize {
        G::DOF
    }
    fn separable(&self) -> bool {
        G::SEPARABLE
    }
    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        self.sys.h(q, p)
    }
    fn grad_q(&self, q: &[f64], p: &[f64], h_q: &mut [f64]) {
        let s = &mut *self.scratch.borrow_mut();
        self.grad_h(s, q, p);
        h_q.copy_from_slice(&s.grad[..G::DOF]);
    }
    fn grad_p(&self, q: &[f64], p: &[f64], h_p: &mut [f64]) {
        let s = &mut *self.scratch.borrow_mut();
        self.grad_h(s, q, p);
        h_p.copy_from_slice(&s.grad[G::DOF..]);
    }
    fn gradient(&self, q: &[f64], p: &[f64], h_q: &mut [f64], h_p: &mut [f64]) {
        let s = &mut *self.scratch.borrow_mut();
        self.grad_h(s, q, p);
        h_q.copy_from_slice(&s.grad[..G::DOF]);
        h_p.copy_from_slice(&s.grad[G::DOF..]);
    }
    fn hessian(&self, q: &[f64], p: &[f64], h_zz: &mut [f64]) {
        let s = &mut *self.scratch.borrow_mut();
        let d = G::DOF;
        let n = 2 * d;
        for k in 0..d {
            s.zh[k] = HyperDual64::from(q[k]);
            s.zh[d + k] = HyperDual64::from(p[k]);
        }
        for a in 0..n {
            for b in a..n {
                s.zh[a].eps1 = 1.0;
                s.zh[b].eps2 = 1.0;
                let (zq, zp) = s.zh.split_at(d);
                let v = self.sys.h(zq, zp).eps1eps2;
                s.zh[a].eps1 = 0.0;
                s.zh[b].eps2 = 0.0;
                h_zz[a + b * n] = v;
                h_zz[b + a * n] = v;
            }
        }
    }
}

impl<G: Generic> ConstrainedSystem for Ad<G> {
    fn constraint_count(&self) -> usize {
        G::CONSTRAINTS
    }
    fn kind(&self) -> ConstraintKind {
        G::KIND
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        G::PATTERN
    }
    fn constraint_name(&self, i: usize) -> &str {
        let _ = i;
        "g"
    }

    fn constraints(&self, q: &[f64], p: &[f64], g: &mut [f64]) {
        self.sys.g(q, p, g);
    }
    fn constraint_jacobian(&self, q: &[f64], p: &[f64], g_z: &mut [f64]) {
        let s = &mut *self.scratch.borrow_mut();
        self.jac_g(s, q, p, g_z);
    }
    fn constraint_hessian(&self, q: &[f64], p: &[f64], lambda: &[f64], out: &mut [f64]) {
        let s = &mut *self.scratch.borrow_mut();
        let (d, m) = (G::DOF, G::CONSTRAINTS);
        let n = 2 * d;
        for k in 0..d {
            s.zh[k] = HyperDual64::from(q[k]);
            s.zh[d + k] = HyperDual64::from(p[k]);
        }
        for a in 0..n {
            for b in a..n {
                s.zh[a].eps1 = 1.0;
                s.zh[b].eps2 = 1.0;
                let (zq, zp) = s.zh.split_at(d);
                self.sys.g(zq, zp, &mut s.gh);
                let v: f64 = (0..m).map(|i| lambda[i] * s.gh[i].eps1eps2).sum();
                s.zh[a].eps1 = 0.0;
                s.zh[b].eps2 = 0.0;
                out[a + b * n] = v;
                out[b + a * n] = v;
            }
        }
    }
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        // {g_i, H} = ∇g_i · J∇H: ∇H, then one dual pass along J∇H.
        let s = &mut *self.scratch.borrow_mut();
        let d = G::DOF;
        self.grad_h(s, q, p);
        let Scratch {
            zd, gd, xh, grad, ..
        } = s;
        j_grad(grad, xh);
        for k in 0..2 * d {
            let re = if k < d { q[k] } else { p[k - d] };
            zd[k] = Dual64::new(re, xh[k]);
        }
        let (zq, zp) = zd.split_at(d);
        self.sys.g(zq, zp, gd);
        for (o, gi) in out.iter_mut().zip(gd.iter()) {
            *o = gi.eps;
        }
    }
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        // ∇{g_i,H} = ∇²g_i J∇H − ∇²H J∇g_i, column k by the hyper-dual
        // passes (e_k, J∇H) on g and (e_k, J∇g_i) on H.
        let (d, m) = (G::DOF, G::CONSTRAINTS);
        let n = 2 * d;
        let mut g_z = vec![0.0; m * n];
        {
            let s = &mut *self.scratch.borrow_mut();
            self.jac_g(s, q, p, &mut g_z);
            self.grad_h(s, q, p);
        }
        let s = &mut *self.scratch.borrow_mut();
        let xh: Vec<f64> = {
            let mut v = vec![0.0; n];
            j_grad(&s.grad, &mut v);
            v
        };
        let mut e = vec![0.0; n];
        let mut xg = vec![0.0; n];
        let mut grad_i = vec![0.0; n];
        for k in 0..n {
            e.fill(0.0);
            e[k] = 1.0;
            seed(&mut s.zh, q, p, &e, &xh);
            let (zq, zp) = s.zh.split_at(d);
            self.sys.g(zq, zp, &mut s.gh);
            for i in 0..m {
                out[i + k * m] = s.gh[i].eps1eps2;
            }
            for i in 0..m {
                for c in 0..n {
                    grad_i[c] = g_z[i + c * m];
                }
                j_grad(&grad_i, &mut xg);
                seed(&mut s.zh, q, p, &e, &xg);
                let (zq, zp) = s.zh.split_at(d);
                out[i + k * m] -= self.sys.h(zq, zp).eps1eps2;
            }
        }
    }
    fn nondegeneracy_matrix(&self, q: &[f64], p: &[f64], n_out: &mut [f64]) {
        // N_ij = −∇{g_i,H}ᵀ J∇g_j
        //      = (J∇g_i)ᵀ ∇²H (J∇g_j) − (J∇H)ᵀ ∇²g_i (J∇g_j).
        let s = &mut *self.scratch.borrow_mut();
        let (d, m) = (G::DOF, G::CONSTRAINTS);
        let n = 2 * d;
        let mut g_z = std::mem::take(&mut s.gz);
        self.jac_g(s, q, p, &mut g_z);
        // Columns J∇g_j (n each) in s.xg.
        for j in 0..m {
            for c in 0..n {
                s.grad[c] = g_z[j + c * m];
            }
            j_grad(&s.grad, &mut s.xg[j * n..(j + 1) * n]);
        }
        s.gz = g_z;
        self.grad_h(s, q, p);
        j_grad(&s.grad, &mut s.xh);
        for j in 0..m {
            // (J∇H)ᵀ ∇²g_i (J∇g_j) for all i in one pass.
            let Scratch { zh, gh, xh, xg, .. } = s;
            seed(zh, q, p, xh, &xg[j * n..(j + 1) * n]);
            let (zq, zp) = zh.split_at(d);
            self.sys.g(zq, zp, gh);
            for i in 0..m {
                n_out[i + j * m] = -gh[i].eps1eps2;
            }
            for i in 0..=j {
                seed(zh, q, p, &xg[i * n..(i + 1) * n], &xg[j * n..(j + 1) * n]);
                let (zq, zp) = zh.split_at(d);
                let t = self.sys.h(zq, zp).eps1eps2;
                n_out[i + j * m] += t;
                if i != j {
                    n_out[j + i * m] += t;
                }
            }
        }
    }
}
