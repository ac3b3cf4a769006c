"""Every built-in task's Gymnasium ids (registered by ``import fuzzyq``): discrete and
continuous, checked by Gymnasium's checker, each driven by a fuzzyq policy through its
Stable-Baselines3-style ``predict``."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import pytest

import fuzzyq

gymnasium = pytest.importorskip("gymnasium", reason="pip install gymnasium")
pytest.importorskip("pettingzoo", reason="pip install pettingzoo")
from gymnasium.utils.env_checker import check_env  # noqa: E402

from fuzzyq import _gym_ids  # noqa: E402

IDS = ["FuzzyQ/PointMass-v0", *_gym_ids.ids()]
CLASSIC = ["dcmotor", "pendulum", "carhill", "arm"]


def test_import_registers_every_built_in_task() -> None:
    registered = {i for i in gymnasium.registry if i.startswith("FuzzyQ/")}
    assert registered == set(IDS)
    for name in ["PointMass", "DcMotor", "Pendulum", "CarHill", "Arm"]:
        assert f"FuzzyQ/{name}Continuous-v0" in registered


@pytest.mark.filterwarnings("ignore:.*symmetric and normalized space")
@pytest.mark.parametrize("env_id", IDS)
def test_each_id_makes_an_env_the_checker_passes(env_id: str) -> None:
    env = gymnasium.make(env_id)
    check_env(env.unwrapped, skip_render_check=True)
    env_name, _ = _gym_ids.ids().get(env_id, ("pointmass", False))
    assert env.spec is not None
    assert env.spec.max_episode_steps == _gym_ids.EPISODE_STEPS[env_name]
    obs, _ = env.reset(seed=3)
    truncated = terminated = False
    steps = 0
    while not (terminated or truncated):
        obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
        steps += 1
    assert steps <= _gym_ids.EPISODE_STEPS[env_name]


@functools.cache
def classic_solution(env: str) -> fuzzyq.Solution:
    model: Any = {"dcmotor": fuzzyq.DcMotor, "pendulum": fuzzyq.Pendulum,
                  "carhill": fuzzyq.CarHill, "arm": fuzzyq.Arm}[env]()  # fmt: skip
    return fuzzyq.solve(model, model.grid(), max_sweeps=30)


@pytest.mark.parametrize("env", CLASSIC)
def test_a_policy_drives_both_variants_through_predict(env: str) -> None:
    solution = classic_solution(env)
    name = _gym_ids.NAMES[env]
    for env_id, kind in [(f"FuzzyQ/{name}-v0", "greedy"), (f"FuzzyQ/{name}Continuous-v0", "interpolated")]:  # fmt: skip
        made = gymnasium.make(env_id, max_episode_steps=20)
        policy = solution.policy(kind)
        obs, _ = made.reset(seed=0)
        for _ in range(20):
            action, state = policy.predict(obs)
            assert state is None and made.action_space.contains(
                np.asarray(action, dtype=made.action_space.dtype)
            )
            obs, _, terminated, truncated, _ = made.step(action)
            if terminated or truncated:
                break


def test_continuous_actions_are_the_joint_action_vector() -> None:
    import fuzzyq.envs

    model = fuzzyq.DcMotor()
    env = fuzzyq.envs.ContinuousModelEnv(model)
    discrete = fuzzyq.envs.ModelEnv(model)
    env.reset(options={"x0": [0.5, 1.0]})
    discrete.reset(options={"x0": [0.5, 1.0]})
    # A discrete action's vector steps as its index does.
    j = 2
    a = env.step(model.joint_action(j))
    b = discrete.step(j)
    assert np.array_equal(a[0], b[0]) and a[1] == b[1]
    # Beyond the box it is clipped; malformed actions are refused.
    env.reset(options={"x0": [0.5, 1.0]})
    high = env.step([1e6])
    env.reset(options={"x0": [0.5, 1.0]})
    assert np.array_equal(high[0], env.step([10.0])[0])
    with pytest.raises(fuzzyq.InputError, match="action"):
        env.step([1.0, 2.0])
    with pytest.raises(fuzzyq.InputError, match="action"):
        env.step([float("nan")])
    with pytest.raises(fuzzyq.InputTypeError, match="action"):
        env.step("left")


def test_make_passes_model_arguments() -> None:
    env = gymnasium.make("FuzzyQ/PointMassContinuous-v0", agents=1)
    assert env.action_space.shape == (2,)
    with pytest.raises(fuzzyq.ConfigError, match="env"):
        from fuzzyq.envs import registry

        registry.make("rocket")
