"""fuzzyq: multi-agent reinforcement learning with a linear fuzzy Q-function.

Fuzzy Q-iteration (Luviano-Cruz et al. 2018; Busoniu et al. 2010) for continuous-state,
discrete-action multi-agent systems, solved in Rust:

>>> import fuzzyq
>>> model = fuzzyq.PointMass(agents=1)
>>> solution = fuzzyq.solve(model, model.paper_grid())
>>> solution.policy("greedy").act([-4.0, 3.0, 0.0, 0.0])
array([2., -2.])

Models are the built-in `PointMass` or any `CallableModel` (a vectorised Python function);
`solve` returns a `Solution` with `V`, the greedy actions, policies, and `save`/`load` in the
format of the `fuzzyq` command line tool. Gymnasium and PettingZoo environments live in
`fuzzyq.envs`.
"""

from fuzzyq._fuzzyq import (
    CallableModel,
    ConfigError,
    FuzzyqError,
    Grid,
    InputError,
    InputTypeError,
    ModelError,
    PointMass,
    Policy,
    PolicyFileError,
    Solution,
    SolverError,
    __version__,
    available_kernels,
    load,
    solve,
)

__all__ = [
    "CallableModel",
    "ConfigError",
    "FuzzyqError",
    "Grid",
    "InputError",
    "InputTypeError",
    "ModelError",
    "PointMass",
    "Policy",
    "PolicyFileError",
    "Solution",
    "SolverError",
    "__version__",
    "available_kernels",
    "load",
    "solve",
]
