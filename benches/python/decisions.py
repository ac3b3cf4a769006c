"""Python decision and memory benchmarks (issue 16): run from a checkout with the package
installed, e.g. `target/python-test-venv/bin/python benches/python/decisions.py`.

Prints, for the paper's two-agent task (the solution loaded from `--policy FILE`, or solved
here, about 8-45 s depending on the host):
- one greedy and one interpolated decision through `Policy.act` on random states (median of
  the per-call times over 2,000 states, Python call overhead included);
- `act_batch` of 10,000 random states against a Python loop of `act` over the same states.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import fuzzyq


def per_call(f, states: np.ndarray) -> float:
    times = []
    for x in states:
        t0 = time.perf_counter()
        f(x)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", help="a policy file of the paper's task (fuzzyq train)")
    parser.add_argument("--agents", type=int, default=2)
    args = parser.parse_args()
    if args.policy:
        solution = fuzzyq.load(args.policy)
        assert isinstance(solution, fuzzyq.Solution)
    else:
        model = fuzzyq.PointMass(agents=args.agents)
        t0 = time.perf_counter()
        solution = fuzzyq.solve(model, model.paper_grid())
        print(f"solved in {time.perf_counter() - t0:.1f} s ({solution.sweeps} sweeps)")
    dim = solution.grid.n_dims
    rng = np.random.default_rng(0)
    limits = np.array([6.0, 6.0, 3.0, 3.0] * (dim // 4))
    states = rng.uniform(-1, 1, size=(10_000, dim)) * limits
    for kind in ("greedy", "interpolated"):
        policy = solution.policy(kind)
        policy.act(states[0])  # prepares the policy
        one = per_call(policy.act, states[:2000])
        t0 = time.perf_counter()
        policy.act_batch(states)
        batch = time.perf_counter() - t0
        t0 = time.perf_counter()
        for x in states:
            policy.act(x)
        loop = time.perf_counter() - t0
        print(
            f"{kind:>12}: act {one * 1e6:8.1f} us per decision (median); "
            f"act_batch(10,000) {batch * 1e3:8.1f} ms vs a loop {loop * 1e3:8.1f} ms "
            f"({loop / batch:.1f}x)"
        )


if __name__ == "__main__":
    main()
