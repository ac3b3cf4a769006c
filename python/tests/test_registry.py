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

import fuzzyq.envs  # noqa: E402
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


@pytest.mark.parametrize("env", CLASSIC)
@pytest.mark.parametrize("continuous", [False, True])
def test_the_native_vector_env_steps_as_the_sync_one(env: str, continuous: bool) -> None:
    name = _gym_ids.NAMES[env] + ("Continuous" if continuous else "")
    env_id = f"FuzzyQ/{name}-v0"
    native = gymnasium.make_vec(env_id, num_envs=4, vectorization_mode="vector_entry_point",
                                max_episode_steps=30)  # fmt: skip
    sync = gymnasium.make_vec(env_id, num_envs=4, vectorization_mode="sync", max_episode_steps=30)
    assert isinstance(native.unwrapped, fuzzyq.envs.ModelVectorEnv)
    assert native.action_space == sync.action_space
    # The classic benchmarks start at their default start: the same in both.
    a, _ = native.reset(seed=1)
    b, _ = sync.reset(seed=1)
    assert np.array_equal(a, b)
    space = native.action_space
    space.seed(5)
    for _ in range(70):  # past two truncations: the autoresets agree too
        actions = space.sample()
        got = native.step(actions)
        want = sync.step(actions)
        for x, y in zip(got[:4], want[:4]):
            assert np.array_equal(x, y)


def test_the_vector_env_refuses_bad_actions() -> None:
    env = fuzzyq.envs.ModelVectorEnv(fuzzyq.DcMotor(), 3)
    env.reset(seed=0)
    with pytest.raises(fuzzyq.InputError, match="actions"):
        env.step(np.array([0, 1]))
    with pytest.raises(fuzzyq.InputError, match="actions"):
        env.step(np.array([0, 1, 99]))
    with pytest.raises(fuzzyq.ConfigError, match="num_envs"):
        fuzzyq.envs.ModelVectorEnv(fuzzyq.DcMotor(), 0)


def test_a_callable_model_vectorises_through_its_own_function() -> None:
    def transition(x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        nx = np.clip(x + 0.1 * u, -1.0, 1.0)
        return nx, -np.abs(x[:, 0])

    model = fuzzyq.CallableModel(transition, state_dim=1, actions=[[-1.0, 1.0]])
    env = fuzzyq.envs.ModelVectorEnv(model, 2, bounds=[[-1.0, 1.0]], max_steps=3)
    obs, _ = env.reset(seed=0)
    obs2, rewards, terminated, truncated, _ = env.step(np.array([0, 1]))
    assert np.allclose(obs2[:, 0], np.clip(obs[:, 0] + np.array([-0.1, 0.1]), -1, 1), atol=1e-6)
    assert np.allclose(rewards, -np.abs(obs[:, 0]), atol=1e-6)
    assert not terminated.any() and not truncated.any()
