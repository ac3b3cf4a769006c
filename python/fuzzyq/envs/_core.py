"""The simulation shared by the Gymnasium and the PettingZoo point-mass environments.

Internal: the public classes are `PointMassEnv` and `PointMassParallelEnv`. Everything that both
environments must do identically (building the model and the spaces, drawing and validating the
initial state, validating actions, stepping, observations and infos) lives here, so that the two
environments cannot drift apart.
"""

from __future__ import annotations

import operator
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import numpy.typing as npt
from gymnasium import error as gym_error
from gymnasium import spaces

import fuzzyq

from ._render import Frame, HumanViewer, point_mass_frame, require_matplotlib

#: Observations are float32 (what Gymnasium prefers); the simulation itself stays float64.
OBS_DTYPE = np.float32

Observation = npt.NDArray[np.float32]
State = npt.NDArray[np.float64]


def agent_name(i: int) -> str:
    """The PettingZoo name of agent `i`: ``"agent_0"``, ``"agent_1"``, ..."""
    return f"agent_{i}"


def validate_render_mode(render_mode: str | None, modes: list[str]) -> str | None:
    """`render_mode` must be None or one of `modes`; ``"human"`` also needs matplotlib."""
    if render_mode is not None and render_mode not in modes:
        raise fuzzyq.InputError(f"render_mode must be None or one of {modes}, got {render_mode!r}")
    if render_mode == "human":
        require_matplotlib()
    return render_mode


class Rendering:
    """An environment's `render_mode` and what it takes to honour it (the ``"human"`` window)."""

    def __init__(self, render_mode: str | None, modes: list[str], title: str) -> None:
        self.mode = validate_render_mode(render_mode, modes)
        self.viewer = HumanViewer(title) if self.mode == "human" else None

    def render(
        self, frame: Callable[[], Frame], text: Callable[[], str], fps: float
    ) -> Frame | str | None:
        """What `render` returns: `frame()` for ``"rgb_array"``, `text()` for ``"ansi"``, None
        otherwise (``"human"`` shows `frame()` in its window first)."""
        if self.mode == "rgb_array":
            return frame()
        if self.mode == "ansi":
            return text()
        if self.viewer is not None:
            self.viewer.show(frame(), fps)
        return None

    def close(self) -> None:
        """Closes the ``"human"`` window, if any."""
        if self.viewer is not None:
            self.viewer.close()


def validate_max_steps(max_steps: object) -> int | None:
    """`max_steps` must be a positive int or None (never truncate)."""
    if max_steps is None:
        return None
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)):
        raise fuzzyq.InputTypeError(
            f"max_steps must be a positive int or None, got {type(max_steps).__name__}"
        )
    if max_steps < 1:
        raise fuzzyq.InputError(f"max_steps must be a positive int or None, got {max_steps}")
    return int(max_steps)


def validate_index(action: object, n: int, what: str) -> int:
    """An action index as a Python int in ``[0, n)``.

    Accepts what `gymnasium.spaces.Discrete(n)` contains: Python ints, NumPy integer scalars and
    0-d integer arrays. Booleans, floats (even integral ones), strings and other arrays raise
    `fuzzyq.InputTypeError` (a `TypeError`); integers out of range raise `fuzzyq.InputError`
    (a `ValueError`).
    """
    if isinstance(action, np.ndarray) and action.shape == () and action.dtype.kind in "iu":
        action = action.item()
    if isinstance(action, (bool, np.bool_)) or not isinstance(action, (int, np.integer)):
        raise fuzzyq.InputTypeError(
            f"{what} must be an integer in [0, {n}) (Discrete({n})), "
            f"got {type(action).__name__}: {action!r}"
        )
    index = operator.index(action)
    if not 0 <= index < n:
        raise fuzzyq.InputError(
            f"{what} must be an integer in [0, {n}) (Discrete({n})), got {index}"
        )
    return index


class PointMassSim:
    """A `fuzzyq.PointMass` plus the episode state: what both environments step."""

    def __init__(self, max_steps: int | None, model_kwargs: dict[str, Any]) -> None:
        self.model = fuzzyq.PointMass(**model_kwargs)
        self.max_steps = validate_max_steps(max_steps)
        model = self.model
        per_agent = [model.position_limit] * 2 + [model.velocity_limit] * 2
        #: Elementwise bound of the state (the model clamps to it).
        self.high = np.tile(np.asarray(per_agent, dtype=np.float64), model.n_agents)
        # Bounds given as float32 so that `Box` does not warn about lowered precision. Rounding to
        # nearest is monotonic, so float32(x) <= float32(limit) for every state x <= limit: every
        # observation is inside the space.
        self.obs_high = self.high.astype(OBS_DTYPE)
        self.state: State | None = None
        self.steps = 0

    # --- spaces ------------------------------------------------------------------------------

    def observation_space(self) -> spaces.Box:
        """A new Box of joint observations (each caller caches its own)."""
        return spaces.Box(
            low=-self.obs_high, high=self.obs_high, shape=self.obs_high.shape, dtype=OBS_DTYPE
        )

    # --- episode -----------------------------------------------------------------------------

    def reset(self, rng: np.random.Generator, options: Mapping[str, Any] | None) -> None:
        """Start an episode: ``options["x0"]`` if given, else random positions, zero velocity."""
        if options is not None and not isinstance(options, Mapping):
            raise fuzzyq.InputTypeError(
                f"options must be a dict or None, got {type(options).__name__}"
            )
        x0 = None if options is None else options.get("x0")
        if x0 is None:
            n = self.model.n_agents
            limit = self.model.position_limit
            state = np.zeros((n, 4), dtype=np.float64)
            state[:, :2] = rng.uniform(-limit, limit, size=(n, 2))
            self.state = state.reshape(-1)
        else:
            self.state = self.validate_state(x0, "options['x0']")
        self.steps = 0

    def validate_state(self, x: object, what: str) -> State:
        """A copy of `x` as a float64 state, or an error naming the expected shape and range."""
        d = self.model.state_dim
        expected = (
            f"{what} must be a finite numeric array of shape ({d},) laid out as "
            f"[s1x, s1y, v1x, v1y, ...], with |position| <= {self.model.position_limit} and "
            f"|velocity| <= {self.model.velocity_limit}"
        )
        try:
            array = np.array(x, dtype=np.float64)  # always a copy
        except (TypeError, ValueError) as exc:
            raise fuzzyq.InputTypeError(f"{expected}; got {x!r}") from exc
        if array.shape != (d,):
            raise fuzzyq.InputError(f"{expected}; got shape {array.shape}")
        if not np.all(np.isfinite(array)):
            raise fuzzyq.InputError(f"{expected}; got non-finite values {array.tolist()}")
        if np.any(np.abs(array) > self.high):
            raise fuzzyq.InputError(f"{expected}; got {array.tolist()}")
        return array

    def require_state(self) -> State:
        if self.state is None:
            raise gym_error.ResetNeeded("call reset() before step() or render()")
        return self.state

    @property
    def truncated(self) -> bool:
        return self.max_steps is not None and self.steps >= self.max_steps

    def step(self, joint_index: int) -> float:
        """Apply joint action `joint_index` (already validated); return the reward rho(x, u).

        The reward is evaluated at the state before the step, as in the paper.
        """
        state = self.require_state()
        if self.truncated:
            raise gym_error.ResetNeeded(
                f"the episode was truncated after max_steps={self.max_steps} steps; call reset()"
            )
        force = self.model.joint_action(joint_index)
        reward = float(self.model.reward(state, force))
        self.state = np.asarray(self.model.step(state, force), dtype=np.float64)
        self.steps += 1
        return reward

    # --- outputs (always fresh objects) ------------------------------------------------------

    def observation(self) -> Observation:
        """A new float32 array of the joint state, clipped into the observation space."""
        obs = self.require_state().astype(OBS_DTYPE)
        np.clip(obs, -self.obs_high, self.obs_high, out=obs)
        return obs

    def info(self) -> dict[str, Any]:
        """A new info dict: ``in_goal``, the exact float64 ``state`` (a copy) and ``steps``."""
        state = self.require_state()
        return {
            "in_goal": bool(self.model.in_goal(state)),
            "state": state.copy(),
            "steps": self.steps,
        }

    def render_ansi(self, names: list[str], max_steps: int | None) -> str:
        """A one-line-per-agent text picture of the current state (the step count shows
        `max_steps` unless it is None: then a wrapper's TimeLimit may truncate)."""
        state = self.require_state()
        limit = "" if max_steps is None else f"/{max_steps}"
        lines = [f"step {self.steps}{limit}  in_goal={bool(self.model.in_goal(state))}"]
        for name, (sx, sy, vx, vy) in zip(names, state.reshape(-1, 4), strict=True):
            lines.append(f"  {name}: s=({sx:+.3f}, {sy:+.3f}) v=({vx:+.3f}, {vy:+.3f})")
        return "\n".join(lines) + "\n"

    def render_rgb(self) -> Frame:
        """The ``"rgb_array"`` picture of the current state (see `point_mass_frame`)."""
        return point_mass_frame(self.model, self.require_state())


class SimBacked:
    """What both environments read straight from their `PointMassSim`."""

    _sim: PointMassSim
    _rendering: Rendering
    metadata: dict[str, Any]
    render_mode: str | None

    def _init_sim(
        self, max_steps: int | None, render_mode: str | None, model_kwargs: dict[str, Any]
    ) -> fuzzyq.PointMass:
        """Builds the simulation and the per-instance metadata; returns the model."""
        self._sim = PointMassSim(max_steps, model_kwargs)
        model = self._sim.model
        # Per-instance metadata: frames are one sample time apart.
        self.metadata = {**type(self).metadata, "render_fps": 1.0 / model.sample_time}
        self._rendering = Rendering(render_mode, self.metadata["render_modes"], "fuzzyq point mass")
        self.render_mode = self._rendering.mode
        return model

    def _render(self, names: list[str], max_steps: int | None) -> Frame | str | None:
        return self._rendering.render(
            self._sim.render_rgb,
            lambda: self._sim.render_ansi(names, max_steps),
            self.metadata["render_fps"],
        )

    def close(self) -> None:
        """Closes the ``"human"`` window, if any (the env stays usable)."""
        self._rendering.close()

    @property
    def model(self) -> fuzzyq.PointMass:
        """The `fuzzyq.PointMass` being simulated (solve it to get a policy for this env)."""
        return self._sim.model

    @property
    def max_steps(self) -> int | None:
        """Steps after which an episode is truncated, for every agent (None: never)."""
        return self._sim.max_steps
