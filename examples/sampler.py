"""Constrained HMC from Python: geoshake.sample against mici, per core.

    bash shake-py/test.sh                      # builds the package into a venv
    target/shake-py-venv/bin/pip install mici
    target/shake-py-venv/bin/python examples/sampler.py [--quick]

Prints one line per target (uniform and von Mises–Fisher on S², a torus in
R⁴, matrix Fisher on SO(3) in R⁹), as `cargo run --release --example sampler`
does, plus mici's effective samples per second and the ratio:

    sampler target=… dim=… constraints=… chains=… draws=… acceptance=…
      rejected_reverse=… rejected_newton=… ess_per_s=… rhat=… check=pass|fail
      mici_ess_per_s=… speedup=… ess_per_s_tol9=… speedup_tol9=…

Both samplers run the same algorithms on the same target, each with its
defaults otherwise: static HMC with L RATTLE steps over Störmer–Verlet, a
reversibility check and the Metropolis test (`integration=static`; mici's
`StaticMetropolisHMC`), then multinomial HMC with the no-U-turn criterion,
trees of depth ≤ 10 (`integration=dynamic`; mici's `DynamicMultinomialHMC`),
with dual-averaging step-size adaptation towards acceptance 0.8 in
warm-up, the same chains, warm-up and draws. Ours also jitters h by ±20 %
and holds trajectories cut by failed solves to 1 % in warm-up (its
defaults: without them a fixed L·h can bias the chain, docs/sampler.md);
mici does neither. mici (`ConstrainedLeapfrogIntegrator`,
`dens_wrt_hausdorff=True`) gets
hand-written gradients and Jacobians; its projections stop at
|c(q)| < 1e-9 and |Δq| < 1e-8, ours at round-off (`speedup`) and, run a
second time, with Newton's updates stopped at 1e-9 of the multipliers
(`newton_tolerance=1e-9`: `ess_per_s_tol9`, `speedup_tol9`), no looser
than mici's. Both run on one core
(RAYON_NUM_THREADS=1, mici's n_process=1, NumPy's BLAS on one thread).
ESS is the minimum over coordinates of the bulk ESS of both samplers' draws, by one estimator (`geoshake.ess_bulk`); time is the wall
time of the whole sampling call, warm-up included. `check` compares the
draws with the target's known answer within 4.5 Monte Carlo standard
errors and (not with --quick) asks R̂ < 1.05 and an ESS of at least 400,
the gates of `tests/suite/sampler.rs`.
"""

import os
import sys
import time

# One core each: our chains on one thread, and NumPy's BLAS (mici's linear
# algebra) on one thread, whose idle workers otherwise spin on the other core.
for var in ("RAYON_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import numpy as np  # noqa: E402

import geoshake  # noqa: E402

try:
    import mici
except ImportError:  # pragma: no cover
    raise SystemExit("pip install mici first")

QUICK = "--quick" in sys.argv
CHAINS, DRAWS, WARMUP, STEPS = (2, 200, 100, 10) if QUICK else (4, 1000, 500, 10)
TREE_DEPTH = 10


class Target:
    """A density on M with a known answer: `stat(q)` over draws
    (…, d) must average to `exact`."""

    def __init__(self, name, source, params, q0, neg_log_dens, grad, constr, jacob, stat, exact):
        self.name, self.q0 = name, np.asarray(q0, float)
        self.system = geoshake.declare(source, **params)
        self.mici = (neg_log_dens, grad, constr, jacob)
        self.stat, self.exact = stat, exact


def sphere(kappa):
    """von Mises–Fisher on S² (uniform for κ = 0): E[x₃] = coth κ − 1/κ;
    for κ = 0 the check is E[x₁²] = 1/3."""
    source = """struct Sphere {
        parameters { kappa }
        dof q[3], p[3];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2) / 2 - kappa * q[2];
        constraints { sphere: q[0]^2 + q[1]^2 + q[2]^2 - 1 }
    }"""
    if kappa == 0.0:
        stat, exact = (lambda q: q[..., 0] ** 2), 1 / 3
    else:
        stat, exact = (lambda q: q[..., 2]), 1 / np.tanh(kappa) - 1 / kappa
    return Target(
        "sphere_uniform" if kappa == 0.0 else f"von_mises_fisher_k{kappa:g}",
        source,
        {"kappa": kappa},
        [1.0, 0.0, 0.0],
        lambda q: -kappa * q[2],
        lambda q: np.array([0.0, 0.0, -kappa]),
        lambda q: np.array([q @ q - 1.0]),
        lambda q: 2.0 * q[None, :],
        stat,
        exact,
    )


def torus(kappa):
    """Two unit circles in R⁴ coupled by U = −κ cos(θ₁ − θ₂): θ₁ − θ₂ has
    the von Mises density, E[cos(θ₁ − θ₂)] = I₁(κ)/I₀(κ) (by quadrature)."""
    source = """struct Torus {
        parameters { kappa }
        dof q[4], p[4];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2 + p[3]^2) / 2
            - kappa * (q[0] * q[2] + q[1] * q[3]);
        constraints {
            first: q[0]^2 + q[1]^2 - 1,
            second: q[2]^2 + q[3]^2 - 1,
        }
    }"""
    delta = np.linspace(0.0, 2 * np.pi, 4097)[:-1]
    w = np.exp(kappa * np.cos(delta))
    exact = (np.cos(delta) * w).sum() / w.sum()  # spectrally exact

    def jacob(q):
        j = np.zeros((2, 4))
        j[0, :2], j[1, 2:] = 2 * q[:2], 2 * q[2:]
        return j

    return Target(
        f"torus_k{kappa:g}",
        source,
        {"kappa": kappa},
        [1.0, 0.0, 1.0, 0.0],
        lambda q: -kappa * (q[0] * q[2] + q[1] * q[3]),
        lambda q: -kappa * np.array([q[2], q[3], q[0], q[1]]),
        lambda q: np.array([q[:2] @ q[:2] - 1.0, q[2:] @ q[2:] - 1.0]),
        jacob,
        lambda q: q[..., 0] * q[..., 2] + q[..., 1] * q[..., 3],
        exact,
    )


def rotation(kappa):
    """Matrix Fisher on SO(3), π(R) ∝ e^{κ tr R} against Haar measure
    (the Hausdorff measure of SO(3) in R⁹, R row-major, RᵀR = I by its six
    entries): tr R = 1 + 2 cos θ with θ ∝ (1 − cos θ) e^{κ(1 + 2 cos θ)} on
    [0, π], E[tr R] by quadrature."""
    source = """struct Rotation {
        parameters { kappa }
        dof q[9], p[9];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2 + p[3]^2 + p[4]^2 + p[5]^2
            + p[6]^2 + p[7]^2 + p[8]^2) / 2 - kappa * (q[0] + q[4] + q[8]);
        constraints {
            c00: q[0]^2 + q[3]^2 + q[6]^2 - 1,
            c11: q[1]^2 + q[4]^2 + q[7]^2 - 1,
            c22: q[2]^2 + q[5]^2 + q[8]^2 - 1,
            c01: q[0] * q[1] + q[3] * q[4] + q[6] * q[7],
            c02: q[0] * q[2] + q[3] * q[5] + q[6] * q[8],
            c12: q[1] * q[2] + q[4] * q[5] + q[7] * q[8],
        }
    }"""
    theta = np.linspace(0.0, np.pi, 8193)
    w = (1 - np.cos(theta)) * np.exp(kappa * (1 + 2 * np.cos(theta)))
    exact = np.trapezoid(w * (1 + 2 * np.cos(theta)), theta) / np.trapezoid(w, theta)
    pairs = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]

    def constr(q):
        c = q.reshape(3, 3).T @ q.reshape(3, 3)
        return np.array([c[i, j] - (i == j) for i, j in pairs])

    def jacob(q):
        # ∂(RᵀR)_ij/∂R_ab = δ_jb R_ai + δ_ib R_aj.
        r, j = q.reshape(3, 3), np.zeros((6, 9))
        for row, (a, b) in enumerate(pairs):
            d = np.zeros((3, 3))
            d[:, b] += r[:, a]
            d[:, a] += r[:, b]
            j[row] = d.ravel()
        return j

    return Target(
        f"so3_matrix_fisher_k{kappa:g}",
        source,
        {"kappa": kappa},
        np.eye(3).ravel(),
        lambda q: -kappa * (q[0] + q[4] + q[8]),
        lambda q: -kappa * np.eye(3).ravel(),
        constr,
        jacob,
        lambda q: q[..., 0] + q[..., 4] + q[..., 8],
        exact,
    )


def min_ess(q):
    return min(geoshake.ess_bulk(q[:, :, k]) for k in range(q.shape[2]))


def mcse(x):
    return x.std() / np.sqrt(geoshake.ess_bulk(x))


def run_ours(t, dynamic, tol=None):
    start = time.perf_counter()
    s = geoshake.sample(
        t.system, t.q0, chains=CHAINS, draws=DRAWS, warmup=WARMUP, steps=STEPS, seed=1,
        max_tree_depth=TREE_DEPTH if dynamic else None, newton_tolerance=tol,
    )
    return s, time.perf_counter() - start


def run_mici(t, dynamic):
    neg_log_dens, grad, constr, jacob = t.mici
    system = mici.systems.DenseConstrainedEuclideanMetricSystem(
        neg_log_dens, constr, grad_neg_log_dens=grad, jacob_constr=jacob, dens_wrt_hausdorff=True
    )
    integrator = mici.integrators.ConstrainedLeapfrogIntegrator(system, step_size=0.1)
    if dynamic:
        sampler = mici.samplers.DynamicMultinomialHMC(
            system, integrator, np.random.default_rng(1), max_tree_depth=TREE_DEPTH
        )
    else:
        sampler = mici.samplers.StaticMetropolisHMC(
            system, integrator, np.random.default_rng(1), n_step=STEPS
        )
    start = time.perf_counter()
    _, traces, _ = sampler.sample_chains(
        WARMUP,
        DRAWS,
        [t.q0.copy() for _ in range(CHAINS)],
        adapters=[mici.adapters.DualAveragingStepSizeAdapter(0.8)],
        n_process=1,
        display_progress=False,
    )
    return np.asarray(traces["pos"]), time.perf_counter() - start


def main():
    failed = False
    for t, dynamic in [(t, d) for d in (False, True) for t in [sphere(0.0), sphere(2.0), torus(1.5), rotation(1.0)]]:
        s, ours_time = run_ours(t, dynamic)
        q = s["positions"]
        x = t.stat(q)
        # The gates of tests/suite/sampler.rs; R̂ and the ESS ask for more
        # draws than --quick takes.
        converged = s["rhat"].max() < 1.05 and min_ess(q) >= 400
        ok = abs(x.mean() - t.exact) <= 4.5 * mcse(x) and (QUICK or converged)
        failed |= not ok
        ess_per_s = min_ess(q) / ours_time
        # Ours again with its solves stopped at 1e-9 (`newton_tolerance`),
        # no looser than mici's projections.
        s9, time9 = run_ours(t, dynamic, tol=1e-9)
        x9 = t.stat(s9["positions"])
        ok &= abs(x9.mean() - t.exact) <= 4.5 * mcse(x9)
        failed |= not ok
        ess9_per_s = min_ess(s9["positions"]) / time9
        mq, mici_time = run_mici(t, dynamic)
        mici_ess_per_s = min_ess(mq) / mici_time
        rejected = s["rejection"]
        print(
            f"sampler target={t.name} integration={'dynamic' if dynamic else 'static'} "
            f"dim={q.shape[2]} constraints={t.system.constraint_count} "
            f"chains={CHAINS} draws={DRAWS} acceptance={s['accepted'].mean():.3f} "
            f"rejected_reverse={(rejected == 'reverse').sum()} "
            f"rejected_newton={(rejected == 'newton').sum()} "
            f"ess_per_s={ess_per_s:.4g} rhat={s['rhat'].max():.4f} "
            f"check={'pass' if ok else 'fail'} "
            f"mici_ess_per_s={mici_ess_per_s:.4g} speedup={ess_per_s / mici_ess_per_s:.0f} "
            f"ess_per_s_tol9={ess9_per_s:.4g} speedup_tol9={ess9_per_s / mici_ess_per_s:.0f}"
        )
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
