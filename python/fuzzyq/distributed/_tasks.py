"""The Ray tasks of `fuzzyq.distributed`: pure functions of their arguments (a configuration's
text, a range of slabs, the halo's layout and the groups' shards), so that Ray may retry them
on any worker with the same result. Each worker process builds the configuration's
`SlabProblem` once and keeps it."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from fuzzyq._fuzzyq import SlabProblem

# The operators this worker process built, most recent last: a few configurations at most (a
# long-lived worker serving many runs keeps only the latest, each can hold gigabytes).
_PROBLEMS: dict[str, SlabProblem] = {}
_KEEP = 2

# Testing hook: the first task to see this variable creates the file it names and kills its
# own worker process mid-task (Ray then retries the task elsewhere). Unset in normal use.
KILL_ONCE = "_FUZZYQ_DISTRIBUTED_KILL_WORKER_ONCE"


def problem(config: str) -> SlabProblem:
    """The configuration's operator, built once per process (while it is among the latest)."""
    p = _PROBLEMS.pop(config, None)
    if p is None:
        while len(_PROBLEMS) >= _KEEP:
            del _PROBLEMS[next(iter(_PROBLEMS))]
        p = SlabProblem(config)
    _PROBLEMS[config] = p
    return p


def _maybe_die() -> None:
    marker = os.environ.get(KILL_ONCE)
    if not marker:
        return
    try:
        fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return
    os.write(fd, str(os.getpid()).encode())
    os.close(fd)
    os._exit(1)


def _slabs(p: SlabProblem, values: Any) -> Any:
    """`values` of consecutive slabs, one array per slab (a single array for one slab: Ray
    stores a task's return as one object unless it returns several)."""
    parts = tuple(values[i : i + p.slab_len] for i in range(0, len(values), p.slab_len))
    return parts[0] if len(parts) == 1 else parts


def _halo(shards: tuple[Any, ...]) -> Any:
    return np.concatenate(shards) if len(shards) > 1 else shards[0]


def _read(p: SlabProblem, shards: tuple[Any, ...], shift: float) -> Any:
    """The slabs `shards` of a buffer, one after another, with the extrapolation's shift the
    buffer still owes them added (in the value type, as the solver adds it)."""
    values = _halo(shards)
    return p.shifted(values, shift) if shift != 0.0 else values


def backup(config: str, start: int, stop: int, halo: Any, shift: float, *v: Any) -> Any:
    """The backup of slabs `start..stop` from `v`, the halo's slabs in order (owing `shift`)."""
    _maybe_die()
    p = problem(config)
    return _slabs(p, p.backup(start, stop, halo, _read(p, v, shift)))


def backup_greedy(config: str, start: int, stop: int, halo: Any, shift: float, *v: Any) -> Any:
    """Each slab's values, then each slab's greedy actions."""
    _maybe_die()
    p = problem(config)
    values, actions = p.backup_greedy(start, stop, halo, _read(p, v, shift))
    vals = (values[i : i + p.slab_len] for i in range(0, len(values), p.slab_len))
    acts = (actions[i : i + p.slab_len] for i in range(0, len(actions), p.slab_len))
    return (*vals, *acts)


def rewards(config: str, start: int, stop: int) -> Any:
    p = problem(config)
    return _slabs(p, p.rewards(start, stop))


def evaluate(config: str, start: int, stop: int, halo: Any, shift: float, *refs: Any) -> Any:
    """`refs`: the slabs' policy, then the halo's values."""
    _maybe_die()
    p = problem(config)
    k = stop - start
    policy, v = _halo(refs[:k]), _read(p, refs[k:], shift)
    return _slabs(p, p.evaluate(start, stop, halo, v, policy))


def greedy(config: str, start: int, stop: int, halo: Any, shift: float, *v: Any) -> Any:
    p = problem(config)
    return _slabs(p, p.greedy(start, stop, halo, _read(p, v, shift)))


def abs_max(
    config: str, start: int, stop: int, halo: Any, a_shift: float, b_shift: float, *refs: Any
) -> float:
    """`refs`: the halo's slabs of buffer `a`, then the same slabs of `b`."""
    p = problem(config)
    half = len(refs) // 2
    a, b = _read(p, refs[:half], a_shift), _read(p, refs[half:], b_shift)
    return p.abs_max(start, stop, halo, a, b)


def diff_stats(
    config: str, shift: float, a_shift: float, b_shift: float, *refs: Any
) -> tuple[float, float, float]:
    """`refs`: some slabs of buffer `a`, then the same slabs of `b`."""
    p = problem(config)
    half = len(refs) // 2
    a, b = _read(p, refs[:half], a_shift), _read(p, refs[half:], b_shift)
    return p.diff_stats(a, b, shift)


def shifted(config: str, shift: float, *v: Any) -> Any:
    p = problem(config)
    return _slabs(p, p.shifted(_halo(v), shift))
