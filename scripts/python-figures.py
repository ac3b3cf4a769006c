#!/usr/bin/env python3
"""Draws the figures of docs/site/python/plots.md with `fuzzyq.plot`: docs/figures/py-*.png.

Each figure is made as the page's example makes it (the same problems, the same calls); the
learning and sample-efficiency curves from the files the command line writes, run here as
``python -m fuzzyq`` (the wheel's command line) in a temporary folder.

Usage, from the repository root, with the wheel and matplotlib installed
(``pip install "fuzzyq[plot]"``, or the test venv ``target/python-test-venv``):

    target/python-test-venv/bin/python scripts/python-figures.py [OUT_DIR]

OUT_DIR defaults to docs/figures. About 20 s on two cores (most of it the two-agent solve and
the sample-efficiency comparison).
"""

from __future__ import annotations

import csv
import subprocess
import sys
import tempfile
from pathlib import Path

import fuzzyq
import fuzzyq.plot
from matplotlib.figure import Figure

ROOT = Path(__file__).resolve().parents[1]
DPI = 72


def cli(*args: str, cwd: Path) -> str:
    """Runs the wheel's command line in `cwd`; returns what it printed."""
    run = [sys.executable, "-m", "fuzzyq", *args]
    return subprocess.run(run, check=True, cwd=cwd, capture_output=True, text=True).stdout


def one_point_mass(cwd: Path, goal_radius: str, name: str) -> Path:
    """`fuzzyq config --env pointmass` for one point mass and a reward region of
    `goal_radius` (m), as the page's `sed` writes it."""
    text = cli("config", "--env", "pointmass", cwd=cwd)
    text = text.replace("\nagents = 2 ", "\nagents = 1 ")
    text = text.replace("\ngoal_radius = 0.1 ", f"\ngoal_radius = {goal_radius} ")
    path = cwd / name
    path.write_text(text)
    return path


def maps_and_rollouts() -> dict[str, Figure]:
    motor = fuzzyq.DcMotor()
    solution = fuzzyq.solve(motor, motor.grid())
    one = fuzzyq.PointMass(agents=1)
    single = fuzzyq.solve(one, one.paper_grid())
    two = fuzzyq.PointMass(agents=2)
    pair = fuzzyq.solve(two, two.paper_grid())
    return {
        "py-dcmotor-maps": fuzzyq.plot.maps(solution),
        "py-pointmass-value": fuzzyq.plot.value_map(single, "sx1", "vx1"),
        "py-pointmass-policy": fuzzyq.plot.policy_map(
            single, "sx1", "sy1", show="index", bounds=((-1, 1), (-1, 1))
        ),
        "py-pointmass-rollout": fuzzyq.plot.rollout(pair.policy().rollout(), two),
        "py-dcmotor-rollout": fuzzyq.plot.rollout(
            solution.policy().rollout(steps=200), solution.policy()
        ),
    }


def curves(work: Path) -> dict[str, Figure]:
    wide = one_point_mass(work, "1.0", "wide.toml")
    train = ["train", "--env", "pointmass", "--config", str(wide), "--learner", "fql"]
    cli(*train, "--curve", "curve.csv", "--out", "fql.fzq", "-q", cwd=work)
    one = one_point_mass(work, "0.1", "one.toml")
    compare = ["compare", "--config", str(one), "--x0=-4,3,0,0", "--starts", "20"]
    learners = ["--learners", "fqi,learned-model,fql,vqql"]
    budgets = ["--curve", "100,1000,10000,100000"]
    cli(*compare, *learners, *budgets, "--out", "efficiency", "-q", cwd=work)
    with open(work / "efficiency" / "table1.csv", newline="") as f:
        fqi = next(row for row in csv.DictReader(f) if row["learner"] == "fqi")
    reference = ("fqi (the true model)", float(fqi["success_rate"]))
    return {
        "py-learning-curve": fuzzyq.plot.learning_curve(work / "curve.csv"),
        "py-efficiency": fuzzyq.plot.efficiency_curve(
            work / "efficiency" / "efficiency.csv", reference
        ),
    }


def main() -> None:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "figures"
    with tempfile.TemporaryDirectory() as tmp:
        figures = {**maps_and_rollouts(), **curves(Path(tmp))}
    for name, fig in figures.items():
        path = out / f"{name}.png"
        fig.savefig(path, dpi=DPI)
        print(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}: "
              f"{path.stat().st_size // 1024} KB")


if __name__ == "__main__":
    main()
