"""Solutions and policies beyond one call: pickling, batched and parallel decisions, the
Stable-Baselines3 `predict` convention, a callback that stops a solve, and progress bars."""

from __future__ import annotations

import copy
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fuzzyq


@pytest.fixture(scope="module")
def one_agent() -> fuzzyq.Solution:
    model = fuzzyq.PointMass(agents=1)
    return fuzzyq.solve(model, model.paper_grid())


@pytest.fixture(scope="module")
def motor() -> fuzzyq.Solution:
    m = fuzzyq.DcMotor("toolbox-demo")
    return fuzzyq.solve(m, m.grid())


def random_states(n: int, dim: int, limit: float = 3.0, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-limit, limit, size=(n, dim))


@pytest.mark.parametrize(
    "make",
    [
        lambda: fuzzyq.Grid([np.linspace(-1, 1, 5), [0.0, 0.5, 2.0]]),
        lambda: fuzzyq.PointMass(
            agents=1, mass=0.7, integrator="rk4", friction_patches=[((0.0, 0.0), 1.0, 2.0)]
        ),
        lambda: fuzzyq.DcMotor("toolbox-demo", damping=1e-5),
        lambda: fuzzyq.Pendulum("fine", integrator={"rk4": {"substeps": 3}}),
        lambda: fuzzyq.CarHill("coarse", actions=[-4.0, 0.0, 4.0]),
        lambda: fuzzyq.Arm("fine"),
    ],
)
def test_grids_and_models_pickle(make: Any) -> None:
    obj = make()
    again = pickle.loads(pickle.dumps(obj))
    assert type(again) is type(obj)
    assert repr(again) == repr(obj)
    if isinstance(obj, fuzzyq.Grid):
        assert all(np.array_equal(a, b) for a, b in zip(again.cores, obj.cores))
    else:
        x = np.zeros(obj.state_dim) + 0.1
        u = obj.joint_action(obj.n_joint_actions - 1)
        assert np.array_equal(np.asarray(again.step(x, u)[0]), np.asarray(obj.step(x, u)[0]))
    if isinstance(obj, fuzzyq.ClassicModel):
        assert again.params == obj.params and again.preset == obj.preset


def test_solutions_and_policies_of_built_in_models_pickle(
    one_agent: fuzzyq.Solution, motor: fuzzyq.Solution
) -> None:
    for solution in (one_agent, motor):
        again = pickle.loads(pickle.dumps(solution))
        assert np.array_equal(again.V, solution.V) and again.V.dtype == solution.V.dtype
        assert np.array_equal(again.greedy, solution.greedy)
        assert again.env == solution.env and again.seconds == solution.seconds
        assert copy.deepcopy(solution).sweeps == solution.sweeps
        dim = solution.grid.n_dims
        states = random_states(64, dim, 1.0)
        for kind in ("greedy", "interpolated"):
            policy = solution.policy(kind)
            restored = pickle.loads(pickle.dumps(policy))
            assert restored.kind == kind
            assert np.array_equal(restored.act_batch(states), policy.act_batch(states))


def test_batched_decisions_equal_one_by_one(one_agent: fuzzyq.Solution) -> None:
    states = random_states(300, 4)
    greedy = one_agent.policy("greedy")
    indices = greedy.act_index(states)
    assert isinstance(indices, np.ndarray) and indices.dtype == np.int64 and indices.shape == (300,)
    assert indices.tolist() == [greedy.act_index(x) for x in states]
    vectors = greedy.act_batch(states)
    assert np.array_equal(vectors, np.stack([greedy.act(x) for x in states]))
    q = greedy.q_values(states[:7])
    assert q.shape == (7, 25)
    assert np.array_equal(q[3], greedy.q_values(states[3]))
    assert np.argmax(q, axis=1).tolist() == indices[:7].tolist()
    interpolated = one_agent.policy("interpolated")
    assert np.array_equal(
        interpolated.act_batch(states), np.stack([interpolated.act(x) for x in states])
    )


def test_predict_follows_stable_baselines3(one_agent: fuzzyq.Solution) -> None:
    states = random_states(5, 4)
    greedy = one_agent.policy("greedy")
    action, state = greedy.predict(states[0], deterministic=True)
    assert state is None and action.shape == () and action.dtype == np.int64
    assert int(action) == greedy.act_index(states[0])
    actions, _ = greedy.predict(states)
    assert actions.shape == (5,) and actions.tolist() == greedy.act_index(states).tolist()
    vectors, _ = one_agent.policy("interpolated").predict(states)
    assert vectors.shape == (5, 2)
    one, _ = one_agent.policy("interpolated").predict(states[0])
    assert one.shape == (2,)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.floats(min_value=-10, max_value=10, allow_nan=False), min_size=4, max_size=4
    )
)
def test_interpolated_actions_stay_within_the_action_bounds(x: list[float]) -> None:
    policy = _interpolated()
    u = policy.act(x)
    assert np.all(u >= -2.0) and np.all(u <= 2.0), u


_cache: dict[str, fuzzyq.Policy] = {}


def _interpolated() -> fuzzyq.Policy:
    if "p" not in _cache:
        model = fuzzyq.PointMass(agents=1)
        _cache["p"] = fuzzyq.solve(model, model.paper_grid()).policy("interpolated")
    return _cache["p"]


def test_interpolated_actions_on_many_random_states_stay_within_bounds(
    one_agent: fuzzyq.Solution,
) -> None:
    u = one_agent.policy("interpolated").act_batch(random_states(4000, 4, 6.0))
    assert u.max() <= 2.0 and u.min() >= -2.0


@pytest.mark.parametrize("evaluation_sweeps", [0, 5])
@pytest.mark.parametrize("extrapolate", [False, True])
def test_a_callback_returning_false_stops_and_keeps_the_partial_solution(
    evaluation_sweeps: int, extrapolate: bool
) -> None:
    model = fuzzyq.PointMass(agents=1)
    grid = model.paper_grid()
    seen: list[int] = []

    def stop_at_4(info: dict[str, Any]) -> bool | None:
        seen.append(info["sweep"])
        return False if info["sweep"] == 4 else None

    opts = dict(extrapolate=extrapolate, evaluation_sweeps=evaluation_sweeps)
    stopped = fuzzyq.solve(model, grid, callback=stop_at_4, **opts)  # type: ignore[arg-type]
    assert seen == [1, 2, 3, 4]
    limited = fuzzyq.solve(model, grid, max_sweeps=4, **opts)  # type: ignore[arg-type]
    assert stopped.stopped and not stopped.converged and not limited.stopped
    # Every sweep counts, evaluation sweeps too: the stop after sweep 4 returns 4 sweeps.
    assert stopped.sweeps == limited.sweeps == 4
    assert np.array_equal(stopped.V, limited.V)
    assert np.array_equal(stopped.greedy, limited.greedy)
    assert stopped.final_delta == limited.final_delta


def test_a_stop_under_the_default_scheme_returns_exactly_the_sweeps_run() -> None:
    # Regression (issue 49): under modified policy iteration (the default) a stop at sweep 10
    # ran on to 35 sweeps and max_sweeps=3 ran 13, counting only full backups.
    model = fuzzyq.PointMass(agents=1)
    grid = model.paper_grid()
    seen: list[dict[str, Any]] = []

    def stop_at_10(info: dict[str, Any]) -> bool:
        seen.append(info)
        return info["sweep"] < 10

    stopped = fuzzyq.solve(model, grid, xi=1e-6, callback=stop_at_10)
    assert seen[-1]["scheme"] == "modified-policy-iteration"
    assert any(d["evaluation"] for d in seen)
    assert [d["sweep"] for d in seen] == list(range(1, 11))
    assert stopped.stopped and not stopped.converged and stopped.sweeps == 10
    for k in (1, 2, 3, 7):
        limited = fuzzyq.solve(model, grid, xi=1e-6, max_sweeps=k)
        assert limited.sweeps == k and not limited.converged
        # The last sweep allowed is a full backup: the bound is MacQueen's, as on convergence.
        assert np.isfinite(limited.error_bound) and limited.error_bound > 0


def test_a_coarse_start_keeps_the_bound_and_reports_itself() -> None:
    model = fuzzyq.PointMass(agents=1)
    grid = model.paper_grid()
    plain = fuzzyq.solve(model, grid, xi=1e-3)
    seen: list[dict[str, object]] = []
    coarse = fuzzyq.solve(model, grid, xi=1e-3, coarse_start=True, callback=seen.append)
    assert plain.coarse_start is None
    # The callback gets the same coarse start after every sweep.
    assert seen and all(d["coarse_start"] == coarse.coarse_start for d in seen)
    info = coarse.coarse_start
    assert info is not None and info["cores"] == 15 * 15 and info["sweeps"] > 0
    assert info["seconds"] >= 0.0 and coarse.converged
    # Both within their own bound of the same fixed point.
    gap = float(np.abs(np.asarray(coarse.V, float) - np.asarray(plain.V, float)).max())
    assert gap <= coarse.error_bound + plain.error_bound + 1e-4
    assert not np.array_equal(coarse.V, plain.V)


def test_a_callback_stops_a_callable_model_solve() -> None:
    def transition(x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.clip(x + 0.1 * u, -1, 1), -(x[:, 0] ** 2)

    model = fuzzyq.CallableModel(transition, state_dim=1, actions=[[-1.0, 0.0, 1.0]])
    grid = fuzzyq.Grid([np.linspace(-1, 1, 11)])
    stopped = fuzzyq.solve(model, grid, xi=1e-9, callback=lambda i: i["sweep"] < 3)
    limited = fuzzyq.solve(model, grid, xi=1e-9, max_sweeps=3)
    assert stopped.stopped and stopped.sweeps == 3
    assert np.array_equal(stopped.V, limited.V)
    # Returning None or True continues; an exception propagates.
    assert not fuzzyq.solve(model, grid, callback=lambda i: None).stopped

    def boom(info: dict[str, Any]) -> None:
        raise KeyError("boom")

    with pytest.raises(KeyError, match="boom"):
        fuzzyq.solve(model, grid, callback=boom)


def test_progress_shows_a_tqdm_bar(capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("tqdm", reason="tqdm is not installed (pip install tqdm)")
    model = fuzzyq.DcMotor("toolbox-demo")
    fuzzyq.solve(model, model.grid(), progress=True)
    err = capsys.readouterr().err
    assert "fuzzy Q-iteration" in err and "sweep" in err


def test_progress_is_a_bool() -> None:
    model = fuzzyq.DcMotor("toolbox-demo")
    with pytest.raises(fuzzyq.InputTypeError, match="progress"):
        fuzzyq.solve(model, model.grid(), progress="yes")  # type: ignore[arg-type]


def test_the_robots_solve_roll_out_and_evaluate_from_python() -> None:
    robots = fuzzyq.Khepera(agents=1, goal_radius=0.3)
    assert robots.state_dim == 3 and robots.n_joint_actions == 4
    assert robots.params["goal_radius"] == 0.3
    again = pickle.loads(pickle.dumps(robots))
    assert again.params == robots.params
    grid = robots.grid()
    assert grid.shape == (19, 19, 17)
    solution = fuzzyq.solve(robots, grid)
    assert solution.env == "khepera" and solution.converged
    run = fuzzyq.rollout(solution.policy("greedy"), [2.0, 1.0, 0.0], 40)
    assert run["poses"].shape == (41, 1, 3)
    report = fuzzyq.evaluate(solution.policy("greedy"), count=3, steps=40, seed=5)
    assert report["summary"]["starts"] == 3
    assert report["runs"]["final_norm"].shape == (3,) and report["runs"]["success"].dtype == bool
    with pytest.raises(fuzzyq.ConfigError, match="unknown parameter"):
        fuzzyq.Khepera(wheels=3)
    with pytest.raises(fuzzyq.ConfigError, match="starts"):
        solution.policy("greedy").evaluate(np.zeros((2, 3)))


def test_evaluate_runs_many_starts(one_agent: fuzzyq.Solution, motor: fuzzyq.Solution) -> None:
    starts = random_states(4, 4, 3.0)
    report = fuzzyq.evaluate(one_agent.policy("greedy"), starts, steps=30)
    runs = report["runs"]
    assert all(len(v) == 4 for v in runs.values())
    one = one_agent.policy("greedy").rollout(starts[2], 30)
    assert runs["return"][2] == pytest.approx(one["metrics"]["return"])
    classic = fuzzyq.evaluate(motor.policy("greedy"), count=7, seed=1)
    assert classic["runs"]["x0"].shape == (7, 2) and "mean_return" in classic["summary"]
    with pytest.raises(fuzzyq.InputError, match="starts"):
        fuzzyq.evaluate(motor.policy("greedy"), [1.0, 2.0])


def test_a_state_beyond_single_precision_is_named_so(tmp_path: Path) -> None:
    # Regression (issue 49): 1e300 on a float32 solution was "not a finite number".
    model = fuzzyq.PointMass(agents=1)
    single = fuzzyq.solve(model, model.paper_grid(), max_sweeps=3)
    for kind in ("greedy", "interpolated"):
        with pytest.raises(fuzzyq.InputError, match="beyond the solution's precision"):
            single.policy(kind).act([1e300, 0.0, 0.0, 0.0])
    double = fuzzyq.solve(model, model.paper_grid(), max_sweeps=3, precision="float64")
    assert np.isfinite(double.policy("greedy").act([1e300, 0.0, 0.0, 0.0])).all()
    # Regression: saving into a missing directory named the temporary file.
    with pytest.raises(fuzzyq.PolicyFileError, match="does not exist") as e:
        single.save(str(tmp_path / "no" / "such" / "x.fzq"))
    assert ".fuzzyq-" not in str(e.value)
