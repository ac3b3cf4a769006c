"""The Gymnasium ids of the built-in tasks: registered by ``import fuzzyq`` without importing
the environments (`fuzzyq.envs.registry` builds them when ``gymnasium.make`` asks)."""

from __future__ import annotations

from typing import Any

#: The length of a ``fuzzyq rollout`` per environment, in steps (fuzzyq-sim's
#: `EnvSpec::default_steps`; test_envs.py checks them against `Policy.rollout`).
EPISODE_STEPS: dict[str, int] = {
    "pointmass": 75,
    "dcmotor": 400,
    "pendulum": 600,
    "carhill": 100,
    "arm": 200,
    "khepera": 250,
}

#: Each environment's name in its ids.
NAMES: dict[str, str] = {
    "pointmass": "PointMass",
    "dcmotor": "DcMotor",
    "pendulum": "Pendulum",
    "carhill": "CarHill",
    "arm": "Arm",
    "khepera": "Khepera",
}


#: Environments whose plant is a stateful simulation (the robots' rapier world): no native
#: vectorisation; ``gymnasium.make_vec`` builds Gymnasium's own vector of copies for them.
STATEFUL = {"khepera"}

#: Where ``gymnasium.make_vec`` builds the natively vectorised environments of every id.
VECTOR_ENTRY_POINT = "fuzzyq.envs.vector:make_vector"


def ids() -> dict[str, tuple[str, bool]]:
    """Every id `fuzzyq.envs.registry.make` serves: ``id -> (env, continuous)``. The point
    masses' discrete id, ``FuzzyQ/PointMass-v0``, is `fuzzyq.envs.PointMassEnv` instead."""
    out: dict[str, tuple[str, bool]] = {}
    for env, name in NAMES.items():
        if env != "pointmass":
            out[f"FuzzyQ/{name}-v0"] = (env, False)
        out[f"FuzzyQ/{name}Continuous-v0"] = (env, True)
    return out


def register(gymnasium: Any) -> None:
    """Registers every id not registered yet, each limited to its environment's
    `EPISODE_STEPS` by Gymnasium's `TimeLimit` (``max_episode_steps=n`` overrides it), with
    `fuzzyq.envs.ModelVectorEnv` as its vector entry point (except the `STATEFUL` ones)."""
    if "FuzzyQ/PointMass-v0" not in gymnasium.registry:
        gymnasium.register(
            id="FuzzyQ/PointMass-v0",
            entry_point="fuzzyq.envs.point_mass_gym:PointMassEnv",
            vector_entry_point=VECTOR_ENTRY_POINT,
            max_episode_steps=EPISODE_STEPS["pointmass"],
            kwargs={"max_steps": None},
        )
    for env_id, (env, continuous) in ids().items():
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id,
                entry_point="fuzzyq.envs.registry:make",
                vector_entry_point=None if env in STATEFUL else VECTOR_ENTRY_POINT,
                max_episode_steps=EPISODE_STEPS[env],
                kwargs={"env": env, "continuous": continuous},
            )
