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
}

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
    /// Bytes held.
    pub(crate) fn bytes(&self) -> usize {
        (self.members.capacity()
            + self.member_start.capacity()
            + self.particles.capacity()
            + self.particle_start.capacity())
            * 4
            + self.slots.capacity()
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
