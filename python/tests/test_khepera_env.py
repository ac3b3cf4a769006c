"""The Khepera robots as environments: `fuzzyq.KheperaPlant` (the rapier plant the command
line rolls out on), ``FuzzyQ/Khepera-v0`` and its continuous variant through `ModelEnv`, and
the PettingZoo parallel environment with one agent per robot."""

from __future__ import annotations

import functools
import warnings
from typing import Any

import numpy as np
import pytest

import fuzzyq

gymnasium = pytest.importorskip("gymnasium", reason="pip install gymnasium")
pytest.importorskip("pettingzoo", reason="pip install pettingzoo")
from gymnasium.utils.env_checker import check_env  # noqa: E402
from pettingzoo.test import api_test, parallel_api_test  # noqa: E402
from pettingzoo.utils.conversions import parallel_to_aec  # noqa: E402

import fuzzyq.envs as fenvs  # noqa: E402

#: One robot starting 1 m left of the goal, facing it.
START = np.array([-1.0, 0.0, 0.0])
#: An arena with a box obstacle (the shape of examples/arenas/obstacle.toml).
OBSTACLE_ARENA = {
    "x": [-3.0, 3.0],
    "y": [-3.0, 3.0],
    "obstacle": [{"shape": "box", "center": [1.5, 1.5], "half_extents": [0.5, 0.25]}],
}


@functools.cache
def one_robot_policy() -> fuzzyq.Policy:
    """A greedy policy for one robot in a 3 m arena, on a small grid (milliseconds to solve)."""
    robots = fuzzyq.Khepera(agents=1, arena={"x": [-3.0, 3.0], "y": [-3.0, 3.0]})
    cores = [-3.0, -2.0, -1.0, -0.5, -0.2, 0.0, 0.2, 0.5, 1.0, 2.0, 3.0]
    grid = fuzzyq.Grid([cores, cores, np.linspace(-np.pi, np.pi, 17)])
    # float64: the policy's wheel speeds are the model's exactly (float32 would round them).
    return fuzzyq.solve(robots, grid, max_sweeps=300, precision="f64").policy("greedy")


def test_the_plant_steps_and_senses() -> None:
    robots = fuzzyq.Khepera(agents=2)
    plant = fuzzyq.KheperaPlant(robots, seed=1)
    with pytest.raises(fuzzyq.ConfigError, match="reset"):
        plant.step(robots.joint_action(0))
    start = robots.random_starts(1, seed=4)[0]
    plant.reset(start)
    np.testing.assert_allclose(plant.poses, start)
    assert plant.paper_state.shape == (8,) and not np.any(plant.paper_state[2::4])
    assert plant.sonar.shape == (2, 5) and np.all(plant.sonar > 0)
    forward = robots.joint_action(robots.joint_index([0, 0]))
    assert plant.step(forward) == 0
    moved = np.hypot(*(plant.poses - start).reshape(2, 3)[:, :2].T)
    speed = robots.params["forward_speed"] * robots.sample_time
    np.testing.assert_allclose(moved, speed, rtol=0.05)
    assert plant.collisions["total"] == 0 and plant.collisions["per_agent"] == [0, 0]


def test_plant_bad_input_is_a_typed_error() -> None:
    robots = fuzzyq.Khepera(agents=2)
    plant = fuzzyq.KheperaPlant(robots)
    with pytest.raises(fuzzyq.InputError, match="poses"):
        plant.reset([0.0, 0.0, 0.0])
    with pytest.raises(fuzzyq.InputError, match="overlaps robot 0"):
        plant.reset([1.0, 1.0, 0.0, 1.05, 1.0, 0.0])
    with pytest.raises(fuzzyq.InputError, match="wall"):
        plant.reset([5.99, 0.0, 0.0, 1.0, 1.0, 0.0])
    plant.reset([1.0, 1.0, 0.0, -1.0, -1.0, 0.0])
    with pytest.raises(fuzzyq.InputError, match="u"):
        plant.step([0.1, 0.1, np.nan, 0.0])
    assert robots.agent_indices(robots.joint_index([3, 1])) == [3, 1]
    assert robots.random_starts(0).shape == (0, 6)


def test_model_env_steps_exactly_the_plant() -> None:
    robots = fuzzyq.Khepera(agents=2)
    env = fenvs.ModelEnv(robots, max_steps=40)
    start = robots.random_starts(1, seed=9)[0]
    obs, info = env.reset(seed=0, options={"x0": start})
    plant = fuzzyq.KheperaPlant(robots)
    plant.reset(start)
    rng = np.random.default_rng(0)
    for _ in range(40):
        joint = int(rng.integers(robots.n_joint_actions))
        expected_reward = plant.reward
        plant.step(robots.joint_action(joint))
        obs, reward, terminated, truncated, info = env.step(joint)
        assert reward == expected_reward and not terminated
        np.testing.assert_array_equal(info["state"], plant.poses)
        np.testing.assert_array_equal(info["sonar"], plant.sonar)
        np.testing.assert_array_equal(obs, plant.poses.astype(np.float32))
    assert truncated and info["collisions"] == plant.collisions


def test_an_env_episode_is_the_command_lines_rollout() -> None:
    policy = one_robot_policy()
    env = fenvs.ModelEnv(policy_robots(), max_steps=60)
    obs, info = env.reset(options={"x0": START})
    poses, states = [info["state"]], [info["paper_state"]]
    for _ in range(60):
        obs, _, _, _, info = env.step(policy.act_index(obs))
        poses.append(info["state"])
        states.append(info["paper_state"])
    run = policy.rollout(START, steps=60)
    np.testing.assert_array_equal(np.array(poses).reshape(61, 1, 3), run["poses"])
    np.testing.assert_array_equal(np.array(states), run["states"])
    assert info["in_goal"], "the solved policy drives the robot into the goal region"


def policy_robots() -> fuzzyq.Khepera:
    return fuzzyq.Khepera(agents=1, arena={"x": [-3.0, 3.0], "y": [-3.0, 3.0]})


def test_predict_drives_the_registered_env() -> None:
    policy = one_robot_policy()
    arena = {"x": [-3.0, 3.0], "y": [-3.0, 3.0]}
    env = gymnasium.make("FuzzyQ/Khepera-v0", agents=1, arena=arena, max_episode_steps=60)
    obs, info = env.reset(options={"x0": START})
    done = False
    while not done:
        action, _ = policy.predict(obs)
        obs, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
    assert info["in_goal"]


@pytest.mark.filterwarnings("ignore:.*symmetric and normalized space")
def test_continuous_and_paper_variants() -> None:
    env = gymnasium.make("FuzzyQ/KheperaContinuous-v0", observation="paper")
    check_env(env.unwrapped, skip_render_check=True)
    speed = fuzzyq.Khepera().params["max_wheel_speed"]
    assert env.action_space.shape == (4,)
    np.testing.assert_allclose(env.action_space.high, speed)
    obs, info = env.reset(seed=2)
    assert obs.shape == (8,) and not np.any(obs[2::4])
    obs, *_, info = env.step(np.array([0.2, 0.2, -0.1, 0.1], dtype=np.float32))
    np.testing.assert_array_equal(obs, info["paper_state"].astype(np.float32))
    assert abs(np.hypot(obs[2], obs[3]) - 0.2) < 0.02  # robot 0 drove straight at 0.2 m/s


def test_wrong_uses_are_refused() -> None:
    with pytest.raises(fuzzyq.ConfigError, match="observation"):
        fenvs.ModelEnv(fuzzyq.DcMotor(), observation="paper")
    with pytest.raises(fuzzyq.ConfigError, match="observation"):
        fenvs.ModelEnv(fuzzyq.Khepera(), observation="sonar")  # type: ignore[arg-type]
    with pytest.raises(fuzzyq.ConfigError, match="bounds"):
        fenvs.ModelEnv(fuzzyq.Khepera(), bounds=[[0, 1]] * 6)
    with pytest.raises(fuzzyq.ConfigError, match="stateful"):
        fenvs.ModelVectorEnv(fuzzyq.Khepera(), 4)
    env = fenvs.ModelEnv(fuzzyq.Khepera())
    with pytest.raises(fuzzyq.InputError, match="overlaps"):
        env.reset(options={"x0": [0.0, 0.0, 0.0, 0.05, 0.0, 0.0]})


def test_make_vec_gives_the_robots_a_sync_vector() -> None:
    vec = gymnasium.make_vec("FuzzyQ/Khepera-v0", num_envs=3, max_episode_steps=5)
    assert isinstance(vec, gymnasium.vector.SyncVectorEnv)
    obs, _ = vec.reset(seed=1)
    assert obs.shape == (3, 6)
    obs, *_ = vec.step(np.array([0, 5, 15]))
    vec.close()


def test_random_resets_are_seeded_starts_clear_of_everything() -> None:
    robots = fuzzyq.Khepera(agents=3, arena=OBSTACLE_ARENA)
    env = fenvs.ModelEnv(robots)
    first, _ = env.reset(seed=5)
    again, _ = env.reset(seed=5)
    np.testing.assert_array_equal(first, again)
    poses = first.reshape(3, 3)
    gaps = [np.hypot(*(poses[i, :2] - poses[j, :2])) for i in range(3) for j in range(i)]
    assert min(gaps) >= 0.5 and np.all(np.abs(poses[:, :2]) <= 2.5)


def test_rgb_frame_draws_arena_obstacle_and_robots() -> None:
    robots = fuzzyq.Khepera(agents=2, arena=OBSTACLE_ARENA)
    env = fenvs.ModelEnv(robots, render_mode="rgb_array")
    env.reset(options={"x0": [-1.0, -1.0, 0.0, 1.0, -1.0, np.pi / 2]})
    frame = env.render()
    assert isinstance(frame, np.ndarray) and frame.shape == (400, 400, 3)
    colours = {tuple(c) for c in frame.reshape(-1, 3)}
    assert (120, 120, 120) in colours  # the obstacle
    assert fenvs.AGENT_COLOURS[0] in colours and fenvs.AGENT_COLOURS[1] in colours
    # The obstacle's centre (1.5, 1.5) is at pixel (row, col) = (20 + 1.5 s, 20 + 4.5 s).
    s = (400 - 1 - 40) / 6.0
    assert tuple(frame[round(20 + 1.5 * s), round(20 + 4.5 * s)]) == (120, 120, 120)


def test_pettingzoo_parallel_and_aec_api() -> None:
    def make() -> fenvs.ModelParallelEnv:
        return fenvs.ModelParallelEnv(fuzzyq.Khepera(agents=2), max_steps=30)

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        parallel_api_test(make(), num_cycles=40)
        api_test(parallel_to_aec(make()), num_cycles=40)
    env = make()
    assert env.possible_agents == ["agent_0", "agent_1"]
    assert all(env.action_space(a).n == 4 for a in env.possible_agents)


def test_parallel_env_equals_the_gym_env() -> None:
    robots = fuzzyq.Khepera(agents=2)
    start = robots.random_starts(1, seed=3)[0]
    gym_env = fenvs.ModelEnv(robots, max_steps=20)
    par = fenvs.ModelParallelEnv(robots, max_steps=20)
    gym_env.reset(options={"x0": start})
    par.reset(options={"x0": start})
    rng = np.random.default_rng(7)
    for _ in range(20):
        a: Any = rng.integers(4, size=2)
        obs, reward, *_ = gym_env.step(robots.joint_index([int(a[0]), int(a[1])]))
        pobs, prewards, *_ = par.step({"agent_0": int(a[0]), "agent_1": int(a[1])})
        np.testing.assert_array_equal(obs, pobs["agent_1"])
        assert prewards["agent_0"] == reward
