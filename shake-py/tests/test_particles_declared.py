"""Particle systems declared from a string (``geoshake.declare_particles``):
a box of rigid waters built here, projected and run by RATTLE, with every
bond and every hidden constraint checked in every frame, the kinetic energy
conserved, the steps checked against ``geoshake.Bonds`` (the same
constraints solved by another route: SHAKE's and RATTLE's stages on a
hand-made distance family, in closed form), and the refusals: a bad
declaration at its line and column, bad tables, a run that fails keeping
its frames."""

import numpy as np
import pytest

import geoshake

WATER = """struct Water {
    particles x[3];
    constraints {
        bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2,
    }
}"""

OH, HH = 1.0, 1.633
MO, MH = 16.0, 1.0


def water_box(side=4, spacing=3.1, kt=1e-3, seed=1):
    """``side``³ rigid waters: O on a cubic lattice, the H's at 1 Å from
    it and 1.633 Å apart in a random orientation; Maxwell momenta at k_B T
    = ``kt`` (masses 16 and 1, time in units where h = 1 is stable).
    Returns (masses, rows of the bonds table, q, p)."""
    rng = np.random.default_rng(seed)
    half = np.arcsin(HH / 2 / OH)
    local = OH * np.array(
        [[0.0, 0.0, 0.0], [np.sin(half), np.cos(half), 0.0], [-np.sin(half), np.cos(half), 0.0]]
    )
    q, masses, rows = [], [], []
    for i, (a, b, c) in enumerate(np.ndindex(side, side, side)):
        rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        q.extend(spacing * np.array([a, b, c]) + local @ rotation.T)
        masses.extend([MO, MH, MH])
        o = 3 * i
        rows += [[o, o + 1, OH], [o, o + 2, OH], [o + 1, o + 2, HH]]
    masses = np.array(masses)
    p = rng.normal(size=(len(masses), 3)) * np.sqrt(masses * kt)[:, None]
    return masses, np.array(rows), np.array(q), p


def relative_bond_errors(q, rows):
    """| |x_a − x_b| − l | / l for every row, in every frame of q (…, n, 3)."""
    a, b = rows[:, 0].astype(int), rows[:, 1].astype(int)
    r = np.linalg.norm(q[..., a, :] - q[..., b, :], axis=-1)
    return np.abs(r - rows[:, 2]) / rows[:, 2]


def relative_hidden(q, p, masses, rows):
    """(x_a − x_b)·(v_a − v_b) / (|x_a − x_b| |v|), v the largest speed of
    the frame: RATTLE's hidden constraints, relative."""
    a, b = rows[:, 0].astype(int), rows[:, 1].astype(int)
    v = p / masses[:, None]
    dv = v[..., a, :] - v[..., b, :]
    dx = q[..., a, :] - q[..., b, :]
    scale = np.linalg.norm(dx, axis=-1) * np.abs(v).max(axis=(-1, -2))[..., None]
    return np.abs(np.sum(dx * dv, axis=-1)) / scale


@pytest.fixture(scope="module")
def water():
    return geoshake.declare_particles(WATER)


@pytest.fixture(scope="module")
def box(water):
    masses, rows, q, p = water_box()
    rattle = water.system(masses, {"bonds": rows}, h=1.0)
    return rattle, masses, rows, q, p


def test_the_declaration_lists_its_families(water):
    assert water.name == "Water"
    assert water.dim == 3
    assert water.parameters == {}
    assert water.families == [
        {"name": "bond", "kind": "constraint", "table": "bonds", "arity": 2, "data": 1}
    ]


def test_a_water_box_runs_with_every_bond_held_and_the_energy_conserved(box):
    rattle, masses, rows, q, p = box
    assert (rattle.particles, rattle.dim, rattle.constraints) == (192, 3, 192)
    # Start off M: the lattice's geometry is exact only to round-off, and
    # a kick off M^H in the momenta.
    q0, p0 = rattle.project(q, p)
    assert relative_bond_errors(q0, rows).max() <= 1e-10
    assert relative_hidden(q0, p0, masses, rows).max() <= 1e-10
    run = rattle.run(q0, p0, 100)
    assert run.error is None
    assert len(run) == 101
    assert run.q.shape == run.p.shape == (101, 192, 3)
    np.testing.assert_array_equal(run.step, np.arange(101))
    np.testing.assert_allclose(run.time, np.arange(101) * 1.0, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(run.q[0], q0)
    # The molecules have turned: the run is not trivially at rest.
    assert np.abs(run.q[-1] - run.q[0]).max() > 0.5
    # Every bond, every frame, to the solver's tolerance (1e-12) with room.
    assert relative_bond_errors(run.q, rows).max() <= 1e-10
    assert relative_hidden(run.q, run.p, masses, rows).max() <= 1e-10
    # H = K (no potential). For free rigid molecules RATTLE keeps K to
    # round-off (measured: 1.3e-13 relative over the 100 steps); 1e-10
    # leaves room for the solver's tolerance and still fails on a velocity
    # stage left out or a momentum scaled wrongly.
    k = np.array([rattle.kinetic_energy(pk) for pk in run.p])
    k_here = 0.5 * np.sum(run.p**2 / masses[None, :, None], axis=(1, 2))
    np.testing.assert_allclose(k, k_here, rtol=1e-13)
    assert np.abs(k / k[0] - 1).max() <= 1e-10
    # The total momentum is conserved exactly (constraint forces cancel in
    # pairs), to round-off.
    total = run.p.sum(axis=1)
    assert np.abs(total - total[0]).max() <= 1e-12 * np.abs(run.p).max() * len(masses)


def test_a_run_with_a_stride_keeps_the_same_frames(box):
    rattle, masses, rows, q, p = box
    q0, p0 = rattle.project(q, p)
    every = rattle.run(q0, p0, 20)
    strided = rattle.run(q0, p0, 20, stride=5)
    np.testing.assert_array_equal(strided.step, [0, 5, 10, 15, 20])
    np.testing.assert_array_equal(strided.q, every.q[::5])
    np.testing.assert_array_equal(strided.p, every.p[::5])


def test_steps_agree_with_the_stages_of_bonds(box):
    """An independent route to the same step: RATTLE with no potential is a
    drift q̃ = q0 + h M⁻¹ p0, SHAKE's position stage along the old bonds
    (``Bonds.shake_positions``, a distance family solved in closed form),
    p = M (q1 − q0) / h, and the velocity stage (``Bonds.project_momenta``)."""
    rattle, masses, rows, q, p = box
    bonds = geoshake.Bonds(masses, rows[:, :2].astype(np.int64), rows[:, 2], tolerance=1e-13)
    qk, pk = rattle.project(q, p)
    h = rattle.h
    for _ in range(10):
        q1, p1 = rattle.step(qk, pk)
        x = qk + h * pk / masses[:, None]
        bonds.shake_positions(qk, x)
        v = masses[:, None] * (x - qk) / h
        bonds.project_momenta(x, v)
        np.testing.assert_allclose(q1, x, rtol=0, atol=1e-10)
        np.testing.assert_allclose(p1, v, rtol=0, atol=1e-9 * np.abs(pk).max())
        qk, pk = q1, p1


def test_a_bad_declaration_raises_at_its_line_and_column():
    src = """struct S {
    particles x[3];
    constraints { c[k in t(a, b)]: norm2(x[a]) - 1 }
}"""
    with pytest.raises(geoshake.DeclarationError) as e:
        geoshake.declare_particles(src)
    assert (e.value.line, e.value.column) == (3, 31)
    assert "does not depend on particle `b`" in e.value.message
    assert isinstance(e.value, geoshake.ShakeError)


def test_a_family_shape_without_a_run_time_stencil_is_a_declaration_error():
    src = "struct S { particles x[7]; constraints { c[k in t(a)]: norm2(x[a]) - 1 } }"
    with pytest.raises(geoshake.DeclarationError, match="no run-time stencil") as e:
        geoshake.declare_particles(src)
    assert (e.value.line, e.value.column) == (None, None)


def test_parameters_are_given_by_name():
    src = """struct Scaled {
    parameters { scale }
    particles x[2];
    constraints { rod[k in rods(a, b; length)]: norm2(x[a] - x[b]) - (scale * length)^2 }
}"""
    with pytest.raises(geoshake.ParameterError, match="scale"):
        geoshake.declare_particles(src)
    with pytest.raises(geoshake.ParameterError, match="unknown parameter `other`"):
        geoshake.declare_particles(src, scale=1.0, other=2.0)
    rod = geoshake.declare_particles(src, scale=2.0)
    assert rod.parameters == {"scale": 2.0}
    rattle = rod.system([1.0, 1.0], {"rods": [[0, 1, 0.5]]}, h=0.01)
    q, p = rattle.project([[0.0, 0.0], [1.5, 0.0]], [[0.0, 1.0], [0.0, -1.0]])
    assert np.linalg.norm(q[0] - q[1]) == pytest.approx(1.0, rel=1e-12)
    run = rattle.run(q, p, 50)
    assert run.q.shape == (51, 2, 2)
    assert np.abs(np.linalg.norm(run.q[:, 0] - run.q[:, 1], axis=-1) - 1.0).max() <= 1e-10


def test_bad_tables_raise_invalid_input(water):
    masses = np.array([MO, MH, MH])
    good = [[0, 1, OH], [0, 2, OH], [1, 2, HH]]
    cases = [
        ({"bonds": [[0, 1, OH], [0, 5, OH]]}, "particle"),  # dangling index
        ({"bonds": [[0, 0, OH]]}, "twice"),  # a particle repeated in a row
        ({"bonds": [[0, 1.5, OH]]}, "whole number"),
        ({"bonds": [[0, -1, OH]]}, "whole number"),
        ({"bonds": [[0, 1, np.nan]]}, "finite"),
        ({"bonds": [[0, 1]]}, "shape"),  # no length
        ({}, "not given"),
        ({"bonds": good, "angles": good}, "no table `angles`"),
        ({"bonds": [["a", "b", "c"]]}, "real numbers"),
    ]
    for tables, message in cases:
        with pytest.raises(geoshake.InvalidInputError, match=message):
            water.system(masses, tables, h=1.0)
    with pytest.raises(geoshake.InvalidInputError):
        water.system([MO, -1.0, MH], {"bonds": good}, h=1.0)
    with pytest.raises(geoshake.InvalidInputError, match="method"):
        water.system(masses, {"bonds": good}, h=1.0, method="verlet")
    with pytest.raises(geoshake.InvalidInputError):
        water.system(masses, {"bonds": good}, h=1.0, tolerance=1e-20)
    # The error is the package's: a subclass of its base class.
    assert issubclass(geoshake.InvalidInputError, geoshake.ShakeError)


def test_states_of_the_wrong_shape_raise_invalid_input(box):
    rattle, masses, rows, q, p = box
    with pytest.raises(geoshake.InvalidInputError, match="shape"):
        rattle.project(q[:-1], p[:-1])
    with pytest.raises(geoshake.InvalidInputError, match="shape"):
        rattle.run(q.ravel(), p.ravel(), 10)


def test_a_nan_start_returns_the_error_with_the_run_so_far(box):
    rattle, masses, rows, q, p = box
    q0, p0 = rattle.project(q, p)
    bad = q0.copy()
    bad[7, 1] = np.nan
    run = rattle.run(bad, p0, 10)
    assert isinstance(run.error, geoshake.NonFiniteError)
    assert run.error.step == 0
    # Refused before the first step: no frame was computed.
    assert run.q.shape == run.p.shape == (0, 192, 3)
    assert len(run) == len(run.time) == len(run.step) == 0
    with pytest.raises(geoshake.NonFiniteError):
        rattle.step(bad, p0)
    with pytest.raises(geoshake.NonFiniteError):
        rattle.project(bad, p0)


def test_a_run_failing_midway_keeps_its_frames(water):
    """A free particle (in no table) thrown at 10³⁰⁷: its position leaves
    f64's range after about 18 steps, and the step that makes it infinite
    fails; the frames before it are returned, equal to those of a run that
    stops in time."""
    masses, rows, q, p = water_box(side=2)
    q, p = water.system(masses, {"bonds": rows}, h=1.0).project(q, p)
    masses = np.append(masses, 1.0)
    q0 = np.vstack([q, [0.0, 0.0, 0.0]])
    p0 = np.vstack([p, [1e307, 0.0, 0.0]])
    rattle = water.system(masses, {"bonds": rows}, h=1.0)
    run = rattle.run(q0, p0, 100)
    assert isinstance(run.error, geoshake.NonFiniteError)
    failed = run.error.step
    assert 10 < failed < 100
    assert len(run) == failed
    np.testing.assert_array_equal(run.step, np.arange(failed))
    assert np.isfinite(run.q).all()
    assert relative_bond_errors(run.q, rows).max() <= 1e-10
    short = rattle.run(q0, p0, failed - 1)
    assert short.error is None
    np.testing.assert_array_equal(short.q, run.q)
    np.testing.assert_array_equal(short.p, run.p)


SPRING_CHAIN = """struct SpringChain {
    parameters { stiffness }
    particles x[3];
    potential {
        spring[k in springs(a, b; rest)]: stiffness / 2 * (norm(x[a] - x[b]) - rest)^2,
    }
    constraints {
        link[k in links(a, b; length)]: norm2(x[a] - x[b]) - length^2,
    }
}"""


def test_a_chain_with_a_potential_family_conserves_its_energy():
    """Rigid links and springs between next-nearest neighbours: the tables
    are taken by name (given here in the other order than declared), and
    H = K + V, V computed here from the rows, stays near its start
    (Störmer–Verlet: an O(h²) error, no drift)."""
    chain = geoshake.declare_particles(SPRING_CHAIN, stiffness=5.0)
    assert [f["table"] for f in chain.families] == ["springs", "links"]
    assert [f["kind"] for f in chain.families] == ["potential", "constraint"]
    n = 12
    rng = np.random.default_rng(3)
    angles = np.linspace(0, 2.0, n)
    q = np.stack([np.cos(angles), np.sin(angles), 0.1 * angles], axis=1) * 3.0
    links = np.array([[a, a + 1, np.linalg.norm(q[a + 1] - q[a])] for a in range(n - 1)])
    springs = np.array([[a, a + 2, 0.9 * np.linalg.norm(q[a + 2] - q[a])] for a in range(n - 2)])
    masses = np.ones(n)
    q0, p0 = q, rng.normal(size=(n, 3))

    def energy(rattle, qk, pk):
        a, b = springs[:, 0].astype(int), springs[:, 1].astype(int)
        r = np.linalg.norm(qk[a] - qk[b], axis=-1)
        return rattle.kinetic_energy(pk), np.sum(5.0 / 2 * (r - springs[:, 2]) ** 2)

    drift = []
    for h in (0.005, 0.0025):
        rattle = chain.system(masses, {"links": links, "springs": springs}, h=h)
        assert rattle.constraints == n - 1
        qh, ph = rattle.project(q0, p0)
        run = rattle.run(qh, ph, round(2.0 / h))
        assert run.error is None
        kv = np.array([energy(rattle, qk, pk) for qk, pk in zip(run.q, run.p)])
        e = kv.sum(axis=1)
        # The springs do work: V changes by far more than H does.
        assert np.ptp(kv[:, 1]) > 50 * np.ptp(e)
        assert relative_bond_errors(run.q, links).max() <= 1e-10
        assert relative_hidden(run.q, run.p, masses, links).max() <= 1e-10
        drift.append(np.abs(e / e[0] - 1).max())
    # Störmer–Verlet's energy error is O(h²): halving h divides it by 4
    # (a wrong gradient of the potential family would leave an O(1) error).
    assert drift[0] <= 2e-3
    assert 3.0 <= drift[0] / drift[1] <= 5.0
