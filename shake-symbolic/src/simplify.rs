//! Smart constructors: every node enters the graph in canonical form.
//!
//! Simplification happens once, at construction, so derivatives and brackets
//! (built through the same constructors) are simplified as they are made. The
//! rules:
//!
//! - constant folding (`2*3` → `6`, `sin(0)` → `0`);
//! - identities `x + 0 → x`, `x * 1 → x`, `x * 0 → 0`, `x^0 → 1`, `x^1 → x`,
//!   `--x → x`, `(x^a)^b → x^(ab)` for integer a, b;
//! - sums are flattened and like terms collected, so `x - x → 0` and
//!   `x + 2x → 3x`; products are flattened and equal bases merged, so
//!   `x * x → x^2` and `x / x → 1` (sound: both sides agree wherever the
//!   left-hand side is defined; at x = 0 the right-hand side is its continuous
//!   extension);
//! - a constant times a sum is distributed (`2(x + y)` → `2x + 2y`);
//! - **canonical polynomial form**: where every factor is a polynomial in z
//!   (parameters count as coefficients), products of sums and positive powers
//!   of sums are expanded, as long as the result has at most
//!   [`EXPAND_LIMIT`] terms. A polynomial then becomes a sum of monomials with
//!   sorted factors and folded coefficients, and two equal polynomials get the
//!   same node: `(x+y)^2 - x^2 - 2xy - y^2` is the constant `0`. This is what
//!   makes "identically zero" (of a bracket, of N) decidable for the
//!   polynomial systems of the paper.
//!
//! In a graph marked `factored` (the one the emitted code is generated
//! from), the two expansions are off: identities are decided on the
//! expanded graph, values are computed in the form the user wrote.
//!
//! Sums and products are sorted by node id. Ids are assigned in creation
//! order, which is deterministic for a given input, so the canonical form is
//! a function of the input alone.

use crate::symbolic::{bits, Func, Graph, Node, NodeId, ParamId, VarId};
use std::collections::BTreeMap;

/// The largest number of terms an expansion into monomials may produce.
pub const EXPAND_LIMIT: usize = 64;

/// A sum (product) with more terms (factors) than this enters a larger sum
/// (product) as one term instead of being flattened into it. Flattening
/// copies the child, so a chain of `let`s `x_k = x_{k−1} + t_k` (or the
/// derivative of a chain of compositions, a product of k factors at link k)
/// would cost O(n²) work and memory; past the limit the copies stop and the
/// cost is linear. Sums and products that size are beyond what collecting
/// like terms is for.
pub const FLATTEN_LIMIT: usize = 64;

/// The largest |n| accepted in `x^n` (integer or real), after merging
/// (`x^a · x^b = x^(a+b)`, `(x^a)^b = x^(ab)`). Beyond it x^n over- or
/// underflows `f64` for every |x| outside [0.5, 2] (2^±1024 is the edge of
/// the exponent range), so such a power is almost surely a mistake; the
/// limit also keeps exponent arithmetic far from `i32` overflow.
pub const MAX_EXPONENT: u32 = 1024;

impl Graph {
    pub fn num(&mut self, x: f64) -> NodeId {
        self.intern(Node::Const(bits(x)))
    }

    pub fn zero(&mut self) -> NodeId {
        self.num(0.0)
    }

    pub fn one(&mut self) -> NodeId {
        self.num(1.0)
    }

    pub fn var(&mut self, v: VarId) -> NodeId {
        self.intern(Node::Var(v))
    }

    pub fn param(&mut self, p: ParamId) -> NodeId {
        self.intern(Node::Param(p))
    }

    pub fn lambda(&mut self, i: usize) -> NodeId {
        self.intern(Node::Lambda(i as u32))
    }

    pub fn neg(&mut self, x: NodeId) -> NodeId {
        let m1 = self.num(-1.0);
        self.mul(vec![m1, x])
    }

    pub fn sub(&mut self, a: NodeId, b: NodeId) -> NodeId {
        let nb = self.neg(b);
        self.add(vec![a, nb])
    }

    pub fn div(&mut self, a: NodeId, b: NodeId) -> NodeId {
        let inv = self.pow(b, -1);
        self.mul(vec![a, inv])
    }

    pub fn add2(&mut self, a: NodeId, b: NodeId) -> NodeId {
        self.add(vec![a, b])
    }

    pub fn mul2(&mut self, a: NodeId, b: NodeId) -> NodeId {
        self.mul(vec![a, b])
    }

    /// Splits a term into (coefficient, rest): `3xy` → (3, `xy`).
    fn split_coef(&mut self, t: NodeId) -> (f64, Option<NodeId>) {
        match self.node(t).clone() {
            Node::Const(b) => (f64::from_bits(b), None),
            Node::Mul(fs) => match self.as_const(fs[0]) {
                Some(c) if fs.len() == 2 => (c, Some(fs[1])),
                Some(c) => (c, Some(self.intern(Node::Mul(fs[1..].into())))),
                None => (1.0, Some(t)),
            },
            _ => (1.0, Some(t)),
        }
    }

    /// `c · rest` for a `rest` without coefficient, without re-running the
    /// product rules (rest is already canonical).
    fn with_coef(&mut self, c: f64, rest: NodeId) -> NodeId {
        if c == 1.0 {
            return rest;
        }
        if c == 0.0 {
            return self.zero();
        }
        let k = self.num(c);
        match self.node(rest).clone() {
            Node::Mul(fs) => {
                let mut v = vec![k];
                v.extend_from_slice(&fs);
                self.intern(Node::Mul(v.into()))
            }
            _ => self.intern(Node::Mul(Box::new([k, rest]))),
        }
    }

    pub fn add(&mut self, terms: Vec<NodeId>) -> NodeId {
        let mut flat = Vec::with_capacity(terms.len());
        for t in terms {
            match self.node(t) {
                Node::Add(c) if c.len() <= FLATTEN_LIMIT => flat.extend_from_slice(c),
                _ => flat.push(t),
            }
        }
        let mut constant = 0.0;
        let mut collected: BTreeMap<NodeId, f64> = BTreeMap::new();
        for t in flat {
            match self.split_coef(t) {
                (c, None) => constant += c,
                (c, Some(rest)) => *collected.entry(rest).or_insert(0.0) += c,
            }
        }
        let mut out = Vec::with_capacity(collected.len() + 1);
        if constant != 0.0 {
            out.push(self.num(constant));
        }
        for (rest, c) in collected {
            if c != 0.0 {
                out.push(self.with_coef(c, rest));
            }
        }
        match out.len() {
            0 => self.zero(),
            1 => out[0],
            _ => {
                out.sort_unstable();
                self.intern(Node::Add(out.into()))
            }
        }
    }

    pub fn mul(&mut self, factors: Vec<NodeId>) -> NodeId {
        let mut flat = Vec::with_capacity(factors.len());
        for f in factors {
            match self.node(f) {
                Node::Mul(c) if c.len() <= FLATTEN_LIMIT => flat.extend_from_slice(c),
                _ => flat.push(f),
            }
        }
        let mut coef = 1.0;
        let mut powers: BTreeMap<NodeId, i32> = BTreeMap::new();
        for f in flat {
            match self.node(f).clone() {
                Node::Const(b) => coef *= f64::from_bits(b),
                // Saturating: a merged exponent past MAX_EXPONENT is refused
                // by the lowering (see `Graph::max_exponent`), never wrapped.
                Node::Pow(base, n) => {
                    let e = powers.entry(base).or_insert(0);
                    *e = e.saturating_add(n);
                }
                _ => {
                    let e = powers.entry(f).or_insert(0);
                    *e = e.saturating_add(1);
                }
            }
        }
        if coef == 0.0 {
            return self.zero();
        }
        let mut rest = Vec::with_capacity(powers.len());
        for (base, n) in powers {
            if n != 0 {
                let f = self.pow_raw(base, n);
                // pow_raw folds constants (e.g. a base that is a constant).
                match self.as_const(f) {
                    Some(c) => coef *= c,
                    None => rest.push(f),
                }
            }
        }
        if coef == 0.0 {
            return self.zero();
        }
        if let Some(expanded) = self.try_expand(coef, &rest) {
            return expanded;
        }
        rest.sort_unstable();
        match rest.len() {
            0 => self.num(coef),
            1 if coef == 1.0 => rest[0],
            _ => {
                let mut v = Vec::with_capacity(rest.len() + 1);
                if coef != 1.0 {
                    v.push(self.num(coef));
                }
                v.extend(rest);
                if v.len() == 1 {
                    return v[0];
                }
                self.intern(Node::Mul(v.into()))
            }
        }
    }

    /// Distributes a product over sums: always for `c · (sum)`, and for
    /// products of polynomial sums within [`EXPAND_LIMIT`] terms.
    fn try_expand(&mut self, coef: f64, factors: &[NodeId]) -> Option<NodeId> {
        if self.factored {
            // The emitted values keep products and powers of sums as the
            // user wrote them: expanding (a − b)² into a² − 2ab + b² cancels
            // catastrophically when |a|, |b| ≫ |a − b|. Only c·(sum) with
            // c = ±2^k is distributed (exact: scaling by 2^k commutes with
            // rounding), so like terms still meet and cancel exactly.
            let scale = coef.abs();
            let exact = scale.is_normal() && scale.to_bits() & ((1u64 << 52) - 1) == 0;
            let sum = factors.len() == 1 && matches!(self.node(factors[0]), Node::Add(_));
            if !(exact && sum && coef != 1.0) {
                return None;
            }
        }
        // Each factor as the list of terms it contributes.
        let mut lists: Vec<Vec<NodeId>> = Vec::with_capacity(factors.len());
        let mut any_sum = false;
        let polynomial = factors.iter().all(|f| self.degree(*f).is_some());
        let mut size = 1usize;
        for &f in factors {
            match self.node(f).clone() {
                Node::Add(ts) => {
                    any_sum = true;
                    size = size.saturating_mul(ts.len());
                    lists.push(ts.to_vec());
                }
                Node::Pow(b, n) if n > 1 && polynomial && matches!(self.node(b), Node::Add(_)) => {
                    let Node::Add(ts) = self.node(b).clone() else {
                        unreachable!()
                    };
                    any_sum = true;
                    for _ in 0..n {
                        size = size.saturating_mul(ts.len());
                        lists.push(ts.to_vec());
                    }
                }
                _ => lists.push(vec![f]),
            }
        }
        if !any_sum
            || coef == 1.0 && factors.len() == 1 && matches!(self.node(factors[0]), Node::Add(_))
        {
            return None;
        }
        let only_constant_times_sum =
            factors.len() == 1 && matches!(self.node(factors[0]), Node::Add(_));
        if !(only_constant_times_sum || polynomial && size <= EXPAND_LIMIT) {
            return None;
        }
        if size > EXPAND_LIMIT * 4 {
            return None;
        }
        let k = self.num(coef);
        let mut products: Vec<Vec<NodeId>> = vec![vec![k]];
        for list in lists {
            let mut next = Vec::with_capacity(products.len() * list.len());
            for p in &products {
                for &t in &list {
                    let mut q = p.clone();
                    q.push(t);
                    next.push(q);
                }
            }
            products = next;
        }
        let terms: Vec<NodeId> = products.into_iter().map(|p| self.mul(p)).collect();
        Some(self.add(terms))
    }

    /// Integer power with folding and the power rules, without expansion.
    fn pow_raw(&mut self, x: NodeId, n: i32) -> NodeId {
        if n == 0 {
            return self.one();
        }
        if n == 1 {
            return x;
        }
        match self.node(x).clone() {
            Node::Const(b) => self.num(f64::from_bits(b).powi(n)),
            Node::Pow(b, m) => match m.checked_mul(n) {
                Some(k) => self.pow_raw(b, k),
                None => self.intern(Node::Pow(x, n)),
            },
            Node::PowF(b, r) => self.powf(b, f64::from_bits(r) * f64::from(n)),
            Node::Mul(fs) if fs.len() <= FLATTEN_LIMIT => {
                let fs: Vec<NodeId> = fs.iter().map(|f| self.pow_raw(*f, n)).collect();
                self.mul(fs)
            }
            _ => self.intern(Node::Pow(x, n)),
        }
    }

    /// x^n for an integer n; expands powers of polynomial sums (canonical
    /// polynomial form) within [`EXPAND_LIMIT`].
    pub fn pow(&mut self, x: NodeId, n: i32) -> NodeId {
        let p = self.pow_raw(x, n);
        if n > 1 && matches!(self.node(p), Node::Pow(..)) {
            // `mul` expands it if it is small and polynomial.
            return self.mul(vec![p]);
        }
        p
    }

    /// x^r for a constant real r (integer r goes to [`Graph::pow`]).
    pub fn powf(&mut self, x: NodeId, r: f64) -> NodeId {
        if r.fract() == 0.0 && r.abs() < f64::from(i32::MAX) {
            return self.pow(x, r as i32);
        }
        match self.node(x).clone() {
            Node::Const(b) => self.num(f64::from_bits(b).powf(r)),
            Node::PowF(b, s) => self.powf(b, f64::from_bits(s) * r),
            _ => self.intern(Node::PowF(x, bits(r))),
        }
    }

    pub fn sqrt(&mut self, x: NodeId) -> NodeId {
        self.powf(x, 0.5)
    }

    pub fn call(&mut self, f: Func, x: NodeId) -> NodeId {
        if let Some(c) = self.as_const(x) {
            return self.num(f.apply(c));
        }
        match (f, self.node(x).clone()) {
            (Func::Ln, Node::Call(Func::Exp, y)) => y,
            _ => self.intern(Node::Call(f, x)),
        }
    }
}
