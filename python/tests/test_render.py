"""render_mode="rgb_array": the software renderer's frames from Python, gymnasium's own render
check, and RecordVideo writing an MP4 of an episode (decoded back with imageio-ffmpeg)."""

from pathlib import Path

import gymnasium as gym
import imageio_ffmpeg
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.wrappers import RecordVideo

import crm_grasp

OBJECT_BLUE = np.array([70, 130, 200])


def steer(obs: np.ndarray) -> np.ndarray:
    rel = [crm_grasp.FEATURES.index(f) for f in ("rel_x", "rel_y", "rel_z")]
    action = np.ones(8, np.float32)
    action[:3] = np.clip(obs[rel] / 0.02, -1, 1)
    return action


def blue_share(frame: np.ndarray) -> float:
    """The share of pixels in the object's hue (blue above red and green)."""
    r, g, b = (frame[..., k].astype(int) for k in range(3))
    return float(((b > r + 30) & (b > g)).mean())


def test_an_rgb_array_frame_shows_the_scene_and_passes_gymnasiums_render_check():
    env = gym.make("CrmGrasp-v0", task="mouse-press", render_mode="rgb_array")
    check_env(env.unwrapped)
    obs, _ = env.reset(seed=3)
    frame = env.render()
    assert frame.shape == (240, 320, 3) and frame.dtype == np.uint8
    # The object sits in the frame, the hand above it, on a background that is neither.
    assert 0.005 < blue_share(frame) < 0.5
    warm = (frame[..., 0].astype(int) > frame[..., 2].astype(int) + 25).mean()
    assert warm > 0.05
    # The same state draws the same bytes; a step moves the hand.
    assert np.array_equal(frame, env.render())
    env.step(steer(obs))
    assert not np.array_equal(frame, env.render())
    big = gym.make("CrmGrasp-v0", task="mouse-press", render_mode="rgb_array", render_size=(64, 48))
    big.reset(seed=3)
    assert big.render().shape == (48, 64, 3)


def test_without_a_render_mode_render_returns_none_and_bad_settings_are_refused():
    env = gym.make("CrmGrasp-v0", task="mouse-press")
    env.reset(seed=0)
    assert env.render() is None
    for kwargs, field in [
        ({"render_mode": "ansi"}, "render_mode"),
        ({"render_mode": "rgb_array", "render_size": (8, 8)}, "render_size"),
        ({"render_mode": "rgb_array", "render_size": "big"}, "render_size"),
    ]:
        with pytest.raises(ValueError, match=f"^{field}:"):
            gym.make("CrmGrasp-v0", **kwargs)
        with pytest.raises(ValueError, match=f"^{field}:"):
            gym.make_vec("CrmGrasp-v0", num_envs=2, **kwargs)


def test_a_vector_env_renders_one_frame_per_environment():
    envs = gym.make_vec("CrmGrasp-v0", num_envs=3, task=["mouse-press", "mug-wrap"],
                        render_mode="rgb_array")
    envs.reset(seed=5)
    frames = envs.render()
    assert isinstance(frames, tuple) and len(frames) == 3
    assert all(f.shape == (240, 320, 3) and f.dtype == np.uint8 for f in frames)
    assert not np.array_equal(frames[0], frames[1])


def test_record_video_writes_an_episode_that_decodes_frame_for_frame(tmp_path: Path):
    env = gym.make("CrmGrasp-v0", task="mouse-press", render_mode="rgb_array")
    env = RecordVideo(env, video_folder=str(tmp_path), episode_trigger=lambda e: True,
                      name_prefix="crm", disable_logger=True)
    obs, _ = env.reset(seed=7)
    first = env.unwrapped.render()
    steps, done = 0, False
    while not done:
        obs, _, terminated, truncated, info = env.step(steer(obs))
        steps += 1
        done = terminated or truncated
    assert info["outcome"] == "success"
    env.close()
    videos = sorted(tmp_path.glob("*.mp4"))
    assert len(videos) == 1, list(tmp_path.iterdir())
    reader = imageio_ffmpeg.read_frames(str(videos[0]))
    meta = next(reader)
    assert tuple(meta["size"]) == (320, 240)
    frames = [np.frombuffer(f, np.uint8).reshape(240, 320, 3) for f in reader]
    # The reset's frame and one a step.
    assert len(frames) == steps + 1
    # Lossy (H.264), yet close to the frame rendered at the reset.
    assert np.abs(frames[0].astype(int) - first.astype(int)).mean() < 6
    assert abs(blue_share(frames[0]) - blue_share(first)) < 0.01
