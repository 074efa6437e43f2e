"""A drop-in for ASE's ``FixBondLengths``, solved by geoshake.

ASE's dynamics (``VelocityVerlet``, ``Langevin``, ...) move the atoms and
ask each constraint to correct them: ``adjust_positions(atoms, new)`` after
the drift, ``adjust_momenta(atoms, momenta)`` after the kick. ASE's own
``ase.constraints.FixBondLengths`` does both with a Python loop over the
bonds, sweep after sweep until every bond is within its tolerance;
:class:`FixBondLengths` here takes the same arguments and solves the same
two equations with the library's solver (Newton on each rigid molecule, or
on the coupled bond graph), to round-off::

    from ase.md.verlet import VelocityVerlet
    from geoshake.ase import FixBondLengths

    atoms.constraints = FixBondLengths([(3 * i + j, 3 * i + (j + 1) % 3)
                                        for i in range(len(atoms) // 3)
                                        for j in range(3)])
    VelocityVerlet(atoms, timestep=1.0 * units.fs).run(1000)

The equations, for bonds g_k = |x_a − x_b|² − l_k² and masses M:

- ``adjust_positions``: new ← new − M⁻¹ G(old)ᵀ ν with every bond at its
  length, moved along the bonds of the old positions (SHAKE's position
  stage, as ASE's loop converges to);
- ``adjust_momenta``: p ← p − G(q)ᵀ μ with G(q) M⁻¹ p = 0 at the current
  positions (RATTLE's velocity stage); ``adjust_forces`` does the same to
  the forces and keeps ``constraint_forces``, as ASE does.

In a periodic cell every bond is taken by the minimum image: each molecule
(connected set of bonds) is made whole, each atom shifted by a lattice
vector next to the atom it is bonded to, starting from the molecule's
lowest-numbered atom, then shifted back, so the atoms keep their images.

Errors of the solver are :class:`geoshake.ShakeError` subclasses (a Newton
failure is :class:`geoshake.NewtonError`); when a bond is at fault the
error's ``member`` is its row in ``pairs`` and ``pair`` its two atoms.
"""

import numpy as np

from ._geoshake import Bonds, InvalidInputError, ShakeError

try:  # ASE's base class when ASE is installed: ``isinstance`` checks pass.
    from ase.constraints import FixConstraint as _Base
except ImportError:  # pragma: no cover - the class works on any atoms-like object
    _Base = object

__all__ = ["FixBondLengths", "FixBondLength"]


class FixBondLengths(_Base):
    """Constant bond lengths between pairs of atoms, solved by geoshake.

    ``pairs``: (m, 2) atom indices. ``tolerance``: every bond's relative
    length error | |x_a − x_b| − l | / l at the end of ``adjust_positions``
    (ASE's criterion is the same to first order), in [4ε, 1) with ε the
    machine epsilon. ``bondlengths``: m lengths; by default the distances
    (minimum image) at the first call, as ASE does. ``iterations`` is
    accepted and ignored, as ASE does.
    """

    #: Newton iterations allowed per call (per molecule); Newton converges
    #: in a few or not at all. (ASE's ``maxiter`` counts its sweeps.)
    maxiter = 50

    def __init__(self, pairs, tolerance=1e-13, bondlengths=None, iterations=None):
        self.pairs = np.asarray(pairs)
        self.tolerance = tolerance
        self.bondlengths = bondlengths
        self._forget()

    def _forget(self):
        self._bonds = None
        self._built_for = None
        self._levels = None

    # -- what ASE asks of a constraint ------------------------------------

    def get_removed_dof(self, atoms):
        return len(self.pairs)

    def adjust_positions(self, atoms, new):
        old = atoms.positions
        bonds = self._solver(atoms)
        if bonds is None:
            return
        if np.may_share_memory(old, new):
            old = old.copy()
        shift = self._shifts(atoms, old)
        if shift is None:
            _in_place(new, lambda x: self._call(bonds.shake_positions, old, x))
        else:
            x = new + shift
            self._call(bonds.shake_positions, old + shift, x)
            new[...] = x - shift

    def adjust_momenta(self, atoms, p):
        q = atoms.positions
        bonds = self._solver(atoms)
        if bonds is None:
            return
        shift = self._shifts(atoms, q)
        if shift is not None:
            q = q + shift
        _in_place(p, lambda p: self._call(bonds.project_momenta, q, p))

    def adjust_forces(self, atoms, forces):
        self.constraint_forces = -forces
        self.adjust_momenta(atoms, forces)
        self.constraint_forces += forces

    def initialize_bond_lengths(self, atoms):
        """The distances between the pairs, by the minimum image."""
        from ase.geometry import find_mic

        pos = atoms.positions
        d = pos[self.pairs[:, 1]] - pos[self.pairs[:, 0]]
        if atoms.pbc.any():
            return find_mic(d, atoms.cell, atoms.pbc)[1]
        return np.sqrt((d**2).sum(1))

    def get_indices(self):
        return np.unique(self.pairs.ravel())

    def todict(self):
        # ASE's own form: a file written with this constraint reads back
        # as ASE's FixBondLengths, which solves the same equations.
        return {
            "name": "FixBondLengths",
            "kwargs": {"pairs": self.pairs.tolist(), "tolerance": self.tolerance},
        }

    def copy(self):
        lengths = None if self.bondlengths is None else np.array(self.bondlengths)
        c = FixBondLengths(self.pairs.copy(), self.tolerance, lengths)
        # (A budget set on this instance goes with it.)
        if "maxiter" in self.__dict__:
            c.maxiter = self.maxiter
        return c

    def index_shuffle(self, atoms, ind):
        """Renumbers the pairs for ``atoms[ind]``, keeping the bonds whose
        two atoms are both kept (and their lengths)."""
        map = np.zeros(len(atoms), int)
        map[ind] = 1
        n = map.sum()
        map[:] = -1
        map[ind] = range(n)
        pairs = map[self.pairs]
        keep = (pairs != -1).all(1)
        self.pairs = pairs[keep]
        if self.bondlengths is not None:
            self.bondlengths = np.asarray(self.bondlengths)[keep]
        self._forget()
        if len(self.pairs) == 0:
            raise IndexError("Constraint not part of slice")

    def __getstate__(self):
        # The solver is rebuilt at the next call (``copy.deepcopy`` of the
        # atoms, pickling).
        state = self.__dict__.copy()
        state.update(_bonds=None, _built_for=None, _levels=None)
        return state

    def __repr__(self):
        return f"FixBondLengths({len(self.pairs)} pairs, tolerance={self.tolerance})"

    # -- the solver --------------------------------------------------------

    def _solver(self, atoms):
        """The solver for these atoms' masses and the bonds, built at the
        first call and again whenever one of them changes."""
        if len(self.pairs) == 0:
            return None
        # Checked before the pairs index the positions (for the lengths,
        # the minimum image): a bad pair is the package's error, as in
        # Bonds, not NumPy's IndexError.
        _check_pairs(self.pairs, len(atoms))
        if self.bondlengths is None:
            self.bondlengths = self.initialize_bond_lengths(atoms)
        masses = atoms.get_masses()
        key = self._built_for
        if (
            key is None
            or key[0] != self.tolerance
            or key[1] != self.maxiter
            or not np.array_equal(key[2], masses)
            or not np.array_equal(key[3], self.pairs)
            or not np.array_equal(key[4], self.bondlengths)
        ):
            pairs = np.asarray(self.pairs, dtype=np.int64).reshape(-1, 2)
            lengths = np.asarray(self.bondlengths, dtype=float)
            self._bonds = Bonds(
                masses,
                pairs,
                lengths,
                tolerance=self.tolerance,
                max_iterations=self.maxiter,
            )
            self._levels = _tree_levels(pairs, len(masses))
            self._built_for = (
                self.tolerance,
                self.maxiter,
                masses,
                pairs.copy(),
                lengths.copy(),
            )
        return self._bonds

    def _shifts(self, atoms, positions):
        """Lattice vectors, one per atom, that make every molecule whole
        (None when none is needed): along each molecule's spanning tree,
        an atom gets its parent's shift plus the lattice vector that takes
        their bond to its minimum image."""
        pbc = atoms.pbc
        if not pbc.any() or not self._levels:
            return None
        cell = atoms.cell
        images = np.zeros((len(positions), 3))
        matrix = cell.array
        if not (matrix - np.diag(np.diag(matrix))).any():
            # ASE's own rule for such cells (``naive_find_mic``), on the
            # lattice numbers directly: a bond's fractional components
            # rounded to the nearest integer, along the periodic axes.
            lengths = np.where(pbc, np.diag(matrix), np.inf)
            for parent, child in self._levels:
                f = (positions[child] - positions[parent]) / lengths
                images[child] = images[parent] - np.floor(f + 0.5)
        else:
            from ase.geometry import find_mic

            to_fractional = np.linalg.inv(cell.complete())
            for parent, child in self._levels:
                d = positions[child] - positions[parent]
                dm = find_mic(d, cell, pbc)[0]
                images[child] = images[parent] + np.rint((dm - d) @ to_fractional)
        if not images.any():
            return None
        return images @ cell.complete()

    def _call(self, method, q, x):
        try:
            method(q, x)
        except ShakeError as e:
            member = getattr(e, "member", None)
            if member is not None:
                e.pair = tuple(int(i) for i in self.pairs[member])
            raise


def _check_pairs(pairs, atoms):
    """Refuses pairs that are not an (m, 2) array of atom indices in
    0 .. atoms − 1 with InvalidInputError."""
    pairs = np.asarray(pairs)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or pairs.dtype.kind not in "iu":
        raise InvalidInputError(
            f"pairs must be an (m, 2) array of atom indices, not shape {pairs.shape} "
            f"of dtype {pairs.dtype}"
        )
    bad = (pairs < 0) | (pairs >= atoms)
    if bad.any():
        row = int(np.argwhere(bad)[0][0])
        raise InvalidInputError(
            f"pair {row} is {tuple(int(i) for i in pairs[row])}: "
            f"atom indices must lie in 0 .. {atoms - 1}"
        )


def FixBondLength(a1, a2):
    """Fix the distance between atoms a1 and a2."""
    return FixBondLengths([(a1, a2)])


def _in_place(a, solve):
    """``solve(a)`` on ``a`` itself when the solver can change it in place
    (a writable C-contiguous float64 array), else on a copy written back."""
    if (
        isinstance(a, np.ndarray)
        and a.dtype == np.float64
        and a.flags.c_contiguous
        and a.flags.writeable
    ):
        solve(a)
    else:
        b = np.array(a, dtype=float, order="C")
        solve(b)
        a[...] = b


def _tree_levels(pairs, n):
    """The bond graph's spanning trees, one per molecule, rooted at its
    lowest-numbered atom, as (parents, children) index arrays level by
    level (the children of level k are k bonds from their root)."""
    neighbours = [[] for _ in range(n)]
    for a, b in pairs:
        neighbours[a].append(b)
        neighbours[b].append(a)
    depth = np.full(n, -1)
    parent = np.full(n, -1)
    for root in np.unique(pairs):
        if depth[root] >= 0:
            continue
        depth[root] = 0
        queue = [root]
        for a in queue:
            for b in neighbours[a]:
                if depth[b] < 0:
                    depth[b] = depth[a] + 1
                    parent[b] = a
                    queue.append(b)
    levels = []
    for k in range(1, depth.max() + 1 if len(depth) else 1):
        children = np.flatnonzero(depth == k)
        levels.append((parent[children], children))
    return levels
