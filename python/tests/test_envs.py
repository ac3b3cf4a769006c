"""Tests of the Gymnasium and PettingZoo point-mass environments in `fuzzyq.envs`."""

from __future__ import annotations

import importlib
import sys
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fuzzyq

gymnasium = pytest.importorskip("gymnasium")
pytest.importorskip("pettingzoo")

import fuzzyq.envs as fenvs  # noqa: E402
from gymnasium.utils.env_checker import check_env, data_equivalence  # noqa: E402
from pettingzoo.test import (  # type: ignore[import-untyped, unused-ignore]  # noqa: E402
    api_test,
    parallel_api_test,
    parallel_seed_test,
)
from pettingzoo.utils.conversions import (  # type: ignore[import-untyped, unused-ignore]  # noqa: E402
    parallel_to_aec,
)

ENV_ID = "FuzzyQ/PointMass-v0"
X0 = [-4.0, 3.0, 0.0, 0.0]


@contextmanager
def warnings_as_errors() -> Iterator[None]:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


@pytest.fixture(scope="module")
def greedy_one_agent() -> fuzzyq.Policy:
    model = fuzzyq.PointMass(agents=1)
    return fuzzyq.solve(model, model.paper_grid()).policy("greedy")


def assert_same(a: Any, b: Any, what: str) -> None:
    assert data_equivalence(a, b, exact=True), f"{what} differ: {a!r} != {b!r}"


# --- API conformance ---------------------------------------------------------------------------


@pytest.mark.parametrize("agents", [1, 2])
def test_gymnasium_check_env(agents: int) -> None:
    with warnings_as_errors():
        # A directly constructed env has no spec, so check_env could only warn that it cannot
        # try the other render modes: skip that part here; the made envs below cover it.
        check_env(fenvs.PointMassEnv(agents=agents), skip_render_check=True)
        check_env(gymnasium.make(ENV_ID, agents=agents).unwrapped)
        check_env(gymnasium.make(ENV_ID, agents=agents, render_mode="ansi").unwrapped)


def test_gymnasium_check_env_with_odd_limits() -> None:
    # Limits that float32 cannot represent: no precision warning, observations at the limits
    # still inside the space.
    kwargs: dict[str, Any] = {"agents": 2, "position_limit": 0.1, "velocity_limit": 0.3}
    with warnings_as_errors():
        check_env(fenvs.PointMassEnv(**kwargs), skip_render_check=True)
        env = fenvs.PointMassEnv(**kwargs)
        obs, _ = env.reset(seed=0, options={"x0": [0.1, -0.1, 0.3, -0.3, -0.1, 0.1, -0.3, 0.3]})
        assert obs in env.observation_space
        env.action_space.seed(0)
        for _ in range(40):  # large forces drive the state into the clamps
            obs, *_ = env.step(env.action_space.sample())
            assert obs in env.observation_space
        state = env.state
        assert state is not None and np.any(np.abs(state) == np.tile([0.1, 0.1, 0.3, 0.3], 2))


def test_gymnasium_make_wrapped_rollout_is_warning_free() -> None:
    with warnings_as_errors():
        env = gymnasium.make(ENV_ID)  # default agents=2, with the passive checker wrapper
        assert env.action_space.n == 25**2
        assert env.observation_space.shape == (8,)
        assert env.observation_space.dtype == np.float32
        env.action_space.seed(1)
        _, info = env.reset(seed=1)
        steps = 0
        truncated = False
        while not truncated:
            _obs, _reward, terminated, truncated, info = env.step(env.action_space.sample())
            steps += 1
            assert terminated is False
        assert steps == 75 and info["steps"] == 75
        env.close()


def test_gymnasium_registration() -> None:
    spec = gymnasium.spec(ENV_ID)
    assert spec.entry_point == "fuzzyq.envs.point_mass_gym:PointMassEnv"
    with warnings_as_errors():  # re-importing must not re-register (which warns)
        importlib.reload(fenvs)
    env = gymnasium.make(ENV_ID, agents=1, max_steps=5).unwrapped
    assert isinstance(env, fenvs.PointMassEnv)
    assert env.max_steps == 5 and env.model.n_agents == 1


@pytest.mark.parametrize("agents", [1, 2])
def test_pettingzoo_api(agents: int) -> None:
    with warnings_as_errors():
        parallel_api_test(fenvs.parallel_env(agents=agents), num_cycles=100)
        parallel_seed_test(lambda: fenvs.parallel_env(agents=agents))
        api_test(parallel_to_aec(fenvs.parallel_env(agents=agents)), num_cycles=100)


def test_pettingzoo_attributes() -> None:
    env = fenvs.parallel_env(agents=3, max_steps=2)
    assert env.metadata["name"] == "fuzzyq_pointmass_v0"
    assert env.possible_agents == ["agent_0", "agent_1", "agent_2"]
    assert env.agents == []
    for agent in env.possible_agents:
        assert env.observation_space(agent) is env.observation_space(agent)
        assert env.action_space(agent) is env.action_space(agent)
        assert env.action_space(agent) == gymnasium.spaces.Discrete(25)
        assert env.observation_space(agent).shape == (12,)
    assert env.action_space("agent_0") is not env.action_space("agent_1")
    obs, _infos = env.reset(seed=3)
    assert env.agents == env.possible_agents and env.agents is not env.possible_agents
    assert env.state() in env.state_space
    assert_same(env.state(), obs["agent_0"], "state() and the observation")
    actions = dict.fromkeys(env.agents, 12)
    _, _, _, truncations, _ = env.step(actions)
    assert not any(truncations.values()) and env.num_agents == 3
    _, _, terminations, truncations, _ = env.step(actions)
    assert all(truncations.values()) and not any(terminations.values())
    assert env.agents == [] and env.possible_agents == ["agent_0", "agent_1", "agent_2"]
    with pytest.raises(gymnasium.error.ResetNeeded):
        env.step({})
    with pytest.raises(ValueError, match="unknown agent"):
        env.action_space("agent_3")


# --- semantics -----------------------------------------------------------------------------------


def test_reset_distribution_and_x0() -> None:
    env = fenvs.PointMassEnv(agents=2)
    starts = np.array([env.reset(seed=s)[1]["state"] for s in range(200)])
    positions = starts.reshape(200, 2, 4)[:, :, :2]
    velocities = starts.reshape(200, 2, 4)[:, :, 2:]
    assert np.all(velocities == 0.0)
    assert np.all(np.abs(positions) <= 6.0)
    assert positions.min() < -5.0 and positions.max() > 5.0  # spread over the whole box
    x0 = np.array([1.0, -2.0, 0.5, -0.5, 6.0, -6.0, 3.0, -3.0])
    obs, info = env.reset(seed=0, options={"x0": x0})
    assert_same(info["state"], x0, "state")
    assert_same(obs, x0.astype(np.float32), "observation")
    assert set(info) == {"in_goal", "state", "steps"}
    assert info["in_goal"] is False and info["steps"] == 0
    # options without x0 (or with x0=None) fall back to a random start.
    assert env.reset(seed=5, options={})[1]["state"][2:4].tolist() == [0.0, 0.0]
    assert_same(env.reset(seed=5, options={"x0": None})[0], env.reset(seed=5)[0], "obs")


def test_step_semantics_reward_before_the_step() -> None:
    env = fenvs.PointMassEnv(agents=1, max_steps=3)
    model = env.model
    zero = model.joint_index([12])  # (0, 0) force
    assert model.joint_action(zero).tolist() == [0.0, 0.0]
    x0 = np.array([0.05, 0.0, 0.0, 0.0])  # in the goal
    _, info = env.reset(options={"x0": x0})
    assert info["in_goal"]
    push = model.joint_index([24])  # (2, 2): leaves the goal in one step
    _, reward, terminated, truncated, info = env.step(push)
    assert reward == model.goal_reward  # rho(x, u) of the state before the step
    assert not info["in_goal"] and terminated is False and truncated is False
    assert_same(info["state"], model.step(x0, model.joint_action(push)), "next state")
    _, reward, terminated, truncated, info = env.step(zero)
    assert reward == 0.0 and truncated is False
    _, reward, terminated, truncated, info = env.step(zero)
    assert truncated is True and terminated is False and info["steps"] == 3
    with pytest.raises(gymnasium.error.ResetNeeded):
        env.step(zero)
    env.reset()
    env.step(zero)  # usable again after reset


def test_no_truncation_when_max_steps_is_none() -> None:
    env = fenvs.PointMassEnv(agents=1, max_steps=None)
    env.reset(seed=0)
    for _ in range(200):
        _, _, terminated, truncated, _ = env.step(12)
        assert not terminated and not truncated


def test_vector_env_autoreset() -> None:
    envs = gymnasium.make_vec(ENV_ID, num_envs=2, vectorization_mode="sync", agents=1, max_steps=3)
    envs.reset(seed=0)
    truncations = []
    for _ in range(8):
        _, _, _, truncated, _ = envs.step(np.array([12, 0]))
        truncations.append(truncated.tolist())
    assert truncations[2] == [True, True] and truncations[6] == [True, True]
    envs.close()


def test_render_ansi() -> None:
    env = fenvs.PointMassEnv(agents=2, render_mode="ansi")
    with pytest.raises(gymnasium.error.ResetNeeded):
        env.render()
    env.reset(options={"x0": [1, 2, 0, 0, -1, -2, 0, 0]})
    text = env.render()
    assert isinstance(text, str) and "agent_0" in text and "agent_1" in text and "+1.000" in text
    assert fenvs.PointMassEnv(agents=1).render() is None
    penv = fenvs.parallel_env(agents=1, render_mode="ansi")
    penv.reset(seed=0)
    text = penv.render()
    assert isinstance(text, str) and "agent_0" in text
    assert penv.metadata["render_fps"] == pytest.approx(2.5)


# --- determinism -------------------------------------------------------------------------------


def gym_rollout(seed: int, action_seed: int) -> list[Any]:
    env = fenvs.PointMassEnv(agents=2)
    rng = np.random.default_rng(action_seed)
    trace: list[Any] = [env.reset(seed=seed)]
    truncated = False
    while not truncated:
        result = env.step(int(rng.integers(env.model.n_joint_actions)))
        trace.append(result)
        truncated = result[3]
    return trace


def parallel_rollout(seed: int, action_seed: int) -> list[Any]:
    env = fenvs.parallel_env(agents=2)
    rng = np.random.default_rng(action_seed)
    trace: list[Any] = [env.reset(seed=seed)]
    while env.agents:
        trace.append(env.step({a: int(rng.integers(25)) for a in env.agents}))
    return trace


@pytest.mark.parametrize("rollout", [gym_rollout, parallel_rollout])
def test_multistep_determinism(rollout: Callable[[int, int], list[Any]]) -> None:
    first, second = rollout(7, 99), rollout(7, 99)
    assert len(first) == len(second) == 76  # reset + 75 steps
    for k, (a, b) in enumerate(zip(first, second, strict=True)):
        assert_same(a, b, f"transition {k}")
    other_seed = rollout(8, 99)
    assert not data_equivalence(first[0], other_seed[0])  # a different initial state
    other_actions = rollout(7, 100)
    assert_same(first[0], other_actions[0], "initial observations")
    assert not data_equivalence(first[-1], other_actions[-1])


def test_gym_and_parallel_envs_agree() -> None:
    """Same seed, same actions: the same trajectory in both envs."""
    gym_env = fenvs.PointMassEnv(agents=2)
    par_env = fenvs.parallel_env(agents=2)
    obs, info = gym_env.reset(seed=11)
    pobs, pinfos = par_env.reset(seed=11)
    rng = np.random.default_rng(0)
    for _ in range(75):
        for agent in par_env.possible_agents:
            assert_same(pobs[agent], obs, "observation")
            assert_same(pinfos[agent], info, "info")
        per_agent = rng.integers(25, size=2).tolist()
        obs, reward, _, truncated, info = gym_env.step(gym_env.model.joint_index(per_agent))
        pobs, prewards, _, ptruncations, pinfos = par_env.step(
            dict(zip(par_env.agents, per_agent, strict=True))
        )
        assert set(prewards.values()) == {reward}
        assert set(ptruncations.values()) == {truncated}
    assert truncated and par_env.agents == []


def test_seeded_then_unseeded_resets_continue_the_stream() -> None:
    for make in (lambda: fenvs.PointMassEnv(agents=1), lambda: fenvs.parallel_env(agents=1)):
        a, b = make(), make()
        a.reset(seed=4)
        b.reset(seed=4)
        assert_same(a.reset(), b.reset(), "unseeded resets after equal seeds")


# --- a trained policy drives the envs ---------------------------------------------------------


def test_greedy_policy_reaches_goal_in_gymnasium_env(greedy_one_agent: fuzzyq.Policy) -> None:
    env = fenvs.PointMassEnv(agents=1)
    obs, info = env.reset(seed=0, options={"x0": X0})
    rewards = []
    for _ in range(75):
        obs, reward, terminated, _truncated, info = env.step(greedy_one_agent.act_index(obs))
        rewards.append(reward)
        assert not terminated
        if info["in_goal"]:
            break
    assert info["in_goal"], f"did not reach the goal: {info}"
    assert np.linalg.norm(info["state"][:2]) < 0.08
    assert np.linalg.norm(obs[:2]) < 0.08
    assert all(r == 0.0 for r in rewards)  # the goal pays from the next step on
    _, reward, _, _, _ = env.step(greedy_one_agent.act_index(obs))
    assert reward == env.model.goal_reward


def test_greedy_policy_reaches_goal_in_parallel_env(greedy_one_agent: fuzzyq.Policy) -> None:
    env = fenvs.parallel_env(agents=1)
    obs, infos = env.reset(seed=0, options={"x0": X0})
    reached = False
    for _ in range(75):
        actions = fenvs.greedy_actions(greedy_one_agent, obs)
        assert actions == fenvs.greedy_actions(greedy_one_agent, obs["agent_0"])
        obs, _rewards, terminations, _truncations, infos = env.step(actions)
        assert not any(terminations.values())
        if infos["agent_0"]["in_goal"]:
            reached = True
            break
    assert reached, f"did not reach the goal: {infos}"
    assert np.linalg.norm(infos["agent_0"]["state"][:2]) < 0.08
    assert np.linalg.norm(obs["agent_0"][:2]) < 0.08


def test_greedy_actions_for_two_agents() -> None:
    # A coarse grid keeps the two-agent solve well under a second.
    model = fuzzyq.PointMass(agents=2)
    grid = fuzzyq.Grid([[-6, -1, 0, 1, 6], [-6, -1, 0, 1, 6], [-3, 0, 3], [-3, 0, 3]] * 2)
    policy = fuzzyq.solve(model, grid).policy("greedy")
    x0 = [-4.0, 3.0, 0.0, 0.0, 2.0, -1.0, 0.0, 0.0]
    par_env = fenvs.parallel_env(agents=2)
    gym_env = fenvs.PointMassEnv(agents=2)
    obs, _ = par_env.reset(options={"x0": x0})
    gym_obs, _ = gym_env.reset(options={"x0": x0})
    distinct = False
    for _ in range(10):
        actions = fenvs.greedy_actions(policy, obs)
        per_agent = policy.agent_actions(obs["agent_0"])
        assert actions == {"agent_0": per_agent[0], "agent_1": per_agent[1]}
        assert actions == fenvs.greedy_actions(policy, obs["agent_1"])  # joint-array form
        assert model.joint_index(per_agent) == policy.act_index(gym_obs)
        distinct |= per_agent[0] != per_agent[1]
        obs, _, _, _, infos = par_env.step(actions)
        gym_obs, _, _, _, info = gym_env.step(policy.act_index(gym_obs))
        assert_same(infos["agent_0"]["state"], info["state"], "states")
    assert distinct, "the test should see the two agents choose different actions"


def test_greedy_actions_errors(greedy_one_agent: fuzzyq.Policy) -> None:
    obs = np.array(X0, dtype=np.float32)
    assert fenvs.greedy_actions(greedy_one_agent, obs) == {
        "agent_0": greedy_one_agent.agent_actions(obs)[0]
    }
    with pytest.raises(ValueError, match="unknown agent"):
        fenvs.greedy_actions(greedy_one_agent, {"agent_1": obs})
    with pytest.raises(ValueError):  # wrong state size
        fenvs.greedy_actions(greedy_one_agent, np.zeros(8))
    model = fuzzyq.PointMass(agents=1)
    interpolated = fuzzyq.solve(model, model.paper_grid()).policy("interpolated")
    with pytest.raises(ValueError):  # only greedy policies have discrete actions
        fenvs.greedy_actions(interpolated, {"agent_0": obs})


# --- bad input ---------------------------------------------------------------------------------

BAD_ACTIONS = [-1, 25, 10**30, 1.5, 2.0, np.float64(3.0), "3", None, True, np.array([1, 2]), [1]]


@pytest.mark.parametrize("action", BAD_ACTIONS, ids=repr)
def test_gymnasium_rejects_invalid_actions(action: Any) -> None:
    env = fenvs.PointMassEnv(agents=1)
    _, info = env.reset(seed=0)
    with pytest.raises((ValueError, TypeError)) as excinfo:
        env.step(action)
    assert "Discrete(25)" in str(excinfo.value)
    assert isinstance(excinfo.value, fuzzyq.FuzzyqError)
    assert_same(env.state, info["state"], "state after a rejected action")
    env.step(np.int64(3))  # the env is still usable; NumPy integers are accepted
    env.step(np.array(3))


@pytest.mark.parametrize("action", BAD_ACTIONS, ids=repr)
def test_parallel_rejects_invalid_actions(action: Any) -> None:
    env = fenvs.parallel_env(agents=2)
    _, infos = env.reset(seed=0)
    with pytest.raises((ValueError, TypeError), match="agent_1"):
        env.step({"agent_0": 3, "agent_1": action})
    assert_same(env.state(), infos["agent_0"]["state"].astype(np.float32), "state")


@pytest.mark.parametrize(
    "actions",
    [{"agent_0": 3}, {"agent_0": 3, "agent_1": 3, "agent_2": 3}, {"agent_0": 3, 1: 3}, [3, 3]],
    ids=repr,
)
def test_parallel_rejects_bad_action_dicts(actions: Any) -> None:
    env = fenvs.parallel_env(agents=2)
    env.reset(seed=0)
    with pytest.raises((ValueError, TypeError)):
        env.step(actions)
    env.step({"agent_0": 3, "agent_1": 3})


BAD_X0 = [
    [0.0, 0.0, 0.0],
    [[0.0, 0.0, 0.0, 0.0]],
    [7.0, 0.0, 0.0, 0.0],
    [0.0, -6.5, 0.0, 0.0],
    [0.0, 0.0, 3.5, 0.0],
    [np.nan, 0.0, 0.0, 0.0],
    [np.inf, 0.0, 0.0, 0.0],
    "abcd",
    ["a", 0.0, 0.0, 0.0],
    {"x": 1},
    3.0,
]


@pytest.mark.parametrize("x0", BAD_X0, ids=repr)
@pytest.mark.parametrize("kind", ["gym", "parallel"])
def test_bad_x0_is_rejected(x0: Any, kind: str) -> None:
    env: Any = fenvs.PointMassEnv(agents=1) if kind == "gym" else fenvs.parallel_env(agents=1)
    with pytest.raises((ValueError, TypeError), match=r"shape \(4,\)"):
        env.reset(options={"x0": x0})
    env.reset(options={"x0": X0})  # still usable


def test_bad_options_and_constructor_arguments() -> None:
    with pytest.raises(TypeError):
        fenvs.PointMassEnv(agents=1).reset(options=[("x0", X0)])  # type: ignore[arg-type]
    with pytest.raises(gymnasium.error.ResetNeeded):
        fenvs.PointMassEnv(agents=1).step(0)
    for make in (fenvs.PointMassEnv, fenvs.parallel_env):
        with pytest.raises(ValueError, match="render_mode"):
            make(render_mode="human")
        with pytest.raises(ValueError, match="max_steps"):
            make(max_steps=0)
        with pytest.raises(TypeError, match="max_steps"):
            make(max_steps=1.5)  # type: ignore[arg-type]
        with pytest.raises(fuzzyq.ConfigError):
            make(agents=0)
        with pytest.raises(TypeError):
            make(no_such_option=1)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-6.0, 6.0), min_size=2, max_size=2),
    st.lists(st.floats(-3.0, 3.0), min_size=2, max_size=2),
)
def test_any_x0_within_limits_is_accepted_exactly(pos: list[float], vel: list[float]) -> None:
    env = fenvs.PointMassEnv(agents=1)
    x0 = np.array(pos + vel)
    obs, info = env.reset(options={"x0": x0})
    assert_same(info["state"], x0, "state")
    assert obs in env.observation_space
    obs, *_ = env.step(0)
    assert obs in env.observation_space


# --- no aliasing -------------------------------------------------------------------------------


def test_gymnasium_observations_do_not_alias() -> None:
    env, control = fenvs.PointMassEnv(agents=2), fenvs.PointMassEnv(agents=2)
    x0 = np.array([1.0, 2.0, 0.0, 0.0, -1.0, -2.0, 0.0, 0.0])
    obs, info = env.reset(options={"x0": x0})
    control.reset(options={"x0": x0.copy()})
    x0[:] = 5.0  # the env copied x0
    obs[:] = 0.0
    info["state"][:] = 0.0
    assert_same(env.state, control.state, "state after mutating reset outputs")
    for _ in range(3):
        obs, _, _, _, info = env.step(100)
        control_obs, *_ = control.step(100)
        assert_same(obs, control_obs, "observations")
        obs += 1.0
        info["state"][:] = 0.0
        assert_same(env.state, control.state, "state after mutating step outputs")
    state = env.state
    assert state is not None
    state[:] = 0.0
    assert_same(env.state, control.state, "state after mutating the state property")


def test_parallel_observations_do_not_alias() -> None:
    env, control = fenvs.parallel_env(agents=2), fenvs.parallel_env(agents=2)
    obs, infos = env.reset(seed=2)
    control.reset(seed=2)
    assert not np.shares_memory(obs["agent_0"], obs["agent_1"])
    assert infos["agent_0"] is not infos["agent_1"]
    assert not np.shares_memory(infos["agent_0"]["state"], infos["agent_1"]["state"])
    obs["agent_0"][:] = 0.0
    infos["agent_1"]["state"][:] = 0.0
    assert obs["agent_1"].any()
    state = env.state()
    state[:] = 0.0
    assert_same(env.state(), control.state(), "state after mutating outputs")
    actions = {"agent_0": 4, "agent_1": 20}
    obs, _, _, _, infos = env.step(actions)
    control.step(actions)
    assert not np.shares_memory(obs["agent_0"], obs["agent_1"])
    obs["agent_1"][:] = 1.0
    assert_same(env.state(), control.state(), "state after mutating step outputs")


# --- optional dependencies ---------------------------------------------------------------------


@pytest.mark.parametrize("missing", ["gymnasium", "pettingzoo"])
def test_missing_optional_dependency_gives_install_hint(
    missing: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    for name in [m for m in sys.modules if m == "fuzzyq.envs" or m.startswith("fuzzyq.envs.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, missing, None)  # makes `import missing` fail
    with pytest.raises(ImportError, match=r"pip install fuzzyq\[envs\]"):
        importlib.import_module("fuzzyq.envs")
