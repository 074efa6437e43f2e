"""The particle path's pieces beyond project/step/run, from Python: forces
brought as a Python callable, the Langevin thermostat (g-BAOAB), the
constraint forces and their virial, the potential energy, and ensembles.

The systems are rigid diatomics (masses 1 and 2, bond length 1) in R³,
free or in a harmonic trap V = (k/2) Σ_a |x_a|², the trap declared as a
potential family or brought as a callable."""

import math
import pickle

import numpy as np
import pytest

import geoshake

K_TRAP = 0.7

DIMERS = """struct Dimers {
    particles x[3];
    constraints {
        bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2,
    }
}"""

TRAPPED = """struct TrappedDimers {
    parameters { stiffness }
    particles x[3];
    potential {
        trap[i in traps(a)]: stiffness / 2 * norm2(x[a]),
    }
    constraints {
        bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2,
    }
}"""


def dimers(count=4, spacing=3.0, kt=1.0, seed=1, free=0):
    """``count`` dimers with centres on a line ``spacing`` apart, random
    orientations, Maxwell momenta at k_B T = ``kt``, then ``free`` free
    particles (mass 1, in no table) at rest beyond them. Returns (masses,
    bonds table, q, p), q and p of shape (2·count + free, 3)."""
    rng = np.random.default_rng(seed)
    q, masses, bonds = [], [], []
    for i in range(count):
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        centre = np.array([spacing * i, 0.3 * i, -0.2 * i])
        q += [centre - u / 3, centre + 2 * u / 3]
        masses += [2.0, 1.0]
        bonds.append([2 * i, 2 * i + 1, 1.0])
    for j in range(free):
        q.append([spacing * (count + j), 0.0, 0.0])
        masses.append(1.0)
    masses = np.array(masses)
    p = rng.normal(size=(len(masses), 3)) * np.sqrt(masses * kt)[:, None]
    p[2 * count :] = 0.0
    return masses, np.array(bonds), np.array(q), p


def trap(q):
    """The trap as a forces callable: (V, F) with F = −∇V."""
    return 0.5 * K_TRAP * float(np.sum(q * q)), -K_TRAP * q


def traps_table(n):
    return np.arange(n, dtype=float)[:, None]


@pytest.fixture(scope="module")
def free_dimers():
    return geoshake.declare_particles(DIMERS)


@pytest.fixture(scope="module")
def trapped_dimers():
    return geoshake.declare_particles(TRAPPED, stiffness=K_TRAP)


def started(rattle, q, p):
    return rattle.project(q, p)


# Forces brought as a callable.


def test_a_trap_as_a_callable_takes_the_steps_of_the_declared_trap(free_dimers, trapped_dimers):
    """The same H two ways: the trap declared as a potential family, and
    brought as forces(q). The steps agree to round-off (measured: equal
    bit for bit, the two sum the same terms); a missing or doubled force,
    or the callable's F subtracted instead of added, is an O(1) change."""
    masses, bonds, q, p = dimers()
    n = len(masses)
    for method in ("rattle", "shake"):
        declared = trapped_dimers.system(
            masses, {"bonds": bonds, "traps": traps_table(n)}, h=0.02, method=method
        )
        brought = free_dimers.system(masses, {"bonds": bonds}, h=0.02, method=method, forces=trap)
        q0, p0 = declared.project(q, p)
        a = declared.run(q0, p0, 500, stride=10)
        b = brought.run(q0, p0, 500, stride=10)
        assert a.error is None and b.error is None
        scale = np.abs(a.q).max()
        assert np.abs(a.q - b.q).max() <= 1e-13 * scale
        assert np.abs(a.p - b.p).max() <= 1e-13 * np.abs(a.p).max()
        # The trap does work: the positions move far from a free flight.
        free = free_dimers.system(masses, {"bonds": bonds}, h=0.02, method=method).run(q0, p0, 500)
        assert np.abs(free.q[-1] - b.q[-1]).max() > 0.5
        # V includes the callable's V, and equals the declared one.
        for qk in b.q[::10]:
            v_declared = declared.potential_energy(qk)
            assert brought.potential_energy(qk) == pytest.approx(v_declared, rel=1e-14)
            assert v_declared == pytest.approx(trap(qk)[0], rel=1e-13)


def test_energy_with_brought_forces_is_conserved_to_second_order(free_dimers):
    """H = K + V along a run with the trap brought as a callable: its
    largest error over a fixed time shrinks 4× when h is halved
    (Störmer–Verlet's O(h²)), and is small."""
    masses, bonds, q, p = dimers(seed=4)
    drift = []
    for h in (0.02, 0.01):
        rattle = free_dimers.system(masses, {"bonds": bonds}, h=h, forces=trap)
        q0, p0 = rattle.project(q, p)
        run = rattle.run(q0, p0, round(4.0 / h))
        assert run.error is None
        e = np.array([rattle.kinetic_energy(pk) + rattle.potential_energy(qk) for qk, pk in zip(run.q, run.p)])
        v = np.array([trap(qk)[0] for qk in run.q])
        assert np.ptp(v) > 100 * np.ptp(e)
        drift.append(np.abs(e / e[0] - 1).max())
    assert drift[0] <= 1e-3
    assert 3.0 <= drift[0] / drift[1] <= 5.0


def test_the_callable_sees_the_positions_of_each_step(free_dimers):
    """forces(q) is called with the new positions of each step, an (n, 3)
    float64 array: once to start a run, then once per step."""
    masses, bonds, q, p = dimers(count=2)
    seen = []

    def recording(x):
        seen.append(np.array(x))
        return trap(x)

    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01, forces=recording)
    q0, p0 = rattle.project(q, p)
    seen.clear()
    run = rattle.run(q0, p0, 5)
    assert run.error is None
    assert len(seen) == 6
    assert all(x.shape == (4, 3) and x.dtype == np.float64 for x in seen)
    np.testing.assert_array_equal(seen[0], run.q[0])
    np.testing.assert_array_equal(seen[-1], run.q[-1])


class Boom(Exception):
    pass


def failing_after(calls, how):
    """A trap that fails on its ``calls``-th call, by ``how``."""
    count = [0]

    def forces(q):
        count[0] += 1
        if count[0] < calls:
            return trap(q)
        if how == "raise":
            raise Boom("the user's own error")
        if how == "nan":
            return 0.0, np.full_like(q, np.nan)
        if how == "shape":
            return 0.0, np.zeros((q.shape[0] + 1, 3))
        if how == "list":
            return [0.0, -q]
        if how == "v":
            return "V", -q
        if how == "dtype":
            return 0.0, np.zeros(q.shape, dtype=complex)
        raise AssertionError(how)

    return forces


@pytest.mark.parametrize(
    "how, error, words",
    [
        ("raise", Boom, "the user's own error"),
        ("nan", geoshake.NonFiniteError, "forces"),
        ("shape", geoshake.InvalidInputError, "(4, 3)"),
        ("list", geoshake.InvalidInputError, "tuple (V, F)"),
        ("v", geoshake.InvalidInputError, "V a float"),
        ("dtype", geoshake.InvalidInputError, "real numbers"),
    ],
)
def test_a_failing_callable_raises_from_step_and_ends_a_run_with_its_frames(free_dimers, how, error, words):
    masses, bonds, q, p = dimers(count=2)
    # Step: the callable is called once at the start and once per step.
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01, forces=failing_after(2, how))
    q0, p0 = rattle.project(q, p)
    with pytest.raises(error) as caught:
        rattle.step(q0, p0)
    assert words in str(caught.value)
    # Run: the 8th call is in step 7; the frames of steps 0..6 are kept.
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01, forces=failing_after(8, how))
    run = rattle.run(q0, p0, 20)
    assert isinstance(run.error, error)
    assert words in str(run.error)
    assert len(run) == 7
    np.testing.assert_array_equal(run.step, np.arange(7))
    reference = free_dimers.system(masses, {"bonds": bonds}, h=0.01, forces=trap).run(q0, p0, 6)
    np.testing.assert_array_equal(run.q, reference.q)
    # The solver is usable afterwards, and a later success is not
    # reported as the old failure.
    healthy = free_dimers.system(masses, {"bonds": bonds}, h=0.01, forces=trap)
    assert healthy.run(q0, p0, 3).error is None


def test_an_interrupt_in_the_callable_stops_a_run_by_raising(free_dimers):
    """Ctrl-C (or sys.exit) in the callable is the user asking to stop: a
    run raises it rather than returning it as the run's error."""
    masses, bonds, q, p = dimers(count=2)
    count = [0]

    def interrupted(x):
        count[0] += 1
        if count[0] == 5:
            raise KeyboardInterrupt
        return trap(x)

    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01, forces=interrupted)
    with pytest.raises(KeyboardInterrupt):
        rattle.run(q, p, 10)
    count[0] = 0
    with pytest.raises(KeyboardInterrupt):
        rattle.ensemble(np.stack([q]), np.stack([p]), 10)


def test_a_callable_that_uses_its_own_solver_is_refused_not_deadlocked(free_dimers):
    masses, bonds, q, p = dimers(count=2)
    other = free_dimers.system(masses, {"bonds": bonds}, h=0.01, forces=trap)
    box = {}

    def reentrant(x):
        # Another system may be used from inside the callable...
        other.potential_energy(x)
        # ...but not the one whose step is calling.
        box["rattle"].potential_energy(x)
        return trap(x)

    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01, forces=reentrant)
    box["rattle"] = rattle
    q0, p0 = other.project(q, p)
    with pytest.raises(geoshake.InvalidInputError, match="cannot use it"):
        rattle.step(q0, p0)
    run = rattle.run(q0, p0, 3)
    assert isinstance(run.error, geoshake.InvalidInputError)


@pytest.mark.parametrize("forces", ["trap", 3.0, np.zeros((4, 3))])
def test_forces_that_are_not_callable_are_refused(free_dimers, forces):
    masses, bonds, _, _ = dimers(count=2)
    with pytest.raises(geoshake.InvalidInputError, match="callable"):
        free_dimers.system(masses, {"bonds": bonds}, h=0.01, forces=forces)


# The Langevin thermostat.


def test_the_thermostat_holds_the_temperature(free_dimers):
    """8 free rigid dimers at k_B T = 1.5 (γ = 1, h = 0.05, g-BAOAB with 2
    substeps), started at rest: the kinetic temperature 2K / (nD − m)
    averaged over 40000 steps after 2000 of equilibration. Its standard
    error comes from 40 batch means of 1000 steps each (≫ the correlation
    time 1/(2γ) = 0.5, 10 steps); the mean must be within 4 standard
    errors of k_B T, and the standard error below 1 % (measured ~0.5 %) so
    that a wrong noise amplitude (√2 or a mass's square root off) cannot
    pass."""
    masses, bonds, q, p = dimers(count=8, seed=7)
    kt = 1.5
    thermostat = geoshake.Langevin(1.0, kt, seed=11, substeps=2)
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.05, thermostat=thermostat)
    q0, p0 = rattle.project(q, np.zeros_like(p))
    run = rattle.run(q0, p0, 42000, stride=1)
    assert run.error is None
    dof = masses.size * 3 - len(bonds)
    temperature = np.sum(run.p**2 / masses[None, :, None], axis=(1, 2)) / dof
    samples = temperature[2001:].reshape(40, 1000).mean(axis=1)
    mean, se = samples.mean(), samples.std(ddof=1) / math.sqrt(len(samples))
    assert se / kt < 0.01
    assert abs(mean - kt) < 4 * se
    # The constraints hold through the noise.
    r = np.linalg.norm(run.q[:, bonds[:, 0].astype(int)] - run.q[:, bonds[:, 1].astype(int)], axis=-1)
    assert np.abs(r - 1.0).max() <= 1e-10


def test_the_thermostat_is_reproducible_by_its_seed(free_dimers):
    masses, bonds, q, p = dimers(seed=2)

    def run(seed):
        th = geoshake.Langevin(0.5, 1.0, seed=seed)
        rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.05, thermostat=th)
        q0, p0 = rattle.project(q, p)
        return rattle.run(q0, p0, 50)

    a, b, c = run(5), run(5), run(6)
    np.testing.assert_array_equal(a.q, b.q)
    np.testing.assert_array_equal(a.p, b.p)
    assert np.abs(a.p[-1] - c.p[-1]).max() > 0.1


def test_steps_go_on_from_the_state_they_made(free_dimers):
    """A loop of `step`, each given back what the last returned, takes the
    run's steps bit for bit: with a thermostat the noise of step k is the
    k-th, not the first again."""
    masses, bonds, q, p = dimers(seed=3)
    th = geoshake.Langevin(0.5, 1.0, seed=9)
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.05, thermostat=th, forces=trap)
    q0, p0 = rattle.project(q, p)
    run = rattle.run(q0, p0, 20)
    qk, pk = q0, p0
    for k in range(1, 21):
        qk, pk = rattle.step(qk, pk)
        np.testing.assert_array_equal(qk, run.q[k])
        np.testing.assert_array_equal(pk, run.p[k])


@pytest.mark.parametrize(
    "args, kwargs, words",
    [
        ((-1.0, 1.0), {}, "friction"),
        ((math.nan, 1.0), {}, "friction"),
        ((math.inf, 1.0), {}, "friction"),
        ((1.0, -1e-9), {}, "k_B T"),
        ((1.0, math.nan), {}, "k_B T"),
        (("fast", 1.0), {}, "friction must be a real number"),
        ((1.0, None), {}, "kT must be a real number"),
        ((1.0, 1.0), {"seed": -1}, "seed"),
        ((1.0, 1.0), {"seed": 2**64}, "seed"),
        ((1.0, 1.0), {"seed": 1.5}, "seed"),
        ((1.0, 1.0), {"seed": np.int64(-2)}, "`seed` = -2"),
        ((1.0, 1.0), {"substeps": "2"}, "substeps"),
        ((1.0, 1.0), {"substeps": 0}, "substeps"),
        ((1.0, 1.0), {"substeps": -3}, "substeps"),
        ((1.0, 1.0), {"substeps": 2**40}, "substeps"),
        ((1.0, 1.0), {"substeps": 2**20 + 1}, "an integer from 1 to 1048576"),
    ],
)
def test_bad_thermostats_are_refused(args, kwargs, words):
    with pytest.raises(geoshake.InvalidInputError, match=words):
        geoshake.Langevin(*args, **kwargs)


def test_a_thermostat_takes_numpy_integers():
    th = geoshake.Langevin(1.0, 1.0, seed=np.uint64(7), substeps=np.int32(2))
    assert (th.seed, th.substeps) == (7, 2)
    assert th.member(np.int64(3)) == th.member(3)


def test_a_thermostat_pickles_and_draws_the_same_noise(free_dimers):
    th = geoshake.Langevin(0.5, 1.0, seed=2**63 + 5, substeps=3)
    masses, bonds, q, p = dimers(seed=4)
    for protocol in range(pickle.HIGHEST_PROTOCOL + 1):
        back = pickle.loads(pickle.dumps(th, protocol=protocol))
        assert back == th and (back.seed, back.substeps) == (2**63 + 5, 3)
    runs = []
    for t in (th, back):
        rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.05, thermostat=t)
        q0, p0 = rattle.project(q, p)
        runs.append(rattle.run(q0, p0, 10))
    np.testing.assert_array_equal(runs[0].p, runs[1].p)


def test_runs_and_constraint_forces_pickle(trapped_dimers):
    # What a worker process returns: plain data, error included.
    masses, bonds, q, p = dimers(count=3, seed=5)
    rattle = trapped_dimers.system(masses, {"bonds": bonds, "traps": traps_table(len(masses))}, h=0.05)
    q0, p0 = rattle.project(q, p)
    run = rattle.run(q0, p0, 5)
    fc = rattle.constraint_forces(*rattle.step(q0, p0))
    for protocol in range(pickle.HIGHEST_PROTOCOL + 1):
        r = pickle.loads(pickle.dumps(run, protocol=protocol))
        for name in ("q", "p", "time", "step"):
            np.testing.assert_array_equal(getattr(r, name), getattr(run, name))
        assert r.error is None and len(r) == len(run)
        f = pickle.loads(pickle.dumps(fc, protocol=protocol))
        for name in ("forces", "virial", "multipliers"):
            np.testing.assert_array_equal(getattr(f, name), getattr(fc, name))
        assert f.time == fc.time
    failed = rattle.run(q0, p0 * 1e300, 3)
    assert isinstance(failed.error, geoshake.ShakeError)
    back = pickle.loads(pickle.dumps(failed))
    assert type(back.error) is type(failed.error) and str(back.error) == str(failed.error)


def test_a_run_too_long_is_refused_before_any_step(free_dimers):
    # It was returned as an empty run whose `error` said so.
    masses, bonds, q, p = dimers(count=2)
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01)
    for call in (lambda: rattle.run(q, p, 2**60), lambda: rattle.ensemble(q[None], p[None], 2**60)):
        with pytest.raises(geoshake.InvalidInputError, match="`steps` = 1152921504606846976"):
            call()


def test_a_thermostat_is_refused_to_shake_and_must_be_a_langevin(free_dimers):
    masses, bonds, _, _ = dimers(count=2)
    th = geoshake.Langevin(1.0, 1.0)
    with pytest.raises(geoshake.InvalidInputError, match="RATTLE"):
        free_dimers.system(masses, {"bonds": bonds}, h=0.01, method="shake", thermostat=th)
    for bad in (1.0, "langevin", {"friction": 1.0}):
        with pytest.raises(geoshake.InvalidInputError, match="Langevin"):
            free_dimers.system(masses, {"bonds": bonds}, h=0.01, thermostat=bad)
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01, thermostat=th)
    assert rattle.thermostat == th
    assert (th.friction, th.kT, th.seed, th.substeps) == (1.0, 1.0, 0, 1)
    assert th.member(0) == th and th.member(1).seed == 0x9E3779B97F4A7C15


# Constraint forces and their virial.


@pytest.mark.parametrize("method", ["rattle", "shake"])
def test_constraint_forces_reproduce_the_step_and_the_bond_tensions(trapped_dimers, method):
    """After a step from (q0, p0) to (q1, p1): q1 = q0 + h M⁻¹ p0 + (h²/2)
    M⁻¹ (F(q0) + f_c) to round-off; each atom's f_c is −2 Λ_k (x_a − x_b)
    at q0 from its bond's multiplier, the two atoms' forces cancel, and
    W = Σ x ⊗ f_c at q0 is symmetric with trace −Σ_k 2 Λ_k l_k²."""
    masses, bonds, q, p = dimers(count=5, seed=8)
    n, h = len(masses), 0.05
    rattle = trapped_dimers.system(masses, {"bonds": bonds, "traps": traps_table(n)}, h=h, method=method)
    q0, p0 = rattle.project(q, p)
    qk, pk = q0, p0
    for _ in range(3):
        previous = qk, pk
        qk, pk = rattle.step(qk, pk)
    qa, pa = previous
    fc = rattle.constraint_forces(qk, pk)
    assert fc.forces.shape == (n, 3) and fc.virial.shape == (3, 3) and fc.multipliers.shape == (5,)
    assert fc.time == pytest.approx(2 * h, abs=1e-15)
    force = -K_TRAP * qa
    predicted = qa + h * pa / masses[:, None] + 0.5 * h * h * (force + fc.forces) / masses[:, None]
    assert np.abs(predicted - qk).max() <= 1e-13 * np.abs(qk).max()
    # Without f_c the prediction is off by far more: the test can fail.
    unconstrained = predicted - 0.5 * h * h * fc.forces / masses[:, None]
    assert np.abs(unconstrained - qk).max() > 1e-4
    a, b = bonds[:, 0].astype(int), bonds[:, 1].astype(int)
    r = qa[a] - qa[b]
    expected = np.zeros_like(qa)
    expected[a] = -2 * fc.multipliers[:, None] * r
    expected[b] = 2 * fc.multipliers[:, None] * r
    np.testing.assert_allclose(fc.forces, expected, rtol=1e-12, atol=1e-14 * np.abs(expected).max())
    assert np.abs(fc.forces[a] + fc.forces[b]).max() <= 1e-13 * np.abs(fc.forces).max()
    w = qa.T @ fc.forces
    np.testing.assert_allclose(fc.virial, w, rtol=1e-12, atol=1e-13 * np.abs(w).max())
    np.testing.assert_allclose(fc.virial, fc.virial.T, atol=1e-12 * np.abs(w).max())
    trace = -np.sum(2 * fc.multipliers * bonds[:, 2] ** 2)
    assert np.trace(fc.virial) == pytest.approx(trace, rel=1e-10)


def test_constraint_forces_of_any_other_state_are_refused(free_dimers):
    masses, bonds, q, p = dimers(count=2)
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01)
    q0, p0 = rattle.project(q, p)
    with pytest.raises(geoshake.InvalidInputError, match="constraint forces"):
        rattle.constraint_forces(q0, p0)
    q1, p1 = rattle.step(q0, p0)
    rattle.constraint_forces(q1, p1)
    with pytest.raises(geoshake.InvalidInputError):
        rattle.constraint_forces(q1, p1 + 1e-9)
    run = rattle.run(q0, p0, 3)
    with pytest.raises(geoshake.InvalidInputError):
        rattle.constraint_forces(run.q[-1], run.p[-1])
    th = free_dimers.system(masses, {"bonds": bonds}, h=0.01, thermostat=geoshake.Langevin(1.0, 1.0))
    q1, p1 = th.step(q0, p0)
    with pytest.raises(geoshake.InvalidInputError, match="thermostat"):
        th.constraint_forces(q1, p1)
    with pytest.raises(geoshake.InvalidInputError):
        rattle.constraint_forces(q1[:-1], p1)


# Ensembles.


def members(q, p, count, seed=0):
    """``count`` starts: the same positions, momenta scaled and rotated."""
    rng = np.random.default_rng(seed)
    qs = np.stack([q] * count)
    ps = np.stack([p * (0.5 + k / count) for k in range(count)])
    ps += 0.01 * rng.normal(size=ps.shape)
    return qs, ps


@pytest.mark.parametrize("with_thermostat", [False, True])
def test_each_member_is_its_serial_run_bit_for_bit(free_dimers, with_thermostat):
    masses, bonds, q, p = dimers(count=4, seed=5)
    th = geoshake.Langevin(0.3, 1.0, seed=21) if with_thermostat else None
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.02, forces=trap, thermostat=th)
    q0, p0 = rattle.project(q, p)
    qs, ps = members(q0, p0, 6)
    qs_before = qs.copy()
    runs = rattle.ensemble(qs, ps, 40, stride=4, t0=1.5)
    np.testing.assert_array_equal(qs, qs_before)
    assert len(runs) == 6
    for i, run in enumerate(runs):
        assert run.error is None
        assert run.q.shape == run.p.shape == (11, 8, 3)
        np.testing.assert_allclose(run.time, 1.5 + 0.02 * np.arange(0, 41, 4), atol=1e-13)
        serial = rattle
        if with_thermostat:
            serial = free_dimers.system(masses, {"bonds": bonds}, h=0.02, forces=trap, thermostat=th.member(i))
        alone = serial.run(qs[i], ps[i], 40, stride=4, t0=1.5)
        np.testing.assert_array_equal(run.q, alone.q)
        np.testing.assert_array_equal(run.p, alone.p)
        np.testing.assert_array_equal(run.time, alone.time)
    if with_thermostat:
        # Each member has its own noise: two members from the same start
        # part ways.
        same = rattle.ensemble(np.stack([q0, q0]), np.stack([p0, p0]), 10)
        assert np.abs(same[0].p[-1] - same[1].p[-1]).max() > 1e-3
    else:
        same = rattle.ensemble(np.stack([q0, q0]), np.stack([p0, p0]), 10)
        np.testing.assert_array_equal(same[0].p, same[1].p)


def test_a_failing_member_keeps_its_frames_while_the_others_complete(free_dimers):
    """Member 1 throws a free particle at 1e307 (it leaves f64's range after
    some steps); member 3's callable raises once its free particle passes
    x = 20. Both keep their frames up to the failure and their errors; the
    others run to the end."""
    masses, bonds, q, p = dimers(count=2, free=1)
    n = len(masses)
    start_x = q[-1, 0]

    def guarded(x):
        if x[-1, 0] > start_x + 1.05:
            raise Boom(f"particle out at {x[-1, 0]}")
        return 0.0, np.zeros_like(x)

    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.5, forces=guarded)
    q0, p0 = rattle.project(q, p)
    qs, ps = members(q0, p0, 5)
    ps[:, -1] = 0.0
    ps[1, -1, 0] = 1e307
    ps[3, -1, 0] = 0.2
    runs = rattle.ensemble(qs, ps, 60)
    for i, run in enumerate(runs):
        if i == 1:
            assert isinstance(run.error, (geoshake.NonFiniteError, Boom))
        elif i == 3:
            # x passes start + 1 in step 11 (0.2 · 0.5 per step).
            assert isinstance(run.error, Boom) and "particle out" in str(run.error)
            assert len(run) == 11
        else:
            assert run.error is None and len(run) == 61
        alone = rattle.run(qs[i], ps[i], 60)
        assert type(alone.error) is type(run.error)
        np.testing.assert_array_equal(run.q, alone.q)
        assert run.q.shape[1:] == (n, 3)


@pytest.mark.parametrize(
    "qs_shape, ps_shape",
    [((2, 4, 3), (3, 4, 3)), ((4, 3), (4, 3)), ((2, 5, 3), (2, 5, 3)), ((2, 4, 2), (2, 4, 2)), ((2, 4, 3, 1), (2, 4, 3, 1))],
)
def test_members_of_the_wrong_shape_are_refused(free_dimers, qs_shape, ps_shape):
    masses, bonds, _, _ = dimers(count=2)
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01)
    with pytest.raises(geoshake.InvalidInputError, match="shape|members"):
        rattle.ensemble(np.zeros(qs_shape), np.zeros(ps_shape), 3)


def test_hostile_members(free_dimers):
    masses, bonds, q, p = dimers(count=2)
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01)
    q0, p0 = rattle.project(q, p)
    qs, ps = members(q0, p0, 3)
    # No members: no runs.
    assert rattle.ensemble(qs[:0], ps[:0], 3) == []
    # A NaN in one member: its error, the others run.
    bad = qs.copy()
    bad[1, 0, 0] = np.nan
    runs = rattle.ensemble(bad, ps, 3)
    assert isinstance(runs[1].error, geoshake.NonFiniteError) and len(runs[1]) == 0
    assert runs[0].error is None and runs[2].error is None
    for qs_bad in ([[[1.0]]], "qs", qs.astype(complex), [q0.tolist(), q0[:-1].tolist()]):
        with pytest.raises(geoshake.InvalidInputError):
            rattle.ensemble(qs_bad, ps, 3)
    # A member list of arrays is taken.
    runs = rattle.ensemble(list(qs), list(ps), 2)
    assert all(r.error is None for r in runs)
    with pytest.raises(geoshake.InvalidInputError):
        rattle.potential_energy(q0[:-1])
    with pytest.raises(geoshake.InvalidInputError):
        rattle.potential_energy(np.full((4, 3), "x"))
    assert rattle.potential_energy(q0) == 0.0


def test_the_guide_s_example_runs():
    """docs/guide/python.md's example of this section, as written."""
    import pathlib

    guide = pathlib.Path(__file__).resolve().parents[2] / "docs" / "guide" / "python.md"
    if not guide.exists():
        pytest.skip("the guide is not beside the tests")
    text = guide.read_text()
    section = text.index("### Forces, thermostat, virial and ensembles")
    start = text.index("```python\n", section) + len("```python\n")
    code = text[start : text.index("```", start)]
    names = {}
    exec(compile(code, str(guide), "exec"), names)
    assert names["fc"].virial.shape == (3, 3)
    runs = names["runs"]
    assert len(runs) == 8 and all(r.error is None and r.q.shape == (101, 4, 3) for r in runs)
    assert np.abs(runs[0].p[-1] - runs[1].p[-1]).max() > 0.1


class ShiftingArray:
    """An object that NumPy reads as (members, n, 3) arrays of another
    number of members on every read."""

    def __init__(self, q, counts):
        self.q, self.counts = q, list(counts)

    def __array__(self, dtype=None, copy=None):
        count = self.counts.pop(0) if len(self.counts) > 1 else self.counts[0]
        return np.stack([self.q] * count)


@pytest.mark.parametrize("counts", [(3, 1), (1, 3)])
def test_members_are_read_once(free_dimers, counts):
    masses, bonds, q, p = dimers(count=2)
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01)
    q0, p0 = rattle.project(q, p)
    # The members' count is that of the one read: 3 or 1 states, and the
    # momenta must agree with it.
    shifting = ShiftingArray(q0, counts)
    first = counts[0]
    runs = rattle.ensemble(shifting, np.stack([p0] * first), 2)
    assert len(runs) == first and all(r.error is None for r in runs)
    np.testing.assert_array_equal(runs[0].q, rattle.run(q0, p0, 2).q)


def test_arguments_no_state_can_make_right_raise(free_dimers):
    masses, bonds, q, p = dimers(count=2)
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01)
    q0, p0 = rattle.project(q, p)
    qs, ps = members(q0, p0, 2)
    with pytest.raises(geoshake.InvalidInputError, match="stride"):
        rattle.run(q0, p0, 10, stride=0)
    with pytest.raises(geoshake.InvalidInputError, match="stride"):
        rattle.ensemble(qs, ps, 10, stride=0)
    # Negative or past a u64: the package's error naming the count (it was
    # Python's OverflowError).
    for steps, stride, says in ((-1, 1, "`steps` = -1"), (10, -2, "`stride` = -2"), (2**64, 1, "`steps`")):
        with pytest.raises(geoshake.InvalidInputError, match=says):
            rattle.run(q0, p0, steps, stride=stride)
        with pytest.raises(geoshake.InvalidInputError, match=says):
            rattle.ensemble(qs, ps, steps, stride=stride)
    with pytest.raises(geoshake.InvalidInputError, match="`max_iterations` = -1"):
        free_dimers.system(masses, {"bonds": bonds}, h=0.01, max_iterations=-1)
    for t0 in (math.nan, math.inf):
        with pytest.raises(geoshake.InvalidInputError, match="t0"):
            rattle.run(q0, p0, 10, t0=t0)
        with pytest.raises(geoshake.InvalidInputError, match="t0"):
            rattle.ensemble(qs, ps, 10, t0=t0)
    # Frames that cannot be stored: raised, with what to do about it.
    with pytest.raises(geoshake.ShakeError, match="larger stride"):
        rattle.run(q0, p0, 10**15)
    with pytest.raises(geoshake.ShakeError, match="larger stride"):
        rattle.ensemble(qs, ps, 10**15)
    # A long stride is fine.
    assert len(rattle.run(q0, p0, 10**15 // 10**13, stride=10)) == 11


def test_a_run_s_frames_are_its_states_in_order(free_dimers):
    """The frames are laid out anew (all q, then all p) from the
    trajectory's interleaved states: each is the state `step` reaches."""
    masses, bonds, q, p = dimers(count=3)
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01)
    q0, p0 = rattle.project(q, p)
    run = rattle.run(q0, p0, 7, stride=2)
    assert run.q.flags.c_contiguous and run.p.flags.c_contiguous
    np.testing.assert_array_equal(run.step, [0, 2, 4, 6, 7])
    stepper = free_dimers.system(masses, {"bonds": bonds}, h=0.01)
    x, y = q0, p0
    for k in range(8):
        if k in run.step:
            i = list(run.step).index(k)
            np.testing.assert_array_equal(run.q[i], x)
            np.testing.assert_array_equal(run.p[i], y)
        x, y = stepper.step(x, y)


def test_energies_of_numbers_that_are_not_finite_raise(free_dimers):
    masses, bonds, q, p = dimers(count=2)
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01)
    for bad in (np.full(p.shape, np.inf), np.full(p.shape, np.nan), np.full(p.shape, 1e200)):
        with pytest.raises(geoshake.NonFiniteError, match="kinetic energy"):
            rattle.kinetic_energy(bad)
    bad = q.copy()
    bad[1, 2] = np.nan
    with pytest.raises(geoshake.NonFiniteError, match="q must be finite"):
        rattle.potential_energy(bad)
    assert rattle.potential_energy(q) == 0.0


def test_a_mass_whose_inverse_overflows_is_refused(free_dimers):
    masses, bonds, q, p = dimers(count=2)
    masses[0] = 5e-324
    with pytest.raises(geoshake.InvalidInputError, match="inverse"):
        free_dimers.system(masses, {"bonds": bonds}, h=0.01)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_a_parameter_that_is_not_finite_is_refused(value):
    with pytest.raises(geoshake.ParameterError, match="stiffness.*finite"):
        geoshake.declare_particles(TRAPPED, stiffness=value)


def test_an_unknown_parameter_of_a_declaration_without_any_says_so():
    with pytest.raises(geoshake.ParameterError, match="has no parameters"):
        geoshake.declare_particles(DIMERS, stiffness=1.0)


def test_a_thermostat_s_noise_goes_on_when_the_arrays_change(free_dimers):
    """Positions changed between steps (here by 1e-13, as wrapping them
    into a box changes their last bits) are a new state, but the step
    count goes on: the steps stay within round-off of the run's, where a
    count restarted at 0 would draw step 1's noise again (an O(1)
    difference in the momenta)."""
    masses, bonds, q, p = dimers(seed=4)
    th = geoshake.Langevin(0.5, 1.0, seed=21)
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.05, thermostat=th)
    q0, p0 = rattle.project(q, p)
    run = rattle.run(q0, p0, 20)
    stepper = free_dimers.system(masses, {"bonds": bonds}, h=0.05, thermostat=th)
    qk, pk = q0, p0
    for k in range(1, 21):
        qk, pk = stepper.step(qk + 1e-13, pk)
        assert np.abs(pk - run.p[k]).max() < 1e-9
        assert np.abs(qk - run.q[k]).max() < 1e-9


@pytest.mark.parametrize("call", ["run", "ensemble"])
def test_ctrl_c_stops_a_run_and_keeps_its_frames(free_dimers, call):
    """10⁹ steps would take hours; SIGINT half a second in must stop the
    run within a few seconds, raising KeyboardInterrupt with the frames
    computed so far attached (`run`, or `runs` for an ensemble)."""
    import signal
    import threading
    import time

    masses, bonds, q, p = dimers(count=2)
    rattle = free_dimers.system(masses, {"bonds": bonds}, h=0.01, tolerance=1e-10)
    q0, p0 = rattle.project(q, p)
    # A job started in the background ignores SIGINT: install Python's
    # handler, or the signal would never arrive.
    qs, ps = members(q0, p0, 2)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.5, lambda: signal.raise_signal(signal.SIGINT))
    start = time.perf_counter()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt) as caught:
            if call == "run":
                rattle.run(q0, p0, 10**9, stride=10**4)
            else:
                rattle.ensemble(qs, ps, 10**9, stride=10**4)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    assert time.perf_counter() - start < 5.0
    runs = [caught.value.run] if call == "run" else caught.value.runs
    starts = [q0] if call == "run" else list(qs)
    assert len(runs) == len(starts)
    for run, start in zip(runs, starts):
        # Stopped early, with the frames so far: the first is the start,
        # the steps increase, each of them a step of that run.
        assert 2 <= len(run) < 10**5 and run.error is None
        np.testing.assert_array_equal(run.q[0], start)
        assert np.all(np.diff(run.step) > 0) and run.step[-1] < 10**9
