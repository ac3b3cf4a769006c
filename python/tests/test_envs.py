"""Tests of the Gymnasium and PettingZoo environments in `fuzzyq.envs`: the point-mass task,
its registration and rendering, and `ModelEnv` / `ModelParallelEnv` over every model kind."""

from __future__ import annotations

import importlib
import importlib.util
import subprocess
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

if importlib.util.find_spec("matplotlib") is not None:
    import matplotlib

    matplotlib.use("Agg")  # "human" rendering draws off screen in the tests
HAS_MATPLOTLIB = importlib.util.find_spec("matplotlib") is not None

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
        # The made envs' render check makes one env per render mode ("human" needs matplotlib).
        skip = not HAS_MATPLOTLIB
        check_env(gymnasium.make(ENV_ID, agents=agents).unwrapped, skip_render_check=skip)
        for mode in ["ansi", "rgb_array"]:
            made = gymnasium.make(ENV_ID, agents=agents, render_mode=mode).unwrapped
            check_env(made, skip_render_check=skip)


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
            make(render_mode="rgb_array_list")
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
    with pytest.raises(ImportError, match=r"pip install gymnasium pettingzoo"):
        importlib.import_module("fuzzyq.envs")


# --- registration on `import fuzzyq`, episode length through the spec ---------------------------


def run_python(code: str) -> subprocess.CompletedProcess[str]:
    """Runs `code` in a fresh interpreter (this one's, so the same installed fuzzyq)."""
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False
    )


def test_plain_import_registers_the_gymnasium_id() -> None:
    result = run_python(
        "import sys\n"
        "import fuzzyq, gymnasium\n"
        "assert 'FuzzyQ/PointMass-v0' in gymnasium.registry\n"
        "assert not any(m in sys.modules for m in ('fuzzyq.envs', 'pettingzoo', 'matplotlib'))\n"
        "env = gymnasium.make('FuzzyQ/PointMass-v0', agents=1)\n"
        "assert env.spec.max_episode_steps == 75 and env.action_space.n == 25\n"
        "print('ok')\n"
    )
    assert result.returncode == 0 and result.stdout == "ok\n", result.stderr


def test_plain_import_without_gymnasium_does_not_try_to_import_it() -> None:
    # `sys.modules[name] = None` is how an uninstalled module looks to `find_spec` (None) and
    # to `import` (ImportError): `import fuzzyq` must still work and import nothing of it.
    result = run_python(
        "import sys\n"
        "sys.modules['gymnasium'] = None\n"
        "import fuzzyq\n"
        "assert not any(m.startswith(('gymnasium.', 'fuzzyq.envs')) for m in sys.modules)\n"
        "assert fuzzyq.PointMass(agents=1).n_joint_actions == 25\n"
        "print('ok')\n"
    )
    assert result.returncode == 0 and result.stdout == "ok\n", result.stderr


def test_spec_sets_max_episode_steps() -> None:
    spec = gymnasium.spec(ENV_ID)
    assert spec.max_episode_steps == 75
    assert spec.kwargs == {"max_steps": None}  # the TimeLimit truncates, not the env


def truncation_step(env: Any, limit: int) -> int:
    """The step at which `env` truncates (at most `limit` + 1 steps)."""
    env.reset(seed=0)
    for k in range(1, limit + 2):
        _, _, terminated, truncated, info = env.step(12)
        assert terminated is False
        if truncated:
            assert info["steps"] == k
            return k
    return -1


def test_make_honours_max_episode_steps() -> None:
    with warnings_as_errors():
        longer = gymnasium.make(ENV_ID, agents=1, max_episode_steps=200)
        assert longer.spec is not None and longer.spec.max_episode_steps == 200
        assert longer.unwrapped.max_steps is None  # type: ignore[attr-defined]
        assert truncation_step(longer, 200) == 200
        assert truncation_step(gymnasium.make(ENV_ID, agents=1), 75) == 75
        assert truncation_step(gymnasium.make(ENV_ID, agents=1, max_episode_steps=3), 3) == 3
    # Built directly, the env truncates on its own (default 75, the paper's 30 s).
    assert truncation_step(fenvs.PointMassEnv(agents=1), 75) == 75
    assert truncation_step(fenvs.PointMassEnv(agents=1, max_steps=10), 10) == 10
    # The text picture shows the env's own episode length (none when made: TimeLimit's).
    env = gymnasium.make(ENV_ID, agents=1, render_mode="ansi")
    env.reset(seed=0)
    assert str(env.render()).startswith("step 0  in_goal=")
    direct = fenvs.PointMassEnv(agents=1, max_steps=10, render_mode="ansi")
    direct.reset(seed=0)
    assert str(direct.render()).startswith("step 0/10  in_goal=")


# --- rendering ---------------------------------------------------------------------------------


def colour_mask(img: np.ndarray, colour: tuple[int, int, int]) -> np.ndarray:
    return np.all(img == np.asarray(colour, dtype=np.uint8), axis=-1)


def centroid(mask: np.ndarray) -> tuple[float, float]:
    rows, cols = np.nonzero(mask)
    assert rows.size > 0, "no pixel of that colour"
    return float(rows.mean()), float(cols.mean())


def test_rgb_array_draws_arena_goal_and_agents_where_they_are() -> None:
    from fuzzyq.envs import _render

    env = fenvs.PointMassEnv(agents=3, render_mode="rgb_array")
    x0 = [-3.0, 3.0, 0.0, 0.0, 3.0, -1.5, 0.0, 0.0, 6.0, 6.0, 0.0, 0.0]
    env.reset(options={"x0": x0})
    img = env.render()
    assert isinstance(img, np.ndarray) and img.dtype == np.uint8 and img.shape == (400, 400, 3)
    colours = fenvs.AGENT_COLOURS[:3]
    assert len(set(colours)) == 3  # distinct colours
    size = img.shape[0]
    for i, (sx, sy) in enumerate([(-3.0, 3.0), (3.0, -1.5), (6.0, 6.0)]):
        row, col = centroid(colour_mask(img, colours[i]))
        # The arena [-6, 6]^2 spans the picture but for a 20-pixel margin, y pointing up.
        expected_col = 20 + (sx + 6.0) / 12.0 * (size - 41)
        expected_row = 20 + (6.0 - sy) / 12.0 * (size - 41)
        tolerance = 3.5 if i == 2 else 1.0  # the corner disc is cut by the arena's border
        assert abs(col - expected_col) < tolerance and abs(row - expected_row) < tolerance
        assert (row, col) == pytest.approx(_render.arena_to_pixel(sx, sy, 6.0), abs=tolerance)
        assert colour_mask(img, colours[i]).sum() > 50  # a disc, not a dot
        assert not colour_mask(img, _render.tick_colour(i)).any()  # at rest: no velocity tick
    # Agent 0 is up and to the left of the centre, agent 1 down and to the right.
    (row0, col0), (row1, col1) = (centroid(colour_mask(img, c)) for c in colours[:2])
    assert col0 < size / 2 < col1 and row0 < size / 2 < row1
    # The goal region at the centre, the arena's border at its edge, white outside.
    goal = colour_mask(img, _render.GOAL) | colour_mask(img, _render.GOAL_BORDER)
    assert centroid(goal) == pytest.approx((size / 2 - 0.5, size / 2 - 0.5), abs=1.0)
    assert colour_mask(img, _render.ARENA_BORDER)[size // 2, 18]
    assert np.all(img[:10] == 255)


def test_rgb_array_velocity_tick_points_along_the_velocity() -> None:
    from fuzzyq.envs import _render

    env = fenvs.PointMassEnv(agents=2, render_mode="rgb_array")
    env.reset(options={"x0": [-3.0, 0.0, 3.0, 0.0, 3.0, 0.0, 0.0, 1.5]})
    img = env.render()
    assert isinstance(img, np.ndarray)
    for i, (d_row, d_col) in enumerate([(0.0, 1.0), (-1.0, 0.0)]):  # +x: right; +y: up
        disc_row, disc_col = centroid(colour_mask(img, fenvs.AGENT_COLOURS[i]))
        tick_row, tick_col = centroid(colour_mask(img, _render.tick_colour(i)))
        direction = np.array([tick_row - disc_row, tick_col - disc_col])
        assert np.linalg.norm(direction) > _render.AGENT_RADIUS
        assert direction / np.linalg.norm(direction) == pytest.approx([d_row, d_col], abs=0.05)
    # Full speed draws a longer tick than half speed.
    full = colour_mask(img, _render.tick_colour(0)).sum()
    half = colour_mask(img, _render.tick_colour(1)).sum()
    assert full > half > 0


def test_rgb_array_frames_follow_the_state_and_are_fresh() -> None:
    env = fenvs.PointMassEnv(agents=1, render_mode="rgb_array")
    env.reset(options={"x0": [-4.0, 0.0, 0.0, 0.0]})
    first = env.render()
    again = env.render()
    assert isinstance(first, np.ndarray) and isinstance(again, np.ndarray)
    assert first is not again and np.array_equal(first, again)
    env.step(env.model.joint_index([24]))  # push up and right
    moved = env.render()
    assert isinstance(moved, np.ndarray) and not np.array_equal(first, moved)
    with pytest.raises(gymnasium.error.ResetNeeded):
        fenvs.PointMassEnv(agents=1, render_mode="rgb_array").render()


def test_rgb_array_of_the_parallel_env_matches_the_gymnasium_env() -> None:
    x0 = [1.0, -2.0, 0.5, 0.0, -5.0, 5.0, 0.0, -3.0]
    gym_env = fenvs.PointMassEnv(agents=2, render_mode="rgb_array")
    par_env = fenvs.parallel_env(agents=2, render_mode="rgb_array")
    gym_env.reset(options={"x0": x0})
    par_env.reset(options={"x0": x0})
    assert_same(gym_env.render(), par_env.render(), "frames")
    assert par_env.metadata["render_modes"] == ["human", "rgb_array", "ansi"]


def test_pettingzoo_render_test() -> None:
    from pettingzoo.test import render_test  # type: ignore[import-untyped, unused-ignore]

    modes = ["rgb_array", "ansi"] + (["human"] if HAS_MATPLOTLIB else [])
    for mode in modes:
        render_test(
            lambda render_mode=mode: parallel_to_aec(
                fenvs.parallel_env(agents=2, render_mode=render_mode)
            )
        )


@pytest.mark.skipif(not HAS_MATPLOTLIB, reason="render_mode='human' needs matplotlib")
@pytest.mark.parametrize("kind", ["gym", "parallel", "model"])
def test_human_mode_draws_into_a_matplotlib_figure(kind: str) -> None:
    import matplotlib.pyplot as plt

    plt.close("all")
    env: Any
    if kind == "gym":
        env = gymnasium.make(ENV_ID, agents=1, render_mode="human")
        env.reset(seed=0)
        assert env.render() is None
        env.step(3)
    elif kind == "parallel":
        env = fenvs.parallel_env(agents=2, render_mode="human")
        env.reset(seed=0)
        assert env.render() is None
        env.step({"agent_0": 3, "agent_1": 4})
    else:
        env = fenvs.ModelEnv(fuzzyq.CarHill(), render_mode="human")
        env.reset(seed=0)
        assert env.render() is None
        env.step(1)
    figures = plt.get_fignums()
    assert len(figures) == 1  # one window, reused by every step
    image = plt.figure(figures[0]).axes[0].images[0].get_array()
    assert image is not None and image.shape[2] == 3
    env.close()
    assert plt.get_fignums() == []


@pytest.mark.parametrize("make", ["gym", "parallel", "model"])
def test_human_mode_without_matplotlib_names_the_extra(
    make: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # as if not installed
    with pytest.raises(ImportError, match=r"pip install matplotlib"):
        if make == "gym":
            fenvs.PointMassEnv(render_mode="human")
        elif make == "parallel":
            fenvs.parallel_env(render_mode="human")
        else:
            fenvs.ModelParallelEnv(fuzzyq.DcMotor(), render_mode="human")
    fenvs.PointMassEnv(render_mode="rgb_array")  # the other modes need nothing


# --- ModelEnv / ModelParallelEnv ------------------------------------------------------------------


def callable_model() -> fuzzyq.CallableModel:
    """Two agents on a line: agent 0 moves x0 by -0.5, 0 or +0.5, agent 1 moves x1 by -0.5 or
    +0.5; the reward is -|x|^2 and x0 reaching 1 is terminal."""

    def transition(x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        nxt = np.clip(x + 0.5 * u, -1.0, 1.0)
        return nxt, -np.sum(x**2, axis=1), nxt[:, 0] >= 1.0

    return fuzzyq.CallableModel(
        transition, state_dim=2, actions=[[[-1.0], [0.0], [1.0]], [[-1.0], [1.0]]]
    )


CALLABLE_BOUNDS = [[-1.0, 1.0], [-1.0, 1.0]]

MODELS: dict[str, Callable[[], Any]] = {
    "pointmass": lambda: fuzzyq.PointMass(agents=1),
    "pointmass2": lambda: fuzzyq.PointMass(agents=2),
    "dcmotor": fuzzyq.DcMotor,
    "pendulum": fuzzyq.Pendulum,
    "carhill": fuzzyq.CarHill,
    "arm": fuzzyq.Arm,
    "callable": callable_model,
}


def model_kwargs(name: str) -> dict[str, Any]:
    return {"bounds": CALLABLE_BOUNDS} if name == "callable" else {}


@pytest.mark.parametrize("name", list(MODELS))
def test_model_env_passes_the_checkers(name: str) -> None:
    from gymnasium.utils.passive_env_checker import env_render_passive_checker

    with warnings_as_errors():
        model = MODELS[name]()
        check_env(fenvs.ModelEnv(model, **model_kwargs(name)), skip_render_check=True)
        for mode in ["rgb_array", "ansi"]:
            env = fenvs.ModelEnv(model, render_mode=mode, **model_kwargs(name))
            env.reset(seed=0)
            env_render_passive_checker(env)
        parallel_api_test(fenvs.ModelParallelEnv(model, **model_kwargs(name)), num_cycles=50)
        parallel_seed_test(lambda: fenvs.ModelParallelEnv(model, **model_kwargs(name)))


@pytest.mark.parametrize("name", [n for n in MODELS if n != "callable"])
def test_model_env_spaces_of_the_built_in_models(name: str) -> None:
    model = MODELS[name]()
    env = fenvs.ModelEnv(model)
    par = fenvs.ModelParallelEnv(model)
    assert env.model is model and par.model is model
    assert env.action_space == gymnasium.spaces.Discrete(model.n_joint_actions)
    if isinstance(model, fuzzyq.PointMass):
        limits = np.tile([6.0, 6.0, 3.0, 3.0], model.n_agents)
        low, high = -limits, limits
        assert [par.action_space(a).n for a in par.possible_agents] == [25] * model.n_agents
    else:
        low, high = model.state_bounds[:, 0], model.state_bounds[:, 1]  # (state_dim, 2)
        assert par.possible_agents == ["agent_0"]
        assert par.action_space("agent_0").n == model.n_joint_actions
    space = env.observation_space
    assert isinstance(space, gymnasium.spaces.Box) and space.dtype == np.float32
    assert_same(space.low, low.astype(np.float32), "low")
    assert_same(space.high, high.astype(np.float32), "high")
    assert par.observation_space("agent_0") == space == par.state_space
    assert env.metadata["render_fps"] == pytest.approx(1.0 / model.sample_time)


def test_model_env_default_episode_lengths_are_those_of_rollout() -> None:
    for name in ["dcmotor", "pendulum", "carhill", "arm", "pointmass"]:
        model = MODELS[name]()
        bounds = (
            model.state_bounds
            if name != "pointmass"
            else np.array([[-6.0, 6.0], [-6.0, 6.0], [-3.0, 3.0], [-3.0, 3.0]])
        )
        grid = fuzzyq.Grid([np.linspace(lo, hi, 3) for lo, hi in bounds])
        policy = fuzzyq.solve(model, grid).policy("greedy")
        x0 = None if name != "pointmass" else X0  # from a start that does not end early
        steps = len(policy.rollout(x0)["states"]) - 1
        assert fenvs.default_episode_steps(model) == steps, name
        assert fenvs.ModelEnv(model).max_steps == steps


def test_model_env_of_a_point_mass_is_the_point_mass_env() -> None:
    """Same seed, same actions: the same trajectory as PointMassEnv, and in parallel form."""
    model = fuzzyq.PointMass(agents=2)
    envs: list[Any] = [fenvs.ModelEnv(model), fenvs.PointMassEnv(agents=2)]
    pars: list[Any] = [fenvs.ModelParallelEnv(model), fenvs.parallel_env(agents=2)]
    first = [env.reset(seed=5) for env in envs]
    assert_same(first[0], first[1], "reset")
    assert_same(pars[0].reset(seed=5), pars[1].reset(seed=5), "parallel reset")
    rng = np.random.default_rng(1)
    for _ in range(75):
        per_agent = rng.integers(25, size=2).tolist()
        a, b = (env.step(model.joint_index(per_agent)) for env in envs)
        assert_same(a, b, "transition")
        actions = dict(zip(pars[0].agents, per_agent, strict=True))
        assert_same(pars[0].step(actions), pars[1].step(actions), "parallel transition")
    assert a[3] is True and pars[0].agents == []


def test_model_env_follows_the_model_and_terminates_like_rollout() -> None:
    model = fuzzyq.CarHill()
    policy = fuzzyq.solve(model, model.grid()).policy("greedy")
    run = policy.rollout()  # from the default start; reaches the hilltop early
    env = fenvs.ModelEnv(model)
    par = fenvs.ModelParallelEnv(model)
    obs, info = env.reset(seed=0)
    par.reset(seed=0)
    assert_same(info["state"], model.default_start, "default start")
    states, rewards = [info["state"]], []
    terminated = truncated = False
    while not (terminated or truncated):
        action = policy.act_index(info["state"])
        obs, reward, terminated, truncated, info = env.step(action)
        _, prewards, pterms, _, pinfos = par.step({"agent_0": action})
        assert_same(pinfos["agent_0"], info, "parallel info")
        assert prewards == {"agent_0": reward} and pterms == {"agent_0": terminated}
        states.append(info["state"])
        rewards.append(reward)
    assert terminated and not truncated and par.agents == []
    assert_same(np.array(states), run["states"], "states of ModelEnv and Policy.rollout")
    assert_same(np.array(rewards), run["rewards"], "rewards of ModelEnv and Policy.rollout")
    assert model.is_terminal(info["state"])
    assert obs in env.observation_space  # clipped, though the car left the hill
    assert info["state"][0] > 1.0 and obs[0] == 1.0
    with pytest.raises(gymnasium.error.ResetNeeded, match="terminal"):
        env.step(0)
    with pytest.raises(gymnasium.error.ResetNeeded):
        par.step({"agent_0": 0})


def test_model_env_start_options() -> None:
    model = fuzzyq.Pendulum()
    fixed = fenvs.ModelEnv(model, start=[0.5, -1.0])
    assert_same(fixed.reset(seed=0)[1]["state"], np.array([0.5, -1.0]), "fixed start")
    assert_same(fixed.reset(options={"x0": [0.0, 2.0]})[1]["state"], np.array([0.0, 2.0]), "x0")

    def draw(rng: np.random.Generator) -> np.ndarray:
        return rng.uniform([-1.0, -1.0], [1.0, 1.0])

    drawn = fenvs.ModelEnv(model, start=draw)
    a = drawn.reset(seed=3)[1]["state"]
    assert_same(drawn.reset(seed=3)[1]["state"], a, "seeded start(rng)")
    assert not np.array_equal(drawn.reset(seed=4)[1]["state"], a)


# The CallableModel tests need its step(), actions and joint_index (fuzzyq > 0.1.0's wheel).


def test_callable_model_env_bounds_and_default_start() -> None:
    assert fenvs.default_episode_steps(callable_model()) is None
    assert fenvs.ModelEnv(callable_model(), bounds=CALLABLE_BOUNDS).max_steps is None
    # The default start of a CallableModel with bounds: uniform within them.
    env = fenvs.ModelEnv(callable_model(), bounds=CALLABLE_BOUNDS)
    starts = np.array([env.reset(seed=s)[1]["state"] for s in range(100)])
    assert np.all(np.abs(starts) <= 1.0) and starts.min() < -0.8 and starts.max() > 0.8
    # A Grid gives the bounds: its first and last cores.
    grid = fuzzyq.Grid([[-2.0, 0.0, 2.0], [-1.0, 1.0]])
    space = fenvs.ModelEnv(callable_model(), bounds=grid).observation_space
    assert isinstance(space, gymnasium.spaces.Box)
    assert space.low.tolist() == [-2.0, -1.0] and space.high.tolist() == [2.0, 1.0]


def test_callable_model_env_steps_the_function() -> None:
    model = callable_model()
    env = fenvs.ModelEnv(model, start=[0.0, 0.5], max_steps=10)
    assert env.action_space == gymnasium.spaces.Discrete(6)
    env.reset(seed=0)
    joint = model.joint_index([2, 0])  # x0 + 0.5, x1 - 0.5
    assert model.agent_indices(joint) == [2, 0]
    _, reward, terminated, truncated, info = env.step(joint)
    assert_same(info["state"], np.array([0.5, 0.0]), "state")
    assert reward == -0.25 and not terminated and not truncated
    _, reward, terminated, truncated, info = env.step(joint)
    assert_same(info["state"], np.array([1.0, -0.5]), "state")
    assert reward == -0.25 and terminated and not truncated
    # The parallel env: each agent its own action set.
    par = fenvs.ModelParallelEnv(model, start=[0.0, 0.5])
    assert par.possible_agents == ["agent_0", "agent_1"]
    assert [par.action_space(a).n for a in par.possible_agents] == [3, 2]
    assert par.observation_space("agent_0").shape == (2,)
    assert not np.isfinite(par.observation_space("agent_0").high).any()  # no bounds given
    par.reset(seed=0)
    _, _, terms, _, infos = par.step({"agent_0": 2, "agent_1": 0})
    assert_same(infos["agent_1"]["state"], np.array([0.5, 0.0]), "parallel state")
    _, rewards, terms, _, _ = par.step({"agent_0": 2, "agent_1": 0})
    assert terms == {"agent_0": True, "agent_1": True} and par.agents == []
    assert rewards == {"agent_0": -0.25, "agent_1": -0.25}
    with pytest.raises(ValueError, match="agent_1"):
        par.reset(seed=0)
        par.step({"agent_0": 0, "agent_1": 2})  # agent 1 has two actions


def test_model_env_rgb_array_of_other_models() -> None:
    from fuzzyq.envs import _render

    env = fenvs.ModelEnv(fuzzyq.Arm(), render_mode="rgb_array")
    env.reset(seed=0)
    img = env.render()
    assert isinstance(img, np.ndarray) and img.dtype == np.uint8 and img.shape == (180, 400, 3)
    low, high = fuzzyq.Arm().state_bounds.T
    for d, value in enumerate(fuzzyq.Arm().default_start):
        row, col = centroid(colour_mask(img, fenvs.AGENT_COLOURS[d]))
        assert row == pytest.approx(30 + 40 * d, abs=0.5)  # one gauge per state variable
        expected = 20 + (value - low[d]) / (high[d] - low[d]) * 359
        assert col == pytest.approx(expected, abs=1.0)
    assert not colour_mask(img, _render.TERMINAL_BORDER).any()
    # A terminal state turns the border red; an unbounded variable sits at (1 + tanh x) / 2.
    car = fenvs.ModelEnv(fuzzyq.CarHill(), start=[0.95, 2.5], render_mode="rgb_array")
    car.reset()
    _, _, terminated, _, _ = car.step(1)
    frame = car.render()
    assert terminated and isinstance(frame, np.ndarray)
    assert colour_mask(frame, _render.TERMINAL_BORDER)[0].all()
    text = fenvs.ModelParallelEnv(fuzzyq.DcMotor(), render_mode="ansi")
    text.reset()
    assert text.render() == "step 0/400  terminal=False\n  x = [-3.142, +0]\n"


def test_callable_model_env_rgb_array_of_unbounded_states() -> None:
    free = fenvs.ModelEnv(callable_model(), start=[0.0, 1.0], render_mode="rgb_array")
    free.reset()
    frame = free.render()
    assert isinstance(frame, np.ndarray)
    assert centroid(colour_mask(frame, fenvs.AGENT_COLOURS[0]))[1] == pytest.approx(199.5, abs=1)
    expected = 20 + (1 + np.tanh(1.0)) / 2 * 359
    assert centroid(colour_mask(frame, fenvs.AGENT_COLOURS[1]))[1] == pytest.approx(expected, abs=1)
    text = fenvs.ModelEnv(callable_model(), start=[0.0, 1.0], render_mode="ansi")
    text.reset()
    assert text.render() == "step 0  terminal=False\n  x = [+0, +1]\n"


def test_model_env_bad_arguments() -> None:
    with pytest.raises(TypeError, match="model must be a fuzzyq.PointMass"):
        fenvs.ModelEnv(object())  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="model must be"):
        fenvs.ModelParallelEnv("dcmotor")  # type: ignore[arg-type]
    with pytest.raises(fuzzyq.ConfigError, match="bounds"):
        fenvs.ModelEnv(fuzzyq.DcMotor(), bounds=[[0.0, 1.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match=r"start must be .* shape \(2,\)"):
        fenvs.ModelEnv(fuzzyq.DcMotor(), start=[0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="start must be"):
        fenvs.ModelEnv(fuzzyq.CarHill(), start=[2.0, 0.0])  # beyond the bounds
    with pytest.raises(TypeError, match="start must be"):
        fenvs.ModelEnv(fuzzyq.CarHill(), start="abc")
    env = fenvs.ModelEnv(fuzzyq.CarHill(), start=lambda rng: [5.0, 0.0])
    with pytest.raises(ValueError, match=r"the state returned by start\(rng\)"):
        env.reset()
    for bad, error in [(0, ValueError), (1.5, TypeError), ("long", TypeError)]:
        with pytest.raises(error, match="max_steps"):
            fenvs.ModelEnv(fuzzyq.CarHill(), max_steps=bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="render_mode"):
        fenvs.ModelEnv(fuzzyq.CarHill(), render_mode="rgb")
    env = fenvs.ModelEnv(fuzzyq.CarHill(), max_steps=None)
    with pytest.raises(gymnasium.error.ResetNeeded):
        env.step(0)
    env.reset()
    with pytest.raises(ValueError, match=r"Discrete\(2\)"):
        env.step(2)
    with pytest.raises(TypeError, match=r"Discrete\(2\)"):
        env.step(0.5)


def test_callable_model_env_bad_arguments() -> None:
    with pytest.raises(fuzzyq.ConfigError, match=r"start: a CallableModel has no default start"):
        fenvs.ModelEnv(callable_model())
    with pytest.raises(fuzzyq.InputError, match=r"bounds must be .* shape \(2, 2\)"):
        fenvs.ModelEnv(callable_model(), bounds=[[0.0, 1.0]])
    with pytest.raises(fuzzyq.InputError, match="low < high"):
        fenvs.ModelEnv(callable_model(), bounds=[[1.0, 0.0], [0.0, 1.0]])
    with pytest.raises(fuzzyq.ConfigError, match="Grid of 1 dimensions"):
        fenvs.ModelEnv(callable_model(), bounds=fuzzyq.Grid([[0.0, 1.0]]))
    with pytest.raises(fuzzyq.InputTypeError, match="bounds must be"):
        fenvs.ModelEnv(callable_model(), bounds="wide")


def test_make_without_pettingzoo_gives_install_hint(monkeypatch: pytest.MonkeyPatch) -> None:
    # The id is registered whenever gymnasium is installed; making it needs fuzzyq.envs.
    for name in [m for m in sys.modules if m == "fuzzyq.envs" or m.startswith("fuzzyq.envs.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "pettingzoo", None)
    with pytest.raises(ImportError, match=r"pip install gymnasium pettingzoo"):
        gymnasium.make(ENV_ID, agents=1)


@pytest.mark.parametrize(
    "make",
    [
        lambda: fenvs.PointMassEnv(agents=1),
        lambda: fenvs.parallel_env(agents=1),
        lambda: fenvs.ModelEnv(fuzzyq.DcMotor()),
        lambda: fenvs.ModelParallelEnv(fuzzyq.Arm()),
    ],
)
def test_metadata_declares_render_modes_and_fps(make: Callable[[], Any]) -> None:
    env = make()
    assert env.metadata["render_modes"] == ["human", "rgb_array", "ansi"]
    assert env.metadata["render_fps"] == pytest.approx(1.0 / env.model.sample_time)
    assert type(env).metadata["render_fps"] > 0  # the class's, for tools that read it
    assert env.render_mode is None and env.render() is None


def test_callable_model_without_terminal_flags_never_terminates() -> None:
    def transition(x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.clip(x + u, -1.0, 1.0), -np.abs(x[:, 0])

    model = fuzzyq.CallableModel(transition, state_dim=1, actions=[[[-1.0], [1.0]]])
    env = fenvs.ModelEnv(model, start=[0.0], max_steps=3)
    env.reset()
    results = [env.step(1) for _ in range(3)]
    assert [r[2] for r in results] == [False] * 3  # never terminated
    assert [r[3] for r in results] == [False, False, True]  # truncated by max_steps
    assert [r[1] for r in results] == [0.0, -1.0, -1.0]
    assert results[-1][4]["state"].tolist() == [1.0]
