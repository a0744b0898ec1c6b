"""`CrmGraspEnv` and `CrmGraspVectorEnv`: the Rust grasping world as Gymnasium environments.

The observation is the world's global observation `u` (38 float32 features, `FEATURES`), the
action the union action space `Box(-1, 1, (8,))` (`ACTIONS`: palm dx, dy, dz and the PIP
commands of thumb, index, middle, ring and little finger). The Contextual Reward Machine
runs inside: each step's `info` says the stage the machine is in (`stage`, `stage_index`),
the reward's two parts (`intra_reward`, `transition_reward`; the reward is their sum), the
event that moved the machine (`event`) and every event that held (`events`), the stage's
`action_mask` (dimensions the stage does not act on are ignored), the `task`, and at an
episode's end its `outcome` (`success`, `failure (dropped)`, ...).

`render_mode="rgb_array"` draws the scene with the same software renderer as
`crm record --video` (no display, no GPU): `render()` returns a `(height, width, 3)` uint8
frame (default 240 x 320, `render_size=(width, height)`), so gymnasium's `RecordVideo` wraps
the single env; the vector env's `render()` returns one frame per environment.
"""

from __future__ import annotations

import os
from typing import Any, Sequence

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv

from . import _native

FEATURES: tuple[str, ...] = tuple(_native.FEATURES)
ACTIONS: tuple[str, ...] = tuple(_native.ACTIONS)
STAGES: tuple[str, ...] = tuple(_native.STAGES)
TASKS: tuple[str, ...] = tuple(_native.TASKS)
ENV_VERSION: str = _native.ENV_VERSION

BUILTIN = "builtin"
REWARD_MODES = ("crm", "dense", "sparse")
OBJECTIVES = ("scripted", "learned")

_MAX_SEED = 2**64 - 1
RENDER_MODES = ["rgb_array"]
# The frame size of `crm record --video` (grasp_sim::render::DEFAULT_SIZE).
DEFAULT_RENDER_SIZE = (320, 240)


def _render_settings(render_mode, render_size) -> tuple[str | None, tuple[int, int]]:
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"render_mode: {render_mode!r} is not one of {RENDER_MODES} or None")
    try:
        width, height = (int(v) for v in render_size)
    except (TypeError, ValueError):
        raise ValueError(f"render_size: {render_size!r} is not (width, height)") from None
    if not (16 <= width <= 4096 and 16 <= height <= 4096):
        raise ValueError(f"render_size: {render_size!r}: width and height are 16 to 4096")
    return render_mode, (width, height)


def _render(batch, k: int, size: tuple[int, int]) -> np.ndarray:
    width, height = size
    frame = np.empty((height, width, 3), dtype=np.uint8)
    batch.render(k, width, height, frame)
    return frame


def _tasks(task: str | Sequence[str] | None, world: str | None) -> list[str]:
    if task is None:
        return []
    names = [task] if isinstance(task, str) else list(task)
    if world is not None:
        # Another world's tasks are checked by the native side, which knows them.
        if not all(isinstance(name, str) for name in names):
            raise ValueError(f"task: task ids are strings, got {names!r}")
        return names
    for name in names:
        if not isinstance(name, str) or name not in TASKS:
            raise ValueError(
                f"task: unknown task {name!r} (crm_grasp.TASKS lists the {len(TASKS)} tasks)"
            )
    return names


def _world_dir(world: str | os.PathLike) -> str | None:
    """None for the built-in world, else the folder holding `world.json`."""
    if isinstance(world, str) and world == BUILTIN:
        return None
    if not isinstance(world, (str, os.PathLike)):
        raise ValueError(f"world: {world!r} is neither \"builtin\" nor a folder")
    path = os.fspath(world)
    if not os.path.isfile(os.path.join(path, "world.json")):
        raise ValueError(
            f"world: {path!r} is neither \"builtin\" nor a folder with a world.json "
            "(docs/WORLDS.md)"
        )
    return path


def _native_batch(num_envs, task, world, objective, randomize, reward_mode, hold_s):
    folder = _world_dir(world)
    if objective not in OBJECTIVES:
        raise ValueError(f"objective: {objective!r} is not one of {OBJECTIVES}")
    if reward_mode not in REWARD_MODES:
        raise ValueError(f"reward_mode: {reward_mode!r} is not one of {REWARD_MODES}")
    return _native.NativeBatch(
        num_envs, _tasks(task, folder), objective, bool(randomize), reward_mode, hold_s, folder
    )


def _check_actions(action, shape: tuple[int, ...]) -> np.ndarray:
    """The action as a C-contiguous float32 array of `shape`, or a ValueError."""
    try:
        array = np.ascontiguousarray(action, dtype=np.float32)
    except (TypeError, ValueError) as err:
        raise ValueError(f"action: not an array of numbers ({err})") from None
    if array.shape != shape:
        raise ValueError(f"action: shape {array.shape}, expected {shape}")
    if not np.isfinite(array).all():
        raise ValueError("action: NaN or infinite values (actions must be finite)")
    return array


def _seed_from(rng: np.random.Generator) -> int:
    return int(rng.integers(0, 2**63))


class CrmGraspEnv(gym.Env):
    """One grasping environment. `gymnasium.make("CrmGrasp-v0", task=..., ...)`.

    Args:
        task: a task id (`crm_grasp.TASKS`), a list of them (drawn with each episode's seed)
            or None for the whole benchmark.
        world: "builtin" (the benchmark's world) or a world folder (`world.json`: your hand
            and objects, docs/WORLDS.md; files found beside it or in `CRM_ASSETS`).
        objective: "scripted" (the paper's protocol: once the grasp is ready the arm executes
            the objective by script within that step) or "learned" (the policy executes it).
        randomize: the paper's domain randomization.
        reward_mode: "crm" (intra-stage and transition rewards), "dense" (intra-stage only,
            LPPO) or "sparse" (transition only, IPPO).
        hold_s: seconds of steady hold the judge asks (default: the paper's 5).
        render_mode: None or "rgb_array" (`render()` returns the scene as an RGB array).
        render_size: (width, height) of rendered frames.

    `reset(seed=s)` reproduces an episode bit for bit.
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": 30}

    def __init__(
        self,
        task: str | Sequence[str] | None = None,
        world: str | os.PathLike = BUILTIN,
        objective: str = "scripted",
        randomize: bool = True,
        reward_mode: str = "crm",
        hold_s: float | None = None,
        render_mode: str | None = None,
        render_size: tuple[int, int] = DEFAULT_RENDER_SIZE,
    ):
        self.render_mode, self._render_size = _render_settings(render_mode, render_size)
        self._batch = _native_batch(1, task, world, objective, randomize, reward_mode, hold_s)
        self._masks = np.asarray(self._batch.action_masks(), dtype=np.float32)
        self.observation_space = spaces.Box(-np.inf, np.inf, (len(FEATURES),), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (len(ACTIONS),), np.float32)
        self._ended = True

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if seed is not None and not 0 <= seed <= _MAX_SEED:
            raise ValueError(f"seed: {seed} is outside 0..2**64-1")
        seed = seed if seed is not None else _seed_from(self.np_random)
        obs = np.empty(len(FEATURES), dtype=np.float32)
        stage, task = self._batch.reset(0, seed, obs)
        self._ended = False
        return obs, self._start_info(stage, task)

    def step(self, action):
        if self._ended:
            raise gym.error.ResetNeeded("the episode ended: call reset() first")
        actions = _check_actions(action, self.action_space.shape)
        obs = np.empty((1, len(FEATURES)), dtype=np.float32)
        final = np.empty_like(obs)
        ((stage, intra, transition, event, events, terminated, truncated, outcome, task, _),) = (
            self._batch.step(actions[None, :], obs, final, False)
        )
        self._ended = terminated or truncated
        info = self._start_info(stage, task)
        info.update(
            intra_reward=float(intra),
            transition_reward=float(transition),
            event=event,
            events=list(events),
        )
        if outcome is not None:
            info["outcome"] = outcome
        return obs[0], float(intra + transition), terminated, truncated, info

    def render(self):
        """The scene as a `(height, width, 3)` uint8 array ("rgb_array"); None without a
        render mode, as gymnasium's environments do."""
        if self.render_mode is None:
            return None
        return _render(self._batch, 0, self._render_size)

    def _start_info(self, stage: int, task: str) -> dict[str, Any]:
        return {
            "stage": STAGES[stage],
            "stage_index": stage,
            "task": task,
            "action_mask": self._masks[stage].copy(),
        }


class CrmGraspVectorEnv(VectorEnv):
    """N grasping environments stepped on Rust threads with the GIL released.
    `gymnasium.make_vec("CrmGrasp-v0", num_envs=N, ...)`; the arguments are `CrmGraspEnv`'s.

    Autoreset is Gymnasium's same-step mode (`metadata["autoreset_mode"]`): a step that ends an
    episode returns the next episode's first observation, and `infos["final_obs"]` and
    `infos["final_info"]` (with masks `_final_obs`, `_final_info`) hold the ended one's last
    observation and step info. `reset(seed=s)` seeds environment i with s + i; the episodes
    after an autoreset draw their seeds from it, so a seeded run repeats bit for bit.
    """

    metadata = {
        "autoreset_mode": AutoresetMode.SAME_STEP,
        "render_modes": RENDER_MODES,
        "render_fps": 30,
    }

    def __init__(
        self,
        num_envs: int = 1,
        task: str | Sequence[str] | None = None,
        world: str | os.PathLike = BUILTIN,
        objective: str = "scripted",
        randomize: bool = True,
        reward_mode: str = "crm",
        hold_s: float | None = None,
        render_mode: str | None = None,
        render_size: tuple[int, int] = DEFAULT_RENDER_SIZE,
    ):
        if not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs: {num_envs!r} is not a positive integer")
        self.render_mode, self._render_size = _render_settings(render_mode, render_size)
        self.num_envs = num_envs
        self._batch = _native_batch(
            num_envs, task, world, objective, randomize, reward_mode, hold_s
        )
        self._masks = np.asarray(self._batch.action_masks(), dtype=np.float32)
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (len(FEATURES),), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (len(ACTIONS),), np.float32)
        self.observation_space = gym.vector.utils.batch_space(
            self.single_observation_space, num_envs
        )
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, num_envs)
        self._started = False

    def reset(self, *, seed: int | Sequence[int] | None = None, options: dict | None = None):
        if isinstance(seed, int) or seed is None:
            super().reset(seed=seed)
            base = seed if seed is not None else _seed_from(self.np_random)
            seeds = [base + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"seed: {len(seeds)} seeds for {self.num_envs} environments")
            super().reset(seed=seeds[0])
        for s in seeds:
            if not isinstance(s, (int, np.integer)) or not 0 <= s <= _MAX_SEED:
                raise ValueError(f"seed: {s!r} is not an integer in 0..2**64-1")
        obs = np.empty((self.num_envs, len(FEATURES)), dtype=np.float32)
        starts = [self._batch.reset(i, int(s), obs[i]) for i, s in enumerate(seeds)]
        self._started = True
        infos = {
            "stage": np.array([STAGES[st] for st, _ in starts], dtype=object),
            "stage_index": np.array([st for st, _ in starts], dtype=np.int64),
            "task": np.array([task for _, task in starts], dtype=object),
            "action_mask": self._masks[[st for st, _ in starts]],
        }
        return obs, _with_masks(infos, np.ones(self.num_envs, dtype=bool))

    def step(self, actions):
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before step()")
        actions = _check_actions(actions, self.action_space.shape)
        n = self.num_envs
        obs = np.empty((n, len(FEATURES)), dtype=np.float32)
        final = np.empty_like(obs)
        steps = self._batch.step(actions, obs, final, True)
        stage = np.empty(n, dtype=np.int64)
        task = np.empty(n, dtype=object)
        intra = np.empty(n, dtype=np.float32)
        transition = np.empty(n, dtype=np.float32)
        terminated = np.empty(n, dtype=bool)
        truncated = np.empty(n, dtype=bool)
        event = np.empty(n, dtype=object)
        events = np.empty(n, dtype=object)
        outcome = np.full(n, None, dtype=object)
        final_stage = np.empty(n, dtype=np.int64)
        final_task = np.empty(n, dtype=object)
        for i, (st, r_in, r_tr, ev, evs, term, trunc, out, tk, start) in enumerate(steps):
            intra[i], transition[i], terminated[i], truncated[i] = r_in, r_tr, term, trunc
            event[i], events[i], outcome[i] = ev, list(evs), out
            final_stage[i], final_task[i] = st, tk
            stage[i], task[i] = start if start is not None else (st, tk)
        ended = terminated | truncated
        stages = np.array([STAGES[s] for s in stage], dtype=object)
        infos = _with_masks(
            {
                "stage": stages,
                "stage_index": stage,
                "task": task,
                "action_mask": self._masks[stage],
                "intra_reward": intra,
                "transition_reward": transition,
                "event": event,
                "events": events,
            },
            np.ones(n, dtype=bool),
        )
        if ended.any():
            final_info = _with_masks(
                {
                    "stage": np.array([STAGES[s] for s in final_stage], dtype=object),
                    "stage_index": final_stage,
                    "task": final_task,
                    "intra_reward": intra,
                    "transition_reward": transition,
                    "event": event,
                    "events": events,
                    "outcome": outcome,
                },
                ended,
            )
            infos.update(
                final_obs=final, _final_obs=ended, final_info=final_info, _final_info=ended
            )
        return obs, intra + transition, terminated, truncated, infos


    def render(self):
        """One `(height, width, 3)` uint8 frame per environment (a tuple, as gymnasium's
        vector environments return them) with "rgb_array"; None without a render mode."""
        if self.render_mode is None:
            return None
        return tuple(_render(self._batch, k, self._render_size) for k in range(self.num_envs))


def _with_masks(infos: dict[str, Any], mask: np.ndarray) -> dict[str, Any]:
    """Gymnasium's vector info layout: each key beside `_key`, the environments it holds for."""
    out: dict[str, Any] = {}
    for key, value in infos.items():
        out[key] = value
        out[f"_{key}"] = mask.copy()
    return out
