"""CrmGrasp-v0 from Python against the Rust world it wraps (scripts/test runs this suite)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import crm_grasp

ROOT = Path(__file__).resolve().parents[2]


def crm_binary() -> Path:
    """The `crm` binary of this checkout's release build (CRM_BIN names another)."""
    if "CRM_BIN" in os.environ:
        return Path(os.environ["CRM_BIN"])
    target = Path(os.environ.get("CARGO_TARGET_DIR") or ROOT / "target")
    path = target / "release" / "crm"
    assert path.exists(), f"{path} is missing: build with `cargo build --release` or set CRM_BIN"
    return path


def test_gymnasium_check_env_passes():
    env = gym.make("CrmGrasp-v0", task="mouse-press")
    check_env(env.unwrapped, skip_render_check=True)
    assert env.observation_space.shape == (len(crm_grasp.FEATURES),) == (38,)
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (8,), np.float32)


def steer(obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Palm towards the grasp location (`rel_*`), fingers closing, with noise: an episode
    through arrive, grasp and the arm's execution."""
    rel = [crm_grasp.FEATURES.index(f) for f in ("rel_x", "rel_y", "rel_z")]
    action = np.ones(8, np.float32)
    action[:3] = np.clip(obs[rel] / 0.02, -1, 1)
    return np.clip(action + rng.normal(0, 0.1, 8), -1, 1).astype(np.float32)


@pytest.mark.parametrize("reward_mode", ["crm", "dense", "sparse"])
def test_a_seeded_episode_equals_the_rust_one_bit_for_bit(tmp_path, reward_mode):
    env = gym.make("CrmGrasp-v0", task="mug-wrap", reward_mode=reward_mode)
    rng = np.random.default_rng(3)
    obs, info = env.reset(seed=11)
    trace = [(obs, info, None, None, None, None)]
    actions = []
    for _ in range(200):
        actions.append(steer(obs, rng))
        obs, reward, terminated, truncated, info = env.step(actions[-1])
        assert obs.dtype == np.float32
        trace.append((obs, info, reward, terminated, truncated, actions[-1]))
        if terminated or truncated:
            break
    stages = [info["stage"] for _, info, *_ in trace]
    assert {"approach", "grasp", "success"} <= set(stages), stages
    assert info["outcome"] == "success"

    # The same actions from the Rust side.
    path = tmp_path / "actions.json"
    path.write_text(json.dumps([a.tolist() for a in actions]))
    rust = subprocess.run(
        [crm_binary(), "replay", "--task", "mug-wrap", "--seed", "11", "--actions", path,
         "--reward-mode", reward_mode],
        check=True, capture_output=True, text=True,
    )
    lines = [json.loads(line) for line in rust.stdout.splitlines()]
    assert len(lines) == len(trace)
    for line, (obs, info, reward, terminated, truncated, _) in zip(lines, trace):
        assert obs.view(np.uint32).tolist() == line["obs_bits"], f"step {line['step']}"
        assert info["stage"] == line["stage"]
        if line["step"] == 0:
            continue
        intra = int(np.float32(info["intra_reward"]).view(np.uint32))
        transition = int(np.float32(info["transition_reward"]).view(np.uint32))
        assert (intra, transition) == (line["intra_bits"], line["transition_bits"])
        assert (terminated, truncated) == (line["terminated"], line["truncated"])
    transitions = [line["transition_reward"] for line in lines[1:]]
    assert any(transitions) == (reward_mode != "dense")


def test_reset_with_a_seed_repeats_the_episode():
    env = gym.make("CrmGrasp-v0")
    runs = []
    for _ in range(2):
        obs, info = env.reset(seed=5)
        trace = [obs.tobytes(), info["task"]]
        for k in range(30):
            obs, reward, *_ = env.step(np.full(8, 0.1 * (k % 3), np.float32))
            trace += [obs.tobytes(), reward]
        runs.append(trace)
    assert runs[0] == runs[1]


def test_a_vector_env_steps_random_actions_through_several_stages():
    envs = gym.make_vec("CrmGrasp-v0", num_envs=4, task=["mouse-press", "mug-wrap"])
    assert isinstance(envs.unwrapped, crm_grasp.CrmGraspVectorEnv)
    assert envs.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    envs.action_space.seed(0)
    obs, infos = envs.reset(seed=0)
    assert obs.shape == (4, 38) and obs.dtype == np.float32
    stages, ended = set(infos["stage"]), 0
    for _ in range(1000):
        obs, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())
        assert obs.shape == (4, 38) and rewards.shape == (4,)
        np.testing.assert_allclose(
            rewards, infos["intra_reward"] + infos["transition_reward"], rtol=0, atol=0
        )
        stages.update(infos["stage"])
        if "final_info" in infos:
            done = infos["_final_info"]
            ended += int(done.sum())
            assert (done == (terminated | truncated)).all()
            stages.update(infos["final_info"]["stage"][done])
            assert all(o is not None for o in infos["final_info"]["outcome"][done])
            # The returned observation is the next episode's first.
            assert (infos["stage"][done] == "approach").all()
    assert ended > 0
    assert len(stages) > 1, stages


def test_vector_episodes_repeat_from_a_seed():
    def run():
        envs = crm_grasp.CrmGraspVectorEnv(num_envs=3, task="mouse-press")
        obs, _ = envs.reset(seed=42)
        out = [obs.copy()]
        rng = np.random.default_rng(1)
        for _ in range(40):
            obs, rewards, *_ = envs.step(rng.uniform(-1, 1, (3, 8)).astype(np.float32))
            out += [obs.copy(), rewards.copy()]
        return np.concatenate([a.ravel() for a in out])

    assert run().tobytes() == run().tobytes()


def test_info_carries_the_machine():
    env = gym.make("CrmGrasp-v0", task="mouse-press")
    _, info = env.reset(seed=0)
    assert info["stage"] == "approach" and info["task"] == "mouse-press"
    assert info["action_mask"].tolist() == [1, 1, 1, 0, 0, 0, 0, 0]
    _, reward, _, _, info = env.step(env.action_space.sample())
    assert {"intra_reward", "transition_reward", "event", "events", "stage_index"} <= set(info)
    assert reward == pytest.approx(info["intra_reward"] + info["transition_reward"])


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"task": "no-such-task"}, "task"),
        ({"world": "elsewhere"}, "world"),
        ({"reward_mode": "shaped"}, "reward_mode"),
        ({"objective": "dance"}, "objective"),
        ({"hold_s": 100.0}, "hold_s"),
    ],
)
def test_bad_arguments_are_value_errors_naming_them(kwargs, field):
    with pytest.raises(ValueError, match=f"^{field}:"):
        gym.make("CrmGrasp-v0", **kwargs)
    with pytest.raises(ValueError, match=f"^{field}:"):
        gym.make_vec("CrmGrasp-v0", num_envs=2, **kwargs)


@pytest.mark.parametrize(
    "bad", [np.full(8, np.nan), np.zeros(7), np.zeros((2, 8)), ["a"] * 8, [np.inf] + [0] * 7]
)
def test_a_bad_action_is_refused_and_changes_nothing(bad):
    env = gym.make("CrmGrasp-v0", task="mug-wrap").unwrapped
    twin = gym.make("CrmGrasp-v0", task="mug-wrap").unwrapped
    env.reset(seed=9)
    twin.reset(seed=9)
    with pytest.raises(ValueError, match="^action:"):
        env.step(bad)
    good = np.linspace(-0.5, 0.5, 8, dtype=np.float32)
    assert env.step(good)[0].tobytes() == twin.step(good)[0].tobytes()

    envs = crm_grasp.CrmGraspVectorEnv(num_envs=2, task="mug-wrap")
    envs.reset(seed=9)
    with pytest.raises(ValueError, match="^action:"):
        envs.step(np.stack([good, np.full(8, np.nan, np.float32)]))
    twins = crm_grasp.CrmGraspVectorEnv(num_envs=2, task="mug-wrap")
    twins.reset(seed=9)
    both = np.stack([good, good])
    assert envs.step(both)[0].tobytes() == twins.step(both)[0].tobytes()


def test_a_world_folder_runs_with_its_hand_tasks_and_sensors(tmp_path, monkeypatch):
    subprocess.run([sys.executable, str(ROOT / "scripts" / "make-test-world"), str(tmp_path)], check=True)
    monkeypatch.setenv("CRM_ASSETS", str(tmp_path / "assets"))
    env = gym.make("CrmGrasp-v0", world=tmp_path / "world", task="blocks-lift")
    obs, info = env.reset(seed=0)
    assert info["task"] == "blocks-lift"
    force = [crm_grasp.FEATURES.index(f) for f in ("force_x", "force_y", "force_z", "cone")]
    for _ in range(40):
        obs, _, terminated, truncated, info = env.step(np.array([0, 0, -1, 0, 0, 0, 0, 0], np.float32))
        # This robot senses no contact force (its world.json: sensors.without).
        assert not obs[force].any()
        if terminated or truncated:
            break
    with pytest.raises(ValueError, match="^task:.*mouse-press"):
        gym.make("CrmGrasp-v0", world=tmp_path / "world", task="mouse-press")
    (tmp_path / "world" / "hand.json").write_text(
        (tmp_path / "world" / "hand.json").read_text().replace('"thumb_ip"', '"thumb_tip"', 1)
    )
    with pytest.raises(ValueError, match="^world:.*hand.json.*fingers.thumb.joints"):
        gym.make("CrmGrasp-v0", world=tmp_path / "world")


def test_the_readme_example_runs():
    readme = (ROOT / "python" / "README.md").read_text()
    example = readme.split("```python\n")[-1].split("```")[0]
    assert "with_stage" in example
    exec(compile(example, "python/README.md", "exec"), {})
