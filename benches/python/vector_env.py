"""Steps per second of the natively vectorised environments (`fuzzyq.envs.ModelVectorEnv`,
the ids' ``vector_entry_point``) against Gymnasium's `SyncVectorEnv` of the same single
environments (issue 50). Run from a checkout with the package installed:

    target/python-test-venv/bin/python benches/python/vector_env.py [--envs 64] [--seconds 2]

Prints, per id, the environment steps per second (copies x vector steps) of both and their
ratio, with random actions drawn before the timing.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import gymnasium

import fuzzyq  # noqa: F401  (registers the ids)

IDS = [
    "FuzzyQ/PointMass-v0",
    "FuzzyQ/DcMotor-v0",
    "FuzzyQ/Pendulum-v0",
    "FuzzyQ/CarHill-v0",
    "FuzzyQ/Arm-v0",
    "FuzzyQ/PendulumContinuous-v0",
]


def steps_per_second(env: Any, n: int, seconds: float) -> float:
    """Environment steps per second over at least `seconds` of vector steps."""
    env.reset(seed=0)
    actions = [env.action_space.sample() for _ in range(200)]
    steps, t0 = 0, time.perf_counter()
    while True:
        for a in actions:
            env.step(a)
        steps += len(actions)
        elapsed = time.perf_counter() - t0
        if elapsed >= seconds:
            return steps * n / elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=64, help="copies per vector env")
    parser.add_argument("--seconds", type=float, default=2.0, help="timing per measurement")
    args = parser.parse_args()
    print(f"{'id':34} {'native':>12} {'sync':>12} {'ratio':>7}   (env steps/s, N={args.envs})")
    for env_id in IDS:
        kwargs: dict[str, Any] = {"agents": 1} if "PointMass" in env_id else {}
        native = gymnasium.make_vec(
            env_id, num_envs=args.envs, vectorization_mode="vector_entry_point", **kwargs
        )
        sync = gymnasium.make_vec(env_id, num_envs=args.envs, vectorization_mode="sync", **kwargs)
        a = steps_per_second(native, args.envs, args.seconds)
        b = steps_per_second(sync, args.envs, args.seconds)
        print(f"{env_id:34} {a:12,.0f} {b:12,.0f} {a / b:6.1f}x")


if __name__ == "__main__":
    main()
