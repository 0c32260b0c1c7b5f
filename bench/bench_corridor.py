"""Speed of the corridor env: actions per second including the 15-reading sensing.

Drives the scripted expert (exact motion, and with the legged robot's motion noise) and random
actions through ``CorridorEnv`` on the default map and prints a table, then ONE line of JSON.
Acceptance: >= 1,000 actions/s in every row.
Usage: .venv/bin/python bench/bench_corridor.py [--actions 5000] [--repeats 3]
"""

from __future__ import annotations

import json
import time

import numpy as np
from _parser import Parser

from corridor.env import CorridorEnv
from corridor.expert import CorridorExpert
from corridor.world import WorldConfig


def _run(policy: str, n: int, seed: int = 0) -> float:
    world = WorldConfig.legged_robot() if policy == "expert_noisy" else WorldConfig()
    env = CorridorEnv(world_config=world)
    expert = CorridorExpert(env.corridor_map, world)
    rng = np.random.default_rng(seed)
    obs, info = env.reset(seed=seed)
    t0 = time.perf_counter()
    for _ in range(n):
        a = int(rng.integers(4)) if policy == "random" else expert(obs, info)
        obs, _, terminated, truncated, info = env.step(a)
        if terminated or truncated:
            obs, info = env.reset()
    return n / (time.perf_counter() - t0)


def main() -> None:
    parser = Parser(__doc__)
    parser.add_argument(
        "--actions", type=int, default=5000, help="actions timed per run (default %(default)s)"
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=3,
        help="runs per row, seeds 0..N-1; the best rate is shown (default %(default)s)",
    )
    ns = parser.parse_args()
    for flag, v in (("--actions", ns.actions), ("--repeats", ns.repeats)):
        if v < 1:
            parser.error(f"{flag}: expected an int >= 1, got {v}")
    rows = {}
    for policy in ("expert", "expert_noisy", "random"):
        rates = [_run(policy, ns.actions, seed=k) for k in range(ns.repeats)]
        rows[policy] = max(rates)
    print(f"{'policy':<12} | {'actions/s (best of ' + str(ns.repeats) + ')':>24}")
    print("-" * 39)
    for k, v in rows.items():
        print(f"{k:<12} | {v:>24,.0f}")
    print(f"target >= 1,000 actions/s in every row: {'ok' if min(rows.values()) >= 1000 else 'NO'}")
    print(
        json.dumps(
            {
                "bench": "corridor_env",
                "actions": ns.actions,
                "repeats": ns.repeats,  # each rate is the best of this many runs
                "expert_actions_per_s": round(rows["expert"], 1),
                "expert_noisy_actions_per_s": round(rows["expert_noisy"], 1),
                "random_actions_per_s": round(rows["random"], 1),
                "ok": min(rows.values()) >= 1000,
            }
        )
    )


if __name__ == "__main__":
    main()
