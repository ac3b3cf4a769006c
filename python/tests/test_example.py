"""The example script trains and plots."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "train_paper.py"


def test_example_trains_and_plots(tmp_path: Path) -> None:
    out = tmp_path / "paths.png"
    run = subprocess.run(
        [sys.executable, EXAMPLE, "--agents", "1", "--out", out],
        capture_output=True,
        text=True,
        check=True,
        env={"MPLBACKEND": "Agg", "PATH": ""},
    )
    assert "sweeps" in run.stdout
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
