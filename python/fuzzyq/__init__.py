"""fuzzyq: multi-agent reinforcement learning with a linear fuzzy Q-function.

Fuzzy Q-iteration (Luviano-Cruz et al. 2018; Busoniu et al. 2010) for continuous-state,
discrete-action multi-agent systems, solved in Rust:

>>> import fuzzyq
>>> model = fuzzyq.PointMass(agents=1)
>>> solution = fuzzyq.solve(model, model.paper_grid())
>>> solution.policy("greedy").act([-4.0, 3.0, 0.0, 0.0]).tolist()
[2.0, -2.0]

Models are the built-in `PointMass`, the classic benchmarks `DcMotor`, `Pendulum`, `CarHill`
and `Arm` (with their presets' grids), or any `CallableModel` (a vectorised Python function).
A system known only through its transitions (a Gymnasium environment, a simulator, logged
data) is declared as a `Task` and learned from interaction: `collect` and `learn`, the model
estimated as ``fuzzyq train --learner learned-model`` estimates it; `evaluate` and `rollout`
run a policy on it.
`solve` returns a `Solution` with `V`, the greedy actions, policies, and `save` in the format
of the `fuzzyq` command line tool. `load` reads every policy file the command line writes: a
`Solution` for fuzzy Q-iteration, a `Policy` for a policy learned from samples (fuzzy
Q-learning, VQQL). `Policy.rollout` runs a policy on its environment as `fuzzyq rollout` does.
Gymnasium and PettingZoo environments live in `fuzzyq.envs`.

The documentation site (``mkdocs build --strict`` in a checkout; its sources are in
docs/site) has a getting-started page, the Python guide (docs/site/python/guide.md), a page
per environment and the API reference generated from these modules and the type stubs. The
package also installs the ``fuzzyq`` command line (``fuzzyq --help``, or
``python -m fuzzyq --help``).

Every error fuzzyq raises for bad input derives from `FuzzyqError`, with a one-line message
that starts with the argument at fault:

- `InputTypeError` (also a `TypeError`): an argument of the wrong type (a string for a
  number, a float for a count, a list for a `Grid`);
- `ConfigError` (also a `ValueError`): a setting, parameter or model definition of the right
  type with a value it cannot take (a negative count, a non-finite number, an unknown name,
  repeated actions, `absorbing_goal=True` on a model without goal states);
- `InputError` (also a `ValueError`): an array of the wrong shape or with bad values, an index
  out of range;
- `ModelError` (also a `ValueError`): a `CallableModel`'s function returned unusable data;
- `PolicyFileError` (also an `OSError`): a policy file that cannot be read or written;
- `SolverError` (also a `RuntimeError`): a problem the solver refuses, or a run larger than
  its memory limit (`solve(..., max_memory_gb=...)` raises it deliberately);
- `InternalError` (also a `RuntimeError`): a bug in fuzzyq (a Rust panic), never bad input.
"""

from typing import Any

import numpy.typing as npt

from fuzzyq._fuzzyq import (
    Arm,
    CallableModel,
    CarHill,
    ClassicModel,
    ConfigError,
    DcMotor,
    FuzzyqError,
    Grid,
    InputError,
    InputTypeError,
    InternalError,
    Khepera,
    KheperaPlant,
    ModelError,
    Pendulum,
    PointMass,
    Policy,
    PolicyFileError,
    SlabProblem,
    Solution,
    SolverError,
    Task,
    __version__,
    available_kernels,
    learn_from_samples,
    load,
    solve,
)
from fuzzyq import _interact
from fuzzyq._interact import collect, learn

__all__ = [
    "Arm",
    "CallableModel",
    "CarHill",
    "ClassicModel",
    "ConfigError",
    "DcMotor",
    "FuzzyqError",
    "Grid",
    "InputError",
    "InputTypeError",
    "InternalError",
    "Khepera",
    "KheperaPlant",
    "ModelError",
    "Pendulum",
    "PointMass",
    "Policy",
    "PolicyFileError",
    "SlabProblem",
    "Solution",
    "SolverError",
    "Task",
    "__version__",
    "available_kernels",
    "collect",
    "evaluate",
    "learn",
    "learn_from_samples",
    "load",
    "rollout",
    "solve",
]


def rollout(
    policy: Policy,
    source: Any = None,
    steps: int | None = None,
    *,
    x0: Any = None,
    task: Task | None = None,
    **kwargs: Any,
) -> dict[str, Any]:
    """Runs `policy` from `x0`: on its environment as `fuzzyq rollout` does, or on a system
    of your own.

    Args:
        policy: a policy of a built-in model, or of a system of your own.
        source: the system to run on, a `CallableModel` or a Gymnasium environment; None (or,
            as before, the start itself): the policy's own environment.
        steps: steps to run (default: the environment's; until the episode ends for a
            Gymnasium environment; required for a `CallableModel`).
        x0: the start (default: the environment's; a Gymnasium environment starts from its
            reset with `seed`).
        task: a Gymnasium environment's `Task` (its actions).
        **kwargs: `Policy.rollout`'s keyword arguments (`seed`, `headings`, `plant`,
            `radius`); for a system of your own, `seed` only.

    Returns:
        `Policy.rollout`'s dict of numpy arrays and metrics; for a system of your own, its
        ``states``, ``actions``, ``rewards``, ``return``, ``steps``, ``done`` and ``success``.
    """
    if _is_system(source):
        return _interact.rollout(policy, source, x0, steps, task=task, **kwargs)
    return policy.rollout(_own_environment("x0", source, x0, task), steps, **kwargs)


def evaluate(
    policy: Policy,
    source: Any = None,
    steps: int | None = None,
    *,
    count: int = 100,
    seed: int = 0,
    starts: Any = None,
    task: Task | None = None,
) -> dict[str, Any]:
    """Monte-Carlo evaluation of `policy` from many starts: on its environment
    (`Policy.evaluate`), or over episodes of a system of your own.

    Args:
        policy: a policy of a built-in model, or of a system of your own.
        source: the system to run on, a `CallableModel` or a Gymnasium environment; None (or,
            as before, the starts themselves): the policy's own environment.
        steps: steps per run (default: the environment's; until the episode ends for a
            Gymnasium environment; required for a `CallableModel`).
        count: number of random starts (episodes).
        seed: seed of the random starts (episode ``i`` of a Gymnasium environment resets with
            ``seed + i``).
        starts: model states, shape ``(n, state_dim)`` (default: `count` random starts); for
            a `CallableModel`, its starts as `fuzzyq.collect` takes them.
        task: a Gymnasium environment's `Task` (its actions).

    Returns:
        Every run's metrics as numpy columns under ``"runs"``, the summary under
        ``"summary"``.
    """
    if _is_system(source):
        return _interact.evaluate(
            policy, source, count=count, steps=steps, seed=seed, starts=starts, task=task
        )
    starts = _own_environment("starts", source, starts, task)
    return policy.evaluate(starts, steps, count=count, seed=seed)


def _own_environment(name: str, positional: Any, keyword: Any, task: Task | None) -> Any:
    """The start argument `name` of a run on the policy's own environment, given positionally
    (as before systems of your own) or by keyword; a one-line error for both, or a task."""
    if task is not None:
        raise ConfigError("task: only a system of your own (a Gymnasium environment) needs one")
    if positional is not None and keyword is not None:
        raise ConfigError(f"{name}: given twice (positionally and by keyword)")
    return keyword if positional is None else positional


def _is_system(obj: Any) -> bool:
    """Whether `obj` is a system of the user's own: a `CallableModel` or a Gymnasium env."""
    return isinstance(obj, CallableModel) or _interact._is_gym_env(obj)


def _register_gymnasium_envs() -> None:
    """Registers fuzzyq's Gymnasium ids (the envs live in `fuzzyq.envs`) when gymnasium is
    installed; never imports it otherwise."""
    import importlib.util

    if importlib.util.find_spec("gymnasium") is None:
        return
    try:
        import gymnasium
    except ImportError:  # a broken gymnasium install must not break `import fuzzyq`
        return
    from fuzzyq import _gym_ids

    _gym_ids.register(gymnasium)


_register_gymnasium_envs()
del _register_gymnasium_envs
