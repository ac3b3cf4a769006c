"""Tests of the fuzzyq Python API: grids, models, solving, policies, files and errors."""

from __future__ import annotations

import _thread
import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fuzzyq


@pytest.fixture(scope="module")
def one_agent() -> tuple[fuzzyq.PointMass, fuzzyq.Grid, fuzzyq.Solution]:
    model = fuzzyq.PointMass(agents=1)
    grid = model.paper_grid()
    return model, grid, fuzzyq.solve(model, grid)


# --- grids -----------------------------------------------------------------------------------


@settings(max_examples=300, deadline=None)
@given(st.floats(-20, 20), st.floats(-20, 20))
def test_memberships_sum_to_one(a: float, b: float) -> None:
    grid = fuzzyq.Grid([[-6, -1, 0, 1, 6], [-3, 0, 3]])
    idx, w = grid.memberships([a, b])
    assert len(idx) <= 4
    # Products of two memberships below ~1e-154 underflow to 0; none is negative or above 1.
    assert np.all(w >= 0) and np.all(w <= 1)
    for dim, v in enumerate([a, b]):
        one = fuzzyq.Grid([grid.cores[dim]])
        _, wd = one.memberships([v])
        assert np.all(wd > 0), "an active core has a positive membership in its variable"
    assert abs(w.sum() - 1) < 1e-12
    assert np.all(np.diff(idx) > 0)


def test_grid_is_row_major_and_exact_at_cores() -> None:
    grid = fuzzyq.Grid([np.array([0.0, 1.0, 2.0]), [0, 1]])
    assert grid.shape == (3, 2) and grid.n_cores == 6 and grid.n_dims == 2
    np.testing.assert_array_equal(grid.core_state(3), [1.0, 1.0])
    idx, w = grid.memberships([1.0, 1.0])
    assert list(idx) == [3] and list(w) == [1.0]
    states = grid.core_states()
    assert states.shape == (6, 2)
    values = np.arange(6.0)
    assert grid.interpolate(values, [0.5, 0.5]) == pytest.approx(np.mean([0, 1, 2, 3]))


def test_grid_errors() -> None:
    with pytest.raises(fuzzyq.ConfigError, match="state variable 0: cores must increase"):
        fuzzyq.Grid([[1.0, 0.0]])
    with pytest.raises(ValueError, match="at least 2 cores"):
        fuzzyq.Grid([[1.0]])
    with pytest.raises(fuzzyq.InputTypeError, match="cores"):
        fuzzyq.Grid(5)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"cores\[0\]: expected an array of numbers"):
        fuzzyq.Grid([["a", "b"]])
    grid = fuzzyq.Grid([[0, 1], [0, 1]])
    with pytest.raises(fuzzyq.InputError, match=r"x: expected shape \(2,\), got \(3,\)"):
        grid.memberships([0, 0, 0])
    with pytest.raises(fuzzyq.InputError, match="not a finite number"):
        grid.memberships([0, np.nan])
    with pytest.raises(fuzzyq.InputError, match="values"):
        grid.interpolate([1.0], [0, 0])
    # Grids are solved in single precision by default: cores must be distinct and finite there.
    with pytest.raises(fuzzyq.ConfigError, match="grid in single precision"):
        fuzzyq.Grid([[0.0, 1e39]])
    with pytest.raises(fuzzyq.ConfigError, match="grid in single precision"):
        fuzzyq.Grid([[1.0, 1.0 + 1e-12]])


# --- the point-mass model ----------------------------------------------------------------------


def test_point_mass_model() -> None:
    m = fuzzyq.PointMass()
    assert (m.state_dim, m.n_agents, m.action_dim, m.n_actions, m.n_joint_actions) == (8, 2, 4, 25, 625)
    assert m.actions.shape == (25, 2)
    np.testing.assert_array_equal(m.actions[1], [-2.0, -0.2])
    np.testing.assert_array_equal(m.joint_action(m.joint_index([1, 24])), [-2.0, -0.2, 2.0, 2.0])
    assert m.agent_indices(26) == [1, 1]
    x = np.array([-4.0, -6, -2, 2, 5, 3, 2, -1])
    u = m.joint_action(0)
    one = m.step(x, u)
    batch = m.step(np.stack([x, x]), np.stack([u, u]))
    assert batch.shape == (2, 8)
    np.testing.assert_array_equal(batch[1], one)
    assert m.reward(np.zeros(8)) == 5.0 and m.in_goal(np.zeros(8))
    assert m.reward(x) == 0.0
    # Frictionless closed form: s' = s + v T + u T^2 / (2 m).
    free = fuzzyq.PointMass(agents=1, friction=0.0)
    np.testing.assert_allclose(free.step([0, 0, 1, 0], [2, 0, ])[:1], [1 * 0.4 + 2 * 0.16 / 1.0])


def test_point_mass_errors() -> None:
    with pytest.raises(fuzzyq.ConfigError, match="env.mass"):
        fuzzyq.PointMass(mass=-1)
    with pytest.raises(fuzzyq.ConfigError, match="integrator"):
        fuzzyq.PointMass(integrator="euler")
    with pytest.raises(fuzzyq.ConfigError, match="rk4"):
        fuzzyq.PointMass(friction_patches=[((0, 0), 1, 2)])
    m = fuzzyq.PointMass(agents=1)
    with pytest.raises(fuzzyq.InputError, match=r"expected shape \(4,\) or \(n, 4\)"):
        m.step(np.zeros(3), np.zeros(2))
    with pytest.raises(fuzzyq.InputError, match="same batch size"):
        m.step(np.zeros((2, 4)), np.zeros(2))
    with pytest.raises(fuzzyq.InputError, match="out of range"):
        m.joint_action(25)
    with pytest.raises(fuzzyq.InputTypeError):
        m.step(None, None)  # type: ignore[arg-type]
    # The paper's grid of three agents has 45^6 = 8.3e9 cores (a grid: no memory yet); 20
    # cores on each of 16 variables, more than a grid can index: a typed error, not a panic.
    assert fuzzyq.PointMass(agents=3).paper_grid().n_cores == 45**6
    with pytest.raises(fuzzyq.ConfigError, match="cores"):
        fuzzyq.Grid([np.linspace(-1.0, 1.0, 20)] * 16)
    with pytest.raises(fuzzyq.ConfigError, match="single precision"):
        fuzzyq.PointMass(force_levels=[-1e39, 0.0, 1e39])


# --- solving -------------------------------------------------------------------------------------


def test_solve_point_mass(one_agent: tuple[fuzzyq.PointMass, fuzzyq.Grid, fuzzyq.Solution]) -> None:
    model, grid, s = one_agent
    assert s.converged and s.final_delta <= 0.05
    assert s.V.shape == (grid.n_cores,) and s.V.dtype == np.float32
    assert s.greedy.shape == (grid.n_cores,) and s.greedy.dtype == np.uint32
    assert s.deltas.shape == (s.sweeps, 2)
    assert s.error_bound == pytest.approx(0.96 / 0.04 * s.final_delta)
    # The paper's plain sweeps: 114 (the change decays like 5 * 0.96^k).
    plain = fuzzyq.solve(model, grid, extrapolate=False)
    assert plain.sweeps == 114
    # Both stop within the error bound of each other's fixed point.
    assert np.max(np.abs(plain.V - s.V)) <= plain.error_bound + s.error_bound
    # theta is consistent with V: V[d] = max_u theta[d, u] for the next sweep.
    theta = s.theta()
    assert theta.shape == (grid.n_cores, 25)
    assert s.value(grid.core_state(0)) == pytest.approx(float(s.V[0]))


def test_solve_a_model_learned_from_transitions(
    one_agent: tuple[fuzzyq.PointMass, fuzzyq.Grid, fuzzyq.Solution], tmp_path: Path
) -> None:
    model, grid, exact = one_agent
    data = fuzzyq.collect(model, 3000, seed=1)
    assert data["states"].shape == (3000, 4) and data["actions"].shape == (3000, 2)
    assert data["next_states"].shape == (3000, 4) and data["rewards"].shape == (3000,)
    # Seeded: the same data for the same seed, other data for another.
    again = fuzzyq.collect(model, 3000, seed=1)
    assert all(np.array_equal(data[k], again[k]) for k in data)
    assert not np.array_equal(fuzzyq.collect(model, 3000, seed=2)["states"], data["states"])
    # Noise-free linear dynamics: the learned tables are the true ones (to rounding), so both
    # solutions are within their error bounds of the same fixed point.
    learned = fuzzyq.solve(model, grid, transitions=data)
    assert learned.converged
    assert np.max(np.abs(learned.V - exact.V)) <= learned.error_bound + exact.error_bound
    path = tmp_path / "learned.fzq"
    learned.save(path)
    loaded = fuzzyq.load(path)
    assert isinstance(loaded, fuzzyq.Solution)
    x = np.array([-4.0, 5.0, 0.0, 0.0])
    assert np.array_equal(loaded.policy("greedy").act(x), learned.policy("greedy").act(x))
    # With process noise the rows spread and the solution differs.
    noisy = fuzzyq.PointMass(agents=1, velocity_noise=0.2)
    spread = fuzzyq.solve(noisy, grid, transitions=fuzzyq.collect(noisy, 3000, seed=1))
    assert np.max(np.abs(spread.V - exact.V)) > spread.error_bound + exact.error_bound
    with pytest.raises(fuzzyq.InputTypeError, match="next_states is missing"):
        fuzzyq.solve(model, grid, transitions={k: data[k] for k in ("states", "actions", "rewards")})
    with pytest.raises(fuzzyq.FuzzyqError, match="transitions.actions"):
        fuzzyq.solve(model, grid, transitions={**data, "actions": data["actions"][:, :1]})
    with pytest.raises(fuzzyq.ConfigError, match="not one of the task's actions"):
        fuzzyq.solve(model, grid, transitions={**data, "actions": data["actions"] + 0.5})
    with pytest.raises(fuzzyq.ConfigError, match="velocity_noise"):
        fuzzyq.PointMass(velocity_noise=-1.0)


def test_the_shaped_reward_adds_the_potential_difference() -> None:
    paper = fuzzyq.PointMass(agents=1)
    shaped = fuzzyq.PointMass(agents=1, reward="shaped", shaping_discount=0.9)
    x, u = np.array([-4.0, 5.0, 0.0, 0.0]), np.array([2.0, -2.0])
    nxt = shaped.step(x, u)
    expected = 0.9 * -np.linalg.norm(nxt) + np.linalg.norm(x)
    assert shaped.reward(x, u) == pytest.approx(expected, abs=1e-12)
    assert paper.reward(x, u) == paper.reward(x) == 0.0
    with pytest.raises(fuzzyq.InputError, match="u is missing"):
        shaped.reward(x)
    with pytest.raises(fuzzyq.ConfigError, match="reward"):
        fuzzyq.PointMass(reward="dense")  # type: ignore[arg-type]
    with pytest.raises(fuzzyq.ConfigError, match="shaping_discount"):
        fuzzyq.PointMass(reward="shaped", shaping_discount=0.0)


def test_policies(one_agent: tuple[fuzzyq.PointMass, fuzzyq.Grid, fuzzyq.Solution]) -> None:
    model, grid, s = one_agent
    greedy, interp = s.policy("greedy"), s.policy("interpolated")
    x = np.array([-4.0, 3.0, 0.5, -0.5])
    q = greedy.q_values(x)
    assert q.shape == (25,)
    u = greedy.act_index(x)
    assert u == int(np.argmax(q))
    np.testing.assert_array_equal(greedy.act(x), model.joint_action(u))
    assert greedy.agent_actions(x) == [u]
    batch = np.stack([x, -x, np.zeros(4)])
    for pol in (greedy, interp):
        out = pol.act_batch(batch)
        assert out.shape == (3, 2)
        for row, xi in zip(out, batch):
            np.testing.assert_array_equal(row, pol.act(xi))
    assert np.all(np.abs(interp.act(x)) <= 2.0 * (1 + 4 * np.finfo(np.float32).eps))
    with pytest.raises(fuzzyq.ConfigError, match="only the greedy policy"):
        interp.act_index(x)
    with pytest.raises(fuzzyq.ConfigError, match="kind"):
        s.policy("epsilon")


def test_rollout_reaches_the_goal(one_agent: tuple[fuzzyq.PointMass, fuzzyq.Grid, fuzzyq.Solution]) -> None:
    model, _, s = one_agent
    for kind in ("greedy", "interpolated"):
        pol = s.policy(kind)
        x = np.array([-4.0, -6.0, -2.0, 2.0])
        reached = False
        for _ in range(75):
            reached |= model.in_goal(x)
            x = model.step(x, pol.act(x))
        assert reached, kind
        assert np.hypot(x[0], x[1]) < 0.08, kind


def test_policy_rollout_steps_the_model(one_agent: tuple[fuzzyq.PointMass, fuzzyq.Grid, fuzzyq.Solution]) -> None:
    model, _, s = one_agent
    policy = s.policy("greedy")
    assert (policy.env, policy.learner, policy.gamma, policy.kind) == ("pointmass", "fqi", 0.96, "greedy")
    assert s.env == "pointmass"
    run = policy.rollout([-4, -6, -2, 2], 30)
    assert set(run) == {"states", "actions", "rewards", "times", "metrics"}
    x = np.array([-4.0, -6.0, -2.0, 2.0])
    for k in range(30):
        np.testing.assert_array_equal(run["states"][k], x)
        u = policy.act(x)
        np.testing.assert_array_equal(run["actions"][k], u)
        assert run["rewards"][k] == model.reward(x)
        x = model.step(x, u)
    np.testing.assert_array_equal(run["states"][30], x)
    m = run["metrics"]
    assert (m["steps"], m["policy_kind"], m["x0"], m["dt"]) == (30, "greedy", [-4, -6, -2, 2], 0.4)
    assert m["value_x0"] == pytest.approx(policy.value([-4, -6, -2, 2]))
    assert m["value_x0"] == pytest.approx(s.value([-4, -6, -2, 2]))
    # Default length: the environment's (75 sample times for the point masses).
    assert policy.rollout([-4, -6, -2, 2])["actions"].shape == (75, 2)
    rapier = policy.rollout([-4, -6, -2, 2], 10, plant="rapier")
    assert rapier["metrics"]["plant"] == "rapier"
    for kwargs, match in [
        ({"plant": "ground"}, "plant"),
        ({"headings": [0.0]}, "headings"),
        ({"radius": 0.1}, "radius"),
        ({"steps": 0}, "steps"),
        ({"x0": None}, "1 agent;"),
        ({"x0": [1.0, 2.0, 3.0]}, "x0"),
        ({"x0": [9.0, 0.0, 0.0, 0.0]}, "outside the state range"),
    ]:
        args = {"x0": [-4, -6, -2, 2], **kwargs}
        with pytest.raises(fuzzyq.ConfigError, match=match):
            policy.rollout(**args)  # type: ignore[arg-type]


def test_solver_settings_and_errors(one_agent: tuple[fuzzyq.PointMass, fuzzyq.Grid, fuzzyq.Solution]) -> None:
    model, grid, s = one_agent
    for kwargs, err, match in [
        ({"gamma": 1.5}, fuzzyq.ConfigError, "solver.gamma"),
        ({"xi": 0}, fuzzyq.ConfigError, "solver.xi"),
        ({"sweep": "gauss"}, fuzzyq.ConfigError, "sweep"),
        ({"precision": "f16"}, fuzzyq.ConfigError, "precision"),
        ({"backup": "fast"}, fuzzyq.ConfigError, "backup"),
        ({"kernel": "neon"}, fuzzyq.ConfigError, "kernel"),
        ({"threads": 0}, fuzzyq.ConfigError, "threads"),
        ({"callback": 3}, fuzzyq.InputTypeError, "callback"),
    ]:
        with pytest.raises(err, match=match):
            fuzzyq.solve(model, grid, **kwargs)  # type: ignore[arg-type]
    with pytest.raises(fuzzyq.ConfigError, match="grid.cores"):
        fuzzyq.solve(model, fuzzyq.Grid([[0, 1]] * 3))
    with pytest.raises(fuzzyq.InputTypeError, match="model"):
        fuzzyq.solve("pointmass", grid)  # type: ignore[arg-type]
    # Every setting gives the same fixed point (within the bounds) and is deterministic.
    a = fuzzyq.solve(model, grid, precision="f64", sweep="async", threads=1)
    b = fuzzyq.solve(model, grid, precision="f64", sweep="async", threads=2)
    np.testing.assert_array_equal(a.V, b.V)
    assert a.V.dtype == np.float64
    assert np.max(np.abs(a.V - s.V)) < 2.5
    for k in fuzzyq.available_kernels():
        np.testing.assert_array_equal(fuzzyq.solve(model, grid, kernel=k).V, s.V)


def test_callback_sees_every_sweep_and_can_stop(one_agent: tuple[fuzzyq.PointMass, fuzzyq.Grid, fuzzyq.Solution]) -> None:
    model, grid, _ = one_agent
    seen: list[dict[str, object]] = []
    s = fuzzyq.solve(model, grid, callback=seen.append)
    assert [d["sweep"] for d in seen] == list(range(1, s.sweeps + 1))
    assert set(seen[0]) >= {"sweep", "delta_lower", "delta_upper", "seconds", "bound", "extrapolated"}
    # What the solver chose, the same in every call: here modified policy iteration with
    # extrapolation (the defaults), no coarse start.
    assert {(d["scheme"], d["extrapolate"], d["coarse_start"]) for d in seen} == {
        ("modified-policy-iteration", True, None)
    }
    plain: list[dict[str, object]] = []
    fuzzyq.solve(model, grid, extrapolate=False, evaluation_sweeps=0, max_sweeps=3, callback=plain.append)
    assert {(d["scheme"], d["extrapolate"]) for d in plain} == {("value-iteration", False)}

    class Stop(Exception):
        pass

    def stop(info: dict[str, object]) -> None:
        if info["sweep"] == 3:
            raise Stop

    with pytest.raises(Stop):
        fuzzyq.solve(model, grid, callback=stop)


@pytest.mark.parametrize("threads", [None, 2])
def test_ctrl_c_interrupts_a_long_solve_promptly(threads: int | None) -> None:
    # The solve runs on the package's worker threads (fork-safe pools, and `threads=2` a pool
    # of its own) while the calling thread looks for Ctrl-C: Python runs signal handlers on
    # the main thread only.
    model = fuzzyq.PointMass(agents=2)
    grid = model.paper_grid()
    # Python's own Ctrl-C handler: a library imported by another test may have installed
    # one that does not raise, and `interrupt_main` calls whichever is installed.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(1.5, _thread.interrupt_main)
    start = time.monotonic()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            # Plain sweeps to a tolerance far below the default: minutes of work however
            # fast the host, so Ctrl-C always lands mid-run (the default solve takes about
            # 3 s now, too close to the timer).
            fuzzyq.solve(
                model, grid, extrapolate=False, evaluation_sweeps=0, xi=1e-6, threads=threads
            )
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    assert time.monotonic() - start < 5.0


# --- the classic benchmarks ----------------------------------------------------------------------


CLASSIC = [
    (fuzzyq.DcMotor, "dcmotor", 2, 1),
    (fuzzyq.Pendulum, "pendulum", 2, 1),
    (fuzzyq.CarHill, "carhill", 2, 1),
    (fuzzyq.Arm, "arm", 4, 2),
]


@pytest.mark.parametrize(("cls", "env", "e", "a"), CLASSIC, ids=[c[1] for c in CLASSIC])
def test_classic_models(cls: type[fuzzyq.ClassicModel], env: str, e: int, a: int) -> None:
    m = cls()
    assert isinstance(m, fuzzyq.ClassicModel)
    assert (m.env, m.preset, m.state_dim, m.action_dim, m.n_agents) == (env, "fine", e, a, 1)
    assert m.actions.shape == (m.n_actions, a) and m.n_joint_actions == m.n_actions
    assert m.grid().n_dims == e and 0 < m.gamma < 1 and m.xi > 0
    assert m.state_bounds.shape == (e, 2)
    x, u = m.default_start, m.joint_action(m.n_actions - 1)
    np.testing.assert_array_equal(u, m.actions[-1])
    nxt, r = m.step(x, u)
    assert nxt.shape == (e,) and isinstance(r, float) and r == m.reward(x, u)
    batch, rewards = m.step(np.stack([x, x, nxt]), np.stack([u, u, u]))
    assert batch.shape == (3, e) and rewards.shape == (3,)
    np.testing.assert_array_equal(batch[1], nxt)
    assert rewards[1] == r
    assert set(m.params) >= {"sample_time", "integrator"} and m.sample_time == m.params["sample_time"]


def test_classic_model_parameters() -> None:
    # Keyword arguments are the configuration's fields; the reward is -x'Qx - R u^2.
    motor = fuzzyq.DcMotor("toolbox-demo", q=[1.0, 0.0], r=0.5)
    assert motor.reward([0.5, 3.0], [2.0]) == -(0.25 + 0.5 * 4)
    assert motor.params["q"] == [1.0, 0.0] and motor.preset == "toolbox-demo"
    assert motor.n_actions == 5 and motor.grid().shape == (21, 21)
    np.testing.assert_array_equal(fuzzyq.DcMotor(actions=[-1, 1]).action_levels, [-1.0, 1.0])
    # The arm combines its torque levels (fractions of each joint's maximum) per joint.
    arm = fuzzyq.Arm(actions=[-1, 0, 1], max_torque=np.array([2.0, 1.0]))
    assert arm.actions.shape == (9, 2)
    np.testing.assert_array_equal(arm.actions[0], [-2.0, -1.0])
    car = fuzzyq.CarHill("coarse", integrator={"rk4": {"substeps": 3}})
    assert car.params["integrator"] == {"rk4": {"substeps": 3}}
    assert fuzzyq.CarHill(integrator="rk4").params["integrator"] == {"rk4": {"substeps": 10}}
    assert car.is_terminal([1.5, 0.0]) and not car.is_terminal([0.0, 0.0])


def test_classic_model_errors() -> None:
    for make, err, match in [
        (lambda: fuzzyq.DcMotor(inertiaa=1.0), fuzzyq.ConfigError, "unknown field `inertiaa`"),
        (lambda: fuzzyq.DcMotor(inertia=-1.0), fuzzyq.ConfigError, "env.inertia"),
        (lambda: fuzzyq.DcMotor(q=[1.0]), fuzzyq.ConfigError, "dcmotor.q"),
        (lambda: fuzzyq.DcMotor(inertia=np.nan), fuzzyq.InputError, "dcmotor.inertia"),
        (lambda: fuzzyq.Pendulum("nope"), fuzzyq.ConfigError, "unknown pendulum preset"),
        (lambda: fuzzyq.CarHill(integrator="zoh"), fuzzyq.ConfigError, "rk4"),
        (lambda: fuzzyq.Arm(actions=[2.0]), fuzzyq.ConfigError, "torque levels"),
        (lambda: fuzzyq.DcMotor(actions=[]), fuzzyq.ConfigError, "actions"),
        (lambda: fuzzyq.ClassicModel(), TypeError, "ClassicModel"),
    ]:
        with pytest.raises(err, match=match):
            make()
    motor = fuzzyq.DcMotor("toolbox-demo")
    with pytest.raises(fuzzyq.InputError, match=r"expected shape \(2,\) or \(n, 2\)"):
        motor.step([0.0, 0.0, 0.0], [1.0])
    with pytest.raises(fuzzyq.InputError, match="same batch size"):
        motor.step(np.zeros((2, 2)), [1.0])
    with pytest.raises(fuzzyq.ConfigError, match="grid.cores"):
        fuzzyq.solve(motor, fuzzyq.Grid([[0, 1]] * 3))
    with pytest.raises(fuzzyq.ConfigError, match="operator"):
        fuzzyq.solve(motor, motor.grid(), operator="bellman")


def test_solve_and_roll_out_a_classic_model() -> None:
    car = fuzzyq.CarHill("coarse")
    s = fuzzyq.solve(car, car.grid())
    # The preset's settings: plain sweeps in float64 with its gamma and xi.
    assert (s.env, s.gamma, s.xi, s.V.dtype) == ("carhill", car.gamma, car.xi, np.float64)
    assert s.converged and s.deltas.shape[0] == s.sweeps
    other = fuzzyq.solve(car, car.grid(), gamma=0.9, precision="float32", extrapolate=True)
    assert other.gamma == 0.9 and other.V.dtype == np.float32
    for kind in ("greedy", "interpolated"):
        policy = s.policy(kind)
        assert (policy.env, policy.learner, policy.state_dim, policy.action_dim) == ("carhill", "fqi", 2, 1)
        run = policy.rollout(steps=100)
        k = len(run["actions"])
        assert run["states"].shape == (k + 1, 2) and run["rewards"].shape == (k,)
        np.testing.assert_allclose(run["times"], car.sample_time * np.arange(k + 1))
        np.testing.assert_array_equal(run["states"][0], car.default_start)
        # The run is the model stepped under the policy's actions, to its terminal state.
        for i in range(k):
            np.testing.assert_array_equal(run["actions"][i], policy.act(run["states"][i]))
            nxt, r = car.step(run["states"][i], run["actions"][i])
            np.testing.assert_array_equal(run["states"][i + 1], nxt)
            assert run["rewards"][i] == r
        m = run["metrics"]
        assert m["steps"] == k and m["terminal"] == (k < 100) and m["x0"] == [-0.5, 0.0]
        assert m["value_x0"] == pytest.approx(policy.value(car.default_start))
    q = fuzzyq.solve(car, car.grid(), operator="q-values")
    assert q.kernel == "q-values" and q.converged


# --- models written in Python ------------------------------------------------------------------


def point_mass_transition(model: fuzzyq.PointMass):  # type: ignore[no-untyped-def]
    def transition(states: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        assert states.dtype == np.float64 and actions.dtype == np.float64
        rewards = np.where(np.linalg.norm(states, axis=1) < model.goal_radius, model.goal_reward, 0.0)
        return model.step(states, actions), rewards

    return transition


def test_callable_model_matches_the_built_in_model(
    one_agent: tuple[fuzzyq.PointMass, fuzzyq.Grid, fuzzyq.Solution], tmp_path: Path
) -> None:
    model, grid, s = one_agent
    calls: list[int] = []

    def transition(states: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        calls.append(len(states))
        return point_mass_transition(model)(states, actions)

    custom = fuzzyq.CallableModel(transition, state_dim=4, actions=[model.actions], batch_size=10_000)
    assert custom.n_joint_actions == 25 and custom.action_dim == 2
    c = fuzzyq.solve(custom, grid, precision="f64")
    ref = fuzzyq.solve(model, grid, precision="f64", backup="generic")
    np.testing.assert_allclose(c.V, ref.V, rtol=1e-12)
    assert c.sweeps == ref.sweeps
    assert sum(calls) == grid.n_cores * 25 and max(calls) <= 10_000
    x = np.array([-4.0, 3.0, 0.5, -0.5])
    np.testing.assert_allclose(c.policy().q_values(x), ref.policy().q_values(x), rtol=1e-9)
    # Saved without its function, read back with it.
    c.save(tmp_path / "callable.fzq")
    again = fuzzyq.load(tmp_path / "callable.fzq", model=custom)
    assert isinstance(again, fuzzyq.Solution)
    np.testing.assert_array_equal(again.policy().q_values(x), c.policy().q_values(x))


def test_a_ten_line_custom_system() -> None:
    # A 1-D double integrator pushed to the origin: the README's example.
    def transition(x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pos = np.clip(x[:, 0] + 0.1 * x[:, 1], -1, 1)
        vel = np.clip(x[:, 1] + 0.1 * u[:, 0], -1, 1)
        return np.stack([pos, vel], axis=1), -(x[:, 0] ** 2)

    model = fuzzyq.CallableModel(transition, state_dim=2, actions=[[-1.0, 0.0, 1.0]])
    grid = fuzzyq.Grid([np.linspace(-1, 1, 21), np.linspace(-1, 1, 21)])
    solution = fuzzyq.solve(model, grid, gamma=0.95, xi=1e-3)
    policy = solution.policy("greedy")
    assert solution.converged
    assert policy.act([0.8, 0.0])[0] == -1.0 and policy.act([-0.8, 0.0])[0] == 1.0
    assert solution.env is None and policy.env is None
    with pytest.raises(fuzzyq.ConfigError, match="plant="):
        policy.rollout([0.5, 0.0])
    # With the model as its plant, the policy runs on the model's function.
    run = policy.rollout([0.5, 0.0], 20, plant=model)
    assert run["states"].shape == (21, 2) and run["success"] is None
    with pytest.raises(fuzzyq.ConfigError, match="q-values"):
        fuzzyq.solve(model, grid, operator="q-values")


def test_callable_model_errors() -> None:
    grid = fuzzyq.Grid([[-1, 0, 1]])
    ok = lambda x, u: (x, np.zeros(len(x)))  # noqa: E731
    with pytest.raises(fuzzyq.InputTypeError, match="callable"):
        fuzzyq.CallableModel(3, state_dim=1, actions=[[0.0]])  # type: ignore[arg-type]
    with pytest.raises(fuzzyq.ConfigError, match="state_dim"):
        fuzzyq.CallableModel(ok, state_dim=0, actions=[[0.0]])
    with pytest.raises(fuzzyq.ConfigError, match="agents"):
        fuzzyq.CallableModel(ok, state_dim=1, actions=[])
    with pytest.raises(fuzzyq.InputError, match=r"actions\[0\]"):
        fuzzyq.CallableModel(ok, state_dim=1, actions=[[0.0, np.inf]])
    with pytest.raises(fuzzyq.ConfigError, match="state variables"):
        fuzzyq.solve(fuzzyq.CallableModel(ok, state_dim=2, actions=[[0.0]]), grid)
    for bad, match in [
        (lambda x, u: x, "a tuple \\(next_states, rewards\\)"),
        (lambda x, u: (x[:, :0], np.zeros(len(x))), r"expected shape \(3, 1\)"),
        (lambda x, u: (x, np.zeros(2)), r"rewards: expected shape \(3,\)"),
        (lambda x, u: (x * np.nan, np.zeros(len(x))), "non-finite next state"),
        (lambda x, u: (x, np.full(len(x), np.inf)), "non-finite reward"),
        (lambda x, u: (x, ["a"] * len(x)), "rewards"),
    ]:
        with pytest.raises(fuzzyq.ModelError, match=match):
            fuzzyq.solve(fuzzyq.CallableModel(bad, state_dim=1, actions=[[0.0]]), grid)

    def boom(x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        raise ZeroDivisionError("inside the model")

    with pytest.raises(ZeroDivisionError, match="inside the model"):
        fuzzyq.solve(fuzzyq.CallableModel(boom, state_dim=1, actions=[[0.0]]), grid)


# --- files: Python and the command line share the format ----------------------------------------


def test_save_load_round_trip(tmp_path: Path, one_agent: tuple[fuzzyq.PointMass, fuzzyq.Grid, fuzzyq.Solution]) -> None:
    _, _, s = one_agent
    path = tmp_path / "one.fzq"
    s.save(path)
    back = fuzzyq.load(path)
    assert isinstance(back, fuzzyq.Solution)  # fuzzy Q-iteration; learned policies load as Policy
    np.testing.assert_array_equal(back.V, s.V)
    np.testing.assert_array_equal(back.greedy, s.greedy)
    assert back.sweeps == s.sweeps and back.grid.shape == s.grid.shape
    x = [-4.0, 3.0, 0.5, -0.5]
    assert back.policy().act_index(x) == s.policy().act_index(x)
    with pytest.raises(fuzzyq.PolicyFileError, match="not a fuzzyq policy file"):
        (tmp_path / "junk.fzq").write_text("hello")
        fuzzyq.load(tmp_path / "junk.fzq")
    with pytest.raises(fuzzyq.PolicyFileError, match="truncated"):
        (tmp_path / "cut.fzq").write_bytes(path.read_bytes()[:100])
        fuzzyq.load(tmp_path / "cut.fzq")
    with pytest.raises(fuzzyq.PolicyFileError, match="cannot read"):
        fuzzyq.load(tmp_path / "missing.fzq")
    with pytest.raises(fuzzyq.PolicyFileError, match="cannot write"):
        s.save(tmp_path / "no" / "dir" / "x.fzq")


def test_solve_releases_the_gil() -> None:
    model = fuzzyq.PointMass(agents=2)
    grid = fuzzyq.Grid([[-6, 0, 6], [-6, 0, 6], [-3, 0, 3], [-3, 0, 3]] * 2)
    ticks = 0
    done = threading.Event()

    def count() -> None:
        nonlocal ticks
        while not done.is_set():
            ticks += 1
            time.sleep(0.001)

    t = threading.Thread(target=count)
    t.start()
    try:
        time.sleep(0.01)
        before = ticks
        start = time.monotonic()
        fuzzyq.solve(model, grid, xi=1e-4, extrapolate=False)
        during, seconds = ticks - before, time.monotonic() - start
    finally:
        done.set()
        t.join()
    # The other thread ticks about once per millisecond only while the GIL is free.
    assert during >= 0.25 * seconds * 1000, (during, seconds)


def test_package_is_typed() -> None:
    pkg = Path(fuzzyq.__file__).parent
    assert (pkg / "py.typed").exists()
    assert (pkg / "_fuzzyq.pyi").exists()
    assert os.path.basename(fuzzyq.__file__) == "__init__.py"
