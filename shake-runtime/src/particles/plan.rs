//! The plan of the cluster kernels and what they exchange with the solver:
//! each family's clusters ([`FamilyClusters`], built by the symbolic phase
//! in `graph`), the inputs shared by every cluster ([`ClusterArgs`]), what a
//! stage measured ([`ClusterReport`]) and why a cluster failed
//! ([`ClusterFailure`]). Data only: the model trait
//! ([`ClusterKernel`](super::ClusterKernel)) names these, the kernels
//! (`cluster`) fill them.

/// Largest number of constraints a cluster may have to be solved on its
/// own: the order of the small dense solvers' matrices.
pub(crate) const MAX_CLUSTER: usize = super::cluster::dense::CAPACITY;
/// Largest number of local coordinates (particles × D) of such a cluster.
pub(crate) const MAX_CLUSTER_COORDS: usize = 96;

/// The clusters of one family: each a connected set of the family's
/// members, with the particles they touch. Built once, by the symbolic
/// phase of [`Rattle::new`](super::Rattle::new).
#[derive(Clone, Debug, Default)]
pub struct FamilyClusters {
    /// Member rows, cluster after cluster.
    pub(crate) members: Vec<u32>,
    /// Start of cluster c in `members` (one more entry than clusters).
    pub(crate) member_start: Vec<u32>,
    /// Particles, cluster after cluster.
    pub(crate) particles: Vec<u32>,
    /// Start of cluster c in `particles`.
    pub(crate) particle_start: Vec<u32>,
    /// For every entry of `members`, the local slot (index into the
    /// cluster's particles) of each of the member's ARITY particles.
    pub(crate) slots: Vec<u8>,
    /// `Some((constraints, particles))` when every cluster has that shape
    /// and it has a fixed-size kernel (`cluster::shake_fixed`); set by
    /// [`FamilyClusters::detect_shape`].
    pub(crate) fixed: Option<(u8, u8)>,
    /// Every cluster is a rigid triangle of distance constraints in R³
    /// (shape (3, 3), the three pairs of its three particles, a stencil
    /// that declares [`Stencil::DISTANCE`](super::Stencil::DISTANCE)):
    /// solved in closed form (`cluster::settle`). Set by
    /// [`ClusterKernel::choose_kernel`](super::ClusterKernel::choose_kernel)
    /// after [`FamilyClusters::detect_shape`].
    pub(crate) settle: bool,
    /// Runs of consecutive clusters whose particles and members lie in
    /// disjoint, increasing index ranges, so that the runs can be solved on
    /// separate threads, each writing its own slices of q, p and ν; set by
    /// [`FamilyClusters::detect_blocks`]. Empty: one run of every cluster.
    pub(crate) blocks: Vec<Block>,
}

/// Clusters `clusters.0..clusters.1` of a family, whose particles lie in
/// `particles.0..particles.1` and members (rows of the family's table) in
/// `members.0..members.1`; the ranges of successive blocks tile `0..n`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Block {
    pub(crate) clusters: (usize, usize),
    pub(crate) particles: (usize, usize),
    pub(crate) members: (usize, usize),
}

/// Clusters per block, about: enough work per block (rigid water: a
/// block is ~0.1 ms) that handing it to a thread costs little, enough
/// blocks in a box of 10⁴ molecules to share among cores.
pub(crate) const BLOCK_CLUSTERS: usize = 256;

impl FamilyClusters {
    /// The number of clusters.
    pub(crate) fn len(&self) -> usize {
        self.member_start.len().saturating_sub(1)
    }
    /// Sets [`FamilyClusters::fixed`] when every cluster has the same
    /// number of constraints and of particles, of a shape the fixed-size
    /// kernel is instantiated for (rigid water: 3 constraints on 3
    /// particles). The stencil's ARITY and DIM are checked at dispatch.
    pub(crate) fn detect_shape(&mut self) {
        self.fixed = None;
        self.settle = false;
        let n = self.len();
        if n == 0 {
            return;
        }
        let mc = self.member_start[1] - self.member_start[0];
        let np = self.particle_start[1] - self.particle_start[0];
        if !matches!((mc, np), (1, 2) | (2, 3) | (3, 3)) {
            return;
        }
        let uniform = (0..n).all(|c| {
            self.member_start[c + 1] - self.member_start[c] == mc
                && self.particle_start[c + 1] - self.particle_start[c] == np
        });
        if uniform {
            self.fixed = Some((mc as u8, np as u8));
        }
    }
    /// Sets [`FamilyClusters::blocks`]: cuts after a cluster where every
    /// particle and member of the clusters so far has a lower index than
    /// every one of the clusters after it, once a block holds at least
    /// `target` clusters. The clusters are the connected components of
    /// the family, so no particle or member is in two of them; a box
    /// whose molecules are numbered one after the other (as data files
    /// number them) is cut everywhere, an interleaved numbering perhaps
    /// nowhere (one block: solved on one thread). Which blocks there are
    /// changes no result: each cluster is solved on its own.
    pub(crate) fn detect_blocks(&mut self, particles: usize, members: usize, target: usize) {
        self.blocks.clear();
        let n = self.len();
        if n == 0 {
            return;
        }
        let target = target.max(1);
        let lowest = |c: usize| {
            let ps = &self.particles
                [self.particle_start[c] as usize..self.particle_start[c + 1] as usize];
            let ms =
                &self.members[self.member_start[c] as usize..self.member_start[c + 1] as usize];
            (
                ps.iter().copied().min().unwrap_or(u32::MAX) as usize,
                ms.iter().copied().min().unwrap_or(u32::MAX) as usize,
            )
        };
        // The lowest particle and member index from cluster c on.
        let mut after = vec![(usize::MAX, usize::MAX); n + 1];
        for c in (0..n).rev() {
            let (p, m) = lowest(c);
            after[c] = (after[c + 1].0.min(p), after[c + 1].1.min(m));
        }
        let (mut start, mut top_p, mut top_m) = (0, 0, 0);
        let mut lo = (0, 0);
        for c in 0..n {
            let ps = &self.particles
                [self.particle_start[c] as usize..self.particle_start[c + 1] as usize];
            let ms =
                &self.members[self.member_start[c] as usize..self.member_start[c + 1] as usize];
            top_p = ps.iter().map(|&i| i as usize + 1).fold(top_p, usize::max);
            top_m = ms.iter().map(|&i| i as usize + 1).fold(top_m, usize::max);
            let last = c + 1 == n;
            let cut = c + 1 - start >= target && top_p <= after[c + 1].0 && top_m <= after[c + 1].1;
            if cut || last {
                let hi = if last {
                    (particles, members)
                } else {
                    (top_p, top_m)
                };
                self.blocks.push(Block {
                    clusters: (start, c + 1),
                    particles: (lo.0, hi.0),
                    members: (lo.1, hi.1),
                });
                (start, lo) = (c + 1, hi);
            }
        }
        if self.blocks.len() == 1 {
            self.blocks.clear();
        }
    }
    /// Bytes held.
    pub(crate) fn bytes(&self) -> usize {
        (self.members.capacity()
            + self.member_start.capacity()
            + self.particles.capacity()
            + self.particle_start.capacity())
            * 4
            + self.slots.capacity()
            + self.blocks.capacity() * std::mem::size_of::<Block>()
    }
}

/// The inputs of the position stage shared by every cluster.
#[derive(Clone, Copy, Debug)]
pub struct ClusterArgs<'a> {
    /// q0 (the start of the step).
    pub(crate) q0: &'a [f64],
    /// 1/m_a per particle.
    pub(crate) inv_mass: &'a [f64],
    /// 1/h: p½ = p̃ − G(q0)ᵀ ν / h; 0 leaves p alone (projection onto M).
    pub(crate) inv_h: f64,
    /// Relative tolerance on every constraint.
    pub(crate) tol: f64,
    /// Newton iteration budget per cluster.
    pub(crate) max_iter: usize,
}

/// What the clusters of a family measured in one stage.
#[derive(Clone, Copy, Debug, Default)]
pub struct ClusterReport {
    /// Largest relative residual |g_k| / (|∇g_k| · extent_k) at the end.
    pub(crate) max_rel: f64,
    /// Largest relative hidden-constraint residual after projection.
    pub(crate) max_hidden: f64,
    /// Largest Newton iteration count of one cluster.
    pub(crate) max_iter: usize,
    /// Newton iterations summed over clusters.
    pub(crate) iterations: u64,
}

/// Why a cluster failed (the caller adds step, time and family).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterFailure {
    /// The member at fault (row of the family's table).
    pub(crate) member: usize,
    /// Its relative residual.
    pub(crate) residual: f64,
    /// Iterations done.
    pub(crate) iterations: usize,
    /// What went wrong.
    pub(crate) kind: FailureKind,
}

/// The kind of a cluster failure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum FailureKind {
    NotConverged,
    SingularNewton,
    SingularN,
    NotFinite,
}

/// The chunk of the passes over every particle that run on threads:
/// particles per chunk of the drift and of the coupled path's scatters,
/// entries (particles × D) per chunk of the closing kick and the
/// finiteness checks, members per chunk of the coupled path's member
/// passes, entries of N per chunk of its assembly.
pub(crate) const PARALLEL_PARTICLES: usize = 8192;

/// True when a pass over `n` items (particles or entries, as the pass
/// counts them) is worth handing to threads: more than one chunk of
/// [`PARALLEL_PARTICLES`], and more than one thread.
/// Each entry is computed as on one thread, so the numbers do not depend
/// on the number of threads.
pub(crate) fn parallel(n: usize) -> bool {
    n > PARALLEL_PARTICLES && rayon::current_num_threads() > 1
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Clusters of two members each on the particle lists given, members
    /// numbered in cluster order unless `members` says otherwise.
    fn plan(particles: &[Vec<u32>], members: &[[u32; 2]]) -> FamilyClusters {
        let mut f = FamilyClusters {
            member_start: vec![0],
            particle_start: vec![0],
            ..Default::default()
        };
        for (ps, ms) in particles.iter().zip(members) {
            f.members.extend_from_slice(ms);
            f.particles.extend_from_slice(ps);
            f.member_start.push(f.members.len() as u32);
            f.particle_start.push(f.particles.len() as u32);
        }
        f
    }

    /// The blocks tile the clusters, the particles and the members in
    /// order, and every cluster's particles and members lie in its block's
    /// ranges: the disjoint slices the threads write.
    fn check_tiling(f: &FamilyClusters, particles: usize, members: usize) {
        let mut next = Block::default();
        for b in &f.blocks {
            assert_eq!(b.clusters.0, next.clusters.1);
            assert_eq!(b.particles.0, next.particles.1);
            assert_eq!(b.members.0, next.members.1);
            for c in b.clusters.0..b.clusters.1 {
                let ps =
                    &f.particles[f.particle_start[c] as usize..f.particle_start[c + 1] as usize];
                let ms = &f.members[f.member_start[c] as usize..f.member_start[c + 1] as usize];
                assert!(ps
                    .iter()
                    .all(|&i| (b.particles.0..b.particles.1).contains(&(i as usize))));
                assert!(ms
                    .iter()
                    .all(|&i| (b.members.0..b.members.1).contains(&(i as usize))));
            }
            next = *b;
        }
        assert_eq!(next.clusters.1, f.len());
        assert_eq!((next.particles.1, next.members.1), (particles, members));
    }

    #[test]
    fn molecules_numbered_in_turn_are_cut_into_blocks_that_tile() {
        let n = 10;
        let parts: Vec<Vec<u32>> = (0..n).map(|c| vec![3 * c, 3 * c + 1, 3 * c + 2]).collect();
        let mems: Vec<[u32; 2]> = (0..n).map(|c| [2 * c, 2 * c + 1]).collect();
        let mut f = plan(&parts, &mems);
        f.detect_blocks(3 * n as usize + 5, 2 * n as usize, 3);
        // Cuts after 3, 6 and 9 clusters; the last block takes the rest
        // and the particles no cluster holds.
        assert_eq!(f.blocks.len(), 4);
        assert_eq!(f.blocks[3].clusters, (9, 10));
        check_tiling(&f, 3 * n as usize + 5, 2 * n as usize);
    }

    #[test]
    fn interleaved_numberings_are_cut_only_where_no_cluster_straddles() {
        let n = 8u32;
        // Clusters 0..4 interleave their particles with clusters 4..8:
        // cluster c holds c and c + 8 for c < 4; the rest are in turn.
        let parts: Vec<Vec<u32>> = (0..n)
            .map(|c| {
                if c < 4 {
                    vec![c, c + 8]
                } else {
                    vec![2 * c + 4, 2 * c + 5]
                }
            })
            .collect();
        let mems: Vec<[u32; 2]> = (0..n).map(|c| [2 * c, 2 * c + 1]).collect();
        let mut f = plan(&parts, &mems);
        f.detect_blocks(20, 16, 1);
        assert!(f
            .blocks
            .iter()
            .all(|b| b.clusters.1 <= 4 || b.clusters.0 >= 4));
        assert_eq!(f.blocks[0].clusters, (0, 4));
        check_tiling(&f, 20, 16);
        // Members numbered against the clusters' order: no cut at all.
        let rev: Vec<[u32; 2]> = (0..n)
            .map(|c| [2 * (n - 1 - c), 2 * (n - 1 - c) + 1])
            .collect();
        let parts: Vec<Vec<u32>> = (0..n).map(|c| vec![2 * c, 2 * c + 1]).collect();
        let mut f = plan(&parts, &rev);
        f.detect_blocks(16, 16, 1);
        assert!(f.blocks.is_empty());
    }
}
