"""The point-mass task as a Gymnasium environment with a joint observation and joint actions."""

from __future__ import annotations

from typing import Any, cast

import gymnasium
import numpy as np
from gymnasium import spaces

import fuzzyq

from ._core import (
    Observation,
    SimBacked,
    agent_name,
    validate_index,
)
from ._render import RENDER_MODES, Frame


class PointMassEnv(SimBacked, gymnasium.Env[Observation, np.int64]):
    """The paper's point-mass task (Luviano-Cruz et al. 2018, section 3.1) as a Gymnasium env.

    One environment drives all agents: the observation is the joint state and the action is a
    joint action index. Registered as ``"FuzzyQ/PointMass-v0"`` by ``import fuzzyq`` (when
    gymnasium is installed), with ``max_episode_steps=75``: ``gymnasium.make(
    "FuzzyQ/PointMass-v0", agents=1)`` truncates after 75 steps (Gymnasium's `TimeLimit`
    wrapper; the made env has ``max_steps=None``) and ``gymnasium.make(...,
    max_episode_steps=200)`` after 200. Built directly, ``PointMassEnv(max_steps=...)``
    truncates on its own.

    Args:
        max_steps: the episode is truncated after this many steps (default 75, the paper's 30 s
            at the default sample time of 0.4 s); None never truncates (what
            `gymnasium.make` passes: its `TimeLimit` truncates instead).
        render_mode: None, ``"rgb_array"`` (`render` returns a ``(400, 400, 3)`` uint8 picture
            of the arena, the goal and the agents: see `fuzzyq.envs.PointMassEnv.render`),
            ``"human"`` (the same picture in a matplotlib window, updated on every `reset` and
            `step` at ``metadata["render_fps"]``; needs ``pip install matplotlib``) or
            ``"ansi"`` (`render` returns a text picture of the state).
        **model_kwargs: passed to `fuzzyq.PointMass` (``agents=2``, ``mass``, ``sample_time``,
            ``position_limit``, ``velocity_limit``, ``force_levels``, ``goal_radius``,
            ``goal_reward``, ``integrator``, ``rk4_substeps``, ``friction``,
            ``friction_patches``); invalid options raise the model's errors.

    Spaces:
        observation_space: ``Box(-limits, limits, (4 * agents,), float32)`` where `limits` is
            ``[position_limit, position_limit, velocity_limit, velocity_limit]`` per agent. The
            state layout is ``[s1x, s1y, v1x, v1y, s2x, s2y, v2x, v2y, ...]``. Observations are
            float32 copies of the float64 state; the exact state is in ``info["state"]``.
        action_space: ``Discrete(model.n_joint_actions)`` (``25**agents`` with the default
            `force_levels`: 25 force pairs per agent). Index `i` applies the forces
            ``model.joint_action(i)``; ``model.agent_indices(i)`` and
            ``model.joint_index(per_agent)`` convert to and from per-agent indices (agent 0
            most significant).

    Semantics:
        reset(seed=None, options=None): seeds `np_random` when `seed` is given; positions are
            drawn uniformly from the position box and velocities are zero, unless
            ``options={"x0": state}`` sets the initial state exactly (a ``(4 * agents,)`` array
            within the limits; anything else raises `fuzzyq.InputError` (a ValueError) or
            `fuzzyq.InputTypeError` (a TypeError)). Other option keys are ignored.
        step(action): next state ``model.step(x, model.joint_action(action))``; reward
            ``model.reward(x)`` evaluated at the state *before* the step (the paper's rho(x, u):
            `goal_reward` while the whole state is within `goal_radius` of the origin).
            `terminated` is always False: the task is continuing and keeps paying in the goal.
            `truncated` is True on the `max_steps`-th step; stepping further (or before `reset`)
            raises `gymnasium.error.ResetNeeded`. Invalid actions raise `fuzzyq.InputError` (out
            of range, a ValueError) or `fuzzyq.InputTypeError` (not an integer, a TypeError).
        info (reset and step): ``"in_goal"``: whether the returned observation's state is in the
            goal (so the next step pays `goal_reward`); ``"state"``: a float64 copy of the exact
            state; ``"steps"``: steps taken in this episode.

    Every returned observation and info is a new object: mutating it never changes the env.

    To run a greedy policy from `fuzzyq.solve` (on ``env.unwrapped.model``), the joint action is
    ``policy.act_index(observation)``.
    """

    #: ``render_fps`` is that of the default sample time; each instance's is
    #: ``1 / sample_time``, one frame per step.
    metadata: dict[str, Any] = {"render_modes": list(RENDER_MODES), "render_fps": 2.5}

    def __init__(
        self, *, max_steps: int | None = 75, render_mode: str | None = None, **model_kwargs: Any
    ) -> None:
        model = self._init_sim(max_steps, render_mode, model_kwargs)
        self.observation_space = cast("spaces.Space[Observation]", self._sim.observation_space())
        self.action_space = spaces.Discrete(model.n_joint_actions)
        self._names = [agent_name(i) for i in range(model.n_agents)]

    @property
    def state(self) -> np.ndarray | None:
        """A float64 copy of the current state, or None before the first reset."""
        return None if self._sim.state is None else self._sim.state.copy()

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Observation, dict[str, Any]]:
        """Start an episode; see the class docstring for `options`."""
        super().reset(seed=seed)
        self._sim.reset(self.np_random, options)
        if self.render_mode == "human":
            self.render()
        return self._sim.observation(), self._sim.info()

    def step(self, action: Any) -> tuple[Observation, float, bool, bool, dict[str, Any]]:
        """Apply joint action index `action`; see the class docstring."""
        index = validate_index(action, self._sim.model.n_joint_actions, "action")
        reward = self._sim.step(index)
        if self.render_mode == "human":
            self.render()
        return self._sim.observation(), reward, False, self._sim.truncated, self._sim.info()

    def render(self) -> Frame | str | None:
        """A picture of the current state, as `render_mode` asks.

        Returns:
            For ``"rgb_array"``, a new ``(400, 400, 3)`` uint8 image: the arena (the position
            limits) as a grey square with a dark border, y pointing up; the goal region as a
            green disc at the origin (at least 5 pixels in radius); agent `i` as a disc of
            colour ``fuzzyq.envs.AGENT_COLOURS[i]`` with a darker tick along its velocity,
            longer the faster it moves. For ``"ansi"``, one line for the step count and one per
            agent. None for ``"human"`` (the picture goes to the window) and for None.

        Raises:
            gymnasium.error.ResetNeeded: before the first `reset` (with a render mode).
        """
        return self._render(self._names, self.max_steps)
