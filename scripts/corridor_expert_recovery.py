"""Does the corridor's scripted expert bring the robot back after a learner's mistake?

Three families of mistakes, the first two on ``figure2`` with the experiment's noisy robot
(:meth:`corridor.world.WorldConfig.legged_robot`), each circuit capped at 150 actions:

- late turns: each of the route's manoeuvres made one or two steps late (forward instead),
  40 noise seeds each (400 circuits);
- random detours: 1-4 random actions at a random step of the circuit (300 circuits; the
  family of ``tests/test_corridor_noise.py``, more seeds);
- long detours: 1-7 random actions at a random step, 600 circuits on each of the shipped maps
  (``figure2``, ``lshape``) with each robot (noisy, exact motion).

The expert drives the rest. Printed per family, for the expert as it is and, for the first two,
for the same expert without ``info["blocked"]`` (so without its rule for a robot resting
against a wall it cannot pass): circuits not finished within the cap, wall contacts per
circuit, actions per finished circuit, and the longest run of forward steps that did not move
the robot. Ends with one JSON line.

    PYTHONPATH=$PWD python scripts/corridor_expert_recovery.py

About 25-30 seconds on one core.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from corridor.env import CorridorEnv
from corridor.expert import CorridorExpert
from corridor.world import Action, WorldConfig

_F = int(Action.FORWARD)
_CAP = 150


def _late_turns(env: CorridorEnv) -> Iterator[tuple[int, Callable[[int, int], int | None]]]:
    """(seed, mistake) for each manoeuvre made one or two steps late."""
    n_turns = sum(1 for k in env.corridor_map.manoeuvres() if k != "straight")
    for turn in range(n_turns):
        for late in (1, 2):
            for seed in range(40):
                state: dict[str, Any] = {"seen": 0, "pending": None}

                def mistake(step: int, expert_action: int, turn=turn, late=late, state=state):
                    p = state["pending"]
                    if p is None and expert_action != _F:
                        if state["seen"] == turn:
                            state["pending"] = p = [late, expert_action]
                        state["seen"] += 1
                    if p is not None and p[0] >= 0:
                        p[0] -= 1
                        return _F if p[0] >= 0 else p[1]
                    return None

                yield seed, mistake


def _random_actions(
    rng_seed: int, circuits: int, last_at: int, most: int
) -> Callable[[CorridorEnv], Iterator[tuple[int, Callable[[int, int], int | None]]]]:
    """A family of detours: in each circuit, 1 to ``most`` random actions from a random step
    in [2, ``last_at``)."""

    def family(env: CorridorEnv) -> Iterator[tuple[int, Callable[[int, int], int | None]]]:
        rng = np.random.default_rng(rng_seed)
        for seed in range(circuits):
            at, n = int(rng.integers(2, last_at)), int(rng.integers(1, most + 1))
            actions = [int(a) for a in rng.integers(4, size=n)]

            def mistake(step: int, expert_action: int, at=at, actions=actions):
                return actions[step - at] if at <= step < at + len(actions) else None

            yield seed, mistake

    return family


_detours = _random_actions(0, 300, 24, 4)
_long_detours = _random_actions(1, 600, 26, 7)


def _drive(env: CorridorEnv, expert: CorridorExpert, seed: int, mistake, hide: bool) -> dict:
    obs, info = env.reset(seed=seed)
    step = stuck = longest = 0
    while True:
        shown = {k: v for k, v in info.items() if k != "blocked"} if hide else info
        a = expert(obs, shown)
        forced = mistake(step, a)
        a = a if forced is None else forced
        before = info["pose"][:2].copy()
        obs, _, terminated, truncated, info = env.step(a)
        step += 1
        moved = not np.array_equal(before, info["pose"][:2])
        stuck = stuck + 1 if (a == _F and not moved) else 0
        longest = max(longest, stuck)
        if terminated or truncated:
            return {
                "finished": bool(terminated),
                "contacts": info["contacts"],
                "steps": step,
                "longest_stuck": longest,
            }


def main() -> None:
    noisy, exact = WorldConfig.legged_robot(), WorldConfig()
    out: dict[str, Any] = {}
    print(
        "| mistakes | expert | circuits | not finished | contacts / circuit "
        "| actions / finished circuit | longest stuck run |"
    )
    print("|---|---|---|---|---|---|---|")
    without = ('without info["blocked"]', True)
    families = [
        ("late turns", _late_turns, "figure2", noisy, (("as is", False), without)),
        ("random detours", _detours, "figure2", noisy, (("as is", False), without)),
    ]
    for map_name in ("figure2", "lshape"):
        for motion, world in (("noisy", noisy), ("exact", exact)):
            name = f"long detours, {map_name}, {motion}"
            families.append((name, _long_detours, map_name, world, (("as is", False),)))
    for family, runs, map_name, world, variants in families:
        env = CorridorEnv(map_name, world, max_episode_steps=_CAP)
        expert = CorridorExpert(env.corridor_map, world)
        for label, hide in variants:
            rows = [_drive(env, expert, seed, m, hide) for seed, m in runs(env)]
            done = [r for r in rows if r["finished"]]
            fig = {
                "circuits": len(rows),
                "not_finished": len(rows) - len(done),
                "contacts_per_circuit": float(np.mean([r["contacts"] for r in rows])),
                "actions_per_finished_circuit": float(np.mean([r["steps"] for r in done])),
                "longest_stuck": max(r["longest_stuck"] for r in rows),
            }
            out[f"{family}, {label}"] = fig
            print(
                f"| {family} | {label} | {fig['circuits']} | {fig['not_finished']} "
                f"| {fig['contacts_per_circuit']:.2f} | {fig['actions_per_finished_circuit']:.1f} "
                f"| {fig['longest_stuck']} |"
            )
    print(json.dumps(out))


if __name__ == "__main__":
    # no options: --help shows the docstring, anything else is a usage error (both exit at once)
    argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    ).parse_args()
    main()
