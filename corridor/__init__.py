"""The robot corridor domain (paper Section 5.1) on pymunk.

Importing the package registers the gymnasium id ``torchcbl/Corridor-v0``
(:class:`corridor.env.CorridorEnv`; pass ``corridor_map="lshape"`` for the second map).
Only :mod:`corridor.world` imports pymunk.
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

ENV_ID = "torchcbl/Corridor-v0"

if ENV_ID not in registry:
    register(id=ENV_ID, entry_point="corridor.env:CorridorEnv")

__all__ = ["ENV_ID"]
