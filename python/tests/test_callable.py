"""CallableModel: independent dynamics blocks, terminal states, single steps, the joint-action
order, and a NumPy reference of fuzzy Q-iteration."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

import fuzzyq

Array = npt.NDArray[np.float64]
LEVELS = [-1.0, 0.0, 1.0]


def agents_transition(x: Array, u: Array) -> tuple[Array, Array]:
    """Three double integrators on a line: agent i is (position, velocity) = x[:, 2i:2i+2],
    driven by u[:, i]; the reward penalises positions and forces."""
    nxt = np.empty_like(x)
    for i in range(x.shape[1] // 2):
        p, v = x[:, 2 * i], x[:, 2 * i + 1]
        nxt[:, 2 * i] = np.clip(p + 0.2 * v, -1, 1)
        nxt[:, 2 * i + 1] = np.clip(0.9 * v + 0.2 * u[:, i], -1, 1)
    reward = -np.sum(x[:, 0::2] ** 2, axis=1) - 0.05 * np.sum(u**2, axis=1)
    return nxt, reward


def agents_grid(agents: int, positions: int = 5, velocities: int = 3) -> fuzzyq.Grid:
    cores = []
    for _ in range(agents):
        cores += [np.linspace(-1, 1, positions), np.linspace(-1, 1, velocities)]
    return fuzzyq.Grid(cores)


def agents_model(agents: int, blocks: bool) -> fuzzyq.CallableModel:
    return fuzzyq.CallableModel(
        agents_transition,
        state_dim=2 * agents,
        actions=[LEVELS] * agents,
        blocks=[([2 * i, 2 * i + 1], [i]) for i in range(agents)] if blocks else None,
    )


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_a_block_declared_model_gives_the_v_of_the_same_model_without_blocks(
    precision: str,
) -> None:
    grid = agents_grid(3)
    xi = 1e-6 if precision == "float64" else 1e-3
    settings = dict(gamma=0.9, xi=xi, precision=precision, max_sweeps=400)
    plain = fuzzyq.solve(agents_model(3, blocks=False), grid, **settings)  # type: ignore[arg-type]
    blocked = fuzzyq.solve(agents_model(3, blocks=True), grid, **settings)  # type: ignore[arg-type]
    assert plain.kernel == "generic"
    assert blocked.kernel != "generic"  # the block backup ran
    assert blocked.converged and plain.converged
    tol = 1e-9 if precision == "float64" else 2e-4
    np.testing.assert_allclose(blocked.V, plain.V, rtol=tol, atol=tol)
    # The greedy actions agree wherever the best action is not a near tie.
    assert np.mean(blocked.greedy == plain.greedy) > 0.99
    x = np.array([0.3, -0.2, -0.5, 0.1, 0.8, 0.0])
    assert blocked.policy("greedy").act_index(x) == plain.policy("greedy").act_index(x)


def test_blocks_that_do_not_hold_are_refused_naming_the_variable() -> None:
    def coupled(x: Array, u: Array) -> tuple[Array, Array]:
        nxt, r = agents_transition(x, u)
        nxt[:, 0] = np.clip(nxt[:, 0] + 0.1 * x[:, 2], -1, 1)  # agent 0 sees agent 1
        return nxt, r

    model = fuzzyq.CallableModel(
        coupled,
        state_dim=4,
        actions=[LEVELS] * 2,
        blocks=[([0, 1], [0]), ([2, 3], [1])],
    )
    with pytest.raises(fuzzyq.ConfigError, match="blocks: state variable 0"):
        fuzzyq.solve(model, agents_grid(2))


@pytest.mark.parametrize(
    ("blocks", "message"),
    [
        ([([0, 1], [0])], "state variable 2 is in no block"),
        ([([0, 1], [0]), ([1, 2, 3], [1])], "state variable 1 is in blocks 0 and 1"),
        ([([0, 1], [0]), ([2, 3], [5])], "action component 5"),
        ([([0, 1, 9], [0]), ([2, 3], [1])], "state variable 9"),
        ([], "at least one block"),
    ],
)
def test_bad_block_declarations_are_refused(blocks: list[object], message: str) -> None:
    with pytest.raises(fuzzyq.ConfigError, match=message):
        fuzzyq.CallableModel(
            agents_transition, state_dim=4, actions=[LEVELS] * 2, blocks=blocks  # type: ignore[arg-type]
        )


def test_block_declarations_of_the_wrong_type_raise_input_type_error() -> None:
    with pytest.raises(fuzzyq.InputTypeError, match="blocks"):
        fuzzyq.CallableModel(agents_transition, state_dim=2, actions=[LEVELS], blocks=5)  # type: ignore[arg-type]
    with pytest.raises(fuzzyq.InputTypeError, match=r"blocks\[0\]"):
        fuzzyq.CallableModel(
            agents_transition, state_dim=2, actions=[LEVELS], blocks=[("a", 1)]  # type: ignore[list-item]
        )


def test_blocks_take_a_fraction_of_the_memory_estimate() -> None:
    # 77^3 = 456,533 cores x 27 joint actions: without blocks the tables need several GB and
    # a 1 GB limit refuses them before the function is called; with blocks they fit.
    calls = []

    def counting(x: Array, u: Array) -> tuple[Array, Array]:
        calls.append(len(x))
        return agents_transition(x, u)

    grid = agents_grid(3, positions=11, velocities=7)
    assert grid.n_cores == 456_533
    plain = fuzzyq.CallableModel(counting, state_dim=6, actions=[LEVELS] * 3)
    with pytest.raises(fuzzyq.SolverError, match="max_memory_gb"):
        fuzzyq.solve(plain, grid, max_memory_gb=1.0)
    assert calls == []


def nearest_interp_reference(
    cores: Array, transition: object, levels: list[float], gamma: float, sweeps: int
) -> Array:
    """Fuzzy Q-iteration on a 1-D grid in NumPy: triangular memberships are linear
    interpolation, a terminal successor is worth nothing after its reward."""
    v = np.zeros(len(cores))
    for _ in range(sweeps):
        thetas = []
        for a in levels:
            u = np.full((len(cores), 1), a)
            out = transition(cores[:, None], u)  # type: ignore[operator]
            nxt, r = out[0][:, 0], out[1]
            term = out[2] if len(out) == 3 else np.zeros(len(cores), dtype=bool)
            future = np.where(term, 0.0, np.interp(nxt, cores, v))
            thetas.append(r + gamma * future)
        v = np.max(thetas, axis=0)
    return v


def cliff(x: Array, u: Array) -> tuple[Array, Array, npt.NDArray[np.bool_]]:
    """A walk on [-1, 1]; stepping beyond 0.95 ends the episode with a reward of 10."""
    nxt = np.clip(x + 0.13 * u, -1, 1)
    terminal = nxt[:, 0] > 0.95
    reward = np.where(terminal, 10.0, -0.1)
    return nxt, reward, terminal


def test_terminal_states_match_a_numpy_reference() -> None:
    cores = np.linspace(-1, 1, 21)
    model = fuzzyq.CallableModel(cliff, state_dim=1, actions=[LEVELS])
    solution = fuzzyq.solve(
        model, fuzzyq.Grid([cores]), gamma=0.9, xi=1e-10, precision="float64", max_sweeps=2000
    )
    reference = nearest_interp_reference(cores, cliff, LEVELS, 0.9, 400)
    np.testing.assert_allclose(solution.V, reference, atol=1e-8)
    # Without the flags the cliff's edge is worth its reward and then more.
    def no_flags(x: Array, u: Array) -> tuple[Array, Array]:
        nxt, r, _ = cliff(x, u)
        return nxt, r

    other = fuzzyq.solve(
        fuzzyq.CallableModel(no_flags, state_dim=1, actions=[LEVELS]),
        fuzzyq.Grid([cores]),
        gamma=0.9,
        xi=1e-10,
        precision="float64",
        max_sweeps=2000,
    )
    assert other.V[-1] > solution.V[-1] + 1


def test_terminal_states_with_blocks_match_the_same_model_without_blocks() -> None:
    def pair(x: Array, u: Array) -> tuple[Array, Array, npt.NDArray[np.bool_]]:
        nxt = np.clip(x + 0.13 * u, -1, 1)
        terminal = np.all(nxt > 0.9, axis=1)
        return nxt, np.where(terminal, 10.0, -0.1 - 0.01 * u[:, 0] ** 2), terminal

    grid = fuzzyq.Grid([np.linspace(-1, 1, 15)] * 2)
    kwargs = dict(state_dim=2, actions=[LEVELS, LEVELS])
    settings = dict(gamma=0.9, xi=1e-9, precision="float64", max_sweeps=2000)
    plain = fuzzyq.solve(fuzzyq.CallableModel(pair, **kwargs), grid, **settings)  # type: ignore[arg-type]
    blocked = fuzzyq.solve(
        fuzzyq.CallableModel(pair, blocks=[([0], [0]), ([1], [1])], **kwargs),  # type: ignore[arg-type]
        grid,
        **settings,  # type: ignore[arg-type]
    )
    np.testing.assert_allclose(blocked.V, plain.V, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        (lambda x, u: (x, -x[:, 0], np.full(len(x), 0.5)), "dtype kind \"f\""),
        (lambda x, u: (x, -x[:, 0], np.full(len(x), 2)), "other than 0 and 1"),
        (lambda x, u: (x, -x[:, 0], np.zeros(len(x) + 1, dtype=bool)), "shape"),
        (lambda x, u: (x, -x[:, 0], None, None), "tuple"),
    ],
)
def test_bad_terminal_flags_raise_model_error(bad: object, message: str) -> None:
    model = fuzzyq.CallableModel(bad, state_dim=1, actions=[LEVELS])  # type: ignore[arg-type]
    with pytest.raises(fuzzyq.ModelError, match=message):
        fuzzyq.solve(model, fuzzyq.Grid([np.linspace(-1, 1, 5)]))


def test_step_actions_and_the_joint_action_order() -> None:
    model = fuzzyq.CallableModel(cliff, state_dim=1, actions=[LEVELS])
    nxt, reward, terminal = model.step([0.9], [1.0])
    assert nxt.tolist() == [1.0] and reward == 10.0 and terminal is True
    nxt, reward, terminal = model.step([0.0], [-1.0])
    assert terminal is False and reward == pytest.approx(-0.1)

    two = fuzzyq.CallableModel(
        agents_transition, state_dim=4, actions=[LEVELS, [[-2.0], [2.0]]]
    )
    assert [a.shape for a in two.actions] == [(3, 1), (2, 1)]
    # Agent 0 is the most significant digit.
    assert two.joint_index([1, 0]) == 2
    assert two.agent_indices(5) == [2, 1]
    assert two.joint_action(5).tolist() == [1.0, 2.0]
    assert two.step([0, 0, 0, 0], [1.0, 2.0])[2] is False
    with pytest.raises(fuzzyq.InputError):
        two.joint_index([3, 0])


def test_a_callable_model_and_its_solution_pickle() -> None:
    model = agents_model(2, blocks=True)
    again = pickle.loads(pickle.dumps(model))
    assert again.blocks == model.blocks and again.state_dim == 4
    grid = agents_grid(2)
    solution = fuzzyq.solve(model, grid, gamma=0.9, xi=1e-4)
    restored = pickle.loads(pickle.dumps(solution))
    assert np.array_equal(restored.V, solution.V)
    assert np.array_equal(restored.greedy, solution.greedy)
    assert restored.sweeps == solution.sweeps and restored.error_bound == solution.error_bound
    rng = np.random.default_rng(0)
    states = rng.uniform(-1, 1, size=(50, 4))
    for kind in ("greedy", "interpolated"):
        assert np.array_equal(
            restored.policy(kind).act_batch(states), solution.policy(kind).act_batch(states)
        )
    policy = pickle.loads(pickle.dumps(solution.policy("interpolated")))
    assert policy.kind == "interpolated"
    assert np.array_equal(policy.act_batch(states), solution.policy("interpolated").act_batch(states))


def test_a_callable_models_solution_saves_and_loads_with_its_model(tmp_path: Path) -> None:
    model = agents_model(2, blocks=True)
    solution = fuzzyq.solve(model, agents_grid(2), gamma=0.9, xi=1e-4)
    path = tmp_path / "custom.fzq"
    solution.save(path)
    loaded = fuzzyq.load(path, model=model)
    assert isinstance(loaded, fuzzyq.Solution)
    assert np.array_equal(loaded.V, solution.V) and loaded.V.dtype == solution.V.dtype
    assert np.array_equal(loaded.greedy, solution.greedy)
    assert (loaded.sweeps, loaded.gamma, loaded.xi) == (solution.sweeps, 0.9, 1e-4)
    states = np.random.default_rng(1).uniform(-1, 1, size=(40, 4))
    for kind in ("greedy", "interpolated"):
        assert np.array_equal(
            loaded.policy(kind).act_batch(states), solution.policy(kind).act_batch(states)
        )
    with pytest.raises(fuzzyq.ConfigError, match="pass that model"):
        fuzzyq.load(path)
    other = fuzzyq.CallableModel(agents_transition, state_dim=4, actions=[[-1.0, 1.0]] * 2)
    with pytest.raises(fuzzyq.ConfigError, match="the file's solution"):
        fuzzyq.load(path, model=other)
    with pytest.raises(fuzzyq.InputTypeError, match="model"):
        fuzzyq.load(path, model=5)  # type: ignore[arg-type]
