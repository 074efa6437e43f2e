"""geoshake.sample: constrained HMC on string-declared targets with known
answers, its determinism and its refusals.

Each known-answer check is |estimate − exact| ≤ 4.5 Monte Carlo standard
errors (the sampler's own MCSE from the bulk ESS): a false failure has
probability ≈ 7e-6 per check for a Gaussian error, and the seeds are fixed,
so a run is deterministic.
"""

import numpy as np
import pytest

import geoshake

SPHERE = """
struct Sphere {
    parameters { kappa }
    dof q[3], p[3];
    hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2) / 2 - kappa * q[2];
    constraints { sphere: q[0]^2 + q[1]^2 + q[2]^2 - 1 }
}"""

GATE = 4.5


def mcse(x):
    """The MCSE of the mean of x (chains, draws) from the sampler's ESS of
    the same statistic, computed by batch means over each chain."""
    chains, draws = x.shape
    batches = 20
    means = x[:, : draws - draws % batches].reshape(chains, batches, -1).mean(axis=2)
    return means.std(ddof=1) / np.sqrt(means.size)


def test_uniform_on_the_sphere_has_its_moments():
    sphere = geoshake.declare(SPHERE, kappa=0.0)
    s = geoshake.sample(sphere, [0.0, 0.0, 1.0], chains=4, draws=2000, warmup=500, seed=11)
    q = s["positions"]
    assert q.shape == (4, 2000, 3)
    # Every draw on the sphere to round-off.
    assert np.abs(np.linalg.norm(q, axis=2) - 1.0).max() <= 1e-13
    for k in range(3):
        x2, x4 = q[:, :, k] ** 2, q[:, :, k] ** 4
        assert abs(x2.mean() - 1 / 3) <= GATE * mcse(x2), (k, x2.mean())
        assert abs(x4.mean() - 1 / 5) <= GATE * mcse(x4), (k, x4.mean())
    assert s["rhat"].max() < 1.01
    assert (s["ess_bulk"] > 1000).all()


def test_von_mises_fisher_has_its_mean_resultant_length():
    # π ∝ e^{κ x₃} on S²: E[x₃] = coth κ − 1/κ.
    kappa = 2.0
    sphere = geoshake.declare(SPHERE, kappa=kappa)
    s = geoshake.sample(sphere, [1.0, 0.0, 0.0], chains=4, draws=2000, warmup=500, seed=5)
    x3 = s["positions"][:, :, 2]
    exact = 1 / np.tanh(kappa) - 1 / kappa
    assert abs(x3.mean() - exact) <= GATE * mcse(x3), (x3.mean(), exact)
    # The sampler's own estimate and MCSE agree with the batch means.
    assert abs(s["mean"][2] - x3.mean()) <= 1e-12
    assert abs(x3.mean() - exact) <= GATE * s["mcse"][2]


def test_dynamic_integration_time_has_the_von_mises_fisher_moments():
    # Multinomial HMC with the no-U-turn criterion, trees of depth <= 8:
    # E[z] = coth k - 1/k within 4.5 MCSE (false failure ~7e-6, fixed seed).
    k = 2.0
    s = geoshake.sample(
        geoshake.declare(SPHERE, kappa=k), [0.0, 0.0, 1.0], chains=4, draws=2000,
        warmup=500, max_tree_depth=8, seed=3,
    )
    z = s["positions"][:, :, 2]
    exact = 1.0 / np.tanh(k) - 1.0 / k
    assert abs(z.mean() - exact) <= GATE * s["mcse"][2], (z.mean(), exact, s["mcse"][2])
    assert s["rhat"].max() < 1.05 and s["ess_bulk"].min() >= 400
    # Trajectories of different lengths: the dynamic time at work.
    assert len(np.unique(s["steps"])) > 3


ELLIPSE = """
struct Ellipse {
    parameters { a, b }
    dof q[2], p[2];
    hamiltonian = (p[0]^2 + p[1]^2) / 2;
    constraints { ellipse: q[0]^2 / a^2 + q[1]^2 / b^2 - 1 }
}"""


def ellipse_x2(a, b, density):
    """E[x²] for U = 0 on the ellipse, by the trapezoidal rule in θ
    (x = a cos θ, y = b sin θ; exact to round-off for a smooth periodic
    integrand). "hausdorff": uniform in arc length, weight ds/dθ.
    "ambient": density 1/|∇g| w.r.t. arc length (co-area), weight
    (ds/dθ)/|∇g|, a constant: uniform in θ."""
    t = np.linspace(0.0, 2 * np.pi, 4096, endpoint=False)
    arc = np.sqrt(a**2 * np.sin(t) ** 2 + b**2 * np.cos(t) ** 2)
    grad = 2 * np.sqrt(np.cos(t) ** 2 / a**2 + np.sin(t) ** 2 / b**2)
    w = arc if density == "hausdorff" else arc / grad
    return (w * a**2 * np.cos(t) ** 2).sum() / w.sum()


@pytest.mark.parametrize("density, other", [("hausdorff", "ambient"), ("ambient", "hausdorff")])
def test_the_ellipse_under_each_density(density, other):
    # E[x²] = 1.680 (arc length) and a²/2 = 2 (conditioned from R²), 0.32
    # apart: each run passes its own answer within 4.5 MCSE and is at least
    # 10 MCSE from the other's, so the test fails if `density` does nothing.
    a, b = 2.0, 1.0
    assert abs(ellipse_x2(a, b, "ambient") - a**2 / 2) < 1e-12
    ellipse = geoshake.declare(ELLIPSE, a=a, b=b)
    starts = [[2.0, 0.0], [0.0, 1.0], [-2.0, 0.0], [0.0, -1.0]]
    s = geoshake.sample(
        ellipse, starts, chains=4, draws=2000, warmup=500, seed=21, density=density
    )
    x2 = s["positions"][:, :, 0] ** 2
    err = mcse(x2)
    assert abs(x2.mean() - ellipse_x2(a, b, density)) <= GATE * err, (x2.mean(), err)
    assert abs(x2.mean() - ellipse_x2(a, b, other)) >= 10 * err, (x2.mean(), err)
    assert s["rhat"].max() < 1.05


def test_the_output_is_what_arviz_reads():
    s = geoshake.sample(
        geoshake.declare(SPHERE, kappa=1.0), [0.0, 0.0, 1.0], chains=2, draws=50, warmup=20
    )
    for key, dtype in [
        ("accepted", np.bool_),
        ("acceptance_probability", np.float64),
        ("energy", np.float64),
        ("steps", np.uint64),
    ]:
        assert s[key].shape == (2, 50) and s[key].dtype == dtype, key
    assert s["rejection"].shape == (2, 50)
    # "" exactly where the proposal was accepted, a kind's name elsewhere.
    assert ((s["rejection"] == "") == s["accepted"]).all()
    names = {"", "metropolis", "reverse", "newton", "non_finite", "degenerate", "jump"}
    assert set(np.unique(s["rejection"])) <= names
    assert s["step_size"].shape == (2,)
    for key in ["mean", "mcse", "rhat", "ess_bulk", "ess_tail"]:
        assert s[key].shape == (3,), key


def test_a_chain_depends_on_the_seed_and_its_index_only():
    sphere = geoshake.declare(SPHERE, kappa=1.0)
    kw = dict(draws=100, warmup=50, seed=3)
    two = geoshake.sample(sphere, [0.0, 0.0, 1.0], chains=2, **kw)
    four = geoshake.sample(sphere, [0.0, 0.0, 1.0], chains=4, **kw)
    again = geoshake.sample(sphere, [0.0, 0.0, 1.0], chains=2, **kw)
    assert np.array_equal(two["positions"], four["positions"][:2])
    assert np.array_equal(two["positions"], again["positions"])
    other = geoshake.sample(sphere, [0.0, 0.0, 1.0], chains=2, draws=100, warmup=50, seed=4)
    assert not np.array_equal(two["positions"], other["positions"])


def test_one_start_per_chain():
    sphere = geoshake.declare(SPHERE, kappa=0.0)
    starts = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    s = geoshake.sample(sphere, starts, chains=2, draws=10, warmup=0, target_acceptance=None)
    assert s["positions"].shape == (2, 10, 3)
    assert np.array_equal(s["step_size"], [0.1, 0.1])


@pytest.mark.parametrize(
    "q0, kw, error, says",
    [
        ([0.0, 0.0, 2.0], {}, geoshake.NotOnConstraintError, "chain 0 is not on M"),
        ([0.0, 0.0, np.nan], {}, geoshake.ShakeError, "chain 0"),
        ([0.0, 1.0], {}, geoshake.InvalidInputError, "shape (3,)"),
        ([[0.0, 0.0, 1.0]] * 3, {"chains": 2}, geoshake.InvalidInputError, "3 starting points"),
        ([0.0, 0.0, 1.0], {"chains": 0}, geoshake.InvalidInputError, "chains"),
        ([0.0, 0.0, 1.0], {"step_size": -1.0}, geoshake.InvalidInputError, "step_size"),
        ([0.0, 0.0, 1.0], {"target_acceptance": 1.5}, geoshake.InvalidInputError, "target"),
        ([0.0, 0.0, 1.0], {"target_failure_rate": 0.0}, geoshake.InvalidInputError, "failure"),
        ([0.0, 0.0, 1.0], {"max_tree_depth": -1}, geoshake.InvalidInputError, "max_tree_depth"),
        ([0.0, 0.0, 1.0], {"max_tree_depth": 21}, geoshake.InvalidInputError, "max_tree_depth"),
        # Integers past a u64 or negative: the package's error naming the
        # option, not Python's OverflowError.
        ([0.0, 0.0, 1.0], {"max_tree_depth": 2**70}, geoshake.InvalidInputError, "max_tree_depth"),
        ([0.0, 0.0, 1.0], {"chains": -1}, geoshake.InvalidInputError, "`chains` = -1"),
        ([0.0, 0.0, 1.0], {"warmup": -1}, geoshake.InvalidInputError, "`warmup` = -1"),
        ([0.0, 0.0, 1.0], {"seed": 2**64}, geoshake.InvalidInputError, "`seed` = 18446744073709551616"),
        ([0.0, 0.0, 1.0], {"steps": -2**70}, geoshake.InvalidInputError, "`steps`"),
        ([0.0, 0.0, 1.0], {"draws": 2**62}, geoshake.InvalidInputError, "do not fit in memory"),
        ([0.0, 0.0, 1.0], {"density": "uniform"}, geoshake.InvalidInputError, "density"),
        # Looser than 1e-9 the step back could miss by the reverse check's
        # own tolerance.
        ([0.0, 0.0, 1.0], {"newton_tolerance": 1e-3}, geoshake.InvalidInputError, "`newton_tolerance`"),
        ([0.0, 0.0, 1.0], {"newton_tolerance": float("nan")}, geoshake.InvalidInputError, "`newton_tolerance`"),
    ],
)
def test_bad_input_is_refused_with_the_package_errors(q0, kw, error, says):
    sphere = geoshake.declare(SPHERE, kappa=0.0)
    with pytest.raises(error, match=None) as e:
        geoshake.sample(sphere, q0, **{"warmup": 10, "draws": 10, **kw})
    assert says in str(e.value), str(e.value)


def test_a_bool_or_float_is_not_a_count():
    sphere = geoshake.declare(SPHERE, kappa=0.0)
    for kw in ({"max_tree_depth": True}, {"chains": 2.0}):
        with pytest.raises(TypeError):
            geoshake.sample(sphere, [0.0, 0.0, 1.0], draws=10, warmup=10, **kw)


def test_a_system_the_sampler_cannot_take_is_refused():
    # The Hopf constraint reads p: not holonomic.
    hopf = geoshake.models.HopfGravity(g0=0.0, g1=-1.0, radius2=1.0)
    with pytest.raises(geoshake.InvalidInputError, match="holonomic"):
        geoshake.sample(hopf, [1.0, 0.0], draws=10, warmup=10)


def test_a_step_size_that_fails_every_proposal_says_so():
    # h = 10 on the unit sphere with a strong field: proposals are rejected
    # (counted by kind), the chain stays where it started, nothing raises.
    sphere = geoshake.declare(SPHERE, kappa=50.0)
    s = geoshake.sample(
        sphere, [0.0, 0.0, 1.0], chains=1, draws=50, warmup=0, step_size=10.0,
        target_acceptance=None, steps=5,
    )
    rejected = ~s["accepted"]
    assert rejected.mean() > 0.9, rejected.mean()
    assert np.isfinite(s["positions"]).all()


def test_ess_and_rhat_of_any_quantity_match_the_samplers_own():
    s = geoshake.sample(geoshake.declare(SPHERE, kappa=1.0), [0.0, 0.0, 1.0], draws=200, warmup=50)
    for k in range(3):
        x = s["positions"][:, :, k]
        assert geoshake.ess_bulk(x) == s["ess_bulk"][k]
        assert geoshake.rhat(x) == s["rhat"][k]
    with pytest.raises(geoshake.InvalidInputError, match="chains, draws"):
        geoshake.ess_bulk(np.zeros(10))
    # A NaN draw makes the ranks meaningless: NaN, never a number.
    x = s["positions"][:, :, 0].copy()
    x[1, 7] = np.nan
    assert np.isnan(geoshake.ess_bulk(x)) and np.isnan(geoshake.rhat(x))


def test_ctrl_c_stops_a_long_run():
    # 10^12 warm-up transitions would take days; SIGINT half a second in
    # must stop every chain and raise KeyboardInterrupt within a second.
    import signal
    import threading
    import time

    sphere = geoshake.declare(SPHERE, kappa=1.0)
    # Python's own handler, whatever this process inherited: a shell that
    # starts a job in the background without job control has it ignore
    # SIGINT, and the signal would then never arrive.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.5, lambda: signal.raise_signal(signal.SIGINT))
    start = time.perf_counter()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            geoshake.sample(sphere, [0.0, 0.0, 1.0], draws=10, warmup=10**12)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    assert time.perf_counter() - start < 5.0


class _CtrlCWhileRead:
    """An argument whose reading by NumPy is where Ctrl-C lands."""

    def __array__(self, dtype=None, copy=None):
        raise KeyboardInterrupt


def test_ctrl_c_while_the_arguments_are_read_stops_the_call():
    # Ctrl-C's handler runs inside whatever Python code executes when the
    # signal arrives, NumPy's reading of q0 included: the interrupt must
    # come out as it is, not as a complaint about q0, and never be dropped
    # (the chains would then run their whole warm-up).
    sphere = geoshake.declare(SPHERE, kappa=1.0)
    with pytest.raises(KeyboardInterrupt):
        geoshake.sample(sphere, _CtrlCWhileRead(), draws=10, warmup=10**12)
    with pytest.raises(KeyboardInterrupt):
        geoshake.ess_bulk(_CtrlCWhileRead())
    with pytest.raises(KeyboardInterrupt):
        geoshake.run(sphere, _CtrlCWhileRead(), h=0.1, steps=10)
