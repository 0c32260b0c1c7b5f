"""Why the human-like driving teacher touches cars: each contact event, classified.

Drives the default teacher (:func:`sumo_scenarios.teacher.make_teacher`, seeded as
``calibrate_teacher.measure`` seeds it) alone on road segments and classifies every contact
event (a run of timesteps in contact) by the last lane change executed in the 4 steps before
its first step:

- ``rear-end, boxed in``: none; in each of the 3 steps before, no neighbour lane was safe to
  enter (by the teacher's own urgent test), nor crossable toward a shoulder;
- ``rear-end, had a way out``: none, but a way out was there in one of those steps (the
  teacher's threshold, its reaction delay or a missed press kept it in its lane);
- ``doubled press``: the change was the repeat of a doubled key press;
- ``after <move>``: the change was the teacher's own decision (``HumanDriver.last_move``:
  ``leave``, ``cross``, ``better`` or ``return``), executed at once or after its delay.

This is how the two defects fixed on 2026-11-23 were found (with the delay and slips off, 79
of 136 events were rear-ends in the middle lane, boxed in); the same classification of today's
teacher shows where its contacts now come from.

Usage: python scripts/driving_teacher_contacts.py [--seeds 100] [--first-seed 1000]
    [--steps 1000] [--scenario train|eval] [--no-delay] [--no-slips]
The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter

import numpy as np

LOOK_BACK = 4  # steps before a contact in which a lane change is blamed for it
BOXED_STEPS = 3  # steps before a contact in which no way out means "boxed in"


def _ways_out(driver, obs: np.ndarray, info: dict) -> bool:
    """Whether the teacher had a neighbour lane to go to (safe to enter when urgent, or
    crossable toward a shoulder), judged as it judges."""
    from sumo_scenarios.teacher import _read

    d, lane, closing, dt = _read(obs, info)
    return bool(driver._ways_out(lane, d, closing, dt, True))


def classify(
    seeds: range, steps: int = 1000, scenario: str = "train", timing=None
) -> dict[str, object]:
    """Drive the default teacher on ``seeds`` of ``scenario`` for ``steps`` steps each ->
    {"steps", "contact_steps", "collisions" (share of steps in contact), "events",
    "causes" {cause: count}, "lanes_of_rear_ends" {lane: count}}."""
    from sumo_scenarios.env import DrivingEnv
    from sumo_scenarios.scenarios import SCENARIOS
    from sumo_scenarios.teacher import make_teacher

    offset = 10_000 if scenario == "eval" else 0
    env = DrivingEnv(scenario=SCENARIOS[scenario], max_episode_steps=10**6)
    causes: Counter = Counter()
    rear_lanes: Counter = Counter()
    n_steps = contact_steps = 0
    try:
        for seed in seeds:
            teacher = make_teacher(offset + seed, timing=timing)
            driver = teacher.teacher
            obs, info = env.reset(seed=seed)
            # per step: (action, why, a way out was there, lane, this press will be doubled)
            history: list[tuple[int, str, bool, int, bool]] = []
            in_contact = False
            for _ in range(steps):
                way_out = _ways_out(driver, obs, info)
                doubled_before = teacher.n_doubled
                repeat = bool(history) and history[-1][4]
                action = teacher(obs, info)
                if action == 0:
                    why = "stay"
                elif repeat:
                    why = "doubled press"
                else:
                    why = f"after {driver.last_move}"
                lane = int(info["lane"])
                history.append((action, why, way_out, lane, teacher.n_doubled > doubled_before))
                obs, _, _, _, info = env.step(action)
                n_steps += 1
                contact = bool(info["contact"])
                contact_steps += contact
                if contact and not in_contact:
                    changes = [h for h in history[-LOOK_BACK:] if h[0] != 0]
                    if changes:
                        causes[changes[-1][1]] += 1
                    else:
                        boxed = not any(h[2] for h in history[-BOXED_STEPS:])
                        causes["rear-end, boxed in" if boxed else "rear-end, had a way out"] += 1
                        rear_lanes[history[-1][3]] += 1
                in_contact = contact
    finally:
        env.close()
    return {
        "steps": n_steps,
        "contact_steps": contact_steps,
        "collisions": contact_steps / max(n_steps, 1),
        "events": sum(causes.values()),
        "causes": dict(causes.most_common()),
        "lanes_of_rear_ends": {str(k): v for k, v in sorted(rear_lanes.items())},
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=100)
    p.add_argument("--first-seed", type=int, default=1000)
    p.add_argument("--steps", type=int, default=1000)
    p.add_argument("--scenario", choices=("train", "eval"), default="train")
    p.add_argument("--no-delay", action="store_true", help="without the reaction delay")
    p.add_argument("--no-slips", action="store_true", help="without missed/doubled presses")
    a = p.parse_args(argv)
    if a.seeds < 1 or a.steps < 1 or a.first_seed < 0:
        print("error: --seeds and --steps must be >= 1, --first-seed >= 0", file=sys.stderr)
        return 2
    from sumo_scenarios.calibrate_teacher import timing_config

    seeds = range(a.first_seed, a.first_seed + a.seeds)
    r = classify(seeds, a.steps, a.scenario, timing_config(a.no_delay, a.no_slips))
    print(
        f"{a.scenario} segments {seeds.start}-{seeds.stop - 1}, {r['steps']} steps: "
        f"{100 * r['collisions']:.3f} % in contact, {r['events']} contact events"
    )
    for cause, n in r["causes"].items():
        print(f"  {n:5d}  {cause}")
    print(f"  rear-ends by lane (0 right shoulder .. 4 left shoulder): {r['lanes_of_rear_ends']}")
    print(json.dumps({"scenario": a.scenario, "first_seed": a.first_seed, "seeds": a.seeds, **r}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
