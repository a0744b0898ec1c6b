#!/usr/bin/env python3
"""How a grasp depends on how fast the fingers close after the first touch.

usage: scripts/closing-rate.py WORLD TASK RATE [RATE ...] [--seeds K]

A scripted controller in the Gymnasium environment (`crm_grasp`, the Python package): it
approaches the task's grasp location from above (the palm 8 cm over it until lined up within
1 cm), lines up in the grasp stage for up to 10 steps, then closes the topology's thumb and
index at the full finger step until the first contact and at RATE of it after, holding when
the grip reaches 0.295 of the object's force limit (the knife's carrying grip, 11.8 N of 40);
the paper's protocol executes the objective once the grasp is ready. It prints, per rate, the
outcomes of seeds 0..K-1. The scripted oracle (`crm oracle`) closes at 0.3 after the touch;
a policy chooses its own rate each step. docs/WORLDS.md, "The Ability Hand", uses it on
`knife-pull`.
"""

import argparse
import collections

import numpy as np

import crm_grasp
from crm_grasp.env import CrmGraspEnv

INDEX = {name: i for i, name in enumerate(crm_grasp.FEATURES)}
WANTED_GRIP = 0.295


def episode(env, seed, rate):
    obs, info = env.reset(seed=seed)
    lined_up, grasp_steps = False, 0
    while True:
        u = obs["observation"] if isinstance(obs, dict) else obs
        rel = np.array([u[INDEX["rel_x"]], u[INDEX["rel_y"]], u[INDEX["rel_z"]]])
        action = np.zeros(len(crm_grasp.ACTIONS), dtype=np.float32)
        if info.get("stage") == "approach":
            lined_up |= bool(np.linalg.norm(rel[:2]) <= 0.01)
            goal = rel if lined_up else rel + np.array([0.0, 0.0, 0.08])
            action[:3] = np.clip(goal / 0.01, -1, 1)
        else:
            grasp_steps += 1
            if grasp_steps <= 10 and np.abs(rel).max() > 0.003:
                action[:3] = np.clip(rel / 0.005, -1, 1)
            elif u[INDEX["grip"]] < WANTED_GRIP:
                action[3] = action[4] = 1.0 if u[INDEX["n_c"]] == 0 else rate
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            return info.get("outcome")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("world")
    parser.add_argument("task")
    parser.add_argument("rates", nargs="+", type=float)
    parser.add_argument("--seeds", type=int, default=10)
    args = parser.parse_args()
    if any(not 0 < r <= 1 for r in args.rates):
        raise SystemExit(f"RATE: each must be in (0, 1], got {args.rates}")
    env = CrmGraspEnv(task=args.task, world=args.world)
    for rate in args.rates:
        outcomes = collections.Counter(episode(env, seed, rate) for seed in range(args.seeds))
        print(f"{rate}: {dict(sorted(outcomes.items()))}", flush=True)


if __name__ == "__main__":
    main()
