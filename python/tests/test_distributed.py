"""`fuzzyq.distributed`: sweeps on a local Ray cluster (``ray start --head`` plus a worker
node) give the single-process policy file byte for byte, also when a worker process dies
mid-sweep and when the driver is killed and resumed from its checkpoint; bad input is refused
before any cluster is touched.

Skipped, with the reason, when Ray is not installed (``pip install "ray>=2.9"``).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import fuzzyq
from fuzzyq.distributed import _tasks


def reduced_paper_task() -> str:
    """A reduced paper task: `fuzzyq config --env pointmass` with a coarser grid and
    `xi = 0.01`. Two point masses on 5 position x 3 velocity cores per axis (50,625 cores, 15
    slabs), modified policy iteration as `fuzzyq train` runs it by default (38 sweeps)."""
    text = subprocess.run(
        [sys.executable, "-m", "fuzzyq", "config", "--env", "pointmass"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    for key, value in [
        ("position_cores", "[-6.0, -3.0, 0.0, 3.0, 6.0]"),
        ("velocity_cores", "[-3.0, 0.0, 3.0]"),
        ("xi", "0.01"),
    ]:
        text, n = re.subn(rf"(?m)^{key} = .*$", f"{key} = {value}", text)
        assert n == 1, f"the configuration sets {key} once"
    return text


CONFIG = reduced_paper_task()


def setting(key: str, value: str) -> str:
    """`CONFIG` with the `[solver]` setting `key` (its last section) set to `value` (TOML)."""
    text, n = re.subn(rf"^{key} = .*$", f"{key} = {value}", CONFIG, count=1, flags=re.M)
    return text if n == 1 else f"{CONFIG}{key} = {value}\n"


def run_cli(*args: object, check: bool = True) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "fuzzyq.distributed", *map(str, args)],
        capture_output=True,
        text=True,
        check=check,
        timeout=600,
    )


# Bad input: refused with one-line errors, without Ray or a cluster.


def test_unshardable_configurations_are_refused(tmp_path: Path) -> None:
    refused = (
        ("sweep", '"async"'),
        ("operator", '"q-values"'),
        ("backup", '"generic"'),
        ("device", '"gpu"'),
    )
    for key, value in refused:
        with pytest.raises(fuzzyq.ConfigError, match=f"solver.{key}"):
            fuzzyq.SlabProblem(setting(key, value))
    with pytest.raises(fuzzyq.ConfigError):
        fuzzyq.SlabProblem("[env]\nkind = 'nowhere'\n")
    p = fuzzyq.SlabProblem(CONFIG)
    assert (p.n_slabs, p.slab_len, p.dtype) == (15, 3375, "float32")
    halo = p.input_slabs(0, 1)
    assert 0 < len(halo) < p.n_slabs
    with pytest.raises(fuzzyq.InputTypeError, match="v_halo"):
        p.backup(0, 1, halo, np.zeros(len(halo) * p.slab_len))  # float64 for float32
    with pytest.raises(fuzzyq.InputError):
        p.backup(0, 1, halo, np.zeros(3, np.float32))
    with pytest.raises(fuzzyq.ConfigError, match="halo"):
        p.backup(0, 1, halo[1:], np.zeros((len(halo) - 1) * p.slab_len, np.float32))
    with pytest.raises(fuzzyq.ConfigError):
        p.input_slabs(3, 3)


def test_a_worker_keeps_the_operators_of_its_latest_two_configurations() -> None:
    configs = [setting("xi", str(x)) for x in (0.01, 0.02, 0.03)]
    first = _tasks.problem(configs[0])
    assert _tasks.problem(configs[0]) is first  # built once
    _tasks.problem(configs[1])
    _tasks.problem(configs[2])
    assert list(_tasks._PROBLEMS) == configs[1:]
    assert _tasks.problem(configs[0]) is not first  # evicted, built again


def test_the_command_line_refuses_bad_input_with_exit_code_2(tmp_path: Path) -> None:
    config = tmp_path / "c.toml"
    config.write_text(setting("sweep", '"async"'))
    out = tmp_path / "p.fzq"
    cases = [
        (["--config", tmp_path / "missing.toml", "--out", out], "missing.toml"),
        (["--config", config, "--out", out], "solver.sweep"),
        (["--config", config, "--out", tmp_path / "no" / "p.fzq"], "--out"),
        (["--config", config, "--out", out, "--slabs-per-task", "0"], "--slabs-per-task"),
        (["--config", config, "--out", out, "--resume", tmp_path / "none"], "--resume"),
    ]
    for args, named in cases:
        r = run_cli("train", *args, check=False)
        assert r.returncode == 2, (args, r.stderr)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and named in lines[0], r.stderr
    assert not out.exists()


def test_without_ray_a_typed_error_says_how_to_install_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import fuzzyq.distributed as fd

    monkeypatch.setitem(sys.modules, "ray", None)
    with pytest.raises(fd.RayUnavailableError, match="pip install"):
        fd.train(CONFIG)


# On a local cluster.

RAY_MISSING = 'Ray is not installed: pip install "ray>=2.9" to run these tests'


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """``ray start --head`` plus a second node process; yields the address."""
    pytest.importorskip("ray", reason=RAY_MISSING)
    exe = shutil.which("ray", path=str(Path(sys.executable).parent)) or shutil.which("ray")
    if exe is None:
        pytest.skip("the `ray` command is not on PATH")
    address = f"127.0.0.1:{_free_port()}"
    # A local test cluster without Ray's token authentication (on by default for `ray start
    # --head` since Ray 2.5x; joining nodes and drivers would need the token).
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "disabled"}
    common = ["--num-cpus=1", "--disable-usage-stats"]
    subprocess.run(
        [exe, "start", "--head", f"--port={address.split(':')[1]}", "--include-dashboard=false",
         *common],
        check=True, capture_output=True, env=env, timeout=120,
    )  # fmt: skip
    try:
        subprocess.run(
            [exe, "start", f"--address={address}", *common],
            check=True, capture_output=True, env=env, timeout=120,
        )  # fmt: skip
        yield address
    finally:
        subprocess.run([exe, "stop", "--force"], capture_output=True, env=env, timeout=120)


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """The single-process policy file: `fuzzyq train --config` when the binary is built
    (`scripts/test.sh` sets `FUZZYQ_BIN`), else the Python solver's."""
    d = tmp_path_factory.mktemp("reference")
    (d / "c.toml").write_text(CONFIG)
    out = d / "p.fzq"
    cli = os.environ.get("FUZZYQ_BIN")
    if cli:
        subprocess.run(
            [cli, "train", "--config", d / "c.toml", "--out", out, "--quiet"],
            check=True, capture_output=True, timeout=600,
        )  # fmt: skip
        return out.read_bytes()
    pytest.skip("FUZZYQ_BIN is not set: no `fuzzyq train` to compare with")


def test_sweeps_on_the_cluster_write_the_single_process_file(
    cluster: str, reference: bytes, tmp_path: Path
) -> None:
    import ray

    import fuzzyq.distributed as fd

    ray.init(address=cluster, log_to_driver=False)
    try:
        seen: list[dict[str, object]] = []
        run = fd.train(CONFIG, out=tmp_path / "p.fzq", slabs_per_group=2, on_sweep=seen.append)
    finally:
        ray.shutdown()
    assert (tmp_path / "p.fzq").read_bytes() == reference
    assert run.nodes == 2 and run.groups == 8
    assert [r["sweep"] for r in seen] == list(range(1, run.solution.sweeps + 1))
    assert any(r["evaluation"] for r in seen) and run.solution.converged
    assert {r["scheme"] for r in seen} == {"modified-policy-iteration"}
    assert all((r["extrapolate"], r["coarse_start"]) == (seen[0]["extrapolate"], seen[0]["coarse_start"]) for r in seen)
    # Each task fetched its halo's groups only: less than a broadcast of V to every task.
    assert 0 < run.fetched_bytes < 0.8 * run.broadcast_bytes
    assert run.summary()["distributed"]["fetched_bytes"] == run.fetched_bytes
    loaded = fuzzyq.load(tmp_path / "p.fzq")
    assert isinstance(loaded, fuzzyq.Solution)
    assert np.array_equal(loaded.V, run.solution.V)


def test_a_worker_killed_mid_sweep_changes_nothing(
    cluster: str, reference: bytes, tmp_path: Path
) -> None:
    import ray

    import fuzzyq.distributed as fd

    marker = tmp_path / "killed"
    ray.init(
        address=cluster,
        log_to_driver=False,
        runtime_env={"env_vars": {_tasks.KILL_ONCE: str(marker)}},
    )
    try:
        fd.train(CONFIG, out=tmp_path / "p.fzq", slabs_per_group=4)
    finally:
        ray.shutdown()
    assert marker.exists(), "no worker was killed"
    assert int(marker.read_text()) != os.getpid()
    assert (tmp_path / "p.fzq").read_bytes() == reference


def test_a_killed_driver_resumes_from_its_checkpoint_to_the_same_bytes(
    cluster: str, reference: bytes, tmp_path: Path
) -> None:
    config, checkpoint, out = tmp_path / "c.toml", tmp_path / "run.ckpt", tmp_path / "p.fzq"
    config.write_text(CONFIG)
    # The driver kills itself (SIGKILL: no clean-up) right after sweep 4's checkpoint.
    script = textwrap.dedent(
        f"""\
        import os, signal
        import fuzzyq.distributed as fd

        def see(record):
            if record["sweep"] == 4:
                os.kill(os.getpid(), signal.SIGKILL)

        fd.train(open({str(config)!r}).read(), out={str(out)!r}, address={cluster!r},
                 checkpoint={str(checkpoint)!r}, on_sweep=see)
        """
    )
    killed = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=600
    )
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    assert checkpoint.exists() and not out.exists()
    done = run_cli(
        "train", "--config", config, "--out", out, "--address", cluster,
        "--resume", checkpoint, "--checkpoint", checkpoint, "--json", tmp_path / "s.json",
    )  # fmt: skip
    assert "wrote" in done.stderr
    assert out.read_bytes() == reference
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["converged"] and summary["distributed"]["nodes"] == 2
    assert summary["distributed"]["sweeps_run"] == summary["sweeps"] - 4
