"""Nothing a user types crashes fuzzyq: every bad argument raises a `fuzzyq.FuzzyqError`.

Each case of `CASES` calls the API with one bad argument and expects a subclass of
`fuzzyq.FuzzyqError` (also the matching built-in class: `TypeError` for a wrong type,
`ValueError` for a bad value) whose message is one line and names the argument. The
hypothesis tests feed arbitrary bytes, corrupted policy files, arbitrary paths and arbitrary
configuration values to the loaders and assert that only `FuzzyqError` subclasses come out.
"""

from __future__ import annotations

import functools
import math
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fuzzyq

# --- small objects the cases act on (built once, on first use) ----------------------------------


@functools.cache
def point_mass() -> fuzzyq.PointMass:
    return fuzzyq.PointMass(agents=1)


@functools.cache
def coarse_grid() -> fuzzyq.Grid:
    return fuzzyq.Grid([[-6, 0, 6], [-6, 0, 6], [-3, 0, 3], [-3, 0, 3]])


def identity(x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return x, np.zeros(len(x))


@functools.cache
def callable_model() -> fuzzyq.CallableModel:
    return fuzzyq.CallableModel(identity, state_dim=1, actions=[[-1.0, 1.0]])


@functools.cache
def line() -> fuzzyq.Grid:
    return fuzzyq.Grid([[-1.0, 0.0, 1.0]])


@functools.cache
def motor() -> fuzzyq.DcMotor:
    return fuzzyq.DcMotor("toolbox-demo")


@functools.cache
def solution() -> fuzzyq.Solution:
    return fuzzyq.solve(point_mass(), coarse_grid())


@functools.cache
def policy() -> fuzzyq.Policy:
    return solution().policy("greedy")


def solve(**kwargs: Any) -> fuzzyq.Solution:
    return fuzzyq.solve(point_mass(), coarse_grid(), **kwargs)


X0 = [-4.0, 3.0, 0.0, 0.0]

Case = tuple[str, Callable[[], object], type[fuzzyq.FuzzyqError], str]

# (id, call, expected class, the argument the message must name)
CASES: list[Case] = [
    # fuzzyq.solve: settings of the wrong type or out of range
    ("solve-max_sweeps-negative", lambda: solve(max_sweeps=-1), fuzzyq.ConfigError, "max_sweeps"),
    ("solve-max_sweeps-float", lambda: solve(max_sweeps=1.5), fuzzyq.InputTypeError, "max_sweeps"),
    ("solve-max_sweeps-huge", lambda: solve(max_sweeps=10**30), fuzzyq.ConfigError, "max_sweeps"),
    ("solve-max_sweeps-str", lambda: solve(max_sweeps="10"), fuzzyq.InputTypeError, "max_sweeps"),
    ("solve-max_sweeps-bool", lambda: solve(max_sweeps=True), fuzzyq.InputTypeError, "max_sweeps"),
    ("solve-max_sweeps-zero", lambda: solve(max_sweeps=0), fuzzyq.ConfigError, "max_sweeps"),
    ("solve-gamma-str", lambda: solve(gamma="0.9"), fuzzyq.InputTypeError, "gamma"),
    ("solve-gamma-list", lambda: solve(gamma=[0.9]), fuzzyq.InputTypeError, "gamma"),
    ("solve-gamma-nan", lambda: solve(gamma=math.nan), fuzzyq.ConfigError, "gamma"),
    ("solve-gamma-above-1", lambda: solve(gamma=1.5), fuzzyq.ConfigError, "gamma"),
    ("solve-xi-inf", lambda: solve(xi=math.inf), fuzzyq.ConfigError, "xi"),
    ("solve-xi-negative", lambda: solve(xi=-1), fuzzyq.ConfigError, "xi"),
    ("solve-sweep-int", lambda: solve(sweep=1), fuzzyq.InputTypeError, "sweep"),
    ("solve-sweep-unknown", lambda: solve(sweep="gauss"), fuzzyq.ConfigError, "sweep"),
    ("solve-extrapolate-int", lambda: solve(extrapolate=1), fuzzyq.InputTypeError, "extrapolate"),
    ("solve-evaluation_sweeps-negative", lambda: solve(evaluation_sweeps=-2), fuzzyq.ConfigError, "evaluation_sweeps"),
    ("solve-absorbing_goal-str", lambda: solve(absorbing_goal="yes"), fuzzyq.InputTypeError, "absorbing_goal"),
    ("solve-absorbing_goal-no-goal-classic", lambda: fuzzyq.solve(motor(), motor().grid(), absorbing_goal=True), fuzzyq.ConfigError, "absorbing_goal"),
    ("solve-absorbing_goal-terminal-not-goal", lambda: fuzzyq.solve(fuzzyq.CarHill("coarse"), fuzzyq.CarHill("coarse").grid(), absorbing_goal=True), fuzzyq.ConfigError, "absorbing_goal"),
    ("solve-absorbing_goal-no-goal-callable", lambda: fuzzyq.solve(callable_model(), line(), absorbing_goal=True), fuzzyq.ConfigError, "absorbing_goal"),
    ("solve-absorbing_goal-no-goal-core", lambda: fuzzyq.solve(point_mass(), fuzzyq.Grid([[-6, -3, 3, 6]] * 2 + [[-3, 3]] * 2), absorbing_goal=True), fuzzyq.ConfigError, "absorbing_goal"),
    ("solve-precision-int", lambda: solve(precision=64), fuzzyq.InputTypeError, "precision"),
    ("solve-precision-unknown", lambda: solve(precision="f16"), fuzzyq.ConfigError, "precision"),
    ("solve-backup-int", lambda: solve(backup=1), fuzzyq.InputTypeError, "backup"),
    ("solve-kernel-int", lambda: solve(kernel=3), fuzzyq.InputTypeError, "kernel"),
    ("solve-operator-unknown", lambda: solve(operator="bellman"), fuzzyq.ConfigError, "operator"),
    ("solve-threads-negative", lambda: solve(threads=-1), fuzzyq.ConfigError, "threads"),
    ("solve-threads-zero", lambda: solve(threads=0), fuzzyq.ConfigError, "threads"),
    ("solve-threads-million", lambda: solve(threads=10**6), fuzzyq.ConfigError, "threads"),
    ("solve-threads-float", lambda: solve(threads=2.0), fuzzyq.InputTypeError, "threads"),
    ("solve-callback-not-callable", lambda: solve(callback=3), fuzzyq.InputTypeError, "callback"),
    ("solve-grid-list", lambda: fuzzyq.solve(point_mass(), [[0.0, 1.0]] * 4), fuzzyq.InputTypeError, "grid"),
    ("solve-model-str", lambda: fuzzyq.solve("pointmass", coarse_grid()), fuzzyq.InputTypeError, "model"),
    ("solve-max_memory_gb-zero", lambda: solve(max_memory_gb=0), fuzzyq.ConfigError, "max_memory_gb"),
    ("solve-max_memory_gb-str", lambda: solve(max_memory_gb="8"), fuzzyq.InputTypeError, "max_memory_gb"),
    ("solve-max_memory_gb-exceeded-callable", lambda: fuzzyq.solve(callable_model(), line(), max_memory_gb=1e-9), fuzzyq.SolverError, "max_memory_gb"),
    ("solve-max_memory_gb-exceeded-q-values", lambda: solve(operator="q-values", max_memory_gb=1e-9), fuzzyq.SolverError, "max_memory_gb"),
    ("solve-transitions-int", lambda: solve(transitions=3), fuzzyq.InputTypeError, "transitions"),
    ("solve-transitions-callable-model", lambda: fuzzyq.solve(callable_model(), line(), transitions={}), fuzzyq.ConfigError, "transitions"),
    # fuzzyq.PointMass
    ("pointmass-agents-negative", lambda: fuzzyq.PointMass(agents=-1), fuzzyq.ConfigError, "agents"),
    ("pointmass-agents-str", lambda: fuzzyq.PointMass(agents="2"), fuzzyq.InputTypeError, "agents"),
    ("pointmass-agents-zero", lambda: fuzzyq.PointMass(agents=0), fuzzyq.ConfigError, "agents"),
    ("pointmass-mass-str", lambda: fuzzyq.PointMass(mass="a"), fuzzyq.InputTypeError, "mass"),
    ("pointmass-mass-nan", lambda: fuzzyq.PointMass(mass=math.nan), fuzzyq.ConfigError, "mass"),
    ("pointmass-sample_time-none", lambda: fuzzyq.PointMass(sample_time=None), fuzzyq.InputTypeError, "sample_time"),
    ("pointmass-position_limit-zero", lambda: fuzzyq.PointMass(position_limit=0), fuzzyq.ConfigError, "position_limit"),
    ("pointmass-integrator-int", lambda: fuzzyq.PointMass(integrator=3), fuzzyq.InputTypeError, "integrator"),
    ("pointmass-integrator-unknown", lambda: fuzzyq.PointMass(integrator="euler"), fuzzyq.ConfigError, "integrator"),
    ("pointmass-rk4_substeps-negative", lambda: fuzzyq.PointMass(rk4_substeps=-1), fuzzyq.ConfigError, "rk4_substeps"),
    ("pointmass-friction_patches-int", lambda: fuzzyq.PointMass(friction_patches=3), fuzzyq.InputTypeError, "friction_patches"),
    ("pointmass-friction_patches-flat", lambda: fuzzyq.PointMass(friction_patches=[(1, 2, 3)]), fuzzyq.InputTypeError, "friction_patches"),
    ("pointmass-friction_patches-nan", lambda: fuzzyq.PointMass(integrator="rk4", friction_patches=[((0, math.nan), 1, 1)]), fuzzyq.ConfigError, "friction_patches"),
    ("pointmass-force_levels-repeated", lambda: fuzzyq.PointMass(force_levels=[-1, 1, 1]), fuzzyq.ConfigError, "force_levels"),
    ("pointmass-force_levels-str", lambda: fuzzyq.PointMass(force_levels="ab"), fuzzyq.InputTypeError, "force_levels"),
    ("pointmass-velocity_noise-negative", lambda: fuzzyq.PointMass(velocity_noise=-1.0), fuzzyq.ConfigError, "velocity_noise"),
    ("pointmass-joint_action-negative", lambda: point_mass().joint_action(-1), fuzzyq.InputError, "index"),
    ("pointmass-joint_action-str", lambda: point_mass().joint_action("a"), fuzzyq.InputTypeError, "index"),
    ("pointmass-joint_action-too-large", lambda: point_mass().joint_action(25), fuzzyq.InputError, "index"),
    ("pointmass-joint_index-str", lambda: point_mass().joint_index("ab"), fuzzyq.InputTypeError, "per_agent"),
    ("pointmass-joint_index-negative", lambda: point_mass().joint_index([-1]), fuzzyq.InputError, "per_agent"),
    ("pointmass-joint_index-length", lambda: point_mass().joint_index([1, 2]), fuzzyq.InputError, "per_agent"),
    ("pointmass-agent_indices-negative", lambda: point_mass().agent_indices(-1), fuzzyq.InputError, "index"),
    ("pointmass-step-none", lambda: point_mass().step(None, None), fuzzyq.InputTypeError, "x"),
    ("pointmass-step-shape", lambda: point_mass().step(np.zeros(3), np.zeros(2)), fuzzyq.InputError, "x"),
    ("pointmass-reward-nan", lambda: point_mass().reward([math.nan] * 4), fuzzyq.InputError, "x"),
    # fuzzyq.Grid
    ("grid-cores-int", lambda: fuzzyq.Grid(5), fuzzyq.InputTypeError, "cores"),
    ("grid-cores-decreasing", lambda: fuzzyq.Grid([[1.0, 0.0]]), fuzzyq.ConfigError, "cores"),
    ("grid-cores-empty", lambda: fuzzyq.Grid([]), fuzzyq.ConfigError, "cores"),
    ("grid-core_state-negative", lambda: line().core_state(-1), fuzzyq.InputError, "index"),
    ("grid-core_state-huge", lambda: line().core_state(10**30), fuzzyq.InputError, "index"),
    ("grid-memberships-nan", lambda: line().memberships([math.nan]), fuzzyq.InputError, "x"),
    ("grid-interpolate-str", lambda: line().interpolate("abc", [0.0]), fuzzyq.InputTypeError, "values"),
    # fuzzyq.CallableModel
    ("callable-actions-repeated", lambda: fuzzyq.CallableModel(identity, state_dim=1, actions=[[0.0, 1.0, 0.0]]), fuzzyq.ConfigError, "actions"),
    ("callable-actions-repeated-rows", lambda: fuzzyq.CallableModel(identity, state_dim=1, actions=[[[0.0, 1.0], [1.0, 0.0], [-0.0, 1.0]]]), fuzzyq.ConfigError, "actions"),
    ("callable-actions-int", lambda: fuzzyq.CallableModel(identity, state_dim=1, actions=3), fuzzyq.InputTypeError, "actions"),
    ("callable-actions-inf", lambda: fuzzyq.CallableModel(identity, state_dim=1, actions=[[0.0, math.inf]]), fuzzyq.InputError, "actions"),
    ("callable-state_dim-negative", lambda: fuzzyq.CallableModel(identity, state_dim=-1, actions=[[0.0]]), fuzzyq.ConfigError, "state_dim"),
    ("callable-state_dim-str", lambda: fuzzyq.CallableModel(identity, state_dim="1", actions=[[0.0]]), fuzzyq.InputTypeError, "state_dim"),
    ("callable-batch_size-negative", lambda: fuzzyq.CallableModel(identity, state_dim=1, actions=[[0.0]], batch_size=-1), fuzzyq.ConfigError, "batch_size"),
    ("callable-batch_size-zero", lambda: fuzzyq.CallableModel(identity, state_dim=1, actions=[[0.0]], batch_size=0), fuzzyq.ConfigError, "batch_size"),
    ("callable-transition-int", lambda: fuzzyq.CallableModel(3, state_dim=1, actions=[[0.0]]), fuzzyq.InputTypeError, "transition"),
    # the classic benchmarks
    ("dcmotor-preset-int", lambda: fuzzyq.DcMotor(3), fuzzyq.InputTypeError, "preset"),
    ("dcmotor-preset-unknown", lambda: fuzzyq.DcMotor("nope"), fuzzyq.ConfigError, "preset"),
    ("dcmotor-actions-repeated", lambda: fuzzyq.DcMotor(actions=[1.0, 1.0]), fuzzyq.ConfigError, "actions"),
    ("arm-actions-repeated", lambda: fuzzyq.Arm(actions=[0.5, 0.5]), fuzzyq.ConfigError, "actions"),
    ("dcmotor-inertia-str", lambda: fuzzyq.DcMotor(inertia="a"), fuzzyq.InputTypeError, "inertia"),
    ("dcmotor-q-object", lambda: fuzzyq.DcMotor(q=object()), fuzzyq.InputTypeError, "q"),
    ("dcmotor-inertia-nan", lambda: fuzzyq.DcMotor(inertia=math.nan), fuzzyq.InputError, "inertia"),
    ("dcmotor-unknown-field", lambda: fuzzyq.DcMotor(inertiaa=1.0), fuzzyq.ConfigError, "inertiaa"),
    ("dcmotor-joint_action-negative", lambda: motor().joint_action(-1), fuzzyq.InputError, "index"),
    ("dcmotor-step-str", lambda: motor().step("ab", [0.0]), fuzzyq.InputTypeError, "x"),
    # fuzzyq.collect
    ("collect-samples-negative", lambda: fuzzyq.collect(point_mass(), -1), fuzzyq.ConfigError, "samples"),
    ("collect-samples-str", lambda: fuzzyq.collect(point_mass(), "10"), fuzzyq.InputTypeError, "samples"),
    ("collect-samples-beyond-memory", lambda: fuzzyq.collect(point_mass(), 10**15), fuzzyq.SolverError, "samples"),
    ("collect-seed-negative", lambda: fuzzyq.collect(point_mass(), 10, seed=-1), fuzzyq.ConfigError, "seed"),
    ("collect-episode_steps-zero", lambda: fuzzyq.collect(point_mass(), 10, episode_steps=0), fuzzyq.ConfigError, "episode_steps"),
    ("collect-callable-no-starts", lambda: fuzzyq.collect(callable_model(), 10), fuzzyq.ConfigError, "starts"),
    ("collect-source-int", lambda: fuzzyq.collect(3, 10), fuzzyq.InputTypeError, "source"),
    ("collect-episode_steps-float", lambda: fuzzyq.collect(callable_model(), 10, starts=[[0.0]], episode_steps=1.5), fuzzyq.InputTypeError, "episode_steps"),
    # files
    ("load-path-int", lambda: fuzzyq.load(3), fuzzyq.InputTypeError, "path"),
    ("load-path-none", lambda: fuzzyq.load(None), fuzzyq.InputTypeError, "path"),
    ("save-path-int", lambda: solution().save(3), fuzzyq.InputTypeError, "path"),
    # solutions and policies
    ("solution-policy-int", lambda: solution().policy(3), fuzzyq.InputTypeError, "kind"),
    ("solution-policy-unknown", lambda: solution().policy("epsilon"), fuzzyq.ConfigError, "kind"),
    ("solution-value-shape", lambda: solution().value([0.0]), fuzzyq.InputError, "x"),
    ("policy-act-str", lambda: policy().act("abc"), fuzzyq.InputTypeError, "x"),
    ("policy-act_batch-shape", lambda: policy().act_batch(np.zeros((2, 3))), fuzzyq.InputError, "states"),
    ("policy-value-nan", lambda: policy().value([math.nan] * 4), fuzzyq.InputError, "x"),
    ("rollout-steps-negative", lambda: policy().rollout(X0, -1), fuzzyq.ConfigError, "steps"),
    ("rollout-steps-beyond-memory", lambda: policy().rollout(X0, 10**15), fuzzyq.SolverError, "steps"),
    ("rollout-seed-negative", lambda: policy().rollout(X0, 5, seed=-1), fuzzyq.ConfigError, "seed"),
    ("rollout-plant-int", lambda: policy().rollout(X0, 5, plant=3), fuzzyq.InputTypeError, "plant"),
    ("rollout-radius-nan", lambda: policy().rollout(X0, 5, plant="rapier", radius=math.nan), fuzzyq.ConfigError, "radius"),
    ("rollout-radius-negative", lambda: policy().rollout(X0, 5, plant="rapier", radius=-1.0), fuzzyq.ConfigError, "radius"),
    ("rollout-x0-nan", lambda: policy().rollout([math.nan, 0.0, 0.0, 0.0], 5), fuzzyq.ConfigError, "x0"),
]

# The built-in class each kind of error also derives from.
ALSO = {
    fuzzyq.InputTypeError: TypeError,
    fuzzyq.ConfigError: ValueError,
    fuzzyq.InputError: ValueError,
    fuzzyq.SolverError: RuntimeError,
}


@pytest.mark.parametrize(("call", "expected", "argument"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_raises_a_typed_error_naming_the_argument(
    call: Callable[[], object], expected: type[fuzzyq.FuzzyqError], argument: str
) -> None:
    with pytest.raises(fuzzyq.FuzzyqError) as info:
        call()
    error = info.value
    assert type(error) is expected, f"{type(error).__name__}: {error}"
    assert isinstance(error, ALSO[expected])
    message = str(error)
    assert "\n" not in message and message.strip() == message, message
    assert re.search(rf"(?<![\w]){re.escape(argument)}(?![\w])", message), message
    # The argument's name is in the message itself, not left in a note.
    assert not getattr(error, "__notes__", None), error.__notes__


def test_there_are_at_least_60_cases() -> None:
    assert len(CASES) >= 60
    assert len({c[0] for c in CASES}) == len(CASES)


def test_a_memory_refusal_gives_the_estimate_and_the_limit() -> None:
    with pytest.raises(fuzzyq.SolverError) as info:
        fuzzyq.solve(callable_model(), line(), max_memory_gb=1e-9)
    message = str(info.value)
    assert re.search(r"needs about [\d.]+ GB", message), message
    assert "limit of 0.00 GB" in message and "3 cores x 2 joint actions" in message, message
    # Refused before the function is called at all.
    calls: list[int] = []

    def counted(x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        calls.append(len(x))
        return identity(x, u)

    model = fuzzyq.CallableModel(counted, state_dim=2, actions=[np.arange(100.0)])
    big = fuzzyq.Grid([np.arange(3000.0)] * 2)  # 9e6 cores x 100 actions: about 80 GB
    with pytest.raises(fuzzyq.SolverError, match="max_memory_gb"):
        fuzzyq.solve(model, big)
    assert calls == []
    # A limit raised deliberately lets a problem through.
    assert fuzzyq.solve(callable_model(), line(), max_memory_gb=1.0).converged


def test_absorbing_goal_is_accepted_where_the_model_has_a_goal() -> None:
    s = solve(absorbing_goal=True)
    assert s.converged and s.sweeps != solve().sweeps


def test_numpy_scalars_are_accepted_where_python_numbers_are() -> None:
    s = solve(gamma=np.float32(0.9), max_sweeps=np.int64(500), threads=np.int32(1))
    assert s.gamma == pytest.approx(0.9)
    assert point_mass().joint_action(np.uint8(3)).shape == (2,)
    assert fuzzyq.solve(callable_model(), line(), extrapolate=np.bool_(False)).converged


def test_internal_error_is_a_fuzzyq_error() -> None:
    # A Rust panic inside the bindings surfaces as InternalError (tested on the Rust side: no
    # bad input reaches one); `except Exception` and `except fuzzyq.FuzzyqError` both catch it.
    assert issubclass(fuzzyq.InternalError, fuzzyq.FuzzyqError)
    assert issubclass(fuzzyq.InternalError, RuntimeError)


def test_other_notes_are_kept() -> None:
    error = fuzzyq.ConfigError("x: bad")
    error.add_note("while processing 'y'")
    assert str(error) == "y: x: bad"
    other = fuzzyq.ConfigError("x: bad")
    other.add_note("see the docs")
    assert str(other) == "x: bad" and other.__notes__ == ["see the docs"]


# --- the loaders, fed arbitrary data -------------------------------------------------------------

LOADER_SETTINGS = settings(
    max_examples=200,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


@functools.cache
def valid_policy_file(directory: str) -> bytes:
    path = Path(directory) / "valid.fzq"
    solution().save(path)
    return path.read_bytes()


def load_or_fuzzyq_error(path: Path) -> None:
    """`fuzzyq.load(path)` raises only FuzzyqError; what it loads acts without error."""
    try:
        loaded = fuzzyq.load(path)
    except fuzzyq.FuzzyqError:
        return
    try:
        p = loaded.policy("greedy") if isinstance(loaded, fuzzyq.Solution) else loaded
        p.act(np.zeros(p.state_dim))
    except fuzzyq.FuzzyqError:
        pass


@LOADER_SETTINGS
@given(data=st.binary(max_size=2048))
def test_load_arbitrary_bytes(tmp_path: Path, data: bytes) -> None:
    path = tmp_path / "arbitrary.fzq"
    path.write_bytes(data)
    load_or_fuzzyq_error(path)


@LOADER_SETTINGS
@given(
    edits=st.lists(
        st.tuples(st.sampled_from(["flip", "cut", "insert"]), st.integers(0, 10**6), st.integers(0, 255)),
        min_size=1,
        max_size=4,
    )
)
def test_load_corrupted_policy_files(tmp_path_factory: pytest.TempPathFactory, edits: list[tuple[str, int, int]]) -> None:
    directory = tmp_path_factory.getbasetemp() / "corrupted"
    directory.mkdir(exist_ok=True)
    data = bytearray(valid_policy_file(str(directory)))
    for kind, at, value in edits:
        i = at % max(len(data), 1)
        if kind == "flip" and data:
            data[i] ^= value or 1
        elif kind == "cut":
            del data[i:]
        else:
            data.insert(i, value)
    path = directory / "edited.fzq"
    path.write_bytes(bytes(data))
    load_or_fuzzyq_error(path)


@LOADER_SETTINGS
@given(name=st.text(max_size=40))
def test_load_arbitrary_paths(tmp_path: Path, name: str) -> None:
    # Relative to an empty directory: names that are not files there, or directories.
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        with pytest.raises(fuzzyq.FuzzyqError):
            fuzzyq.load(name)
    finally:
        os.chdir(cwd)


JSONISH = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=10),
    lambda children: st.lists(children, max_size=3) | st.dictionaries(st.text(max_size=5), children, max_size=3),
    max_leaves=6,
)
DCMOTOR_FIELDS = ["inertia", "damping", "torque_constant", "resistance", "sample_time", "max_angle", "max_velocity", "q", "r", "integrator"]


@LOADER_SETTINGS
@given(field=st.sampled_from(DCMOTOR_FIELDS), value=JSONISH)
def test_classic_configuration_values(field: str, value: object) -> None:
    # The keyword arguments of a classic model are read by the configuration's loader.
    try:
        m = fuzzyq.DcMotor("toolbox-demo", **{field: value})
    except fuzzyq.FuzzyqError:
        return
    m.step(m.default_start, m.actions[0])
