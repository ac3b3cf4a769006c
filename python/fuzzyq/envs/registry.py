"""The Gymnasium ids of the built-in tasks, registered by ``import fuzzyq``.

========================================  =================================================
id                                        environment
========================================  =================================================
``FuzzyQ/PointMass-v0``                   `PointMassEnv` (joint action index)
``FuzzyQ/PointMassContinuous-v0``         `ContinuousModelEnv` of `fuzzyq.PointMass`
``FuzzyQ/DcMotor-v0``                     `ModelEnv` of `fuzzyq.DcMotor`
``FuzzyQ/DcMotorContinuous-v0``           `ContinuousModelEnv` of `fuzzyq.DcMotor`
``FuzzyQ/Pendulum-v0``, ``...Continuous``  the pendulum swing-up, `fuzzyq.Pendulum`
``FuzzyQ/CarHill-v0``, ``...Continuous``   the car on the hill, `fuzzyq.CarHill`
``FuzzyQ/Arm-v0``, ``...Continuous``       the two-link arm, `fuzzyq.Arm`
``FuzzyQ/Khepera-v0``, ``...Continuous``   the robots on their rapier plant, `fuzzyq.Khepera`
========================================  =================================================

Each is limited to the length of a ``fuzzyq rollout`` by Gymnasium's `TimeLimit`
(`default_episode_steps`), which ``gymnasium.make(id, max_episode_steps=n)`` overrides. Keyword
arguments of ``gymnasium.make`` go to the model's constructor (``agents=1`` for the point
masses or the robots, a classic benchmark's parameters), except `start`, `render_mode` and
`observation` (``"paper"`` for the robots), which go to the environment. The robots' ids have
no native vector entry point (their rapier worlds are stateful): ``gymnasium.make_vec`` gives
them Gymnasium's synchronous vector. The ids are declared in ``fuzzyq._gym_ids``.
"""

from __future__ import annotations

from typing import Any, Literal

import fuzzyq

from .model_env import ContinuousModelEnv, ModelEnv

#: The built-in models by environment name.
MODELS: dict[str, Any] = {
    "pointmass": fuzzyq.PointMass,
    "dcmotor": fuzzyq.DcMotor,
    "pendulum": fuzzyq.Pendulum,
    "carhill": fuzzyq.CarHill,
    "arm": fuzzyq.Arm,
    "khepera": fuzzyq.Khepera,
}


def make(
    env: str,
    continuous: bool = False,
    *,
    start: Any = None,
    render_mode: str | None = None,
    observation: Literal["paper"] | None = None,
    **model_kwargs: Any,
) -> ModelEnv:
    """The environment of a registered id (the entry point ``gymnasium.make`` calls).

    Args:
        env: the environment's name (``"dcmotor"``, ...).
        continuous: `ContinuousModelEnv` (actions are joint action vectors) instead of
            `ModelEnv` (joint action indices).
        start: the episodes' start (see `ModelEnv`).
        render_mode: see `ModelEnv`.
        observation: None, or ``"paper"`` for the robots; see `ModelEnv`.
        **model_kwargs: the model constructor's keyword arguments.

    Returns:
        The environment, truncating never on its own (Gymnasium's `TimeLimit` does).
    """
    if env not in MODELS:
        raise fuzzyq.ConfigError(f"env: expected one of {sorted(MODELS)}, got {env!r}")
    model = MODELS[env](**model_kwargs)
    cls = ContinuousModelEnv if continuous else ModelEnv
    return cls(
        model, start=start, max_steps=None, render_mode=render_mode, observation=observation
    )
