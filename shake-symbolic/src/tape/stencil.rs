//! The tape of one family's template: f(x; c) and its gradient over the
//! local coordinates x of a member (ARITY·D of them) and the numbers c of
//! its table row, the evaluator of a particle system declared at run time.
//!
//! Registers `0..w` hold x (w = ARITY·D), `w..w + DATA` hold c, then come
//! the statics (the system's parameters and the constants). The nodes are
//! compiled as for [`Program`](super::Program), so a template computes the
//! same `f64`s as the stencil `constrained_system!` emits for it: the
//! value of the form as written, and the gradient with that value
//! recomputed beside it, as the emitted `Stencil::gradient` does.

use super::{check_registers, execute, next_id, shift, with_registers, Compiler, Tape};
use crate::topology::Lowered;
use std::collections::HashMap;

/// One family's template, compiled: f(x; c) and its gradient with the
/// operations of the stencil `constrained_system!` emits for it.
///
/// `Send` and `Sync`: threads evaluate members of one family at once, each
/// on its own register file.
#[derive(Clone, Debug)]
pub struct Stencil {
    width: usize,
    data: usize,
    /// Parameters then constants, copied to registers `width + data ..`.
    statics: Vec<f64>,
    id: u64,
    /// f (one output, index 0).
    value: Tape,
    /// f at index 0, ∂f/∂x_l at index 1 + l.
    gradient: Tape,
}

impl Stencil {
    /// Compiles a lowered template of `width` = ARITY·D local coordinates
    /// and `data` numbers per row, with the system's parameter values in
    /// declaration order.
    ///
    /// ```
    /// use geoshake_symbolic::{declare_particles, tape::Stencil};
    /// let water = declare_particles(
    ///     "struct W { particles x[3];
    ///       constraints { bond[k in bonds(a, b; l)]: norm2(x[a] - x[b]) - l^2 } }",
    /// )
    /// .unwrap();
    /// let bond = Stencil::compile(&water.families[0], 6, 1, &[]);
    /// let mut grad = [0.0; 6];
    /// let g = bond.gradient(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0], &[0.5], &mut grad);
    /// assert_eq!((g, grad), (0.75, [2.0, 0.0, 0.0, -2.0, 0.0, 0.0]));
    /// ```
    pub fn compile(low: &Lowered, width: usize, data: usize, params: &[f64]) -> Stencil {
        let mut c = Compiler {
            graph: &low.graph,
            inputs: width + data,
            lambda: width + data,
            n_params: params.len(),
            data: width,
            statics: params.to_vec(),
            consts: HashMap::new(),
        };
        let mut value = c.tape(&[(0, low.written)]);
        let entries: Vec<_> = std::iter::once(low.written)
            .chain(low.gradient.iter().copied())
            .enumerate()
            .collect();
        let mut gradient = c.tape(&entries);
        let first = (c.base() + c.statics.len()) as u32;
        for t in [&mut value, &mut gradient] {
            shift(t, first);
            check_registers(t);
        }
        Stencil {
            width,
            data,
            statics: c.statics,
            id: next_id(),
            value,
            gradient,
        }
    }

    /// ARITY·D, the local coordinates of a member.
    pub fn width(&self) -> usize {
        self.width
    }

    /// The numbers of a table row.
    pub fn data(&self) -> usize {
        self.data
    }

    /// f(x; c). `x` has [`width`](Self::width) entries, `c` at least
    /// [`data`](Self::data) (the first are read).
    #[inline]
    pub fn value(&self, x: &[f64], c: &[f64]) -> f64 {
        let mut v = 0.0;
        self.run(&self.value, x, c, |_, f| v = f);
        v
    }

    /// f(x; c), with ∂f/∂x written into `grad` (the layout of `x`).
    #[inline]
    pub fn gradient(&self, x: &[f64], c: &[f64], grad: &mut [f64]) -> f64 {
        let mut v = 0.0;
        self.run(&self.gradient, x, c, |i, f| {
            if i == 0 {
                v = f;
            } else {
                grad[i - 1] = f;
            }
        });
        v
    }

    #[inline]
    fn run(&self, tape: &Tape, x: &[f64], c: &[f64], mut out: impl FnMut(usize, f64)) {
        assert!(
            x.len() == self.width && c.len() >= self.data,
            "a member has {} coordinates and {} numbers",
            self.width,
            self.data
        );
        with_registers(self.id, tape.regs, |r, fresh| {
            let (w, n) = (self.width, self.data);
            r[..w].copy_from_slice(x);
            r[w..w + n].copy_from_slice(&c[..n]);
            if fresh {
                r[w + n..w + n + self.statics.len()].copy_from_slice(&self.statics);
            }
            execute(&tape.ops, &mut r[..tape.regs]);
            for &(i, s) in &tape.outs {
                out(i as usize, r[s as usize]);
            }
        });
    }
}
