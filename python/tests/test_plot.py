"""Tests of `fuzzyq.plot`: every figure draws the data it is given (heat maps equal to the
solution's values and the policy's actions, rollout lines equal to the trajectory, the curves
equal to their CSV files and to the same data as mappings), renders, and refuses bad input with
the package's typed one-line errors."""

from __future__ import annotations

import csv
import importlib
import io
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("matplotlib", reason='pip install "fuzzyq[plot]"')
import matplotlib  # noqa: E402

matplotlib.use("Agg")
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import StepPatch  # noqa: E402

import fuzzyq  # noqa: E402
import fuzzyq.plot as fp  # noqa: E402

LEARNING_HEADER = (
    "episode,steps,return,discounted_return,mean_abs_td,max_abs_td,epsilon,alpha,"
    "param_change,terminal,eval_mean_return,eval_success_rate"
)
EFFICIENCY_CSV = """learner,transitions,success_rate,mean_final_error_cm,train_seconds,failure
learned-model,1000,0.5,12.5,0.1,
fql,3000,0.25,80,0.2,
learned-model,100,0,848.5,0.01,too few transitions: block 0 action 3 never taken
fql,1000,0,848.5,0.1,
vqql,1000,0.1,500,0.3,
"""


# --- fixtures and helpers --------------------------------------------------------------------


@pytest.fixture(scope="module")
def dcmotor() -> fuzzyq.Solution:
    model = fuzzyq.DcMotor()
    return fuzzyq.solve(model, model.grid())


@pytest.fixture(scope="module")
def one_mass() -> tuple[fuzzyq.PointMass, fuzzyq.Solution]:
    model = fuzzyq.PointMass(agents=1)
    grid = fuzzyq.Grid([[-6, -1, 0, 1, 6], [-6, -1, 0, 1, 6], [-3, 0, 3], [-3, 0, 3]])
    return model, fuzzyq.solve(model, grid)


@pytest.fixture(scope="module")
def two_masses() -> tuple[fuzzyq.PointMass, fuzzyq.Solution]:
    model = fuzzyq.PointMass(agents=2)
    grid = fuzzyq.Grid([[-6, -1, 0, 1, 6], [-6, -1, 0, 1, 6], [-3, 0, 3], [-3, 0, 3]] * 2)
    return model, fuzzyq.solve(model, grid)


@pytest.fixture(scope="module")
def fql_curve(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A learning curve written by `fuzzyq train --learner fql --curve` (the wheel's command
    line): evaluations every 100 episodes, no parameter change before a full window."""
    path = tmp_path_factory.mktemp("curve") / "curve.csv"
    args = ["train", "--env", "pointmass", "--learner", "fql", "--episodes", "250"]
    out = path.with_suffix(".fzq")
    cmd = [sys.executable, "-m", "fuzzyq", *args, "--curve", str(path), "--out", str(out), "-q"]
    subprocess.run(cmd, check=True, capture_output=True)
    return path


def image(ax: Axes) -> np.ndarray:
    """The heat map drawn on `ax`."""
    return np.asarray(ax.images[0].get_array())


def lattice(lo: tuple[float, float], hi: tuple[float, float], n: int) -> tuple[Any, Any]:
    return np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n)


def line_data(ax: Axes) -> list[tuple[list[float], list[float]]]:
    return [(floats(ln.get_xdata()), floats(ln.get_ydata())) for ln in ax.lines]


def floats(values: Any) -> list[float]:
    return [float(v) for v in np.asarray(values)]


def stairs(ax: Axes) -> list[StepPatch]:
    return [p for p in ax.patches if isinstance(p, StepPatch)]


def renders(fig: Figure) -> None:
    """Draws `fig` (mathtext and layout errors show only when drawing)."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=30)
    assert buffer.getvalue().startswith(b"\x89PNG")


# --- value and policy maps -------------------------------------------------------------------


def test_value_map_equals_the_solution_value(dcmotor: fuzzyq.Solution) -> None:
    fig = fp.value_map(dcmotor, resolution=7)
    cores = dcmotor.grid.cores
    xs, ys = lattice((cores[0][0], cores[1][0]), (cores[0][-1], cores[1][-1]), 7)
    expected = [[dcmotor.value([x, y]) for x in xs] for y in ys]
    assert len(fig.axes) == 2  # the map and its colour bar
    ax = fig.axes[0]
    np.testing.assert_allclose(image(ax), expected, rtol=1e-12)
    dx, dy = (xs[1] - xs[0]) / 2, (ys[1] - ys[0]) / 2
    np.testing.assert_allclose(
        ax.images[0].get_extent(), [xs[0] - dx, xs[-1] + dx, ys[0] - dy, ys[-1] + dy]
    )
    assert ax.get_xlabel() == "angle (rad)"
    assert ax.get_ylabel() == "angular velocity (rad/s)"
    assert fig.get_suptitle() == "dcmotor: value function"
    renders(fig)


def test_maps_by_name_hold_the_others_at_the_given_state(
    one_mass: tuple[fuzzyq.PointMass, fuzzyq.Solution],
) -> None:
    _, solution = one_mass
    at = [0.0, 0.7, 0.0, -0.4]
    fig = fp.maps(solution, "vx1", "sx1", at=at, resolution=5, show="index")
    assert len(fig.axes) == 4  # two maps, two colour bars
    vs, ss = lattice((-3.0, -6.0), (3.0, 6.0), 5)
    states = [[[s, 0.7, v, -0.4] for v in vs] for s in ss]
    policy = solution.policy("greedy")
    values = [[solution.value(x) for x in row] for row in states]
    actions = [[policy.act_index(x) for x in row] for row in states]
    np.testing.assert_allclose(image(fig.axes[0]), values, rtol=1e-12)
    np.testing.assert_array_equal(image(fig.axes[1]), actions)
    assert fig.axes[0].get_xlabel() == "$v_x$ (m/s)"
    assert "others at sy1 = 0.7, vy1 = -0.4" in fig.get_suptitle()
    ticks = fig.axes[3].get_yticks()
    np.testing.assert_array_equal(ticks, np.arange(25))  # one per joint action
    renders(fig)


def test_the_default_state_is_zero_inside_the_grid_and_the_middle_outside() -> None:
    model = fuzzyq.PointMass(agents=1)
    solution = fuzzyq.solve(model, fuzzyq.Grid([[-6, 0, 6], [-6, 0, 6], [1, 2, 3], [-3, 0, 3]]))
    fig = fp.value_map(solution, 0, 1, resolution=3)
    xs = np.linspace(-6, 6, 3)
    expected = [[solution.value([x, y, 2.0, 0.0]) for x in xs] for y in xs]
    np.testing.assert_allclose(image(fig.axes[0]), expected, rtol=1e-12)
    assert "vx1 = 2" in fig.get_suptitle()


def test_policy_map_of_actions_and_of_the_interpolated_policy(dcmotor: fuzzyq.Solution) -> None:
    bounds = ((-1.0, 1.0), (-10.0, 10.0))
    xs, ys = lattice((-1.0, -10.0), (1.0, 10.0), 6)
    for kind in ("greedy", "interpolated"):
        fig = fp.policy_map(dcmotor, kind=kind, bounds=bounds, resolution=6)
        policy = dcmotor.policy(kind)
        expected = [[policy.act([x, y])[0] for x in xs] for y in ys]
        np.testing.assert_allclose(image(fig.axes[0]), expected, rtol=1e-12)
        assert fig.axes[0].get_title() == f"{kind} action"
        assert fig.axes[1].get_ylabel() == "voltage (V)"


def test_a_policy_is_drawn_over_the_given_bounds(
    two_masses: tuple[fuzzyq.PointMass, fuzzyq.Solution],
) -> None:
    _, solution = two_masses
    policy = solution.policy()
    at = [0.0, 0.0, 0.0, 0.0, 1.0, -1.0, 0.0, 0.0]
    fig = fp.policy_map(policy, "sx1", "sy1", at=at, bounds=((-2, 2), (-1, 1)), component=2,
                        resolution=4)
    xs, ys = lattice((-2.0, -1.0), (2.0, 1.0), 4)
    expected = [[policy.act([x, y, 0, 0, 1, -1, 0, 0])[2] for x in xs] for y in ys]
    np.testing.assert_allclose(image(fig.axes[0]), expected, rtol=1e-12)
    assert fig.axes[1].get_ylabel() == "$u_x$ (N), agent 2"
    renders(fig)


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"source": "solution"}, fuzzyq.InputTypeError, r"^source: expected a Solution"),
        ({"x": 2}, fuzzyq.InputError, r"^x: index 2 out of range for 2 state variables$"),
        ({"y": -1}, fuzzyq.InputError, r"^y: index -1 out of range"),
        ({"x": 1.0}, fuzzyq.InputTypeError, r"^x: expected an index or a name, got float$"),
        ({"y": "speed"}, fuzzyq.InputError, r"^y: no state variable 'speed'"),
        ({"x": 1, "y": "x2"}, fuzzyq.InputError, r"^y: the same state variable as x \(x2\)$"),
        ({"resolution": 1}, fuzzyq.ConfigError, r"^resolution: expected an integer >= 2"),
        ({"resolution": 2.5}, fuzzyq.InputTypeError, r"^resolution: expected an integer"),
        ({"at": [0.0]}, fuzzyq.InputError, r"^at: expected a full state, shape \(2,\)"),
        ({"at": [0.0, np.nan]}, fuzzyq.InputError, r"^at: non-finite values$"),
        ({"at": ["a", "b"]}, fuzzyq.InputTypeError, r"^at: expected numbers, got list$"),
        ({"bounds": ((1, 0), (0, 1))}, fuzzyq.InputError, r"^bounds: expected \(\(x_lo"),
        ({"bounds": (0, 1)}, fuzzyq.InputError, r"^bounds: expected 2 dimensions"),
        ({"show": "both"}, fuzzyq.ConfigError, r'^show: expected "index" or "action"'),
        ({"component": 1}, fuzzyq.InputError, r"^component: index 1 out of range"),
        ({"component": "u"}, fuzzyq.InputTypeError, r"^component: expected an integer"),
        (
            {"kind": "interpolated", "show": "index"},
            fuzzyq.ConfigError,
            r"^show: the interpolated policy has no action indices",
        ),
        ({"kind": "gredy"}, fuzzyq.ConfigError, r"gredy"),
    ],
)
def test_maps_refuse_bad_input(
    dcmotor: fuzzyq.Solution, kwargs: dict[str, Any], error: type[Exception], message: str
) -> None:
    source = kwargs.pop("source", dcmotor)
    with pytest.raises(error, match=message):
        fp.maps(source, resolution=kwargs.pop("resolution", 3), **kwargs)


def test_a_policy_map_needs_bounds(dcmotor: fuzzyq.Solution) -> None:
    with pytest.raises(fuzzyq.ConfigError, match=r"^bounds: a Policy has no grid"):
        fp.value_map(dcmotor.policy(), resolution=3)


# --- rollouts --------------------------------------------------------------------------------


def test_point_mass_rollout_draws_states_forces_and_paths(
    two_masses: tuple[fuzzyq.PointMass, fuzzyq.Solution],
) -> None:
    model, solution = two_masses
    run = solution.policy().rollout(steps=20)
    fig = fp.rollout(run, model)
    assert len(fig.axes) == 5  # states and forces of 2 agents, the paths
    t = run["times"]
    for i in range(2):
        states, forces = fig.axes[2 * i], fig.axes[2 * i + 1]
        assert states.get_title() == f"Agent {i + 1}: states"
        assert line_data(states) == [
            (list(t), list(run["states"][:, 4 * i + j])) for j in range(4)
        ]
        assert forces.get_title() == f"Agent {i + 1}: forces"
        for j, patch in enumerate(stairs(forces)):
            np.testing.assert_array_equal(patch.get_data()[0], run["actions"][:, 2 * i + j])
            np.testing.assert_array_equal(patch.get_data()[1], t)
        assert len(stairs(forces)) == 2
    paths = fig.axes[4]
    assert paths.get_title() == "Paths in the plane"
    drawn = line_data(paths)
    assert drawn[0] == ([0.0], [0.0])  # the goal
    for i in range(2):
        sx, sy = list(run["states"][:, 4 * i]), list(run["states"][:, 4 * i + 1])
        assert drawn[1 + 2 * i] == (sx, sy)
        assert drawn[2 + 2 * i] == (sx[:1], sy[:1])  # the start
    assert fig.get_suptitle() == "pointmass rollout (greedy policy, T = 0.4 s)"
    renders(fig)


def test_classic_rollout_draws_one_panel_per_variable(dcmotor: fuzzyq.Solution) -> None:
    policy = dcmotor.policy("interpolated")
    run = policy.rollout(steps=30)
    fig = fp.rollout(run, policy)
    assert len(fig.axes) == 4  # angle, velocity, voltage, reward
    t = list(run["times"])
    assert [ax.get_title() for ax in fig.axes] == [
        "angle (rad)", "angular velocity (rad/s)", "voltage (V)", "reward"
    ]
    for j in range(2):
        assert line_data(fig.axes[j]) == [(t, list(run["states"][:, j]))]
    (voltage,), (reward,) = stairs(fig.axes[2]), stairs(fig.axes[3])
    np.testing.assert_array_equal(voltage.get_data()[0], run["actions"][:, 0])
    np.testing.assert_array_equal(reward.get_data()[0], run["rewards"])
    assert fig.get_suptitle() == "dcmotor rollout (interpolated policy, T = 0.005 s)"
    renders(fig)


def test_a_rollout_without_times_counts_steps_and_draws_the_asked_paths() -> None:
    states = np.arange(18.0).reshape(6, 3)
    run = {"states": states, "actions": np.ones((5, 1)), "rewards": np.zeros(5)}
    fig = fp.rollout(run, paths=[(2, 0)], state_labels=["a", "b", "c"], action_labels=["u"])
    assert len(fig.axes) == 6  # 3 states, 1 action, the reward, the paths
    assert fig.axes[0].get_xlabel() == "step"
    assert line_data(fig.axes[0]) == [(list(range(6)), list(states[:, 0]))]
    paths = fig.axes[5]
    assert line_data(paths)[1] == (list(states[:, 2]), list(states[:, 0]))
    assert (paths.get_xlabel(), paths.get_ylabel()) == ("c", "a")
    assert fig.get_suptitle() == "rollout"
    renders(fig)


def test_khepera_rollout_has_the_headings() -> None:
    robots = fuzzyq.Khepera(agents=1)
    policy = fuzzyq.solve(robots, robots.grid()).policy()
    run = policy.rollout([-1.0, 1.0, 0.0, 0.0], steps=15)
    fig = fp.rollout(run, title="one robot")
    assert len(fig.axes) == 3
    assert fig.get_suptitle() == "one robot"
    heading = line_data(fig.axes[0])[4]
    assert heading == (list(run["times"]), list(run["poses"][:, 0, 2]))
    assert fig.axes[1].get_title() == "Agent 1: wheel speeds"
    renders(fig)


@pytest.mark.parametrize(
    ("change", "error", "message"),
    [
        ({"trajectory": [1, 2]}, fuzzyq.InputTypeError, r"^trajectory: expected the dict"),
        ({"drop": "states"}, fuzzyq.InputError, r"^trajectory: no 'states'"),
        ({"actions": np.zeros((3, 1))}, fuzzyq.InputError, r"^trajectory\['actions'\]: expected 5"),
        ({"times": np.zeros(5)}, fuzzyq.InputError, r"^trajectory\['times'\]: expected shape"),
        ({"states": np.zeros((1, 2))}, fuzzyq.InputError, r"a rollout of no steps"),
        ({"states": np.full((6, 2), np.inf)}, fuzzyq.InputError, r"non-finite values$"),
        ({"env": "mars"}, fuzzyq.ConfigError, r"^env: expected one of pointmass"),
        ({"env": 3}, fuzzyq.InputTypeError, r"^env: expected a name, a model or a policy"),
        ({"env": "pointmass"}, fuzzyq.InputError, r"^trajectory: pointmass needs 4 states"),
        (
            {"states": np.zeros((6, 4)), "actions": np.zeros((5, 2)), "poses": np.zeros((6, 2, 3))},
            fuzzyq.InputError,
            r"^trajectory\['poses'\]: 2 robots, the states 1$",
        ),
        ({"poses": np.zeros((6, 3))}, fuzzyq.InputError, r"^trajectory\['poses'\]: expected sh"),
        ({"paths": [(0, 2)]}, fuzzyq.InputError, r"^paths: index 2 out of range for 2"),
        ({"paths": [0, 1]}, fuzzyq.InputTypeError, r"^paths: expected pairs"),
        ({"paths": []}, fuzzyq.InputError, r"^paths: no pairs"),
        ({"state_labels": ["a"]}, fuzzyq.InputError, r"^state_labels: expected 2 labels, got 1"),
        ({"action_labels": "u"}, fuzzyq.InputTypeError, r"^action_labels: expected a sequence"),
    ],
)
def test_rollout_refuses_bad_input(
    change: dict[str, Any], error: type[Exception], message: str
) -> None:
    run: dict[str, Any] = {"states": np.zeros((6, 2)), "actions": np.zeros((5, 1))}
    for key in ("states", "actions", "times", "poses"):
        if key in change:
            run[key] = change.pop(key)
    run.pop(change.pop("drop", ""), None)
    trajectory = change.pop("trajectory", run)
    with pytest.raises(error, match=message):
        fp.rollout(trajectory, **change)


# --- learning curve --------------------------------------------------------------------------


def read_mapping(path: Path) -> dict[str, list[float | None]]:
    """The CSV's columns as a mapping, with None for the empty fields."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return {c: [field(c, r[c]) for r in rows] for c in LEARNING_HEADER.split(",")}


def field(column: str, text: str) -> float | None:
    if text == "":
        return None
    return float(text == "true") if column == "terminal" else float(text)


def trailing_mean(values: list[float], window: int) -> list[float]:
    return [float(np.mean(values[max(0, k + 1 - window): k + 1])) for k in range(len(values))]


def test_learning_curve_from_the_cli_csv(fql_curve: Path) -> None:
    data = read_mapping(fql_curve)
    fig = fp.learning_curve(fql_curve)
    assert len(fig.axes) == 6
    episodes = [float(e) for e in data["episode"] if e is not None]
    returns = [float(r) for r in data["return"] if r is not None]
    per_episode, average, evals = line_data(fig.axes[0])
    assert per_episode == (episodes, returns)
    assert average[0] == episodes
    np.testing.assert_allclose(average[1], trailing_mean(returns, 20), rtol=1e-12)
    shown = [(e, v) for e, v in zip(data["episode"], data["eval_mean_return"]) if v is not None]
    assert evals == ([e for e, _ in shown], [v for _, v in shown])
    assert 0 < len(shown) < len(episodes)  # every 100 episodes
    change = line_data(fig.axes[5])[0]
    assert len(change[0]) == sum(v is not None for v in data["param_change"]) < len(episodes)
    titles = [ax.get_title() for ax in fig.axes]
    assert titles[:5] == [
        "Return per episode", "Mean |TD error| per episode", "Steps per episode",
        "Exploration and step size", "Greedy evaluation: success rate",
    ]
    renders(fig)


def test_learning_curve_from_a_mapping_draws_the_same(fql_curve: Path) -> None:
    from_file = fp.learning_curve(str(fql_curve), window=5)
    from_mapping = fp.learning_curve(read_mapping(fql_curve), window=5)
    for a, b in zip(from_file.axes, from_mapping.axes, strict=True):
        assert line_data(a) == line_data(b)
    arrays = {k: np.array([np.nan if v is None else v for v in vs])
              for k, vs in read_mapping(fql_curve).items()}
    from_arrays = fp.learning_curve(arrays, window=5)
    for a, b in zip(from_file.axes, from_arrays.axes, strict=True):
        assert line_data(a) == line_data(b)


def small_curve(n: int = 4, **columns: Any) -> dict[str, list[Any]]:
    base: dict[str, list[Any]] = {c: [0.0] * n for c in LEARNING_HEADER.split(",")}
    base["episode"] = list(range(n))
    return {**base, **columns}


def test_the_moving_average_is_trailing() -> None:
    ramp = [float(k) for k in range(30)]
    fig = fp.learning_curve(small_curve(30, mean_abs_td=ramp))
    _, (episodes, average) = line_data(fig.axes[1])
    assert episodes == ramp
    assert average[:2] == [0.0, 0.5]
    assert average[29] == pytest.approx(19.5)  # the mean of 10..=29
    np.testing.assert_allclose(average, trailing_mean(ramp, 20), rtol=1e-12)


def test_parameter_change_on_a_log_scale_with_zeros_on_a_floor() -> None:
    fig = fp.learning_curve(small_curve(param_change=[None, 0.3, 0.0, 0.03]))
    ax = fig.axes[5]
    assert ax.get_yscale() == "log"
    line, zeros = line_data(ax)
    assert line[0] == [1.0, 2.0, 3.0]
    np.testing.assert_allclose(line[1], [0.3, 0.01, 0.03], rtol=1e-12)  # 0 at 0.03 / 3
    assert zeros[0] == [2.0]
    np.testing.assert_allclose(zeros[1], [0.01], rtol=1e-12)
    flat = fp.learning_curve(small_curve(param_change=[0.0] * 4, eval_success_rate=[None] * 4))
    assert flat.axes[5].get_yscale() == "linear"
    assert [t.get_text() for t in flat.axes[4].texts] == ["no evaluation ran"]
    renders(flat)


@pytest.mark.parametrize(
    ("curve", "kwargs", "error", "message"),
    [
        (5, {}, fuzzyq.InputTypeError, r"^curve: expected a CSV file's path"),
        ({"episode": [1]}, {}, fuzzyq.InputError, r"^curve: no column 'steps'$"),
        (small_curve(alpha=[0.1]), {}, fuzzyq.InputError, r"^curve: column 'alpha' has 1 rows"),
        (small_curve(steps=[1, 2, "x", 4]), {}, fuzzyq.InputError, r"row 2: 'x' is not a number"),
        (small_curve(steps=[1, 2, [3], 4]), {}, fuzzyq.InputTypeError, r"row 2: expected a num"),
        (small_curve(steps=3), {}, fuzzyq.InputTypeError, r"^curve\['steps'\]: expected a seq"),
        ({c: [] for c in LEARNING_HEADER.split(",")}, {}, fuzzyq.InputError, r"^curve: no rows"),
        (small_curve(), {"window": 0}, fuzzyq.ConfigError, r"^window: expected an integer >= 1"),
    ],
)
def test_learning_curve_refuses_bad_input(
    curve: Any, kwargs: dict[str, Any], error: type[Exception], message: str
) -> None:
    with pytest.raises(error, match=message):
        fp.learning_curve(curve, **kwargs)


def test_learning_curve_files_need_the_columns(tmp_path: Path) -> None:
    path = tmp_path / "curve.csv"
    path.write_text("episode,steps,return\n0,1,2\n")
    with pytest.raises(fuzzyq.InputError, match=r"curve.csv has no column 'mean_abs_td'$"):
        fp.learning_curve(path)
    with pytest.raises(FileNotFoundError):
        fp.learning_curve(tmp_path / "missing.csv")


# --- sample-efficiency curve -----------------------------------------------------------------


def test_efficiency_curve_draws_one_line_per_learner(tmp_path: Path) -> None:
    path = tmp_path / "efficiency.csv"
    path.write_text(EFFICIENCY_CSV)
    fig = fp.efficiency_curve(path, ("fqi (the true model)", 0.45))
    assert len(fig.axes) == 1
    ax = fig.axes[0]
    assert ax.get_xscale() == "log"
    reference, *lines = ax.lines
    assert floats(reference.get_ydata()) == [0.45, 0.45]
    assert reference.get_linestyle() == "--"
    # The command line's order of learners, transitions increasing, each thinner.
    assert [ln.get_label() for ln in lines] == ["fql", "vqql", "learned-model"]
    assert line_data(ax)[1:] == [
        ([1000.0, 3000.0], [0.0, 0.25]), ([1000.0], [0.1]), ([100.0, 1000.0], [0.0, 0.5])
    ]
    assert [ln.get_linewidth() for ln in lines] == [7, 5, 3]
    legend = ax.get_legend()
    assert legend is not None
    assert legend.get_texts()[0].get_text() == "fqi (the true model)"
    renders(fig)


def test_efficiency_curve_from_columns_and_rows_draws_the_same(tmp_path: Path) -> None:
    path = tmp_path / "efficiency.csv"
    path.write_text(EFFICIENCY_CSV)
    rows = list(csv.DictReader(io.StringIO(EFFICIENCY_CSV)))
    records = [{"learner": r["learner"], "transitions": int(r["transitions"]),
                "success_rate": float(r["success_rate"])} for r in rows]
    columns = {k: [r[k] for r in records] for k in ("learner", "transitions", "success_rate")}
    expected = line_data(fp.efficiency_curve(path, 0.5).axes[0])
    assert line_data(fp.efficiency_curve(records, 0.5).axes[0]) == expected
    assert line_data(fp.efficiency_curve(columns, 0.5).axes[0]) == expected
    legend = fp.efficiency_curve(columns, 0.5).axes[0].get_legend()
    assert legend is not None
    assert legend.get_texts()[0].get_text() == "reference"


@pytest.mark.parametrize(
    ("points", "reference", "error", "message"),
    [
        ("no-such-dir/efficiency.csv", None, FileNotFoundError, r"efficiency.csv"),
        (3, None, fuzzyq.InputTypeError, r"^points: expected a CSV file's path"),
        ({"learner": ["fql"], "transitions": [10]}, None, fuzzyq.InputError,
         r"^points: no column 'success_rate'$"),
        ({"learner": ["fql"], "transitions": [0], "success_rate": [0.5]}, None,
         fuzzyq.InputError, r"^points\['transitions'\]: expected positive numbers"),
        ({"learner": [1], "transitions": [10], "success_rate": [0.5]}, None,
         fuzzyq.InputTypeError, r"^points\['learner'\]: expected a sequence of learner names"),
        ({"learner": ["fql", "vqql"], "transitions": [10], "success_rate": [0.5]}, None,
         fuzzyq.InputError, r"^points: column 'learner' has 2 rows, 'transitions' 1$"),
        ([{"learner": "fql", "transitions": 10, "success_rate": 0.5}], "high",
         fuzzyq.InputTypeError, r"^reference: expected a success rate or \(name, rate\)"),
        ([{"learner": "fql", "transitions": 10, "success_rate": 0.5}], float("nan"),
         fuzzyq.ConfigError, r"^reference: expected a finite success rate"),
    ],
)
def test_efficiency_curve_refuses_bad_input(
    points: Any, reference: Any, error: type[Exception], message: str
) -> None:
    with pytest.raises(error, match=message):
        fp.efficiency_curve(points, reference)


# --- the module ------------------------------------------------------------------------------


def test_the_pages_examples_run(
    fql_curve: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """docs/site/python/plots.md's Python blocks, given the files its commands write."""
    page = Path(__file__).resolve().parents[2] / "docs" / "site" / "python" / "plots.md"
    blocks = re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)
    assert len(blocks) == 6
    (tmp_path / "curve.csv").write_bytes(fql_curve.read_bytes())
    (tmp_path / "efficiency").mkdir()
    (tmp_path / "efficiency" / "efficiency.csv").write_text(EFFICIENCY_CSV)
    (tmp_path / "efficiency" / "table1.csv").write_text("learner,success_rate\nfqi,0.75\n")
    monkeypatch.chdir(tmp_path)
    for i, block in enumerate(blocks):
        exec(compile(block, f"plots.md python block {i}", "exec"), {})
    saved = sorted(p.name for p in tmp_path.glob("*.png"))
    assert saved == [
        "dcmotor-maps.png", "dcmotor-rollout.png", "efficiency.png", "learning-curve.png",
        "pointmass-policy.png", "pointmass-rollout.png", "pointmass-value.png",
    ]


def test_without_matplotlib_the_import_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    monkeypatch.delitem(sys.modules, "fuzzyq.plot")
    with pytest.raises(ImportError, match=r'pip install "fuzzyq\[plot\]"'):
        importlib.import_module("fuzzyq.plot")


def test_every_public_function_documents_its_arguments() -> None:
    import inspect

    for name in fp.__all__:
        obj = getattr(fp, name)
        if not callable(obj):
            continue
        doc = inspect.getdoc(obj) or ""
        for section in ("Args:", "Returns:", "Raises:"):
            assert section in doc, f"{name}: no {section}"
        for parameter in inspect.signature(obj).parameters:
            assert f"\n    {parameter}:" in doc, f"{name}: {parameter} is not documented"
