//! Initial data onto M and M^H: the projections a user applies to a
//! state before a run ([`Integrator::project`], Π onto M^H along the
//! fibre; [`Integrator::project_to_hidden`], first onto M then Π), and the
//! error for a state off M. The momentum-only projection is in
//! `keep_positions`.

use crate::base_map::BaseMap;
use crate::error::{Stage, StepError};
use crate::guard::Guard;
use crate::integrator::Integrator;
use crate::rattle::{check_nondegeneracy, g_at_roundoff, project_constraint, project_hidden};
use crate::state::State;
use crate::system::ConstrainedSystem;
use crate::validate;

impl<S: ConstrainedSystem, B: BaseMap> Integrator<S, B> {
    /// Π: moves z ∈ M along its fibre onto M^H (RATTLE's projection).
    ///
    /// z must lie on M to [`Options::constraint_tolerance`](crate::Options::constraint_tolerance)
    /// (else [`StepError::NotOnConstraint`]). A z that is within it but
    /// not on M to round-off is first brought onto M, as
    /// [`project_to_hidden`](Self::project_to_hidden) does: the result
    /// lies on M and on M^H to round-off, or the call fails with a typed
    /// error. A z on M to round-off moves by Π alone.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let z = integ.project(&State::from_slices(&[0.0, -1.0], &[0.3, 0.4])).unwrap();
    /// assert!((z.p[1]).abs() < 1e-15 && (z.p[0] - 0.3).abs() < 1e-15);
    /// ```
    pub fn project(&mut self, z: &State) -> Result<State, StepError> {
        self.check_dims(z)?;
        Guard::finite(z.q.as_slice(), z.p.as_slice(), "state", 0, 0.0)?;
        validate::options(&self.guard.options)?;
        let tol = self.guard.options.constraint_tolerance;
        crate::guard::membership::on_constraint(
            &self.system,
            z.q.as_slice(),
            z.p.as_slice(),
            &mut self.steps.map.ws,
            tol,
        )?;
        let mut out = z.clone();
        let (q, p) = (out.q.as_mut_slice(), out.p.as_mut_slice());
        self.onto_hidden(q, p, true)?;
        crate::guard::membership::on_constraint(&self.system, q, p, &mut self.steps.map.ws, tol)?;
        Ok(out)
    }

    /// Initial data: brings a nearby point onto M (Gauss–Newton, orthogonal
    /// to M) and then onto M^H along the fibre (Π). Fails with a typed error
    /// when either Newton iteration fails, when the result is not on M to
    /// [`Options::constraint_tolerance`](crate::Options::constraint_tolerance), or when N is singular there.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, ConstrainedSystem, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let z = integ.project_to_hidden(&State::from_slices(&[0.7, -0.75], &[1.0, 0.2])).unwrap();
    /// let (mut g, mut gh) = ([0.0], [0.0]);
    /// integ.system().constraints(z.q.as_slice(), z.p.as_slice(), &mut g);
    /// integ.system().hidden_constraints(z.q.as_slice(), z.p.as_slice(), &mut gh);
    /// assert!(g[0].abs() < 1e-15 && gh[0].abs() < 1e-15);
    /// ```
    pub fn project_to_hidden(&mut self, z: &State) -> Result<State, StepError> {
        self.check_dims(z)?;
        Guard::finite(z.q.as_slice(), z.p.as_slice(), "initial state", 0, 0.0)?;
        validate::options(&self.guard.options)?;
        let mut out = z.clone();
        let (q, p) = (out.q.as_mut_slice(), out.p.as_mut_slice());
        self.onto_hidden(q, p, false)?;
        if self.system.constraint_count() > 0 {
            let tol = self.guard.options.constraint_tolerance;
            crate::guard::membership::on_constraint(
                &self.system,
                q,
                p,
                &mut self.steps.map.ws,
                tol,
            )?;
            let ws = &mut self.steps.map.ws;
            let nd = check_nondegeneracy(&self.system, q, p, ws);
            self.guard.nondegenerate_at_start(
                &self.system,
                q,
                p,
                ws,
                &nd,
                Stage::Rattle,
                0,
                0.0,
            )?;
        }
        Ok(out)
    }

    /// Onto M, then Π along the fibre, in place. Π keeps g = 0 only to the
    /// round-off of the fibre flow (it moves q too when g depends on p), so
    /// a state left above g's round-off goes round once more: each round
    /// starts closer, and three are more than round-off needs. `on_m`: the
    /// caller has checked that (q, p) is on M to the tolerance, and a state
    /// on M to round-off skips the first projection onto M.
    fn onto_hidden(&mut self, q: &mut [f64], p: &mut [f64], on_m: bool) -> Result<(), StepError> {
        let opts = *self.guard.newton();
        for round in 0..3 {
            let ws = &mut self.steps.map.ws;
            let skip_m = on_m && round == 0 && g_at_roundoff(&self.system, q, p, ws);
            if !skip_m && let Err(e) = project_constraint(&self.system, q, p, ws, &opts) {
                // Gauss–Newton could not bring the point onto M: say how
                // far it got, for which constraint, and why it stopped.
                let cause = match e {
                    StepError::NewtonNotConverged { source, .. } => Some(source),
                    _ => None,
                };
                return Err(self.off_m(q, p, cause));
            }
            project_hidden(&self.system, q, p, &mut self.steps.map.ws, &opts)?;
            validate::finite("projected state", q, p)?;
            if g_at_roundoff(&self.system, q, p, &mut self.steps.map.ws) {
                break;
            }
        }
        Ok(())
    }

    /// [`StepError::NotOnConstraint`] for initial data (q, p) known to be
    /// off M, naming the constraint furthest off against its tolerance.
    pub(crate) fn off_m(
        &mut self,
        q: &[f64],
        p: &[f64],
        cause: Option<crate::SolveError>,
    ) -> StepError {
        let tol = self.guard.options.constraint_tolerance;
        let (residual, i, tolerance) = if self.system.constraint_count() > 0 {
            crate::guard::membership::furthest_off(&self.system, q, p, &mut self.steps.map.ws, tol)
        } else {
            (0.0, 0, tol)
        };
        StepError::NotOnConstraint {
            step: 0,
            t: 0.0,
            residual,
            tolerance,
            constraint: if self.system.constraint_count() > 0 {
                self.system.constraint_name(i).to_string()
            } else {
                String::new()
            },
            cause,
        }
    }
}
