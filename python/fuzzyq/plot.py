"""Pictures of fuzzyq's results with matplotlib: the figures the command line draws.

Requires matplotlib (the ``plot`` extra: ``pip install "fuzzyq[plot]"``). ``import fuzzyq.plot``
without it raises an ImportError that says so.

- `value_map`, `policy_map` and `maps` (both side by side, as ``fuzzyq rollout --maps``): heat
  maps of a `fuzzyq.Solution`'s or `fuzzyq.Policy`'s value function and greedy actions over two
  chosen state variables, the others held at given values.
- `rollout`: a run of `fuzzyq.Policy.rollout` or `fuzzyq.rollout`: for the point masses and the
  robots, per agent the states and the actions over time and the paths in the plane (the
  paper's figures 2-4, as ``fuzzyq rollout --plot``); for the classic benchmarks and systems of
  your own, one panel per state variable, per action component and the reward.
- `learning_curve`: the learning curve of fuzzy Q-learning, from the CSV file of
  ``fuzzyq train --learner fql --curve FILE.csv`` or a mapping of its columns.
- `efficiency_curve`: success against transitions of interaction, per learner, from the
  ``efficiency.csv`` of ``fuzzyq compare --curve`` or its rows.

Every function returns a `matplotlib.figure.Figure` made without pyplot: nothing opens a
window and it works headless. Save it with ``fig.savefig("value.png")``, or let a notebook show
it. Bad input raises the package's one-line errors: `fuzzyq.InputTypeError` for an argument of
the wrong type, `fuzzyq.InputError` for arrays of the wrong shape or values and indices out of
range, `fuzzyq.ConfigError` for an option it cannot take.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

try:
    import matplotlib
except ImportError as exc:  # pragma: no cover - exercised by a test that hides matplotlib
    raise ImportError('fuzzyq.plot needs matplotlib: pip install "fuzzyq[plot]"') from exc
from matplotlib.axes import Axes
from matplotlib.colorbar import Colorbar
from matplotlib.colors import BoundaryNorm, Colormap
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from fuzzyq._fuzzyq import (
    ClassicModel,
    ConfigError,
    InputError,
    InputTypeError,
    Khepera,
    PointMass,
    Policy,
    Solution,
)

__all__ = [
    "MOVING_AVERAGE_WINDOW",
    "efficiency_curve",
    "learning_curve",
    "maps",
    "policy_map",
    "rollout",
    "value_map",
]

MOVING_AVERAGE_WINDOW = 20
"""Episodes in the learning curve's moving averages (as the command line's)."""

_Floats = npt.NDArray[np.float64]

_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e")
_PURPLE = "#9467bd"
_GOOD = "#2ca02c"
_LEARNERS = (
    "fqi",
    "crisp",
    "crisp-uniform",
    "fql",
    "fql-literal",
    "vqql",
    "learned-model",
    "fqi-samples",
    "vqql-batch",
)
_LEARNER_COLOURS = (*_COLOURS, _PURPLE, "#8c564b", "#17becf", "#e377c2", "#7f7f7f")
_ENVS = ("pointmass", "khepera", "dcmotor", "pendulum", "carhill", "arm")
_AGENTS = ("pointmass", "khepera")  # per-agent layouts; their variables carry the agent number

# One agent's state variables, (name, label): the state a policy acts on (for fuzzy
# Q-iteration on the robots their poses) and the state a rollout reports.
_POINT = (("sx", "$s_x$ (m)"), ("sy", "$s_y$ (m)"), ("vx", "$v_x$ (m/s)"), ("vy", "$v_y$ (m/s)"))
_ANGLE = (("x1", "angle (rad)"), ("x2", "angular velocity (rad/s)"))
_POLICY_STATES: dict[str, tuple[tuple[str, str], ...]] = {
    "pointmass": _POINT,
    "khepera": (("x", "$x$ (m)"), ("y", "$y$ (m)"), ("heading", "heading (rad)")),
    "dcmotor": _ANGLE,
    "pendulum": (("x1", "angle (rad, 0 = up)"), ("x2", "angular velocity (rad/s)")),
    "carhill": (("x1", "position (m)"), ("x2", "velocity (m/s)")),
    "arm": (
        ("x1", "angle 1 (rad)"),
        ("x2", "angular velocity 1 (rad/s)"),
        ("x3", "angle 2 (rad)"),
        ("x4", "angular velocity 2 (rad/s)"),
    ),
}
_ROLLOUT_STATES = {**_POLICY_STATES, "khepera": _POINT}
_ACTIONS: dict[str, tuple[tuple[str, str], ...]] = {
    "pointmass": (("ux", "$u_x$ (N)"), ("uy", "$u_y$ (N)")),
    "khepera": (("vl", "$v_l$ (m/s)"), ("vr", "$v_r$ (m/s)")),
    "dcmotor": (("u1", "voltage (V)"),),
    "pendulum": (("u1", "voltage (V)"),),
    "carhill": (("u1", "force (N)"),),
    "arm": (("u1", "torque 1 (N m)"), ("u2", "torque 2 (N m)")),
}

_LEARNING_COLUMNS = (
    "episode",
    "steps",
    "return",
    "mean_abs_td",
    "epsilon",
    "alpha",
    "param_change",
    "eval_mean_return",
    "eval_success_rate",
)

# The learning curve's panels but the last (which titles itself): caption and y label.
_LEARNING_PANELS = (
    ("Return per episode", "return"),
    ("Mean |TD error| per episode", "mean |delta|"),
    ("Steps per episode", "steps"),
    ("Exploration and step size", "value"),
    ("Greedy evaluation: success rate", "success rate"),
)


# Shared checks and conversions.


def _type_name(value: object) -> str:
    return type(value).__name__


def _floats(name: str, value: Any, ndim: int | None = None) -> _Floats:
    """`value` as a float64 array with `ndim` dimensions, finite; one-line errors."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputTypeError(f"{name}: expected numbers, got {_type_name(value)}") from None
    if ndim is not None and array.ndim != ndim:
        raise InputError(f"{name}: expected {ndim} dimensions, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise InputError(f"{name}: non-finite values")
    return array


def _count(name: str, value: Any, least: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InputTypeError(f"{name}: expected an integer >= {least}, got {_type_name(value)}")
    if value < least:
        raise ConfigError(f"{name}: expected an integer >= {least}, got {value}")
    return int(value)


def _variables(
    per: Sequence[tuple[str, str]] | None, agents: int, suffix: bool, dim: int, prefix: str
) -> tuple[list[str], list[str]]:
    """Names and labels of `dim` variables: one agent's `per` repeated for each agent (names
    numbered by agent where `suffix`), or ``prefix1``, ``prefix2``, ... when they do not fit."""
    if not per or len(per) * agents != dim:
        names = [f"{prefix}{i + 1}" for i in range(dim)]
        return names, names
    names = [f"{n}{i + 1}" if suffix else n for i in range(agents) for n, _ in per]
    labels = [lab if agents == 1 else f"{lab}, agent {i + 1}" for i in range(agents)
              for _, lab in per]
    return names, labels


def _env_name(env: Any) -> str | None:
    """The environment's name from `env`: a name, anything with an ``env`` attribute (a policy,
    a solution, a classic model), a `PointMass` or a `Khepera`, or None."""
    if env is None or isinstance(env, str):
        if env is not None and env not in _ENVS:
            raise ConfigError(f"env: expected one of {', '.join(_ENVS)}, got {env!r}")
        return env
    if isinstance(env, PointMass):
        return "pointmass"
    if isinstance(env, Khepera):
        return "khepera"
    if isinstance(env, (Policy, Solution, ClassicModel)):
        name: str | None = env.env
        return name
    raise InputTypeError(f"env: expected a name, a model or a policy, got {_type_name(env)}")


# Value and policy maps.


@dataclass(frozen=True)
class _Lattice:
    """The states of a heat map: `xs` by `ys` samples of two variables, the others at `at`."""

    policy: Policy
    value: Callable[[npt.ArrayLike], float]
    xs: _Floats
    ys: _Floats
    states: _Floats  # (len(ys) * len(xs), state_dim): row j holds ys[j], xs varying fastest
    labels: tuple[str, str]
    fixed: str  # the other variables' values, for the title ("" in two dimensions)

    def image(self, values: npt.ArrayLike) -> _Floats:
        return np.asarray(values, dtype=np.float64).reshape(len(self.ys), len(self.xs))


def _lattice(
    source: Any,
    x: int | str,
    y: int | str,
    at: npt.ArrayLike | None,
    bounds: npt.ArrayLike | None,
    resolution: int,
    kind: Literal["greedy", "interpolated"],
) -> _Lattice:
    if isinstance(source, Solution):
        policy, value = source.policy(kind), source.value
    elif isinstance(source, Policy):
        policy, value = source, source.value
    else:
        raise InputTypeError(f"source: expected a Solution or a Policy, got {_type_name(source)}")
    n = _count("resolution", resolution, 2)
    suffix = policy.env in _AGENTS
    per = _POLICY_STATES.get(policy.env or "")
    names, labels = _variables(per, policy.n_agents, suffix, policy.state_dim, "x")
    ix, iy = _index("x", x, names), _index("y", y, names)
    if ix == iy:
        raise InputError(f"y: the same state variable as x ({names[ix]})")
    (x0, x1), (y0, y1) = _ranges(source, bounds, ix, iy)
    point = _at(source, at, policy.state_dim)
    xs, ys = np.linspace(x0, x1, n), np.linspace(y0, y1, n)
    states = np.tile(point, (n * n, 1))
    states[:, ix] = np.tile(xs, n)
    states[:, iy] = np.repeat(ys, n)
    others = [f"{names[d]} = {point[d]:.3g}" for d in range(len(point)) if d not in (ix, iy)]
    fixed = "others at " + ", ".join(others) if others else ""
    return _Lattice(policy, value, xs, ys, states, (labels[ix], labels[iy]), fixed)


def _index(name: str, which: int | str, names: list[str]) -> int:
    """The index of state variable `which`, given by index or by name."""
    if isinstance(which, str):
        if which not in names:
            raise InputError(f"{name}: no state variable {which!r}; the names are {names}")
        return names.index(which)
    if isinstance(which, bool) or not isinstance(which, (int, np.integer)):
        raise InputTypeError(f"{name}: expected an index or a name, got {_type_name(which)}")
    if not 0 <= which < len(names):
        raise InputError(f"{name}: index {which} out of range for {len(names)} state variables")
    return int(which)


def _ranges(
    source: Solution | Policy, bounds: npt.ArrayLike | None, ix: int, iy: int
) -> tuple[tuple[float, float], tuple[float, float]]:
    """The ranges of x and y: `bounds`, or the solution grid's first and last cores."""
    if bounds is None:
        if not isinstance(source, Solution):
            raise ConfigError("bounds: a Policy has no grid; give ((x_lo, x_hi), (y_lo, y_hi))")
        cores = source.grid.cores
        return (cores[ix][0], cores[ix][-1]), (cores[iy][0], cores[iy][-1])
    b = _floats("bounds", bounds, 2)
    if b.shape != (2, 2) or not np.all(b[:, 0] < b[:, 1]):
        raise InputError("bounds: expected ((x_lo, x_hi), (y_lo, y_hi)) with lo < hi")
    return (b[0, 0], b[0, 1]), (b[1, 0], b[1, 1])


def _at(source: Solution | Policy, at: npt.ArrayLike | None, dim: int) -> _Floats:
    """The full state the other variables are held at: `at`, or per variable 0 where the
    solution's grid covers it and the middle of its cores otherwise (0 for a Policy)."""
    if at is None:
        if isinstance(source, Policy):
            return np.zeros(dim)
        ends = [(c[0], c[-1]) for c in source.grid.cores]
        return np.array([0.0 if lo <= 0.0 <= hi else (lo + hi) / 2 for lo, hi in ends])
    point = _floats("at", at, 1)
    if point.shape != (dim,):
        raise InputError(f"at: expected a full state, shape ({dim},), got shape {point.shape}")
    return point


def _heat(
    fig: Figure, ax: Axes, lat: _Lattice, image: _Floats, titles: tuple[str, str], **kw: Any
) -> Colorbar:
    """Draws `image` over the lattice on `ax` with its colour bar; `titles` are the panel's
    and the colour bar's."""
    dx, dy = (lat.xs[1] - lat.xs[0]) / 2, (lat.ys[1] - lat.ys[0]) / 2
    extent = (lat.xs[0] - dx, lat.xs[-1] + dx, lat.ys[0] - dy, lat.ys[-1] + dy)
    shown = ax.imshow(
        image, origin="lower", extent=extent, aspect="auto", interpolation="nearest", **kw
    )
    ax.set(title=titles[0], xlabel=lat.labels[0], ylabel=lat.labels[1])
    return fig.colorbar(shown, ax=ax, label=titles[1])


def _draw_value(fig: Figure, ax: Axes, lat: _Lattice) -> None:
    values = [lat.value(s) for s in lat.states]
    _heat(fig, ax, lat, lat.image(values), ("$V(x)$", "value"), cmap="viridis")


def _draw_policy(fig: Figure, ax: Axes, lat: _Lattice, show: str, component: int) -> None:
    p = lat.policy
    if show == "action":
        j = _component(component, p)
        env = p.env or ""
        per = _ACTIONS.get(env)
        labels = _variables(per, p.n_agents, env in _AGENTS, p.action_dim, "u")[1]
        image = lat.image(p.act_batch(lat.states)[:, j])
        _heat(fig, ax, lat, image, (f"{p.kind} action", labels[j]), cmap="viridis")
        return
    if show != "index":
        raise ConfigError(f'show: expected "index" or "action", got {show!r}')
    if p.kind != "greedy":
        raise ConfigError('show: the interpolated policy has no action indices; use show="action"')
    n = p.n_joint_actions
    image = lat.image(p.act_index(lat.states))
    norm = BoundaryNorm(np.arange(n + 1) - 0.5, n)
    titles = ("greedy joint action", "joint action index")
    bar = _heat(fig, ax, lat, image, titles, cmap=_categories(n), norm=norm)
    bar.set_ticks(range(n) if n <= 25 else MaxNLocator(integer=True))


def _component(component: int, policy: Policy) -> int:
    if isinstance(component, bool) or not isinstance(component, (int, np.integer)):
        raise InputTypeError(f"component: expected an integer, got {_type_name(component)}")
    if not 0 <= component < policy.action_dim:
        raise InputError(
            f"component: index {component} out of range for {policy.action_dim} action values"
        )
    return int(component)


def _categories(n: int) -> Colormap:
    """A colour map of `n` distinguishable colours (qualitative where there are few)."""
    name = "tab10" if n <= 10 else "tab20" if n <= 20 else "turbo"
    return matplotlib.colormaps[name].resampled(n)


def _map_title(title: str | None, default: str, lat: _Lattice) -> str:
    if title is not None:
        return title
    env = lat.policy.env
    text = f"{env}: {default}" if env else default
    return f"{text}\n{lat.fixed}" if lat.fixed else text


def value_map(
    source: Solution | Policy,
    x: int | str = 0,
    y: int | str = 1,
    *,
    at: npt.ArrayLike | None = None,
    bounds: npt.ArrayLike | None = None,
    resolution: int = 101,
    title: str | None = None,
) -> Figure:
    """A heat map of the value function over state variables `x` and `y`, the others fixed.

    The value at each of ``resolution x resolution`` states is ``source.value(state)``: `V`
    interpolated on the grid (fuzzy Q-iteration), or ``max_u Q`` for a policy learned from
    samples.

    Args:
        source: a `fuzzyq.Solution`, or a `fuzzyq.Policy` (then with `bounds`).
        x: the state variable on the horizontal axis: its index, or its name (``"x1"``,
            ``"x2"``, ... for the classic benchmarks; ``"sx1"``, ``"sy1"``, ``"vx1"``,
            ``"vy1"``, ``"sx2"``, ... for the point masses; ``"x1"``, ``"y1"``,
            ``"heading1"``, ... for the robots' poses).
        y: the state variable on the vertical axis, likewise.
        at: the full state the other variables are held at (its `x` and `y` entries are
            ignored); default: per variable 0 where the solution's grid covers it, the middle
            of its cores otherwise (zeros for a `Policy`).
        bounds: the ranges drawn, ``((x_lo, x_hi), (y_lo, y_hi))``; default: from the first to
            the last core of the solution's grid.
        resolution: samples per axis, at least 2.
        title: the figure's title; default: the environment, and the values of the others.

    Returns:
        The figure: one panel with its colour bar.

    Raises:
        InputTypeError: `source` is not a Solution or Policy, or an argument of the wrong type.
        InputError: `x` or `y` out of range, unknown or equal; `at` or `bounds` of the wrong
            shape or non-finite.
        ConfigError: `resolution` below 2, or no `bounds` for a Policy.
    """
    lat = _lattice(source, x, y, at, bounds, resolution, "greedy")
    fig = Figure(figsize=(6.4, 5.4), layout="constrained")
    _draw_value(fig, fig.add_subplot(), lat)
    fig.suptitle(_map_title(title, "value function", lat))
    return fig


def policy_map(
    source: Solution | Policy,
    x: int | str = 0,
    y: int | str = 1,
    *,
    show: Literal["action", "index"] = "action",
    component: int = 0,
    kind: Literal["greedy", "interpolated"] = "greedy",
    at: npt.ArrayLike | None = None,
    bounds: npt.ArrayLike | None = None,
    resolution: int = 101,
    title: str | None = None,
) -> Figure:
    """A heat map of the policy over state variables `x` and `y`, the others fixed.

    ``show="action"`` draws one value of the joint action vector (``policy.act_batch``), as
    ``fuzzyq rollout --maps`` draws the first; ``show="index"`` the greedy joint action index
    (``policy.act_index``) in distinct colours, one per index.

    Args:
        source: a `fuzzyq.Solution` (its policy of `kind`), or a `fuzzyq.Policy` (drawn as it
            is, with `bounds`).
        x: the state variable on the horizontal axis: its index or its name (see `value_map`).
        y: the state variable on the vertical axis, likewise.
        show: ``"action"`` (an action value) or ``"index"`` (the joint action index; greedy
            policies only).
        component: with ``show="action"``, which value of the joint action vector (for the
            point masses ``0`` is agent 1's ``u_x``, ``1`` its ``u_y``, ``2`` agent 2's
            ``u_x``, ...).
        kind: the policy of a Solution: ``"greedy"`` or ``"interpolated"``.
        at: the full state the other variables are held at (see `value_map`).
        bounds: the ranges drawn, ``((x_lo, x_hi), (y_lo, y_hi))`` (see `value_map`).
        resolution: samples per axis, at least 2.
        title: the figure's title; default: the environment, and the values of the others.

    Returns:
        The figure: one panel with its colour bar.

    Raises:
        InputTypeError: `source` is not a Solution or Policy, or an argument of the wrong type.
        InputError: `x`, `y` or `component` out of range, `x` and `y` unknown or equal; `at`
            or `bounds` of the wrong shape or non-finite.
        ConfigError: an unknown `show` or `kind`, ``show="index"`` for an interpolated policy,
            `resolution` below 2, or no `bounds` for a Policy.
    """
    lat = _lattice(source, x, y, at, bounds, resolution, kind)
    fig = Figure(figsize=(6.4, 5.4), layout="constrained")
    _draw_policy(fig, fig.add_subplot(), lat, show, component)
    fig.suptitle(_map_title(title, f"{lat.policy.kind} policy", lat))
    return fig


def maps(
    source: Solution | Policy,
    x: int | str = 0,
    y: int | str = 1,
    *,
    show: Literal["action", "index"] = "action",
    component: int = 0,
    kind: Literal["greedy", "interpolated"] = "greedy",
    at: npt.ArrayLike | None = None,
    bounds: npt.ArrayLike | None = None,
    resolution: int = 101,
    title: str | None = None,
) -> Figure:
    """`value_map` and `policy_map` side by side, as ``fuzzyq rollout --maps`` draws them.

    Args:
        source: a `fuzzyq.Solution` (its policy of `kind`), or a `fuzzyq.Policy` (with
            `bounds`).
        x: the state variable on the horizontal axis: its index or its name (see `value_map`).
        y: the state variable on the vertical axis, likewise.
        show: the policy panel's ``"action"`` or ``"index"`` (see `policy_map`).
        component: with ``show="action"``, which value of the joint action vector.
        kind: the policy of a Solution: ``"greedy"`` or ``"interpolated"``.
        at: the full state the other variables are held at (see `value_map`).
        bounds: the ranges drawn, ``((x_lo, x_hi), (y_lo, y_hi))`` (see `value_map`).
        resolution: samples per axis, at least 2.
        title: the figure's title; default: the environment, and the values of the others.

    Returns:
        The figure: the value panel (left) and the policy panel (right), each with its colour
        bar.

    Raises:
        InputTypeError: `source` is not a Solution or Policy, or an argument of the wrong type.
        InputError: `x`, `y` or `component` out of range, `x` and `y` unknown or equal; `at`
            or `bounds` of the wrong shape or non-finite.
        ConfigError: an unknown `show` or `kind`, ``show="index"`` for an interpolated policy,
            `resolution` below 2, or no `bounds` for a Policy.
    """
    lat = _lattice(source, x, y, at, bounds, resolution, kind)
    fig = Figure(figsize=(12.4, 5.4), layout="constrained")
    left, right = fig.subplots(1, 2)
    _draw_value(fig, left, lat)
    _draw_policy(fig, right, lat, show, component)
    default = f"value function and {lat.policy.kind} policy"
    fig.suptitle(_map_title(title, default, lat))
    return fig


# Rollouts.


@dataclass(frozen=True)
class _Run:
    """A checked trajectory."""

    states: _Floats  # (K + 1, E)
    actions: _Floats  # (K, A)
    rewards: _Floats | None  # (K,)
    times: _Floats  # (K + 1,): the times, or the step numbers
    timed: bool  # whether `times` are times (s)
    headings: _Floats | None  # (K + 1, n): the robots' headings from their poses
    title: str


def _run(trajectory: Any, env: str | None, kind: str | None) -> _Run:
    if not isinstance(trajectory, Mapping):
        raise InputTypeError(
            f"trajectory: expected the dict of Policy.rollout or fuzzyq.rollout, "
            f"got {_type_name(trajectory)}"
        )
    for key in ("states", "actions"):
        if key not in trajectory:
            raise InputError(f"trajectory: no {key!r} (expected the dict of a rollout)")
    states = _floats("trajectory['states']", trajectory["states"], 2)
    k = len(states) - 1
    if k < 1:
        raise InputError("trajectory['states']: a rollout of no steps; nothing to draw")
    actions = _floats("trajectory['actions']", trajectory["actions"], 2)
    if len(actions) != k:
        got = len(actions)
        raise InputError(f"trajectory['actions']: expected {k} rows (one a step), got {got}")
    rewards = _optional(trajectory, "rewards", (k,))
    times = _optional(trajectory, "times", (k + 1,))
    poses = _optional(trajectory, "poses", None)
    headings = None
    if poses is not None:
        if poses.ndim != 3 or len(poses) != k + 1 or poses.shape[2] != 3:
            shape = f"({k + 1}, n, 3)"
            raise InputError(f"trajectory['poses']: expected shape {shape}, got {poses.shape}")
        headings = poses[:, :, 2]
    title = _rollout_title(env, trajectory.get("metrics"), times, kind)
    timed = times is not None
    axis = np.arange(k + 1, dtype=np.float64) if times is None else times
    return _Run(states, actions, rewards, axis, timed, headings, title)


def _optional(
    trajectory: Mapping[str, Any], key: str, shape: tuple[int, ...] | None
) -> _Floats | None:
    if key not in trajectory or trajectory[key] is None:
        return None
    array = _floats(f"trajectory[{key!r}]", trajectory[key])
    if shape is not None and array.shape != shape:
        raise InputError(f"trajectory[{key!r}]: expected shape {shape}, got {array.shape}")
    return array


def _rollout_title(env: str | None, metrics: Any, times: _Floats | None, kind: str | None) -> str:
    details = []
    if isinstance(metrics, Mapping) and isinstance(metrics.get("policy_kind"), str):
        kind = metrics["policy_kind"]
    if kind is not None:
        details.append(f"{kind} policy")
    if times is not None:
        details.append(f"T = {times[1] - times[0]:.3g} s")
    head = f"{env} rollout" if env else "rollout"
    return f"{head} ({', '.join(details)})" if details else head


def _check_paths(paths: Any, width: int) -> list[tuple[int, int]]:
    """`paths` as pairs of state indices."""
    try:
        pairs = [(a, b) for a, b in paths]
    except (TypeError, ValueError):
        raise InputTypeError(
            f"paths: expected pairs of state indices, got {_type_name(paths)}"
        ) from None
    for a, b in pairs:
        for v in (a, b):
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise InputTypeError(f"paths: expected integer indices, got {_type_name(v)}")
            if not 0 <= v < width:
                raise InputError(f"paths: index {v} out of range for {width} state variables")
    if not pairs:
        raise InputError("paths: no pairs of state indices")
    return [(int(a), int(b)) for a, b in pairs]


def _time_axis(ax: Axes, run: _Run, title: str, ylabel: str) -> None:
    ax.set(title=title, xlabel="time (s)" if run.timed else "step", ylabel=ylabel)
    ax.set_xlim(run.times[0], run.times[-1])
    ax.grid(alpha=0.3)


def _draw_paths(ax: Axes, run: _Run, pairs: list[tuple[int, int]], labels: list[str]) -> None:
    """The paths in the plane: one line per pair of state indices, the start as a triangle."""
    ax.plot([0.0], [0.0], "kx", markersize=10, markeredgewidth=2, label="origin (goal)")
    for i, (a, b) in enumerate(pairs):
        colour = _COLOURS[i % len(_COLOURS)]
        sx, sy = run.states[:, a], run.states[:, b]
        ax.plot(sx, sy, "-o", color=colour, linewidth=2, markersize=3, label=f"agent {i + 1}")
        ax.plot(sx[:1], sy[:1], "^", color=colour, markersize=10)
    ax.set(title="Paths in the plane", xlabel=labels[0], ylabel=labels[1])
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")


def _agent_figure(run: _Run, env: str, paths: list[tuple[int, int]] | None) -> Figure:
    """Point masses and robots: per agent its states (top) and actions (bottom); the paths."""
    n = run.states.shape[1] // 4
    if n == 0 or run.states.shape[1] != 4 * n or run.actions.shape[1] != 2 * n:
        raise InputError(
            f"trajectory: {env} needs 4 states and 2 actions per agent, "
            f"got {run.states.shape[1]} and {run.actions.shape[1]}"
        )
    if run.headings is not None and run.headings.shape[1] != n:
        raise InputError(f"trajectory['poses']: {run.headings.shape[1]} robots, the states {n}")
    fig = Figure(figsize=(5.2 * n + 6.0, 8.0), layout="constrained")
    grid = fig.add_gridspec(2, n + 1, width_ratios=[1.0] * n + [1.2])
    states, actions = _ROLLOUT_STATES[env], _ACTIONS[env]
    moves = "forces" if env == "pointmass" else "wheel speeds"
    for i in range(n):
        top = fig.add_subplot(grid[0, i])
        for j, (_, label) in enumerate(states):
            top.plot(run.times, run.states[:, 4 * i + j], color=_COLOURS[j], lw=2, label=label)
        if run.headings is not None:
            top.plot(run.times, run.headings[:, i], color=_PURPLE, lw=2, label="heading (rad)")
        _time_axis(top, run, f"Agent {i + 1}: states", "m, m/s")
        top.legend(loc="best")
        bottom = fig.add_subplot(grid[1, i])
        for j, (_, label) in enumerate(actions):
            u = run.actions[:, 2 * i + j]
            bottom.stairs(u, run.times, baseline=None, color=_COLOURS[j], lw=2, label=label)
        _time_axis(bottom, run, f"Agent {i + 1}: {moves}", "N" if env == "pointmass" else "m/s")
        bottom.legend(loc="best")
    pairs = paths if paths is not None else [(4 * i, 4 * i + 1) for i in range(n)]
    labels = [states[pairs[0][0] % 4][1], states[pairs[0][1] % 4][1]]
    _draw_paths(fig.add_subplot(grid[:, n]), run, pairs, labels)
    fig.suptitle(run.title)
    return fig


def _labels(name: str, given: Sequence[str] | None, default: list[str]) -> list[str]:
    if given is None:
        return default
    if isinstance(given, str) or not all(isinstance(g, str) for g in given):
        raise InputTypeError(f"{name}: expected a sequence of strings, got {_type_name(given)}")
    if len(given) != len(default):
        raise InputError(f"{name}: expected {len(default)} labels, got {len(given)}")
    return list(given)


def _series_figure(
    run: _Run,
    env: str | None,
    paths: list[tuple[int, int]] | None,
    labels: tuple[Sequence[str] | None, Sequence[str] | None],
) -> Figure:
    """Classic benchmarks and own systems: a panel per state variable, per action value, the
    reward, and the paths when asked for."""
    width, actions = run.states.shape[1], run.actions.shape[1]
    xs = _variables(_ROLLOUT_STATES.get(env or ""), 1, False, width, "x")[1]
    us = _variables(_ACTIONS.get(env or ""), 1, False, actions, "u")[1]
    xs, us = _labels("state_labels", labels[0], xs), _labels("action_labels", labels[1], us)
    panels = width + actions + (run.rewards is not None) + (paths is not None)
    rows = math.ceil(panels / 2)
    fig = Figure(figsize=(12.0, 3.4 * rows + 0.6), layout="constrained")
    axes = list(fig.subplots(rows, 2, squeeze=False).flat)
    for j, label in enumerate(xs):
        axes[j].plot(run.times, run.states[:, j], color=_COLOURS[j % 4], lw=2)
        _time_axis(axes[j], run, label, label)
    for j, label in enumerate(us):
        ax = axes[width + j]
        ax.stairs(run.actions[:, j], run.times, baseline=None, color=_COLOURS[(j + 2) % 4], lw=2)
        _time_axis(ax, run, label, label)
    if run.rewards is not None:
        ax = axes[width + actions]
        ax.stairs(run.rewards, run.times, baseline=None, color=_PURPLE, lw=2)
        _time_axis(ax, run, "reward", "reward")
    if paths is not None:
        _draw_paths(axes[panels - 1], run, paths, [xs[paths[0][0]], xs[paths[0][1]]])
    for ax in axes[panels:]:
        fig.delaxes(ax)
    fig.suptitle(run.title)
    return fig


def rollout(
    trajectory: Mapping[str, Any],
    env: str | Policy | Solution | PointMass | Khepera | ClassicModel | None = None,
    *,
    paths: Sequence[tuple[int, int]] | None = None,
    state_labels: Sequence[str] | None = None,
    action_labels: Sequence[str] | None = None,
    title: str | None = None,
) -> Figure:
    """A rollout: the states and the actions over time, and the paths in the plane.

    For the point masses and the robots (`env` names them; a trajectory with ``poses`` is the
    robots'), the figure of ``fuzzyq rollout --plot``, the paper's figures 2-4: per agent
    (columns) its states ``s_x, s_y, v_x, v_y`` (and a robot's heading) over time (top) and its
    actions, held over each sample time (bottom); right, every agent's path from its start (a
    triangle) with the goal at the origin. For anything else (the classic benchmarks, a system
    of your own) one panel per state variable, per action value and the reward; and, with
    `paths`, the paths in the plane.

    Args:
        trajectory: the dict of `fuzzyq.Policy.rollout` or `fuzzyq.rollout`: ``states``
            ``(K + 1, E)`` and ``actions`` ``(K, A)``; ``rewards`` ``(K,)``, ``times``
            ``(K + 1,)`` (otherwise the x axis counts steps), the robots' ``poses``
            ``(K + 1, n, 3)`` and ``metrics`` are used when present.
        env: the environment, for the layout and the labels: its name (``"pointmass"``,
            ``"khepera"``, ``"dcmotor"``, ``"pendulum"``, ``"carhill"``, ``"arm"``), the
            policy, solution or model; None: the robots' if there are ``poses``, else a
            system of your own.
        paths: pairs of state indices ``(i_x, i_y)``, one path each; default: each point
            mass's or robot's position, no paths for the others.
        state_labels: labels of the state variables (the one-panel-per-variable layout);
            default: the environment's, or ``x1``, ``x2``, ...
        action_labels: labels of the action values, likewise (``u1``, ``u2``, ...).
        title: the figure's title; default: the environment, the policy kind and the sample
            time.

    Returns:
        The figure: ``2 * n + 1`` panels for `n` point masses or robots; otherwise one per
        state variable, per action value, the reward and the paths (with `paths`).

    Raises:
        InputTypeError: `trajectory` is not a mapping, or an argument of the wrong type.
        InputError: arrays missing, of inconsistent shapes or non-finite; `paths` out of
            range; labels of the wrong number.
        ConfigError: an unknown environment name.
    """
    name = _env_name(env)
    if name is None and isinstance(trajectory, Mapping) and "poses" in trajectory:
        name = "khepera"
    run = _run(trajectory, name, env.kind if isinstance(env, Policy) else None)
    if title is not None:
        run = replace(run, title=title)
    pairs = None if paths is None else _check_paths(paths, run.states.shape[1])
    if name is not None and name in _AGENTS:
        return _agent_figure(run, name, pairs)
    return _series_figure(run, name, pairs, (state_labels, action_labels))


# Learning and sample-efficiency curves.


def _column(name: str, values: Any) -> _Floats:
    """Numbers from a CSV field list or a mapping's values: empty fields and None are NaN."""
    if isinstance(values, (str, bytes)) or not isinstance(values, (Sequence, np.ndarray)):
        raise InputTypeError(f"{name}: expected a sequence of numbers, got {_type_name(values)}")
    out = np.empty(len(values))
    for k, v in enumerate(values):
        if v is None or (isinstance(v, str) and not v.strip()):
            out[k] = np.nan
        elif isinstance(v, (str, int, float, np.integer, np.floating)) and not isinstance(v, bool):
            try:
                out[k] = float(v)
            except ValueError:
                raise InputError(f"{name}: row {k}: {v!r} is not a number") from None
        else:
            raise InputTypeError(f"{name}: row {k}: expected a number, got {_type_name(v)}")
    return out


def _read_csv(
    name: str, path: str | os.PathLike[str], columns: Sequence[str]
) -> dict[str, list[str]]:
    """The named columns of the CSV file at `path`, as strings."""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        header = reader.fieldnames or []
        missing = [c for c in columns if c not in header]
        if missing:
            raise InputError(f"{name}: {os.fspath(path)} has no column {missing[0]!r}")
        rows = list(reader)
    return {c: [row[c] or "" for row in rows] for c in columns}


def _table(name: str, data: Any, columns: Sequence[str]) -> dict[str, Any]:
    """The named columns of a CSV file, a mapping of columns, or a sequence of row mappings."""
    if isinstance(data, (str, os.PathLike)):
        return _read_csv(name, data, columns)
    if isinstance(data, Mapping):
        source: Mapping[str, Any] = data
    elif isinstance(data, Sequence) and all(isinstance(r, Mapping) for r in data):
        source = {c: [r.get(c) for r in data] for c in columns if all(c in r for r in data)}
    else:
        raise InputTypeError(
            f"{name}: expected a CSV file's path, a mapping of columns or a list of rows, "
            f"got {_type_name(data)}"
        )
    missing = [c for c in columns if c not in source]
    if missing:
        raise InputError(f"{name}: no column {missing[0]!r}")
    return {c: source[c] for c in columns}


def _numeric(name: str, table: Mapping[str, Any], columns: Sequence[str]) -> dict[str, _Floats]:
    out = {c: _column(f"{name}[{c!r}]", table[c]) for c in columns}
    lengths = {c: len(v) for c, v in out.items()}
    first = columns[0]
    for c, n in lengths.items():
        if n != lengths[first]:
            raise InputError(f"{name}: column {c!r} has {n} rows, {first!r} {lengths[first]}")
    if lengths[first] == 0:
        raise InputError(f"{name}: no rows")
    return out


def _moving_average(values: _Floats, window: int) -> _Floats:
    """The trailing mean of the last `window` values (fewer at the start)."""
    sums = np.cumsum(np.concatenate([[0.0], values]))
    k = np.arange(1, len(values) + 1)
    lo = np.maximum(k - window, 0)
    mean: _Floats = (sums[k] - sums[lo]) / (k - lo)
    return mean


def _note(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", color="0.45")


def _trend(
    ax: Axes,
    episodes: _Floats,
    values: _Floats,
    colour: str,
    window: int,
    extra: tuple[str, _Floats] | None = None,
) -> None:
    """A noisy series (thin) with its moving average (bold) and optional points (black)."""
    keep = np.isfinite(values)
    if not keep.any():
        _note(ax, "no finite values")
        return
    e, v = episodes[keep], values[keep]
    ax.plot(e, v, color=colour, alpha=0.35, lw=1, label="per episode")
    ax.plot(e, _moving_average(v, window), color=colour, lw=2, label=f"moving average ({window})")
    if extra is not None and np.isfinite(extra[1]).any():
        shown = np.isfinite(extra[1])
        ax.plot(episodes[shown], extra[1][shown], "-o", color="k", lw=1, ms=4, label=extra[0])
    ax.legend(loc="best")


def _schedules(ax: Axes, episodes: _Floats, epsilon: _Floats, alpha: _Floats) -> None:
    """The exploration rate and the step size."""
    for values, colour, label in ((epsilon, _COLOURS[3], "epsilon (exploration)"),
                                  (alpha, _PURPLE, "alpha (step size)")):
        keep = np.isfinite(values)
        ax.plot(episodes[keep], values[keep], color=colour, lw=2, label=label)
    ax.legend(loc="best")


def _success(ax: Axes, episodes: _Floats, rates: _Floats) -> None:
    """The greedy evaluations' success rate, where an evaluation ran."""
    keep = np.isfinite(rates)
    ax.plot(episodes[keep], rates[keep], "-o", color=_GOOD, lw=2, ms=5)
    ax.set_ylim(-0.05, 1.05)
    if not keep.any():
        _note(ax, "no evaluation ran")


def _param_change(ax: Axes, episodes: _Floats, changes: _Floats) -> None:
    """The windowed parameter change on a log scale; zeros on a floor below the rest."""
    keep = np.isfinite(changes)
    e, c = episodes[keep], changes[keep]
    ax.set(title="Parameter change over the window", ylabel="max |phi - phi window ago|")
    if not len(c):
        _note(ax, "no full window yet")
        return
    positive = c > 0
    if not positive.any():
        ax.plot(e, c, color=_COLOURS[0], lw=2)
        return
    floor = c[positive].min() / 3
    ax.set_yscale("log")
    ax.set_title("Parameter change over the window (log scale)")
    ax.plot(e, np.where(positive, c, floor), color=_COLOURS[0], lw=2, label="per episode")
    if not positive.all():
        ax.plot(e[~positive], np.full((~positive).sum(), floor), "o", mfc="none",
                color=_COLOURS[0], label="zero (drawn at the floor)")
        ax.legend(loc="upper right")


def learning_curve(
    curve: str | os.PathLike[str] | Mapping[str, Any],
    *,
    window: int = MOVING_AVERAGE_WINDOW,
    title: str | None = None,
) -> Figure:
    """The learning curve of fuzzy Q-learning, as ``fuzzyq train --learner fql`` draws it.

    Six panels over the episodes: the return per episode with its moving average and the
    greedy evaluations' mean return; the mean |TD error|; the steps per episode; the
    exploration rate epsilon and the step size alpha; the greedy evaluations' success rate;
    the parameter change over the window (log scale; zeros drawn on a floor below the rest).
    Missing values (empty fields, None, NaN) are left out.

    Args:
        curve: the path of the CSV file of ``fuzzyq train --learner fql --curve FILE.csv``
            (header ``episode,steps,return,discounted_return,mean_abs_td,max_abs_td,epsilon,
            alpha,param_change,terminal,eval_mean_return,eval_success_rate``), or a mapping
            from those column names to sequences (``episode``, ``steps``, ``return``,
            ``mean_abs_td``, ``epsilon``, ``alpha``, ``param_change``, ``eval_mean_return``
            and ``eval_success_rate`` are drawn).
        window: episodes in the moving averages, at least 1.
        title: the figure's title.

    Returns:
        The figure: six panels (two rows of three).

    Raises:
        InputTypeError: `curve` is not a path or mapping, or a column holds non-numbers.
        InputError: a column missing, of another length than the others, or empty; a field
            that is not a number.
        ConfigError: `window` below 1.
        OSError: the file cannot be read.
    """
    window = _count("window", window, 1)
    c = _numeric("curve", _table("curve", curve, _LEARNING_COLUMNS), _LEARNING_COLUMNS)
    ep = c["episode"]
    fig = Figure(figsize=(16.0, 8.5), layout="constrained")
    axes = list(fig.subplots(2, 3, sharex=True).flat)
    evals = ("greedy evaluation (mean)", c["eval_mean_return"])
    _trend(axes[0], ep, c["return"], _COLOURS[0], window, evals)
    _trend(axes[1], ep, c["mean_abs_td"], _COLOURS[1], window)
    _trend(axes[2], ep, c["steps"], _COLOURS[2], window)
    _schedules(axes[3], ep, c["epsilon"], c["alpha"])
    _success(axes[4], ep, c["eval_success_rate"])
    _param_change(axes[5], ep, c["param_change"])
    for ax, (caption, ylabel) in zip(axes, _LEARNING_PANELS):
        ax.set(title=caption, ylabel=ylabel)
    for k, ax in enumerate(axes):
        ax.grid(alpha=0.3)
        ax.set_xlabel("episode" if k >= 3 else "")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    fig.suptitle(title or "Fuzzy Q-learning: learning curve")
    return fig


def _reference(reference: Any) -> tuple[str, float] | None:
    """`reference` as ``(name, success rate)``."""
    if reference is None:
        return None
    if isinstance(reference, tuple) and len(reference) == 2 and isinstance(reference[0], str):
        name, rate = reference
    else:
        name, rate = "reference", reference
    if isinstance(rate, bool) or not isinstance(rate, (int, float, np.integer, np.floating)):
        raise InputTypeError(
            f"reference: expected a success rate or (name, rate), got {_type_name(reference)}"
        )
    if not math.isfinite(rate):
        raise ConfigError(f"reference: expected a finite success rate, got {rate}")
    return name, float(rate)


def _learner_order(learners: Sequence[str]) -> list[str]:
    """The learners present: the command line's order first, then others as they come."""
    known = [name for name in _LEARNERS if name in learners]
    return known + [name for name in dict.fromkeys(learners) if name not in _LEARNERS]


def efficiency_curve(
    points: str | os.PathLike[str] | Mapping[str, Any] | Sequence[Mapping[str, Any]],
    reference: float | tuple[str, float] | None = None,
    *,
    title: str | None = None,
) -> Figure:
    """The sample-efficiency curve of ``fuzzyq compare --curve``: success over the random
    starts against the transitions each learner learned from.

    One line per learner (each drawn thinner than the one before, so that lines that coincide
    stay visible), transitions on a log scale, and `reference` (such as fuzzy Q-iteration on
    the true model) as a dashed line.

    Args:
        points: the path of ``efficiency.csv`` (header ``learner,transitions,success_rate,
            mean_final_error_cm,train_seconds,failure``), a mapping from column names to
            sequences, or a sequence of rows (mappings, such as ``efficiency.json``'s); the
            columns ``learner``, ``transitions`` and ``success_rate`` are drawn.
        reference: a success rate drawn as a dashed line, or ``(name, rate)`` to label it.
        title: the figure's title.

    Returns:
        The figure: one panel.

    Raises:
        InputTypeError: `points` is not a path, mapping or sequence of rows, or a column or
            `reference` holds non-numbers.
        InputError: a column missing, of another length than the others, or empty;
            transitions not positive; a field that is not a number.
        ConfigError: a non-finite `reference`.
        OSError: the file cannot be read.
    """
    ref = _reference(reference)
    table = _table("points", points, ("learner", "transitions", "success_rate"))
    learners = table["learner"]
    if isinstance(learners, (str, bytes)) or not all(isinstance(v, str) for v in learners):
        raise InputTypeError("points['learner']: expected a sequence of learner names")
    c = _numeric("points", table, ("transitions", "success_rate"))
    if len(learners) != len(c["transitions"]):
        rows = f"{len(learners)} rows, 'transitions' {len(c['transitions'])}"
        raise InputError(f"points: column 'learner' has {rows}")
    if not np.all(c["transitions"] > 0):
        raise InputError("points['transitions']: expected positive numbers (a log scale)")
    names = np.asarray(learners, dtype=object)
    fig = Figure(figsize=(10.0, 6.4), layout="constrained")
    ax = fig.add_subplot()
    if ref is not None:
        ax.axhline(ref[1], color="0.4", lw=2, ls="--", label=ref[0])
    for k, learner in enumerate(_learner_order(list(learners))):
        rows = names == learner
        order = np.argsort(c["transitions"][rows], kind="stable")
        known = _LEARNERS.index(learner) if learner in _LEARNERS else len(_LEARNERS) + k
        colour = _LEARNER_COLOURS[known % len(_LEARNER_COLOURS)]
        width = max(7 - 2 * k, 2)
        x, y = c["transitions"][rows][order], c["success_rate"][rows][order]
        ax.plot(x, y, "-o", color=colour, lw=width, ms=width + 3, label=learner)
    ax.set_xscale("log")
    ax.set(xlabel="transitions of interaction", ylabel="success over the random starts")
    ax.set_ylim(-0.05, 1.05)
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="best")
    fig.suptitle(title or "Success against transitions of interaction")
    return fig
