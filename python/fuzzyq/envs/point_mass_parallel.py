"""The point-mass task as a PettingZoo parallel environment: one agent per point mass."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt
from gymnasium import error as gym_error
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv  # type: ignore[import-untyped, unused-ignore]

import fuzzyq

from ._core import (
    Observation,
    SimBacked,
    agent_name,
    validate_index,
)
from ._render import RENDER_MODES, Frame


class PointMassParallelEnv(
    SimBacked,
    ParallelEnv[str, Observation, int]  # type: ignore[misc, unused-ignore]
):
    """The paper's point-mass task (Luviano-Cruz et al. 2018, section 3.1) as a PettingZoo env.

    Each point mass is an agent, ``"agent_0"``, ``"agent_1"``, ... (`possible_agents`). As in the
    paper, every agent observes the whole joint state and all agents share one reward; each agent
    chooses its own force from ``Discrete(model.n_actions)`` (25 force pairs with the default
    `force_levels`: index `a` applies ``model.actions[a]``, ``u_x`` slowest).
    `parallel_env(**kwargs)` builds one.

    Args:
        max_steps: all agents are truncated (and removed from `agents`) after this many steps
            (default 75); None never truncates.
        render_mode: None, ``"rgb_array"`` (`render` returns the ``(400, 400, 3)`` uint8
            picture of `PointMassEnv.render`), ``"human"`` (that picture in a matplotlib window,
            updated on every `reset` and `step`; needs ``pip install matplotlib``) or
            ``"ansi"`` (`render` returns a text picture of the state).
        **model_kwargs: passed to `fuzzyq.PointMass` (``agents=2``, ``mass``, ``sample_time``,
            ...); invalid options raise the model's errors.

    Semantics:
        reset(seed=None, options=None): seeds `np_random` when `seed` is given (the first reset
            without a seed draws fresh entropy); positions uniform in the position box,
            velocities zero, unless ``options={"x0": state}`` sets the joint state exactly (a
            ``(4 * agents,)`` array within the limits, else `fuzzyq.InputError` (ValueError) or
            `fuzzyq.InputTypeError` (TypeError)). Other option keys are ignored. Returns a fresh
            copy of the joint observation (float32) and a fresh info dict for every agent.
        step(actions): `actions` maps every live agent to its action index; the joint action is
            ``model.joint_index([actions[a] for a in agents])`` (agent 0 most significant), the
            next state is ``model.step(x, model.joint_action(joint))`` and every agent receives
            the shared reward ``model.reward(x)`` of the state *before* the step (the paper's
            rho(x, u)). Terminations are always False (the task is continuing); on the
            `max_steps`-th step every truncation is True and `agents` becomes empty. Missing,
            unknown or invalid actions raise `fuzzyq.InputError` / `fuzzyq.InputTypeError`;
            stepping with no live agents (before reset or after truncation) raises
            `gymnasium.error.ResetNeeded`.
        infos: ``"in_goal"`` (the returned state is in the goal, so the next step pays),
            ``"state"`` (a float64 copy of the exact joint state) and ``"steps"``.
        state(): a fresh float32 copy of the joint state, in `state_space`.

    `observation_space(agent)` and `action_space(agent)` return the same object on every call
    (one per agent, so each can be seeded on its own). Drive the env with a greedy policy from
    `fuzzyq.solve` via `greedy_actions(policy, observations)`.
    """

    metadata: dict[str, Any] = {
        "name": "fuzzyq_pointmass_v0",
        "render_modes": list(RENDER_MODES),
        "render_fps": 2.5,
    }

    def __init__(
        self, *, max_steps: int | None = 75, render_mode: str | None = None, **model_kwargs: Any
    ) -> None:
        model = self._init_sim(max_steps, render_mode, model_kwargs)
        self.possible_agents = [agent_name(i) for i in range(model.n_agents)]
        self.agents: list[str] = []
        self.observation_spaces = {a: self._sim.observation_space() for a in self.possible_agents}
        self.action_spaces = {a: spaces.Discrete(model.n_actions) for a in self.possible_agents}
        #: The space of `state()`: the joint state, as every agent's observation.
        self.state_space = self._sim.observation_space()
        self._np_random: np.random.Generator | None = None
        self._np_random_seed: int | None = None

    # --- properties --------------------------------------------------------------------------

    @property
    def np_random(self) -> np.random.Generator:
        """The generator of initial states (seeded by ``reset(seed=...)``)."""
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
        """The Box of joint observations of `agent` (the same object on every call)."""
        return self.observation_spaces[self._check_agent(agent)]

    def action_space(self, agent: str) -> spaces.Discrete:
        """``Discrete(model.n_actions)`` for `agent` (the same object on every call)."""
        return self.action_spaces[self._check_agent(agent)]

    # --- API ---------------------------------------------------------------------------------

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Observation], dict[str, dict[str, Any]]]:
        """Start an episode with all agents; see the class docstring for `options`."""
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
        """Apply every live agent's action at once; see the class docstring."""
        if not self.agents:
            raise gym_error.ResetNeeded(
                "no live agents (the episode was truncated or never started); call reset()"
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
        model = self._sim.model
        per_agent = [
            validate_index(actions[a], model.n_actions, f"action of {a}") for a in self.agents
        ]
        reward = self._sim.step(model.joint_index(per_agent))
        truncated = self._sim.truncated
        agents = self.agents
        observations = {a: self._sim.observation() for a in agents}
        rewards = dict.fromkeys(agents, reward)
        terminations = dict.fromkeys(agents, False)
        truncations = dict.fromkeys(agents, truncated)
        infos = {a: self._sim.info() for a in agents}
        if truncated:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return observations, rewards, terminations, truncations, infos

    def state(self) -> Observation:
        """A fresh float32 copy of the joint state (in `state_space`)."""
        return self._sim.observation()

    def render(self) -> Frame | str | None:
        """A picture of the current state, as `render_mode` asks.

        Returns:
            The ``(400, 400, 3)`` uint8 image of `PointMassEnv.render` for ``"rgb_array"``, a
            text picture for ``"ansi"``, None for ``"human"`` (shown in the window) and None.

        Raises:
            gymnasium.error.ResetNeeded: before the first `reset` (with a render mode).
        """
        return self._render(self.possible_agents, self.max_steps)


def parallel_env(**kwargs: Any) -> PointMassParallelEnv:
    """A `PointMassParallelEnv`; the keyword arguments are those of its constructor."""
    return PointMassParallelEnv(**kwargs)


def greedy_actions(
    policy: fuzzyq.Policy, observations: Mapping[str, npt.ArrayLike] | npt.ArrayLike
) -> dict[str, int]:
    """Each agent's action under a greedy `policy`, for `PointMassParallelEnv.step`.

    `observations` is either the dict returned by `reset`/`step` (each agent then acts on its
    own observation: ``policy.agent_actions(obs)[i]`` for ``"agent_i"``, the paper's
    decentralised execution of the shared greedy joint action) or one joint observation (every
    agent of the policy acts on it). For the Gymnasium `PointMassEnv` use
    ``policy.act_index(observation)`` instead: it is the joint action index.

    Raises the policy's errors for a non-greedy policy or a wrong state size, and
    `fuzzyq.InputError` for a key that is not an agent name of the form ``"agent_<i>"``.
    """
    if isinstance(observations, Mapping):
        actions: dict[str, int] = {}
        for agent, obs in observations.items():
            actions[agent] = int(policy.agent_actions(obs)[_agent_number(agent, policy)])
        return actions
    per_agent = policy.agent_actions(observations)
    return {agent_name(i): int(a) for i, a in enumerate(per_agent)}


def _agent_number(agent: object, policy: fuzzyq.Policy) -> int:
    names = [agent_name(i) for i in range(policy.n_agents)]
    if agent not in names:
        raise fuzzyq.InputError(f"unknown agent {agent!r} for a policy of agents {names}")
    return names.index(str(agent))
