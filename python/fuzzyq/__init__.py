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
