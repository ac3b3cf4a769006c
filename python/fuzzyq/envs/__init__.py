"""Gymnasium and PettingZoo environments: the paper's point-mass task, and any fuzzyq model.

Requires the optional dependencies: gymnasium and pettingzoo (``pip install gymnasium pettingzoo``, or the ``envs`` extra: ``pip install ".[envs]"`` in a checkout, ``pip install "fuzzyq-*.whl[envs]"`` for a wheel).

- `PointMassEnv`: a Gymnasium `Env` with the joint observation and ``Discrete(25**agents)``
  joint actions; registered as ``"FuzzyQ/PointMass-v0"`` (with ``max_episode_steps=75``) by
  ``import fuzzyq`` whenever gymnasium is installed, so ``gymnasium.make`` and
  Stable-Baselines3's ``make_vec_env("FuzzyQ/PointMass-v0", env_kwargs={"agents": 1})`` work
  without importing this package.
- `PointMassParallelEnv` (built by `parallel_env`): a PettingZoo `ParallelEnv` with one agent
  per point mass, ``"agent_0"``, ``"agent_1"``, ..., each observing the joint state and choosing
  from ``Discrete(25)``; all agents share the reward.
- `greedy_actions(policy, observations)`: the parallel env's actions under a greedy policy from
  `fuzzyq.solve`. For `PointMassEnv` the joint action is ``policy.act_index(observation)``.
- Every built-in task has Gymnasium ids, registered by ``import fuzzyq`` (see
  `fuzzyq.envs.registry`): ``FuzzyQ/DcMotor-v0``, ``FuzzyQ/Pendulum-v0``,
  ``FuzzyQ/CarHill-v0``, ``FuzzyQ/Arm-v0`` (joint action indices), and a continuous-action
  variant of each task, ``FuzzyQ/<Name>Continuous-v0`` (``PointMassContinuous`` too), and
  ``FuzzyQ/Khepera-v0`` / ``FuzzyQ/KheperaContinuous-v0``: the robots on their rapier plant
  with sonars (observing their poses, or the paper's state with ``observation="paper"``).
- `ModelVectorEnv(model, num_envs, *, continuous=False, ...)`: `num_envs` copies stepped
  as one batch (in Rust with the GIL released for the built-in models); every id's
  ``vector_entry_point``, so ``gymnasium.make_vec(id, num_envs=n)`` builds it.
- `ContinuousModelEnv(model, ...)`: `ModelEnv` whose actions are joint action vectors in a
  `Box` spanning the model's actions (for the interpolated policy and continuous-control
  learners).
- `ModelEnv(model, *, start=None, max_steps="default", bounds=None, render_mode=None)` and
  `ModelParallelEnv(...)` (same arguments): any fuzzyq model (`fuzzyq.PointMass`, the classic
  `DcMotor`, `Pendulum`, `CarHill`, `Arm`, the `fuzzyq.Khepera` robots, or a `CallableModel`)
  as a Gymnasium `Env` with
  ``Discrete(n_joint_actions)`` actions, or as a PettingZoo `ParallelEnv` with each agent's own
  ``Discrete(n_i)``; `default_episode_steps(model)` is their default `max_steps`.

Both point-mass envs take the keyword arguments of `fuzzyq.PointMass` plus ``max_steps=75`` and
``render_mode=None``. Rewards are the paper's rho(x, u), evaluated at the state before the step;
the task is continuing (never terminated) and truncated after `max_steps`. Every env renders
as ``"rgb_array"`` (a uint8 picture drawn with NumPy: for the point masses the arena, the goal
and each agent in its colour of `AGENT_COLOURS` with a velocity tick), ``"human"`` (that picture
in a matplotlib window: ``pip install matplotlib``, in the ``envs`` extra) or ``"ansi"`` (text), so
`gymnasium.wrappers.RecordVideo` records them.

>>> import fuzzyq, fuzzyq.envs
>>> env = fuzzyq.envs.PointMassEnv(agents=1)
>>> policy = fuzzyq.solve(env.model, env.model.paper_grid()).policy("greedy")
>>> obs, info = env.reset(options={"x0": [-4.0, 3.0, 0.0, 0.0]})
>>> while not info["in_goal"]:
...     obs, reward, terminated, truncated, info = env.step(policy.act_index(obs))
>>> info["steps"] < 75
True
"""

from __future__ import annotations

try:
    import gymnasium  # noqa: F401
    import pettingzoo  # type: ignore[import-untyped, unused-ignore]  # noqa: F401
except ImportError as exc:  # pragma: no cover - exercised by a test that hides the modules
    raise ImportError(
        "fuzzyq.envs needs the optional dependencies gymnasium and pettingzoo: "
        "pip install gymnasium pettingzoo"
    ) from exc

from ._model_sim import default_episode_steps
from ._render import AGENT_COLOURS
from .model_env import ContinuousModelEnv, ModelEnv
from .model_parallel import ModelParallelEnv
from .point_mass_gym import PointMassEnv
from .point_mass_parallel import PointMassParallelEnv, greedy_actions, parallel_env
from .vector import ModelVectorEnv

#: The Gymnasium id of `PointMassEnv` (registered by ``import fuzzyq``).
ENV_ID = "FuzzyQ/PointMass-v0"

__all__ = [
    "AGENT_COLOURS",
    "ENV_ID",
    "ContinuousModelEnv",
    "ModelEnv",
    "ModelParallelEnv",
    "ModelVectorEnv",
    "PointMassEnv",
    "PointMassParallelEnv",
    "default_episode_steps",
    "greedy_actions",
    "parallel_env",
]
