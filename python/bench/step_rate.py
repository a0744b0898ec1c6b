"""Control steps per second of `gymnasium.make_vec("CrmGrasp-v0", num_envs=N)` stepped from
Python, beside `crm bench env` (docs/BENCHMARKS.md, "The environment from Python").

    python python/bench/step_rate.py [--seconds 20] [--envs 2 8 16 32]

Actions are `crm bench env`'s random ones expressed in the union space (palm +-0.01 m, finger
commands 0.1 * (u + 0.3) rad per step, u uniform in [-1, 1]); the stage's mask applies, as in
training. Prints one JSON object.
"""

import argparse
import json
import os
import time

import gymnasium as gym
import numpy as np

import crm_grasp  # noqa: F401  (registers CrmGrasp-v0)

# The grasping spec's scales: palm 0.02 m and fingers 0.2 rad per unit of action.
PALM_SCALE, FINGER_SCALE = 0.02, 0.2


def rate(num_envs: int, seconds: float, seed: int) -> dict:
    envs = gym.make_vec("CrmGrasp-v0", num_envs=num_envs)
    envs.reset(seed=seed)
    rng = np.random.default_rng(seed)
    palm = 0.01 / PALM_SCALE
    steps, episodes = 0, 0
    for _ in range(20):  # warm-up
        envs.step(np.zeros((num_envs, 8), np.float32))
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        u = rng.uniform(-1, 1, (num_envs, 8)).astype(np.float32)
        action = np.empty_like(u)
        action[:, :3] = palm * u[:, :3]
        action[:, 3:] = 0.1 * (u[:, 3:] + 0.3) / FINGER_SCALE
        _, _, terminated, truncated, _ = envs.step(action)
        steps += num_envs
        episodes += int((terminated | truncated).sum())
    elapsed = time.perf_counter() - start
    return {"num_envs": num_envs, "control_steps_per_sec": steps / elapsed,
            "steps": steps, "episodes_ended": episodes}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--envs", type=int, nargs="+", default=[2, 8, 16, 32])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    runs = [rate(n, args.seconds, args.seed) for n in args.envs]
    print(json.dumps({"cores": os.cpu_count(), "runs": runs}))


if __name__ == "__main__":
    main()
