from ._geoshake import (
    Bonds as Bonds,
    ComponentJumpError as ComponentJumpError,
    ConstraintForces as ConstraintForces,
    DeclarationError as DeclarationError,
    DeclaredParticles as DeclaredParticles,
    FibreJumpError as FibreJumpError,
    InvalidInputError as InvalidInputError,
    Langevin as Langevin,
    NewtonError as NewtonError,
    NondegeneracyError as NondegeneracyError,
    NonFiniteError as NonFiniteError,
    NotOnConstraintError as NotOnConstraintError,
    ParameterError as ParameterError,
    ParticleRattle as ParticleRattle,
    ParticleRun as ParticleRun,
    Result as Result,
    ShakeError as ShakeError,
    System as System,
    declare as declare,
    declare_particles as declare_particles,
    ensemble as ensemble,
    ess_bulk as ess_bulk,
    rhat as rhat,
    run as run,
    sample as sample,
)
from . import models as models
import numpy as np
import numpy.typing as npt
from typing import Any

def rattle(system: System, z0: npt.NDArray[np.float64], h: float, **kwargs: Any) -> Result: ...
def shake(system: System, z0: npt.NDArray[np.float64], h: float, **kwargs: Any) -> Result: ...
