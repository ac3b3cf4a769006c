"""The Ray tasks of `fuzzyq.distributed`: pure functions of their arguments (a configuration's
text, a range of slabs, the halo's layout and the groups' shards), so that Ray may retry them
on any worker with the same result. Each worker process builds the configuration's
`SlabProblem` once and keeps it."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from fuzzyq._fuzzyq import SlabProblem

_PROBLEMS: dict[str, SlabProblem] = {}

# Testing hook: the first task to see this variable creates the file it names and kills its
# own worker process mid-task (Ray then retries the task elsewhere). Unset in normal use.
KILL_ONCE = "_FUZZYQ_DISTRIBUTED_KILL_WORKER_ONCE"


def problem(config: str) -> SlabProblem:
    """The configuration's operator, built once per process."""
    p = _PROBLEMS.get(config)
    if p is None:
        p = _PROBLEMS[config] = SlabProblem(config)
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


def gather(slab_len: int, pieces: list[tuple[int, int]], shards: tuple[Any, ...]) -> Any:
    """The halo's values: for each halo slab, `(shard, first slab in it)` names where it is."""
    return np.concatenate([shards[s][o * slab_len : (o + 1) * slab_len] for s, o in pieces])


def backup(
    config: str, start: int, stop: int, halo: Any, pieces: list[tuple[int, int]], *shards: Any
) -> Any:
    _maybe_die()
    p = problem(config)
    return p.backup(start, stop, halo, gather(p.slab_len, pieces, shards))


def backup_greedy(
    config: str, start: int, stop: int, halo: Any, pieces: list[tuple[int, int]], *shards: Any
) -> tuple[Any, Any]:
    _maybe_die()
    p = problem(config)
    values, actions = p.backup_greedy(start, stop, halo, gather(p.slab_len, pieces, shards))
    return values, actions


def rewards(config: str, start: int, stop: int) -> Any:
    return problem(config).rewards(start, stop)


def evaluate(
    config: str,
    start: int,
    stop: int,
    halo: Any,
    pieces: list[tuple[int, int]],
    policy: Any,
    *shards: Any,
) -> Any:
    _maybe_die()
    p = problem(config)
    return p.evaluate(start, stop, halo, gather(p.slab_len, pieces, shards), policy)


def greedy(
    config: str, start: int, stop: int, halo: Any, pieces: list[tuple[int, int]], *shards: Any
) -> Any:
    p = problem(config)
    return p.greedy(start, stop, halo, gather(p.slab_len, pieces, shards))


def abs_max(
    config: str, start: int, stop: int, halo: Any, pieces: list[tuple[int, int]], *shards: Any
) -> float:
    """`shards` holds the needed groups of buffer `a`, then the same groups of `b`."""
    p = problem(config)
    half = len(shards) // 2
    a = gather(p.slab_len, pieces, shards[:half])
    b = gather(p.slab_len, pieces, shards[half:])
    return p.abs_max(start, stop, halo, a, b)


def diff_stats(config: str, a: Any, b: Any, shift: float) -> tuple[float, float, float]:
    return problem(config).diff_stats(a, b, shift)


def shifted(config: str, v: Any, shift: float) -> Any:
    return problem(config).shifted(v, shift)
