"""Three agents as a user's own model, at full speed: independent dynamics blocks.

Three double integrators on a line (agent i: position and velocity, driven by its own force
in {-1, 0, 1}), rewarded for bringing all three to the origin. A grid of 11 x 7 cores per
agent gives 77^3 = 456,533 joint cores x 27 joint actions. Declared as one block per agent,
the solver keeps only each agent's 77 x 3 successors and one reward per (core, joint action)
and runs the block backup; without the declaration it keeps every successor and their
memberships (several GB). Run:

    python examples/three_agents.py            # with blocks
    python examples/three_agents.py --no-blocks  # the same model without them (about 6 GB)

and compare the printed peak memory and time.
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np
import numpy.typing as npt

import fuzzyq

Array = npt.NDArray[np.float64]
AGENTS = 3


def transition(x: Array, u: Array) -> tuple[Array, Array]:
    """Next states and rewards of a batch: x is (n, 6), u is (n, 3)."""
    nxt = np.empty_like(x)
    for i in range(AGENTS):
        p, v = x[:, 2 * i], x[:, 2 * i + 1]
        nxt[:, 2 * i] = np.clip(p + 0.1 * v, -1.0, 1.0)
        nxt[:, 2 * i + 1] = np.clip(0.95 * v + 0.1 * u[:, i], -1.0, 1.0)
    reward = -np.sum(x[:, 0::2] ** 2, axis=1) - 0.01 * np.sum(u**2, axis=1)
    return nxt, reward


def main() -> None:
    parser = argparse.ArgumentParser(description="three agents, with or without blocks")
    parser.add_argument("--no-blocks", action="store_true", help="do not declare the blocks")
    args = parser.parse_args()
    blocks = None if args.no_blocks else [([2 * i, 2 * i + 1], [i]) for i in range(AGENTS)]
    model = fuzzyq.CallableModel(
        transition, state_dim=2 * AGENTS, actions=[[-1.0, 0.0, 1.0]] * AGENTS, blocks=blocks
    )
    grid = fuzzyq.Grid([np.linspace(-1, 1, 11), np.linspace(-1, 1, 7)] * AGENTS)
    t0 = time.perf_counter()
    solution = fuzzyq.solve(model, grid, gamma=0.95, xi=1e-3, max_memory_gb=20.0)
    seconds = time.perf_counter() - t0
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    print(
        f"{grid.n_cores} cores x {model.n_joint_actions} joint actions, "
        f"{'without' if args.no_blocks else 'with'} blocks: {solution.sweeps} sweeps "
        f"({solution.kernel}), {seconds:.1f} s, peak memory {peak_gb:.2f} GB"
    )
    x = np.array([0.8, 0.0, -0.6, 0.2, 0.4, -0.3])
    policy = solution.policy("greedy")
    for _ in range(60):
        x, _, _ = model.step(x, policy.act(x))
    print("after 60 greedy steps, positions", np.round(x[0::2], 3))


if __name__ == "__main__":
    main()
