//! Systems declared at run time, from a string in the grammar of
//! [`constrained_system!`](crate::constrained_system).
//!
//! The string goes through the macro's own front end (`geoshake-symbolic`):
//! the same parsing, differentiation, simplification and checks (coisotropy,
//! Section 3.2; nondegeneracy, Section 5.2), so a declaration the macro
//! refuses at compile time is refused here with the same message, located
//! by line and column in the string. What the macro would emit as Rust is
//! compiled into a tape (`geoshake_symbolic::tape`) that computes the same
//! `f64`s as the macro's code, operation for operation; [`DeclaredSystem`]
//! implements [`Hamiltonian`] and [`ConstrainedSystem`] on it, so an
//! [`Integrator`](crate::Integrator) runs it unchanged.
//!
//! Particle systems (`particles x[D];`, families over run-time tables) are
//! declared the same way by `DeclaredParticles`, with the feature
//! `declared-particles`: each family's template becomes a tape evaluating
//! its value and gradient, and the system is a
//! [`ParticleSystem`](crate::runtime::particles::ParticleSystem) that
//! [`particles::Rattle`](crate::runtime::particles::Rattle) runs. The
//! feature is off by default because it compiles the particle kernels
//! once for each shape a run-time family may have (eight), which made the
//! facade the slowest crate of a build; the Python package turns it on.
//!
//! ```
//! use geoshake::declared::DeclaredSystem;
//! use geoshake::{ImplicitMidpoint, Integrator, State};
//!
//! let pendulum = DeclaredSystem::new(
//!     "struct Pendulum {
//!         parameters { length, gravity }
//!         dof q[2], p[2];
//!         hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
//!         constraints { rod: q[0]^2 + q[1]^2 - length^2 }
//!     }",
//!     &[("length", 1.0), ("gravity", 9.81)],
//! )
//! .unwrap();
//! let mut rattle = Integrator::new(pendulum, ImplicitMidpoint, 0.01).rattle();
//! let z0 = rattle.project_to_hidden(&State::from_slices(&[1.0, 0.0], &[0.0, 0.0])).unwrap();
//! let z1 = rattle.step(&z0).unwrap();
//! assert!((z1.q.norm() - 1.0).abs() < 1e-14);
//! ```

use crate::runtime::{ClosedForm, ConstrainedSystem, ConstraintKind, Hamiltonian};
use geoshake_symbolic::diff::Kind;
use geoshake_symbolic::tape::Program;
pub use geoshake_symbolic::DeclError;
#[cfg(feature = "declared-particles")]
pub use particles::{DeclaredParticles, FamilyKind, FamilyShape};

#[cfg(feature = "declared-particles")]
mod particles;

/// The most particles a member of a run-time family may touch.
const MAX_ARITY: usize = 4;
/// The most numbers a row of a run-time family's table may hold.
const MAX_DATA: usize = 4;

/// Why a run-time declaration was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DeclareError {
    /// The declaration itself: the macro's compile error, with its
    /// position in the string.
    #[error("{0}")]
    Declaration(#[from] DeclError),
    /// A value was given for a name the declaration does not have.
    #[error("unknown parameter `{name}`; {}", if declared.is_empty() { "the declaration has no parameters".to_string() } else { format!("the declaration's parameters are: {declared}") })]
    UnknownParameter {
        /// The name given.
        name: String,
        /// The declared names, comma-separated.
        declared: String,
    },
    /// A declared parameter was given no value.
    #[error("parameter `{name}` is not given a value")]
    MissingParameter {
        /// The declared name.
        name: String,
    },
    /// A parameter was given a value that is not finite: every number
    /// the tape computes from it would be NaN or infinite.
    #[error("parameter `{name}` must be finite, not {value}")]
    NonFiniteParameter {
        /// The name given.
        name: String,
        /// Its value.
        value: f64,
    },
    /// A parameter was given two values.
    #[error("parameter `{name}` is given twice")]
    DuplicateParameter {
        /// The name given twice.
        name: String,
    },
    /// A particle family whose shape (particles per member, dimension) has
    /// no run-time stencil: see `DeclaredParticles` for the shapes there
    /// are.
    #[error(
        "family `{family}`: members of {arity} particles in R^{dim} have no run-time stencil \
         (there are 1 to {max_arity} particles in R^2 or R^3, with at most {max_data} numbers \
         per row); declare this system with `constrained_system!`",
        max_arity = MAX_ARITY,
        max_data = MAX_DATA
    )]
    Shape {
        /// The family.
        family: String,
        /// Its particles per member.
        arity: usize,
        /// The particles' dimension.
        dim: usize,
        /// Its numbers per row.
        data: usize,
    },
    /// `DeclaredParticles::system` was given another number of tables
    /// than the declaration has families.
    #[error("{got} tables given, the declaration has {expected} families ({tables})")]
    Tables {
        /// Tables given.
        got: usize,
        /// Families declared.
        expected: usize,
        /// The tables' names, in declaration order, comma-separated.
        tables: String,
    },
    /// The tables or masses of a particle system: the runtime's refusal.
    #[error(transparent)]
    Topology(#[from] crate::runtime::particles::TopologyError),
}

/// The values of `names` from `given`, by name: every name once.
fn parameter_values(names: &[String], given: &[(&str, f64)]) -> Result<Vec<f64>, DeclareError> {
    let mut values: Vec<Option<f64>> = vec![None; names.len()];
    for &(name, value) in given {
        let i =
            names
                .iter()
                .position(|n| n == name)
                .ok_or_else(|| DeclareError::UnknownParameter {
                    name: name.into(),
                    declared: names.join(", "),
                })?;
        if !value.is_finite() {
            return Err(DeclareError::NonFiniteParameter {
                name: name.into(),
                value,
            });
        }
        if values[i].replace(value).is_some() {
            return Err(DeclareError::DuplicateParameter { name: name.into() });
        }
    }
    values
        .iter()
        .zip(names)
        .map(|(v, n)| v.ok_or_else(|| DeclareError::MissingParameter { name: n.clone() }))
        .collect()
}

/// A constrained Hamiltonian system declared from a string (see the
/// [module documentation](self)), evaluated by a tape.
///
/// `Send` and `Sync`: ensembles share one across threads.
#[derive(Clone, Debug)]
pub struct DeclaredSystem {
    name: String,
    parameter_names: Vec<String>,
    program: Program,
}

impl DeclaredSystem {
    /// Parses, checks and compiles `src` (the `struct` of a
    /// `constrained_system!`, without the macro call), with a value for
    /// every declared parameter, by name.
    ///
    /// ```
    /// use geoshake::declared::{DeclaredSystem, DeclareError};
    /// let src = "struct Free { dof q[1], p[1]; hamiltonian = p[0]^2 / 2 + q[0] * z; }";
    /// let Err(DeclareError::Declaration(e)) = DeclaredSystem::new(src, &[]) else { panic!() };
    /// assert_eq!((e.line, e.column), (1, 65));
    /// ```
    pub fn new(src: &str, parameters: &[(&str, f64)]) -> Result<Self, DeclareError> {
        let declared = geoshake_symbolic::declare(src)?;
        let names = declared.parameters();
        let values = parameter_values(&names, parameters)?;
        let (sys, der) = declared.analysis.values();
        Ok(DeclaredSystem {
            name: declared.name(),
            program: Program::compile(sys, der, &values),
            parameter_names: names,
        })
    }

    /// The declared struct name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The parameter names, in declaration order.
    pub fn parameter_names(&self) -> &[String] {
        &self.parameter_names
    }

    /// The parameter values, in declaration order.
    pub fn parameters(&self) -> &[f64] {
        self.program.parameters()
    }

    /// The compiled functions (tapes), e.g. to count their instructions.
    pub fn program(&self) -> &Program {
        &self.program
    }
}

impl Hamiltonian for DeclaredSystem {
    fn dof(&self) -> usize {
        self.program.dof()
    }

    fn separable(&self) -> bool {
        self.program.separable
    }

    fn quadratic_kinetic(&self) -> bool {
        self.program.quadratic_kinetic
    }

    fn variable_name(&self, k: usize) -> std::borrow::Cow<'_, str> {
        self.program.variable_names[k].as_str().into()
    }

    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        let mut h = 0.0;
        self.program
            .eval(&self.program.hamiltonian, q, p, &[], |_, v| h = v);
        h
    }

    fn grad_q(&self, q: &[f64], p: &[f64], h_q: &mut [f64]) {
        self.program.eval_into(&self.program.grad_q, q, p, &[], h_q);
    }

    fn grad_p(&self, q: &[f64], p: &[f64], h_p: &mut [f64]) {
        self.program.eval_into(&self.program.grad_p, q, p, &[], h_p);
    }

    fn gradient(&self, q: &[f64], p: &[f64], h_q: &mut [f64], h_p: &mut [f64]) {
        let d = self.program.dof();
        self.program
            .eval(&self.program.gradient, q, p, &[], |k, v| {
                if k < d {
                    h_q[k] = v;
                } else {
                    h_p[k - d] = v;
                }
            });
    }

    fn hessian(&self, q: &[f64], p: &[f64], h_zz: &mut [f64]) {
        self.program
            .eval_into(&self.program.hessian, q, p, &[], h_zz);
    }
}

impl ConstrainedSystem for DeclaredSystem {
    fn constraint_count(&self) -> usize {
        self.program.constraint_count()
    }

    fn quadratic_constraints(&self) -> bool {
        self.program.quadratic_constraints
    }

    fn interpreted(&self) -> bool {
        true
    }

    fn kind(&self) -> ConstraintKind {
        match self.program.kind {
            Kind::None => ConstraintKind::None,
            Kind::Holonomic => ConstraintKind::Holonomic,
            Kind::Quadratic => ConstraintKind::Quadratic,
            Kind::General => ConstraintKind::General,
        }
    }

    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        &self.program.jacobian_pattern
    }

    fn constraint_name(&self, i: usize) -> &str {
        &self.program.constraint_names[i]
    }

    fn constraints(&self, q: &[f64], p: &[f64], g: &mut [f64]) {
        self.program
            .eval_into(&self.program.constraints, q, p, &[], g);
    }

    fn constraint_jacobian(&self, q: &[f64], p: &[f64], g_z: &mut [f64]) {
        self.program
            .eval_into(&self.program.jacobian, q, p, &[], g_z);
    }

    fn constraint_jacobian_values(&self, q: &[f64], p: &[f64], values: &mut [f64]) -> bool {
        if values.len() != self.program.jacobian_pattern.len() {
            return false;
        }
        self.program
            .eval_into(&self.program.jacobian_values, q, p, &[], values);
        true
    }

    fn constraint_hessian(&self, q: &[f64], p: &[f64], lambda: &[f64], out: &mut [f64]) {
        let t = &self.program.constraint_hessian;
        self.program.eval_into(t, q, p, lambda, out);
    }

    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        self.program.eval_into(&self.program.hidden, q, p, &[], out);
    }

    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        let t = &self.program.hidden_jacobian;
        self.program.eval_into(t, q, p, &[], out);
    }

    fn nondegeneracy_matrix(&self, q: &[f64], p: &[f64], n: &mut [f64]) {
        let t = &self.program.nondegeneracy;
        self.program.eval_into(t, q, p, &[], n);
    }

    /// For holonomic g: p ← p − g_q(q)ᵀλ (Section 5.1), as the macro emits.
    fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        match &self.program.kick {
            Some(kick) => {
                // The kick reads q and λ only (g = g(q)).
                self.program.eval(kick, q, &[], lambda, |k, v| p[k] -= v);
                ClosedForm::Applied
            }
            None if self.program.kind == Kind::None => ClosedForm::Applied,
            None => ClosedForm::Unavailable,
        }
    }
}
