"""Every policy the command line writes acts in Python exactly as `fuzzyq rollout` runs it.

For each environment and learner, a small policy is trained with the `fuzzyq` binary and
rolled out with `--csv` and `--json`; `fuzzyq.load` reads the file, and the Python policy must
choose the CLI's actions step by step (exact equality): on the model states of the CSV, and
through `Policy.rollout` (the same rollout code) from the same start, whose states, actions,
rewards and metrics must equal the CLI's. The robots' CSV holds the paper's 8-D state, not what
their policies act on, so for them the actions are checked on the rollout's own poses
(fuzzy Q-iteration) or observations (fuzzy Q-learning).
"""

from __future__ import annotations

import csv
import json
import os
import pickle
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import fuzzyq

REPO = Path(__file__).resolve().parents[2]


def fuzzyq_cli() -> Path | None:
    """`$FUZZYQ_BIN` (`scripts/test.sh` sets it to the binary it just built; missing is an
    error), else the most recently built of `target/{release,debug}/fuzzyq`."""
    given = os.environ.get("FUZZYQ_BIN")
    if given:
        if not Path(given).is_file():
            raise FileNotFoundError(f"FUZZYQ_BIN={given} does not exist")
        return Path(given)
    built = [REPO / "target" / p / "fuzzyq" for p in ("release", "debug")]
    built = [exe for exe in built if exe.exists()]
    return max(built, key=lambda exe: exe.stat().st_mtime, default=None)


CLI = fuzzyq_cli()
pytestmark = pytest.mark.skipif(
    CLI is None, reason="the fuzzyq binary is not built (cargo build -p fuzzyq-cli)"
)


def cli(*args: object) -> str:
    assert CLI is not None
    run = subprocess.run([CLI, *map(str, args)], check=True, capture_output=True, text=True)
    return run.stdout


@dataclass
class CliRun:
    """A `fuzzyq rollout` run as its CSV and JSON report it."""

    states: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    times: np.ndarray
    metrics: dict[str, Any]


def cli_rollout(policy_file: Path, action_dim: int, *args: object) -> CliRun:
    out = policy_file.with_suffix("")
    tag = "-".join(str(a).strip("-") for a in args).replace(",", "_") or "default"
    csv_path, json_path = Path(f"{out}-{tag}.csv"), Path(f"{out}-{tag}.json")
    cli("rollout", "--policy", policy_file, *args, "--csv", csv_path, "--json", json_path, "-q")
    with open(csv_path, newline="") as f:
        header, *rows = list(csv.reader(f))
    e = len(header) - 2 - action_dim
    # Rust writes the shortest representation that round-trips: float() reads it exactly.
    values = [[float(v) if v else np.nan for v in row] for row in rows]
    return CliRun(
        states=np.array([r[1 : 1 + e] for r in values]),
        actions=np.array([r[1 + e : 1 + e + action_dim] for r in values[:-1]]),
        rewards=np.array([r[-1] for r in values[:-1]]),
        times=np.array([r[0] for r in values]),
        metrics=json.loads(json_path.read_text()),
    )


@pytest.fixture(scope="module")
def work(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("cli-policies")
    # One point mass on the paper's grid.
    config = cli("config", "--env", "pointmass").replace("agents = 2 ", "agents = 1 ")
    (path / "pointmass.toml").write_text(config)
    # One robot on a coarse grid.
    lines = []
    for line in cli("config", "--env", "khepera").splitlines():
        if line.startswith("agents = "):
            line = "agents = 1"
        elif line.startswith("position_cores = "):
            line = "position_cores = [-6.0, -2.0, -0.5, 0.0, 0.5, 2.0, 6.0]"
        elif line.startswith("heading_divisions = "):
            line = "heading_divisions = 4"
        lines.append(line)
    (path / "khepera.toml").write_text("\n".join(lines) + "\n")
    return path


@dataclass(frozen=True)
class Case:
    name: str
    env: str
    train: tuple[str, ...]
    learner: str = "fqi"
    x0: tuple[float, ...] | None = None
    headings: tuple[float, ...] | None = None
    steps: int = 40


CASES = [
    Case("pointmass-fqi", "pointmass", ("--config", "{work}/pointmass.toml"), x0=(-4, -6, -2, 2)),
    Case(
        "pointmass-fql",
        "pointmass",
        ("--config", "{work}/pointmass.toml", "--learner", "fql", "--episodes", "5"),
        learner="fql",
        x0=(-4, -6, -2, 2),
    ),
    Case(
        "pointmass-vqql",
        "pointmass",
        ("--config", "{work}/pointmass.toml", "--learner", "vqql", "--episodes", "5", "--cells", "16"),
        learner="vqql",
        x0=(-4, -6, -2, 2),
    ),
    Case(
        "khepera-fqi",
        "khepera",
        ("--env", "khepera", "--config", "{work}/khepera.toml"),
        x0=(-4, 5, 0, 0),
        headings=(90,),
    ),
    Case(
        "khepera-fql",
        "khepera",
        ("--env", "khepera", "--config", "{work}/khepera.toml", "--learner", "fql", "--episodes", "5"),
        learner="fql",
        x0=(-4, 5, 0, 0),
        headings=(90,),
    ),
    # The classic benchmarks from their default start (the same in Python and on the CLI).
    Case("dcmotor", "dcmotor", ("--env", "dcmotor", "--preset", "toolbox-demo"), steps=60),
    Case("pendulum", "pendulum", ("--env", "pendulum", "--preset", "toolbox-demo"), steps=60),
    Case("carhill", "carhill", ("--env", "carhill", "--preset", "coarse"), steps=60),
    Case("arm", "arm", ("--env", "arm", "--preset", "coarse"), steps=60),
]


def train(work: Path, case: Case) -> Path:
    out = work / f"{case.name}.fzq"
    if not out.exists():
        cli("train", *(a.format(work=work) for a in case.train), "--out", out, "-q")
    return out


def kinds(case: Case) -> list[str]:
    return ["greedy", "interpolated"] if case.learner == "fqi" else ["greedy"]


@pytest.mark.parametrize(
    ("case", "kind"),
    [(c, k) for c in CASES for k in kinds(c)],
    ids=[f"{c.name}-{k}" for c in CASES for k in kinds(c)],
)
def test_loaded_policy_acts_as_the_cli_rollout(work: Path, case: Case, kind: str) -> None:
    path = train(work, case)
    loaded = fuzzyq.load(path)
    if case.learner == "fqi":
        assert isinstance(loaded, fuzzyq.Solution)
        assert loaded.env == case.env
        policy = loaded.policy(kind)
    else:
        # A policy learned from samples is a policy: greedy and decentralised.
        assert isinstance(loaded, fuzzyq.Policy)
        policy = loaded
    assert (policy.kind, policy.env, policy.learner) == (kind, case.env, case.learner)
    # Every policy pickles (a solution's by the solution and kind, a learned one by its
    # file's bytes): the checks below run on the unpickled copy.
    policy = pickle.loads(pickle.dumps(policy))
    assert (policy.kind, policy.env, policy.learner) == (kind, case.env, case.learner)

    args: list[object] = ["--steps", case.steps, "--policy-kind", kind]
    if case.x0 is not None:
        args += ["--x0", ",".join(map(str, case.x0))]
    if case.headings is not None:
        args += ["--headings", ",".join(map(str, case.headings))]
    ref = cli_rollout(path, policy.action_dim, *args)
    # The car on the hill ends its run at a terminal state.
    assert len(ref.actions) == case.steps or (case.env == "carhill" and ref.metrics["terminal"])

    # The same rollout code from the same start: the same run, bit for bit.
    run = policy.rollout(case.x0, case.steps, headings=case.headings)
    np.testing.assert_array_equal(run["actions"], ref.actions)
    np.testing.assert_array_equal(run["states"], ref.states)
    np.testing.assert_array_equal(run["rewards"], ref.rewards)
    np.testing.assert_array_equal(run["times"], ref.times)
    assert run["metrics"] == ref.metrics

    if case.env != "khepera":
        # The policy acts on the model state: every CSV row's action from its state.
        for x, u in zip(ref.states, ref.actions):
            np.testing.assert_array_equal(policy.act(x), u)
        np.testing.assert_array_equal(policy.act_batch(ref.states[:-1]), ref.actions)
        return

    # The robots: the policy acts on poses (fuzzy Q-iteration) or on each robot's sonars and
    # goal distance and angle (fuzzy Q-learning), which the rollout returns.
    n = 1
    assert run["poses"].shape == (case.steps + 1, n, 3)
    assert run["sonar"].shape == (case.steps + 1, n, 5)
    assert run["observations"].shape == (case.steps + 1, n, 7)
    np.testing.assert_array_equal(run["observations"][:, :, :5], run["sonar"])
    seen = run["poses"] if case.learner == "fqi" else run["observations"]
    assert policy.state_dim == seen[0].size
    for k, u in enumerate(ref.actions):
        np.testing.assert_array_equal(policy.act(seen[k].ravel()), u)
        if kind == "greedy":
            assert policy.agent_actions(seen[k].ravel()) == list(run["action_indices"][k])


def test_the_robots_start_from_poses_too(work: Path) -> None:
    path = train(work, CASES[3])
    policy = fuzzyq.load(path)
    assert isinstance(policy, fuzzyq.Solution)
    greedy = policy.policy("greedy")
    a = greedy.rollout([-4, 5, 0, 0], 10, headings=[90])
    b = greedy.rollout([-4, 5, np.pi / 2], 10)
    np.testing.assert_array_equal(a["poses"], b["poses"])
    np.testing.assert_array_equal(a["actions"], b["actions"])
    # The robots turn towards the goal: the policy does not only drive straight on.
    assert len({tuple(u) for u in a["actions"]}) > 1
    # As on the command line, the robots run on their rapier plant only.
    with pytest.raises(fuzzyq.ConfigError, match="rapier plant only"):
        greedy.rollout([-4, 5, 0, 0], 10, headings=[90], plant="model")
    # The command line reads poses as --x0 too.
    ref = cli_rollout(path, b["actions"].shape[1], "--x0", f"-4,5,{np.pi / 2}", "--steps", 10)
    np.testing.assert_array_equal(ref.actions, b["actions"])


def test_point_masses_on_the_rapier_plant(work: Path) -> None:
    path = train(work, CASES[0])
    solution = fuzzyq.load(path)
    assert isinstance(solution, fuzzyq.Solution)
    policy = solution.policy("greedy")
    ref = cli_rollout(path, 2, "--x0", "-4,-6,-2,2", "--steps", 30, "--plant", "rapier", "--radius", 0.2)
    run = policy.rollout([-4, -6, -2, 2], 30, plant="rapier", radius=0.2)
    np.testing.assert_array_equal(run["actions"], ref.actions)
    np.testing.assert_array_equal(run["states"], ref.states)
    assert run["metrics"] == ref.metrics
    assert run["metrics"]["plant"] == "rapier" and "collisions" in run["metrics"]


def test_a_learned_policy_is_greedy_on_its_q_values(work: Path) -> None:
    policy = fuzzyq.load(train(work, CASES[1]))
    assert isinstance(policy, fuzzyq.Policy)
    assert (policy.state_dim, policy.action_dim, policy.n_agents, policy.n_joint_actions) == (4, 2, 1, 25)
    rng = np.random.default_rng(0)
    for x in rng.uniform(-3, 3, size=(20, 4)):
        q = policy.q_values(x)
        assert q.shape == (25,)
        u = policy.act_index(x)
        assert u == int(np.argmax(q)) and policy.agent_actions(x) == [u]
        assert policy.value(x) == pytest.approx(float(q.max()))
        np.testing.assert_array_equal(policy.act(x), fuzzyq.PointMass(agents=1).joint_action(u))


def test_python_solves_classic_models_as_the_cli_trains_them(work: Path) -> None:
    motor = fuzzyq.DcMotor("toolbox-demo")
    assert (motor.env, motor.preset, motor.state_dim, motor.action_dim, motor.n_actions) == ("dcmotor", "toolbox-demo", 2, 1, 5)
    assert (motor.gamma, motor.xi) == (0.98, 0.01)
    cli_file = train(work, CASES[5])
    ref = fuzzyq.load(cli_file)
    assert isinstance(ref, fuzzyq.Solution)
    # The preset's settings by default (plain sweeps in float64), as `fuzzyq train --preset`.
    s = fuzzyq.solve(motor, motor.grid())
    assert s.V.dtype == np.float64 and s.gamma == 0.98 and s.xi == 0.01
    np.testing.assert_array_equal(s.V, ref.V)
    np.testing.assert_array_equal(s.greedy, ref.greedy)
    assert s.sweeps == ref.sweeps
    # Saved from Python, rolled out by the CLI.
    s.save(work / "py-dcmotor.fzq")
    policy = s.policy("greedy")
    run = cli_rollout(work / "py-dcmotor.fzq", 1, "--steps", 50)
    for x, u in zip(run.states, run.actions):
        np.testing.assert_array_equal(policy.act(x), u)
    # Busoniu's operator through the same code.
    cli("train", "--env", "dcmotor", "--preset", "toolbox-demo", "--operator", "q-values", "--out", work / "q.fzq", "-q")
    q_ref = fuzzyq.load(work / "q.fzq")
    assert isinstance(q_ref, fuzzyq.Solution)
    q = fuzzyq.solve(motor, motor.grid(), operator="q-values")
    np.testing.assert_array_equal(q.V, q_ref.V)
    assert q.kernel == "q-values"


def test_python_and_cli_policies_act_alike(tmp_path: Path) -> None:
    exe = CLI
    assert exe is not None
    model = fuzzyq.PointMass(agents=1)
    x0 = "-4,-6,-2,2"
    # Python -> CLI: the CLI's greedy rollout matches the Python policy step by step.
    s = fuzzyq.solve(model, model.paper_grid())
    s.save(tmp_path / "py.fzq")
    subprocess.run(
        [exe, "rollout", "--policy", tmp_path / "py.fzq", "--x0", x0, "--steps", "30", "--csv", tmp_path / "py.csv", "-q"],
        check=True,
    )
    rows = np.loadtxt(tmp_path / "py.csv", delimiter=",", skiprows=1, max_rows=30)
    pol = s.policy("greedy")
    for row in rows:
        np.testing.assert_array_equal(pol.act(row[1:5]), row[5:7])
    # CLI -> Python.
    config = subprocess.run([exe, "config"], check=True, capture_output=True, text=True).stdout
    (tmp_path / "one.toml").write_text(config.replace("agents = 2 ", "agents = 1 "))
    subprocess.run([exe, "train", "--config", tmp_path / "one.toml", "--out", tmp_path / "cli.fzq", "-q"], check=True)
    subprocess.run(
        [exe, "rollout", "--policy", tmp_path / "cli.fzq", "--x0", x0, "--steps", "30", "--csv", tmp_path / "cli.csv", "--json", tmp_path / "m.json", "-q"],
        check=True,
    )
    cli_solution = fuzzyq.load(tmp_path / "cli.fzq")
    assert isinstance(cli_solution, fuzzyq.Solution)
    loaded = cli_solution.policy("greedy")
    rows = np.loadtxt(tmp_path / "cli.csv", delimiter=",", skiprows=1, max_rows=30)
    for row in rows:
        np.testing.assert_array_equal(loaded.act(row[1:5]), row[5:7])
    assert json.loads((tmp_path / "m.json").read_text())["final_error_m"][0] < 0.08


def test_the_cli_refuses_a_callable_models_solution_by_name(tmp_path: Path) -> None:
    def transition(x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.clip(x + 0.1 * u, -1, 1), -(x[:, 0] ** 2)

    model = fuzzyq.CallableModel(transition, state_dim=1, actions=[[-1.0, 0.0, 1.0]])
    fuzzyq.solve(model, fuzzyq.Grid([np.linspace(-1, 1, 11)])).save(tmp_path / "custom.fzq")
    assert CLI is not None
    run = subprocess.run(
        [CLI, "rollout", "--policy", tmp_path / "custom.fzq", "-q"], capture_output=True, text=True
    )
    assert run.returncode == 2
    assert "fuzzyq.load(path, model=...)" in run.stderr and run.stderr.count("\n") == 1


def read_curve(path: Path) -> dict[str, np.ndarray]:
    """`fuzzyq train --curve`'s CSV as columns (empty fields NaN)."""
    with open(path, newline="") as f:
        header, *rows = list(csv.reader(f))
    columns: dict[str, np.ndarray] = {}
    for j, name in enumerate(header):
        cells = [r[j] for r in rows]
        if name == "terminal":
            columns[name] = np.array([c == "true" for c in cells])
        else:
            columns[name] = np.array([float(c) if c else np.nan for c in cells])
    return columns


@pytest.mark.parametrize(
    "case", [c for c in CASES if c.learner != "fqi"], ids=lambda c: str(c.name)
)
def test_learn_from_samples_is_the_cli_run(work: Path, case: Case) -> None:
    out, curve = work / f"{case.name}-seed3.fzq", work / f"{case.name}-seed3.csv"
    args = [a.format(work=work) for a in case.train]
    cli("train", *args, "--seed", 3, "--out", out, "--curve", curve, "-q")
    model: Any = fuzzyq.PointMass(agents=1) if case.env == "pointmass" else fuzzyq.Khepera(agents=1)
    cells = 16 if case.learner == "vqql" else None
    policy, report = fuzzyq.learn_from_samples(model, case.learner, episodes=5, cells=cells, seed=3)
    assert (policy.learner, policy.env, policy.kind) == (case.learner, case.env, "greedy")
    # The same policy file, byte for byte (a learned policy pickles as its file's bytes).
    assert policy.__reduce__()[1][1][0] == out.read_bytes()
    expected = read_curve(curve)
    assert list(report["curve"]) == list(expected)
    for name, column in expected.items():
        np.testing.assert_array_equal(report["curve"][name], column, err_msg=name)
    assert report["stop"] == "episode-limit" and report["steps_total"] == expected["steps"].sum()
    assert (report["lloyd"] is not None) == (case.learner == "vqql")


def test_learn_from_samples_refuses_what_the_cli_refuses() -> None:
    one = fuzzyq.PointMass(agents=1)
    with pytest.raises(fuzzyq.ConfigError, match="learner: expected"):
        fuzzyq.learn_from_samples(one, "fqi")  # type: ignore[arg-type]
    with pytest.raises(fuzzyq.ConfigError, match="learner"):
        fuzzyq.learn_from_samples(one, "sarsa")  # type: ignore[arg-type]
    with pytest.raises(fuzzyq.ConfigError, match="source: of the built-in tasks"):
        fuzzyq.learn_from_samples(fuzzyq.DcMotor())
    with pytest.raises(fuzzyq.ConfigError, match="task: applies to a system of your own"):
        fuzzyq.learn_from_samples(one, task=fuzzyq.Task(state_bounds=[[0, 1]] * 4, actions=[[0.0, 1.0]]))
    with pytest.raises(fuzzyq.ConfigError, match="vqql is available for the pointmass"):
        fuzzyq.learn_from_samples(fuzzyq.Khepera(agents=1), "vqql")
    with pytest.raises(fuzzyq.ConfigError, match="cells"):
        fuzzyq.learn_from_samples(one, "fql", cells=8)
    with pytest.raises(fuzzyq.ConfigError, match="episodes"):
        fuzzyq.learn_from_samples(one, episodes=0)
    with pytest.raises(fuzzyq.InputTypeError, match="seed"):
        fuzzyq.learn_from_samples(one, seed="1")  # type: ignore[arg-type]
