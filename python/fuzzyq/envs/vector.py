"""`ModelVectorEnv`: many copies of a fuzzyq model stepped together, natively vectorised.

Every step of all copies is one call: for a built-in model into Rust (``_step_batch``, with
the GIL released), for a `fuzzyq.CallableModel` into its own vectorised function. The
registered ids use it as their ``vector_entry_point``, so
``gymnasium.make_vec("FuzzyQ/DcMotor-v0", num_envs=64)`` builds one.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
import numpy.typing as npt
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

import fuzzyq
from fuzzyq._fuzzyq import _step_batch
from fuzzyq._gym_ids import EPISODE_STEPS

from ._core import OBS_DTYPE
from .model_env import ContinuousModelEnv, ModelEnv

Batch = npt.NDArray[np.float64]


class ModelVectorEnv(gymnasium.vector.VectorEnv[Any, Any, Any]):
    """`num_envs` copies of `ModelEnv` (or `ContinuousModelEnv`) stepped as one batch.

    Spaces, starts, rewards, termination and truncation are those of the single environment;
    the copies reset on the step after they end (Gymnasium's ``NEXT_STEP`` autoreset: that
    step returns the new start with reward 0). ``infos`` is empty.

    Args:
        model: a `fuzzyq.PointMass`, a classic benchmark or a `fuzzyq.CallableModel`.
        num_envs: number of copies.
        continuous: joint action vectors (`ContinuousModelEnv`'s `Box`) instead of indices.
        **kwargs: `ModelEnv`'s keyword arguments (`start`, `max_steps`, `bounds`).

    Raises:
        fuzzyq.ConfigError: ``num_envs`` below 1, or the `fuzzyq.Khepera` robots.
    """

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, model: Any, num_envs: int, *, continuous: bool = False, **kwargs: Any):
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise fuzzyq.ConfigError(f"num_envs: expected a positive integer, got {num_envs!r}")
        if isinstance(model, fuzzyq.Khepera):
            raise fuzzyq.ConfigError(
                "model: the robots' rapier plant is stateful and has no native vector; use "
                "gymnasium.vector.SyncVectorEnv (gymnasium.make_vec does for their ids)"
            )
        single = (ContinuousModelEnv if continuous else ModelEnv)(model, **kwargs)
        self._sim = single._sim
        self.num_envs = num_envs
        self.single_observation_space = single.observation_space
        self.single_action_space = single.action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        adapter = self._sim.adapter
        self._continuous = continuous
        self._vectors = adapter.joint_vectors()
        self._action_low, self._action_high = self._vectors.min(axis=0), self._vectors.max(axis=0)
        self._builtin = isinstance(model, (fuzzyq.PointMass, fuzzyq.ClassicModel))
        self._states = np.zeros((num_envs, adapter.state_dim))
        self._steps = np.zeros(num_envs, dtype=np.int64)
        self._ended = np.zeros(num_envs, dtype=bool)

    @property
    def model(self) -> Any:
        """The wrapped fuzzyq model."""
        return self._sim.adapter.model

    def _restart(self, copies: npt.NDArray[np.intp]) -> None:
        """Starts `copies` anew, drawing their starts as the single environment does."""
        for i in copies:
            self._sim.reset(self.np_random, None)
            assert self._sim.state is not None
            self._states[i] = self._sim.state
        self._steps[copies] = 0
        self._ended[copies] = False

    def _observations(self) -> npt.NDArray[np.float32]:
        obs = self._states.astype(OBS_DTYPE)
        np.clip(obs, self._sim.obs_low, self._sim.obs_high, out=obs)
        return obs

    def reset(
        self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[npt.NDArray[np.float32], dict[str, Any]]:
        """Starts every copy (drawing the starts from `np_random`, seeded by `seed`).

        Args:
            seed: seeds `np_random` (an int; a list's first entry).
            options: unused.

        Returns:
            The observations, shape ``(num_envs, state_dim)``, and an empty info dict.
        """
        if isinstance(seed, list):
            seed = seed[0] if seed else None
        if seed is not None:
            self._np_random, self._np_random_seed = gymnasium.utils.seeding.np_random(seed)
        self._restart(np.arange(self.num_envs))
        return self._observations(), {}

    def _joint_vectors(self, actions: Any) -> Batch:
        """The copies' joint action vectors, or a one-line error."""
        a = np.asarray(actions)
        if self._continuous:
            u = np.asarray(a, dtype=np.float64).reshape(self.num_envs, -1)
            if u.shape[1] != len(self._action_low) or not np.all(np.isfinite(u)):
                raise fuzzyq.InputError(
                    f"actions: expected ({self.num_envs}, {len(self._action_low)}) finite "
                    f"joint action vectors, got shape {a.shape}"
                )
            return np.clip(u, self._action_low, self._action_high)
        if a.shape != (self.num_envs,) or a.dtype.kind not in "iu":
            raise fuzzyq.InputError(
                f"actions: expected {self.num_envs} joint action indices, got {a!r}"
            )
        if np.any(a < 0) or np.any(a >= len(self._vectors)):
            raise fuzzyq.InputError(
                f"actions: indices must lie in [0, {len(self._vectors)}), got {a.tolist()}"
            )
        return np.asarray(self._vectors[a], dtype=np.float64)

    def _transitions(self, x: Batch, u: Batch) -> tuple[Batch, Batch, npt.NDArray[np.bool_]]:
        """The rows' next states, rewards and terminal flags, in one call."""
        if self._builtin:
            return _step_batch(self.model, x, u)
        out = self.model.transition(x, u)
        next_states = np.asarray(out[0], dtype=np.float64)
        rewards = np.asarray(out[1], dtype=np.float64)
        terminal = np.asarray(out[2], dtype=bool) if len(out) > 2 else np.zeros(len(x), bool)
        return next_states, rewards, terminal

    def step(
        self, actions: Any
    ) -> tuple[
        npt.NDArray[np.float32], Batch, npt.NDArray[np.bool_], npt.NDArray[np.bool_], dict[str, Any]
    ]:
        """Steps every copy: the ones that ended on the previous step restart instead.

        Args:
            actions: ``(num_envs,)`` joint action indices, or ``(num_envs, action_dim)``
                joint action vectors for the continuous variant.

        Returns:
            ``(observations, rewards, terminations, truncations, infos)`` of the batch.
        """
        u = self._joint_vectors(actions)
        rewards = np.zeros(self.num_envs)
        terminated = np.zeros(self.num_envs, dtype=bool)
        live = np.flatnonzero(~self._ended)
        self._restart(np.flatnonzero(self._ended))
        if len(live):
            nx, r, term = self._transitions(self._states[live], u[live])
            self._states[live] = nx
            rewards[live] = r
            terminated[live] = term
            self._steps[live] += 1
        limit = self._sim.max_steps
        truncated = np.zeros(self.num_envs, dtype=bool)
        if limit is not None:
            truncated[live] = self._steps[live] >= limit
        self._ended = terminated | truncated
        return self._observations(), rewards, terminated, truncated, {}


def make_vector(
    num_envs: int = 1,
    *,
    env: str = "pointmass",
    continuous: bool = False,
    max_episode_steps: int | None = None,
    max_steps: int | None = None,
    start: Any = None,
    render_mode: str | None = None,
    **model_kwargs: Any,
) -> ModelVectorEnv:
    """The vector entry point of the registered ids (``gymnasium.make_vec`` calls it).

    Args:
        num_envs: number of copies.
        env: the environment's name.
        continuous: the continuous-action variant.
        max_episode_steps: the episode length (default: the id's, that of ``fuzzyq
            rollout``).
        max_steps: the single environment's spelling of the same (the point masses' id).
        start: the episodes' start (see `ModelEnv`).
        render_mode: must be None (a vector of copies does not render).
        **model_kwargs: the model constructor's keyword arguments.

    Returns:
        The vector environment.
    """
    from .registry import MODELS

    if render_mode is not None:
        raise fuzzyq.ConfigError("render_mode: the vector environments do not render")
    if env not in MODELS:
        raise fuzzyq.ConfigError(f"env: expected one of {sorted(MODELS)}, got {env!r}")
    steps = max_episode_steps or max_steps or EPISODE_STEPS[env]
    model = MODELS[env](**model_kwargs)
    return ModelVectorEnv(model, num_envs, continuous=continuous, start=start, max_steps=steps)
