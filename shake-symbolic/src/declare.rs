//! Declarations read at run time: the grammar of `constrained_system!` from
//! a string, through the same front end and the same checks, with errors
//! located by line and column in the string instead of by span.

use crate::parse::SystemDef;
use crate::parse_topology::{FamilyKind, ParticleDef};
use crate::topology::Lowered;
use crate::{analyse, parse_topology, topology, Analysis};
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

/// A particle system (`particles x[D];`, families over run-time tables)
/// that parsed and passed every check of the macro: each family's template
/// lowered and differentiated, ready to be compiled into an evaluator
/// ([`tape::Stencil`](crate::tape::Stencil)).
///
/// Like [`Declared`], it holds `proc_macro2` identifiers: neither `Send`
/// nor `Sync`.
pub struct DeclaredParticles {
    /// The parsed declaration.
    pub def: ParticleDef,
    /// Every family's lowered template, in declaration order.
    pub families: Vec<Lowered>,
}

impl DeclaredParticles {
    /// The struct name of the declaration.
    pub fn name(&self) -> String {
        self.def.name.to_string()
    }

    /// The parameter names, in declaration order.
    pub fn parameters(&self) -> Vec<String> {
        self.def.params.iter().map(|p| p.to_string()).collect()
    }

    /// D, the dimension of each particle's position.
    pub fn dim(&self) -> usize {
        self.def.dim
    }

    /// The families, in declaration order (potential and constraint
    /// families interleaved as written): name, kind, table name, ARITY
    /// (particles per row) and DATA (numbers per row).
    pub fn family_shapes(&self) -> Vec<FamilyShape> {
        self.def
            .families
            .iter()
            .map(|f| FamilyShape {
                name: f.name.to_string(),
                kind: f.kind,
                table: f.table.to_string(),
                arity: f.particles.len(),
                data: f.data.len(),
            })
            .collect()
    }
}

/// What a family of a [`DeclaredParticles`] needs of its table.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FamilyShape {
    /// The family's name (`bond`).
    pub name: String,
    /// Constraint or potential.
    pub kind: FamilyKind,
    /// The table's name (`bonds`).
    pub table: String,
    /// Particle indices per row.
    pub arity: usize,
    /// Numbers per row.
    pub data: usize,
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
/// Particle systems (`particles x[3]; ...`, run-time topologies) are
/// declared by [`declare_particles`] and refused here.
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
    let tokens = tokens(src)?;
    if parse_topology::is_particle_system(&tokens) {
        return Err(DeclError {
            message: "this is a particle system (`particles x[D];`, families over run-time \
                      tables): declare it with `declare_particles`"
                .into(),
            line: 1,
            column: 1,
        });
    }
    let def: SystemDef = syn::parse2(tokens).map_err(|e| DeclError::first(vec![e]))?;
    let analysis = analyse(&def).map_err(DeclError::first)?;
    Ok(Declared { def, analysis })
}

/// Parses and checks a particle system (`particles x[D];` with families
/// over run-time tables) exactly as `constrained_system!` does at compile
/// time: the same refusals with the same messages, located by line and
/// column in `src` (the first, when the macro would report several). The
/// limits are those of [`declare`].
///
/// ```
/// use geoshake_symbolic::declare_particles;
/// let src = "struct Water {
///     particles x[3];
///     constraints { bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2 }
/// }";
/// let water = declare_particles(src).unwrap();
/// let shapes = water.family_shapes();
/// assert_eq!((water.dim(), shapes[0].arity, shapes[0].data), (3, 2, 1));
///
/// let Err(e) = declare_particles(&src.replace("x[b])", "x[c])")) else { panic!() };
/// assert_eq!((e.line, e.column), (3, 66));
/// assert!(e.message.contains("`c` is not a particle of the table"), "{e}");
/// ```
pub fn declare_particles(src: &str) -> Result<DeclaredParticles, DeclError> {
    let tokens = tokens(src)?;
    if !parse_topology::is_particle_system(&tokens) {
        return Err(DeclError {
            message: "this is not a particle system (it has no `particles x[D];` item): \
                      declare it with `declare`"
                .into(),
            line: 1,
            column: 1,
        });
    }
    let def: ParticleDef = syn::parse2(tokens).map_err(|e| DeclError::first(vec![e]))?;
    let families = topology::analyse(&def).map_err(DeclError::first)?;
    Ok(DeclaredParticles { def, families })
}

/// `src` split into tokens, with the bracket depth checked before anything
/// recursive reads them.
fn tokens(src: &str) -> Result<TokenStream, DeclError> {
    let tokens: TokenStream = src.parse().map_err(|e: proc_macro2::LexError| {
        DeclError::at(
            e.span(),
            "the declaration does not split into tokens: unbalanced (), [] or {}, an \
                 unterminated literal or a character outside the grammar"
                .into(),
        )
    })?;
    crate::parse::check_bracket_depth(&tokens).map_err(|e| DeclError::first(vec![e]))?;
    Ok(tokens)
}
