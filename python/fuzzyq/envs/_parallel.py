"""What the two PettingZoo parallel environments share: agents and their spaces, seeding,
`reset` and `step` (the joint action from every live agent's own, one shared reward)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import error as gym_error
from gymnasium import spaces
from gymnasium.utils import seeding

import fuzzyq

from ._core import Observation, agent_name, validate_index


class ParallelAgents:
    """The agents of a parallel environment over one simulation (`_sim`), which every agent
    observes whole and whose reward all share. A subclass gives the joint action index of
    the agents' actions (`_joint_index`) and whether the state is terminal (`_terminal`)."""

    _sim: Any
    render_mode: str | None

    def _init_agents(self, sizes: list[int]) -> None:
        """Agents ``"agent_0"``, ... choosing from ``Discrete(sizes[i])``."""
        self.possible_agents = [agent_name(i) for i in range(len(sizes))]
        self.agents: list[str] = []
        self.observation_spaces: dict[str, spaces.Box] = {
            a: self._sim.observation_space() for a in self.possible_agents
        }
        self.action_spaces = {
            a: spaces.Discrete(n) for a, n in zip(self.possible_agents, sizes, strict=True)
        }
        #: The space of `state()`: the state, as every agent's observation.
        self.state_space: spaces.Box = self._sim.observation_space()
        self._np_random: np.random.Generator | None = None
        self._np_random_seed: int | None = None

    def _joint_index(self, per_agent: list[int]) -> int:
        raise NotImplementedError

    def _terminal(self) -> bool:
        raise NotImplementedError

    def render(self) -> Any:
        raise NotImplementedError

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
        reward = self._sim.step(self._joint_index(per_agent))
        terminal, truncated = self._terminal(), bool(self._sim.truncated)
        agents = self.agents
        observations = {a: self._sim.observation() for a in agents}
        rewards = dict.fromkeys(agents, reward)
        terminations = dict.fromkeys(agents, terminal)
        truncations = dict.fromkeys(agents, truncated)
        infos = {a: self._sim.info() for a in agents}
        if terminal or truncated:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return observations, rewards, terminations, truncations, infos

    def state(self) -> Observation:
        """A fresh float32 copy of the state (in `state_space`)."""
        return self._sim.observation()  # type: ignore[no-any-return]
