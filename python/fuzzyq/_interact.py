"""Learning and evaluation for a system of your own: a `CallableModel` (its function as the
simulator) or any Gymnasium environment, known to the learner only through its transitions.

The loops here only move arrays between the system and fuzzyq: the estimator of the
transition tables and rewards (`fuzzyq.solve(task, grid, transitions=...)`) and the solver
are the Rust ones `fuzzyq train --learner learned-model` uses.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from fuzzyq._fuzzyq import (
    CallableModel,
    ClassicModel,
    ConfigError,
    Grid,
    InputError,
    InputTypeError,
    PointMass,
    Policy,
    Solution,
    Task,
)
from fuzzyq._fuzzyq import collect as _collect_builtin
from fuzzyq._fuzzyq import solve as _solve

Starts = npt.ArrayLike | Callable[[np.random.Generator], npt.ArrayLike] | None
"""Where episodes of a `CallableModel` start: an array of start states (episode ``i`` starts
at row ``i`` modulo their number), a function ``start(rng) -> state``, or None (uniform within
the task's state bounds)."""

ROUND_SEED_STRIDE = 1_000_003
"""Round ``k`` of `learn` seeds its collection with ``seed + k * ROUND_SEED_STRIDE``."""


class _Episodes(Protocol):
    """A system stepped one transition at a time."""

    n_actions: list[int]
    """Each agent's number of actions."""

    def vector(self, joint: int) -> npt.NDArray[np.float64]:
        """The joint action vector of joint action `joint`."""

    def reset(self, episode: int) -> npt.NDArray[np.float64]:
        """The start state of episode `episode`."""

    def step(
        self, x: npt.NDArray[np.float64], action: int | npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], float, bool, bool, bool | None]:
        """``(next_state, reward, terminated, truncated, success)`` under a joint action index
        or a joint action vector: terminated at an absorbing state, truncated where the
        system cut the episode (a time limit); success is None where undefined."""


def _joint_of(indices: Sequence[int], n_actions: Sequence[int]) -> int:
    """The joint index of per-agent action indices (agent 0 most significant)."""
    j = 0
    for i, m in zip(indices, n_actions):
        j = j * m + int(i)
    return j


class _CallableEpisodes:
    """A `CallableModel` as the simulator: its function steps one transition at a time."""

    def __init__(
        self,
        model: CallableModel,
        task: Task | None,
        starts: Starts,
        rng: np.random.Generator,
    ) -> None:
        self.model = model
        self.n_actions = [len(a) for a in model.actions]
        self.vectors = np.array(
            [model.joint_action(j) for j in range(model.n_joint_actions)], dtype=np.float64
        )
        self.rng = rng
        self.start = _start_function(model.state_dim, task, starts)

    def vector(self, joint: int) -> npt.NDArray[np.float64]:
        return np.asarray(self.vectors[joint], dtype=np.float64)

    def reset(self, episode: int) -> npt.NDArray[np.float64]:
        return self.start(episode, self.rng)

    def step(
        self, x: npt.NDArray[np.float64], action: int | npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], float, bool, bool, bool | None]:
        u = self.vectors[action] if isinstance(action, int) else action
        nx, r, terminal = self.model.step(x, u)
        return np.asarray(nx, dtype=np.float64), float(r), bool(terminal), False, None


def _start_function(
    state_dim: int, task: Task | None, starts: Starts
) -> Callable[[int, np.random.Generator], npt.NDArray[np.float64]]:
    """Episode `i`'s start, as `Starts` describes it."""
    if callable(starts):
        f = starts
        return lambda _i, rng: _state(f(rng), state_dim, "starts(rng)")
    if starts is not None:
        rows = np.atleast_2d(np.asarray(starts, dtype=np.float64))
        if rows.ndim != 2 or rows.shape[1] != state_dim or len(rows) == 0:
            raise InputError(f"starts: expected states of shape (n, {state_dim}), got {rows.shape}")
        if not np.isfinite(rows).all():
            raise InputError("starts: every value must be finite")
        return lambda i, _rng: rows[i % len(rows)].copy()
    if task is None:
        raise ConfigError(
            "starts: a CallableModel's episodes need starts (states or a function) or a task "
            "(uniform starts within its state bounds)"
        )
    bounds = task.state_bounds
    return lambda _i, rng: rng.uniform(bounds[:, 0], bounds[:, 1])


def _state(x: npt.ArrayLike, state_dim: int, what: str) -> npt.NDArray[np.float64]:
    v = np.asarray(x, dtype=np.float64).ravel()
    if v.shape != (state_dim,) or not np.isfinite(v).all():
        raise InputError(f"{what}: expected {state_dim} finite values, got {np.shape(x)}")
    return v


class _GymEpisodes:
    """A Gymnasium environment: its observation is the state, episode `i` starts from
    ``env.reset(seed=seed + i)``, and its action is the joint action as its action space
    takes it (an index for `Discrete`, per-agent indices for `MultiDiscrete`, the joint
    action vector for `Box`)."""

    def __init__(self, env: Any, task: Task, seed: int) -> None:
        from gymnasium import spaces

        self.env = env
        self.task = task
        self.seed = seed
        self.vectors = np.asarray(task.joint_actions)
        self.n_actions = [len(a) for a in task.actions]
        space = env.action_space
        self.space = space
        m = len(self.vectors)
        if isinstance(space, spaces.Discrete):
            if int(space.n) != m:
                raise ConfigError(
                    f"task: the environment has Discrete({space.n}) actions, the task {m} joint "
                    "actions"
                )
            self.action: Callable[[int], Any] = lambda j: j
        elif isinstance(space, spaces.MultiDiscrete):
            if list(np.ravel(space.nvec)) != self.n_actions:
                raise ConfigError(
                    f"task: the environment has MultiDiscrete({list(np.ravel(space.nvec))}) "
                    f"actions, the task's agents have {self.n_actions}"
                )
            self.action = lambda j: np.array(self._indices(j), dtype=space.dtype)
        elif isinstance(space, spaces.Box):
            if int(np.prod(space.shape)) != task.action_dim:
                raise ConfigError(
                    f"task: the environment's Box actions have shape {space.shape}, the task's "
                    f"joint action vector {task.action_dim} values"
                )
            self.action = lambda j: self.vectors[j].astype(space.dtype).reshape(space.shape)
        else:
            raise InputTypeError(
                f"source: a Gymnasium environment with Discrete, MultiDiscrete or Box actions, "
                f"got {type(space).__name__}"
            )

    def _indices(self, j: int) -> list[int]:
        out = []
        for m in reversed(self.n_actions):
            out.append(j % m)
            j //= m
        return out[::-1]

    def vector(self, joint: int) -> npt.NDArray[np.float64]:
        return np.asarray(self.vectors[joint], dtype=np.float64)

    def reset(self, episode: int) -> npt.NDArray[np.float64]:
        obs, _ = self.env.reset(seed=self.seed + episode)
        return _state(obs, self.task.state_dim, "observation")

    def step(
        self, x: npt.NDArray[np.float64], action: int | npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], float, bool, bool, bool | None]:
        from gymnasium import spaces

        if isinstance(action, int):
            act = self.action(action)
        elif isinstance(self.space, spaces.Box):
            act = action.astype(self.space.dtype).reshape(self.space.shape)
        else:
            raise ConfigError(
                "policy: an interpolated policy acts with joint action vectors; this "
                f"environment takes {type(self.space).__name__} actions (use the greedy policy)"
            )
        obs, r, terminated, truncated, info = self.env.step(act)
        success = info.get("is_success") if isinstance(info, Mapping) else None
        return (
            _state(obs, self.task.state_dim, "observation"),
            float(r),
            bool(terminated),
            bool(truncated),
            None if success is None else bool(success),
        )


def _check_count(what: str, value: Any, none_ok: bool = False) -> None:
    """A one-line error unless `value` is a positive integer (or None where allowed)."""
    if value is None and none_ok:
        return
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InputTypeError(f"{what}: expected a positive integer, got {value!r}")
    if value < 1:
        raise ConfigError(f"{what}: expected a positive integer, got {value!r}")


def _is_gym_env(source: Any) -> bool:
    return hasattr(source, "action_space") and hasattr(source, "reset") and hasattr(source, "step")


def _episodes(
    source: Any, task: Task | None, starts: Starts, seed: int, rng: np.random.Generator
) -> _Episodes:
    if isinstance(source, CallableModel):
        return _CallableEpisodes(source, task, starts, rng)
    if _is_gym_env(source):
        if task is None:
            raise ConfigError(
                "task: a Gymnasium environment needs a fuzzyq.Task declaring its state bounds "
                "and actions"
            )
        if starts is not None:
            raise ConfigError("starts: a Gymnasium environment starts from its own resets")
        return _GymEpisodes(source, task, seed)
    raise InputTypeError(
        "source: expected a fuzzyq.CallableModel, a Gymnasium environment, or (collect only) "
        f"a built-in model, got {type(source).__name__}"
    )


def collect(
    source: Any,
    samples: int,
    *,
    task: Task | None = None,
    seed: int = 0,
    episode_steps: int | None = None,
    starts: Starts = None,
    policy: Policy | None = None,
    epsilon: float = 0.1,
) -> dict[str, npt.NDArray[np.float64]]:
    """Collects transitions by interacting with a system.

    Args:
        source: a built-in model (its plant, with random actions, as ``fuzzyq train
            --learner learned-model`` collects), a `CallableModel` (its function as the
            simulator), or a Gymnasium environment (its observation as the state; `Discrete`
            actions are joint action indices, `MultiDiscrete` per-agent indices, `Box` joint
            action vectors).
        samples: the number of transitions.
        task: the `Task` the transitions are for; required for a Gymnasium environment (its
            actions give the action vectors recorded) and for a `CallableModel` without
            `starts`.
        seed: the seed of the actions, the starts and the environment's resets (episode ``i``
            resets with ``seed + i``).
        episode_steps: steps per episode; None: until the episode ends (a Gymnasium
            environment), 50 for a model.
        starts: a `CallableModel`'s starts (see `Starts`).
        policy: explore epsilon-greedily with this policy's greedy actions (None: uniformly
            random actions).
        epsilon: with `policy`, each agent's probability per step of a random action.

    Returns:
        float64 arrays ``states`` ``(n, state_dim)``, ``actions`` ``(n, action_dim)``,
        ``next_states`` and ``rewards`` ``(n,)``, ready for
        ``solve(task, grid, transitions=...)``.
    """
    if isinstance(source, (PointMass, ClassicModel)):
        if policy is not None or task is not None or starts is not None:
            raise ConfigError(
                "policy, task, starts: a built-in model's plant is collected from its own "
                "random starts with random actions"
            )
        per_episode = 50 if episode_steps is None else episode_steps
        return _collect_builtin(source, samples, seed=seed, episode_steps=per_episode)
    _check_count("samples", samples)
    if not 0.0 <= float(epsilon) <= 1.0:
        raise ConfigError(f"epsilon: expected a probability in [0, 1], got {epsilon!r}")
    _check_count("episode_steps", episode_steps, none_ok=True)
    rng = np.random.default_rng(seed)
    src = _episodes(source, task, starts, seed, rng)
    steps = episode_steps if episode_steps is not None else (None if _is_gym_env(source) else 50)
    xs: list[npt.NDArray[np.float64]] = []
    us: list[npt.NDArray[np.float64]] = []
    nxs: list[npt.NDArray[np.float64]] = []
    rs: list[float] = []
    episode = 0
    while len(rs) < samples:
        x = src.reset(episode)
        t = 0
        while steps is None or t < steps:
            j = _choose(src, x, rng, policy, epsilon)
            nx, r, terminated, truncated, _ = src.step(x, j)
            xs.append(x)
            us.append(src.vector(j))
            nxs.append(nx)
            rs.append(r)
            t += 1
            if terminated or truncated or len(rs) >= samples:
                break
            x = nx
        episode += 1
    return {
        "states": np.array(xs, dtype=np.float64),
        "actions": np.array(us, dtype=np.float64),
        "next_states": np.array(nxs, dtype=np.float64),
        "rewards": np.array(rs, dtype=np.float64),
    }


def _choose(
    src: _Episodes,
    x: npt.NDArray[np.float64],
    rng: np.random.Generator,
    policy: Policy | None,
    epsilon: float,
) -> int:
    """The joint action at `x`: each agent's uniformly random action, or with `policy` its
    greedy one with probability ``1 - epsilon``."""
    greedy = policy.agent_actions(x) if policy is not None else None
    indices = []
    for i, m in enumerate(src.n_actions):
        if greedy is None or rng.random() < epsilon:
            indices.append(int(rng.integers(m)))
        else:
            indices.append(greedy[i])
    return _joint_of(indices, src.n_actions)


def concat(*parts: Mapping[str, npt.ArrayLike]) -> dict[str, npt.NDArray[np.float64]]:
    """Transitions of several collections as one (in order)."""
    keys = ("states", "actions", "next_states", "rewards")
    return {k: np.concatenate([np.asarray(p[k], dtype=np.float64) for p in parts]) for k in keys}


def learn(
    source: Any,
    task: Task,
    grid: Grid,
    *,
    samples: int,
    rounds: int = 1,
    epsilon: float = 0.1,
    seed: int = 0,
    episode_steps: int | None = None,
    starts: Starts = None,
    **solve_kwargs: Any,
) -> Solution:
    """Learns a system from interaction: collects `samples` transitions with random actions,
    learns the task's model from them and solves it; each further round collects `samples`
    more epsilon-greedily with the last solution's greedy policy, learns from everything
    collected and solves again (``fuzzyq train --rounds``).

    Args:
        source: a `CallableModel` or a Gymnasium environment (see `collect`).
        task: the system's declaration (state bounds, actions, blocks, reward).
        grid: the fuzzy grid to learn and solve on.
        samples: transitions per round.
        rounds: rounds of collection (at least 1).
        epsilon: each agent's probability of a random action per step after the first round.
        seed: the first round's seed; round ``k`` uses ``seed + k * ROUND_SEED_STRIDE``.
        episode_steps: steps per episode (see `collect`).
        starts: a `CallableModel`'s starts (see `Starts`).
        **solve_kwargs: `fuzzyq.solve`'s settings.

    Returns:
        The last round's solution; its ``fit`` reports the estimation.
    """
    _check_count("rounds", rounds)
    if not isinstance(task, Task):
        raise InputTypeError(f"task: expected a fuzzyq.Task, got {type(task).__name__}")
    common: dict[str, Any] = {"task": task, "episode_steps": episode_steps, "starts": starts}
    data = collect(source, samples, seed=seed, **common)
    solution = _solve(task, grid, transitions=data, **solve_kwargs)
    for k in range(1, rounds):
        more = collect(
            source,
            samples,
            seed=seed + k * ROUND_SEED_STRIDE,
            policy=solution.policy("greedy"),
            epsilon=epsilon,
            **common,
        )
        data = concat(data, more)
        solution = _solve(task, grid, transitions=data, **solve_kwargs)
    return solution


def rollout(
    policy: Policy,
    source: Any,
    x0: npt.ArrayLike | None = None,
    steps: int | None = None,
    *,
    task: Task | None = None,
    seed: int = 0,
) -> dict[str, Any]:
    """Runs `policy` on a system of your own: the greedy policy's joint actions, or the
    interpolated policy's action vectors (a `CallableModel`, or a Gymnasium environment with
    `Box` actions).

    Args:
        policy: a policy whose joint actions are the system's.
        source: a `CallableModel` (its function as the plant) or a Gymnasium environment.
        x0: a `CallableModel`'s start (a Gymnasium environment starts from
            ``env.reset(seed=seed)``).
        steps: the most steps; None: until the episode ends (a Gymnasium environment;
            required for a `CallableModel`).
        task: the `Task` for a Gymnasium environment (its actions).
        seed: the seed of the environment's reset.

    Returns:
        ``states`` ``(T + 1, state_dim)``, ``actions`` ``(T, action_dim)``, ``rewards``
        ``(T,)`` as numpy arrays; ``return`` (their sum, in step order), ``steps`` (``T``), ``done``
        (whether the episode ended) and ``success`` (the environment's last
        ``info["is_success"]``; None where it has none).
    """
    _check_count("steps", steps, none_ok=True)
    if isinstance(source, CallableModel):
        if x0 is None:
            raise ConfigError("x0: a CallableModel's rollout needs a start state")
        if steps is None:
            raise ConfigError("steps: a CallableModel's rollout needs a number of steps")
        starts: Starts = [_state(x0, source.state_dim, "x0")]
    else:
        if x0 is not None:
            raise ConfigError("x0: a Gymnasium environment starts from its own reset")
        starts = None
    src = _episodes(source, task, starts, seed, np.random.default_rng(seed))
    return _run(policy, src, 0, steps)


def _run(policy: Policy, src: _Episodes, episode: int, steps: int | None) -> dict[str, Any]:
    x = src.reset(episode)
    states = [x]
    actions: list[npt.NDArray[np.float64]] = []
    rewards: list[float] = []
    done, success, total = False, None, 0.0
    interpolated = policy.kind == "interpolated"
    while steps is None or len(rewards) < steps:
        # The greedy policy picks a joint action; the interpolated one (eq 22) a vector.
        u = np.asarray(policy.act(x), dtype=np.float64) if interpolated else None
        action: int | npt.NDArray[np.float64] = int(policy.act_index(x)) if u is None else u
        x, r, terminated, truncated, success = src.step(x, action)
        done = terminated or truncated
        states.append(x)
        actions.append(src.vector(action) if isinstance(action, int) else action)
        rewards.append(r)
        total += r  # in step order, as a plain loop adds them
        if done:
            break
    a = np.array(actions, dtype=np.float64).reshape(len(actions), -1)
    return {
        "states": np.array(states, dtype=np.float64),
        "actions": a,
        "rewards": np.array(rewards, dtype=np.float64),
        "return": total,
        "steps": len(rewards),
        "done": done,
        "success": success,
    }


def evaluate(
    policy: Policy,
    source: Any,
    *,
    count: int = 100,
    steps: int | None = None,
    seed: int = 0,
    starts: Starts = None,
    task: Task | None = None,
) -> dict[str, Any]:
    """Evaluates `policy` over `count` episodes of a system of your own.

    Episode ``i`` of a Gymnasium environment starts from ``env.reset(seed=seed + i)``; of a
    `CallableModel`, from `starts` (see `Starts`; uniform within the task's bounds, drawn with
    `seed`, when None).

    Returns:
        ``runs``: numpy columns ``return``, ``steps``, ``done`` and, where the environment
        reports it, ``success``; ``summary``: ``episodes``, ``mean_return``, ``std_return`` and
        ``success_rate`` (None without success reports).
    """
    _check_count("count", count)
    _check_count("steps", steps, none_ok=True)
    if isinstance(source, CallableModel) and steps is None:
        raise ConfigError("steps: a CallableModel's episodes need a number of steps")
    src = _episodes(source, task, starts, seed, np.random.default_rng(seed))
    runs = [_run(policy, src, i, steps) for i in range(count)]
    returns = np.array([r["return"] for r in runs])
    cols: dict[str, npt.NDArray[Any]] = {
        "return": returns,
        "steps": np.array([r["steps"] for r in runs], dtype=np.int64),
        "done": np.array([r["done"] for r in runs], dtype=bool),
    }
    reported = [r["success"] for r in runs]
    if all(s is not None for s in reported):
        cols["success"] = np.array(reported, dtype=bool)
    return {
        "runs": cols,
        "summary": {
            "episodes": count,
            "mean_return": float(returns.mean()),
            "std_return": float(returns.std()),
            "success_rate": float(cols["success"].mean()) if "success" in cols else None,
        },
    }
