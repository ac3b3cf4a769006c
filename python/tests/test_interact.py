"""Learning and evaluation for a system of your own (`fuzzyq.Task`, `collect`, `learn`,
`evaluate`, `rollout`), on the two carts of examples/two_carts.py: as a Gymnasium environment
alone, and as a `CallableModel`."""

from __future__ import annotations

import pickle
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import fuzzyq

pytest.importorskip("gymnasium", reason="pip install gymnasium")
import fuzzyq.envs  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples"))
import two_carts  # noqa: E402


def resets(seed: int, episodes: int) -> np.ndarray:
    """The environment's start states of `episodes` episodes from `seed`, as `collect` draws
    them."""
    env = two_carts.TwoCartsEnv()
    return np.array([env.reset(seed=seed + i)[0] for i in range(episodes)])


@pytest.fixture(scope="module")
def learned() -> fuzzyq.Solution:
    return two_carts.learn(samples=20_000, seed=0)


def test_the_carts_are_learned_from_the_environment_alone(learned: fuzzyq.Solution) -> None:
    fit = learned.fit
    assert fit is not None and fit["samples"] == 20_000
    assert [b["state_dims"] for b in fit["blocks"]] == [[0, 1], [2, 3]]
    assert fit["reward"]["depends_on_action"] is False
    result = fuzzyq.evaluate(
        learned.policy("greedy"),
        two_carts.TwoCartsEnv(),
        task=two_carts.task(),
        count=100,
        seed=10_000,
    )
    assert result["summary"]["episodes"] == 100
    assert result["summary"]["success_rate"] >= 0.9, result["summary"]


def test_the_callable_model_learns_the_same_tables() -> None:
    task, grid = two_carts.task(), two_carts.grid()
    from_env = fuzzyq.collect(two_carts.TwoCartsEnv(), 3_000, task=task, seed=5)
    from_model = fuzzyq.collect(
        two_carts.callable_model(),
        3_000,
        seed=5,
        starts=resets(5, 30),
        episode_steps=two_carts.EPISODE_STEPS,
    )
    for key in ("states", "actions", "next_states", "rewards"):
        assert np.array_equal(from_env[key], from_model[key]), key
    a = fuzzyq.solve(task, grid, transitions=from_env)
    b = fuzzyq.solve(task, grid, transitions=from_model)
    assert np.asarray(a.V).tobytes() == np.asarray(b.V).tobytes()
    assert a.fit == b.fit


def test_evaluate_is_a_plain_loop(learned: fuzzyq.Solution) -> None:
    policy = learned.policy("greedy")
    task = two_carts.task()
    # A Gymnasium environment: episode i resets with seed + i.
    got = fuzzyq.evaluate(policy, two_carts.TwoCartsEnv(), task=task, count=3, seed=7)
    env = two_carts.TwoCartsEnv()
    for i in range(3):
        obs, _ = env.reset(seed=7 + i)
        total, done = 0.0, False
        while not done:
            j = int(policy.act_index(obs))
            action = np.array(divmod(j, len(two_carts.FORCES)))
            obs, r, terminated, truncated, info = env.step(action)
            total += r
            done = terminated or truncated
        assert got["runs"]["return"][i] == total
        assert got["runs"]["success"][i] == info["is_success"]
    # A CallableModel, against ModelEnv stepping the same function.
    model = two_carts.callable_model()
    starts = resets(11, 3)
    got = fuzzyq.evaluate(policy, model, starts=starts, steps=50, count=3)
    for i in range(3):
        menv = fuzzyq.envs.ModelEnv(model, start=starts[i], max_steps=50)
        menv.reset(seed=0)
        total, done = 0.0, False
        while not done:
            assert menv.state is not None
            _, r, terminated, truncated, _ = menv.step(policy.act_index(menv.state))
            total += float(r)
            done = terminated or truncated
        assert got["runs"]["return"][i] == total
    run = fuzzyq.rollout(policy, model, x0=starts[0], steps=50)
    assert run["return"] == got["runs"]["return"][0]
    assert run["states"].shape == (51, 4) and run["actions"].shape == (50, 2)
    assert run["success"] is None
    # The policy's own methods, with the system as its plant.
    assert policy.rollout(starts[0], 50, plant=model)["return"] == run["return"]
    by_method = policy.evaluate(starts, 50, count=3, plant=model)
    assert np.array_equal(by_method["runs"]["return"], got["runs"]["return"])


def test_rounds_collect_more_with_the_last_policy() -> None:
    sol = fuzzyq.learn(
        two_carts.TwoCartsEnv(),
        two_carts.task(),
        two_carts.grid(),
        samples=2_000,
        rounds=2,
        epsilon=0.2,
        gamma=0.97,
    )
    assert sol.fit is not None and sol.fit["samples"] == 4_000


def test_a_learned_solution_pickles(learned: fuzzyq.Solution) -> None:
    back = pickle.loads(pickle.dumps(learned))
    assert np.asarray(back.V).tobytes() == np.asarray(learned.V).tobytes()
    assert back.fit == learned.fit
    x = np.array([0.3, 0.1, -0.7, 0.0])
    assert back.policy("greedy").act_index(x) == learned.policy("greedy").act_index(x)


def test_a_reward_function_replaces_the_learned_reward() -> None:
    def reward(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return two_carts.transition(x, u)[1]

    base = two_carts.task()
    task = fuzzyq.Task(
        state_bounds=base.state_bounds,
        actions=base.actions,
        blocks=base.blocks,
        reward=reward,
    )
    data = fuzzyq.collect(two_carts.TwoCartsEnv(), 2_000, task=task, seed=1)
    sol = fuzzyq.solve(task, two_carts.grid(), transitions=data, gamma=0.97)
    assert sol.fit is not None and sol.fit["reward"] is None


@pytest.mark.parametrize(
    ("call", "error", "words"),
    [
        (lambda: fuzzyq.Task(state_bounds=[[1.0, 0.0]], actions=[[0.0, 1.0]]), fuzzyq.ConfigError, "state_bounds[0]"),
        (lambda: fuzzyq.Task(state_bounds=[[0.0, 1.0]], actions=[[0.0, 1.0]], periodic=[3]), fuzzyq.ConfigError, "periodic"),
        (lambda: fuzzyq.solve(two_carts.task(), two_carts.grid()), fuzzyq.ConfigError, "transitions"),
        (lambda: fuzzyq.collect(two_carts.TwoCartsEnv(), 10), fuzzyq.ConfigError, "task"),
        (lambda: fuzzyq.collect(two_carts.callable_model(), 10), fuzzyq.ConfigError, "starts"),
        (lambda: fuzzyq.collect(two_carts.TwoCartsEnv(), 0, task=two_carts.task()), fuzzyq.ConfigError, "samples"),
        (lambda: fuzzyq.collect(object(), 10), fuzzyq.InputTypeError, "source"),
        (lambda: fuzzyq.learn(two_carts.TwoCartsEnv(), two_carts.task(), two_carts.grid(), samples=10, rounds=0), fuzzyq.ConfigError, "rounds"),
    ],
)  # fmt: skip
def test_bad_input_is_refused(call: Any, error: type[Exception], words: str) -> None:
    with pytest.raises(error, match=words.replace("[", r"\[").replace("]", r"\]")):
        call()


def test_a_learned_solution_is_not_saved_as_a_file(tmp_path: Path) -> None:
    data = fuzzyq.collect(two_carts.TwoCartsEnv(), 500, task=two_carts.task(), seed=2)
    sol = fuzzyq.solve(two_carts.task(), two_carts.grid(), transitions=data)
    with pytest.raises(fuzzyq.ConfigError, match="pickling"):
        sol.save(tmp_path / "p.fzq")
    assert not (tmp_path / "p.fzq").exists()


def test_an_interpolated_policy_acts_with_vectors(learned: fuzzyq.Solution) -> None:
    policy = learned.policy("interpolated")
    model = two_carts.callable_model()
    x0 = np.array([0.3, 0.0, -0.6, 0.0])
    run = fuzzyq.rollout(policy, model, x0=x0, steps=5)
    for t in range(5):
        assert np.array_equal(run["actions"][t], policy.act(run["states"][t]))
        nx, r, _ = model.step(run["states"][t], run["actions"][t])
        assert np.array_equal(run["states"][t + 1], nx) and run["rewards"][t] == r
    # The carts' environment takes force indices: a vector cannot be applied.
    with pytest.raises(fuzzyq.ConfigError, match="interpolated"):
        fuzzyq.rollout(policy, two_carts.TwoCartsEnv(), task=two_carts.task())


#: The page of the docs on your own system.
PAGE = Path(__file__).resolve().parents[2] / "docs" / "site" / "python" / "own-system.md"


def run_docs_block(index: int) -> dict[str, Any]:
    """Runs python block `index` of `PAGE` as written; returns its variables."""
    blocks = re.findall(r"```python\n(.*?)```", PAGE.read_text(), flags=re.S)
    assert len(blocks) == 2
    scope: dict[str, Any] = {}
    exec(compile(blocks[index], str(PAGE), "exec"), scope)
    return scope


def test_the_docs_single_cart_example_runs_as_it_says(capsys: pytest.CaptureFixture[str]) -> None:
    scope = run_docs_block(0)
    assert scope["result"]["summary"]["success_rate"] == 1.0
    assert "success_rate" in capsys.readouterr().out


def test_fuzzy_q_learning_learns_the_carts_from_the_environment_alone() -> None:
    """The docs' example of fuzzy Q-learning on the carts, run as written."""
    scope = run_docs_block(1)
    policy, report = scope["policy"], scope["report"]
    assert (policy.learner, policy.env, policy.n_agents) == ("fql", None, 2)
    steps = report["curve"]["steps"]
    # The environment truncates at 100 steps, before the learner's own limit of 200.
    assert steps.max() == two_carts.EPISODE_STEPS and report["steps_total"] == steps.sum()
    assert not report["curve"]["terminal"].any()
    assert scope["result"]["summary"]["success_rate"] >= 0.9, scope["result"]["summary"]


@pytest.mark.parametrize("learner", ["fql", "vqql"])
def test_learning_your_own_system_is_deterministic_and_pickles(learner: Any) -> None:
    task, grid = two_carts.task(), two_carts.grid()
    runs = [
        fuzzyq.learn_from_samples(
            two_carts.TwoCartsEnv(), learner, task=task, grid=grid, episodes=30, seed=4
        )
        for _ in range(2)
    ]
    (policy, report), (again, _) = runs
    assert pickle.dumps(policy) == pickle.dumps(again)
    copy = pickle.loads(pickle.dumps(policy))
    states = np.random.default_rng(0).uniform(-1, 1, (50, 4))
    assert np.array_equal(copy.act_index(states), policy.act_index(states))
    assert np.array_equal(copy.q_values(states), policy.q_values(states))
    assert (report["lloyd"] is not None) == (learner == "vqql")
    run = policy.rollout(plant=two_carts.TwoCartsEnv(), task=task, seed=3)
    assert run["steps"] == two_carts.EPISODE_STEPS


def test_a_callable_model_learns_from_samples_too() -> None:
    policy, report = fuzzyq.learn_from_samples(
        two_carts.callable_model(),
        task=two_carts.task(),
        grid=two_carts.grid(),
        episodes=20,
        episode_steps=50,
    )
    assert report["curve"]["steps"].max() == 50
    # Decentralised and greedy: the joint action maximises the joint Q-values.
    for x in np.random.default_rng(1).uniform(-1, 1, (20, 4)):
        q = policy.q_values(x)
        assert q[policy.act_index(x)] == q.max()
        assert policy.act_index(x) == two_carts.callable_model().joint_index(policy.agent_actions(x))


def test_learning_your_own_system_refuses_what_it_lacks() -> None:
    env, task, grid = two_carts.TwoCartsEnv(), two_carts.task(), two_carts.grid()
    with pytest.raises(fuzzyq.ConfigError, match="task: learning"):
        fuzzyq.learn_from_samples(env, grid=grid)
    with pytest.raises(fuzzyq.ConfigError, match="grid: a system of your own"):
        fuzzyq.learn_from_samples(env, task=task)
    with pytest.raises(fuzzyq.ConfigError, match="grid: the task's state has 4 variables"):
        fuzzyq.learn_from_samples(env, task=task, grid=fuzzyq.Grid([[-1, 1]] * 3))
    with pytest.raises(fuzzyq.InputTypeError, match="task: expected a fuzzyq.Task"):
        fuzzyq.learn_from_samples(env, task=grid, grid=grid)  # type: ignore[arg-type]
    with pytest.raises(fuzzyq.ConfigError, match="cells"):
        fuzzyq.learn_from_samples(env, task=task, grid=grid, cells=4)
    with pytest.raises(fuzzyq.ConfigError, match="gamma"):
        fuzzyq.learn_from_samples(env, task=task, grid=grid, gamma=1.5)
    with pytest.raises(fuzzyq.ConfigError, match="reward_bound"):
        fuzzyq.learn_from_samples(env, task=task, grid=grid, reward_bound=-1.0)


def test_a_reward_bound_keeps_the_parameters_within_the_discounted_returns() -> None:
    task, grid = two_carts.task(), two_carts.grid()
    kw: dict[str, Any] = {"task": task, "grid": grid, "episodes": 30, "gamma": 0.9}
    free, _ = fuzzyq.learn_from_samples(two_carts.TwoCartsEnv(), **kw)
    bounded, _ = fuzzyq.learn_from_samples(two_carts.TwoCartsEnv(), reward_bound=0.05, **kw)
    states = np.random.default_rng(2).uniform(-1, 1, (200, 4))
    # Each cart's term stays within 0.05 / (1 - 0.9) = 0.5: their sum within 1.
    assert np.abs(bounded.q_values(states)).max() <= 1.0 + 1e-12  # 0.05 / 0.1 rounds up
    assert np.abs(free.q_values(states)).max() > 1.0


def test_an_exception_in_the_environment_is_raised() -> None:
    class Broken(two_carts.TwoCartsEnv):
        def step(self, action: Any) -> Any:
            if self.t == 7:
                raise RuntimeError("the carts derailed")
            return super().step(action)

    task, grid = two_carts.task(), two_carts.grid()
    with pytest.raises(RuntimeError, match="derailed"):
        fuzzyq.learn_from_samples(Broken(), task=task, grid=grid, episodes=5)
