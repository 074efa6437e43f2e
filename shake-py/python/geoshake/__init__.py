"""Geometric SHAKE and RATTLE for constrained Hamiltonian systems.

Declare a system as a string in the grammar of the Rust macro
``constrained_system!`` (checked exactly as the macro checks it: coisotropy
and nondegeneracy, the paper's Sections 3.2 and 5.2), or take a compiled one
from :mod:`geoshake.models`, and integrate it::

    import numpy as np
    import geoshake

    pendulum = geoshake.declare('''
        struct Pendulum {
            parameters { length, gravity }
            dof q[2], p[2];
            hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
            constraints { rod: q[0]^2 + q[1]^2 - length^2 }
        }''', length=1.0, gravity=9.81)
    out = geoshake.rattle(pendulum, np.array([1.0, 0.0, 0.0, 0.0]), h=0.01, steps=1000)
    out.trajectory   # (1001, 4): q then p
    out.lambda_      # (1001, 1): the multipliers

Constrained Hamiltonian Monte Carlo on M for a system H = |p|²/2 + U(q)
with holonomic constraints: ``geoshake.sample(system, q0, chains=4,
draws=1000)`` returns the draws as arrays of shape (chains, draws, d).

Particle systems (molecular dynamics: constraint families over run-time
tables) are declared with ``geoshake.declare_particles(source)`` and run on
arrays of shape (n, D) by ``.system(masses, {table: rows}, h)``, with
forces from a Python callable (``forces=``), a Langevin thermostat
(``thermostat=geoshake.Langevin(friction, kT, seed)``), the constraint
forces and virial of a step, and ensembles of states run in parallel.

Every failure is a subclass of :class:`ShakeError`; a failed run's error
carries ``step``, ``time``, ``residual`` and the partial trajectory.
"""

from ._geoshake import (
    Bonds,
    ComponentJumpError,
    ConstraintForces,
    DeclarationError,
    DeclaredParticles,
    FibreJumpError,
    InvalidInputError,
    Langevin,
    NewtonError,
    NondegeneracyError,
    NonFiniteError,
    NotOnConstraintError,
    ParameterError,
    ParticleRattle,
    ParticleRun,
    Result,
    ShakeError,
    System,
    declare,
    declare_particles,
    ensemble,
    ess_bulk,
    rhat,
    run,
    sample,
)
from . import models

__all__ = [
    "Bonds",
    "ComponentJumpError",
    "ConstraintForces",
    "DeclarationError",
    "DeclaredParticles",
    "FibreJumpError",
    "InvalidInputError",
    "Langevin",
    "NewtonError",
    "NondegeneracyError",
    "NonFiniteError",
    "NotOnConstraintError",
    "ParameterError",
    "ParticleRattle",
    "ParticleRun",
    "Result",
    "ShakeError",
    "System",
    "declare",
    "declare_particles",
    "ensemble",
    "ess_bulk",
    "models",
    "rattle",
    "rhat",
    "run",
    "sample",
    "shake",
]


def rattle(system, z0, h, **kwargs):
    """RATTLE (the state stays on M and M^H): ``run(..., method="rattle")``."""
    return run(system, z0, h, method="rattle", **kwargs)


def shake(system, z0, h, **kwargs):
    """SHAKE (the state stays on M): ``run(..., method="shake")``."""
    return run(system, z0, h, method="shake", **kwargs)
