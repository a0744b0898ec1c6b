#!/usr/bin/env python3
"""Stable-Baselines3's PPO with VecNormalize (the authors' stack) on CrmGrasp-v0, for the
side-by-side with `crm train` in docs/BENCHMARKS.md ("Stable-Baselines3 on the same world").

    python scripts/sb3_compare.py --config paper   --minutes 20 --seed 1 --out runs/sb3-paper.jsonl
    python scripts/sb3_compare.py --config shipped --minutes 20 --seed 1 --out runs/sb3-shipped.jsonl

The world is the whole benchmark (random tasks over all 26, randomization on, the paper's
protocol), as `crm train` without `--task`. The policy sees the global observation and the
CRM stage one-hot (CRM-PPO's input); the reward is the CRM's, intra-stage plus transition.
`paper`: the paper's PPO settings (`PpoConfig`'s defaults: learning rate 3e-5 with the
paper's steps, 2,048 samples per rollout, minibatch 64, 10 epochs); `shipped`: the shipped
model's recipe (models/crm-ppo.config.json: 3e-4, 8,192 per rollout, minibatch 512,
log-std -0.5). Both: gamma 0.99, lambda 0.95, clip 0.2, value coef 0.5, grad norm 0.5,
256x256 tanh networks, VecNormalize on observations and rewards, 16 environments. Training
stops when 99% of the last `--window` episodes succeeded or after `--minutes`.

Writes one JSON line per rollout: wall seconds, env steps, success over the last 100 and
over the window, env steps/s, and the update's samples/s (SB3's rollout and update timed
apart). Needs `pip install stable-baselines3 torch` and the package (`pip install ./python`).
"""

import argparse
import json
import time
from collections import deque

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

import crm_grasp

CONFIGS = {
    # crates/api/src/config.rs, PpoConfig::default() (the paper's section V-B).
    "paper": dict(learning_rate=3e-5, rollout=2048, batch_size=64, log_std_init=0.0),
    # models/crm-ppo.config.json (models/README.md), at a constant learning rate.
    "shipped": dict(learning_rate=3e-4, rollout=8192, batch_size=512, log_std_init=-0.5),
}


class CrmSb3VecEnv(VecEnv):
    """`CrmGraspVectorEnv` behind SB3's VecEnv: the stage one-hot appended to the
    observation, SB3's `terminal_observation` and `is_success` in each ended env's info."""

    def __init__(self, num_envs: int, seed: int):
        self.envs = crm_grasp.CrmGraspVectorEnv(num_envs=num_envs)
        self.stages = len(crm_grasp.STAGES)
        width = len(crm_grasp.FEATURES) + self.stages
        obs_space = spaces.Box(-np.inf, np.inf, (width,), np.float32)
        super().__init__(num_envs, obs_space, self.envs.single_action_space)
        self._seed = seed
        self._actions = None

    def _with_stage(self, obs, stage_index):
        return np.concatenate([obs, np.eye(self.stages, dtype=np.float32)[stage_index]], axis=1)

    def reset(self):
        obs, info = self.envs.reset(seed=self._seed)
        return self._with_stage(obs, info["stage_index"])

    def step_async(self, actions):
        self._actions = np.clip(actions, -1, 1).astype(np.float32)

    def step_wait(self):
        obs, rewards, terminated, truncated, info = self.envs.step(self._actions)
        out = self._with_stage(obs, info["stage_index"])
        dones = terminated | truncated
        infos = [{} for _ in range(self.num_envs)]
        if dones.any():
            final = info["final_info"]
            for i in np.flatnonzero(dones):
                last = self._with_stage(info["final_obs"][i : i + 1], final["stage_index"][i : i + 1])
                infos[i] = {
                    "terminal_observation": last[0],
                    "TimeLimit.truncated": bool(truncated[i] and not terminated[i]),
                    "is_success": final["outcome"][i] == "success",
                }
        return out, rewards.astype(np.float32), dones, infos

    def close(self):
        pass

    def get_attr(self, attr_name, indices=None):
        return [None] * self.num_envs

    def set_attr(self, attr_name, value, indices=None):
        pass

    def env_method(self, method_name, *args, indices=None, **kwargs):
        return [None] * self.num_envs

    def env_is_wrapped(self, wrapper_class, indices=None):
        return [False] * self.num_envs


class Log(BaseCallback):
    """One JSON line per rollout; stops at the early-stop rule or the time budget."""

    def __init__(self, out, minutes: float, window: int):
        super().__init__()
        self.out, self.deadline, self.window = out, minutes * 60.0, window
        self.last_100, self.last_window = deque(maxlen=100), deque(maxlen=window)
        self.start = time.perf_counter()
        self.rollout_start = self.start
        self.update_s = 0.0
        self.update_samples = 0
        self.rollout_end = None

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            if "is_success" in info:
                self.last_100.append(info["is_success"])
                self.last_window.append(info["is_success"])
        return True

    def _on_rollout_start(self) -> None:
        if self.rollout_end is not None:  # the time since the last rollout was the update
            self.update_s += time.perf_counter() - self.rollout_end
            self.update_samples += self.model.n_steps * self.model.n_envs * self.model.n_epochs
        self.rollout_start = time.perf_counter()

    def _on_rollout_end(self) -> None:
        now = time.perf_counter()
        self.rollout_end = now
        wall = now - self.start
        line = {
            "wall_s": wall,
            "steps": self.num_timesteps,
            "episodes": len(self.last_window),
            "success_last_100": float(np.mean(self.last_100)) if self.last_100 else None,
            "success_window": float(np.mean(self.last_window)) if self.last_window else None,
            "env_steps_per_s": self.model.n_steps * self.model.n_envs / (now - self.rollout_start),
            "update_samples_per_s": self.update_samples / self.update_s if self.update_s else None,
        }
        self.out.write(json.dumps(line) + "\n")
        self.out.flush()
        full = len(self.last_window) == self.window
        if (full and np.mean(self.last_window) >= 0.99) or wall >= self.deadline:
            self.model._crm_stop = True


class StopOnFlag(BaseCallback):
    def _on_step(self) -> bool:
        return not getattr(self.model, "_crm_stop", False)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", choices=sorted(CONFIGS), required=True)
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--envs", type=int, default=16)
    parser.add_argument("--steps", type=int, default=2_000_000,
                        help="the budget the learning-rate steps are laid over (crm train's --steps)")
    parser.add_argument("--window", type=int, default=1000)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", required=True)
    parser.add_argument("--save", help="a folder for the final model and VecNormalize statistics")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    cfg = CONFIGS[args.config]
    env = VecNormalize(CrmSb3VecEnv(args.envs, args.seed), norm_obs=True, norm_reward=True,
                       gamma=0.99)
    total = args.steps

    def schedule(remaining: float) -> float:  # the paper's steps over the run's progress
        progress = 1.0 - remaining
        return cfg["learning_rate"] * (1.0 if progress < 0.4 else 0.9 if progress < 0.7 else 0.8)

    model = PPO(
        "MlpPolicy", env, seed=args.seed, device="cpu",
        learning_rate=schedule, n_steps=cfg["rollout"] // args.envs, batch_size=cfg["batch_size"],
        n_epochs=10, gamma=0.99, gae_lambda=0.95, clip_range=0.2, ent_coef=0.0, vf_coef=0.5,
        max_grad_norm=0.5, target_kl=0.02,
        policy_kwargs=dict(net_arch=dict(pi=[256, 256], vf=[256, 256]),
                           activation_fn=torch.nn.Tanh, log_std_init=cfg["log_std_init"]),
    )
    with open(args.out, "w") as out:
        log = Log(out, args.minutes, args.window)
        model.learn(total_timesteps=total, callback=[log, StopOnFlag()])
    if args.save:
        model.save(f"{args.save}/ppo.zip")
        env.save(f"{args.save}/vecnormalize.pkl")
    print(json.dumps({"config": args.config, "seed": args.seed, "steps": model.num_timesteps,
                      "minutes": (time.perf_counter() - log.start) / 60}))


if __name__ == "__main__":
    main()
