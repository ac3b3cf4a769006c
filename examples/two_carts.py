"""Two carts on parallel rails that must each stop on a marked spot, learned from interaction
with a Gymnasium environment alone: no model function, no reward function.

Each cart has a position ``p`` in ``[-1, 1]`` m and a velocity ``v`` in ``[-1, 1]`` m/s and is
pushed by its own force ``u`` in ``{-1, -0.25, 0, 0.25, 1}`` N (unit mass, viscous friction,
``dt = 0.1`` s). Cart 1 must stop at ``p = -0.5``, cart 2 at ``p = +0.5``; the reward is
``-((p1 + 0.5)^2 + (p2 - 0.5)^2) - 0.1 (v1^2 + v2^2)`` per step, and an episode (10 s) is a
success when both carts end within 0.1 m of their spots, slower than 0.2 m/s.

The learner is told what a researcher knows of such a system: the state's ranges, each
cart's forces, and that each cart moves by its own force alone (two independent blocks). It
learns the rest from at most 20,000 transitions:

    python examples/two_carts.py

prints the fit report and the success rate over 100 seeded episodes (above 90%). The same
system written as a `fuzzyq.CallableModel` (`transition` below) gives the same learned
tables from the same transitions.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
import numpy.typing as npt
from gymnasium import spaces

import fuzzyq

FORCES = np.array([-1.0, -0.25, 0.0, 0.25, 1.0])
"""Each cart's forces (N)."""
SPOTS = np.array([-0.5, 0.5])
"""Where cart 1 and cart 2 must stop (m)."""
DT = 0.1
"""Sample time (s)."""
FRICTION = 1.0
"""Viscous friction (1/s)."""
EPISODE_STEPS = 100
"""Steps per episode (10 s)."""


def transition(
    x: npt.NDArray[np.float64], u: npt.NDArray[np.float64]
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """The carts' dynamics and reward for a batch: states ``(n, 4)`` as
    ``[p1, v1, p2, v2]``, forces ``(n, 2)``."""
    p, v = x[:, 0::2], x[:, 1::2]
    v_next = np.clip(v + DT * (u - FRICTION * v), -1.0, 1.0)
    p_next = np.clip(p + DT * v_next, -1.0, 1.0)
    reward = -((p - SPOTS) ** 2).sum(axis=1) - 0.1 * (v**2).sum(axis=1)
    nx = np.empty_like(x)
    nx[:, 0::2], nx[:, 1::2] = p_next, v_next
    return nx, reward


def at_rest_on_spots(x: npt.NDArray[np.float64]) -> bool:
    """Whether both carts are within 0.1 m of their spots, slower than 0.2 m/s."""
    return bool((np.abs(x[0::2] - SPOTS) < 0.1).all() and (np.abs(x[1::2]) < 0.2).all())


class TwoCartsEnv(gymnasium.Env[npt.NDArray[np.float64], npt.NDArray[np.int64]]):
    """The two carts as a Gymnasium environment: observation ``[p1, v1, p2, v2]``, action
    each cart's force index (`MultiDiscrete([5, 5])`), carts at rest at uniform random
    positions on reset, truncated after `EPISODE_STEPS` steps; ``info["is_success"]`` says
    whether both carts are at rest on their spots."""

    def __init__(self) -> None:
        self.observation_space = spaces.Box(-1.0, 1.0, (4,), np.float64)
        self.action_space = spaces.MultiDiscrete([len(FORCES), len(FORCES)])
        self.x = np.zeros(4)
        self.t = 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[npt.NDArray[np.float64], dict[str, Any]]:
        super().reset(seed=seed)
        self.x = np.zeros(4)
        self.x[0::2] = self.np_random.uniform(-1.0, 1.0, 2)
        self.t = 0
        return self.x.copy(), {"is_success": at_rest_on_spots(self.x)}

    def step(
        self, action: npt.NDArray[np.int64]
    ) -> tuple[npt.NDArray[np.float64], float, bool, bool, dict[str, Any]]:
        u = FORCES[np.asarray(action)]
        nx, r = transition(self.x[None, :], u[None, :])
        self.x = nx[0]
        self.t += 1
        info = {"is_success": at_rest_on_spots(self.x)}
        return self.x.copy(), float(r[0]), False, self.t >= EPISODE_STEPS, info


def task() -> fuzzyq.Task:
    """What the learner is told: the ranges, the forces, one block per cart."""
    return fuzzyq.Task(
        state_bounds=[[-1.0, 1.0]] * 4,
        actions=[FORCES, FORCES],
        blocks=[([0, 1], [0]), ([2, 3], [1])],
        reward_depends_on_action=False,
    )


def grid() -> fuzzyq.Grid:
    """Cores denser around the spots and at slow speeds."""
    p = [-1.0, -0.75, -0.6, -0.5, -0.4, -0.25, 0.0, 0.25, 0.4, 0.5, 0.6, 0.75, 1.0]
    v = [-1.0, -0.5, -0.2, 0.0, 0.2, 0.5, 1.0]
    return fuzzyq.Grid([p, v, p, v])


def callable_model() -> fuzzyq.CallableModel:
    """The same system as a `CallableModel`."""
    return fuzzyq.CallableModel(
        transition, state_dim=4, actions=[FORCES, FORCES], blocks=[([0, 1], [0]), ([2, 3], [1])]
    )


def learn(samples: int = 20_000, seed: int = 0) -> fuzzyq.Solution:
    """Learns the carts from `samples` transitions of the environment, in one round."""
    return fuzzyq.learn(TwoCartsEnv(), task(), grid(), samples=samples, seed=seed, gamma=0.97)


def main() -> None:
    solution = learn()
    fit = solution.fit
    assert fit is not None
    print(f"learned from {fit['samples']} transitions; reward: {fit['reward']}")
    for b in fit["blocks"]:
        print(
            f"  block {b['state_dims']}: {b['rows']} rows, residual rms {b['residual_rms']}, "
            f"{b['under_sampled_rows']} under-sampled"
        )
    policy = solution.policy("greedy")
    result = fuzzyq.evaluate(policy, TwoCartsEnv(), task=task(), count=100, seed=10_000)
    summary = result["summary"]
    print(
        f"success in {summary['success_rate']:.0%} of {summary['episodes']} episodes, "
        f"mean return {summary['mean_return']:.2f}"
    )


if __name__ == "__main__":
    main()
