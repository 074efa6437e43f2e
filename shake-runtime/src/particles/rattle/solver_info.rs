//! What a [`Rattle`] runs and what it holds: its solver's name, its
//! clusters and their blocks, its workspaces, and the switches between the
//! cluster kernels (closed form, fixed-size and general Newton), which give
//! the same steps to round-off and exist to compare them.

use super::{Path, Rattle};

impl Rattle {
    /// Makes the cluster path use its general kernel (any cluster shape,
    /// run-time sizes) even where a fixed-size kernel applies (every
    /// cluster of a family with the same small shape, e.g. rigid water).
    /// Both give the same steps to round-off; this exists to compare them
    /// (tests, benchmarks). No effect on the coupled paths.
    ///
    /// ```
    /// use geoshake_runtime::particles::{generate, Options, Rattle};
    /// let (system, _) = generate::water(2, 1).unwrap();
    /// let mut rattle = Rattle::new(system, 1e-3, Options::default()).unwrap();
    /// rattle.use_general_cluster_kernel();
    /// ```
    pub fn use_general_cluster_kernel(&mut self) {
        if let Path::Clusters { plans, .. } = &mut self.path {
            plans
                .iter_mut()
                .for_each(|p| (p.fixed, p.settle) = (None, false));
        }
    }

    /// Makes the cluster path solve rigid triangles of distance
    /// constraints (rigid water) by Newton, with the fixed-size kernel,
    /// instead of in closed form (SETTLE). Both solve the same SHAKE and
    /// RATTLE equations and give the same steps to round-off; this exists
    /// to compare them (tests, benchmarks). No effect elsewhere.
    ///
    /// ```
    /// use geoshake_runtime::particles::{generate, Options, Rattle};
    /// let (system, _) = generate::water(2, 1).unwrap();
    /// let mut rattle = Rattle::new(system, 1e-3, Options::default()).unwrap();
    /// assert!(rattle.closed_form_clusters());
    /// rattle.use_newton_cluster_kernel();
    /// assert!(!rattle.closed_form_clusters());
    /// ```
    pub fn use_newton_cluster_kernel(&mut self) {
        if let Path::Clusters { plans, .. } = &mut self.path {
            plans.iter_mut().for_each(|p| p.settle = false);
        }
    }

    /// True when some family's clusters are solved in closed form (rigid
    /// triangles of distance constraints in R³, [`Stencil::DISTANCE`]).
    ///
    /// [`Stencil::DISTANCE`]: crate::particles::Stencil::DISTANCE
    pub fn closed_form_clusters(&self) -> bool {
        match &self.path {
            Path::Clusters { plans, .. } => plans.iter().any(|p| p.settle),
            Path::Global(_) => false,
        }
    }

    /// Independent clusters on the cluster path (1 on the coupled path).
    pub fn clusters(&self) -> usize {
        match &self.path {
            Path::Clusters { plans, .. } => plans.iter().map(|p| p.len()).sum(),
            Path::Global(_) => 1,
        }
    }

    /// Blocks of clusters the cluster path hands to threads, summed over the
    /// constraint families (0 on the coupled path, and for a family too
    /// small to split or numbered so that no run of its clusters owns a
    /// range of particles of its own). A step runs on the threads of the
    /// rayon pool it is called in (the global pool: all cores, or
    /// `RAYON_NUM_THREADS`) and gives the same numbers, bit for bit, on
    /// any number of them.
    ///
    /// ```
    /// use geoshake_runtime::particles::{generate, Options, Rattle};
    /// let (system, _) = generate::water(2000, 1).unwrap();
    /// let rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    /// assert!(rattle.cluster_blocks() > 1);
    /// ```
    pub fn cluster_blocks(&self) -> usize {
        match &self.path {
            Path::Clusters { plans, .. } => plans.iter().map(|p| p.blocks.len()).sum(),
            Path::Global(_) => 0,
        }
    }

    /// "clusters", "band" or "sparse": the solver chosen.
    pub fn solver_name(&self) -> &'static str {
        match &self.path {
            Path::Clusters { .. } => "clusters",
            Path::Global(g) => g.solver.name(),
        }
    }

    /// Bytes held by the solver and its workspaces (not the system's tables
    /// or the state).
    pub fn workspace_bytes(&self) -> usize {
        let mut b = (self.qn.capacity() + self.pn.capacity() + self.force.capacity()) * 8;
        match &self.path {
            Path::Clusters { plans, nu, .. } => {
                b += plans.iter().map(|p| p.bytes()).sum::<usize>() + nu.capacity() * 8;
            }
            Path::Global(g) => b += g.bytes(),
        }
        b
    }
}
