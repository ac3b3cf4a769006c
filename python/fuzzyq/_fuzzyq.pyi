"""Type stubs of the fuzzyq extension module (checked against it with mypy.stubtest)."""

from collections.abc import Callable, Mapping, Sequence
from os import PathLike
from typing import Any, final

import numpy as np
import numpy.typing as npt
from typing_extensions import disjoint_base

__all__ = [
    "FuzzyqError",
    "ConfigError",
    "InputError",
    "InputTypeError",
    "ModelError",
    "PolicyFileError",
    "SolverError",
    "InternalError",
    "__version__",
    "Grid",
    "PointMass",
    "CallableModel",
    "ClassicModel",
    "DcMotor",
    "Pendulum",
    "CarHill",
    "Arm",
    "Solution",
    "Policy",
    "solve",
    "load",
    "collect",
    "available_kernels",
]

__version__: str

class FuzzyqError(Exception):
    """Base class of every error fuzzyq raises.

    Messages are one line and start with the argument they are about
    (``max_sweeps: expected an integer >= 0, got int -1``).
    """

class ConfigError(FuzzyqError, ValueError):
    """An invalid setting, grid or model definition."""

class InputError(FuzzyqError, ValueError):
    """An array of the wrong shape, or with values out of range."""

class InputTypeError(FuzzyqError, TypeError):
    """An argument of the wrong type or dtype."""

class ModelError(FuzzyqError, ValueError):
    """A model returned data of the wrong shape or non-finite values."""

class PolicyFileError(FuzzyqError, OSError):
    """A policy file that cannot be read or written."""

class SolverError(FuzzyqError, RuntimeError):
    """A problem the solver refuses to solve, or a run too large for the memory limit."""

class InternalError(FuzzyqError, RuntimeError):
    """A bug in fuzzyq (a Rust panic), never caused by bad input: please report it."""

@final
class Grid:
    """A fuzzy grid: triangular memberships per state variable, combined by product."""

    def __new__(cls, cores: Sequence[npt.ArrayLike]) -> Grid: ...
    @property
    def n_dims(self) -> int: ...
    @property
    def n_cores(self) -> int: ...
    @property
    def shape(self) -> tuple[int, ...]: ...
    @property
    def cores(self) -> list[npt.NDArray[np.float64]]: ...
    def memberships(
        self, x: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]: ...
    def core_state(self, index: int) -> npt.NDArray[np.float64]: ...
    def core_states(self) -> npt.NDArray[np.float64]: ...
    def interpolate(self, values: npt.ArrayLike, x: npt.ArrayLike) -> float: ...

@final
class PointMass:
    """The point-mass task of the paper's section 3.1."""

    def __new__(
        cls,
        agents: int = 2,
        *,
        mass: float = 0.5,
        sample_time: float = 0.4,
        position_limit: float = 6.0,
        velocity_limit: float = 3.0,
        force_levels: npt.ArrayLike | None = None,
        goal_radius: float = 0.1,
        goal_reward: float = 5.0,
        integrator: str = "exact",
        rk4_substeps: int = 10,
        friction: float = 1.0,
        friction_patches: Sequence[tuple[tuple[float, float], float, float]] | None = None,
        velocity_noise: float = 0.0,
    ) -> PointMass: ...
    @property
    def state_dim(self) -> int: ...
    @property
    def n_agents(self) -> int: ...
    @property
    def action_dim(self) -> int: ...
    @property
    def n_actions(self) -> int: ...
    @property
    def n_joint_actions(self) -> int: ...
    @property
    def sample_time(self) -> float: ...
    @property
    def position_limit(self) -> float: ...
    @property
    def velocity_limit(self) -> float: ...
    @property
    def goal_radius(self) -> float: ...
    @property
    def goal_reward(self) -> float: ...
    @property
    def actions(self) -> npt.NDArray[np.float64]: ...
    def joint_action(self, index: int) -> npt.NDArray[np.float64]: ...
    def joint_index(self, per_agent: Sequence[int]) -> int: ...
    def agent_indices(self, index: int) -> list[int]: ...
    def step(self, x: npt.ArrayLike, u: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
    def reward(self, x: npt.ArrayLike) -> float: ...
    def in_goal(self, x: npt.ArrayLike) -> bool: ...
    def paper_grid(self) -> Grid: ...

@final
class CallableModel:
    """A model defined by a vectorised Python function `transition(states, actions)`."""

    def __new__(
        cls,
        transition: Callable[
            [npt.NDArray[np.float64], npt.NDArray[np.float64]],
            tuple[npt.ArrayLike, npt.ArrayLike],
        ],
        *,
        state_dim: int,
        actions: Sequence[npt.ArrayLike],
        batch_size: int = 65536,
    ) -> CallableModel: ...
    @property
    def state_dim(self) -> int: ...
    @property
    def n_agents(self) -> int: ...
    @property
    def action_dim(self) -> int: ...
    @property
    def n_joint_actions(self) -> int: ...
    def joint_action(self, index: int) -> npt.NDArray[np.float64]: ...

@disjoint_base
class ClassicModel:
    """A classic benchmark (Busoniu et al. 2010): the base of DcMotor, Pendulum, CarHill, Arm."""

    @property
    def env(self) -> str: ...
    @property
    def preset(self) -> str: ...
    @property
    def gamma(self) -> float: ...
    @property
    def xi(self) -> float: ...
    def grid(self) -> Grid: ...
    @property
    def params(self) -> dict[str, Any]: ...
    @property
    def state_dim(self) -> int: ...
    @property
    def n_agents(self) -> int: ...
    @property
    def action_dim(self) -> int: ...
    @property
    def n_actions(self) -> int: ...
    @property
    def n_joint_actions(self) -> int: ...
    @property
    def action_levels(self) -> npt.NDArray[np.float64]: ...
    @property
    def actions(self) -> npt.NDArray[np.float64]: ...
    @property
    def sample_time(self) -> float: ...
    @property
    def state_bounds(self) -> npt.NDArray[np.float64]: ...
    @property
    def default_start(self) -> npt.NDArray[np.float64]: ...
    def joint_action(self, index: int) -> npt.NDArray[np.float64]: ...
    def step(
        self, x: npt.ArrayLike, u: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], float | npt.NDArray[np.float64]]: ...
    def reward(self, x: npt.ArrayLike, u: npt.ArrayLike) -> float: ...
    def is_terminal(self, x: npt.ArrayLike) -> bool: ...

# An integrator: "zoh", "rk4" (the model's default substeps; 1 for the DC motor, whose default
# is "zoh") or {"rk4": {"substeps": n}}.
_Integrator = str | dict[str, dict[str, int]]

@final
class DcMotor(ClassicModel):
    """The DC motor: state [angle, angular velocity], voltage actions."""

    def __new__(
        cls,
        preset: str = "fine",
        *,
        actions: npt.ArrayLike | None = None,
        inertia: float = ...,
        damping: float = ...,
        torque_constant: float = ...,
        resistance: float = ...,
        sample_time: float = ...,
        max_angle: float = ...,
        max_velocity: float = ...,
        q: Sequence[float] = ...,
        r: float = ...,
        integrator: _Integrator = ...,
    ) -> DcMotor: ...

@final
class Pendulum(ClassicModel):
    """The inverted pendulum swing-up: state [angle (0 = up), angular velocity]."""

    def __new__(
        cls,
        preset: str = "fine",
        *,
        actions: npt.ArrayLike | None = None,
        disc_inertia: float = ...,
        mass: float = ...,
        length: float = ...,
        gravity: float = ...,
        damping: float = ...,
        torque_constant: float = ...,
        resistance: float = ...,
        sample_time: float = ...,
        max_velocity: float = ...,
        max_voltage: float = ...,
        q: Sequence[float] = ...,
        r: float = ...,
        integrator: _Integrator = ...,
    ) -> Pendulum: ...

@final
class CarHill(ClassicModel):
    """The car on the hill: state [position, velocity], force actions."""

    def __new__(
        cls,
        preset: str = "fine",
        *,
        actions: npt.ArrayLike | None = None,
        mass: float = ...,
        gravity: float = ...,
        sample_time: float = ...,
        position_limit: float = ...,
        velocity_limit: float = ...,
        integrator: _Integrator = ...,
    ) -> CarHill: ...

@final
class Arm(ClassicModel):
    """The two-link robot arm: state [angle 1, velocity 1, angle 2, velocity 2], torques."""

    def __new__(
        cls,
        preset: str = "fine",
        *,
        actions: npt.ArrayLike | None = None,
        link_lengths: Sequence[float] = ...,
        masses: Sequence[float] = ...,
        inertias: Sequence[float] = ...,
        centres_of_mass: Sequence[float] = ...,
        damping: Sequence[float] = ...,
        max_velocity: Sequence[float] = ...,
        max_torque: Sequence[float] = ...,
        q: Sequence[float] = ...,
        r: Sequence[float] = ...,
        sample_time: float = ...,
        wrap: bool = ...,
        integrator: _Integrator = ...,
    ) -> Arm: ...

@final
class Solution:
    """The result of `solve` or `load`."""

    @property
    def V(self) -> npt.NDArray[np.float32] | npt.NDArray[np.float64]: ...
    @property
    def greedy(self) -> npt.NDArray[np.uint32]: ...
    @property
    def grid(self) -> Grid: ...
    @property
    def env(self) -> str | None: ...
    @property
    def sweeps(self) -> int: ...
    @property
    def converged(self) -> bool: ...
    @property
    def final_delta(self) -> float: ...
    @property
    def error_bound(self) -> float: ...
    @property
    def deltas(self) -> npt.NDArray[np.float64]: ...
    @property
    def seconds(self) -> float: ...
    @property
    def kernel(self) -> str: ...
    @property
    def gamma(self) -> float: ...
    @property
    def xi(self) -> float: ...
    def theta(self) -> npt.NDArray[np.float64]: ...
    def value(self, x: npt.ArrayLike) -> float: ...
    def policy(self, kind: str = "greedy") -> Policy: ...
    def save(self, path: str | PathLike[str]) -> None: ...

@final
class Policy:
    """A policy of any learner: fuzzy Q-iteration (greedy, eq 7, or interpolated, eq 22) or
    learned from samples (fuzzy Q-learning, VQQL: greedy, decentralised)."""

    @property
    def kind(self) -> str: ...
    @property
    def learner(self) -> str: ...
    @property
    def env(self) -> str | None: ...
    @property
    def gamma(self) -> float: ...
    @property
    def state_dim(self) -> int: ...
    @property
    def action_dim(self) -> int: ...
    @property
    def n_joint_actions(self) -> int: ...
    @property
    def n_agents(self) -> int: ...
    def act(self, x: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
    def act_batch(self, states: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
    def act_index(self, x: npt.ArrayLike) -> int: ...
    def agent_actions(self, x: npt.ArrayLike) -> list[int]: ...
    def q_values(self, x: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
    def value(self, x: npt.ArrayLike) -> float: ...
    def rollout(
        self,
        x0: npt.ArrayLike | None = None,
        steps: int | None = None,
        *,
        seed: int = 0,
        headings: npt.ArrayLike | None = None,
        plant: str | None = None,
        radius: float | None = None,
    ) -> dict[str, Any]: ...

def solve(
    model: PointMass | ClassicModel | CallableModel,
    grid: Grid,
    *,
    gamma: float | None = None,
    xi: float | None = None,
    max_sweeps: int = 1000,
    sweep: str = "sync",
    extrapolate: bool | None = None,
    evaluation_sweeps: int | None = None,
    absorbing_goal: bool = False,
    precision: str | None = None,
    backup: str = "auto",
    kernel: str | None = None,
    operator: str = "values",
    threads: int | None = None,
    callback: Callable[[dict[str, Any]], object] | None = None,
    transitions: Mapping[str, npt.ArrayLike] | None = None,
    max_memory_gb: float | None = None,
) -> Solution: ...
def collect(
    model: PointMass | ClassicModel,
    samples: int,
    *,
    seed: int = 0,
    episode_steps: int = 50,
) -> dict[str, npt.NDArray[np.float64]]: ...
def load(path: str | PathLike[str]) -> Solution | Policy:
    """Reads a policy file of any kind: a Solution (fuzzy Q-iteration) or a Policy (learned
    from samples: fuzzy Q-learning, VQQL)."""

def available_kernels() -> list[str]: ...
