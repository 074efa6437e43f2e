//! Declarations read at run time: the grammar of `constrained_system!` from
//! a string, through the same front end and the same checks, with errors
//! located by line and column in the string instead of by span.

use crate::parse::SystemDef;
use crate::{analyse, parse_topology, Analysis};
use proc_macro2::TokenStream;
use std::fmt;

/// A declaration that parsed and passed every check of the macro.
///
/// It holds the expression graph (with `proc_macro2` identifiers, so it is
/// neither `Send` nor `Sync`): compile it into an evaluator (the runtime's
/// tape) and drop it.
pub struct Declared {
    /// The parsed declaration.
    pub def: SystemDef,
    /// The checked graphs.
    pub analysis: Analysis,
}

impl Declared {
    /// The struct name of the declaration.
    pub fn name(&self) -> String {
        self.def.name.to_string()
    }

    /// The parameter names, in declaration order.
    pub fn parameters(&self) -> Vec<String> {
        self.def.params.iter().map(|p| p.to_string()).collect()
    }

    /// d, the number of coordinates (z ∈ R^{2d}).
    pub fn dof(&self) -> usize {
        self.analysis.checked.0.dof
    }

    /// m, the number of constraints.
    pub fn constraint_count(&self) -> usize {
        self.analysis.checked.0.constraints.len()
    }

    /// The constraint names (`rod`, `link[3]`), in order.
    pub fn constraint_names(&self) -> Vec<String> {
        let sys = &self.analysis.checked.0;
        sys.constraints.iter().map(|c| c.name.clone()).collect()
    }
}

/// A declaration refused: the message the macro would give as a compile
/// error, at the position of the offending token in the string.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DeclError {
    /// The message, word for word the macro's.
    pub message: String,
    /// 1-based line in the string.
    pub line: usize,
    /// 1-based column (in characters) in that line.
    pub column: usize,
}

impl fmt::Display for DeclError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}: {}", self.line, self.column, self.message)
    }
}

impl std::error::Error for DeclError {}

impl DeclError {
    fn at(span: proc_macro2::Span, message: String) -> DeclError {
        let start = span.start();
        DeclError {
            message,
            line: start.line,
            column: start.column + 1,
        }
    }

    /// The first of the errors (the macro reports them all; the first is
    /// the one to fix first).
    fn first(errors: Vec<syn::Error>) -> DeclError {
        let e = errors
            .into_iter()
            .flat_map(|e| e.into_iter())
            .next()
            .expect("a refusal carries at least one error");
        DeclError::at(e.span(), e.to_string())
    }
}

/// Parses and checks a declaration in the grammar of `constrained_system!`
/// (the `struct` with its body, without the macro call around it), exactly
/// as the macro does at compile time: the same refusals, with the same
/// messages, located by line and column in `src`.
///
/// Particle systems (`particles x[3]; ...`, run-time topologies) are not
/// declarable this way yet and are refused.
///
/// # Limits
///
/// No string overflows the stack: past each limit the declaration is
/// refused with a [`DeclError`] at the line and column where the limit is
/// passed.
///
/// - Sums and products of any length: `a + b - c` and `a * b / c % d` are
///   read as flat lists, not as trees as deep as they are long (a sum of
///   10⁵ terms declares in about a second).
/// - One expression nests at most
///   [`MAX_NESTING`](crate::parse::MAX_NESTING) = 256 levels: each
///   parenthesis, unary minus, `^` (right-associative, so `a^b^c` nests),
///   call, `sum` body and `if` branch is a level (a bracket inside a
///   product inside a sum can cost up to three). The error is at the first
///   token past the limit.
/// - Brackets `()`, `[]`, `{}` nest at most
///   [`MAX_BRACKET_DEPTH`](crate::parse::MAX_BRACKET_DEPTH) = 259 deep (an
///   expression's 256 inside the struct's braces, `constraints {}` and a
///   family's `[]`). This is checked on the tokens before they are
///   parsed, so 10⁶ nested parentheses are refused in a fraction of a
///   second, at the first bracket past the limit.
/// - As in the macro: a `let` built on `let`s is at most 1000 operations
///   deep, exponents satisfy |n| ≤ 1024, ranges have at most 10⁵ members,
///   the `sum`s expand to at most 10⁶ terms in all, d ≤ 1024.
///
/// Past the parser, every pass works on the expression graph and is
/// iterative or bounded. At these limits the recursive ones (parsing,
/// lowering) take at most about 0.4 MiB of stack in an optimised build and
/// 1 MiB without optimisation, so a declaration can be read on any thread
/// with the 2 MiB Rust gives a spawned thread.
///
/// ```
/// use geoshake_symbolic::{declare, parse::MAX_BRACKET_DEPTH};
///
/// let head = "struct S { dof q[1], p[1]; hamiltonian = p[0]^2 / 2 + ";
/// let sum = vec!["q[0]^2"; 100_000].join(" + ");
/// assert!(declare(&format!("{head}{sum}; }}")).is_ok());
///
/// let n = 100_000;
/// let deep = format!("{head}{}q[0]{}; }}", "(".repeat(n), ")".repeat(n));
/// let e = declare(&deep).err().unwrap();
/// // The struct's braces are the first level, the first `(` the second.
/// assert_eq!((e.line, e.column), (1, head.len() + MAX_BRACKET_DEPTH));
/// assert!(e.message.contains("nested too deeply"), "{e}");
/// ```
pub fn declare(src: &str) -> Result<Declared, DeclError> {
    let tokens: TokenStream = src.parse().map_err(|e: proc_macro2::LexError| {
        DeclError::at(
            e.span(),
            "the declaration does not split into tokens: unbalanced (), [] or {}, an \
                 unterminated literal or a character outside the grammar"
                .into(),
        )
    })?;
    crate::parse::check_bracket_depth(&tokens).map_err(|e| DeclError::first(vec![e]))?;
    if parse_topology::is_particle_system(&tokens) {
        return Err(DeclError {
            message: "particle systems (run-time topologies) cannot be declared from a string \
                      yet; declare them with `constrained_system!`"
                .into(),
            line: 1,
            column: 1,
        });
    }
    let def: SystemDef = syn::parse2(tokens).map_err(|e| DeclError::first(vec![e]))?;
    let analysis = analyse(&def).map_err(DeclError::first)?;
    Ok(Declared { def, analysis })
}
