//! A chain with springs (a potential family) and rigid links (a constraint
//! family), both over run-time tables, with a parameter.
use geoshake::constrained_system;
use geoshake::runtime::particles::Stencil;

constrained_system! {
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

fn main() {
    assert_eq!(SpringChainSpring::ARITY * SpringChainSpring::DIM, 6);
    let chain = SpringChain::new(100.0);
    assert_eq!(chain.spring_stencil().stiffness, 100.0);
    let (mut springs, mut links) = (SpringChain::springs_table(), SpringChain::links_table());
    for i in 0..9 {
        links.push(&[i, i + 1], &[1.0]).unwrap();
    }
    for i in 0..8 {
        springs.push(&[i, i + 2], &[1.5]).unwrap();
    }
    let system = chain.system(vec![1.0; 10], springs, links).unwrap();
    assert_eq!((system.particles(), system.constraints()), (10, 9));
    assert_eq!(system.potential_families()[0].name(), "spring");
}
