//! The symbolic phase: the constraint graph (constraints joined when they
//! share a particle), its connected components (clusters), the checks that
//! need the concrete topology, and the pattern of N = G M⁻¹ Gᵀ.

use super::plan::{FamilyClusters, MAX_CLUSTER, MAX_CLUSTER_COORDS};
use super::{ParticleSystem, TopologyError};
use crate::error::{SolveError, Stage, StepError};

/// Constraint c of the system as (family, member).
#[derive(Clone, Debug)]
pub(crate) struct Numbering {
    /// Global number of each family's first constraint (one more entry).
    pub(crate) offsets: Vec<usize>,
    /// Offset of each family's first gradient entry in a gradient buffer
    /// (members × ARITY × D per family; one more entry).
    pub(crate) grad_offsets: Vec<usize>,
}

impl Numbering {
    pub(crate) fn new(system: &ParticleSystem) -> Self {
        let (mut offsets, mut grad_offsets) = (vec![0], vec![0]);
        for f in system.constraint_families() {
            let t = f.table();
            offsets.push(offsets.last().unwrap() + t.len());
            grad_offsets.push(grad_offsets.last().unwrap() + t.len() * t.arity() * system.dim());
        }
        Numbering {
            offsets,
            grad_offsets,
        }
    }
    /// (family, member) of constraint c.
    pub(crate) fn locate(&self, c: usize) -> (usize, usize) {
        let f = self.offsets.partition_point(|&o| o <= c) - 1;
        (f, c - self.offsets[f])
    }

    /// The error of `stage` at member `member` of family `f`, step k at
    /// `time`: the member named by its family's declared name.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn member_error(
        system: &ParticleSystem,
        f: usize,
        member: usize,
        stage: Stage,
        k: u64,
        time: f64,
        source: SolveError,
    ) -> StepError {
        StepError::AtMember {
            stage,
            step: k,
            t: time,
            family: system.constraint_families()[f].name().to_string(),
            member,
            source,
        }
    }

    /// [`member_error`](Self::member_error) at constraint c (global number).
    pub(crate) fn error_at(
        &self,
        system: &ParticleSystem,
        c: usize,
        stage: Stage,
        k: u64,
        time: f64,
        source: SolveError,
    ) -> StepError {
        let (f, member) = self.locate(c);
        Self::member_error(system, f, member, stage, k, time, source)
    }
}

/// The connected components of the constraint graph.
pub(crate) struct Components {
    /// Component of each constraint (numbered in order of first constraint).
    pub(crate) of: Vec<u32>,
    /// Constraints per component.
    pub(crate) size: Vec<u32>,
    /// Particles per component.
    pub(crate) particles: Vec<u32>,
    /// For every particle, the constraints touching it (CSR).
    pub(crate) touch_start: Vec<usize>,
    pub(crate) touch: Vec<u32>,
}

fn find(parent: &mut [u32], mut a: u32) -> u32 {
    while parent[a as usize] != a {
        let g = parent[parent[a as usize] as usize];
        parent[a as usize] = g;
        a = g;
    }
    a
}

/// Builds the components and refuses a component with more constraints
/// than the coordinates it moves (G cannot have full rank there).
pub(crate) fn components(
    system: &ParticleSystem,
    num: &Numbering,
) -> Result<Components, TopologyError> {
    let n = system.particles();
    let m = system.constraints();
    let mut count = vec![0usize; n + 1];
    for f in system.constraint_families() {
        for &i in f.table().all_particles() {
            count[i as usize + 1] += 1;
        }
    }
    for i in 0..n {
        count[i + 1] += count[i];
    }
    let touch_start = count.clone();
    let mut touch = vec![0u32; touch_start[n]];
    let mut fill = count;
    for (fi, f) in system.constraint_families().iter().enumerate() {
        let t = f.table();
        for k in 0..t.len() {
            for &i in t.particles(k) {
                touch[fill[i as usize]] = (num.offsets[fi] + k) as u32;
                fill[i as usize] += 1;
            }
        }
    }
    let mut parent: Vec<u32> = (0..m as u32).collect();
    for i in 0..n {
        let cs = &touch[touch_start[i]..touch_start[i + 1]];
        if let Some((&first, rest)) = cs.split_first() {
            for &c in rest {
                let (a, b) = (find(&mut parent, first), find(&mut parent, c));
                if a != b {
                    parent[a.max(b) as usize] = a.min(b);
                }
            }
        }
    }
    let mut id = vec![u32::MAX; m];
    let mut of = vec![0u32; m];
    let mut size = Vec::new();
    for c in 0..m {
        let r = find(&mut parent, c as u32) as usize;
        if id[r] == u32::MAX {
            id[r] = size.len() as u32;
            size.push(0u32);
        }
        of[c] = id[r];
        size[id[r] as usize] += 1;
    }
    let mut particles = vec![0u32; size.len()];
    for i in 0..n {
        if touch_start[i + 1] > touch_start[i] {
            particles[of[touch[touch_start[i]] as usize] as usize] += 1;
        }
    }
    let d = system.dim();
    // The first constraint of each component names it in the error.
    let mut first = vec![usize::MAX; size.len()];
    for c in (0..m).rev() {
        first[of[c] as usize] = c;
    }
    for (k, (&s, &p)) in size.iter().zip(&particles).enumerate() {
        if s as usize > p as usize * d {
            let (f, member) = num.locate(first[k]);
            return Err(TopologyError::TooManyConstraints {
                family: system.constraint_families()[f].name().to_string(),
                member,
                constraints: s as usize,
                coordinates: p as usize * d,
            });
        }
    }
    Ok(Components {
        of,
        size,
        particles,
        touch_start,
        touch,
    })
}

impl Components {
    /// True when every component is small and lies within one family: the
    /// independent-cluster solver applies.
    pub(crate) fn all_small(&self, system: &ParticleSystem, num: &Numbering) -> bool {
        let d = system.dim();
        if self
            .size
            .iter()
            .zip(&self.particles)
            .any(|(&s, &p)| s as usize > MAX_CLUSTER || p as usize * d > MAX_CLUSTER_COORDS)
        {
            return false;
        }
        // One family per component.
        let mut fam = vec![u32::MAX; self.size.len()];
        for (c, &k) in self.of.iter().enumerate() {
            let f = num.locate(c).0 as u32;
            let slot = &mut fam[k as usize];
            if *slot == u32::MAX {
                *slot = f;
            } else if *slot != f {
                return false;
            }
        }
        true
    }

    /// The cluster plans, one per family.
    pub(crate) fn cluster_plans(
        &self,
        system: &ParticleSystem,
        num: &Numbering,
    ) -> Vec<FamilyClusters> {
        let mut plans = Vec::new();
        for (fi, f) in system.constraint_families().iter().enumerate() {
            let t = f.table();
            let ar = t.arity();
            let off = num.offsets[fi];
            // Members sorted by component (stable: members keep their order).
            let mut order: Vec<u32> = (0..t.len() as u32).collect();
            order.sort_by_key(|&k| self.of[off + k as usize]);
            let mut plan = FamilyClusters {
                member_start: vec![0],
                particle_start: vec![0],
                ..Default::default()
            };
            let mut start = 0;
            while start < order.len() {
                let comp = self.of[off + order[start] as usize];
                let mut end = start;
                while end < order.len() && self.of[off + order[end] as usize] == comp {
                    end += 1;
                }
                let pbase = plan.particles.len();
                for &k in &order[start..end] {
                    plan.members.push(k);
                    for &i in t.particles(k as usize) {
                        let local = match plan.particles[pbase..].iter().position(|&j| j == i) {
                            Some(s) => s,
                            None => {
                                plan.particles.push(i);
                                plan.particles.len() - 1 - pbase
                            }
                        };
                        plan.slots.push(local as u8);
                    }
                }
                debug_assert_eq!(plan.slots.len(), plan.members.len() * ar);
                plan.member_start.push(plan.members.len() as u32);
                plan.particle_start.push(plan.particles.len() as u32);
                start = end;
            }
            plans.push(plan);
        }
        plans
    }

    /// The lower-triangle pattern of N = G M⁻¹ Gᵀ ((i, j), i ≥ j; constraints
    /// sharing a particle), deduplicated, and its half-bandwidth in the
    /// natural order.
    pub(crate) fn pattern(&self, m: usize) -> (Vec<(usize, usize)>, usize) {
        let mut e: Vec<(usize, usize)> = (0..m).map(|c| (c, c)).collect();
        for i in 0..self.touch_start.len() - 1 {
            let cs = &self.touch[self.touch_start[i]..self.touch_start[i + 1]];
            for (a, &x) in cs.iter().enumerate() {
                for &y in &cs[..a] {
                    let (x, y) = (x as usize, y as usize);
                    e.push((x.max(y), x.min(y)));
                }
            }
        }
        e.sort_unstable();
        e.dedup();
        let b = e.iter().map(|&(i, j)| i - j).max().unwrap_or(0);
        (e, b)
    }
}
