"""fuzzyq: multi-agent reinforcement learning with a linear fuzzy Q-function.

Fuzzy Q-iteration (Luviano-Cruz et al. 2018; Busoniu et al. 2010) for continuous-state,
discrete-action multi-agent systems, solved in Rust:

>>> import fuzzyq
>>> model = fuzzyq.PointMass(agents=1)
>>> solution = fuzzyq.solve(model, model.paper_grid())
>>> solution.policy("greedy").act([-4.0, 3.0, 0.0, 0.0]).tolist()
[2.0, -2.0]

Models are the built-in `PointMass`, the classic benchmarks `DcMotor`, `Pendulum`, `CarHill`
and `Arm` (with their presets' grids), or any `CallableModel` (a vectorised Python function);
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
    ModelError,
    Pendulum,
    PointMass,
    Policy,
    PolicyFileError,
    SlabProblem,
    Solution,
    SolverError,
    __version__,
    available_kernels,
    collect,
    load,
    solve,
)

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
    "ModelError",
    "Pendulum",
    "PointMass",
    "Policy",
    "PolicyFileError",
    "SlabProblem",
    "Solution",
    "SolverError",
    "__version__",
    "available_kernels",
    "collect",
    "evaluate",
    "load",
    "rollout",
    "solve",
]


def rollout(
    policy: Policy,
    x0: npt.ArrayLike | None = None,
    steps: int | None = None,
    **kwargs: Any,
) -> dict[str, Any]:
    """Runs `policy` on its environment from `x0`, as `fuzzyq rollout` does.

    Args:
        policy: a policy of a built-in model.
        x0: the start (default: the environment's).
        steps: steps to run (default: the environment's).
        **kwargs: `Policy.rollout`'s keyword arguments (`seed`, `headings`, `plant`,
            `radius`).

    Returns:
        `Policy.rollout`'s dict of numpy arrays and metrics.
    """
    return policy.rollout(x0, steps, **kwargs)


def evaluate(
    policy: Policy,
    starts: npt.ArrayLike | None = None,
    steps: int | None = None,
    *,
    count: int = 100,
    seed: int = 0,
) -> dict[str, Any]:
    """Monte-Carlo evaluation of `policy` from many starts (`Policy.evaluate`).

    Args:
        policy: a policy of a built-in model.
        starts: model states, shape ``(n, state_dim)`` (default: `count` random starts).
        steps: steps per run (default: the environment's).
        count: number of random starts when `starts` is not given.
        seed: seed of the random starts.

    Returns:
        Every run's metrics as numpy columns under ``"runs"``, the summary under
        ``"summary"``.
    """
    return policy.evaluate(starts, steps, count=count, seed=seed)


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
    if "FuzzyQ/PointMass-v0" not in gymnasium.registry:
        gymnasium.register(
            id="FuzzyQ/PointMass-v0",
            entry_point="fuzzyq.envs.point_mass_gym:PointMassEnv",
            # The paper's 30 s episodes, as Gymnasium's TimeLimit (so that `gymnasium.make(...,
            # max_episode_steps=n)` overrides it): the made env does not truncate on its own.
            max_episode_steps=75,
            kwargs={"max_steps": None},
        )


_register_gymnasium_envs()
del _register_gymnasium_envs
