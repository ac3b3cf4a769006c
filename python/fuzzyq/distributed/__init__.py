"""Fuzzy Q-iteration with its sweeps distributed on a Ray cluster.

`V` is held in Ray's object store as one object per slab (a slab: one core of the first
contracted dynamics block times every core of the others). Every pass over `V` is one Ray task
per group of consecutive slabs, which fetches exactly the slabs of its halo (the input slabs
its cores' successors reach) and computes its group's slabs with the same Rust kernels as the single-process
solver (`fuzzyq.SlabProblem`, the GIL released). The driver is the solver's own (stopping rule,
extrapolation, modified policy iteration, error bound); it only combines the groups' maxima and
minima, so every sweep's `V`, the greedy actions and the policy file are bit for bit those of
``fuzzyq train --config FILE.toml``.

>>> import fuzzyq.distributed as fd  # doctest: +SKIP
>>> run = fd.train(open("pointmass.toml").read(), out="policy.fzq")  # doctest: +SKIP

Ray is an optional dependency (``pip install "ray>=2.9"``, or the ``distributed`` extra); without ``address`` a
local Ray instance is started, with it (``"auto"`` or ``"HOST:PORT"``) the driver joins an
existing cluster (``ray start --head``). Tasks lost with a worker are retried by Ray and give
the same result (each is a pure function of its inputs); a driver that dies is continued from
its per-sweep checkpoint (``checkpoint=``, then ``resume=``), to the same policy bytes.

The command line: ``python -m fuzzyq.distributed train --config FILE.toml --out POLICY.fzq
[--address ADDRESS] [--json SUMMARY.json]`` (``--help`` lists the rest).
"""

from __future__ import annotations

from fuzzyq.distributed._run import DistributedRun, RayUnavailableError, train

__all__ = ["DistributedRun", "RayUnavailableError", "train"]
