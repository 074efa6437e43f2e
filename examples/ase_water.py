"""ASE's TIP3P water box, run with ASE's FixBondLengths and with geoshake's.

    python examples/ase_water.py [--side 4] [--steps 100] [--dynamics langevin]

Builds the box of ASE's example "Equilibrating a TIP3P water box" (rigid
TIP3P waters on a cubic lattice at 0.9982 g/cm³, side³ molecules, periodic,
ase.calculators.tip3p.TIP3P with rc = 4.5 Å, three bonds per molecule) and
runs it twice from the same start with the same random numbers: once with
ase.constraints.FixBondLengths (tolerance 1e-13) and once with
geoshake.ase.FixBondLengths. It times every call of the constraints
(adjust_positions and adjust_momenta) in both runs, compares the positions
after every step, and ends with one line:

    ase n=<molecules> steps=… ours_ms_per_step=… ase_ms_per_step=… speedup=… max_dx=<Å> …

Needs ASE (pip install ase) and geoshake (bash shake-py/test.sh builds it).
"""

import argparse
import time

import numpy as np


def water_box(side):
    """ASE's TIP3P box of side³ molecules (its example uses side 3). The
    Coulomb cut-off is the example's 4.5 Å, or half the box when that is
    smaller (TIP3P refuses a cut-off beyond half the box)."""
    from ase import Atoms
    from ase.calculators.tip3p import TIP3P, angleHOH, rOH

    x = angleHOH * np.pi / 180 / 2
    pos = [
        [0, 0, 0],
        [0, rOH * np.cos(x), rOH * np.sin(x)],
        [0, rOH * np.cos(x), -rOH * np.sin(x)],
    ]
    atoms = Atoms("OH2", positions=pos)
    vol = ((18.01528 / 6.022140857e23) / (0.9982 / 1e24)) ** (1 / 3.0)
    atoms.set_cell((vol, vol, vol))
    atoms.center()
    atoms = atoms.repeat((side, side, side))
    atoms.set_pbc(True)
    atoms.calc = TIP3P(rc=min(4.5, 0.5 * side * vol))
    return atoms


def thermalize(atoms, seed, kelvin=300):
    """Maxwell–Boltzmann momenta, projected by the atoms' constraints
    (ASE's set_momenta calls their adjust_momenta)."""
    try:
        from ase.md.velocitydistribution import thermalize_momenta
    except ImportError:  # ASE before 3.29
        from ase.md.velocitydistribution import MaxwellBoltzmannDistribution as thermalize_momenta
    thermalize_momenta(atoms, temperature_K=kelvin, rng=np.random.default_rng(seed))


def water_pairs(molecules):
    """O–H1, H1–H2, H2–O of every molecule, as in ASE's example."""
    return [(3 * i + j, 3 * i + (j + 1) % 3) for i in range(molecules) for j in range(3)]


class Timed:
    """Adds the wall time of a constraint's adjust_positions and
    adjust_momenta calls to ``seconds`` (the constraint is changed in
    place: its methods are wrapped on the instance)."""

    def __init__(self, constraint):
        self.seconds = 0.0
        self.calls = 0
        for name in ("adjust_positions", "adjust_momenta"):
            method = getattr(constraint, name)

            def timed(*args, _method=method):
                t = time.perf_counter()
                try:
                    return _method(*args)
                finally:
                    self.seconds += time.perf_counter() - t
                    self.calls += 1

            setattr(constraint, name, timed)


def run(constraint_class, side=3, steps=100, dynamics="langevin", seed=42):
    """One run from ASE's box: Maxwell–Boltzmann momenta at 300 K, then
    `steps` steps of 1 fs of Langevin (300 K, friction 0.01, ASE's example)
    or velocity Verlet. Returns the positions at the start and after every
    step, the constraints' time per step in ms, and the atoms."""
    import ase.units as units
    from ase.md.langevin import Langevin
    from ase.md.verlet import VelocityVerlet

    atoms = water_box(side)
    constraint = constraint_class(water_pairs(len(atoms) // 3), tolerance=1e-13)
    atoms.constraints = constraint
    thermalize(atoms, seed)
    if dynamics == "langevin":
        md = Langevin(
            atoms,
            1 * units.fs,
            temperature_K=300,
            friction=0.01,
            fixcm=False,
            rng=np.random.default_rng(seed + 1),
        )
    else:
        md = VelocityVerlet(atoms, 1 * units.fs)
    clock = Timed(constraint)
    # (Observers are called at the start too: steps + 1 frames.)
    frames = []
    md.attach(lambda: frames.append(atoms.get_positions()), interval=1)
    md.run(steps)
    return np.array(frames), 1e3 * clock.seconds / steps, atoms


def max_bond_error(atoms, pairs):
    """The largest relative deviation of a bond from its length at the
    start (minimum image)."""
    pairs = np.asarray(pairs)
    d = atoms.get_distances  # per-pair minimum-image distances
    lengths = np.array([d(a, [b], mic=True)[0] for a, b in pairs])
    from ase.calculators.tip3p import angleHOH, rOH

    hh = 2 * rOH * np.sin(angleHOH * np.pi / 180 / 2)
    want = np.where(np.arange(len(pairs)) % 3 == 1, hh, rOH)
    return float(np.max(np.abs(lengths - want) / want))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--side", type=int, default=4, help="side³ molecules (ASE's example: 3)")
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--dynamics", choices=["langevin", "verlet"], default="langevin")
    args = parser.parse_args(argv)

    from ase.constraints import FixBondLengths as AseFixBondLengths

    from geoshake.ase import FixBondLengths

    ours, ours_ms, atoms = run(FixBondLengths, args.side, args.steps, args.dynamics)
    theirs, ase_ms, _ = run(AseFixBondLengths, args.side, args.steps, args.dynamics)
    dx = np.abs(ours - theirs).max(axis=(1, 2))
    for k in range(0, args.steps + 1, max(1, args.steps // 10)):
        print(f"step {k:5d}  max |x_ours - x_ase| = {dx[k]:.2e} Å")
    molecules = len(atoms) // 3
    bond_error = max_bond_error(atoms, water_pairs(molecules))
    print(
        f"ase n={molecules} steps={args.steps} ours_ms_per_step={ours_ms:.4g} "
        f"ase_ms_per_step={ase_ms:.4g} speedup={ase_ms / ours_ms:.4g} max_dx={dx.max():.3g} "
        f"atoms={len(atoms)} bonds={3 * molecules} dynamics={args.dynamics} "
        f"max_rel_bond_error={bond_error:.2g}"
    )
    return dx.max()


if __name__ == "__main__":
    main()
