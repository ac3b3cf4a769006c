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
    """Ray is not installed (``pip install "ray>=2.9"``)."""


def _ray() -> Any:
    try:
        import ray
    except ImportError as e:
        raise RayUnavailableError(
            'fuzzyq.distributed needs Ray: pip install "ray>=2.9"'
        ) from e
    return ray


@dataclasses.dataclass
class DistributedRun:
    """What `train` did: the solution (as `fuzzyq.solve` returns it) and the traffic."""

    solution: fuzzyq.Solution
    """The result, the single-process solver's bit for bit."""
    groups: int
    """Tasks per pass: groups of consecutive slabs (each slab is one object of the store)."""
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
    Ray object per slab, computed by one task per group of consecutive slabs that receives
    exactly its halo's slabs (`fuzzyq._fuzzyq.train_sharded` calls these methods)."""

    def __init__(self, ray: Any, config: str, problem: SlabProblem, per_group: int) -> None:
        self.ray = ray
        n, self.slab_len = problem.n_slabs, problem.slab_len
        self.n_slabs = n
        self.dtype = np.dtype(problem.dtype)
        self.groups = [(s, min(s + per_group, n)) for s in range(0, n, per_group)]
        self.halos = [problem.input_slabs(start, stop) for start, stop in self.groups]
        # `bufs[b][c]`: slab `c` of value buffer `b`; None: every value 0 (not yet written).
        self.bufs: list[list[Any] | None] = [None, None, None]
        # `owed[b]`: the extrapolation's shift buffer `b` still owes its values. A shift is
        # applied by the tasks that next read the buffer (the same `x + s` in the value type),
        # which saves a pass over `V` per sweep.
        self.owed = [0.0, 0.0, 0.0]
        self.problem = problem
        self.policy_refs: list[Any] | None = None
        self.config = ray.put(config)
        self.slab_bytes = self.slab_len * self.dtype.itemsize
        self.fetched_bytes = 0
        self.broadcast_bytes = 0
        self.v_bytes = n * self.slab_bytes
        self.task = {
            name: ray.remote(max_retries=_RETRIES)(getattr(_tasks, name))
            for name in (
                "backup",
                "backup_greedy",
                "rewards",
                "evaluate",
                "greedy",
                "abs_max",
                "diff_stats",
                "shifted",
            )
        }

    def _zeros(self, dtype: Any) -> list[Any]:
        zero = self.ray.put(np.zeros(self.slab_len, dtype))
        return [zero] * self.n_slabs

    def _buf(self, b: int) -> list[Any]:
        refs = self.bufs[b]
        if refs is None:
            refs = self.bufs[b] = self._zeros(self.dtype)
        return refs

    def _policy(self) -> list[Any]:
        if self.policy_refs is None:
            self.policy_refs = self._zeros(np.uint32)
        return self.policy_refs

    def _halo(self, g: int, *bufs: int) -> list[Any]:
        """Group `g`'s halo slabs of each buffer in `bufs`, counted as fetched."""
        halo = self.halos[g]
        self.fetched_bytes += len(halo) * self.slab_bytes * len(bufs)
        self.broadcast_bytes += self.v_bytes * len(bufs)
        return [self._buf(b)[c] for b in bufs for c in halo]

    def _call(self, name: str, g: int, returns: int, *args: Any) -> list[Any]:
        """Task `name` for group `g` with `returns` objects (a list even for one)."""
        start, stop = self.groups[g]
        refs = (
            self.task[name]
            .options(num_returns=returns)
            .remote(self.config, start, stop, *args)
        )
        return [refs] if returns == 1 else list(refs)

    def _per_group(self, name: str, extra: Callable[[int], list[Any]], v: int) -> list[Any]:
        """One task per group: the new slabs of a buffer, in order."""
        out: list[Any] = []
        for g, (start, stop) in enumerate(self.groups):
            out += self._call(
                name, g, stop - start, self.halos[g], self.owed[v], *extra(g), *self._halo(g, v)
            )
        return out

    def _write(self, out: int, refs: list[Any]) -> None:
        self.bufs[out], self.owed[out] = refs, 0.0

    def _own(self, refs: list[Any], g: int) -> list[Any]:
        start, stop = self.groups[g]
        return refs[start:stop]

    # The passes (buffer numbers 0, 1, 2 in the solver's internal order).

    def backup(self, v: int, out: int) -> None:
        self._write(out, self._per_group("backup", lambda g: [], v))

    def backup_greedy(self, v: int, out: int) -> None:
        values: list[Any] = []
        actions: list[Any] = []
        for g, (start, stop) in enumerate(self.groups):
            k = stop - start
            refs = self._call(
                "backup_greedy", g, 2 * k, self.halos[g], self.owed[v], *self._halo(g, v)
            )
            values += refs[:k]
            actions += refs[k:]
        self._write(out, values)
        self.policy_refs = actions

    def rewards(self, out: int) -> None:
        refs: list[Any] = []
        for g, (start, stop) in enumerate(self.groups):
            refs += self._call("rewards", g, stop - start)
        self._write(out, refs)

    def evaluate(self, v: int, out: int) -> None:
        policy = self._policy()
        self._write(out, self._per_group("evaluate", lambda g: self._own(policy, g), v))

    def greedy(self, v: int) -> None:
        self.policy_refs = self._per_group("greedy", lambda g: [], v)

    def diff_stats(self, a: int, b: int, shift: float) -> tuple[float, float, float]:
        x, y = self._buf(a), self._buf(b)
        stats = self.ray.get(
            [
                self.task["diff_stats"].remote(
                    self.config, shift, self.owed[a], self.owed[b], *x[s:e], *y[s:e]
                )
                for s, e in self.groups
            ]
        )
        return (
            max(s[0] for s in stats),
            min(s[1] for s in stats),
            max(s[2] for s in stats),
        )

    def shift(self, v: int, shift: float) -> None:
        if self.owed[v] != 0.0:
            self._settle(v)
        self.owed[v] = shift

    def _settle(self, v: int) -> None:
        """Applies the shift `v` owes (a pass of its own: two shifts in a row never add up to
        the same bits as one)."""
        refs: list[Any] = []
        x = self._buf(v)
        for s, e in self.groups:
            task = self.task["shifted"].options(num_returns=e - s)
            r = task.remote(self.config, self.owed[v], *x[s:e])
            refs += [r] if e - s == 1 else list(r)
        self._write(v, refs)

    def exact_delta(self, a: int, b: int) -> float:
        refs = [
            self._call("abs_max", g, 1, self.halos[g], self.owed[a], self.owed[b],
                       *self._halo(g, a, b))[0]  # fmt: skip
            for g in range(len(self.groups))
        ]
        return float(max(self.ray.get(refs)))

    def load(self, v: int, values: Any) -> None:
        self._write(v, self._split(values))

    def load_policy(self, policy: Any) -> None:
        self.policy_refs = self._split(policy)

    def _split(self, a: Any) -> list[Any]:
        k = self.slab_len
        return [self.ray.put(np.array(a[c * k : (c + 1) * k])) for c in range(self.n_slabs)]

    def values(self, v: int) -> Any:
        values = np.concatenate(self.ray.get(self._buf(v)))
        return self.problem.shifted(values, self.owed[v]) if self.owed[v] != 0.0 else values

    def policy(self) -> Any:
        return np.concatenate(self.ray.get(self._policy()))


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
    ``seconds``, ``bound``, and the run's ``scheme``, ``extrapolate`` and ``coarse_start`` as
    `fuzzyq.solve`'s callback gets them); returning ``False`` stops the run
    (`fuzzyq.SolverError`).

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
