"""The wheel installs and works without a Rust toolchain (issue 49): `scripts/build-wheels.sh`'s
wheel, installed into a fresh virtual environment with no `cargo` on `PATH`, gives
`import fuzzyq`, the `fuzzyq` command (a small `fuzzyq train`) and `python -m fuzzyq`.

The wheel is the one `scripts/test.sh` built, named by `FUZZYQ_WHEEL`; without it the test is
skipped with that reason. Installing fetches numpy and tqdm from the package index (or pip's
cache)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

WHEEL = os.environ.get("FUZZYQ_WHEEL")


@pytest.fixture(scope="module")
def venv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if not WHEEL or not Path(WHEEL).is_file():
        pytest.skip("FUZZYQ_WHEEL names no wheel (scripts/test.sh sets it to the built wheel)")
    root = tmp_path_factory.mktemp("wheel") / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(root)], check=True)
    start = time.monotonic()
    subprocess.run(
        [str(root / "bin" / "pip"), "install", "--quiet", WHEEL], check=True, env=no_cargo()
    )
    print(f"wheel installed in {time.monotonic() - start:.1f} s")
    return root


def no_cargo() -> dict[str, str]:
    """The environment with every `PATH` entry holding a `cargo` executable removed."""
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join(
        p for p in env.get("PATH", "").split(os.pathsep) if p and not (Path(p) / "cargo").exists()
    )
    env.pop("CARGO_HOME", None)
    env.pop("RUSTUP_HOME", None)
    return env


def run(venv: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = no_cargo()
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env['PATH']}"
    assert shutil.which("cargo", path=env["PATH"]) is None
    return subprocess.run(args, capture_output=True, text=True, env=env, cwd=cwd, timeout=600)


def test_the_wheel_gives_the_package_the_command_and_python_m(venv: Path, tmp_path: Path) -> None:
    python = str(venv / "bin" / "python")
    done = run(venv, python, "-c", "import fuzzyq; print(fuzzyq.__version__)", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    for command in (["fuzzyq", "--help"], [python, "-m", "fuzzyq", "--help"]):
        done = run(venv, *command, cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        assert "train" in done.stdout and "rollout" in done.stdout
    done = run(
        venv,
        "fuzzyq", "train", "--env", "dcmotor", "--preset", "toolbox-demo", "--out", "m.fzq", "-q",
        cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "m.fzq").stat().st_size > 0
    # A bad flag: one line and exit code 2, as from the Rust binary.
    done = run(venv, "fuzzyq", "train", "--gamma", "2", "--out", "x.fzq", cwd=tmp_path)
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    done = run(venv, python, "-c", "import fuzzyq; fuzzyq.load('m.fzq')", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
