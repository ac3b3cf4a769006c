"""Stable-Baselines3 training and Gymnasium video recording on ``FuzzyQ/PointMass-v0``.

These need large optional packages (``pip install ".[sb3]"``: stable-baselines3, which
brings torch, and moviepy) that CI does not install: each test skips with the reason when its
package is missing.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

gymnasium = pytest.importorskip(
    "gymnasium", reason="gymnasium is not installed (pip install gymnasium pettingzoo)"
)
pytest.importorskip("pettingzoo", reason="pettingzoo is not installed (pip install gymnasium pettingzoo)")

import fuzzyq  # noqa: E402, F401  (registers FuzzyQ/PointMass-v0 for gymnasium.make)

ENV_ID = "FuzzyQ/PointMass-v0"


def require_sb3() -> None:
    pytest.importorskip(
        "torch",
        reason="torch is not installed (Stable-Baselines3 needs it: pip install '.[sb3]')",
    )
    pytest.importorskip(
        "stable_baselines3", reason="stable-baselines3 is not installed (pip install '.[sb3]')"
    )


def test_ppo_learns_on_make_vec_env() -> None:
    require_sb3()
    from stable_baselines3 import PPO  # type: ignore[import-not-found, unused-ignore]
    from stable_baselines3.common.env_util import (  # type: ignore[import-not-found, unused-ignore]
        make_vec_env,
    )

    # make_vec_env passes render_mode="rgb_array" and wraps each env in Monitor.
    env = make_vec_env(ENV_ID, n_envs=4, env_kwargs={"agents": 1}, seed=0)
    assert env.num_envs == 4
    assert env.action_space == gymnasium.spaces.Discrete(25)
    assert env.observation_space.shape == (4,)
    assert env.render_mode == "rgb_array"
    model = PPO("MlpPolicy", env, n_steps=512, batch_size=256, n_epochs=2, seed=0, device="cpu")
    model.learn(total_timesteps=2048)
    assert model.num_timesteps == 2048
    # 512 steps per env: six episodes each, every one truncated by the spec's 75 steps.
    assert model.ep_info_buffer is not None
    lengths = [episode["l"] for episode in model.ep_info_buffer]
    assert len(lengths) == 4 * (512 // 75) and set(lengths) == {75}
    obs: Any = env.reset()
    actions, _ = model.predict(obs, deterministic=True)
    assert actions.shape == (4,) and all(0 <= a < 25 for a in actions)
    frames: Any = env.get_images()
    assert len(frames) == 4
    assert all(f.shape == (400, 400, 3) and f.dtype == np.uint8 for f in frames)
    env.close()


def test_sb3_env_checker_accepts_the_env() -> None:
    require_sb3()
    from stable_baselines3.common import (  # type: ignore[import-not-found, unused-ignore]
        env_checker,
    )

    import fuzzyq.envs

    env_checker.check_env(fuzzyq.envs.PointMassEnv(agents=1, render_mode="rgb_array"))
    env_checker.check_env(fuzzyq.envs.ModelEnv(fuzzyq.CarHill(), render_mode="rgb_array"))


def test_record_video_writes_the_episode(tmp_path: Path) -> None:
    moviepy = pytest.importorskip(
        "moviepy", reason="moviepy is not installed (RecordVideo needs it: pip install '.[sb3]')"
    )
    from gymnasium.wrappers import RecordVideo

    base = gymnasium.make(ENV_ID, agents=1, render_mode="rgb_array", max_episode_steps=20)
    folder = tmp_path / "videos"
    env = RecordVideo(base, video_folder=str(folder), episode_trigger=lambda _: True)
    env.reset(seed=0)
    truncated = False
    while not truncated:
        _, _, terminated, truncated, _ = env.step(24)  # full force up and to the right
        assert not terminated
    env.close()
    videos = sorted(folder.glob("*.mp4"))
    assert [v.name for v in videos] == ["rl-video-episode-0.mp4"]
    clip = moviepy.VideoFileClip(str(videos[0]))
    try:
        assert tuple(clip.size) == (400, 400)
        assert clip.fps == pytest.approx(2.5)  # one frame per 0.4 s sample time
        assert clip.duration == pytest.approx(21 / 2.5, abs=0.5)  # reset + 20 steps
        first, last = clip.get_frame(0), clip.get_frame(clip.duration - 0.5)
        assert not np.array_equal(first, last)  # the agent moved
    finally:
        clip.close()
