"""`solve(..., device="gpu")`: the block backup on a GPU through wgpu. On CI's software Vulkan
(Mesa's lavapipe, whose `fma` rounds the product first) the values differ from the CPU's in
the last bits; on an adapter that fuses (NVIDIA's) they are equal. Skipped, with the reason,
where no adapter opens, unless FUZZYQ_REQUIRE_GPU is set."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import numpy.typing as npt
import pytest

import fuzzyq

Array = npt.NDArray[np.float64]


def transition3(x: Array, u: Array) -> tuple[Array, Array]:
    """The README's three agents with declared blocks."""
    nxt = np.empty_like(x)
    for i in range(3):
        nxt[:, 2 * i] = np.clip(x[:, 2 * i] + 0.1 * x[:, 2 * i + 1], -1, 1)
        nxt[:, 2 * i + 1] = np.clip(0.95 * x[:, 2 * i + 1] + 0.1 * u[:, i], -1, 1)
    return nxt, -np.sum(x[:, 0::2] ** 2, axis=1)


def readme_model() -> fuzzyq.CallableModel:
    return fuzzyq.CallableModel(
        transition3,
        state_dim=6,
        actions=[[-1.0, 0.0, 1.0]] * 3,
        blocks=[([0, 1], [0]), ([2, 3], [1]), ([4, 5], [2])],
    )


def readme_grid() -> fuzzyq.Grid:
    return fuzzyq.Grid([np.linspace(-1, 1, 5), np.linspace(-1, 1, 3)] * 3)


def solve_on_gpu(model: object, grid: fuzzyq.Grid, **kw: object) -> fuzzyq.Solution:
    try:
        return fuzzyq.solve(model, grid, device="gpu", **kw)  # type: ignore[arg-type]
    except fuzzyq.SolverError as e:
        if "no GPU adapter" in str(e) and not os.environ.get("FUZZYQ_REQUIRE_GPU"):
            pytest.skip(f"no GPU adapter: {e}")
        raise


# A fixed number of plain sweeps, so that both devices run the same sweeps even where the last
# bits differ (a stopping test on the edge could otherwise stop one a sweep earlier).
FIXED = dict(xi=1e-9, max_sweeps=25, extrapolate=False, evaluation_sweeps=0, precision="f32")


def test_the_readme_block_model_solves_on_the_gpu_as_on_the_cpu() -> None:
    gpu = solve_on_gpu(readme_model(), readme_grid(), gamma=0.9, **FIXED)
    cpu = fuzzyq.solve(readme_model(), readme_grid(), gamma=0.9, **FIXED)  # type: ignore[arg-type]
    assert gpu.kernel == "wgpu"
    assert gpu.sweeps == cpu.sweeps == 25
    # Equal where the adapter fuses; within the rounding of the products elsewhere.
    np.testing.assert_allclose(gpu.V, cpu.V, rtol=0, atol=1e-3)
    assert np.mean(gpu.greedy == cpu.greedy) > 0.99


def test_point_masses_solve_on_the_gpu() -> None:
    model = fuzzyq.PointMass(agents=2)
    # 3 x 3 cores per axis (6,561 joint cores), as the Rust GPU tests take: 5 x 3 took 40 s of
    # CI's lavapipe.
    grid = fuzzyq.Grid([[-6.0, 0.0, 6.0], [-3.0, 0.0, 3.0]] * 4)
    gpu = solve_on_gpu(model, grid, **FIXED)
    cpu = fuzzyq.solve(model, grid, **FIXED)  # type: ignore[arg-type]
    assert gpu.kernel == "wgpu" and gpu.sweeps == cpu.sweeps == 25
    np.testing.assert_allclose(gpu.V, cpu.V, rtol=0, atol=1e-3)


def test_what_the_gpu_does_not_run_is_a_config_error() -> None:
    with pytest.raises(fuzzyq.ConfigError, match="f32"):
        fuzzyq.solve(readme_model(), readme_grid(), device="gpu", precision="f64")
    with pytest.raises(fuzzyq.ConfigError, match="device"):
        fuzzyq.solve(readme_model(), readme_grid(), device="tpu")  # type: ignore[arg-type]
    with pytest.raises(fuzzyq.ConfigError, match="sync"):
        fuzzyq.solve(fuzzyq.PointMass(agents=1), fuzzyq.PointMass(agents=1).paper_grid(),
                     device="gpu", sweep="async")


def test_a_mistyped_gpu_setting_is_a_config_error() -> None:
    # `FUZZYQ_GPU_*` settings are read when a process first opens the GPU (before any adapter
    # is looked for, so on any machine): in a process of its own.
    code = (
        "import fuzzyq\n"
        "m = fuzzyq.PointMass(agents=1)\n"
        "try:\n"
        "    fuzzyq.solve(m, m.paper_grid(), device='gpu')\n"
        "except fuzzyq.ConfigError as e:\n"
        "    print('ConfigError:', e)\n"
    )
    env = dict(os.environ, FUZZYQ_GPU_EVAL="stages")
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("ConfigError: FUZZYQ_GPU_EVAL=stages "), run.stdout + run.stderr
    assert "auto, nested or stages:K" in run.stdout
