//! A compact evaluator for run-time declarations: the CSE'd expression DAG
//! of each function the macro would emit, compiled into a flat instruction
//! array over a register file.
//!
//! # Layout
//!
//! Registers `0..d` hold q, `d..2d` hold p, `2d..2d+m` hold λ, then come the
//! parameters and the constants (the *statics*, copied in when another
//! program last used the thread's register file),
//! then one register per computed node. A particle family's template
//! ([`Stencil`]) has its own inputs (a member's coordinates, its row's
//! numbers) in place of q, p and λ, and is compiled the same way. Hash-consing already made every
//! shared subexpression one node, so, as for the macro's `let`s, a function
//! is scheduled by collecting the nodes its outputs reach and computing
//! each once, by increasing id (a topological order, by the graph's
//! invariant).
//!
//! # Same numbers as the macro
//!
//! Each node is evaluated with the same operations in the same order as the
//! code `constrained_system!` emits for it (sums and products left to right,
//! the coefficient first, negative powers collected into one denominator,
//! x² as x·x, x^n as `powi`, x^½ as `sqrt`): a string-declared system and
//! the macro-declared one compute the same `f64`s.
//!
//! # Cost
//!
//! Evaluation allocates nothing: registers live in a per-thread scratch
//! buffer that grows to the largest tape once.

use crate::diff::{Derived, Kind};
use crate::lower::System;
use crate::symbolic::{Func, Graph, Node, NodeId};
use std::cell::RefCell;
use std::collections::{BTreeSet, HashMap};
use std::sync::atomic::{AtomicU64, Ordering};

mod stencil;

pub use stencil::Stencil;

/// One instruction: `dst = f(a, b)` on registers.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum Op {
    /// `r[d] = r[a] + r[b]`
    Add(u32, u32, u32),
    /// `r[d] = r[a] · r[b]`
    Mul(u32, u32, u32),
    /// `r[d] = r[c] + r[a] · r[b]`: a product whose only reader is a sum,
    /// fused into it (`fuse`), rounded twice as the two operations are.
    MulAdd(u32, u32, u32, u32),
    /// `r[d] = r[a] / r[b]`
    Div(u32, u32, u32),
    /// `r[d] = −r[a]`
    Neg(u32, u32),
    /// `r[d] = r[a]^n`
    Powi(u32, u32, i32),
    /// `r[d] = r[a]^r[b]`
    Powf(u32, u32, u32),
    /// `r[d] = √r[a]`
    Sqrt(u32, u32),
    /// `r[d] = f(r[a])`
    Call(u32, Func, u32),
}

/// The straight-line program of one function: instructions, then outputs
/// `(index, register)` read off the register file.
#[derive(Clone, Debug, Default)]
pub struct Tape {
    ops: Vec<Op>,
    outs: Vec<(u32, u32)>,
    regs: usize,
    /// Whether a program's tape reads p, and λ (`Program::compile`): the
    /// inputs it does not read are not copied in.
    reads_p: bool,
    reads_lambda: bool,
}

impl Tape {
    /// The number of instructions.
    pub fn len(&self) -> usize {
        self.ops.len()
    }

    /// True when the function is only copies (constants, inputs).
    pub fn is_empty(&self) -> bool {
        self.ops.is_empty()
    }

    /// The output indices written, in order.
    pub fn outputs(&self) -> impl Iterator<Item = usize> + '_ {
        self.outs.iter().map(|o| o.0 as usize)
    }
}

/// Every function of a declared system, compiled, with its statics.
///
/// Output layouts are the runtime's (`shake-runtime/src/system.rs`):
/// column-major, q-columns before p-columns, only structurally nonzero
/// entries written.
#[derive(Clone, Debug)]
pub struct Program {
    dof: usize,
    m: usize,
    n_params: usize,
    /// Parameters then constants, copied to registers `2d + m ..`.
    statics: Vec<f64>,
    /// Names this program's statics: the register file skips copying them
    /// when they are already there (a new id on every change).
    id: u64,
    /// H (one output, index 0).
    pub hamiltonian: Tape,
    /// ∂H/∂q (d outputs).
    pub grad_q: Tape,
    /// ∂H/∂p (d outputs).
    pub grad_p: Tape,
    /// ∇H: index k < d is ∂H/∂q_k, d + k is ∂H/∂p_k (shared subexpressions).
    pub gradient: Tape,
    /// H_zz (2d × 2d).
    pub hessian: Tape,
    /// g (m).
    pub constraints: Tape,
    /// g_z (m × 2d).
    pub jacobian: Tape,
    /// g_z's entries packed: output e is the entry (i, k) =
    /// `jacobian_pattern[e]` (the same roots as `jacobian`: the same bits).
    pub jacobian_values: Tape,
    /// Σ λ_i ∇²g_i (2d × 2d).
    pub constraint_hessian: Tape,
    /// {g_i, H} (m).
    pub hidden: Tape,
    /// The Jacobian of {g_i, H} (m × 2d).
    pub hidden_jacobian: Tape,
    /// N_ij = {{H,g_i},g_j} (m × m).
    pub nondegeneracy: Tape,
    /// For holonomic g: (k, Σ_i λ_i ∂g_i/∂q_k), the fibre flow's momentum
    /// kick p_k ← p_k − value (Section 5.1).
    pub kick: Option<Tape>,
    /// How g depends on z.
    pub kind: Kind,
    /// H = T(p) + V(q).
    pub separable: bool,
    /// H = ½ pᵀAp + V(q), A constant.
    pub quadratic_kinetic: bool,
    /// Every g_i of degree at most 2 in z.
    pub quadratic_constraints: bool,
    /// The structurally nonzero (i, k) of g_z, sorted by i then k.
    pub jacobian_pattern: Vec<(usize, usize)>,
    /// The constraint names (`rod`, `link[3]`).
    pub constraint_names: Vec<String>,
    /// The names of z = (q, p), 2d of them (`theta`, `p_theta`; `q[0]`).
    pub variable_names: Vec<String>,
}

/// A register file: the registers and the id of the program whose statics
/// it holds (0: none).
struct Registers {
    r: Vec<f64>,
    statics_of: u64,
}

thread_local! {
    /// The register file, per thread, grown once to the largest tape.
    static REGISTERS: RefCell<Registers> = const {
        RefCell::new(Registers { r: Vec::new(), statics_of: 0 })
    };
}

/// A fresh program id (never 0).
fn next_id() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(1);
    NEXT.fetch_add(1, Ordering::Relaxed)
}

/// Compiles the functions of one graph into tapes over one register
/// layout: the inputs (variables, then λ or a row's data) in registers
/// `0..inputs`, then the statics.
struct Compiler<'a> {
    graph: &'a Graph,
    /// Registers before the statics.
    inputs: usize,
    /// The register of λ_0.
    lambda: usize,
    /// Parameters held as statics; `ParamId`s from here on are inputs
    /// (a row's data), from register `data`.
    n_params: usize,
    data: usize,
    statics: Vec<f64>,
    consts: HashMap<u64, u32>,
}

impl Compiler<'_> {
    fn base(&self) -> usize {
        self.inputs
    }

    fn constant(&mut self, x: f64) -> u32 {
        let base = self.base();
        let statics = &mut self.statics;
        *self.consts.entry(x.to_bits()).or_insert_with(|| {
            statics.push(x);
            (base + statics.len() - 1) as u32
        })
    }

    /// The register of a leaf (inputs and statics), `None` for a computed
    /// node.
    fn leaf(&mut self, id: NodeId) -> Option<u32> {
        match self.graph.node(id) {
            Node::Const(b) => Some(self.constant(f64::from_bits(*b))),
            Node::Var(v) => Some(v.0),
            Node::Lambda(i) => Some(self.lambda as u32 + i),
            Node::Param(p) if (p.0 as usize) < self.n_params => {
                Some((self.base() + p.0 as usize) as u32)
            }
            Node::Param(p) => Some((self.data + p.0 as usize - self.n_params) as u32),
            _ => None,
        }
    }

    fn tape(&mut self, entries: &[(usize, NodeId)]) -> Tape {
        let mut needed = BTreeSet::new();
        let mut stack: Vec<NodeId> = entries.iter().map(|e| e.1).collect();
        while let Some(id) = stack.pop() {
            if needed.insert(id) {
                stack.extend(self.graph.emitted_deps(id));
            }
        }
        let mut em = Emitter {
            ops: Vec::new(),
            next: 0,
            reg: HashMap::new(),
        };
        let mut tape = Tape::default();
        for &id in &needed {
            if let Some(r) = self.leaf(id) {
                em.reg.insert(id, r);
            }
        }
        // Temporaries go past the statics, whose count is only final once
        // every tape is compiled: numbered from `TEMP`, shifted by `shift`.
        for &id in &needed {
            if !em.reg.contains_key(&id) {
                let r = self.node(&mut em, id);
                em.reg.insert(id, r);
            }
        }
        tape.ops = em.ops;
        tape.outs = entries
            .iter()
            .map(|&(i, id)| (i as u32, em.reg[&id]))
            .collect();
        tape.regs = em.next as usize;
        fuse(&mut tape);
        tape
    }

    /// Emits node `id` (its operands already have registers).
    fn node(&mut self, em: &mut Emitter, id: NodeId) -> u32 {
        match self.graph.node(id).clone() {
            Node::Add(ts) => {
                let mut acc = em.reg[&ts[0]];
                for t in ts[1..].iter() {
                    acc = em.op2(Op::Add, acc, em.reg[t]);
                }
                acc
            }
            Node::Mul(fs) => {
                let mut coef = 1.0;
                let mut num = Vec::new();
                let mut den = Vec::new();
                for f in fs.iter() {
                    match self.graph.node(*f) {
                        Node::Const(b) => coef = f64::from_bits(*b),
                        Node::Pow(b, n) if *n < 0 => den.push((*b, -n)),
                        _ => num.push(em.reg[f]),
                    }
                }
                if coef.abs() != 1.0 || num.is_empty() {
                    num.insert(0, self.constant(coef.abs()));
                }
                let mut e = num[0];
                for &f in &num[1..] {
                    e = em.op2(Op::Mul, e, f);
                }
                if !den.is_empty() {
                    let mut d = self.power(em, den[0].0, den[0].1);
                    for &(b, n) in &den[1..] {
                        let f = self.power(em, b, n);
                        d = em.op2(Op::Mul, d, f);
                    }
                    e = em.op2(Op::Div, e, d);
                }
                if coef < 0.0 {
                    e = em.op1(Op::Neg, e);
                }
                e
            }
            Node::Pow(b, n) => self.power(em, b, n),
            Node::PowF(b, r) => {
                let r = f64::from_bits(r);
                let x = em.reg[&b];
                if r == 0.5 {
                    em.op1(Op::Sqrt, x)
                } else if r == -0.5 {
                    let s = em.op1(Op::Sqrt, x);
                    let one = self.constant(1.0);
                    em.op2(Op::Div, one, s)
                } else {
                    let e = self.constant(r);
                    em.op2(Op::Powf, x, e)
                }
            }
            Node::Call(f, x) => {
                let x = em.reg[&x];
                em.op1(|d, a| Op::Call(d, f, a), x)
            }
            Node::Const(_) | Node::Var(_) | Node::Param(_) | Node::Lambda(_) => {
                unreachable!("leaves have registers")
            }
        }
    }

    /// b^n as the macro writes it: b·b, b·b·b, `powi`, 1/(b^−n).
    fn power(&mut self, em: &mut Emitter, base: NodeId, n: i32) -> u32 {
        let b = em.reg[&base];
        match n {
            1 => b,
            2 => em.op2(Op::Mul, b, b),
            3 => {
                let s = em.op2(Op::Mul, b, b);
                em.op2(Op::Mul, s, b)
            }
            n if n < 0 => {
                let d = self.power(em, base, -n);
                let one = self.constant(1.0);
                em.op2(Op::Div, one, d)
            }
            n => em.op1(|d, a| Op::Powi(d, a, n), b),
        }
    }
}

/// Temporaries of one tape, numbered from `TEMP` (shifted past the statics
/// once they are all known).
struct Emitter {
    ops: Vec<Op>,
    next: u32,
    reg: HashMap<NodeId, u32>,
}

/// Temporaries are numbered from here until the statics are known.
const TEMP: u32 = 1 << 31;

impl Emitter {
    fn fresh(&mut self) -> u32 {
        self.next += 1;
        TEMP + self.next - 1
    }
    fn op2(&mut self, f: fn(u32, u32, u32) -> Op, a: u32, b: u32) -> u32 {
        let d = self.fresh();
        self.ops.push(f(d, a, b));
        d
    }
    fn op1(&mut self, f: impl FnOnce(u32, u32) -> Op, a: u32) -> u32 {
        let d = self.fresh();
        self.ops.push(f(d, a));
        d
    }
}

/// Fuses each product that only one sum reads (not an output, not read
/// twice) into that sum: `t = a·b; d = c + t` becomes `d = c + a·b` at the
/// sum's place. Sums of products, the bulk of a constraint's tape and of
/// its derivatives', then take one dispatch of the interpreter per term
/// instead of two. The numbers are the same to the bit: the product is
/// still rounded before the sum (no fused multiply-add), addition is
/// commutative in IEEE arithmetic, and a and b still hold their values at
/// the sum's place (each register is written once per run).
fn fuse(tape: &mut Tape) {
    let mut reads: HashMap<u32, u32> = HashMap::new();
    for r in registers_read(tape) {
        *reads.entry(r).or_insert(0) += 1;
    }
    // The instruction that writes each product read once.
    let mut product: HashMap<u32, usize> = HashMap::new();
    for (i, op) in tape.ops.iter().enumerate() {
        if let Op::Mul(d, _, _) = *op
            && reads.get(&d) == Some(&1)
        {
            product.insert(d, i);
        }
    }
    let mut dead = vec![false; tape.ops.len()];
    for i in 0..tape.ops.len() {
        let Op::Add(d, x, y) = tape.ops[i] else {
            continue;
        };
        // The later term first (a sum's running total is its left operand).
        let fused = [(y, x), (x, y)].into_iter().find_map(|(t, c)| {
            let &at = product.get(&t)?;
            let Op::Mul(_, a, b) = tape.ops[at] else {
                unreachable!("a product's instruction")
            };
            Some((at, Op::MulAdd(d, c, a, b)))
        });
        if let Some((at, op)) = fused {
            dead[at] = true;
            tape.ops[i] = op;
        }
    }
    let mut keep = dead.iter().map(|d| !d);
    tape.ops.retain(|_| keep.next().unwrap_or(true));
}

/// Renumbers a tape's temporaries to start at `first`.
fn shift(tape: &mut Tape, first: u32) {
    let s = |r: &mut u32| {
        if *r >= TEMP {
            *r = *r - TEMP + first;
        }
    };
    for op in &mut tape.ops {
        match op {
            Op::Add(d, a, b) | Op::Mul(d, a, b) | Op::Div(d, a, b) | Op::Powf(d, a, b) => {
                s(d);
                s(a);
                s(b);
            }
            Op::MulAdd(d, c, a, b) => {
                s(d);
                s(c);
                s(a);
                s(b);
            }
            Op::Neg(d, a) | Op::Powi(d, a, _) | Op::Sqrt(d, a) | Op::Call(d, _, a) => {
                s(d);
                s(a);
            }
        }
    }
    for o in &mut tape.outs {
        s(&mut o.1);
    }
    tape.regs += first as usize;
}

/// Upper-triangle entries (a, b) of an n×n symmetric matrix, written to
/// both (a, b) and (b, a), column-major.
fn symmetric(entries: &[((usize, usize), NodeId)], n: usize) -> Vec<(usize, NodeId)> {
    let mut out = Vec::new();
    for &((a, b), node) in entries {
        out.push((a + b * n, node));
        if a != b {
            out.push((b + a * n, node));
        }
    }
    out
}

impl Program {
    /// Compiles every function of a checked system (`sys` and `der` as
    /// returned by [`crate::Analysis::values`]), with parameter values in
    /// declaration order.
    pub fn compile(sys: &System, der: &Derived, params: &[f64]) -> Program {
        let (d, m) = (sys.dof, der.g.len());
        let n2 = 2 * d;
        let mut c = Compiler {
            graph: &sys.graph,
            inputs: n2 + m,
            lambda: n2,
            n_params: sys.params.len(),
            data: n2 + m,
            statics: params.to_vec(),
            consts: HashMap::new(),
        };
        debug_assert_eq!(params.len(), c.n_params);
        let h_q: Vec<_> = der.h_z.iter().filter(|e| e.0 < d).copied().collect();
        let h_p: Vec<_> = der
            .h_z
            .iter()
            .filter(|e| e.0 >= d)
            .map(|e| (e.0 - d, e.1))
            .collect();
        let hamiltonian = c.tape(&[(0, sys.hamiltonian)]);
        let grad_q = c.tape(&h_q);
        let grad_p = c.tape(&h_p);
        let gradient = c.tape(&der.h_z);
        let hessian = c.tape(&symmetric(&der.h_zz, n2));
        let g: Vec<_> = der.g.iter().copied().enumerate().collect();
        let constraints = c.tape(&g);
        let jac: Vec<_> = der.g_z.iter().map(|((i, k), n)| (i + k * m, *n)).collect();
        let jacobian = c.tape(&jac);
        let packed: Vec<_> = der
            .g_z
            .iter()
            .enumerate()
            .map(|(e, (_, n))| (e, *n))
            .collect();
        let jacobian_values = c.tape(&packed);
        let constraint_hessian = c.tape(&symmetric(&der.g_hess, n2));
        let hid: Vec<_> = der
            .hidden
            .iter()
            .copied()
            .enumerate()
            .filter(|(_, n)| !sys.graph.is_zero(*n))
            .collect();
        let hidden = c.tape(&hid);
        let hz: Vec<_> = der
            .hidden_z
            .iter()
            .map(|((i, k), n)| (i + k * m, *n))
            .collect();
        let hidden_jacobian = c.tape(&hz);
        let mut n_entries = Vec::new();
        for (i, row) in der.n.iter().enumerate() {
            for (j, &nij) in row.iter().enumerate() {
                if !sys.graph.is_zero(nij) {
                    n_entries.push((i + j * m, nij));
                }
            }
        }
        let nondegeneracy = c.tape(&n_entries);
        let kick = (der.kind == Kind::Holonomic).then(|| c.tape(&der.kick));
        let first = (c.base() + c.statics.len()) as u32;
        let mut p = Program {
            dof: d,
            m,
            n_params: c.n_params,
            statics: c.statics,
            id: next_id(),
            hamiltonian,
            grad_q,
            grad_p,
            gradient,
            hessian,
            constraints,
            jacobian,
            jacobian_values,
            constraint_hessian,
            hidden,
            hidden_jacobian,
            nondegeneracy,
            kick,
            kind: der.kind,
            separable: der.separable,
            quadratic_kinetic: der.quadratic_kinetic,
            quadratic_constraints: der.quadratic_constraints,
            jacobian_pattern: der.g_z.iter().map(|e| e.0).collect(),
            constraint_names: sys.constraints.iter().map(|c| c.name.clone()).collect(),
            variable_names: sys.graph.names.vars.clone(),
        };
        for t in p.tapes_mut() {
            shift(t, first);
            check_registers(t);
            let reads = |range: std::ops::Range<usize>| {
                registers_read(t).any(|r| range.contains(&(r as usize)))
            };
            (t.reads_p, t.reads_lambda) = (reads(d..n2), reads(n2..n2 + m));
        }
        p
    }

    fn tapes_mut(&mut self) -> impl Iterator<Item = &mut Tape> {
        [
            &mut self.hamiltonian,
            &mut self.grad_q,
            &mut self.grad_p,
            &mut self.gradient,
            &mut self.hessian,
            &mut self.constraints,
            &mut self.jacobian,
            &mut self.jacobian_values,
            &mut self.constraint_hessian,
            &mut self.hidden,
            &mut self.hidden_jacobian,
            &mut self.nondegeneracy,
        ]
        .into_iter()
        .chain(self.kick.as_mut())
    }

    /// d.
    pub fn dof(&self) -> usize {
        self.dof
    }

    /// m.
    pub fn constraint_count(&self) -> usize {
        self.m
    }

    /// The parameter values, in declaration order.
    pub fn parameters(&self) -> &[f64] {
        &self.statics[..self.n_params]
    }

    /// Sets parameter `i` (declaration order).
    pub fn set_parameter(&mut self, i: usize, value: f64) {
        self.statics[..self.n_params][i] = value;
        self.id = next_id();
    }

    /// Runs `tape` at (q, p, λ) and hands each output `(index, value)` to
    /// `out`. `p` and `lambda` may be shorter (empty) when the tape does not
    /// read them (the holonomic kick reads q and λ only).
    #[inline]
    pub fn eval(
        &self,
        tape: &Tape,
        q: &[f64],
        p: &[f64],
        lambda: &[f64],
        mut out: impl FnMut(usize, f64),
    ) {
        with_registers(self.id, tape.regs, |r, fresh| {
            self.run(tape, q, p, lambda, r, fresh, &mut out)
        });
    }

    #[inline]
    #[allow(clippy::too_many_arguments)]
    fn run(
        &self,
        tape: &Tape,
        q: &[f64],
        p: &[f64],
        lambda: &[f64],
        r: &mut [f64],
        statics: bool,
        out: &mut impl FnMut(usize, f64),
    ) {
        let (d, m) = (self.dof, self.m);
        // Element by element: these are a few entries, below the size where
        // a call to memcpy pays. Only what the tape reads (g(q) reads no p):
        // the other registers are never read, whatever they hold.
        for (r, x) in r[..d].iter_mut().zip(q) {
            *r = *x;
        }
        if tape.reads_p {
            for (r, x) in r[d..2 * d].iter_mut().zip(p) {
                *r = *x;
            }
        }
        if tape.reads_lambda {
            for (r, x) in r[2 * d..2 * d + m].iter_mut().zip(lambda) {
                *r = *x;
            }
        }
        if statics {
            let b = 2 * d + m;
            r[b..b + self.statics.len()].copy_from_slice(&self.statics);
        }
        execute(&tape.ops, &mut r[..tape.regs]);
        for &(i, s) in &tape.outs {
            out(i as usize, r[s as usize]);
        }
    }

    /// Runs `tape` and writes each output into `out[index]`.
    #[inline]
    pub fn eval_into(&self, tape: &Tape, q: &[f64], p: &[f64], lambda: &[f64], out: &mut [f64]) {
        self.eval(tape, q, p, lambda, |i, v| out[i] = v);
    }
}

/// Runs `f` on a register file of at least `regs` entries, with whether
/// the statics of program `id` must be copied in (another program used
/// the file last, or it is new).
#[inline]
fn with_registers<R>(id: u64, regs: usize, f: impl FnOnce(&mut [f64], bool) -> R) -> R {
    REGISTERS.with(|cell| match cell.try_borrow_mut() {
        Ok(mut file) => {
            let file = &mut *file;
            if file.r.len() < regs {
                file.r.resize(regs, 0.0);
            }
            let fresh = file.statics_of != id;
            file.statics_of = id;
            f(&mut file.r, fresh)
        }
        // Re-entered from an output callback: a file of its own.
        Err(_) => f(&mut vec![0.0; regs], true),
    })
}

/// The interpreter loop.
///
/// Every register an instruction names is below `r.len()`: `Program::compile`
/// checks it for each tape (`check_registers`) and `run` passes a register
/// file of `tape.regs` entries, so the accesses skip bounds checks (with
/// them the loop runs about twice as slow).
#[inline]
fn execute(ops: &[Op], r: &mut [f64]) {
    let r = r.as_mut_ptr();
    // SAFETY: see above; registers are plain f64 slots, read before the
    // write of the same instruction.
    unsafe {
        let g = |i: u32| *r.add(i as usize);
        let set = |i: u32, v: f64| *r.add(i as usize) = v;
        for op in ops {
            match *op {
                Op::Add(d, a, b) => set(d, g(a) + g(b)),
                Op::Mul(d, a, b) => set(d, g(a) * g(b)),
                Op::MulAdd(d, c, a, b) => set(d, g(c) + g(a) * g(b)),
                Op::Div(d, a, b) => set(d, g(a) / g(b)),
                Op::Neg(d, a) => set(d, -g(a)),
                Op::Powi(d, a, n) => set(d, g(a).powi(n)),
                Op::Powf(d, a, b) => set(d, g(a).powf(g(b))),
                Op::Sqrt(d, a) => set(d, g(a).sqrt()),
                Op::Call(d, f, a) => set(d, f.apply(g(a))),
            }
        }
    }
}

/// Every register `tape` reads: its instructions' operands and its
/// outputs.
fn registers_read(tape: &Tape) -> impl Iterator<Item = u32> + '_ {
    let operands = tape.ops.iter().flat_map(|op| match *op {
        Op::Add(_, a, b) | Op::Mul(_, a, b) | Op::Div(_, a, b) | Op::Powf(_, a, b) => {
            [Some(a), Some(b), None]
        }
        Op::MulAdd(_, c, a, b) => [Some(c), Some(a), Some(b)],
        Op::Neg(_, a) | Op::Powi(_, a, _) | Op::Sqrt(_, a) | Op::Call(_, _, a) => {
            [Some(a), None, None]
        }
    });
    operands.flatten().chain(tape.outs.iter().map(|o| o.1))
}

/// The register an instruction writes.
fn written(op: &Op) -> u32 {
    match *op {
        Op::Add(d, ..)
        | Op::Mul(d, ..)
        | Op::MulAdd(d, ..)
        | Op::Div(d, ..)
        | Op::Powf(d, ..)
        | Op::Neg(d, _)
        | Op::Powi(d, ..)
        | Op::Sqrt(d, _)
        | Op::Call(d, ..) => d,
    }
}

/// Panics unless every register of `tape` is below `tape.regs` (the
/// invariant `execute` relies on; a compiler bug otherwise).
fn check_registers(tape: &Tape) {
    let n = tape.regs as u32;
    let ok = tape.ops.iter().all(|op| written(op) < n) && registers_read(tape).all(|r| r < n);
    assert!(ok, "tape names a register past its register file");
}

#[cfg(test)]
mod tests {
    use super::{execute, fuse, Op, Program, Tape};

    /// A product read once by a sum is fused into it, on either side of
    /// the sum, with the numbers of the two operations to the bit; a
    /// product that is also an output, or read twice, is not.
    #[test]
    fn products_fuse_into_their_sums_with_the_same_numbers() {
        // r6 = r0·r1, r7 = r2·r3, r8 = r6 + r7, r9 = r4·r5, r10 = r9 + r8,
        // r11 = r0·r2 (an output), r12 = r11 + r5, r13 = r1·r3 (read twice),
        // r14 = r13 + r13.
        let ops = vec![
            Op::Mul(6, 0, 1),
            Op::Mul(7, 2, 3),
            Op::Add(8, 6, 7),
            Op::Mul(9, 4, 5),
            Op::Add(10, 9, 8),
            Op::Mul(11, 0, 2),
            Op::Add(12, 11, 5),
            Op::Mul(13, 1, 3),
            Op::Add(14, 13, 13),
        ];
        let outs = vec![(0, 10), (1, 11), (2, 12), (3, 14)];
        let plain = Tape {
            ops,
            outs,
            regs: 15,
            ..Tape::default()
        };
        let mut fused = plain.clone();
        fuse(&mut fused);
        // r7 into r8, r9 into r10; r6, r11 and r13 stay.
        assert_eq!(fused.len(), plain.len() - 2, "{:?}", fused.ops);
        let mut state = 0x2545_f491_4f6c_dd1du64;
        for _ in 0..1000 {
            let mut x = [0.0; 15];
            for v in &mut x[..6] {
                // Uniform in [−1, 1), with all 52 bits of the mantissa in play.
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                *v = (state >> 11) as f64 / (1u64 << 52) as f64 - 1.0;
            }
            let (mut a, mut b) = (x, x);
            execute(&plain.ops, &mut a);
            execute(&fused.ops, &mut b);
            for &(_, r) in &plain.outs {
                assert_eq!(a[r as usize].to_bits(), b[r as usize].to_bits());
            }
        }
    }

    /// Every instruction kind against the formula written by hand: a
    /// Hamiltonian with a quotient, a real power, sqrt, 1/sqrt, powi and the
    /// elementary functions, and its gradient.
    #[test]
    fn tapes_compute_the_declared_functions() {
        let src = "struct S {
            parameters { k }
            dof q[2], p[2];
            hamiltonian = (p[0]^2 + p[1]^2) / (2 * k) + sin(q[0]) * exp(q[1]) - ln(q[0]) / sqrt(q[1])
                + q[0]^5 + q[1]^1.5 + cos(p[0]) + tan(q[1]) - q[0]^(-3);
            constraints { c: q[0]^2 + q[1]^2 - 1 }
        }";
        let decl = crate::declare(src).unwrap();
        let (s, d) = decl.analysis.values();
        let k = 1.7;
        let prog = Program::compile(s, d, &[k]);
        let (q, p) = ([0.6, 0.8], [0.3, -0.4]);
        let h = |q: [f64; 2], p: [f64; 2]| {
            (p[0] * p[0] + p[1] * p[1]) / (2.0 * k) + q[0].sin() * q[1].exp()
                - q[0].ln() / q[1].sqrt()
                + q[0].powi(5)
                + q[1].powf(1.5)
                + p[0].cos()
                + q[1].tan()
                - q[0].powi(-3)
        };
        let mut got = 0.0;
        prog.eval(&prog.hamiltonian, &q, &p, &[], |_, v| got = v);
        let want = h(q, p);
        assert!(
            (got - want).abs() <= 8.0 * f64::EPSILON * want.abs(),
            "{got} {want}"
        );
        // ∂H/∂q_0 by hand.
        let hq0 = q[0].cos() * q[1].exp() - 1.0 / (q[0] * q[1].sqrt())
            + 5.0 * q[0].powi(4)
            + 3.0 * q[0].powi(-4);
        let mut g = [0.0; 2];
        prog.eval_into(&prog.grad_q, &q, &p, &[], &mut g);
        assert!(
            (g[0] - hq0).abs() <= 16.0 * f64::EPSILON * hq0.abs(),
            "{} {hq0}",
            g[0]
        );
        // The constraint and its kick p ← p − λ g_q.
        let mut c = [0.0];
        prog.eval_into(&prog.constraints, &[0.6, 0.9], &p, &[], &mut c);
        assert!((c[0] - (0.36 + 0.81 - 1.0)).abs() <= 4.0 * f64::EPSILON);
        let mut pk = p;
        prog.eval(prog.kick.as_ref().unwrap(), &q, &[], &[0.5], |i, v| {
            pk[i] -= v
        });
        assert_eq!(pk, [p[0] - 0.5 * 2.0 * q[0], p[1] - 0.5 * 2.0 * q[1]]);
    }
}
