"""fuzzyq: multi-agent reinforcement learning with a linear fuzzy Q-function.

Fuzzy Q-iteration (Luviano-Cruz et al. 2018; Busoniu et al. 2010) for continuous-state,
discrete-action multi-agent systems, solved in Rust:

>>> import fuzzyq
>>> model = fuzzyq.PointMass(agents=1)
>>> solution = fuzzyq.solve(model, model.paper_grid())
>>> solution.policy("greedy").act([-4.0, 3.0, 0.0, 0.0])
array([2., -2.])

Models are the built-in `PointMass`, the classic benchmarks `DcMotor`, `Pendulum`, `CarHill`
and `Arm` (with their presets' grids), or any `CallableModel` (a vectorised Python function);
`solve` returns a `Solution` with `V`, the greedy actions, policies, and `save` in the format
of the `fuzzyq` command line tool. `load` reads every policy file the command line writes: a
`Solution` for fuzzy Q-iteration, a `Policy` for a policy learned from samples (fuzzy
Q-learning, VQQL). `Policy.rollout` runs a policy on its environment as `fuzzyq rollout` does.
Gymnasium and PettingZoo environments live in `fuzzyq.envs`.

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
    ModelError,
    Pendulum,
    PointMass,
    Policy,
    PolicyFileError,
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
    "ModelError",
    "Pendulum",
    "PointMass",
    "Policy",
    "PolicyFileError",
    "Solution",
    "SolverError",
    "__version__",
    "available_kernels",
    "collect",
    "load",
    "solve",
]
