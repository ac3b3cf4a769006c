"""Gymnasium and PettingZoo environments of the paper's point-mass task.

Requires the optional dependencies: ``pip install fuzzyq[envs]`` (gymnasium and pettingzoo).

- `PointMassEnv`: a Gymnasium `Env` with the joint observation and ``Discrete(25**agents)``
  joint actions; registered as ``"FuzzyQ/PointMass-v0"`` when this package is imported.
- `PointMassParallelEnv` (built by `parallel_env`): a PettingZoo `ParallelEnv` with one agent
  per point mass, ``"agent_0"``, ``"agent_1"``, ..., each observing the joint state and choosing
  from ``Discrete(25)``; all agents share the reward.
- `greedy_actions(policy, observations)`: the parallel env's actions under a greedy policy from
  `fuzzyq.solve`. For `PointMassEnv` the joint action is ``policy.act_index(observation)``.

Both envs take the keyword arguments of `fuzzyq.PointMass` plus ``max_steps=75`` and
``render_mode=None`` (or ``"ansi"``). Rewards are the paper's rho(x, u), evaluated at the state
before the step; the task is continuing (never terminated) and truncated after `max_steps`.

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
    import gymnasium
    import pettingzoo  # type: ignore[import-untyped, unused-ignore]  # noqa: F401
except ImportError as exc:  # pragma: no cover - exercised by a test that hides the modules
    raise ImportError(
        "fuzzyq.envs needs the optional dependencies gymnasium and pettingzoo: "
        "pip install fuzzyq[envs]"
    ) from exc

from .point_mass_gym import PointMassEnv
from .point_mass_parallel import PointMassParallelEnv, greedy_actions, parallel_env

#: The Gymnasium id of `PointMassEnv`.
ENV_ID = "FuzzyQ/PointMass-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="fuzzyq.envs.point_mass_gym:PointMassEnv")

__all__ = ["ENV_ID", "PointMassEnv", "PointMassParallelEnv", "greedy_actions", "parallel_env"]
