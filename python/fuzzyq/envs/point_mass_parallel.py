"""The point-mass task as a PettingZoo parallel environment: one agent per point mass."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy.typing as npt
from pettingzoo import ParallelEnv  # type: ignore[import-untyped, unused-ignore]

import fuzzyq

from ._core import (
    Observation,
    SimBacked,
    agent_name,
)
from ._parallel import ParallelAgents
from ._render import RENDER_MODES, Frame


class PointMassParallelEnv(
    ParallelAgents,
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
        self._init_agents([model.n_actions] * model.n_agents)

    def _joint_index(self, per_agent: list[int]) -> int:
        return int(self._sim.model.joint_index(per_agent))

    def _terminal(self) -> bool:
        return False  # the task is continuing

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
