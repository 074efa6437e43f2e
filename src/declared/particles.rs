//! Particle systems declared at run time: the families of a `particles x[D];`
//! declaration, each template compiled into a tape
//! ([`geoshake_symbolic::tape::Stencil`]) that a [`Stencil`] of the runtime
//! evaluates.
//!
//! The runtime's stencils have their sizes (particles per member, dimension,
//! numbers per row) as constants, so that each family's cluster kernel is
//! compiled for them; a declaration read at run time picks one of a few
//! instantiations by its shape. There is one per ARITY in 1..=[`MAX_ARITY`]
//! and DIM in {2, 3}; the rows' numbers are padded with zeros to
//! [`MAX_DATA`] (the tape reads only the declared ones), so that the data's
//! width does not multiply the instantiations. Other shapes are refused
//! with [`DeclareError::Shape`].

use super::{parameter_values, DeclareError, MAX_ARITY, MAX_DATA};
use crate::runtime::particles::{ParticleSystem, Stencil, Table, TopologyError};
use geoshake_symbolic::tape;
pub use geoshake_symbolic::{parse_topology::FamilyKind, FamilyShape};

/// A particle system declared from a string in the grammar of
/// [`constrained_system!`](crate::constrained_system) (`particles x[D];`
/// with families over run-time tables), with its parameters' values: the
/// run-time counterpart of the macro's struct. [`system`](Self::system)
/// takes the masses and one table per family, as the macro's `system(..)`
/// does, and gives the same [`ParticleSystem`]; each family evaluates its
/// template by a tape that computes the same `f64`s as the macro's
/// stencil.
///
/// Families of 1 to 4 particles in R² or R³ with at most 4 numbers per
/// row: the runtime compiles a cluster kernel for each stencil shape, so a
/// declaration read at run time picks one of a few compiled shapes (the
/// rows' numbers are padded with zeros to 4, so that their count does not
/// multiply the shapes). Other shapes are refused with
/// [`DeclareError::Shape`].
///
/// ```
/// use geoshake::declared::{DeclareError, DeclaredParticles};
/// use geoshake::runtime::particles::{Options, ParticleState, Rattle, TopologyError};
///
/// let dimer = DeclaredParticles::new(
///     "struct Dimer {
///         particles x[3];
///         constraints { bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2 }
///     }",
///     &[],
/// )
/// .unwrap();
/// let mut bonds = dimer.table("bonds").unwrap();
/// bonds.push(&[0, 1], &[1.0]).unwrap();
/// let system = dimer.system(vec![1.0, 2.0], vec![bonds.clone()]).unwrap();
///
/// let mut rattle = Rattle::new(system, 0.01, Options::default()).unwrap();
/// let mut z = ParticleState::new(vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0], vec![0.0, 1.0, 0.0, 0.0, 0.0, 0.0]);
/// rattle.project(&mut z).unwrap();
/// let out = rattle.run_in_place(&mut z, 100);
/// assert!(out.error.is_none());
/// let r: f64 = (0..3).map(|c| (z.q()[c] - z.q()[3 + c]).powi(2)).sum::<f64>().sqrt();
/// assert!((r - 1.0).abs() < 1e-9);
///
/// // A table naming a particle the system does not have: the runtime's error.
/// let Err(DeclareError::Topology(e)) = dimer.system(vec![1.0], vec![bonds]) else { panic!() };
/// assert!(matches!(e, TopologyError::DanglingParticle { member: 0, particle: 1, .. }));
/// ```
#[derive(Clone, Debug)]
pub struct DeclaredParticles {
    name: String,
    parameter_names: Vec<String>,
    parameters: Vec<f64>,
    dim: usize,
    families: Vec<Family>,
    shapes: Vec<FamilyShape>,
}

/// One family: its shape and its compiled template.
#[derive(Clone, Debug)]
struct Family {
    shape: FamilyShape,
    stencil: tape::Stencil,
}

impl DeclaredParticles {
    /// Parses, checks and compiles `src` (the `struct` of a
    /// `constrained_system!` particle system, without the macro call), with
    /// a value for every declared parameter, by name. A declaration the
    /// macro refuses is a [`DeclareError::Declaration`] with the macro's
    /// message at its line and column in `src`.
    ///
    /// ```
    /// use geoshake::declared::{DeclareError, DeclaredParticles};
    /// let src = "struct S {
    ///     particles x[3];
    ///     constraints { c[k in t(a, b)]: norm2(x[a]) - 1 }
    /// }";
    /// let Err(DeclareError::Declaration(e)) = DeclaredParticles::new(src, &[]) else { panic!() };
    /// assert_eq!((e.line, e.column), (3, 31));
    /// assert!(e.message.contains("does not depend on particle `b`"), "{e}");
    /// ```
    pub fn new(src: &str, parameters: &[(&str, f64)]) -> Result<Self, DeclareError> {
        let declared = geoshake_symbolic::declare_particles(src)?;
        let names = declared.parameters();
        let values = parameter_values(&names, parameters)?;
        let dim = declared.dim();
        let shapes = declared.family_shapes();
        let mut families = Vec::with_capacity(shapes.len());
        for (shape, low) in shapes.iter().zip(&declared.families) {
            if !(1..=MAX_ARITY).contains(&shape.arity)
                || !(2..=3).contains(&dim)
                || shape.data > MAX_DATA
            {
                return Err(DeclareError::Shape {
                    family: shape.name.clone(),
                    arity: shape.arity,
                    dim,
                    data: shape.data,
                });
            }
            let width = shape.arity * dim;
            families.push(Family {
                shape: shape.clone(),
                stencil: tape::Stencil::compile(low, width, shape.data, &values),
            });
        }
        Ok(DeclaredParticles {
            name: declared.name(),
            parameter_names: names,
            parameters: values,
            dim,
            families,
            shapes,
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
        &self.parameters
    }

    /// The dimension D of each particle's position.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The families in declaration order, with what their tables hold.
    pub fn families(&self) -> &[FamilyShape] {
        &self.shapes
    }

    /// An empty table of the right shape for the family whose table is
    /// named `table` (the macro's `*_table()`), `None` if there is none.
    pub fn table(&self, table: &str) -> Option<Table> {
        let s = self.shapes.iter().find(|s| s.table == table)?;
        Some(Table::new(s.arity, s.data))
    }

    /// The particle system: n = `masses.len()` particles in R^D and one
    /// table per family, in declaration order (the macro's `system(..)`).
    /// The runtime checks the masses and the topology exactly as for the
    /// macro's system: a refusal is [`DeclareError::Topology`] with the
    /// runtime's [`TopologyError`] naming the family and the member.
    pub fn system(
        &self,
        masses: Vec<f64>,
        tables: Vec<Table>,
    ) -> Result<ParticleSystem, DeclareError> {
        if tables.len() != self.families.len() {
            let names: Vec<&str> = self.shapes.iter().map(|s| s.table.as_str()).collect();
            return Err(DeclareError::Tables {
                got: tables.len(),
                expected: self.families.len(),
                tables: names.join(", "),
            });
        }
        let mut system = ParticleSystem::new(self.dim, masses)?;
        for (family, table) in self.families.iter().zip(tables) {
            let table = padded(&family.shape, table)?;
            system = add(system, family, table)?;
        }
        Ok(system)
    }
}

/// `table` with its rows' numbers padded with zeros to [`MAX_DATA`], after
/// the shape checks the runtime would make on the table as given.
fn padded(shape: &FamilyShape, table: Table) -> Result<Table, TopologyError> {
    let refuse = |what, got, expected| TopologyError::RowShape {
        family: shape.name.clone(),
        member: 0,
        what,
        got,
        expected,
    };
    if table.arity() != shape.arity {
        return Err(refuse("particle list", table.arity(), shape.arity));
    }
    if table.width() != shape.data {
        return Err(refuse("data", table.width(), shape.data));
    }
    let mut out = Table::with_capacity(shape.arity, MAX_DATA, table.len());
    let mut row = [0.0; MAX_DATA];
    let mut particles = [0usize; MAX_ARITY];
    for k in 0..table.len() {
        row[..shape.data].copy_from_slice(table.data(k));
        for (p, &i) in particles.iter_mut().zip(table.particles(k)) {
            *p = i as usize;
        }
        out.push(&particles[..shape.arity], &row)
            .expect("the same checks accepted this row in the given table");
    }
    Ok(out)
}

/// A runtime [`Stencil`] of `A` particles in R^`D` evaluated by a tape
/// (rows padded to [`MAX_DATA`] numbers).
struct TapeStencil<const A: usize, const D: usize>(tape::Stencil);

impl<const A: usize, const D: usize> Stencil for TapeStencil<A, D> {
    const ARITY: usize = A;
    const DIM: usize = D;
    const DATA: usize = MAX_DATA;

    #[inline]
    fn value(&self, x: &[f64], c: &[f64]) -> f64 {
        self.0.value(x, c)
    }

    #[inline]
    fn gradient(&self, x: &[f64], c: &[f64], grad: &mut [f64]) -> f64 {
        self.0.gradient(x, c, grad)
    }
}

/// Adds `family` over `table` to `system`, through the instantiation of
/// its shape.
fn add(
    system: ParticleSystem,
    family: &Family,
    table: Table,
) -> Result<ParticleSystem, TopologyError> {
    fn with<const A: usize, const D: usize>(
        system: ParticleSystem,
        family: &Family,
        table: Table,
    ) -> Result<ParticleSystem, TopologyError> {
        let stencil = TapeStencil::<A, D>(family.stencil.clone());
        let name = &family.shape.name;
        match family.shape.kind {
            FamilyKind::Constraint => system.with_constraints(name, stencil, table),
            FamilyKind::Potential => system.with_potential(name, stencil, table),
        }
    }
    match (family.shape.arity, system.dim()) {
        (1, 2) => with::<1, 2>(system, family, table),
        (2, 2) => with::<2, 2>(system, family, table),
        (3, 2) => with::<3, 2>(system, family, table),
        (4, 2) => with::<4, 2>(system, family, table),
        (1, 3) => with::<1, 3>(system, family, table),
        (2, 3) => with::<2, 3>(system, family, table),
        (3, 3) => with::<3, 3>(system, family, table),
        (4, 3) => with::<4, 3>(system, family, table),
        _ => unreachable!("`DeclaredParticles::new` refuses other shapes"),
    }
}
