"""Train the paper's point-mass task from Python and plot both robots' paths.

    python examples/train_paper.py [--agents 2] [--out paths.png]

Solves the joint fuzzy Q-function on the paper's grid (4,100,625 cores x 625 joint actions
for two agents, about 10 seconds on 2 cores), rolls the greedy and the interpolated policies
out from the paper's start [-4, -6, -2, 2, 5, 3, 2, -1] and draws the paths (the paper's
figure 4) with matplotlib.
"""

from __future__ import annotations

import argparse
import time
from typing import Literal

import numpy as np

import fuzzyq

PAPER_X0 = np.array([-4.0, -6.0, -2.0, 2.0, 5.0, 3.0, 2.0, -1.0])


def rollout(model: fuzzyq.PointMass, policy: fuzzyq.Policy, x0: np.ndarray, steps: int) -> np.ndarray:
    """The states x_0 .. x_steps under `policy`."""
    states = [x0]
    for _ in range(steps):
        x = states[-1]
        states.append(model.step(x, policy.act(x)))
    return np.array(states)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=2, choices=[1, 2])
    parser.add_argument("--steps", type=int, default=75)
    parser.add_argument("--out", default="paths.png", help="figure file (PNG, SVG, PDF)")
    args = parser.parse_args()

    model = fuzzyq.PointMass(agents=args.agents)
    grid = model.paper_grid()
    print(f"solving {grid.n_cores:,} cores x {model.n_joint_actions} joint actions ...")
    start = time.perf_counter()
    solution = fuzzyq.solve(model, grid, callback=lambda p: None)
    print(
        f"{solution.sweeps} sweeps, final change {solution.final_delta:.4f} "
        f"(error bound {solution.error_bound:.3f}), {time.perf_counter() - start:.1f} s"
    )

    x0 = PAPER_X0[: model.state_dim]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 5.5), sharex=True, sharey=True)
    kinds: list[Literal["greedy", "interpolated"]] = ["greedy", "interpolated"]
    for ax, kind in zip(axes, kinds):
        states = rollout(model, solution.policy(kind), x0, args.steps)
        for i in range(model.n_agents):
            path = states[:, 4 * i : 4 * i + 2]
            err = np.hypot(*path[-1])
            ax.plot(path[:, 0], path[:, 1], "o-", ms=3, label=f"agent {i + 1} (final error {100 * err:.1f} cm)")
            ax.plot(*path[0], "^", ms=10, color=ax.lines[-1].get_color())
        ax.plot(0, 0, "kx", ms=10, mew=2, label="origin (goal)")
        ax.set_title(f"{kind} policy")
        ax.set_xlabel("s_x (m)")
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right", fontsize=8)
    axes[0].set_ylabel("s_y (m)")
    fig.suptitle("fuzzyq: paths from the paper's start (Luviano-Cruz et al. 2018, fig. 4)")
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"figure written to {args.out}")


if __name__ == "__main__":
    main()
