"""crm-grasp from Python: the Rust grasping world of "Task-Oriented Grasping Using
Reinforcement Learning with a Contextual Reward Machine" as Gymnasium environments.

    import gymnasium as gym
    import crm_grasp  # registers CrmGrasp-v0 (the gymnasium.envs entry point does too)

    env = gym.make("CrmGrasp-v0", task="mug-wrap", reward_mode="crm")
    envs = gym.make_vec("CrmGrasp-v0", num_envs=8)

See `crm_grasp.env` for the observation, the action and what `info` carries.
"""

import gymnasium

from .env import (
    ACTIONS,
    ENV_VERSION,
    FEATURES,
    OBJECTIVES,
    REWARD_MODES,
    STAGES,
    TASKS,
    BUILTIN,
    CrmGraspEnv,
    CrmGraspVectorEnv,
)

__all__ = [
    "ACTIONS",
    "ENV_VERSION",
    "FEATURES",
    "OBJECTIVES",
    "REWARD_MODES",
    "STAGES",
    "TASKS",
    "BUILTIN",
    "CrmGraspEnv",
    "CrmGraspVectorEnv",
    "register_envs",
]

ENV_ID = "CrmGrasp-v0"


def register_envs() -> None:
    """Registers `CrmGrasp-v0` (idempotent): `make` builds `CrmGraspEnv`, `make_vec` the
    native `CrmGraspVectorEnv`."""
    if ENV_ID in gymnasium.registry:
        return
    gymnasium.register(
        id=ENV_ID,
        entry_point="crm_grasp.env:CrmGraspEnv",
        vector_entry_point="crm_grasp.env:CrmGraspVectorEnv",
        # The world's own limit (600 control steps) ends episodes with `truncated`.
        max_episode_steps=None,
    )


register_envs()
