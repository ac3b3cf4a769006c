"""Any fuzzyq model as a PettingZoo parallel environment: one agent per agent of the model."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from gymnasium import error as gym_error
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv  # type: ignore[import-untyped, unused-ignore]

import fuzzyq

from ._core import Observation, agent_name, validate_index
from ._model_sim import ModelBacked
from ._render import RENDER_MODES, Frame


class ModelParallelEnv(
    ModelBacked,
    ParallelEnv[str, Observation, int],  # type: ignore[misc, unused-ignore]
):
    """Any fuzzyq model as a PettingZoo `ParallelEnv`: each of the model's agents is an agent.

    The agents are ``"agent_0"``, ``"agent_1"``, ... (`possible_agents`; one for a classic
    model). Every agent observes the whole state and all share one reward, as in the paper;
    agent `i` chooses from ``Discrete(n_i)``, its own action set (``model.n_actions`` for a
    `fuzzyq.PointMass`, ``len(model.actions[i])`` for a `fuzzyq.CallableModel`, all actions of
    a classic model). The joint action is ``model.joint_index([a_0, a_1, ...])`` (agent 0 most
    significant), so a trajectory is the one `ModelEnv` takes with that joint index.

    >>> import fuzzyq, fuzzyq.envs
    >>> env = fuzzyq.envs.ModelParallelEnv(fuzzyq.PointMass(agents=2), max_steps=5)
    >>> observations, infos = env.reset(seed=0)
    >>> observations, rewards, terms, truncs, infos = env.step({"agent_0": 3, "agent_1": 20})

    Args:
        model: the model to simulate; see `ModelEnv`.
        start: the start state, or a function ``start(rng) -> state``; see `ModelEnv`.
        max_steps: truncation after this many steps; ``"default"``, None or an int; see
            `ModelEnv`.
        bounds: the state bounds of a `CallableModel`; see `ModelEnv`.
        render_mode: None, ``"rgb_array"``, ``"human"`` or ``"ansi"``; see `ModelEnv.render`.

    Raises:
        fuzzyq.InputTypeError: `model` is not a fuzzyq model, or an argument has a wrong type.
        fuzzyq.ConfigError: no start is known, or `bounds` given for a model with its own.
        fuzzyq.InputError: `start`, `bounds`, `max_steps` or `render_mode` has a bad value.
        ImportError: ``render_mode="human"`` without matplotlib.

    Semantics:
        reset(seed=None, options=None): as `ModelEnv.reset` (``options={"x0": state}``),
            returning the same observation (a fresh float32 copy) and info for every agent.
        step(actions): `actions` maps every live agent to its action index. Every agent gets
            the shared reward; on a terminal state every termination is True, on the
            `max_steps`-th step every truncation, and `agents` becomes empty. Missing, unknown
            or invalid actions raise `fuzzyq.InputError` / `fuzzyq.InputTypeError`; stepping
            with no live agents raises `gymnasium.error.ResetNeeded`.
        infos: as `ModelEnv`'s, one fresh dict per agent.
        state(): a fresh float32 copy of the state, in `state_space`.

    `observation_space(agent)` and `action_space(agent)` return the same object on every call
    (one per agent, so each can be seeded on its own).
    """

    metadata: dict[str, Any] = {
        "name": "fuzzyq_model_v0",
        "render_modes": list(RENDER_MODES),
        "render_fps": 30.0,
    }

    def __init__(
        self,
        model: fuzzyq.PointMass | fuzzyq.ClassicModel | fuzzyq.CallableModel,
        *,
        start: npt.ArrayLike | Callable[[np.random.Generator], npt.ArrayLike] | None = None,
        max_steps: int | Literal["default"] | None = "default",
        bounds: npt.ArrayLike | fuzzyq.Grid | None = None,
        render_mode: str | None = None,
    ) -> None:
        adapter = self._init_sim(model, start, max_steps, bounds, render_mode)
        self.possible_agents = [agent_name(i) for i in range(adapter.n_agents)]
        self.agents: list[str] = []
        self.observation_spaces = {a: self._sim.observation_space() for a in self.possible_agents}
        self.action_spaces = {
            a: spaces.Discrete(n) for a, n in zip(self.possible_agents, adapter.agent_sizes)
        }
        #: The space of `state()`: the model's state, as every agent's observation.
        self.state_space = self._sim.observation_space()
        self._np_random: np.random.Generator | None = None
        self._np_random_seed: int | None = None

    @property
    def np_random(self) -> np.random.Generator:
        """The generator of start states (seeded by ``reset(seed=...)``)."""
        if self._np_random is None:
            self._np_random, self._np_random_seed = seeding.np_random()
        return self._np_random

    @property
    def np_random_seed(self) -> int | None:
        """The seed of `np_random` (drawn from entropy when no seed was given)."""
        if self._np_random is None:
            self._np_random, self._np_random_seed = seeding.np_random()
        return self._np_random_seed

    def _check_agent(self, agent: str) -> str:
        if agent not in self.observation_spaces:
            raise fuzzyq.InputError(
                f"unknown agent {agent!r}; possible agents are {self.possible_agents}"
            )
        return agent

    def observation_space(self, agent: str) -> spaces.Box:
        """The Box of states `agent` observes (the same object on every call).

        Args:
            agent: one of `possible_agents`.
        """
        return self.observation_spaces[self._check_agent(agent)]

    def action_space(self, agent: str) -> spaces.Discrete:
        """``Discrete(n_i)`` for agent `i` (the same object on every call).

        Args:
            agent: one of `possible_agents`.
        """
        return self.action_spaces[self._check_agent(agent)]

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Observation], dict[str, dict[str, Any]]]:
        """Start an episode with all agents.

        Args:
            seed: seeds `np_random` (the first reset without a seed draws fresh entropy).
            options: ``{"x0": state}`` starts exactly at `state`; other keys are ignored.

        Returns:
            Every agent's observation and info.
        """
        if seed is not None or self._np_random is None:
            self._np_random, self._np_random_seed = seeding.np_random(seed)
        self._sim.reset(self._np_random, options)
        self.agents = self.possible_agents[:]
        observations = {a: self._sim.observation() for a in self.agents}
        infos = {a: self._sim.info() for a in self.agents}
        if self.render_mode == "human":
            self.render()
        return observations, infos

    def step(
        self, actions: dict[str, Any]
    ) -> tuple[
        dict[str, Observation],
        dict[str, float],
        dict[str, bool],
        dict[str, bool],
        dict[str, dict[str, Any]],
    ]:
        """Apply every live agent's action at once.

        Args:
            actions: each live agent's action index.

        Returns:
            ``(observations, rewards, terminations, truncations, infos)``, dicts keyed by agent.
        """
        if not self.agents:
            raise gym_error.ResetNeeded(
                "no live agents (the episode ended or never started); call reset()"
            )
        if not isinstance(actions, Mapping):
            raise fuzzyq.InputTypeError(
                f"actions must be a dict mapping each agent to its action index, "
                f"got {type(actions).__name__}"
            )
        missing = [a for a in self.agents if a not in actions]
        unexpected = [a for a in actions if a not in self.agents]
        if missing or unexpected:
            raise fuzzyq.InputError(
                f"actions must have exactly one entry per live agent {self.agents}; "
                f"missing {missing}, unexpected {unexpected}"
            )
        per_agent = [
            validate_index(actions[a], int(self.action_spaces[a].n), f"action of {a}")
            for a in self.agents
        ]
        reward = self._sim.step(self._sim.adapter.joint_index(per_agent))
        agents = self.agents
        observations = {a: self._sim.observation() for a in agents}
        rewards = dict.fromkeys(agents, reward)
        terminations = dict.fromkeys(agents, self._sim.terminal)
        truncations = dict.fromkeys(agents, self._sim.truncated)
        infos = {a: self._sim.info() for a in agents}
        if self._sim.terminal or self._sim.truncated:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return observations, rewards, terminations, truncations, infos

    def state(self) -> Observation:
        """A fresh float32 copy of the state (in `state_space`)."""
        return self._sim.observation()

    def render(self) -> Frame | str | None:
        """A picture of the current state, as `render_mode` asks; see `ModelEnv.render`.

        Raises:
            gymnasium.error.ResetNeeded: before the first `reset` (with a render mode).
        """
        return self._render()
