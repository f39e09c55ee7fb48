"""gymnasium.wrappers.RecordVideo on DualLidar-v0: the set-up installs what it needs."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401 - registers DualLidar-v0

pytest.importorskip("moviepy", reason="RecordVideo needs moviepy: pip install 'duallidar[video]'")


def test_record_video_writes_a_20_step_mp4(tmp_path: Path) -> None:
    env = gym.make("DualLidar-v0", world="hallway", trace="straight", render_mode="rgb_array")
    env = gym.wrappers.RecordVideo(
        env, str(tmp_path / "videos"), episode_trigger=lambda episode: True, video_length=20,
        disable_logger=True,
    )
    env.reset(seed=0)
    for _ in range(20):
        env.step(np.array([0.5, 0.0], dtype=np.float32))
    env.close()
    videos = sorted((tmp_path / "videos").glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000
    from moviepy import VideoFileClip

    with VideoFileClip(str(videos[0])) as clip:
        assert clip.duration * clip.fps == pytest.approx(20, abs=1.5)
        frame = clip.get_frame(0)
    assert frame.ndim == 3 and frame.std() > 0  # not a blank picture
