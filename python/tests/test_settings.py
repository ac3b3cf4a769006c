"""One answer to every setting (issue 49): `fuzzyq train` and `fuzzyq.solve` with default
settings run the same solver settings for every built-in environment and preset, so they
give the same `V` and greedy actions, byte for byte.

The command line runs as the installed package's `fuzzyq` command (`python -m fuzzyq`: the
Rust binary's code, built in release with the extension). The point masses and the robots
run on small grids (one point mass on the paper's grid, two robots on a coarse grid), so
that the test is quick; the classic benchmarks run every preset on its own grid."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import fuzzyq


def train(tmp_path: Path, *args: str, config: str | None = None) -> fuzzyq.Solution:
    out = tmp_path / "cli.fzq"
    command = [sys.executable, "-m", "fuzzyq", "train", *args, "--out", str(out), "-q"]
    if config is not None:
        (tmp_path / "task.toml").write_text(config)
        command += ["--config", str(tmp_path / "task.toml")]
    done = subprocess.run(command, capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    return fuzzyq.load(str(out))


def default_config(env: str, agents: int) -> str:
    """`fuzzyq config --env ENV` with `agents` agents (nothing else changed)."""
    text = subprocess.run(
        [sys.executable, "-m", "fuzzyq", "config", "--env", env],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    text, n = re.subn(r"(?m)^agents = \d+", f"agents = {agents}", text)
    assert n == 1, "the configuration names its number of agents once"
    return text


def assert_same(cli: fuzzyq.Solution, py: fuzzyq.Solution) -> None:
    assert cli.sweeps == py.sweeps
    assert np.asarray(cli.V).dtype == np.asarray(py.V).dtype
    assert np.asarray(cli.V).tobytes() == np.asarray(py.V).tobytes()
    assert np.array_equal(cli.greedy, py.greedy)


def test_point_masses(tmp_path: Path) -> None:
    model = fuzzyq.PointMass(agents=1)
    cli = train(tmp_path, "--env", "pointmass", config=default_config("pointmass", 1))
    assert_same(cli, fuzzyq.solve(model, model.paper_grid()))


def test_khepera_robots(tmp_path: Path) -> None:
    # Their default includes a coarse start, which Python's default once left out. Two robots
    # (one robot's model runs value iteration, where a coarse start does not apply) on a
    # coarser grid than the paper's, the same for both: the command line's own.
    config = default_config("khepera", 2)
    config, n = re.subn(
        r"(?m)^position_cores = \[.*\]", "position_cores = [-6.0, -1.5, 0.0, 1.5, 6.0]", config
    )
    config, m = re.subn(r"(?m)^heading_divisions = \d+", "heading_divisions = 6", config)
    assert n == m == 1
    cli = train(tmp_path, "--env", "khepera", config=config)
    seen: list[dict[str, object]] = []
    py = fuzzyq.solve(fuzzyq.Khepera(agents=2), cli.grid, callback=seen.append)
    assert seen[-1]["coarse_start"] is not None
    assert_same(cli, py)


CLASSIC = {
    "dcmotor": (fuzzyq.DcMotor, ["toolbox-demo", "fine"]),
    "pendulum": (fuzzyq.Pendulum, ["toolbox-demo", "fine"]),
    "carhill": (fuzzyq.CarHill, ["fine", "coarse"]),
    "arm": (fuzzyq.Arm, ["fine", "coarse"]),
}


@pytest.mark.parametrize(
    ("env", "preset"), [(env, p) for env, (_, presets) in CLASSIC.items() for p in presets]
)
def test_classic_benchmarks(env: str, preset: str, tmp_path: Path) -> None:
    cls, _ = CLASSIC[env]
    model = cls(preset=preset)
    cli = train(tmp_path, "--env", env, "--preset", preset)
    assert_same(cli, fuzzyq.solve(model, model.grid()))
