//! Particle systems declared from a string (`geoshake::declared::DeclaredParticles`)
//! against the same declarations made with `constrained_system!`: the same
//! steps, the same refusals at the same places, and the runtime's topology
//! errors for bad tables.

use geoshake::constrained_system;
use geoshake::declared::{DeclareError, DeclaredParticles};
use geoshake::runtime::particles::{
    generate, Options, ParticleState, ParticleSystem, Rattle, Table, TopologyError,
};

constrained_system! {
    /// Rigid water: three distance constraints per molecule.
    pub struct Water {
        particles x[3];
        constraints {
            bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2,
        }
    }
}

const WATER: &str = "struct Water {
    particles x[3];
    constraints {
        bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2,
    }
}";

constrained_system! {
    /// A chain: springs between next-nearest neighbours, rigid links.
    pub struct SpringChain {
        parameters { stiffness }
        particles x[3];
        potential {
            spring[k in springs(a, b; rest)]: stiffness / 2 * (norm(x[a] - x[b]) - rest)^2,
        }
        constraints {
            link[k in links(a, b; length)]: norm2(x[a] - x[b]) - length^2,
        }
    }
}

const SPRING_CHAIN: &str = "struct SpringChain {
    parameters { stiffness }
    particles x[3];
    potential {
        spring[k in springs(a, b; rest)]: stiffness / 2 * (norm(x[a] - x[b]) - rest)^2,
    }
    constraints {
        link[k in links(a, b; length)]: norm2(x[a] - x[b]) - length^2,
    }
}";

/// Runs `steps` steps of RATTLE (`h`) on each system from the same start,
/// every cluster by Newton, and returns the end states.
fn run_both(
    systems: [ParticleSystem; 2],
    z0: &ParticleState,
    h: f64,
    steps: u64,
) -> Vec<ParticleState> {
    let mut ends = Vec::new();
    for system in systems {
        let mut rattle = Rattle::new(system, h, Options::default()).unwrap();
        rattle.use_newton_cluster_kernel();
        let mut z = ParticleState::new(z0.q().to_vec(), z0.p().to_vec());
        rattle.project(&mut z).unwrap();
        generate::set_temperature(rattle.system(), &mut z, 300.0);
        let out = rattle.run_in_place(&mut z, steps);
        assert!(out.error.is_none(), "{:?}", out.error);
        assert!(out.summary.max_residual.unwrap() <= Options::default().tol);
        ends.push(z);
    }
    ends
}

/// The string-declared family evaluates its template by a tape that
/// performs the operations of the macro's stencil in the same order
/// (`geoshake_symbolic::tape`), so every value and gradient, hence every
/// Newton iterate and every step, is the same `f64`: the states agree
/// bit for bit (tolerance 0), not merely to round-off.
fn assert_same(ends: &[ParticleState]) {
    assert_eq!(ends[0].q(), ends[1].q(), "positions differ");
    assert_eq!(ends[0].p(), ends[1].p(), "momenta differ");
}

#[test]
fn a_water_box_declared_as_a_string_takes_the_macro_steps() {
    let (hand, z0) = generate::water(200, 7).unwrap();
    let bonds = hand.constraint_families()[0].table().clone();
    let masses = hand.masses().to_vec();
    let by_macro = Water::new().system(masses.clone(), bonds.clone()).unwrap();
    let by_string = DeclaredParticles::new(WATER, &[])
        .unwrap()
        .system(masses, vec![bonds])
        .unwrap();
    assert_eq!(by_string.constraints(), 600);
    let ends = run_both([by_macro, by_string], &z0, 2.0, 200);
    assert_same(&ends);
}

#[test]
fn a_spring_chain_declared_as_a_string_takes_the_macro_steps() {
    let (hand, z0) = generate::chain_with_springs(60, 11).unwrap();
    let links = hand.constraint_families()[0].table().clone();
    // The generator's springs hold (stiffness, rest) per row; the template
    // takes the stiffness as a parameter and the rest length per row.
    let given = hand.potential_families()[0].table();
    let stiffness = given.data(0)[0];
    let mut springs = Table::new(2, 1);
    for k in 0..given.len() {
        let ij: Vec<usize> = given.particles(k).iter().map(|&i| i as usize).collect();
        springs.push(&ij, &given.data(k)[1..]).unwrap();
    }
    let masses = hand.masses().to_vec();
    let by_macro = SpringChain::new(stiffness)
        .system(masses.clone(), springs.clone(), links.clone())
        .unwrap();
    let declared = DeclaredParticles::new(SPRING_CHAIN, &[("stiffness", stiffness)]).unwrap();
    let tables: Vec<&str> = declared
        .families()
        .iter()
        .map(|f| f.table.as_str())
        .collect();
    assert_eq!(tables, ["springs", "links"]);
    let by_string = declared.system(masses, vec![springs, links]).unwrap();
    let ends = run_both([by_macro, by_string], &z0, 1.0, 200);
    assert_same(&ends);
}

/// The struct inside `constrained_system! { .. }` of a UI test, with the
/// lines before it left blank, so that a position in the string is the
/// position in the file.
fn declaration_of(ui: &str) -> String {
    let lines: Vec<&str> = ui.lines().collect();
    let open = lines
        .iter()
        .position(|l| l.starts_with("constrained_system!"))
        .expect("a macro call");
    let close = (open + 1..lines.len())
        .find(|&i| lines[i] == "}")
        .expect("the call's end");
    let mut out = vec![""; open + 1];
    out.extend(&lines[open + 1..close]);
    out.join("\n")
}

/// Every UI test of a refused particle declaration, declared as a string:
/// the first error of its `.stderr`, message, line and column.
#[test]
fn refused_declarations_give_the_macro_message_at_its_place() {
    let mut seen = 0;
    let mut files: Vec<_> = std::fs::read_dir("shake-ui/tests/ui")
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "stderr"))
        .collect();
    files.sort();
    for stderr in files {
        let src = std::fs::read_to_string(stderr.with_extension("rs")).unwrap();
        if !src.contains("particles x[") {
            continue;
        }
        let want = std::fs::read_to_string(&stderr).unwrap();
        let message = want
            .lines()
            .next()
            .unwrap()
            .strip_prefix("error: ")
            .unwrap();
        let at = want
            .lines()
            .find_map(|l| l.trim_start().strip_prefix("--> "))
            .unwrap();
        let mut pos = at.rsplit(':').map(|n| n.parse::<usize>().unwrap());
        let (column, line) = (pos.next().unwrap(), pos.next().unwrap());
        let decl = declaration_of(&src);
        let got = match DeclaredParticles::new(&decl, &[]) {
            Err(DeclareError::Declaration(e)) => e,
            other => panic!(
                "{}: not refused as a declaration: {other:?}",
                stderr.display()
            ),
        };
        assert_eq!(got.message, message, "{}", stderr.display());
        assert_eq!(
            (got.line, got.column),
            (line, column),
            "{}",
            stderr.display()
        );
        seen += 1;
    }
    assert!(seen >= 3, "only {seen} particle UI tests found");
}

#[test]
fn a_dangling_index_is_the_runtime_topology_error() {
    let water = DeclaredParticles::new(WATER, &[]).unwrap();
    let mut bonds = water.table("bonds").unwrap();
    bonds.push(&[0, 1], &[1.0]).unwrap();
    bonds.push(&[1, 3], &[1.0]).unwrap();
    let by_string = water.system(vec![16.0, 1.0, 1.0], vec![bonds.clone()]);
    let by_macro = Water::new().system(vec![16.0, 1.0, 1.0], bonds);
    let Err(DeclareError::Topology(e)) = by_string else {
        panic!("accepted, or refused otherwise: {:?}", by_string.err())
    };
    assert_eq!(
        e,
        TopologyError::DanglingParticle {
            family: "bond".into(),
            member: 1,
            particle: 3,
            particles: 3
        }
    );
    assert_eq!(Some(e), by_macro.err());
}

#[test]
fn tables_of_the_wrong_shape_or_number_are_refused() {
    let water = DeclaredParticles::new(WATER, &[]).unwrap();
    let e = water
        .system(vec![1.0; 3], vec![Table::new(2, 2)])
        .err()
        .unwrap();
    assert!(
        matches!(
            e,
            DeclareError::Topology(TopologyError::RowShape {
                what: "data",
                got: 2,
                expected: 1,
                ..
            })
        ),
        "{e:?}"
    );
    let e = water.system(vec![1.0; 3], vec![]).err().unwrap();
    assert!(
        matches!(
            e,
            DeclareError::Tables {
                got: 0,
                expected: 1,
                ..
            }
        ),
        "{e:?}"
    );
    let five = "struct S { particles x[3]; constraints { c[k in t(a, b, c, d, e)]: norm2(x[a] + x[b] + x[c] + x[d] - x[e]) - 1 } }";
    let e = DeclaredParticles::new(five, &[]).unwrap_err();
    assert!(
        matches!(
            e,
            DeclareError::Shape {
                arity: 5,
                dim: 3,
                ..
            }
        ),
        "{e:?}"
    );
}
