"""Type stubs of the fuzzyq extension module (checked against it with mypy.stubtest).

The extension module ``fuzzyq._fuzzyq`` is written in Rust (pyo3); the package ``fuzzyq``
re-exports everything here. Every string option is typed as a ``Literal`` of the names the
extension accepts, so that a misspelt option (``policy("gredy")``) fails type checking
instead of raising `ConfigError` at run time.
"""

from collections.abc import Callable, Mapping, Sequence
from os import PathLike
from typing import Any, Literal, final, overload

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
    "Khepera",
    "KheperaPlant",
    "CallableModel",
    "ClassicModel",
    "DcMotor",
    "Pendulum",
    "CarHill",
    "Arm",
    "Solution",
    "Policy",
    "SlabProblem",
    "Task",
    "solve",
    "load",
    "collect",
    "learn_from_samples",
    "available_kernels",
    "train_sharded",
    "_restore",
    "_cli",
    "_step_batch",
]

__version__: str
"""The version of the fuzzyq package (the Rust crates' version)."""

class FuzzyqError(Exception):
    """Base class of every error fuzzyq raises.

    Messages are one line and start with the argument they are about
    (``max_sweeps: expected an integer >= 0, got int -1``).
    """

class ConfigError(FuzzyqError, ValueError):
    """An invalid setting, grid or model definition.

    A setting, parameter or model definition of the right type with a value it cannot take:
    a negative count, a non-finite number, an unknown option name, repeated actions,
    ``absorbing_goal=True`` on a model without goal states.
    """

class InputError(FuzzyqError, ValueError):
    """An array of the wrong shape, or with values out of range.

    The message names the expected shape; an index out of range raises it too.
    """

class InputTypeError(FuzzyqError, TypeError):
    """An argument of the wrong type or dtype.

    For example a string for a number, a float for a count, a list for a `Grid`.
    """

class ModelError(FuzzyqError, ValueError):
    """A model returned data of the wrong shape or non-finite values.

    Raised when a `CallableModel`'s transition function returns unusable data.
    """

class PolicyFileError(FuzzyqError, OSError):
    """A policy file that cannot be read or written.

    Truncated, corrupted or foreign files are refused with this error.
    """

class SolverError(FuzzyqError, RuntimeError):
    """A problem the solver refuses to solve, or a run too large for the memory limit.

    ``solve(..., max_memory_gb=...)`` raises it deliberately, with the estimate, before
    anything is allocated.
    """

class InternalError(FuzzyqError, RuntimeError):
    """A bug in fuzzyq (a Rust panic), never caused by bad input: please report it."""

@final
class Grid:
    """A fuzzy grid: triangular memberships per state variable, combined by product.

    Each state variable has an increasing sequence of cores; the membership of a core is 1 at
    the core and falls linearly to 0 at its neighbours, and a joint core's membership is the
    product over the variables (the memberships of a state sum to 1). Joint cores are numbered
    in row-major (C) order: ``values.reshape(grid.shape)`` views per-core values (such as
    `Solution.V`) as an array over the grid.

    Grids pickle (``pickle.dumps(grid)``).

    Args:
        cores: one increasing 1-D sequence of cores per state variable.

    Raises:
        InputTypeError: `cores` is not a sequence of 1-D arrays.
        ConfigError: cores not strictly increasing, non-finite, beyond single precision's
            range or too close to stay distinct in it, or too many joint cores.

    Example:
        ```python
        grid = fuzzyq.Grid([np.linspace(-1, 1, 21), np.linspace(-1, 1, 21)])
        grid.shape  # (21, 21)
        ```
    """

    def __new__(cls, cores: Sequence[npt.ArrayLike]) -> Grid:
        """Creates the grid of `cores` (see the class docstring)."""

    @property
    def n_dims(self) -> int:
        """Number of state variables."""

    @property
    def n_cores(self) -> int:
        """Number of joint cores: the product of the per-variable counts."""

    @property
    def shape(self) -> tuple[int, ...]:
        """Number of cores per state variable, as a tuple."""

    @property
    def cores(self) -> list[npt.NDArray[np.float64]]:
        """The cores of each state variable (copies)."""

    def memberships(
        self, x: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
        """The active cores of state `x` and their memberships.

        Args:
            x: a state, shape ``(n_dims,)``, finite.

        Returns:
            ``(indices, memberships)``: the joint indices of the cores whose membership at
            `x` is not zero, and those memberships, which sum to 1.

        Raises:
            InputError: `x` has the wrong shape or non-finite values.
        """

    def core_state(self, index: int) -> npt.NDArray[np.float64]:
        """The state at which joint core `index` has membership 1.

        Args:
            index: a joint core index, ``0 <= index < n_cores``.

        Returns:
            The core's state, shape ``(n_dims,)``.

        Raises:
            InputError: `index` is out of range.
        """

    def core_states(self) -> npt.NDArray[np.float64]:
        """Every core's state, in joint-core order.

        Returns:
            An array of shape ``(n_cores, n_dims)``.

        Raises:
            InputError: the grid has more than 2e8 values to return.
        """

    def interpolate(self, values: npt.ArrayLike, x: npt.ArrayLike) -> float:
        """The fuzzy interpolation ``sum_d mu_d(x) values[d]`` of per-core values at `x`.

        Args:
            values: one value per joint core, shape ``(n_cores,)`` (for example
                `Solution.V`).
            x: a state, shape ``(n_dims,)``.

        Returns:
            The interpolated value.

        Raises:
            InputError: `values` or `x` has the wrong shape, or `x` non-finite values.
        """

@final
class PointMass:
    """The point-mass task of the paper's section 3.1, for `agents` agents.

    Each agent is a point mass on the plane with friction, ``m s'' = -eta s' + u``; forces
    are held over each sample time, positions and velocities are clamped to their limits
    after each step. The state is ``[s1x, s1y, v1x, v1y, s2x, ...]`` (4 variables per agent);
    each agent's actions are the square of `force_levels` (``u_x`` slowest); the shared reward
    is `goal_reward` while the whole state is within `goal_radius` of the origin (evaluated at
    the current state). The defaults are the paper's task: ``m = 0.5 kg``, ``eta = 1 kg/s``,
    ``T = 0.4 s``, forces ``{-2, -0.2, 0, 0.2, 2}`` per axis (25 actions per agent), reward 5
    within 0.1 of the origin. With constant friction the dynamics separate into one
    ``(position, velocity)`` block per agent and axis, which the solver's block backup uses.

    Point masses pickle (``pickle.dumps(model)``).

    Args:
        agents: number of agents (point masses), at least 1.
        mass: mass of each point mass (kg), ``m``.
        sample_time: sample time ``T`` (s): each force is held this long.
        position_limit: positions are clamped to ``[-position_limit, position_limit]`` (m).
        velocity_limit: velocities are clamped to ``[-velocity_limit, velocity_limit]``
            (m/s).
        force_levels: the force levels of one axis (N), distinct; each agent's actions are
            every pair ``(u_x, u_y)`` of levels. None: the paper's ``[-2, -0.2, 0, 0.2, 2]``.
        goal_radius: radius of the reward region around the origin, over the whole state.
        goal_reward: the reward inside the region (0 elsewhere).
        integrator: ``"exact"`` (the exact zero-order-hold solution, for constant friction)
            or ``"rk4"`` (classical Runge-Kutta with `rk4_substeps` steps per sample time).
        rk4_substeps: RK4 steps per sample time (with ``integrator="rk4"`` or friction
            patches).
        friction: the viscous friction coefficient ``eta`` (kg/s); with `friction_patches`,
            the friction outside the patches.
        friction_patches: discs of other friction, each ``((x, y), radius, eta)``; the
            dynamics then depend on the position, are integrated with RK4 and no longer form
            blocks.
        velocity_noise: standard deviation (m/s) of the plant's zero-mean Gaussian process
            noise on every velocity per step (used by `collect` and rollouts); the model that
            is solved stays noise-free.
        reward: ``"paper"`` (the goal reward alone) or ``"shaped"``: plus the
            potential-based term ``gamma * Phi(f(x, u)) - Phi(x)`` with
            ``Phi(x) = -sum_i ||x_i||`` (each agent's distance to its goal state), which keeps
            the optimal policy (Ng, Harada and Russell 1999); the reward then depends on the
            action.
        shaping_discount: the ``gamma`` of the shaping term, in ``(0, 1]``; use the discount
            you solve or learn with (the identity needs it).

    Raises:
        ConfigError: a parameter out of range, or repeated force levels.
        InputTypeError: a parameter of the wrong type.
    """

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
        integrator: Literal["exact", "rk4"] = "exact",
        rk4_substeps: int = 10,
        friction: float = 1.0,
        friction_patches: Sequence[tuple[tuple[float, float], float, float]] | None = None,
        velocity_noise: float = 0.0,
        reward: Literal["paper", "shaped"] = "paper",
        shaping_discount: float = 0.96,
    ) -> PointMass:
        """Creates the task (see the class docstring for the arguments)."""

    @property
    def state_dim(self) -> int:
        """Length of the state vector, ``4 * agents``."""

    @property
    def n_agents(self) -> int:
        """Number of agents."""

    @property
    def action_dim(self) -> int:
        """Length of the joint action vector, ``2 * agents``."""

    @property
    def n_actions(self) -> int:
        """Actions per agent: ``len(force_levels) ** 2``."""

    @property
    def n_joint_actions(self) -> int:
        """Joint actions, ``n_actions ** agents``."""

    @property
    def sample_time(self) -> float:
        """Sample time (s)."""

    @property
    def position_limit(self) -> float:
        """Positions are clamped to ``[-position_limit, position_limit]`` (m)."""

    @property
    def velocity_limit(self) -> float:
        """Velocities are clamped to ``[-velocity_limit, velocity_limit]`` (m/s)."""

    @property
    def goal_radius(self) -> float:
        """The reward region's radius."""

    @property
    def goal_reward(self) -> float:
        """The reward inside the region."""

    @property
    def actions(self) -> npt.NDArray[np.float64]:
        """Each agent's actions, shape ``(n_actions, 2)``: forces ``(u_x, u_y)``."""

    def joint_action(self, index: int) -> npt.NDArray[np.float64]:
        """The joint action vector (all agents' forces) of joint action `index`.

        Args:
            index: a joint action index, ``0 <= index < n_joint_actions``.

        Returns:
            The forces ``[u1x, u1y, u2x, u2y, ...]``, shape ``(action_dim,)``.

        Raises:
            InputError: `index` is out of range.
        """

    def joint_index(self, per_agent: Sequence[int]) -> int:
        """The joint action index of per-agent action indices (agent 0 most significant).

        Args:
            per_agent: one action index per agent, each ``< n_actions``.

        Returns:
            The joint action index.

        Raises:
            InputError: wrong number of agents or an index out of range.
        """

    def agent_indices(self, index: int) -> list[int]:
        """The per-agent action indices of joint action `index` (the inverse of `joint_index`).

        Args:
            index: a joint action index, ``0 <= index < n_joint_actions``.

        Returns:
            One action index per agent.

        Raises:
            InputError: `index` is out of range.
        """

    def step(self, x: npt.ArrayLike, u: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The successor of state `x` under joint force vector `u` (noise-free).

        Args:
            x: a state, shape ``(state_dim,)``, or a batch, shape ``(n, state_dim)``.
            u: a joint force vector, shape ``(action_dim,)``, or a batch ``(n, action_dim)``
                with a batch of states.

        Returns:
            The next state, shape ``(state_dim,)``, or the batch ``(n, state_dim)``.

        Raises:
            InputError: wrong shapes, different batch sizes, or non-finite values.
        """

    def reward(self, x: npt.ArrayLike, u: npt.ArrayLike | None = None) -> float:
        """The reward of joint force vector `u` at state `x`.

        Args:
            x: a state, shape ``(state_dim,)``.
            u: a joint force vector, shape ``(2 * agents,)``; may be left out under the
                paper's reward, which does not depend on it.

        Returns:
            `goal_reward` if `x` is in the reward region, else 0; under ``reward="shaped"``
            plus ``gamma * Phi(f(x, u)) - Phi(x)``.

        Raises:
            InputError: `x` or `u` has the wrong shape or non-finite values, or `u` is
                missing under the shaped reward.
        """

    def in_goal(self, x: npt.ArrayLike) -> bool:
        """Whether `x` is in the reward region (``||x||_2 < goal_radius``).

        Args:
            x: a state, shape ``(state_dim,)``.

        Returns:
            True inside the region.

        Raises:
            InputError: `x` has the wrong shape or non-finite values.
        """

    def paper_grid(self) -> Grid:
        """The paper's grid for this number of agents.

        Position cores ``[-6, -3, -0.3, -0.1, 0, 0.1, 0.3, 3, 6]`` and velocity cores
        ``[-3, -1, 0, 1, 3]`` on every agent and axis: 2,025 cores for one agent, 4,100,625
        for two.

        Returns:
            The grid (three agents: 45^6 = 8.3e9 cores).
        """

@final
class CallableModel:
    """A model defined by a vectorised Python function `transition(states, actions)`.

    The solver calls `transition` once per batch of `batch_size` (core, joint action) pairs
    of the grid, on every pair, and then solves on the resulting table with the GIL
    released. `transition` receives a batch of states, shape ``(n, state_dim)``, and of joint
    action vectors, shape ``(n, action_dim)`` (float64), and returns
    ``(next_states, rewards)`` of shapes ``(n, state_dim)`` and ``(n,)``, or
    ``(next_states, rewards, terminal)`` with `terminal` a bool array of shape ``(n,)``: a
    terminal successor is worth its reward and nothing after it.

    Joint actions are numbered with agent 0 most significant: joint action ``j`` of two
    agents with ``m1`` actions for the second is ``(j // m1, j % m1)``.

    A `CallableModel` pickles with its function pickled by reference: the function must be
    importable by its qualified name (a module-level function, not a lambda or a closure).

    Args:
        transition: the vectorised transition and reward function (see above).
        state_dim: length of the state vector.
        actions: each agent's discrete actions: one array per agent, of shape
            ``(n_actions, components)``, or ``(n_actions,)`` for one component. The joint
            action vector concatenates the agents' components.
        blocks: optional independent dynamics blocks, a sequence of
            ``(state_indices, action_components)`` pairs: a partition of the state variables
            in which each group's next value depends only on the group itself and on those
            components of the joint action vector (a point mass's position and velocity on
            one axis, driven by its force on that axis). The solver then keeps per block only
            its successors at its own cores and runs the fast block backup
            (``backup="auto"`` or ``"block"``): a solve needs about the memory of the rewards,
            one value per (core, joint action) pair. The declaration is checked on every
            pair when the model is tabulated: a successor that differs from the blocks' is
            refused with a `ConfigError`. None: no blocks, the generic backup.
        batch_size: at most this many pairs per call of `transition`.

    Raises:
        InputTypeError: `transition` is not callable, or `actions` or `blocks` is not a
            sequence of the expected items.
        ConfigError: a bad `state_dim` (1 to the maximum number of dimensions),
            ``batch_size=0``, repeated or non-finite actions, no agent or too many agents or
            joint actions, or `blocks` that do not partition the state.

    Example:
        ```python
        def transition(x, u):
            pos = np.clip(x[:, 0] + 0.1 * x[:, 1], -1, 1)
            vel = np.clip(x[:, 1] + 0.1 * u[:, 0], -1, 1)
            return np.stack([pos, vel], axis=1), -x[:, 0] ** 2

        model = fuzzyq.CallableModel(transition, state_dim=2, actions=[[-1.0, 0.0, 1.0]])
        ```
    """

    def __new__(
        cls,
        transition: Callable[
            [npt.NDArray[np.float64], npt.NDArray[np.float64]],
            tuple[npt.ArrayLike, npt.ArrayLike]
            | tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike],
        ],
        *,
        state_dim: int,
        actions: Sequence[npt.ArrayLike],
        blocks: Sequence[tuple[Sequence[int], Sequence[int]]] | None = None,
        batch_size: int = 65536,
    ) -> CallableModel:
        """Creates the model (see the class docstring for the arguments)."""

    @property
    def state_dim(self) -> int:
        """Length of the state vector."""

    @property
    def n_agents(self) -> int:
        """Number of agents (one per entry of `actions`)."""

    @property
    def action_dim(self) -> int:
        """Length of the joint action vector (the agents' components, concatenated)."""

    @property
    def n_joint_actions(self) -> int:
        """Number of joint actions: the product of the agents' action counts."""

    @property
    def actions(self) -> list[npt.NDArray[np.float64]]:
        """Each agent's actions, one array of shape ``(n_actions, components)`` per agent."""

    @property
    def transition(
        self,
    ) -> Callable[
        [npt.NDArray[np.float64], npt.NDArray[np.float64]],
        tuple[npt.ArrayLike, npt.ArrayLike] | tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike],
    ]:
        """The transition function."""

    @property
    def blocks(self) -> list[tuple[list[int], list[int]]]:
        """The declared blocks, ``(state_indices, action_components)`` pairs (empty: none)."""

    def joint_action(self, index: int) -> npt.NDArray[np.float64]:
        """The joint action vector of joint action `index`.

        Args:
            index: a joint action index, ``0 <= index < n_joint_actions``.

        Returns:
            The joint action vector, shape ``(action_dim,)``.

        Raises:
            InputError: `index` is out of range.
        """

    def joint_index(self, per_agent: Sequence[int]) -> int:
        """The joint action index of per-agent action indices (agent 0 most significant).

        Args:
            per_agent: one action index per agent.

        Returns:
            The joint action index.

        Raises:
            InputError: wrong number of agents or an index out of range.
        """

    def agent_indices(self, index: int) -> list[int]:
        """The per-agent action indices of joint action `index` (the inverse of `joint_index`).

        Args:
            index: a joint action index, ``0 <= index < n_joint_actions``.

        Returns:
            One action index per agent.

        Raises:
            InputError: `index` is out of range.
        """

    def __getnewargs_ex__(self) -> tuple[tuple[Any, ...], dict[str, Any]]:
        """Pickling support: the constructor's arguments.

        Returns:
            ``((transition,), kwargs)``: the function (pickled by reference, so a
            module-level function), and the state length, the actions, the blocks and the
            batch size as keyword arguments.
        """

    def step(
        self, x: npt.ArrayLike, u: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], float, bool]:
        """One transition: calls `transition` on a batch of one.

        Args:
            x: a state, shape ``(state_dim,)``.
            u: a joint action vector, shape ``(action_dim,)``.

        Returns:
            ``(next_state, reward, terminal)``; `terminal` is False when `transition`
            returns no terminal flags.

        Raises:
            InputError: `x` or `u` has the wrong shape or non-finite values.
            ModelError: `transition` returned unusable data.
        """

@disjoint_base
class ClassicModel:
    """A classic benchmark (Busoniu et al. 2010): the base of DcMotor, Pendulum, CarHill, Arm.

    One agent; the model computes in float64. The preset names the grid, actions, `gamma` and
    `xi` of a toolbox run (`grid()`, `gamma`, `xi`): ``fuzzyq.solve(model, model.grid())``
    solves it as ``fuzzyq train --env ENV --preset PRESET`` does. The model is one dynamics
    block (the whole state and action), so the solver tabulates its transitions once.

    Classic models pickle (``pickle.dumps(model)``).
    """

    @property
    def env(self) -> Literal["dcmotor", "pendulum", "carhill", "arm"]:
        """The environment's name."""

    @property
    def preset(self) -> Literal["toolbox-demo", "fine", "coarse"]:
        """The preset's name."""

    @property
    def gamma(self) -> float:
        """The preset's discount factor (the default of `solve` for this model)."""

    @property
    def xi(self) -> float:
        """The preset's stopping threshold (the default of `solve` for this model)."""

    def grid(self) -> Grid:
        """The preset's grid.

        Returns:
            The grid of the preset's cores.
        """

    @property
    def params(self) -> dict[str, Any]:
        """The model's parameters (a configuration file's ``[env.model]`` fields), as a dict."""

    @property
    def state_dim(self) -> int:
        """Length of the state vector."""

    @property
    def n_agents(self) -> int:
        """Number of agents (1)."""

    @property
    def action_dim(self) -> int:
        """Length of an action vector (2 for the arm, 1 for the others)."""

    @property
    def n_actions(self) -> int:
        """Number of discrete actions."""

    @property
    def n_joint_actions(self) -> int:
        """Number of joint actions (the actions: one agent)."""

    @property
    def action_levels(self) -> npt.NDArray[np.float64]:
        """The listed action levels (the configuration's ``actions``).

        For the arm, torque levels as fractions of each joint's maximum torque, combined per
        joint into the action vectors.
        """

    @property
    def actions(self) -> npt.NDArray[np.float64]:
        """The discrete action vectors, shape ``(n_actions, action_dim)``."""

    @property
    def sample_time(self) -> float:
        """Sample time (s)."""

    @property
    def state_bounds(self) -> npt.NDArray[np.float64]:
        """The range ``(low, high)`` of every state variable, shape ``(state_dim, 2)``."""

    @property
    def default_start(self) -> npt.NDArray[np.float64]:
        """The default start of a rollout (``fuzzyq rollout``'s)."""

    def joint_action(self, index: int) -> npt.NDArray[np.float64]:
        """The action vector of action `index`.

        Args:
            index: an action index, ``0 <= index < n_actions``.

        Returns:
            The action vector, shape ``(action_dim,)``.

        Raises:
            InputError: `index` is out of range.
        """

    def step(
        self, x: npt.ArrayLike, u: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], float | npt.NDArray[np.float64]]:
        """The successor of state `x` under action vector `u`, and the reward of `u` at `x`.

        Args:
            x: a state, shape ``(state_dim,)``, or a batch ``(n, state_dim)``.
            u: an action vector, shape ``(action_dim,)``, or a batch ``(n, action_dim)`` with
                a batch of states.

        Returns:
            ``(next_state, reward)``, or for batches ``(next_states (n, state_dim),
            rewards (n,))``.

        Raises:
            InputError: wrong shapes, different batch sizes, or non-finite values.
        """

    def reward(self, x: npt.ArrayLike, u: npt.ArrayLike) -> float:
        """The reward of action vector `u` at state `x`.

        Args:
            x: a state, shape ``(state_dim,)``.
            u: an action vector, shape ``(action_dim,)``.

        Returns:
            The reward.

        Raises:
            InputError: wrong shapes or non-finite values.
        """

    def is_terminal(self, x: npt.ArrayLike) -> bool:
        """Whether `x` is a terminal state (the car that left the hill); a rollout stops there.

        Args:
            x: a state, shape ``(state_dim,)``.

        Returns:
            True for a terminal state (only the car on the hill has them).

        Raises:
            InputError: `x` has the wrong shape or non-finite values.
        """

    def __getnewargs_ex__(self) -> tuple[tuple[Any, ...], dict[str, Any]]:
        """Pickling support: the constructor's arguments.

        Returns:
            ``((preset,), kwargs)``: the preset's name, and the actions and every parameter
            as keyword arguments of the class.
        """

@final
class DcMotor(ClassicModel):
    """The DC motor (Busoniu et al. 2010, section 4.5.3): state ``[angle, angular velocity]``.

    ``alpha'' = -(b/J + K^2/(Re J)) alpha' + K/(Re J) u`` driven by a voltage `u`; the state
    is saturated (not wrapped) to the angle and velocity limits, and the reward is
    ``-x' Q x - r u^2`` at the current state. Every parameter is a keyword argument; left out,
    it keeps the toolbox's value (`params` lists them).

    Args:
        preset: ``"toolbox-demo"`` (the toolbox demo's 21 x 21 grid, 5 actions) or
            ``"fine"`` (its default fine grid, 73 x 193, 9 actions).
        actions: the voltage levels (V), distinct; None: the preset's.
        inertia: rotor and load inertia ``J`` (kg m^2).
        damping: viscous damping ``b`` (N m s/rad).
        torque_constant: torque constant ``K`` (N m/A).
        resistance: rotor resistance ``Re`` (Ohm).
        sample_time: sample time ``Ts`` (s).
        max_angle: the angle is saturated to ``[-max_angle, max_angle]`` (rad).
        max_velocity: the angular velocity is saturated to ``[-max_velocity, max_velocity]``
            (rad/s).
        q: the diagonal of the state weight ``Q`` of the reward.
        r: the action weight of the reward.
        integrator: ``"zoh"`` (exact zero-order hold, the default), ``"rk4"`` (RK4, one step
            per sample time) or ``{"rk4": {"substeps": n}}``.

    Raises:
        ConfigError: an unknown preset, a parameter out of range or repeated actions.
        InputTypeError: a parameter of the wrong type.
    """

    def __new__(
        cls,
        preset: Literal["toolbox-demo", "fine"] = "fine",
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
        integrator: (
            Literal["zoh", "rk4"] | Mapping[Literal["rk4"], Mapping[Literal["substeps"], int]]
        ) = ...,
    ) -> DcMotor:
        """Creates the motor (see the class docstring for the arguments)."""

@final
class Pendulum(ClassicModel):
    """The inverted pendulum swing-up: state ``[angle (0 = up), angular velocity]``.

    A weight on a DC motor's disc, driven by a voltage too weak to lift it in one go
    (Busoniu et al. 2010, section 4.5.4): the voltage is limited to `max_voltage`, the angle
    wrapped into ``[-pi, pi)``, the velocity saturated, and the reward is
    ``-x' Q x - r u^2`` at the current state. Every parameter is a keyword argument; left out,
    it keeps the toolbox's value (`params` lists them).

    Args:
        preset: ``"toolbox-demo"`` (the toolbox demo's 41 x 21 grid, 5 actions) or
            ``"fine"`` (its default fine grid, 73 x 91, 15 actions).
        actions: the voltage levels (V), distinct; None: the preset's.
        disc_inertia: inertia of the rotor and disc without the weight, ``J0`` (kg m^2).
        mass: mass of the weight ``m`` (kg).
        length: distance ``l`` of the weight from the axis (m).
        gravity: gravitational acceleration ``g`` (m/s^2).
        damping: viscous damping ``b`` (N m s/rad).
        torque_constant: torque constant ``K`` (N m/A).
        resistance: rotor resistance ``R`` (Ohm).
        sample_time: sample time ``Ts`` (s).
        max_velocity: the angular velocity is saturated to ``[-max_velocity, max_velocity]``
            (rad/s).
        max_voltage: the voltage is limited to ``[-max_voltage, max_voltage]`` (V).
        q: the diagonal of the state weight ``Q`` of the reward.
        r: the action weight of the reward.
        integrator: ``"rk4"`` (the default, RK4 with one step per sample time) or
            ``{"rk4": {"substeps": n}}``; ``"zoh"`` is refused (the model is nonlinear).

    Raises:
        ConfigError: an unknown preset, a parameter out of range or repeated actions.
        InputTypeError: a parameter of the wrong type.
    """

    def __new__(
        cls,
        preset: Literal["toolbox-demo", "fine"] = "fine",
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
        integrator: (
            Literal["zoh", "rk4"] | Mapping[Literal["rk4"], Mapping[Literal["substeps"], int]]
        ) = ...,
    ) -> Pendulum:
        """Creates the pendulum (see the class docstring for the arguments)."""

@final
class CarHill(ClassicModel):
    """The car on the hill: state ``[position, velocity]``, force actions.

    A car on the hill of Ernst et al. 2005 under a horizontal force. Successors that leave
    the box ``|p| <= 1``, ``|p'| <= 3`` are terminal: +1 at the top of the hill (``p > 1``,
    slowly enough), -1 otherwise, 0 for every regular step; terminal successors contribute no
    future value, and a rollout ends there. Every parameter is a keyword argument; left out,
    it keeps the toolbox's value (`params` lists them).

    Args:
        preset: ``"fine"`` (the toolbox's 41 x 31 grid) or ``"coarse"`` (17 x 17, for quick
            runs); both with the forces ``{-4, 4}``.
        actions: the force levels (N), distinct; None: the preset's.
        mass: mass of the car (kg).
        gravity: gravitational acceleration (m/s^2).
        sample_time: sample time (s).
        position_limit: the episode ends when ``|p|`` exceeds this (m).
        velocity_limit: the episode ends when ``|p'|`` exceeds this (m/s).
        integrator: ``"rk4"`` (RK4 with 10 steps per sample time, the default) or
            ``{"rk4": {"substeps": n}}``; ``"zoh"`` is refused (the model is nonlinear).

    Raises:
        ConfigError: an unknown preset, a parameter out of range or repeated actions.
        InputTypeError: a parameter of the wrong type.
    """

    def __new__(
        cls,
        preset: Literal["fine", "coarse"] = "fine",
        *,
        actions: npt.ArrayLike | None = None,
        mass: float = ...,
        gravity: float = ...,
        sample_time: float = ...,
        position_limit: float = ...,
        velocity_limit: float = ...,
        integrator: (
            Literal["zoh", "rk4"] | Mapping[Literal["rk4"], Mapping[Literal["substeps"], int]]
        ) = ...,
    ) -> CarHill:
        """Creates the car (see the class docstring for the arguments)."""

@final
class Arm(ClassicModel):
    """The two-link robot arm: state ``[angle 1, velocity 1, angle 2, velocity 2]``, torques.

    Two links in a horizontal plane (no gravity) under joint torques ``[tau_1, tau_2]``
    (Busoniu et al. 2010, section 4.5.2); the angles are wrapped into ``[-pi, pi)`` and the
    velocities saturated; the reward is ``-x' Q x - tau' R tau`` at the current state, so the
    goal is the stretched-out arm at rest. The action levels are fractions of each joint's
    maximum torque, combined per joint (``tau_1`` slowest). Every parameter is a keyword
    argument; left out, it keeps the toolbox's value (`params` lists them).

    Args:
        preset: ``"fine"`` (the toolbox's 13 x 7 x 13 x 7 grid) or ``"coarse"``
            (9 x 7 x 9 x 7, for quick runs); both with the levels ``[-1, 0, 1]``.
        actions: the torque levels, fractions of the maximum torques in ``[-1, 1]``,
            distinct; None: the preset's.
        link_lengths: the links' lengths (m), one per link.
        masses: the links' masses (kg).
        inertias: the links' inertias about their centres of mass (kg m^2).
        centres_of_mass: the distances of the centres of mass from the joints (m).
        damping: the joints' viscous dampings.
        max_velocity: the joints' velocity limits (rad/s).
        max_torque: the joints' torque limits (N m).
        q: the diagonal of the state weight ``Q`` of the reward.
        r: the diagonal of the torque weight ``R`` of the reward.
        sample_time: sample time (s).
        wrap: wrap the angles into ``[-pi, pi)`` (True, the default) or saturate them to
            ``[-pi, pi]``.
        integrator: ``"rk4"`` (RK4 with 5 steps per sample time, the default) or
            ``{"rk4": {"substeps": n}}``.

    Raises:
        ConfigError: an unknown preset, a parameter out of range or repeated actions.
        InputTypeError: a parameter of the wrong type.
    """

    def __new__(
        cls,
        preset: Literal["fine", "coarse"] = "fine",
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
        integrator: (
            Literal["zoh", "rk4"] | Mapping[Literal["rk4"], Mapping[Literal["substeps"], int]]
        ) = ...,
    ) -> Arm:
        """Creates the arm (see the class docstring for the arguments)."""

_EnvName = Literal["pointmass", "khepera", "dcmotor", "pendulum", "carhill", "arm"]

@final
class Solution:
    """The result of `solve` or `load`: `V`, the greedy actions, the run's record, policies.

    Solutions pickle (``pickle.dumps(solution)``; a solution of a `CallableModel` pickles its
    model's function by reference).
    """

    @property
    def V(self) -> npt.NDArray[np.float32] | npt.NDArray[np.float64]:
        """``V[d] = max_u theta[d, u]`` per core (row-major grid order), in the solver's
        precision: float32 or float64."""

    @property
    def greedy(self) -> npt.NDArray[np.uint32]:
        """The greedy joint action of every core (the lowest index among the maximisers)."""

    @property
    def grid(self) -> Grid:
        """The grid."""

    @property
    def env(self) -> _EnvName | None:
        """The environment's name, or None for a `CallableModel`."""

    @property
    def sweeps(self) -> int:
        """Sweeps performed (full backups and evaluation sweeps)."""

    @property
    def converged(self) -> bool:
        """Whether the stopping rule was met."""

    @property
    def stopped(self) -> bool:
        """Whether the `solve` callback stopped the run by returning False.

        The solution is then that of the run limited to the sweeps done, with its error bound.
        """

    @property
    def final_delta(self) -> float:
        """The exact change ``||theta_K - theta_{K-1}||_inf`` of the last sweep."""

    @property
    def error_bound(self) -> float:
        """``gamma / (1 - gamma) * final_delta``: a bound on the distance to the fixed point."""

    @property
    def deltas(self) -> npt.NDArray[np.float64]:
        """``(lower, upper)`` bounds of every sweep's change, shape ``(sweeps, 2)``."""

    @property
    def seconds(self) -> float:
        """Wall-clock seconds of the solve.

        0 for a solution loaded from a file: files keep no timings, so that the same problem
        gives the same file.
        """

    @property
    def coarse_start(self) -> dict[str, Any] | None:
        """The coarse start (``coarse_start=True``): the coarse grid's ``cores``, its
        ``sweeps`` and the ``seconds`` of its solve and interpolation.

        None for a run without one and for a solution loaded from a file.
        """

    @property
    def fit(self) -> dict[str, Any] | None:
        """How a `Task`'s model was learned from its transitions (None for every other model).

        ``samples``; ``blocks``, per block its ``state_dims`` and ``action_components``, its
        ``rows``, ``samples_per_action``, ``entries_per_row``, ``residual_rms`` per variable,
        ``under_sampled_rows`` and the first of them (``under_sampled``: rows that needed a
        wider kernel); ``reward``: None with a reward function, else ``depends_on_action``,
        ``pairs_without_samples``, ``cores_without_samples``, ``fallback`` (the lowest reward
        recorded, used where no transition reached) and ``residual_rms``.
        """

    @property
    def kernel(self) -> Literal["avx512", "avx2", "portable", "scalar", "generic", "q-values"]:
        """The kernel instance used.

        A SIMD kernel of the block backup, ``"generic"`` for the generic backup, or
        ``"q-values"`` for that operator.
        """

    @property
    def gamma(self) -> float:
        """The discount factor."""

    @property
    def xi(self) -> float:
        """The stopping threshold."""

    def theta(self) -> npt.NDArray[np.float64]:
        """The Q-value parameters ``theta[d, u]`` for every core and joint action.

        Returns:
            An array of shape ``(n_cores, n_joint_actions)``.

        Raises:
            InputError: the problem has more than 5e7 Q-values (the paper's has 2.56e9);
                use `V` and policies instead.
        """

    def value(self, x: npt.ArrayLike) -> float:
        """`V` interpolated at state `x`.

        Args:
            x: a state, shape ``(state_dim,)``.

        Returns:
            The interpolated value.

        Raises:
            InputError: `x` has the wrong shape or non-finite values.
        """

    def policy(self, kind: Literal["greedy", "interpolated"] = "greedy") -> Policy:
        """A policy of this solution.

        Args:
            kind: ``"greedy"`` (eq 7: the maximiser of ``Q(x, .)``, lowest joint index on
                ties) or ``"interpolated"`` (eq 22: the membership-weighted average of the
                active cores' greedy actions).

        Returns:
            The policy.

        Raises:
            ConfigError: an unknown `kind`.
        """

    def save(self, path: str | PathLike[str]) -> None:
        """Writes the policy file (the format ``fuzzyq rollout`` reads), atomically.

        Solutions of built-in models and of `CallableModel` can be saved; `load` reads them
        back (a `CallableModel`'s with ``load(path, model=...)``).

        Args:
            path: the file to write.

        Raises:
            PolicyFileError: the file cannot be written.
        """

@final
class Policy:
    """A policy of any learner, ready to act.

    From `Solution.policy` (fuzzy Q-iteration: greedy, eq 7, or interpolated, eq 22) or from
    `load` of a policy learned from samples (fuzzy Q-learning, VQQL: greedy, each agent
    acting on its own observation). A state `x` is what the policy acts on: the model's
    state; for fuzzy Q-iteration on the robots their poses ``[x, y, heading]`` per robot; for
    a policy learned on the robots each robot's observation
    ``[sonar_1, ..., sonar_S, goal distance, goal angle]``, concatenated.

    Policies pickle (``pickle.dumps(policy)``).
    """

    @property
    def kind(self) -> Literal["greedy", "interpolated"]:
        """``"greedy"`` or ``"interpolated"`` (a policy learned from samples is greedy)."""

    @property
    def learner(self) -> Literal["fqi", "fql", "vqql"]:
        """What learned it: ``"fqi"`` (fuzzy Q-iteration), ``"fql"`` (fuzzy Q-learning) or
        ``"vqql"``."""

    @property
    def env(self) -> _EnvName | None:
        """The environment's name, or None for a `CallableModel`."""

    @property
    def gamma(self) -> float:
        """The discount the policy was trained with."""

    @property
    def state_dim(self) -> int:
        """Length of the state (or joint observation) the policy acts on."""

    @property
    def action_dim(self) -> int:
        """Length of the joint action vector."""

    @property
    def n_joint_actions(self) -> int:
        """Number of joint actions."""

    @property
    def n_agents(self) -> int:
        """Number of agents."""

    def act(self, x: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The joint action vector at state `x`.

        The greedy joint action's vector, or the interpolated one (clamped into the action
        bounds).

        Args:
            x: a state, shape ``(state_dim,)``.

        Returns:
            The joint action vector, shape ``(action_dim,)``.

        Raises:
            InputError: `x` has the wrong shape or non-finite values.
        """

    def act_batch(self, states: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The joint action vectors at a batch of states, decided in parallel in Rust.

        The GIL is released; the result is identical to `act` state by state.

        Args:
            states: states, shape ``(n, state_dim)`` (one state ``(state_dim,)`` is a batch
                of one).

        Returns:
            The joint action vectors, shape ``(n, action_dim)``.

        Raises:
            InputError: `states` has the wrong shape or non-finite values.
        """

    @overload
    def act_index(self, x: Sequence[float]) -> int:
        """The greedy joint action index at state `x` (the lowest index on ties).

        Also batches: a batch of states gives an int64 array of indices, decided in parallel
        as by `act_batch`. The overloads type a
        list of numbers as one state (an `int`) and a list of lists as a batch (an array);
        for a numpy array, whose shape the type does not tell, the result is typed `Any`.

        Args:
            x: a state, shape ``(state_dim,)``, or a batch, shape ``(n, state_dim)``.

        Returns:
            The joint action index, or for a batch the indices, shape ``(n,)``.

        Raises:
            ConfigError: the policy is not greedy (the interpolated policy has no discrete
                actions).
            InputError: `x` has the wrong shape or non-finite values.
        """

    @overload
    def act_index(self, x: Sequence[Sequence[float]]) -> npt.NDArray[np.int64]: ...
    @overload
    def act_index(self, x: npt.NDArray[Any]) -> Any: ...

    def agent_actions(self, x: npt.ArrayLike) -> list[int]:
        """The greedy action of each agent at `x` (indices into each agent's action set).

        Args:
            x: a state, shape ``(state_dim,)``.

        Returns:
            One action index per agent.

        Raises:
            ConfigError: the policy is not greedy.
            InputError: `x` has the wrong shape or non-finite values.
        """

    def q_values(self, x: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """``Q(x, .)``, one value per joint action.

        Fuzzy Q-iteration's one-step lookahead on `V` (eq 7), or the sum of the agents'
        terms of a policy learned from samples.

        Args:
            x: a state, shape ``(state_dim,)``, or a batch, shape ``(n, state_dim)``.

        Returns:
            Shape ``(n_joint_actions,)``, or ``(n, n_joint_actions)`` for a batch.

        Raises:
            InputError: `x` has the wrong shape or non-finite values, or a policy learned
                from samples has too many joint actions to return.
        """

    def value(self, x: npt.ArrayLike) -> float:
        """The value the policy predicts at `x`.

        Args:
            x: a state, shape ``(state_dim,)``.

        Returns:
            `V` interpolated (fuzzy Q-iteration) or ``max_u Q(x, u)`` (a policy learned from
            samples).

        Raises:
            InputError: `x` has the wrong shape or non-finite values.
        """

    def predict(
        self,
        observation: npt.ArrayLike,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[npt.NDArray[Any], None]:
        """Acts with the Stable-Baselines3 convention, so that SB3-style evaluation code runs it.

        Args:
            observation: one observation, shape ``(state_dim,)``, or a batch
                ``(n, state_dim)``.
            state: a recurrent policy's state in SB3; ignored (the policy has none).
            episode_start: SB3's episode-start flags; ignored.
            deterministic: SB3's flag; the policies are deterministic either way.

        Returns:
            ``(actions, None)``: for a greedy policy joint action indices (int64, shape
            ``()`` for one observation, ``(n,)`` for a batch: the actions of a ``Discrete``
            joint action space such as `fuzzyq.envs.PointMassEnv`'s); for the interpolated
            policy joint action vectors (``(action_dim,)`` or ``(n, action_dim)``, for a
            ``Box`` space).

        Raises:
            InputError: `observation` has the wrong shape or non-finite values.
        """

    def rollout(
        self,
        x0: npt.ArrayLike | None = None,
        steps: int | None = None,
        *,
        seed: int = 0,
        headings: npt.ArrayLike | None = None,
        plant: Literal["model", "rapier"] | CallableModel | Any | None = None,
        radius: float | None = None,
        task: Task | None = None,
    ) -> dict[str, Any]:
        """Runs the policy on its environment, as ``fuzzyq rollout`` does (the same code), or
        on a system of your own given as `plant` (a `CallableModel` or a Gymnasium
        environment: then see `fuzzyq.rollout`).

        Args:
            x0: the start in the state the environment reports (default: the environment's,
                as ``fuzzyq rollout``'s): the model's state; for the robots the paper's 8-D
                state ``[s_x, s_y, v_x, v_y]`` per robot at rest (with `headings`), or their
                poses ``[x, y, heading (rad)]`` per robot.
            steps: number of steps (default: the environment's; 75 for the point masses,
                250 for the robots).
            seed: seed of the plant's noise (the robots' sensors and wheels, the point
                masses' `velocity_noise`).
            headings: the robots' initial headings in degrees (default 0); robots only.
            plant: None (the environment's own), ``"model"`` (the point masses on their
                model) or ``"rapier"`` (the point masses as colliding discs on rapier2d
                physics). The robots always run on their rapier plant, the classic benchmarks
                on their model (a run may end early at a terminal state). A `CallableModel`
                (its function as the plant, from `x0` for `steps`) or a Gymnasium environment
                (from its reset with `seed`, with `task`) runs a policy of your own system.
            radius: the discs' radius (m) with ``plant="rapier"`` for the point masses.
            task: the `Task` of a Gymnasium environment given as `plant` (its actions).

        Returns:
            A dict of numpy arrays: ``states`` (K+1, E) as ``fuzzyq rollout --csv`` writes
            them (the robots' paper state), ``actions`` (K, A), ``rewards`` (K,), ``times``
            (K+1,); for the robots also ``poses`` (K+1, n, 3), ``sonar`` (K+1, n, S),
            ``observations`` (K+1, n, S+2) and ``action_indices`` (K, n); and ``metrics``, a
            dict with the fields of ``fuzzyq rollout --json``.

        Raises:
            ConfigError: a policy of a `CallableModel` or a `Task` without a `plant`, an
                option that does not apply to the environment, or ``steps=0``.
            InputError: `x0` or `headings` of the wrong shape.
            SolverError: the trajectory would exceed the memory limit.
        """

    def evaluate(
        self,
        starts: npt.ArrayLike | None = None,
        steps: int | None = None,
        *,
        count: int = 100,
        seed: int = 0,
        plant: CallableModel | Any | None = None,
        task: Task | None = None,
    ) -> dict[str, Any]:
        """Monte-Carlo evaluation on the policy's environment, as ``fuzzyq compare`` evaluates
        policies: runs from many starts, each as `rollout` runs one; or over episodes of a
        system of your own given as `plant` (see `fuzzyq.evaluate`).

        Args:
            starts: model states, shape ``(n, state_dim)`` (the point masses and the classic
                benchmarks); default: `count` states drawn uniformly within the model's state
                bounds with `seed`. The robots always start from `count` random
                collision-free poses of `seed` (run ``k`` on the plant seeded with
                ``seed + k``).
            steps: steps per run; default: the environment's.
            count: number of random starts when `starts` is not given.
            seed: seed of the random starts.
            plant: a `CallableModel` (its function as the plant) or a Gymnasium environment
                to evaluate on instead of the policy's own environment.
            task: the `Task` of a Gymnasium environment given as `plant` (its actions).

        Returns:
            A dict: ``"runs"``, every run's metrics as columns (a numpy array per numeric
            field, one entry per run, named as in ``fuzzyq rollout --json``), and
            ``"summary"``: the robots' success report, the classic benchmarks' mean, minimum
            and maximum discounted return, or None for the point masses.

        Raises:
            ConfigError: a policy of a `CallableModel` or a `Task` without a `plant`,
                ``steps`` or ``count`` of 0, or `starts` given for the robots.
            InputError: `starts` of the wrong shape or with non-finite values.
        """

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickling support.

        Returns:
            ``(_restore, ("policy", (origin, kind)))``: the solution it was made from and
            its kind, or the bytes of a learned policy's file.
        """

@final
class Khepera:
    """The paper's Khepera IV robots (sections 3.2-3.3), solved on their kinematic model.

    Every field of ``[env]`` in ``fuzzyq config --env khepera`` (``radius``,
    ``forward_speed``, ``turn_speed``, ``sample_time``, ``goal_radius``, ``goal_reward``,
    ``collision_penalty``, the sonars, ``arena`` as a dict with ``x``, ``y`` and
    ``obstacle``, ``noise``, ...) is a keyword argument. The state fuzzy Q-iteration solves is
    each robot's pose ``[x, y, heading]``; the four actions are forward, turn clockwise, turn
    counter-clockwise and stop. ``solve(robots, robots.grid())`` trains as
    ``fuzzyq train --env khepera`` does, and the solution's policies roll out on the rapier
    plant with sonars (`Policy.rollout`, `Policy.evaluate`).

    Args:
        agents: number of robots (1 to 4).
        params: keyword arguments, the fields of the configuration's ``[env]`` table.

    Raises:
        ConfigError: an unknown parameter or a value out of range.
        InputTypeError: a parameter of the wrong type.
    """

    def __new__(cls, agents: int = 2, **params: Any) -> Khepera:
        """Creates the robots (see the class docstring for the arguments)."""

    @property
    def state_dim(self) -> int:
        """Length of the state: 3 per robot (``x``, ``y``, heading)."""

    @property
    def n_agents(self) -> int:
        """Number of robots."""

    @property
    def action_dim(self) -> int:
        """Length of the joint action vector (two wheel speeds per robot)."""

    @property
    def n_joint_actions(self) -> int:
        """Number of joint actions (``4 ** agents``)."""

    @property
    def sample_time(self) -> float:
        """The control period, seconds."""

    @property
    def params(self) -> dict[str, Any]:
        """Every parameter, as the configuration's ``[env]`` table."""

    def joint_action(self, index: int) -> npt.NDArray[np.float64]:
        """The joint action vector (wheel speeds) of joint action `index`.

        Args:
            index: a joint action index.

        Returns:
            The wheel speeds of every robot, shape ``(action_dim,)``.

        Raises:
            InputError: `index` out of range.
        """

    def joint_index(self, per_agent: Sequence[int]) -> int:
        """The joint action index of per-robot action indices (robot 0 most significant).

        Args:
            per_agent: one action index in ``[0, 4)`` per robot.

        Returns:
            The joint action index.

        Raises:
            InputError: wrong length or an index out of range.
        """

    def agent_indices(self, index: int) -> list[int]:
        """The per-robot action indices of joint action `index`.

        Args:
            index: a joint action index.

        Returns:
            One action index per robot.

        Raises:
            InputError: `index` out of range.
        """

    def random_starts(self, count: int, seed: int = 0) -> npt.NDArray[np.float64]:
        """Random starts as ``fuzzyq rollout --starts`` draws them.

        Args:
            count: number of starts.
            seed: seed of the draw.

        Returns:
            Shape ``(count, state_dim)``: flat poses, at least 0.5 m inside the walls, 0.3 m
            clear of the obstacles and 0.5 m apart.

        Raises:
            ConfigError: the arena leaves no room for such starts.
        """

    def step(self, x: npt.ArrayLike, u: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The kinematic model's successor of poses `x` under wheel speeds `u`.

        Args:
            x: the poses, shape ``(state_dim,)``.
            u: the wheel speeds, shape ``(action_dim,)``.

        Returns:
            The poses one sample time later, shape ``(state_dim,)``.
        """

    def reward(self, x: npt.ArrayLike, u: npt.ArrayLike) -> float:
        """The reward ``rho(x, u)`` (eq 42: the goal reward near the origin, the collision
        penalty where robots overlap).

        Args:
            x: the poses, shape ``(state_dim,)``.
            u: the wheel speeds, shape ``(action_dim,)``.

        Returns:
            The reward.
        """

    def grid(self) -> Grid:
        """The default grid of these robots.

        Returns:
            The grid of ``fuzzyq train --env khepera``: per robot the position cores on ``x``
            and ``y`` and 17 heading cores over ``[-pi, pi]``.
        """

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickling support.

        Returns:
            ``(_restore, ("khepera", json))``: the configuration as JSON.
        """

@final
class KheperaPlant:
    """The Khepera robots on the rapier plant: colliding discs with ray-cast sonars and the
    configured noise, one control period per `step` (what `Policy.rollout` runs the robots on,
    and what ``fuzzyq.envs.ModelEnv(fuzzyq.Khepera())`` steps).

    >>> import fuzzyq
    >>> robots = fuzzyq.Khepera(agents=2)
    >>> plant = fuzzyq.KheperaPlant(robots, seed=0)
    >>> plant.reset(robots.random_starts(1, seed=0)[0])
    >>> contacts = plant.step(robots.joint_action(0))
    >>> plant.poses.shape, plant.sonar.shape
    ((6,), (2, 5))

    Args:
        robots: the robots' model (its parameters, arena and noise).
        seed: seed of the plant's noise (wheels and sonars).

    Raises:
        ConfigError: the robots' configuration cannot be built as a plant.
    """

    def __new__(cls, robots: Khepera, seed: int = 0) -> KheperaPlant:
        """Creates the plant (see the class docstring for the arguments)."""

    def reset(self, poses: npt.ArrayLike, seed: int | None = None) -> None:
        """Places the robots at rest and clears the collision counts.

        Args:
            poses: ``[x, y, heading]`` per robot, flat, shape ``(3 * agents,)``.
            seed: restarts the noise generator from this seed (None: continue it).

        Raises:
            InputError: wrong length, non-finite values, or a robot overlapping a wall, an
                obstacle or another robot.
        """

    def step(self, u: npt.ArrayLike) -> int:
        """Drives every robot for one sample time.

        Args:
            u: joint wheel speeds ``[v_left, v_right]`` per robot, flat, shape
                ``(2 * agents,)``; limited to ``+-max_wheel_speed``.

        Returns:
            The number of contacts (robot-robot, robot-wall, robot-obstacle) that started.

        Raises:
            ConfigError: before the first `reset`.
            InputError: wrong length or non-finite values.
        """

    @property
    def poses(self) -> npt.NDArray[np.float64]:
        """The flat poses ``[x, y, heading, ...]`` (heading in ``(-pi, pi]``), a new array."""

    @property
    def paper_state(self) -> npt.NDArray[np.float64]:
        """The paper's state ``[s_x, s_y, v_x, v_y]`` per robot, flat (velocity: displacement
        over the last sample time; zero after a reset), a new array."""

    @property
    def sonar(self) -> npt.NDArray[np.float64]:
        """Sonar readings (m) after the last reset or step, shape ``(agents, n_sonars)``."""

    @property
    def reward(self) -> float:
        """The reward of the current poses: the goal reward in the region, minus the
        collision penalty where robots overlap or touch the arena, else 0."""

    @property
    def in_goal(self) -> bool:
        """Whether the current poses are in the reward region (False before a reset)."""

    @property
    def collisions(self) -> dict[str, Any]:
        """Collisions since the last reset: ``total``, ``robot_robot``, ``robot_wall``,
        ``robot_obstacle`` (ints) and ``per_agent`` (a list)."""

def solve(
    model: PointMass | Khepera | ClassicModel | CallableModel | Task,
    grid: Grid,
    *,
    gamma: float | None = None,
    xi: float | None = None,
    max_sweeps: int | None = None,
    sweep: Literal["sync", "async"] | None = None,
    extrapolate: bool | None = None,
    evaluation_sweeps: int | None = None,
    coarse_start: bool | None = None,
    absorbing_goal: bool | None = None,
    precision: Literal["f32", "f64", "float32", "float64"] | None = None,
    backup: Literal["auto", "block", "generic"] | None = None,
    kernel: Literal["avx512", "avx2", "portable", "scalar"] | None = None,
    operator: Literal["values", "q-values"] | None = None,
    device: Literal["cpu", "gpu"] | None = None,
    threads: int | None = None,
    callback: Callable[[dict[str, Any]], bool | None] | None = None,
    transitions: Mapping[str, npt.ArrayLike] | None = None,
    max_memory_gb: float | None = None,
    progress: bool = False,
) -> Solution:
    """Solves a model on a grid by fuzzy Q-iteration (the paper's eq 20), with the GIL released.

    A built-in model (`PointMass`, `DcMotor`, `Pendulum`, `CarHill`, `Arm`) is solved through
    the same code as ``fuzzyq train``; a `CallableModel` is tabulated on the grid first.
    Settings left at None take the task's defaults, the very settings ``fuzzyq train`` runs
    for it (one definition serves both): for a classic benchmark its preset's `gamma` and
    `xi`, plain sweeps (``extrapolate=False``, ``evaluation_sweeps=0``) in ``"f64"``; for the
    Khepera robots the paper's settings with ``coarse_start=True``; otherwise ``gamma=0.96``,
    ``xi=0.05``, ``extrapolate=True``, ``evaluation_sweeps=5`` (modified policy iteration where
    it applies), ``"f32"``, ``max_sweeps=1000``, ``sweep="sync"``, ``backup="auto"``,
    ``operator="values"``, ``device="cpu"``, no coarse start and no absorbing goal. Ctrl-C raises `KeyboardInterrupt` at the end of the current sweep.

    Args:
        model: the model to solve.
        grid: the fuzzy grid, with as many state variables as the model.
        gamma: the discount factor, in ``[0, 1)``.
        xi: the stopping threshold: the run stops when the sweep's change
            ``||theta_{k+1} - theta_k||_inf`` is at most `xi` (the paper's rule).
        max_sweeps: the most sweeps to run, full backups and evaluation sweeps alike (under
            modified policy iteration the last one allowed is a full backup); the solution
            then has ``converged=False``.
        sweep: ``"sync"`` (every core reads the previous sweep's values: Jacobi, the paper's
            eq 20) or ``"async"`` (slabs update in place, later ones read the new values:
            Gauss-Seidel).
        extrapolate: move `V` to the midpoint of MacQueen's bounds every other sweep.
        evaluation_sweeps: evaluation sweeps under the greedy actions after each full backup
            (modified policy iteration); 0 for value iteration.
        coarse_start: start modified policy iteration from the solution on the grid with
            every other core of each variable, interpolated: the same stopping rule and error
            bound, fewer sweeps on fine grids (the Khepera robots' default grid: 52 instead
            of 80); ignored by value iteration and by models known only on the grid.
        absorbing_goal: the goal pays once, then nothing; needs a model with goal states at
            some core of the grid (the point masses), else `ConfigError`.
        precision: the solver's floating-point type: ``"f32"`` (half the memory, twice the
            SIMD width) or ``"f64"``; ``"float32"`` and ``"float64"`` are synonyms.
        backup: ``"auto"`` (the block backup when the model declares blocks, else the
            generic one), ``"block"`` (the model must declare blocks) or ``"generic"`` (step
            the model and interpolate over every active successor core).
        kernel: the SIMD kernel of the block backup (`available_kernels` lists this CPU's);
            None: the fastest available. All give bit-identical results.
        operator: ``"values"`` (interpolate the per-core maxima, only `V` stored: any grid
            size) or ``"q-values"`` (Busoniu's fuzzy Q-iteration with theta stored, as the
            ApproxRL toolbox runs it; built-in models only).
        device: ``"cpu"`` or ``"gpu"``: the block backup's sweeps on a GPU through wgpu
            (Vulkan, Metal, DX12), in ``"f32"``, synchronous, for models that declare blocks
            and have no terminal states (`ConfigError` otherwise, and `SolverError` where no
            adapter opens). Where the adapter's multiply-adds are fused (NVIDIA's) `V` and
            the greedy actions equal the CPU's bit for bit; elsewhere (Mesa's lavapipe) each
            product is rounded first, so the last bits differ. ``Solution.kernel`` is
            ``"wgpu"``.
        threads: the number of threads (a dedicated pool); None: all cores. Results are
            bit-identical for any count.
        callback: called after every sweep with a dict: ``sweep`` (from 1),
            ``delta_lower`` and ``delta_upper`` (bounds of the sweep's change),
            ``extrapolated``, ``evaluation``, ``seconds``, ``bound`` (the a-priori sweep
            bound of eq 37) and ``xi``; and what the solver chose for the run, the same in
            every call: ``scheme`` (``"value-iteration"`` or ``"modified-policy-iteration"``),
            ``extrapolate`` (whether its sweeps move `V` to the midpoint of MacQueen's
            bounds: not with absorbing goals or terminal states) and ``coarse_start`` (None,
            or the dict `Solution.coarse_start` gives). Returning False stops the solve after that sweep:
            `solve` then returns the solution of the run limited to the sweeps done, with its
            error bound and ``stopped=True``. Any other return value continues. An exception
            it raises stops the solve and propagates.
        transitions: solve a model *learned* from transitions instead of the model's own
            dynamics (built-in models only): a mapping with ``states`` ``(n, state_dim)``,
            ``actions`` ``(n, action_dim)``, ``next_states`` and ``rewards`` ``(n,)``, as
            `collect` returns, or logged data. Every dynamics block's transition table is
            estimated from them; the model supplies only the reward, actions and state
            ranges.
        max_memory_gb: the memory the solve may need (default: 90% of the machine's); a
            larger problem is refused with its estimate before anything is allocated or a
            `CallableModel`'s function is called.
        progress: show a tqdm progress bar of the sweeps (tqdm is installed with the
            package; if it was removed, ``progress=True`` raises `ConfigError`).

    Returns:
        The solution.

    Raises:
        InputTypeError: a model of another type, or an argument of the wrong type.
        ConfigError: an invalid setting, a grid that does not fit the model, an option the
            model does not support, or ``progress=True`` without tqdm.
        ModelError: a `CallableModel`'s function returned unusable data.
        SolverError: the problem exceeds `max_memory_gb`.
    """

def collect(
    model: PointMass | ClassicModel,
    samples: int,
    *,
    seed: int = 0,
    episode_steps: int = 50,
) -> dict[str, npt.NDArray[np.float64]]:
    """Collects transitions on the plant of a built-in model, with random actions.

    As ``fuzzyq train --learner learned-model`` does: seeded episodes of random joint
    actions from the task's random starts, with the model's process noise (for example
    ``PointMass(velocity_noise=0.05)``).

    Args:
        model: a `PointMass` or a classic benchmark.
        samples: the number of transitions.
        seed: the seed of the starts, actions and noise.
        episode_steps: steps per episode.

    Returns:
        A dict of float64 arrays: ``states`` ``(n, state_dim)``, ``actions``
        ``(n, action_dim)``, ``next_states`` ``(n, state_dim)`` and ``rewards`` ``(n,)``,
        ready for ``solve(model, grid, transitions=...)``.

    Raises:
        InputTypeError: `model` is not a built-in model.
        SolverError: the samples would exceed the memory limit.
    """

def learn_from_samples(
    source: PointMass | Khepera | CallableModel | Any,
    learner: Literal["fql", "vqql"] = "fql",
    *,
    task: Task | None = None,
    grid: Grid | None = None,
    episodes: int | None = None,
    episode_steps: int | None = None,
    gamma: float | None = None,
    reward_bound: float | None = None,
    literal: bool = False,
    cells: int | None = None,
    seed: int = 0,
    starts: npt.ArrayLike | Callable[[np.random.Generator], npt.ArrayLike] | None = None,
    progress: bool = False,
) -> tuple[Policy, dict[str, Any]]:
    """Learns a task from samples, without its model: the point masses or the robots as
    ``fuzzyq train --learner fql|vqql`` does (the same code: the same seed gives the same
    policy file and learning curve), or a system of your own: a `CallableModel` (its function
    as the simulator) or a Gymnasium environment, declared by a `Task`.

    ``"fql"`` is model-free fuzzy Q-learning (the paper's section 2.5) with the additive
    layout: each agent's own Q-function over its own observation, epsilon-greedy episodes,
    greedy evaluations along the way. A point mass observes its ``[s_x, s_y, v_x, v_y]``
    (fuzzified on the paper's cores), a robot its quantised sonars, goal distance and angle,
    and an agent of your own system the state variables of its own block (when the task's
    `blocks` give every agent one; the whole state otherwise), fuzzified on `grid`'s cores of
    those variables. ``"vqql"`` is vector-quantised Q-learning, the crisp learner of the
    paper's Table 1: k-means cells per agent over explored observations, tabular Q-learning
    over them (not for the robots).

    A system of your own learns with `FqlConfig`'s defaults (1000 episodes of at most 200
    steps, step size 0.1, epsilon from 0.3 to 0.05 over 500 episodes, 10 greedy evaluation
    episodes every 50, stopping when the parameters settle); its episodes start as
    `collect`'s do (a Gymnasium environment's ``reset(seed=seed + k)``), and one ends at a
    terminal state, when the environment truncates it, or after `episode_steps`.

    >>> import fuzzyq
    >>> policy, report = fuzzyq.learn_from_samples(fuzzyq.PointMass(agents=1), episodes=20)
    >>> policy.learner, len(report["curve"]["return"])
    ('fql', 20)

    Args:
        source: a `PointMass` (its parameters), `Khepera` robots, a `CallableModel` or a
            Gymnasium environment (see `collect`).
        learner: ``"fql"`` or ``"vqql"``.
        task: a system of your own's `Task` (its state bounds, actions and blocks).
        grid: a system of your own's `Grid` over the task's state.
        episodes: learning episodes (default: 3000 for the point masses, 2000 for the
            robots, 1000 for a system of your own).
        episode_steps: a system of your own's steps per episode at most (default 200).
        gamma: a system of your own's discount (default 0.96, the paper's).
        reward_bound: the largest magnitude of a step's reward of your own system, if you
            know it: every parameter is then kept within ``reward_bound / (1 - gamma)`` (the
            projected update, which the built-in tasks always apply with their goal reward
            and collision penalty). None: no projection.
        literal: the update as printed in the paper (eqs 24-26) instead of the corrected
            one (kept to measure what the printed form learns).
        cells: VQQL's cells per agent (default: as many as the fuzzy partition has cores: the
            grid's own-state cores for the point masses, the largest agent's for your own
            system).
        seed: seed of exploration, starts, the plant's noise and VQQL's quantiser.
        starts: a `CallableModel`'s starts (see `collect`).
        progress: show a tqdm bar of episodes.

    Returns:
        ``(policy, report)``: the greedy, decentralised `Policy` (``policy.learner`` is
        ``"fql"`` or ``"vqql"``; on a built-in task it acts on the agents' observations
        concatenated and rolls out with `Policy.rollout` and `Policy.evaluate`; on your own
        system it acts on the state, ``fuzzyq.evaluate(policy, source, task=task)`` runs it, and
        it pickles) and a dict: ``curve`` (numpy columns named as ``fuzzyq train --curve``'s
        CSV: ``episode``, ``steps``, ``return``, ``discounted_return``, ``mean_abs_td``,
        ``max_abs_td``, ``epsilon``, ``alpha``, ``param_change``, ``terminal``,
        ``eval_mean_return``, ``eval_success_rate``; NaN where an episode had no
        evaluation), ``converged_at`` (the first episode that passed the convergence test, or
        None), ``steps_total``, ``stop`` (``"episode-limit"``, ``"converged"`` or
        ``"diverged"``), ``seconds`` and ``lloyd`` (VQQL's quantiser report, or None).

    Raises:
        ConfigError: a classic benchmark, another learner, ``"vqql"`` for the robots, `cells`
            with ``"fql"``, ``episodes=0``; a system of your own without `task` or `grid`, or
            a grid of another dimension, a negative `reward_bound`; `task`, `grid`,
            `episode_steps`, `gamma`, `reward_bound` or `starts` for a built-in task.
        InputTypeError: an argument of the wrong type, or a source that is no system.
        KeyboardInterrupt: Ctrl-C (the run stops after its current episode).
    """

def load(path: str | PathLike[str], model: CallableModel | None = None) -> Solution | Policy:
    """Reads a policy file of any kind: written by ``fuzzyq train`` or by `Solution.save`.

    Args:
        path: the policy file.
        model: for a file saved from a solution of a `CallableModel`, that model (the file
            does not hold its function); leave None for the files of built-in models.

    Returns:
        A `Solution` for a fuzzy Q-iteration policy (`V`, `greedy`, `grid`, the run's record,
        ``.policy(kind)``), a `Policy` for a policy learned from samples (fuzzy Q-learning,
        VQQL: greedy and decentralised, each agent acting on its own observation).

    Raises:
        PolicyFileError: the file cannot be read, or is truncated, corrupted or foreign.
    """

_Values = npt.NDArray[np.float32] | npt.NDArray[np.float64]
_Actions = npt.NDArray[np.uint32]

@final
class Task:
    """A system known only through its transitions: a Gymnasium environment, a simulator or
    logged data, declared by what the learner is told about it.

    ``solve(task, grid, transitions=...)`` learns its model from the transitions with the
    estimator ``fuzzyq train --learner learned-model`` uses, then solves it: per block, the
    distribution of the block's successor from each block core under each block action,
    estimated by local linear regression around the core (kernels widen where samples are
    scarce; `Solution.fit` reports where); the reward at each core and joint action as the
    membership-weighted mean of the recorded rewards (or `reward` at the cores when given),
    with the lowest recorded reward where no transition reached. `fuzzyq.collect` and
    `fuzzyq.learn` gather the transitions by interaction.

    Args:
        state_bounds: the range of each state variable, a ``(state_dim, 2)`` array of
            ``[low, high]`` rows (a successor at an edge counts as clamped there).
        actions: each agent's discrete actions, as `CallableModel` takes them.
        blocks: independent dynamics blocks as `CallableModel` declares them (each is
            learned separately, from far fewer samples); None: one block of the whole state.
        periodic: the state variables that are angles periodic over their range.
        reward: a vectorised ``reward(states, actions) -> rewards`` evaluated at the cores
            instead of learning the reward; None: learned from the transitions.
        reward_depends_on_action: whether the reward depends on the action (False: one
            learned reward per core, from all transitions at once).

    Raises:
        InputTypeError: an argument of the wrong type.
        ConfigError: bounds with ``low >= high``, bad actions or blocks, a periodic variable
            out of range.
    """

    def __new__(
        cls,
        *,
        state_bounds: npt.ArrayLike,
        actions: Sequence[npt.ArrayLike],
        blocks: Sequence[tuple[Sequence[int], Sequence[int]]] | None = None,
        periodic: Sequence[int] | None = None,
        reward: Callable[
            [npt.NDArray[np.float64], npt.NDArray[np.float64]], npt.ArrayLike
        ]
        | None = None,
        reward_depends_on_action: bool = True,
    ) -> Task:
        """Creates the task (see the class docstring for the arguments)."""

    @property
    def state_dim(self) -> int:
        """Length of the state vector."""

    @property
    def n_agents(self) -> int:
        """Number of agents."""

    @property
    def action_dim(self) -> int:
        """Length of the joint action vector."""

    @property
    def state_bounds(self) -> npt.NDArray[np.float64]:
        """The range of each state variable, shape ``(state_dim, 2)``."""

    @property
    def periodic(self) -> list[int]:
        """The periodic state variables."""

    @property
    def actions(self) -> list[npt.NDArray[np.float64]]:
        """Each agent's actions, shape ``(n_actions, components)``."""

    @property
    def joint_actions(self) -> npt.NDArray[np.float64]:
        """Every joint action vector, shape ``(n_joint_actions, action_dim)``, agent 0 most
        significant."""

    @property
    def blocks(self) -> list[tuple[list[int], list[int]]]:
        """The blocks (one block of everything when none were declared)."""

    @property
    def reward(
        self,
    ) -> Callable[[npt.NDArray[np.float64], npt.NDArray[np.float64]], npt.ArrayLike] | None:
        """The reward function, or None (learned from the transitions)."""

    @property
    def reward_depends_on_action(self) -> bool:
        """Whether the reward is learned per joint action (else per core)."""

    def __getnewargs_ex__(self) -> tuple[tuple[Any, ...], dict[str, Any]]:
        """Pickling support: the constructor's arguments.

        Returns:
            ``((), kwargs)``: the declaration as keyword arguments (a reward function is
            pickled by reference, so a module-level function).
        """

@final
class SlabProblem:
    """The block operator of a training configuration, for computing sweeps in shards.

    `V` is kept in the operator's internal order, in slabs: one core of the first contracted
    dynamics block times every core of the others (`n_slabs` slabs of `slab_len` cores). Each
    method computes one pass for the output slabs ``start..stop`` from their halo: the input
    slabs `input_slabs` names (or more, increasing) and those slabs' values one after another,
    in the configured precision (`dtype`). The work runs in Rust with the GIL released; every
    process that builds the problem from the same configuration computes the same bits, so
    shards assembled in any grouping give the single-process solver's sweeps. This is the
    building block of `fuzzyq.distributed`.

    Args:
        config: a training configuration as TOML text (``fuzzyq config`` writes one).

    Raises:
        ConfigError: the configuration does not parse, or its sweeps cannot be sharded (the
            q-values operator, asynchronous sweeps, the generic backup path).
    """

    def __new__(cls, config: str) -> SlabProblem:
        """Builds the operator of `config` (see the class docstring)."""

    @property
    def n_slabs(self) -> int:
        """Slabs of `V` (the first contracted block's cores)."""

    @property
    def slab_len(self) -> int:
        """Cores per slab."""

    @property
    def dtype(self) -> Literal["float32", "float64"]:
        """The value type of every buffer."""

    def input_slabs(self, start: int, stop: int) -> _Actions:
        """The input slabs that the output slabs ``start..stop`` read.

        Args:
            start: the first output slab.
            stop: one past the last output slab.

        Returns:
            Slab indices, increasing, each once (uint32).

        Raises:
            ConfigError: an empty range or one past the last slab.
        """

    def backup(self, start: int, stop: int, halo: _Actions, v_halo: _Values) -> _Values:
        """The backup ``max_u (rho + gamma P V)`` of the output slabs' cores.

        Args:
            start: the first output slab.
            stop: one past the last output slab.
            halo: input slabs, increasing, containing ``input_slabs(start, stop)``.
            v_halo: the values of those slabs of `V`, one slab after another.

        Returns:
            ``(stop - start) * slab_len`` values.

        Raises:
            ConfigError: a bad range or halo.
            InputError: `v_halo` of the wrong length.
            InputTypeError: `v_halo` not of `dtype`.
        """

    def backup_greedy(
        self, start: int, stop: int, halo: _Actions, v_halo: _Values
    ) -> tuple[_Values, _Actions]:
        """`backup` and each core's greedy joint action (the lowest-index maximiser).

        Args:
            start: the first output slab.
            stop: one past the last output slab.
            halo: input slabs, increasing, containing ``input_slabs(start, stop)``.
            v_halo: the values of those slabs of `V`, one slab after another.

        Returns:
            The values and the joint actions.
        """

    def rewards(self, start: int, stop: int) -> _Values:
        """The backup of ``V = 0`` on the output slabs' cores (``max_u rho``).

        Args:
            start: the first output slab.
            stop: one past the last output slab.

        Returns:
            ``(stop - start) * slab_len`` values.
        """

    def evaluate(
        self, start: int, stop: int, halo: _Actions, v_halo: _Values, policy: _Actions
    ) -> _Values:
        """One policy-evaluation sweep ``rho + gamma P_policy V`` of the output slabs' cores.

        Args:
            start: the first output slab.
            stop: one past the last output slab.
            halo: input slabs, increasing, containing ``input_slabs(start, stop)``.
            v_halo: the values of those slabs of `V`, one slab after another.
            policy: the output slabs' joint actions.

        Returns:
            ``(stop - start) * slab_len`` values.
        """

    def greedy(self, start: int, stop: int, halo: _Actions, v_halo: _Values) -> _Actions:
        """The greedy joint actions of the output slabs' cores.

        Args:
            start: the first output slab.
            stop: one past the last output slab.
            halo: input slabs, increasing, containing ``input_slabs(start, stop)``.
            v_halo: the values of those slabs of `V`, one slab after another.

        Returns:
            Joint actions (uint32).
        """

    def abs_max(
        self, start: int, stop: int, halo: _Actions, a_halo: _Values, b_halo: _Values
    ) -> float:
        """``gamma max |P (a - b)|`` over the output slabs' cores: the exact change of theta.

        Args:
            start: the first output slab.
            stop: one past the last output slab.
            halo: input slabs, increasing, containing ``input_slabs(start, stop)``.
            a_halo: those slabs of one value buffer.
            b_halo: the same slabs of another.

        Returns:
            The maximum over these cores (maxima of disjoint shards combine exactly).
        """

    def diff_stats(self, a: _Values, b: _Values, shift: float) -> tuple[float, float, float]:
        """A sweep's change on some cores, in float64.

        Args:
            a: the sweep's output on those cores.
            b: its input on the same cores.
            shift: the constant the extrapolation added to `b`.

        Returns:
            ``(max |a - b + shift|, min (a - b), max (a - b))``.
        """

    def shifted(self, v: _Values, shift: float) -> _Values:
        """A copy of `v` with `shift` added to every value, in `dtype`.

        Args:
            v: values.
            shift: the constant.

        Returns:
            The shifted copy.
        """

def train_sharded(
    config: str,
    backend: Any,
    *,
    resume: str | PathLike[str] | None = None,
    checkpoint: str | PathLike[str] | None = None,
    on_sweep: Callable[[dict[str, Any]], bool | None] | None = None,
) -> Solution:
    """Trains a configuration with every pass over `V` run by `backend` (the driver of
    `fuzzyq.distributed`; use that module).

    Args:
        config: a training configuration as TOML text.
        backend: an object with the methods ``backup``, ``backup_greedy``, ``rewards``,
            ``evaluate``, ``diff_stats``, ``shift``, ``exact_delta``, ``greedy``, ``load``,
            ``load_policy``, ``values`` and ``policy`` on value buffers numbered 0, 1, 2.
        resume: a checkpoint to continue from.
        checkpoint: where to write the run's state after every sweep.
        on_sweep: called with each sweep's record; returning False stops the run.

    Returns:
        The solution ``fuzzyq train --config`` computes, bit for bit.

    Raises:
        ConfigError: the configuration does not parse or cannot be sharded.
        InputError: `resume` is not a checkpoint of this configuration.
        SolverError: `on_sweep` stopped the run.
    """

def available_kernels() -> list[Literal["avx512", "avx2", "portable", "scalar"]]:
    """The kernel instances this CPU runs, fastest first.

    Returns:
        A list of kernel names, for `solve`'s `kernel`.
    """

def _restore(kind: str, data: Any) -> Any:
    """Rebuilds a pickled object (the inverse of the classes' ``__reduce__``; not for direct use).

    Args:
        kind: which class the payload is of.
        data: the pickled payload.

    Returns:
        The object.
    """

def _cli(argv: list[str]) -> int:
    """Runs the ``fuzzyq`` command line (the package's ``fuzzyq`` command and ``python -m
    fuzzyq``; not for direct use).

    Args:
        argv: the program's name, then its arguments.

    Returns:
        The exit code: 0 on success, 2 for an error, 130 when Ctrl-C stopped a training run.
    """

def _step_batch(
    model: PointMass | ClassicModel, states: npt.ArrayLike, actions: npt.ArrayLike
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """Steps a batch of a built-in model's states in Rust with the GIL released (what
    `fuzzyq.envs.ModelVectorEnv` steps with; not for direct use).

    Args:
        model: a `PointMass` or a classic benchmark.
        states: shape ``(n, state_dim)``.
        actions: joint action vectors, shape ``(n, action_dim)`` (any vectors).

    Returns:
        ``(next_states, rewards, terminal)`` of shapes ``(n, state_dim)``, ``(n,)`` and
        ``(n,)``: the reward at each state under its action, and whether each next state is
        terminal.
    """
