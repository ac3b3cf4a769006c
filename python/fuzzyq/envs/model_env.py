"""Any fuzzyq model as a Gymnasium environment with joint actions."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal, cast

import gymnasium
import numpy as np
import numpy.typing as npt
from gymnasium import spaces

import fuzzyq

from ._core import Observation, validate_index
from ._model_sim import ModelBacked
from ._render import RENDER_MODES, Frame


class ModelEnv(ModelBacked, gymnasium.Env[Observation, np.int64]):
    """Any fuzzyq model as a Gymnasium `Env`: the observation is the model's state and the
    action a joint action index.

    Works with `fuzzyq.PointMass`, the classic benchmarks (`fuzzyq.DcMotor`,
    `fuzzyq.Pendulum`, `fuzzyq.CarHill`, `fuzzyq.Arm`), the `fuzzyq.Khepera` robots (on their
    rapier plant, a `fuzzyq.KheperaPlant`: contacts, sonars and noise, as ``fuzzyq rollout``
    runs them) and `fuzzyq.CallableModel` (which needs its ``step``, ``actions`` and
    ``joint_index``). A policy from ``fuzzyq.solve(model, grid)``
    drives it: the action is ``policy.act_index(observation)``.

    >>> import fuzzyq, fuzzyq.envs
    >>> env = fuzzyq.envs.ModelEnv(fuzzyq.CarHill())
    >>> obs, info = env.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = env.step(1)

    Args:
        model: the model to simulate (kept, not copied: `model` returns it).
        start: the start state of every episode, a ``(state_dim,)`` array; or a function
            ``start(rng) -> state`` called by each `reset` with the env's `np_random` (a
            `numpy.random.Generator`). Default (None): the model's own start — random
            positions at rest for `fuzzyq.PointMass` (as `PointMassEnv`), ``model.default_start``
            for a classic model, ``model.random_starts`` for the robots, uniform within
            `bounds` for a `CallableModel` (which needs `start` or `bounds`). A start must lie
            within the state bounds (for the robots: poses clear of walls, obstacles and each
            other).
        max_steps: the episode is truncated after this many steps; None never truncates;
            ``"default"`` (the default) uses `default_episode_steps(model)`: the length of a
            ``fuzzyq rollout`` (75 for the point masses, 400 for the DC motor, 600 for the
            pendulum, 100 for the car, 200 for the arm, 250 for the robots) and None for a
            `CallableModel`.
        bounds: for a `CallableModel` only (the other models know theirs): the state bounds, a
            ``(state_dim, 2)`` array of ``[low, high]`` rows or a `fuzzyq.Grid` (its first and
            last cores). They bound the observation space and the default start.
        render_mode: None, ``"rgb_array"``, ``"human"`` (a matplotlib window, updated on every
            `reset` and `step`; needs ``pip install matplotlib``) or ``"ansi"``. See `render`.
        observation: None observes the state; ``"paper"`` (the robots only) observes the
            paper's ``[s_x, s_y, v_x, v_y]`` per robot (velocity: displacement over the last
            sample time) instead of the poses ``[x, y, heading]``.

    Raises:
        fuzzyq.InputTypeError: `model` is not a fuzzyq model, or an argument has a wrong type.
        fuzzyq.ConfigError: no start is known (a `CallableModel` without `start` or
            `bounds`), `bounds` given for a model with its own, or ``observation="paper"``
            for a model other than the robots.
        fuzzyq.InputError: `start`, `bounds`, `max_steps` or `render_mode` has a bad value.
        ImportError: ``render_mode="human"`` without matplotlib.

    Spaces:
        observation_space: ``Box(low, high, (state_dim,), float32)``: the position and velocity
            limits of a `PointMass`, ``model.state_bounds`` of a classic model (rows
            ``[low, high]``), the walls and ``[-pi, pi]`` for the robots' poses (their top
            wheel speed bounds the paper's velocities), `bounds` of a `CallableModel`
            (unbounded without them).
            Observations are float32 copies of the float64 state, clipped into the box (a
            terminal state of the car lies beyond it); the exact state is in ``info["state"]``.
        action_space: ``Discrete(model.n_joint_actions)``: index `i` applies
            ``model.joint_action(i)`` (per-agent indices combine with agent 0 most
            significant, as ``model.joint_index`` does).

    Semantics:
        reset(seed=None, options=None): seeds `np_random` when `seed` is given and starts at
            ``options["x0"]`` if given (validated like `start`), else at `start`.
        step(action): the model's transition. The reward is the model's: ``model.reward(x)`` of
            the state before the step for a `PointMass` (the paper's rho) and the robots (the
            plant's `fuzzyq.KheperaPlant.reward`), the reward of ``model.step(x, u)`` for the
            others. `terminated` is True when the next state is
            terminal (``model.is_terminal`` of a classic model, the third value of a
            `CallableModel`'s step; never for a `PointMass`); `truncated` on the `max_steps`-th
            step. Stepping after either (or before `reset`) raises
            `gymnasium.error.ResetNeeded`; invalid actions raise `fuzzyq.InputError` (out of
            range) or `fuzzyq.InputTypeError` (not an integer).
        info: ``"state"`` (a float64 copy of the exact state), ``"steps"`` (steps taken in this
            episode), for a `PointMass` ``"in_goal"``, and for the robots ``"in_goal"``,
            ``"sonar"`` (readings in m, one row per robot), ``"paper_state"`` and
            ``"collisions"`` (`fuzzyq.KheperaPlant.collisions`).
        metadata["render_fps"]: one frame per sample time (``1 / model.sample_time``; 30 for a
            `CallableModel`).
    """

    metadata: dict[str, Any] = {"render_modes": list(RENDER_MODES), "render_fps": 30.0}

    def __init__(
        self,
        model: fuzzyq.PointMass | fuzzyq.ClassicModel | fuzzyq.Khepera | fuzzyq.CallableModel,
        *,
        start: npt.ArrayLike | Callable[[np.random.Generator], npt.ArrayLike] | None = None,
        max_steps: int | Literal["default"] | None = "default",
        bounds: npt.ArrayLike | fuzzyq.Grid | None = None,
        render_mode: str | None = None,
        observation: Literal["paper"] | None = None,
    ) -> None:
        adapter = self._init_sim(model, start, max_steps, bounds, render_mode, observation)
        self.observation_space = cast("spaces.Space[Observation]", self._sim.observation_space())
        self.action_space = spaces.Discrete(adapter.n_joint_actions)

    @property
    def state(self) -> np.ndarray | None:
        """A float64 copy of the current state, or None before the first reset."""
        return None if self._sim.state is None else self._sim.state.copy()

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Observation, dict[str, Any]]:
        """Start an episode.

        Args:
            seed: seeds `np_random` (and so the start drawn from it).
            options: ``{"x0": state}`` starts exactly at `state`; other keys are ignored.

        Returns:
            The first observation and info.
        """
        super().reset(seed=seed)
        self._sim.reset(self.np_random, options)
        if self.render_mode == "human":
            self.render()
        return self._sim.observation(), self._sim.info()

    def step(self, action: Any) -> tuple[Observation, float, bool, bool, dict[str, Any]]:
        """Apply joint action index `action`.

        Args:
            action: an integer in ``[0, n_joint_actions)``.

        Returns:
            ``(observation, reward, terminated, truncated, info)``; see the class docstring.
        """
        return self._apply(validate_index(action, self._sim.adapter.n_joint_actions, "action"))

    def _apply(
        self, joint: int | npt.NDArray[np.float64]
    ) -> tuple[Observation, float, bool, bool, dict[str, Any]]:
        """Steps the simulation under a validated joint action (index or vector)."""
        reward = self._sim.step(joint)
        if self.render_mode == "human":
            self.render()
        truncated = self._sim.truncated
        return self._sim.observation(), reward, self._sim.terminal, truncated, self._sim.info()

    def render(self) -> Frame | str | None:
        """A picture of the current state, as `render_mode` asks.

        Returns:
            For ``"rgb_array"``, a new uint8 image: for a `PointMass` the ``(400, 400, 3)``
            arena of `PointMassEnv.render`; for any other model a ``(40 * state_dim + 20,
            400, 3)`` picture with one gauge per state variable (a marker of colour
            ``AGENT_COLOURS[d]`` on a track spanning the variable's bounds, at
            ``(1 + tanh(x_d)) / 2`` of it when unbounded; a red border in a terminal state).
            For ``"ansi"``, the step count and the state as text. None for ``"human"`` (the
            picture goes to the window) and for None.

        Raises:
            gymnasium.error.ResetNeeded: before the first `reset` (with a render mode).
        """
        return self._render()


class ContinuousModelEnv(ModelEnv):
    """`ModelEnv` with continuous actions: the joint action vector itself.

    The action space is ``Box(low, high, (action_dim,), float32)``, each component's range
    over the model's joint actions (the point masses' forces, the DC motor's and the
    pendulum's voltages, the car's force, the arm's torques). An action is clipped into the
    box and applied as given (the robots' box is every wheel within ``+-max_wheel_speed``),
    so the interpolated policy (the paper's eq 22,
    ``solution.policy("interpolated").act(x)``) and continuous-control learners act here.
    Everything else (observations, rewards, termination, starts, rendering) is `ModelEnv`'s.

    >>> import fuzzyq, fuzzyq.envs
    >>> env = fuzzyq.envs.ContinuousModelEnv(fuzzyq.DcMotor())
    >>> obs, info = env.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = env.step([2.5])

    Args:
        model: the model to simulate (a `fuzzyq.PointMass`, a classic benchmark or a
            `fuzzyq.CallableModel`, whose function must accept any action vector).
        **kwargs: `ModelEnv`'s keyword arguments.

    Raises:
        fuzzyq.InputTypeError: an action that is not a numeric vector (from `step`).
        fuzzyq.InputError: an action of the wrong length or with non-finite values.
    """

    def __init__(self, model: Any, **kwargs: Any) -> None:
        super().__init__(model, **kwargs)
        low, high = self._sim.adapter.action_bounds()
        self._action_bounds = (low, high)
        box = spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
        self.action_space = cast("spaces.Space[np.int64]", box)

    def step(self, action: Any) -> tuple[Observation, float, bool, bool, dict[str, Any]]:
        """Apply joint action vector `action`, clipped into the action box.

        Args:
            action: ``action_dim`` finite numbers.

        Returns:
            ``(observation, reward, terminated, truncated, info)``, as `ModelEnv.step`.
        """
        low, high = self._action_bounds
        expected = f"action must be {len(low)} finite numbers (a joint action vector)"
        try:
            u = np.array(action, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise fuzzyq.InputTypeError(f"{expected}, got {action!r}") from exc
        if u.shape != low.shape or not np.all(np.isfinite(u)):
            raise fuzzyq.InputError(f"{expected}, got {np.asarray(action).tolist()}")
        return self._apply(np.clip(u, low, high))
