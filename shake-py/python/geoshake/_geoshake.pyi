"""Type stubs of the Rust extension ``geoshake._geoshake``."""

from typing import Any, Callable, Literal, Optional, TypedDict, Union

import numpy as np
import numpy.typing as npt

Base = Literal["midpoint", "verlet", "euler"]
Method = Literal["rattle", "shake"]

class ShakeError(Exception):
    """Every error of shake. A run's errors carry the step, time and
    residual (NaN when the error has none) and the partial trajectory."""

    step: int
    time: float
    residual: float
    trajectory: npt.NDArray[np.float64]
    times: npt.NDArray[np.float64]
    steps: npt.NDArray[np.uint64]
    lambda_: npt.NDArray[np.float64]
    sigma: npt.NDArray[np.float64]

class DeclarationError(ShakeError):
    """A declaration refused, with the macro's message and its position
    (None for a particle family of a shape the runtime has no stencil for)."""

    message: str
    line: Optional[int]
    column: Optional[int]

class ParameterError(ShakeError): ...
class InvalidInputError(ShakeError): ...
class NonFiniteError(ShakeError): ...
class NewtonError(ShakeError): ...
class NondegeneracyError(ShakeError): ...
class ComponentJumpError(ShakeError): ...
class FibreJumpError(ShakeError): ...
class NotOnConstraintError(ShakeError): ...

class System:
    """A constrained Hamiltonian system, declared or compiled."""

    @property
    def dof(self) -> int: ...
    @property
    def constraint_count(self) -> int: ...
    @property
    def name(self) -> str: ...
    @property
    def kind(self) -> Literal["none", "holonomic", "quadratic", "general"]: ...
    @property
    def compiled(self) -> bool: ...
    @property
    def parameters(self) -> dict[str, float]: ...
    @property
    def constraint_names(self) -> list[str]: ...
    @property
    def variable_names(self) -> list[str]: ...
    def hamiltonian(self, z: npt.ArrayLike) -> float: ...
    def constraints(self, z: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
    def hidden_constraints(self, z: npt.ArrayLike) -> npt.NDArray[np.float64]: ...

class Result:
    """A run: states (n, 2d), times (n,), steps (n,), λ and σ (n, m)."""

    trajectory: npt.NDArray[np.float64]
    times: npt.NDArray[np.float64]
    steps: npt.NDArray[np.uint64]
    lambda_: npt.NDArray[np.float64]
    sigma: npt.NDArray[np.float64]
    def __len__(self) -> int: ...

class Bonds:
    """Distance constraints |x_a − x_b| = l between atoms in R³, solved in
    place on (n, 3) float64 arrays: SHAKE's position stage and RATTLE's
    velocity stage. Errors carry ``member``, the row of the bond at fault
    (None when no bond is)."""

    def __init__(
        self,
        masses: npt.ArrayLike,
        pairs: npt.ArrayLike,
        lengths: npt.ArrayLike,
        *,
        tolerance: float = 1e-13,
        max_iterations: int = 50,
    ) -> None: ...
    def shake_positions(self, q0: npt.ArrayLike, x: npt.NDArray[np.float64]) -> float: ...
    def project_momenta(self, q: npt.ArrayLike, p: npt.NDArray[np.float64]) -> float: ...
    @property
    def atoms(self) -> int: ...
    @property
    def solver(self) -> Literal["clusters", "band", "sparse"]: ...
    def __len__(self) -> int: ...

class FamilyInfo(TypedDict):
    name: str
    kind: Literal["constraint", "potential"]
    table: str
    arity: int
    data: int

class DeclaredParticles:
    """A particle system declared from a string: its families and the
    tables they read."""

    @property
    def name(self) -> str: ...
    @property
    def dim(self) -> int: ...
    @property
    def parameters(self) -> dict[str, float]: ...
    @property
    def families(self) -> list[FamilyInfo]: ...
    def system(
        self,
        masses: npt.ArrayLike,
        tables: dict[str, npt.ArrayLike],
        h: float,
        *,
        method: Method = "rattle",
        tolerance: Optional[float] = None,
        max_iterations: Optional[int] = None,
        forces: Optional[Forces] = None,
        thermostat: Optional[Langevin] = None,
    ) -> ParticleRattle: ...

Forces = Callable[[npt.NDArray[np.float64]], tuple[float, npt.ArrayLike]]
"""``forces(q) -> (V, F)``: q of shape (n, D), V = V_ext(q), F = −∇V_ext(q)
of shape (n, D)."""

class Langevin:
    """A Langevin thermostat, dp = −∇V dt − γ p dt + √(2 γ k_B T) M^{1/2} dW,
    integrated by g-BAOAB with RATTLE's drifts (``substeps`` per drift)."""

    def __init__(
        self, friction: float, kT: float, seed: Optional[int] = None, *, substeps: Optional[int] = None
    ) -> None: ...
    @property
    def friction(self) -> float: ...
    @property
    def kT(self) -> float: ...
    @property
    def seed(self) -> int: ...
    @property
    def substeps(self) -> int: ...
    def member(self, i: int) -> Langevin: ...

class ConstraintForces:
    """The constraint forces f_c = −Σ_k Λ_k ∇g_k(q0) of the step that made
    a state (acting at its start q0, at ``time``), their multipliers Λ and
    their virial W = Σ_a x_a ⊗ f_{c,a}."""

    forces: npt.NDArray[np.float64]
    virial: npt.NDArray[np.float64]
    multipliers: npt.NDArray[np.float64]
    time: float

class ParticleRun:
    """A particle run: q and p of shape (frames, n, D), time and step of
    shape (frames,), and the error that ended it early (None if none)."""

    q: npt.NDArray[np.float64]
    p: npt.NDArray[np.float64]
    time: npt.NDArray[np.float64]
    step: npt.NDArray[np.uint64]
    error: Optional[BaseException]
    """None, a ``ShakeError``, or the exception the forces callable raised."""
    def __len__(self) -> int: ...

class ParticleRattle:
    """RATTLE or SHAKE on a declared particle system, on (n, D) arrays."""

    def project(
        self, q: npt.ArrayLike, p: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
    def step(
        self, q: npt.ArrayLike, p: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
    def run(
        self,
        q: npt.ArrayLike,
        p: npt.ArrayLike,
        steps: int,
        *,
        stride: int = 1,
        t0: float = 0.0,
    ) -> ParticleRun: ...
    def ensemble(
        self,
        qs: npt.ArrayLike,
        ps: npt.ArrayLike,
        steps: int,
        *,
        stride: int = 1,
        t0: float = 0.0,
    ) -> list[ParticleRun]: ...
    def kinetic_energy(self, p: npt.ArrayLike) -> float: ...
    def potential_energy(self, q: npt.ArrayLike) -> float: ...
    def constraint_forces(self, q: npt.ArrayLike, p: npt.ArrayLike) -> ConstraintForces: ...
    @property
    def thermostat(self) -> Optional[Langevin]: ...
    @property
    def particles(self) -> int: ...
    @property
    def dim(self) -> int: ...
    @property
    def constraints(self) -> int: ...
    @property
    def h(self) -> float: ...
    @property
    def solver(self) -> Literal["clusters", "band", "sparse"]: ...

def declare(source: str, **parameters: float) -> System: ...
def declare_particles(source: str, **parameters: float) -> DeclaredParticles: ...
def model(name: str, **parameters: float) -> System: ...
def model_names() -> list[tuple[str, list[str]]]: ...
def run(
    system: System,
    z0: npt.ArrayLike,
    h: float,
    *,
    steps: Optional[int] = None,
    time: Optional[float] = None,
    method: Method = "rattle",
    base: Base = "midpoint",
    stride: int = 1,
    project: bool = True,
    multipliers: bool = True,
    constraint_tolerance: Optional[float] = None,
    newton_tolerance: Optional[float] = None,
    max_iterations: Optional[int] = None,
) -> Result: ...
def ensemble(
    system: System,
    z0s: npt.ArrayLike,
    h: float,
    *,
    steps: Optional[int] = None,
    time: Optional[float] = None,
    method: Method = "rattle",
    base: Base = "midpoint",
    stride: int = 1,
    project: bool = True,
    multipliers: bool = True,
    constraint_tolerance: Optional[float] = None,
    newton_tolerance: Optional[float] = None,
    max_iterations: Optional[int] = None,
    errors: Literal["raise", "return"] = "raise",
) -> list[Union[Result, ShakeError]]: ...

def sample(
    system: System,
    q0: npt.ArrayLike,
    *,
    chains: int = 4,
    draws: int = 1000,
    warmup: int = 1000,
    steps: int = 10,
    max_tree_depth: Optional[int] = None,
    step_size: float = 0.1,
    target_acceptance: Optional[float] = 0.8,
    target_failure_rate: float = 0.01,
    step_size_jitter: float = 0.2,
    reverse_tolerance: float = 1e-8,
    seed: int = 0,
    density: Literal["hausdorff", "ambient"] = "hausdorff",
    newton_tolerance: Optional[float] = None,
) -> dict[str, npt.NDArray[Any]]: ...
def ess_bulk(x: npt.ArrayLike) -> float: ...
def rhat(x: npt.ArrayLike) -> float: ...
