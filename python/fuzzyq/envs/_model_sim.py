"""One simulation over every kind of fuzzyq model, shared by `ModelEnv` and `ModelParallelEnv`.

Internal: `adapt(model)` wraps a `fuzzyq.PointMass`, a classic benchmark (`fuzzyq.DcMotor`,
`Pendulum`, `CarHill`, `Arm`: any `fuzzyq.ClassicModel`), the `fuzzyq.Khepera` robots (on
their rapier plant) or a `fuzzyq.CallableModel` (or an object with the same methods) in one
interface; `ModelSim` adds the episode (start states,
step counting, truncation) and the outputs both environments return.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from gymnasium import error as gym_error
from gymnasium import spaces

import fuzzyq
from fuzzyq._gym_ids import EPISODE_STEPS

from ._core import OBS_DTYPE, Observation, Rendering, State, validate_max_steps
from ._render import Frame, khepera_frame, point_mass_frame, state_bars_frame

#: A start state, or a function of the env's random generator that draws one.
StartSpec = npt.ArrayLike | Callable[[np.random.Generator], npt.ArrayLike] | None
#: `max_steps` as the envs take it: a positive int, None (never truncate) or ``"default"``.
MaxSteps = int | Literal["default"] | None
#: What the robots' environments observe: None (the poses) or ``"paper"``.
ObservationKind = Literal["paper"] | None

#: The default episode lengths of the built-in models, in steps: those of ``fuzzyq rollout``.
DEFAULT_EPISODE_STEPS = EPISODE_STEPS


def default_episode_steps(model: object) -> int | None:
    """The episode length `ModelEnv` and `ModelParallelEnv` use by default for `model`.

    Args:
        model: a fuzzyq model.

    Returns:
        The length of a ``fuzzyq rollout`` of the built-in model, in steps: 75 for
        `fuzzyq.PointMass` (the paper's 30 s), 400 for `fuzzyq.DcMotor`, 600 for
        `fuzzyq.Pendulum`, 100 for `fuzzyq.CarHill`, 200 for `fuzzyq.Arm` and 250 for
        `fuzzyq.Khepera` (the paper's 100 s); None (never
        truncate) for a `fuzzyq.CallableModel` or any other model.
    """
    if isinstance(model, fuzzyq.PointMass):
        return DEFAULT_EPISODE_STEPS["pointmass"]
    if isinstance(model, fuzzyq.Khepera):
        return DEFAULT_EPISODE_STEPS["khepera"]
    if isinstance(model, fuzzyq.ClassicModel):
        return DEFAULT_EPISODE_STEPS.get(model.env)
    return None


class ModelAdapter:
    """The interface `ModelSim` needs, over one model kind (the base: a `CallableModel`).

    Attributes:
        model: the wrapped model.
        state_dim: length of the state vector.
        agent_sizes: each agent's number of actions (agent 0 first).
        n_joint_actions: the product of `agent_sizes`.
        low, high: elementwise bounds of the state (``-inf``/``inf`` where unknown).
        sample_time: seconds per step, when the model has one.
    """

    def __init__(self, model: Any, bounds: npt.NDArray[np.float64] | None) -> None:
        self.model = model
        self.state_dim = int(model.state_dim)
        self.agent_sizes = [len(np.asarray(a)) for a in model.actions]
        self.n_joint_actions = int(model.n_joint_actions)
        if bounds is None:
            self.low = np.full(self.state_dim, -np.inf)
            self.high = np.full(self.state_dim, np.inf)
        else:
            self.low, self.high = bounds[:, 0].copy(), bounds[:, 1].copy()
        self.sample_time: float | None = None

    @property
    def n_agents(self) -> int:
        """Number of agents."""
        return len(self.agent_sizes)

    @property
    def bounded(self) -> bool:
        """Whether every state variable has finite bounds."""
        return bool(np.all(np.isfinite(self.low)) and np.all(np.isfinite(self.high)))

    def default_start(self, rng: np.random.Generator) -> State | None:
        """A start state when the user gave none: uniform within the bounds when they are all
        known, else None (no default)."""
        if not self.bounded:
            return None
        return rng.uniform(self.low, self.high)

    def joint_index(self, per_agent: list[int]) -> int:
        """The joint action index of per-agent action indices (agent 0 most significant)."""
        return int(self.model.joint_index(per_agent))

    def start(self, x: State, rng: np.random.Generator) -> None:
        """An episode starts at `x` (the stateful plants place themselves there)."""

    def observe(self, x: State) -> State:
        """The observation at state `x`: the state itself."""
        return x

    def observation_bounds(self) -> tuple[State, State]:
        """Elementwise bounds of `observe`'s values: the state's."""
        return self.low, self.high

    def step(self, x: State, joint: int) -> tuple[State, float, bool]:
        """The next state, the reward and whether the next state is terminal, under joint
        action `joint`."""
        return self.step_vector(x, np.asarray(self.model.joint_action(joint), dtype=np.float64))

    def step_vector(self, x: State, u: npt.NDArray[np.float64]) -> tuple[State, float, bool]:
        """`step` under the joint action vector `u` (any vector, not only a joint action's)."""
        next_state, reward, terminal = self.model.step(x, u)
        return np.asarray(next_state, dtype=np.float64), float(reward), bool(terminal)

    def joint_vectors(self) -> npt.NDArray[np.float64]:
        """Every joint action's vector, shape ``(n_joint_actions, action_dim)``."""
        return np.array(
            [self.model.joint_action(j) for j in range(self.n_joint_actions)], dtype=np.float64
        )

    def action_bounds(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Each joint action vector component's smallest and largest value over the joint
        actions: the box the continuous-action variant acts in."""
        vectors = self.joint_vectors()
        return vectors.min(axis=0), vectors.max(axis=0)

    def info(self, x: State) -> dict[str, Any]:
        """Model-specific info entries at state `x`."""
        return {}

    def frame(self, x: State, terminal: bool) -> Frame:
        """The ``"rgb_array"`` picture of state `x`."""
        return state_bars_frame(x, self.low.tolist(), self.high.tolist(), terminal)


class PointMassAdapter(ModelAdapter):
    """A `fuzzyq.PointMass`: bounded by its limits, never terminal, reward rho(x) of the state
    before the step; starts at random positions at rest (as `PointMassEnv`)."""

    def __init__(self, model: fuzzyq.PointMass) -> None:
        self.model = model
        self.state_dim = model.state_dim
        self.agent_sizes = [model.n_actions] * model.n_agents
        self.n_joint_actions = model.n_joint_actions
        per_agent = [model.position_limit] * 2 + [model.velocity_limit] * 2
        self.high = np.tile(np.asarray(per_agent, dtype=np.float64), model.n_agents)
        self.low = -self.high
        self.sample_time = model.sample_time

    def default_start(self, rng: np.random.Generator) -> State:
        """Positions uniform in the position box, zero velocities."""
        n, limit = self.model.n_agents, self.model.position_limit
        state = np.zeros((n, 4), dtype=np.float64)
        state[:, :2] = rng.uniform(-limit, limit, size=(n, 2))
        return state.reshape(-1)

    def step_vector(self, x: State, u: npt.NDArray[np.float64]) -> tuple[State, float, bool]:
        """The next state, the model's reward rho(x, u) at `x`, and False (never terminal)."""
        reward = float(self.model.reward(x, u))
        next_state = self.model.step(x, u)
        return np.asarray(next_state, dtype=np.float64), reward, False

    def info(self, x: State) -> dict[str, Any]:
        """``in_goal``: whether `x` is in the goal (so the next step pays)."""
        return {"in_goal": bool(self.model.in_goal(x))}

    def frame(self, x: State, terminal: bool) -> Frame:
        """The arena picture of `point_mass_frame`."""
        return point_mass_frame(self.model, x)


class ClassicAdapter(ModelAdapter):
    """A classic benchmark: one agent, bounded by `state_bounds` (shape ``(state_dim, 2)``),
    starting at `default_start`, terminal where `is_terminal` says (the car off the hill)."""

    def __init__(self, model: fuzzyq.ClassicModel) -> None:
        self.model = model
        self.state_dim = model.state_dim
        self.agent_sizes = [model.n_joint_actions]
        self.n_joint_actions = model.n_joint_actions
        bounds = np.asarray(model.state_bounds, dtype=np.float64)
        self.low, self.high = bounds[:, 0].copy(), bounds[:, 1].copy()
        self.sample_time = model.sample_time
        self._start = np.asarray(model.default_start, dtype=np.float64)

    def default_start(self, rng: np.random.Generator) -> State:
        """The model's `default_start` (that of ``fuzzyq rollout``), a new array."""
        return self._start.copy()

    def joint_index(self, per_agent: list[int]) -> int:
        """One agent: its action index."""
        return per_agent[0]

    def step_vector(self, x: State, u: npt.NDArray[np.float64]) -> tuple[State, float, bool]:
        """``model.step(x, u)`` and ``model.is_terminal`` of the next state."""
        next_state, reward = self.model.step(x, u)
        next_state = np.asarray(next_state, dtype=np.float64)
        return next_state, float(reward), bool(self.model.is_terminal(next_state))


class KheperaAdapter(ModelAdapter):
    """The `fuzzyq.Khepera` robots on their rapier plant (a `fuzzyq.KheperaPlant`: contacts,
    sonars and the configured noise), not on the kinematic model they are solved on.

    The state is the robots' poses ``[x, y, heading]`` (bounded by the walls and
    ``[-pi, pi]``); the observation is the state, or with ``observation="paper"`` the paper's
    ``[s_x, s_y, v_x, v_y]`` per robot. The reward is the plant's of the poses before the
    step; episodes start at `fuzzyq.Khepera.random_starts`' draws and never terminate.
    """

    def __init__(self, model: fuzzyq.Khepera, observation: ObservationKind) -> None:
        self.model = model
        self.params = model.params
        self.plant = fuzzyq.KheperaPlant(model)
        n = model.n_agents
        self.state_dim = model.state_dim
        self.agent_sizes = [4] * n
        self.n_joint_actions = model.n_joint_actions
        (x0, x1), (y0, y1) = self.params["arena"]["x"], self.params["arena"]["y"]
        self.low = np.tile([x0, y0, -np.pi], n)
        self.high = np.tile([x1, y1, np.pi], n)
        self.sample_time = model.sample_time
        self.paper = observation == "paper"
        self.speed = float(self.params["max_wheel_speed"])

    def default_start(self, rng: np.random.Generator) -> State:
        """One of `fuzzyq.Khepera.random_starts`, drawn with a seed from `rng`."""
        seed = int(rng.integers(2**63))
        return np.asarray(self.model.random_starts(1, seed=seed)[0], dtype=np.float64)

    def start(self, x: State, rng: np.random.Generator) -> None:
        """Places the robots at `x` at rest; the plant's noise is seeded from `rng`."""
        self.plant.reset(x, seed=int(rng.integers(2**63)))

    def observe(self, x: State) -> State:
        """The poses, or the paper's positions and velocities."""
        return self.plant.paper_state if self.paper else x

    def observation_bounds(self) -> tuple[State, State]:
        """The walls and ``[-pi, pi]``; the paper's velocities within the top wheel speed."""
        if not self.paper:
            return self.low, self.high
        n, s = self.model.n_agents, self.speed
        return np.tile([self.low[0], self.low[1], -s, -s], n), np.tile(
            [self.high[0], self.high[1], s, s], n
        )

    def step_vector(self, x: State, u: npt.NDArray[np.float64]) -> tuple[State, float, bool]:
        """One sample time of the plant under wheel speeds `u`; the reward of the poses before
        it; never terminal."""
        reward = float(self.plant.reward)
        self.plant.step(u)
        return np.asarray(self.plant.poses, dtype=np.float64), reward, False

    def action_bounds(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Every wheel within ``+-max_wheel_speed``."""
        n = self.model.action_dim
        return np.full(n, -self.speed), np.full(n, self.speed)

    def info(self, x: State) -> dict[str, Any]:
        """``in_goal``, the ``sonar`` readings (one row per robot), the ``paper_state`` and
        the ``collisions`` since the start (`fuzzyq.KheperaPlant.collisions`)."""
        return {
            "in_goal": bool(self.plant.in_goal),
            "sonar": self.plant.sonar,
            "paper_state": self.plant.paper_state,
            "collisions": self.plant.collisions,
        }

    def frame(self, x: State, terminal: bool) -> Frame:
        """The arena from above (`khepera_frame`)."""
        return khepera_frame(self.params, x)


def _bounds_array(bounds: object, state_dim: int) -> npt.NDArray[np.float64]:
    """`bounds` (a ``(state_dim, 2)`` array of ``[low, high]`` rows, or a `fuzzyq.Grid`, whose
    first and last cores are used) as a float64 array, or a one-line error."""
    expected = f"bounds must be a fuzzyq.Grid or an array of shape ({state_dim}, 2) of [low, high]"
    if isinstance(bounds, fuzzyq.Grid):
        cores = bounds.cores
        if len(cores) != state_dim:
            raise fuzzyq.ConfigError(f"{expected}; got a Grid of {len(cores)} dimensions")
        return np.array([[float(np.min(c)), float(np.max(c))] for c in cores])
    try:
        array = np.array(bounds, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise fuzzyq.InputTypeError(f"{expected}; got {bounds!r}") from exc
    if array.shape != (state_dim, 2):
        raise fuzzyq.InputError(f"{expected}; got shape {array.shape}")
    if np.any(np.isnan(array)) or np.any(array[:, 0] >= array[:, 1]):
        raise fuzzyq.InputError(f"{expected} with low < high; got {array.tolist()}")
    return array


def adapt(model: object, bounds: object, observation: object = None) -> ModelAdapter:
    """The adapter of `model`, or a one-line error naming what it should be."""
    if observation is not None and not (
        isinstance(model, fuzzyq.Khepera) and observation == "paper"
    ):
        raise fuzzyq.ConfigError(
            f"observation: expected None (the state) or 'paper' (fuzzyq.Khepera only), got "
            f"{observation!r} for a {type(model).__name__}"
        )
    if isinstance(model, fuzzyq.Khepera):
        if bounds is not None:
            raise fuzzyq.ConfigError("bounds: the robots' arena bounds their state")
        return KheperaAdapter(model, observation)
    if isinstance(model, fuzzyq.PointMass | fuzzyq.ClassicModel):
        if bounds is not None:
            raise fuzzyq.ConfigError(
                f"bounds: a {type(model).__name__} has its own state bounds; "
                "bounds= is for models without them (a CallableModel)"
            )
        if isinstance(model, fuzzyq.PointMass):
            return PointMassAdapter(model)
        return ClassicAdapter(model)
    needed = ["state_dim", "n_joint_actions", "actions", "joint_action", "joint_index", "step"]
    missing = [name for name in needed if not hasattr(model, name)]
    if missing:
        raise fuzzyq.InputTypeError(
            "model must be a fuzzyq.PointMass, fuzzyq.Khepera, a classic model (DcMotor, "
            f"Pendulum, CarHill, Arm) or a fuzzyq.CallableModel; {type(model).__name__} lacks "
            f"{missing}"
        )
    state_dim = int(model.state_dim)  # type: ignore[attr-defined]
    return ModelAdapter(model, None if bounds is None else _bounds_array(bounds, state_dim))


class ModelSim:
    """An adapted model plus the episode state: what `ModelEnv` and `ModelParallelEnv` step."""

    def __init__(
        self,
        model: object,
        start: StartSpec,
        max_steps: MaxSteps,
        bounds: object,
        observation: object = None,
    ) -> None:
        self.adapter = adapt(model, bounds, observation)
        if max_steps == "default":
            self.max_steps = default_episode_steps(model)
        else:
            self.max_steps = validate_max_steps(max_steps)
        self._start_fn: Callable[[np.random.Generator], npt.ArrayLike] | None = None
        self._start: State | None = None
        if callable(start):
            self._start_fn = start
        elif start is not None:
            self._start = self.validate_state(start, "start")
        elif self.adapter.default_start(np.random.default_rng(0)) is None:
            raise fuzzyq.ConfigError(
                f"start: a {type(model).__name__} has no default start state; pass start= (a "
                "state, or a function of a numpy Generator returning one) or bounds= (to start "
                "uniformly within them)"
            )
        #: Observation bounds as float32 (rounding to nearest keeps every state inside them).
        low, high = self.adapter.observation_bounds()
        self.obs_low, self.obs_high = low.astype(OBS_DTYPE), high.astype(OBS_DTYPE)
        self.state: State | None = None
        self.steps = 0
        self.terminal = False

    # --- spaces ------------------------------------------------------------------------------

    def observation_space(self) -> spaces.Box:
        """A new Box of states: the model's bounds, unbounded where it has none."""
        return spaces.Box(
            low=self.obs_low, high=self.obs_high, shape=self.obs_low.shape, dtype=OBS_DTYPE
        )

    # --- episode -----------------------------------------------------------------------------

    def validate_state(self, x: object, what: str) -> State:
        """A copy of `x` as a float64 state, or an error naming the expected shape and range."""
        d = self.adapter.state_dim
        low, high = self.adapter.low, self.adapter.high
        expected = f"{what} must be a finite numeric array of shape ({d},)"
        if np.any(np.isfinite(low)) or np.any(np.isfinite(high)):
            expected += f" within [{low.tolist()}, {high.tolist()}]"
        try:
            array = np.array(x, dtype=np.float64)  # always a copy
        except (TypeError, ValueError) as exc:
            raise fuzzyq.InputTypeError(f"{expected}; got {x!r}") from exc
        if array.shape != (d,):
            raise fuzzyq.InputError(f"{expected}; got shape {array.shape}")
        if not np.all(np.isfinite(array)):
            raise fuzzyq.InputError(f"{expected}; got non-finite values {array.tolist()}")
        if np.any(array < low) or np.any(array > high):
            raise fuzzyq.InputError(f"{expected}; got {array.tolist()}")
        return array

    def reset(self, rng: np.random.Generator, options: Mapping[str, Any] | None) -> None:
        """Start an episode at ``options["x0"]``, else at the env's start."""
        if options is not None and not isinstance(options, Mapping):
            raise fuzzyq.InputTypeError(
                f"options must be a dict or None, got {type(options).__name__}"
            )
        x0 = None if options is None else options.get("x0")
        if x0 is not None:
            state = self.validate_state(x0, "options['x0']")
        elif self._start_fn is not None:
            state = self.validate_state(self._start_fn(rng), "the state returned by start(rng)")
        elif self._start is not None:
            state = self._start.copy()
        else:
            drawn = self.adapter.default_start(rng)
            assert drawn is not None  # checked in __init__
            state = drawn
        self.adapter.start(state, rng)
        self.state = state
        self.steps = 0
        self.terminal = False

    def require_state(self) -> State:
        """The current state; `gymnasium.error.ResetNeeded` before the first reset."""
        if self.state is None:
            raise gym_error.ResetNeeded("call reset() before step() or render()")
        return self.state

    @property
    def truncated(self) -> bool:
        """Whether the episode reached `max_steps`."""
        return self.max_steps is not None and self.steps >= self.max_steps

    def step(self, joint: int | npt.NDArray[np.float64]) -> float:
        """Apply joint action `joint` (an index, or a joint action vector; already validated);
        return the reward."""
        state = self.require_state()
        if self.terminal:
            raise gym_error.ResetNeeded("the episode reached a terminal state; call reset()")
        if self.truncated:
            raise gym_error.ResetNeeded(
                f"the episode was truncated after max_steps={self.max_steps} steps; call reset()"
            )
        if isinstance(joint, np.ndarray):
            self.state, reward, self.terminal = self.adapter.step_vector(state, joint)
        else:
            self.state, reward, self.terminal = self.adapter.step(state, joint)
        self.steps += 1
        return reward

    # --- outputs (always fresh objects) ------------------------------------------------------

    def observation(self) -> Observation:
        """A new float32 array of the state, clipped into the observation space (a terminal
        state may lie beyond the bounds: the exact state is in the info)."""
        obs = self.adapter.observe(self.require_state()).astype(OBS_DTYPE)
        np.clip(obs, self.obs_low, self.obs_high, out=obs)
        return obs

    def info(self) -> dict[str, Any]:
        """A new info dict: the exact float64 ``state`` (a copy), ``steps``, and the model's
        own entries (``in_goal`` for a `fuzzyq.PointMass`)."""
        state = self.require_state()
        return {"state": state.copy(), "steps": self.steps, **self.adapter.info(state)}

    def render_ansi(self) -> str:
        """A text picture: the step count, whether terminal, and the state."""
        state = self.require_state()
        limit = "" if self.max_steps is None else f"/{self.max_steps}"
        values = ", ".join(f"{v:+.4g}" for v in state)
        return f"step {self.steps}{limit}  terminal={self.terminal}\n  x = [{values}]\n"

    def render_rgb(self) -> Frame:
        """The ``"rgb_array"`` picture of the current state."""
        return self.adapter.frame(self.require_state(), self.terminal)

    @property
    def render_fps(self) -> float:
        """One frame per step of the model's sample time; 30 without one."""
        return 30.0 if self.adapter.sample_time is None else 1.0 / self.adapter.sample_time


class ModelBacked:
    """What `ModelEnv` and `ModelParallelEnv` read straight from their `ModelSim`."""

    _sim: ModelSim
    _rendering: Rendering
    metadata: dict[str, Any]
    render_mode: str | None

    def _init_sim(
        self,
        model: object,
        start: StartSpec,
        max_steps: MaxSteps,
        bounds: object,
        render_mode: str | None,
        observation: object = None,
    ) -> ModelAdapter:
        """Builds the simulation and the per-instance metadata; returns the adapter."""
        self._sim = ModelSim(model, start, max_steps, bounds, observation)
        self.metadata = {**type(self).metadata, "render_fps": self._sim.render_fps}
        title = f"fuzzyq {type(model).__name__}"
        self._rendering = Rendering(render_mode, self.metadata["render_modes"], title)
        self.render_mode = self._rendering.mode
        return self._sim.adapter

    def _render(self) -> Frame | str | None:
        return self._rendering.render(
            self._sim.render_rgb, self._sim.render_ansi, self.metadata["render_fps"]
        )

    @property
    def model(self) -> Any:
        """The wrapped fuzzyq model (solve it to get a policy for this env)."""
        return self._sim.adapter.model

    @property
    def max_steps(self) -> int | None:
        """Steps after which an episode is truncated (None: never)."""
        return self._sim.max_steps

    def close(self) -> None:
        """Closes the ``"human"`` window, if any (the env stays usable)."""
        self._rendering.close()
