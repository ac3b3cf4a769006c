"""The driver side of `fuzzyq.distributed`: the Ray backend of the solver's passes and
`train`."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

import fuzzyq
from fuzzyq._fuzzyq import SlabProblem, train_sharded
from fuzzyq.distributed import _tasks


# Retries of a task whose worker died (Ray's default is 3): each retry gives the same result.
_RETRIES = 5


class RayUnavailableError(fuzzyq.FuzzyqError, ImportError):
    """Ray is not installed (``pip install "fuzzyq[distributed]"``)."""


def _ray() -> Any:
    try:
        import ray
    except ImportError as e:
        raise RayUnavailableError(
            'fuzzyq.distributed needs Ray: pip install "fuzzyq[distributed]" (or "ray>=2.9")'
        ) from e
    return ray


@dataclasses.dataclass
class DistributedRun:
    """What `train` did: the solution (as `fuzzyq.solve` returns it) and the traffic."""

    solution: fuzzyq.Solution
    """The result, the single-process solver's bit for bit."""
    groups: int
    """Tasks per pass: groups of slabs, each one object of the store per value buffer."""
    slabs_per_group: int
    """Slabs per group (the last may hold fewer)."""
    sweeps: int
    """Sweeps this call ran (a resumed run's earlier ones excluded)."""
    evaluation_sweeps: int
    """The part of `sweeps` that were evaluation sweeps (modified policy iteration)."""
    fetched_bytes: int
    """Bytes of `V` the tasks fetched over the run (their halos' groups)."""
    broadcast_bytes: int
    """What the same passes would fetch if every task received all of `V`."""
    nodes: int
    """Nodes of the Ray cluster."""
    cpus: float
    """CPUs of the Ray cluster."""
    seconds: float
    """Wall time of the call, set-up included."""

    @property
    def fetched_fraction(self) -> float:
        """`fetched_bytes / broadcast_bytes`: the halos' share of a full broadcast."""
        return self.fetched_bytes / self.broadcast_bytes if self.broadcast_bytes else 0.0

    def summary(self) -> dict[str, Any]:
        """The run as JSON-ready values."""
        s = self.solution
        return {
            "sweeps": s.sweeps,
            "converged": s.converged,
            "final_delta": s.final_delta,
            "error_bound": s.error_bound,
            "solver_seconds": s.seconds,
            "kernel": s.kernel,
            "distributed": {
                "groups": self.groups,
                "slabs_per_group": self.slabs_per_group,
                "sweeps_run": self.sweeps,
                "evaluation_sweeps_run": self.evaluation_sweeps,
                "fetched_bytes": self.fetched_bytes,
                "broadcast_bytes": self.broadcast_bytes,
                "fetched_per_sweep_bytes": self.fetched_bytes / max(self.sweeps, 1),
                "broadcast_per_sweep_bytes": self.broadcast_bytes / max(self.sweeps, 1),
                "nodes": self.nodes,
                "cpus": self.cpus,
                "seconds": self.seconds,
            },
        }


class _RayBackend:
    """The solver's passes over three value buffers and a policy buffer, each held as one
    Ray object per group of slabs (`fuzzyq._fuzzyq.train_sharded` calls these methods)."""

    def __init__(self, ray: Any, config: str, problem: SlabProblem, per_group: int) -> None:
        self.ray = ray
        self.config = config
        self.problem = problem
        n, self.slab_len = problem.n_slabs, problem.slab_len
        self.dtype = np.dtype(problem.dtype)
        self.groups = [(s, min(s + per_group, n)) for s in range(0, n, per_group)]
        owner = np.repeat(np.arange(len(self.groups)), per_group)[:n]
        # Per group: the halo, the groups holding it, and where each halo slab sits in them.
        self.halos: list[Any] = []
        self.needs: list[list[int]] = []
        self.pieces: list[list[tuple[int, int]]] = []
        for start, stop in self.groups:
            halo = problem.input_slabs(start, stop)
            need = sorted({int(owner[c]) for c in halo})
            at = {g: i for i, g in enumerate(need)}
            self.halos.append(halo)
            self.needs.append(need)
            self.pieces.append(
                [(at[int(owner[c])], int(c) - self.groups[int(owner[c])][0]) for c in halo]
            )
        self.bufs: list[list[Any] | None] = [None, None, None]
        self.policy_refs: list[Any] | None = None
        self.config_ref = ray.put(config)
        self.fetched_bytes = 0
        self.broadcast_bytes = 0
        self.v_bytes = n * self.slab_len * self.dtype.itemsize
        remote = ray.remote(max_retries=_RETRIES)
        self.t = {
            name: remote(getattr(_tasks, name))
            for name in (
                "backup",
                "rewards",
                "evaluate",
                "greedy",
                "abs_max",
                "diff_stats",
                "shifted",
            )
        }
        self.t["backup_greedy"] = ray.remote(num_returns=2, max_retries=_RETRIES)(_tasks.backup_greedy)

    def _shard_len(self, g: int) -> int:
        start, stop = self.groups[g]
        return (stop - start) * self.slab_len

    def _zeros(self, dtype: Any) -> list[Any]:
        return [self.ray.put(np.zeros(self._shard_len(g), dtype)) for g in range(len(self.groups))]

    def _buf(self, b: int) -> list[Any]:
        refs = self.bufs[b]
        if refs is None:
            refs = self.bufs[b] = self._zeros(self.dtype)
        return refs

    def _policy(self) -> list[Any]:
        if self.policy_refs is None:
            self.policy_refs = self._zeros(np.uint32)
        return self.policy_refs

    def _halo_args(self, g: int, *bufs: int) -> list[Any]:
        """The needed groups of each buffer, counted as fetched."""
        args = [self._buf(b)[h] for b in bufs for h in self.needs[g]]
        size = sum(self._shard_len(h) for h in self.needs[g]) * self.dtype.itemsize
        self.fetched_bytes += size * len(bufs)
        self.broadcast_bytes += self.v_bytes * len(bufs)
        return args

    def _each(self, task: str, v: int, *extra: Callable[[int], Any]) -> list[Any]:
        refs = []
        for g, (start, stop) in enumerate(self.groups):
            args = [f(g) for f in extra]
            refs.append(
                self.t[task].remote(
                    self.config_ref,
                    start,
                    stop,
                    self.halos[g],
                    self.pieces[g],
                    *args,
                    *self._halo_args(g, v),
                )
            )
        return refs

    def _wait(self, refs: list[Any]) -> list[Any]:
        """Waits for `refs` (so a failed task raises here, in its pass)."""
        got: list[Any] = self.ray.get(refs)
        return got

    # The passes (buffer numbers 0, 1, 2 in the solver's internal order).

    def backup(self, v: int, out: int) -> None:
        refs = self._each("backup", v)
        self.bufs[out] = refs

    def backup_greedy(self, v: int, out: int) -> None:
        pairs = self._each("backup_greedy", v)
        values, actions = [p[0] for p in pairs], [p[1] for p in pairs]
        self.bufs[out], self.policy_refs = values, actions

    def rewards(self, out: int) -> None:
        refs = [self.t["rewards"].remote(self.config_ref, s, e) for s, e in self.groups]
        self.bufs[out] = refs

    def evaluate(self, v: int, out: int) -> None:
        policy = self._policy()
        refs = self._each("evaluate", v, lambda g: policy[g])
        self.bufs[out] = refs

    def greedy(self, v: int) -> None:
        refs = self._each("greedy", v)
        self.policy_refs = refs

    def diff_stats(self, a: int, b: int, shift: float) -> tuple[float, float, float]:
        stats = self._wait(
            [
                self.t["diff_stats"].remote(self.config_ref, x, y, shift)
                for x, y in zip(self._buf(a), self._buf(b), strict=True)
            ]
        )
        return (
            max(s[0] for s in stats),
            min(s[1] for s in stats),
            max(s[2] for s in stats),
        )

    def shift(self, v: int, shift: float) -> None:
        refs = [self.t["shifted"].remote(self.config_ref, x, shift) for x in self._buf(v)]
        self.bufs[v] = refs

    def exact_delta(self, a: int, b: int) -> float:
        refs = []
        for g, (start, stop) in enumerate(self.groups):
            refs.append(
                self.t["abs_max"].remote(
                    self.config_ref,
                    start,
                    stop,
                    self.halos[g],
                    self.pieces[g],
                    *self._halo_args(g, a, b),
                )
            )
        return float(max(self._wait(refs)))

    def load(self, v: int, values: Any) -> None:
        self.bufs[v] = self._split(values)

    def load_policy(self, policy: Any) -> None:
        self.policy_refs = self._split(policy)

    def _split(self, a: Any) -> list[Any]:
        bounds = np.cumsum([0] + [self._shard_len(g) for g in range(len(self.groups))])
        return [self.ray.put(np.array(a[s:e])) for s, e in zip(bounds[:-1], bounds[1:])]

    def values(self, v: int) -> Any:
        return np.concatenate(self._wait(self._buf(v)))

    def policy(self) -> Any:
        return np.concatenate(self._wait(self._policy()))


def _default_per_group(n_slabs: int, cpus: float) -> int:
    """About four groups per CPU of the cluster (load balance against per-task overhead)."""
    groups = max(1, min(n_slabs, int(4 * max(cpus, 1))))
    return math.ceil(n_slabs / groups)


def train(
    config: str,
    *,
    out: str | Path | None = None,
    address: str | None = None,
    slabs_per_group: int | None = None,
    checkpoint: str | Path | None = None,
    resume: str | Path | None = None,
    on_sweep: Callable[[dict[str, Any]], bool | None] | None = None,
) -> DistributedRun:
    """Trains the configuration `config` (TOML text, as ``fuzzyq config`` writes it) with its
    sweeps distributed on Ray, and writes the policy file to `out` if given (atomically; the
    bytes ``fuzzyq train --config`` writes).

    `address`: a running cluster to join (``"auto"``, ``"HOST:PORT"``, ``"ray://..."``);
    without it, the Ray instance this process already joined, or a new local one.
    `slabs_per_group`: slabs per task (default: about four tasks per CPU of the cluster).
    `checkpoint`: write the run's state there after every sweep (the format of
    ``fuzzyq train --checkpoint``); `resume`: continue from such a file. `on_sweep(record)`:
    called after every sweep with a dict (``sweep``, ``delta``, ``delta_v``, ``evaluation``,
    ``seconds``, ``bound``); returning ``False`` stops the run (`fuzzyq.SolverError`).

    Errors: `RayUnavailableError` without Ray; `fuzzyq.ConfigError` for a configuration that
    does not parse or cannot be sharded (the q-values operator, asynchronous sweeps, the
    generic backup path); `fuzzyq.InputTypeError` for arguments of the wrong type.
    """
    t0 = time.perf_counter()
    if not isinstance(config, str):
        raise fuzzyq.InputTypeError(
            f"config: expected the TOML text of a configuration, got {type(config).__name__}"
        )
    if slabs_per_group is not None and (
        isinstance(slabs_per_group, bool)
        or not isinstance(slabs_per_group, int)
        or slabs_per_group < 1
    ):
        raise fuzzyq.ConfigError(
            f"slabs_per_group: expected a positive integer, got {slabs_per_group!r}"
        )
    problem = SlabProblem(config)
    ray = _ray()
    if not ray.is_initialized():
        ray.init(address=address, log_to_driver=False, include_dashboard=False)
    elif address is not None:
        raise fuzzyq.ConfigError(
            "address: this process has already joined a Ray cluster (ray.init); "
            "pass address=None to use it"
        )
    resources = ray.cluster_resources()
    cpus = float(resources.get("CPU", 1.0))
    nodes = len([n for n in ray.nodes() if n.get("Alive")])
    per_group = slabs_per_group or _default_per_group(problem.n_slabs, cpus)
    backend = _RayBackend(ray, config, problem, min(per_group, problem.n_slabs))
    swept, evaluations = 0, 0

    def see(record: dict[str, Any]) -> bool | None:
        nonlocal swept, evaluations
        swept += 1
        evaluations += bool(record["evaluation"])
        return on_sweep(record) if on_sweep is not None else None

    solution = train_sharded(
        config,
        backend,
        resume=None if resume is None else str(resume),
        checkpoint=None if checkpoint is None else str(checkpoint),
        on_sweep=see,
    )
    if out is not None:
        solution.save(str(out))
    return DistributedRun(
        solution=solution,
        groups=len(backend.groups),
        slabs_per_group=min(per_group, problem.n_slabs),
        sweeps=swept,
        evaluation_sweeps=evaluations,
        fetched_bytes=backend.fetched_bytes,
        broadcast_bytes=backend.broadcast_bytes,
        nodes=nodes,
        cpus=cpus,
        seconds=time.perf_counter() - t0,
    )
