"""Processes forked from one that used fuzzyq work (regression, issue 49): the extension's
threads belong to the process that started them, and a forked child starts its own.

Each scenario runs in a subprocess with a timeout, so that a hang fails the test instead of
the test run: the parent solves (or unpickles a policy and acts), then forks workers by
`multiprocessing.Pool` with the fork start method, by the default `ProcessPoolExecutor`
(fork on Linux up to Python 3.13; given the fork context explicitly where the default is
another), or by joblib's `multiprocessing` backend; each worker solves and acts, and must give
the parent's own results."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(
    not hasattr(os, "fork") or sys.platform == "darwin", reason="fork start method (Linux)"
)

SCENARIO = textwrap.dedent(
    """
    import multiprocessing as mp
    import pickle
    import sys

    import numpy as np

    import fuzzyq

    MODEL = fuzzyq.PointMass(agents=1)
    GRID = MODEL.paper_grid()
    STATES = np.array([[-4.0, 3.0, 0.0, 0.0], [1.0, -2.0, 0.5, 0.5]])


    def work(_: int) -> tuple[bytes, bytes]:
        solution = fuzzyq.solve(MODEL, GRID, max_sweeps=6)
        actions = solution.policy("interpolated").act_batch(STATES)
        return solution.V.tobytes(), actions.tobytes()


    if __name__ == "__main__":
        before, way = sys.argv[1], sys.argv[2]
        want = work(0)
        if before == "unpickle":
            # Unpickling a policy and acting with it, in a fresh interpreter state.
            policy = pickle.loads(pickle.dumps(fuzzyq.solve(MODEL, GRID).policy("greedy")))
            policy.act_batch(STATES)
        fork = mp.get_context("fork")
        if way == "pool":
            with fork.Pool(2) as pool:
                got = pool.map(work, range(4))
        elif way == "executor":
            from concurrent.futures import ProcessPoolExecutor

            context = None if mp.get_start_method() == "fork" else fork
            with ProcessPoolExecutor(2, mp_context=context) as executor:
                got = list(executor.map(work, range(4)))
        else:
            from joblib import Parallel, delayed

            got = Parallel(n_jobs=2, backend="multiprocessing")(delayed(work)(i) for i in range(4))
        assert all(g == want for g in got), "a worker's results differ from the parent's"
        print("ok")
    """
)


@pytest.mark.parametrize("way", ["pool", "executor", "joblib"])
@pytest.mark.parametrize("before", ["solve", "unpickle"])
def test_forked_workers_finish(before: str, way: str, tmp_path: Path) -> None:
    if way == "joblib":
        pytest.importorskip("joblib", reason="joblib is not installed (pip install joblib)")
    script = tmp_path / "scenario.py"
    script.write_text(SCENARIO)
    try:
        done = subprocess.run(
            [sys.executable, str(script), before, way],
            capture_output=True,
            text=True,
            timeout=120,
            cwd=tmp_path,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"forked workers hung ({way} after {before})")
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ok"


def test_no_work_runs_on_threads_other_than_the_packages(tmp_path: Path) -> None:
    # Every parallel call runs on the extension's own pool (threads named fuzzyq-N), never on
    # rayon's global pool, which a forked child could not restart.
    if not Path("/proc/self/task").is_dir():
        pytest.skip("needs /proc (Linux)")
    script = tmp_path / "threads.py"
    script.write_text(
        textwrap.dedent(
            """
            import os
            import pickle

            import numpy as np

            import fuzzyq


            def others() -> int:
                names = [open(f"/proc/self/task/{t}/comm").read().strip()
                         for t in os.listdir("/proc/self/task")]
                return sum(not n.startswith("fuzzyq-") for n in names)


            start = others()
            model = fuzzyq.PointMass(agents=1)
            solution = fuzzyq.solve(model, model.paper_grid(), max_sweeps=6)
            solution.save("p.fzq")
            loaded = fuzzyq.load("p.fzq")
            for kind in ("greedy", "interpolated"):
                policy = pickle.loads(pickle.dumps(loaded.policy(kind)))
                policy.act_batch(np.zeros((64, 4)))
                policy.act([0.0, 0.0, 0.0, 0.0])
            solution.theta()
            solution.policy().rollout([-4.0, 3.0, 0.0, 0.0])
            assert others() == start, (start, others())
            print("ok")
            """
        )
    )
    done = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr
