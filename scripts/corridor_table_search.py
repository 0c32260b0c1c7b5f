"""Which 8-state table does Prioritized Sweeping's reward prefer? (issue 12, an exhaustive search)

Scores every distinct behaviour of a deterministic wall/no-wall table with
:func:`corridor.baseline.score_tables` (exact motion, noise-free sensing, the learner's episodes
and reward) for each contact penalty asked, and prints per penalty the best behaviours, the
route-driving one's rank, and the break-even penalty: the smallest at which no behaviour with a
wall contact earns more per step than the best route-driving one (each contact-making
behaviour's novelty surplus over it, divided by its contacts).

With ``--noisy-seeds N`` it also runs every behaviour (its unreached states filled with the
route's actions) on the noisy robot for N seeds of ``--steps`` steps each, and prints that
ranking: the route's table itself touches walls under noise (the aliasing of the 8 states),
so the exact ranking need not hold there. About 1.5 minutes per penalty on two cores.

    PYTHONPATH=$PWD python scripts/corridor_table_search.py [--penalties 1,2] [--steps 1000]
        [--top 5] [--noisy-seeds 3]

Ends with one JSON line of the figures.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from corridor.baseline import PrioritizedSweepingConfig, TableScore, binary_state, score_tables
from corridor.experiment import CorridorExperimentConfig
from corridor.maps import load_map
from corridor.world import CorridorWorld, WorldConfig

_NAMES = "FLRU"
# The route's table on figure2: forward in corridors and northbound at J, left at corners, right
# southbound at J, u-turn at the spur's end (state bits left/front/right; 110 is not on the route).
_ROUTE = (0, 0, 1, 1, 2, 0, 0, 3)


def _fmt(table: tuple[tuple[int, int], ...]) -> str:
    return " ".join(f"{s:03b}:{_NAMES[a]}" for s, a in table)


def _break_even(scores: list[TableScore], penalty: float, steps: int) -> float | None:
    routes = [sc for sc in scores if sc.drives_route]
    if not routes:
        return None
    base = max(sc.reward_per_step for sc in routes) * steps
    surplus = [
        (sc.reward_per_step * steps + penalty * sc.contacts - base) / sc.contacts
        for sc in scores
        if sc.contacts
    ]
    return max([0.0, *surplus])


def _noisy(args: tuple[tuple[int, ...], PrioritizedSweepingConfig, str, int, int]) -> tuple:
    table, cfg, map_name, seed, steps = args
    rng = np.random.default_rng(seed)
    world = CorridorWorld(load_map(map_name), WorldConfig.legged_robot())

    def cell() -> tuple[int, int]:
        x, y, _ = world.pose
        return (round(x / cfg.cell_size), round(y / cfg.cell_size))

    last = {cell(): 0}
    s = binary_state(world.sense(rng), cfg.wall_threshold)
    total, contacts, circuits, ep_t = 0.0, 0, 0, 0
    for t in range(1, steps + 1):
        contact = world.step(table[s], rng)
        s = binary_state(world.sense(rng), cfg.wall_threshold)
        c = cell()
        since = t - last[c] if c in last else cfg.recency_horizon
        total += min(1.0, since / cfg.recency_horizon) - cfg.contact_penalty * float(contact)
        contacts += int(contact)
        last[c] = t
        ep_t += 1
        if world.laps > 0 or ep_t >= cfg.episode_steps:
            circuits += int(world.laps > 0)
            world.reset()
            ep_t = 0
            s = binary_state(world.sense(rng), cfg.wall_threshold)
    return total / steps, contacts, circuits


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--map", default="figure2")
    ap.add_argument("--penalties", default="1,2", help="contact penalties, comma-separated")
    ap.add_argument("--steps", type=int, default=1000, help="learning steps scored per table")
    ap.add_argument("--top", type=int, default=5)
    ap.add_argument("--noisy-seeds", type=int, default=0)
    args = ap.parse_args()
    t0 = time.perf_counter()
    base = CorridorExperimentConfig().ps
    out: dict[str, dict] = {}
    for penalty in (float(p) for p in args.penalties.split(",")):
        cfg = dataclasses.replace(base, contact_penalty=penalty)
        scores = score_tables(load_map(args.map), cfg, steps=args.steps)
        routes = [i for i, sc in enumerate(scores, 1) if sc.drives_route]
        be = _break_even(scores, penalty, args.steps)
        print(f"\n## contact penalty {penalty:g}: {len(scores)} behaviours, {args.steps} steps")
        print(f"route-driving behaviours at ranks {routes}; break-even penalty {be:.3f}")
        print("| rank | reward/step | episodes | circuits | contacts | table (reached states) |")
        print("|---|---|---|---|---|---|")
        for i, sc in enumerate(scores[: args.top], 1):
            print(
                f"| {i} | {sc.reward_per_step:.4f} | {sc.episodes} | {sc.circuits} | "
                f"{sc.contacts} | {_fmt(sc.table)} |"
            )
        row = {
            "behaviours": len(scores),
            "route_ranks": routes,
            "break_even_penalty": None if be is None else round(be, 4),
            "best_table": _fmt(scores[0].table),
            "best_reward": round(scores[0].reward_per_step, 6),
            "best_contacts": scores[0].contacts,
        }
        if args.noisy_seeds:
            tables = []
            for sc in scores:
                full = list(_ROUTE)
                for s, a in sc.table:
                    full[s] = a
                if tuple(full) not in tables:
                    tables.append(tuple(full))
            jobs = [
                (t, cfg, args.map, 100 + k, args.steps)
                for t in tables
                for k in range(args.noisy_seeds)
            ]
            with ProcessPoolExecutor(2) as ex:
                res = list(ex.map(_noisy, jobs, chunksize=20))
            n = args.noisy_seeds
            rows = sorted(
                (
                    (
                        float(np.mean([r[0] for r in res[i * n : (i + 1) * n]])),
                        sum(r[1] for r in res[i * n : (i + 1) * n]),
                        sum(r[2] for r in res[i * n : (i + 1) * n]),
                        "".join(_NAMES[a] for a in t),
                    )
                    for i, t in enumerate(tables)
                ),
                reverse=True,
            )
            route = "".join(_NAMES[a] for a in _ROUTE)
            rank = 1 + [r[3] for r in rows].index(route)
            print(f"\nnoisy robot, {n} seeds: the route's table ranks {rank} of {len(rows)}")
            print("| rank | reward/step | contacts | circuits | table (states 000..111) |")
            print("|---|---|---|---|---|")
            for i, r in enumerate(rows[: args.top], 1):
                print(f"| {i} | {r[0]:.4f} | {r[1]} | {r[2]} | {r[3]} |")
            row["noisy_route_rank"] = rank
            row["noisy_best"] = {"table": rows[0][3], "reward": round(rows[0][0], 6)}
            row["noisy_route"] = {"contacts": rows[rank - 1][1], "circuits": rows[rank - 1][2]}
        out[f"{penalty:g}"] = row
    out["seconds"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
