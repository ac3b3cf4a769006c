"""Any fuzzyq model as a PettingZoo parallel environment: one agent per agent of the model."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from pettingzoo import ParallelEnv  # type: ignore[import-untyped, unused-ignore]

import fuzzyq

from ._core import Observation
from ._model_sim import ModelBacked
from ._parallel import ParallelAgents
from ._render import RENDER_MODES, Frame


class ModelParallelEnv(
    ParallelAgents,
    ModelBacked,
    ParallelEnv[str, Observation, int],  # type: ignore[misc, unused-ignore]
):
    """Any fuzzyq model as a PettingZoo `ParallelEnv`: each of the model's agents is an agent.

    The agents are ``"agent_0"``, ``"agent_1"``, ... (`possible_agents`; one for a classic
    model, one per robot for `fuzzyq.Khepera`, each choosing from its four actions). Every agent observes the whole state and all share one reward, as in the paper;
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
        observation: None or ``"paper"`` (the robots); see `ModelEnv`.

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
        model: fuzzyq.PointMass | fuzzyq.ClassicModel | fuzzyq.Khepera | fuzzyq.CallableModel,
        *,
        start: npt.ArrayLike | Callable[[np.random.Generator], npt.ArrayLike] | None = None,
        max_steps: int | Literal["default"] | None = "default",
        bounds: npt.ArrayLike | fuzzyq.Grid | None = None,
        render_mode: str | None = None,
        observation: Literal["paper"] | None = None,
    ) -> None:
        adapter = self._init_sim(model, start, max_steps, bounds, render_mode, observation)
        self._init_agents(list(adapter.agent_sizes))

    def _joint_index(self, per_agent: list[int]) -> int:
        return int(self._sim.adapter.joint_index(per_agent))

    def _terminal(self) -> bool:
        return bool(self._sim.terminal)

    def render(self) -> Frame | str | None:
        """A picture of the current state, as `render_mode` asks; see `ModelEnv.render`.

        Raises:
            gymnasium.error.ResetNeeded: before the first `reset` (with a render mode).
        """
        return self._render()
