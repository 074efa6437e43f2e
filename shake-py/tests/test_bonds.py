"""geoshake.Bonds: distance constraints solved in place on (n, 3) arrays,
checked from the conditions that define the results, and its refusals."""

import numpy as np
import pytest

import geoshake


def water(n, seed=1):
    """n rigid waters (O–H 0.9572 Å, H–O–H 104.52°) on a line, 3 Å apart,
    random orientations: masses, pairs, lengths, positions."""
    rng = np.random.default_rng(seed)
    r, theta = 0.9572, np.radians(104.52)
    local = np.array(
        [[0, 0, 0], [r, 0, 0], [r * np.cos(theta), r * np.sin(theta), 0]]
    )
    q = []
    for m in range(n):
        a, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        q.append(local @ a.T + [3.0 * m, 0.0, 0.0])
    q = np.concatenate(q)
    masses = np.tile([15.999, 1.008, 1.008], n)
    pairs = np.array([(3 * m + i, 3 * m + (i + 1) % 3) for m in range(n) for i in range(3)])
    d = q[pairs[:, 1]] - q[pairs[:, 0]]
    return masses, pairs, np.sqrt((d**2).sum(1)), q


def bond_errors(pairs, lengths, x):
    d = x[pairs[:, 1]] - x[pairs[:, 0]]
    return np.abs(np.sqrt((d**2).sum(1)) - lengths) / lengths


def assert_internal(q, dp, force, torque):
    """Per molecule of three atoms, the changes dp exert no net force and
    no torque about the origin at the positions q."""
    for m in range(len(q) // 3):
        s = slice(3 * m, 3 * m + 3)
        assert np.abs(dp[s].sum(0)).max() < force
        assert np.abs(np.cross(q[s], dp[s]).sum(0)).max() < torque


def test_shake_positions_moves_along_the_old_bonds_to_the_lengths():
    masses, pairs, lengths, q0 = water(10)
    bonds = geoshake.Bonds(masses, pairs, lengths, tolerance=1e-13)
    assert (len(bonds), bonds.atoms, bonds.solver) == (30, 30, "clusters")
    rng = np.random.default_rng(2)
    kicked = q0 + 0.03 * rng.normal(size=q0.shape)
    x = kicked.copy()
    residual = bonds.shake_positions(q0, x)
    assert residual <= 1e-13
    assert bond_errors(pairs, lengths, x).max() <= 2e-13
    # Forces along the bonds at q0 carry no net force and no torque per
    # molecule: with the 3 lengths that fixes all 9 coordinates.
    dp = masses[:, None] * (x - kicked)
    assert np.abs(dp).max() > 1e-3
    assert_internal(q0, dp, 1e-13, 1e-12)


def test_project_momenta_leaves_every_bond_rigid():
    masses, pairs, lengths, q = water(10)
    bonds = geoshake.Bonds(masses, pairs, lengths)
    p_in = np.random.default_rng(3).normal(size=q.shape)
    p = p_in.copy()
    hidden = bonds.project_momenta(q, p)
    assert hidden < 1e-13
    v = p / masses[:, None]
    r = q[pairs[:, 1]] - q[pairs[:, 0]]
    assert np.abs(((v[pairs[:, 1]] - v[pairs[:, 0]]) * r).sum(1)).max() < 1e-13
    # Idempotent, and the change is internal: no net force, no torque.
    again = p.copy()
    bonds.project_momenta(q, again)
    assert np.abs(again - p).max() < 1e-14
    assert_internal(q, p - p_in, 1e-14, 1e-12)


def test_inputs_that_are_not_float64_are_read_outputs_must_be():
    masses, pairs, lengths, q0 = water(2)
    bonds = geoshake.Bonds(list(masses), pairs.tolist(), list(lengths))
    x = q0 + 0.01
    bonds.shake_positions(q0.tolist(), x)  # a list for the read-only input
    assert bond_errors(pairs, lengths, x).max() <= 2e-13
    for bad in [q0.astype(np.float32), np.asfortranarray(q0), q0[:, :2], q0.tolist()]:
        with pytest.raises(geoshake.InvalidInputError, match="in place"):
            bonds.shake_positions(q0, bad)
    with pytest.raises(geoshake.InvalidInputError, match="same array"):
        bonds.shake_positions(x, x)
    with pytest.raises(geoshake.InvalidInputError, match=r"shape \(6, 3\)"):
        bonds.project_momenta(q0[:5], np.zeros((6, 3)))


def test_bad_numbers_raise_typed_errors_and_change_nothing():
    masses, pairs, lengths, q0 = water(2)
    bonds = geoshake.Bonds(masses, pairs, lengths)
    x = q0 + 0.01
    before = x.copy()
    bad = q0.copy()
    bad[1, 2] = np.nan
    with pytest.raises(geoshake.NonFiniteError) as e:
        bonds.shake_positions(bad, x)
    assert "entry 5" in str(e.value) and e.value.member is None and e.value.family is None
    np.testing.assert_array_equal(x, before)
    p = np.ones_like(q0)
    p[0, 0] = np.inf
    with pytest.raises(geoshake.NonFiniteError):
        bonds.project_momenta(q0, p)
    # A bond that no move along the old bond can bring to its length:
    # stretched across the old bond direction.
    dimer = geoshake.Bonds([1.0, 3.0], [(0, 1)], [1.0])
    q0 = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    x = np.array([[0.0, 0.0, 0.0], [0.01, 1.5, 0.0]])
    with pytest.raises(geoshake.NewtonError) as e:
        dimer.shake_positions(q0, x)
    assert isinstance(e.value, geoshake.ShakeError) and (e.value.family, e.value.member) == ("bond", 0)
    np.testing.assert_array_equal(x, [[0.0, 0.0, 0.0], [0.01, 1.5, 0.0]])


@pytest.mark.parametrize(
    "args, kwargs, match",
    [
        (([1.0, 1.0], [(0, 2)], [1.0]), {}, "does not exist"),
        (([1.0, 1.0], [(0, 0)], [1.0]), {}, "family `bond`, member 0: particle 0 appears twice"),
        (([1.0, 1.0], [(0, 1), (1, 0)], [1.0, 1.0]), {}, "same constraint"),
        (([1.0, 1.0], [(0, -1)], [1.0]), {}, "non-negative"),
        (([1.0, -1.0], [(0, 1)], [1.0]), {}, "positive"),
        (([1.0, 1.0], [(0, 1)], [0.0]), {}, "positive"),
        (([1.0, 1.0], [(0, 1)], [1.0, 2.0]), {}, "1 pairs but 2 lengths"),
        (([1.0, 1.0], [(0, 1)], [1.0]), {"tolerance": 1e-17}, "tol"),
        (([1.0, 1.0], [(0, 1)], [1.0]), {"max_iterations": 0}, "max_iter"),
        (([1.0, 1.0], [(0, 1)], [1.0]), {"max_iterations": -1}, "`max_iterations` = -1"),
        # Every pair of 8 atoms: 28 bonds on 24 coordinates.
        (
            ([1.0] * 8, [(a, b) for a in range(8) for b in range(a)], [1.0] * 28),
            {},
            "more constraints than coordinates",
        ),
    ],
)
def test_bad_topologies_and_options_are_refused(args, kwargs, match):
    with pytest.raises(geoshake.InvalidInputError, match=match):
        geoshake.Bonds(*args, **kwargs)
