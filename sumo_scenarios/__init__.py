"""The highway driving domain (paper Section 5.2) on SUMO through libsumo.

Import-light: only :mod:`sumo_scenarios.sim` imports libsumo. The environment is registered with
gymnasium as ``torchcbl/Driving-v0``::

    env = gymnasium.make("torchcbl/Driving-v0", scenario="train")
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

ENV_ID = "torchcbl/Driving-v0"

if ENV_ID not in registry:
    register(id=ENV_ID, entry_point="sumo_scenarios.env:DrivingEnv", max_episode_steps=None)

__all__ = ["ENV_ID"]
