"""geoshake.ase.FixBondLengths against ASE's own FixBondLengths: ASE's TIP3P
water box run with each gives the same trajectory, the minimum image of a
periodic cell is taken as ASE takes it, and ASE's machinery (copies,
slices, degrees of freedom, files) accepts it."""

import copy
import importlib.util
import pickle
from pathlib import Path

import numpy as np
import pytest

ase = pytest.importorskip(
    "ase",
    reason="ASE is not installed in this venv (shake-py/test.sh installs it with pip; "
    "without a package index it cannot): the comparisons with ASE are skipped",
)

import ase.units as units  # noqa: E402
from ase.constraints import FixBondLengths as AseFixBondLengths  # noqa: E402
from ase.md.verlet import VelocityVerlet  # noqa: E402

import geoshake  # noqa: E402
from geoshake.ase import FixBondLength, FixBondLengths  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def example():
    """examples/ase_water.py, the script that reports the comparison."""
    spec = importlib.util.spec_from_file_location("ase_water", ROOT / "examples" / "ase_water.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_tip3p_box_same_trajectory_as_ase():
    # ASE's example "Equilibrating a TIP3P water box" (Langevin at 300 K,
    # 1 fs, friction 0.01) on 2³ molecules, 100 steps from Maxwell–Boltzmann
    # momenta. ASE's loop takes about a second a step here even on so few
    # (its sweeps to 1e-13 and a find_mic per bond per sweep):
    # examples/ase_water.py runs larger boxes.
    ex = example()
    ours, ours_ms, atoms = ex.run(FixBondLengths, side=2, steps=100)
    theirs, ase_ms, _ = ex.run(AseFixBondLengths, side=2, steps=100)
    assert ours.shape == theirs.shape == (101, 24, 3)
    # Not a trajectory standing still: the atoms moved.
    assert np.abs(ours[-1] - ours[0]).max() > 0.05
    dx = np.abs(ours - theirs).max()
    print(f"8 waters, 100 steps: max |dx| = {dx:.2e} Å; ms/step ours {ours_ms:.3g}, ASE {ase_ms:.3g}")
    assert dx <= 1e-9
    assert ex.max_bond_error(atoms, ex.water_pairs(8)) < 1e-12


def straddling_box(skew=0.0):
    """ASE's box of 2³ waters shifted by part of a molecule's cell and
    wrapped: molecules cut by the cell's faces, their atoms on opposite
    sides. With `skew`, the second cell vector leans by that much along
    the first (a triclinic cell)."""
    atoms = example().water_box(2)
    atoms.calc = None
    cell = atoms.cell.array.copy()
    cell[1, 0] = skew
    atoms.set_cell(cell)
    atoms.positions += 0.25 * atoms.cell.lengths() + 0.35
    atoms.wrap()
    pairs = example().water_pairs(8)
    raw = np.array([np.linalg.norm(atoms.positions[a] - atoms.positions[b]) for a, b in pairs])
    assert (raw > 2).sum() >= 6, "too few molecules cut by the cell"
    return atoms, pairs


@pytest.mark.parametrize("skew", [0.0, 2.0])
def test_minimum_image_as_ase_takes_it(skew):
    atoms, pairs = straddling_box(skew)
    rng = np.random.default_rng(5)
    ours, theirs = FixBondLengths(pairs), AseFixBondLengths(pairs, tolerance=1e-13)
    for _ in range(3):
        new = atoms.positions + 0.02 * rng.normal(size=atoms.positions.shape)
        a, b = new.copy(), new.copy()
        ours.adjust_positions(atoms, a)
        theirs.adjust_positions(atoms, b)
        assert np.abs(a - new).max() > 1e-3
        assert np.abs(a - b).max() < 1e-11
        # Atoms keep their images: nothing jumped by a cell vector.
        assert np.abs(a - new).max() < 0.5
        p = rng.normal(size=new.shape)
        a, b = p.copy(), p.copy()
        ours.adjust_momenta(atoms, a)
        theirs.adjust_momenta(atoms, b)
        assert np.abs(a - p).max() > 1e-2
        assert np.abs(a - b).max() < 1e-10
    np.testing.assert_allclose(ours.bondlengths, theirs.bondlengths, rtol=0, atol=1e-15)


def test_velocity_verlet_across_the_cell_faces_as_ase():
    from ase.calculators.lj import LennardJones

    def run(constraint):
        atoms, pairs = straddling_box()
        atoms.calc = LennardJones(sigma=1.0, epsilon=0.005, rc=3.0, smooth=True)
        atoms.constraints = constraint(pairs, tolerance=1e-13)
        example().thermalize(atoms, seed=3)
        frames = []
        md = VelocityVerlet(atoms, 1 * units.fs)
        md.attach(lambda: frames.append(atoms.get_positions()), interval=1)
        md.run(20)
        return np.array(frames), atoms

    ours, atoms = run(FixBondLengths)
    theirs, _ = run(AseFixBondLengths)
    assert np.abs(ours[-1] - ours[0]).max() > 1e-2
    assert np.abs(ours - theirs).max() <= 1e-9
    d = np.array([atoms.get_distance(a, b, mic=True) for a, b in atoms.constraints[0].pairs])
    assert np.abs(d - atoms.constraints[0].bondlengths).max() < 1e-12


def test_ase_machinery_accepts_it():
    atoms, pairs = straddling_box()
    c = FixBondLengths(pairs)
    atoms.constraints = c
    assert isinstance(c, ase.constraints.FixConstraint)
    assert atoms.get_number_of_degrees_of_freedom() == 3 * 24 - 24
    atoms.set_momenta(np.random.default_rng(1).normal(size=(24, 3)))  # adjust_momenta
    assert c.bondlengths is not None and len(c.bondlengths) == 24
    # Copies: deep (Atoms.copy) and by the constraint's own copy().
    twin = atoms.copy()
    assert type(twin.constraints[0]) is FixBondLengths
    assert twin.constraints[0] is not c
    twin.set_positions(twin.positions + 0.01)
    assert type(c.copy()) is FixBondLengths
    np.testing.assert_array_equal(c.copy().pairs, c.pairs)
    c.maxiter = 7  # a budget set on the instance goes with its copies
    assert c.copy().maxiter == 7 and FixBondLengths(pairs).maxiter == 50
    assert pickle.loads(pickle.dumps(c)).pairs.shape == (24, 2)
    assert copy.deepcopy(c)._bonds is None
    # A slice keeps the bonds of the molecules it keeps, renumbered.
    part = atoms[3:9]
    kept = part.constraints[0]
    np.testing.assert_array_equal(kept.pairs, [[0, 1], [1, 2], [2, 0], [3, 4], [4, 5], [5, 3]])
    np.testing.assert_array_equal(kept.bondlengths, c.bondlengths[3:9])
    # ASE's file form: read back as ASE's own class, the same bonds.
    d = c.todict()
    assert d["name"] == "FixBondLengths" and d["kwargs"]["tolerance"] == 1e-13
    back = ase.constraints.dict2constraint(d)
    assert isinstance(back, AseFixBondLengths)
    np.testing.assert_array_equal(back.pairs, c.pairs)
    one = FixBondLength(0, 1)
    assert one.get_removed_dof(atoms) == 1


def test_solver_errors_name_the_bond():
    from ase import Atoms

    atoms = Atoms("H2", positions=[[0, 0, 0], [1, 0, 0]])
    c = FixBondLengths([(0, 1)])
    atoms.constraints = c
    with pytest.raises(geoshake.NewtonError) as e:
        # Stretched across the old bond: no move along it reaches 1 Å.
        atoms.set_positions([[0, 0, 0], [0.01, 1.5, 0]])
    assert isinstance(e.value, geoshake.ShakeError)
    assert (e.value.member, e.value.pair) == (0, (0, 1))
    np.testing.assert_array_equal(atoms.positions, [[0, 0, 0], [1, 0, 0]])
    with pytest.raises(geoshake.InvalidInputError, match="tol"):
        FixBondLengths([(0, 1)], tolerance=0.0).adjust_positions(atoms, atoms.get_positions())


@pytest.mark.parametrize(
    "pairs, match",
    [
        ([(0, 1), (1, 5)], "pair 1 is \\(1, 5\\)"),
        ([(0, 1), (-1, 0)], "pair 1 is \\(-1, 0\\)"),
        ([(0.5, 1.5)], "atom indices"),
        ([0, 1], "\\(m, 2\\)"),
    ],
)
def test_bad_pairs_are_the_package_error_not_numpy_indexing(pairs, match):
    # Out of range, negative, not integers, not (m, 2): refused before they
    # index the positions for the bond lengths (NumPy's IndexError, or a
    # negative index silently taken from the end).
    from ase import Atoms

    atoms = Atoms("H3", positions=[[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    c = FixBondLengths(pairs)
    new = atoms.get_positions()
    with pytest.raises(geoshake.InvalidInputError, match=match):
        c.adjust_positions(atoms, new)
    with pytest.raises(geoshake.InvalidInputError, match=match):
        c.adjust_momenta(atoms, np.zeros((3, 3)))
