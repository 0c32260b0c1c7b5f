"""Which 8-state table does Prioritized Sweeping's reward prefer? (issue 12, an exhaustive search)

Scores every distinct behaviour of a deterministic wall/no-wall table with
:func:`corridor.baseline.score_tables` (exact motion, noise-free sensing, the learner's episodes
and reward) for each contact penalty asked, and prints per penalty the best behaviours, the
route-driving one's rank, and the break-even penalty: the smallest at which no behaviour with a
wall contact earns more per step than the best route-driving one (each contact-making
behaviour's novelty surplus over it, divided by its contacts).

With ``--noisy-seeds N`` it also runs the ``--noisy-top`` best exact behaviours on the noisy
robot, each with every completion of the states it does not reach with exact motion (noise
reaches them: a table's action there matters), for N seeds of ``--steps`` steps each, and prints
that ranking: the route's table itself touches walls under noise (the aliasing of the 8
states), so the exact ranking need not hold there. With ``--penalties 1,2 --noisy-seeds 5
--model-check 20000``, under a minute on two cores.

With ``--model-check N`` it asks whether a learner that plans on the 8 states can hold the best
table even when the best table is what it sees: the robot drives the best (exact) table with 10%
random actions for N steps, in the learner's episodes and reward; the 8-state model of those
steps (transition counts and sample-mean rewards, as ``PrioritizedSweeping`` keeps them) is
solved by value iteration to its fixed point (the values Prioritized Sweeping's backups converge
to on that model, pairs tried fewer than ``optimism_visits`` times valued optimistically), and
its greedy table is compared with the best table on the states the best table reaches, for
exact and noisy motion and three seeds each.

With ``--ceiling-seeds N`` it asks, for Prioritized Sweeping runs 0..N-1 of the experiment
(its noisy robot, and exact motion), whether any 8-state table passes each run's evaluation
(:func:`corridor.baseline.passing_tables`: the ceiling of the learned share), whether the
route's table does (the best route-driving exact behaviour, its unreached states u-turn), and
where the route's table first touches a wall when it fails (state, action, the nearest node,
the heading, the two actions before).
``--ceiling-seeds 100`` takes about a minute on two cores.

    PYTHONPATH=$PWD python scripts/corridor_table_search.py [--penalties 1,2] [--steps 1000]
        [--top 5] [--noisy-seeds 3] [--model-check 20000] [--ceiling-seeds 100]

Ends with one JSON line of the figures.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from corridor.baseline import (  # the evaluation's own drive, to say where a table fails
    PrioritizedSweepingConfig,
    RecencyReward,
    TableScore,
    _drive_evaluation,
    _eval_seed,
    binary_state,
    passing_tables,
    score_tables,
)
from corridor.experiment import CorridorExperimentConfig
from corridor.maps import load_map
from corridor.world import N_ACTIONS, CorridorWorld, WorldConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))  # _args, also when loaded by path
from _args import int_at_least, numbers_at_least_zero  # noqa: E402

_NAMES = "FLRU"
# The best table's actions in states it does not reach with exact motion, for --model-check
# (where noise and the random actions reach them): u-turn, the completion of the route's table
# that touched walls least on the noisy robot (110, walls left and ahead, is not on the route).
_FILL = 3


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


def _episodes(
    table: tuple[int, ...],
    cfg: PrioritizedSweepingConfig,
    map_name: str,
    noisy: bool,
    seed: int,
    steps: int,
    epsilon: float = 0.0,
):
    """Drive ``table`` (with ``epsilon`` random actions) for ``steps`` steps in the learner's
    episodes and reward; yields ``(state, action, reward, next state, contact, circuit done)``."""
    rng = np.random.default_rng(seed)
    world = CorridorWorld(
        load_map(map_name), WorldConfig.legged_robot() if noisy else WorldConfig()
    )
    reward = RecencyReward(cfg)
    reward.visit(0, *world.pose[:2])
    s = binary_state(world.sense(rng), cfg.wall_threshold)
    ep_t = 0
    for t in range(1, steps + 1):
        a = int(rng.integers(N_ACTIONS)) if epsilon and rng.random() < epsilon else table[s]
        before = world.progress.s
        contact = world.step(a, rng)
        s2 = binary_state(world.sense(rng), cfg.wall_threshold)
        advanced = world.progress.s > before + 1e-9
        r = reward(t, *world.pose[:2], advanced=advanced, contact=contact)
        lapped = world.laps > 0
        yield s, a, r, s2, contact, lapped
        s = s2
        ep_t += 1
        if lapped or ep_t >= cfg.episode_steps:
            world.reset()
            ep_t = 0
            s = binary_state(world.sense(rng), cfg.wall_threshold)


def _noisy(args: tuple[tuple[int, ...], PrioritizedSweepingConfig, str, int, int]) -> tuple:
    table, cfg, map_name, seed, steps = args
    total, contacts, circuits = 0.0, 0, 0
    for _, _, r, _, contact, lapped in _episodes(table, cfg, map_name, True, seed, steps):
        total += r
        contacts += int(contact)
        circuits += int(lapped)
    return total / steps, contacts, circuits


def _model_greedy(
    table: tuple[int, ...],
    cfg: PrioritizedSweepingConfig,
    map_name: str,
    noisy: bool,
    seed: int,
    steps: int,
    epsilon: float = 0.1,
) -> tuple[list[int], list[bool]]:
    """The greedy table of the 8-state model learned from ``steps`` steps of ``table`` with
    ``epsilon`` random actions, and which states were reached."""
    n = np.zeros((8, N_ACTIONS))
    trans = np.zeros((8, N_ACTIONS, 8))
    rsum = np.zeros((8, N_ACTIONS))
    for s, a, r, s2, _, _ in _episodes(table, cfg, map_name, noisy, seed, steps, epsilon):
        n[s, a] += 1
        trans[s, a, s2] += 1
        rsum[s, a] += r
    trusted = n >= cfg.optimism_visits
    reward = np.where(trusted, rsum / np.maximum(n, 1), 0.0)
    p = trans / np.maximum(n, 1)[..., None]
    q = np.zeros((8, N_ACTIONS))
    for _ in range(5000):
        q_new = np.where(trusted, reward + cfg.gamma * p @ q.max(axis=1), 1 / (1 - cfg.gamma))
        if np.abs(q_new - q).max() < 1e-10:
            break
        q = q_new
    return [int(a) for a in q.argmax(axis=1)], [bool(v) for v in n.sum(axis=1) > 0]


def _first_failure(
    table: tuple[int, ...], cfg: PrioritizedSweepingConfig, world: CorridorWorld, seed: int
) -> str | None:
    """Where ``table`` first fails run ``seed``'s evaluation (the drive of
    :func:`evaluation_passes`); None if it passes. A failure reads "STATE ACTION at NODE heading H
    after PREVIOUS": the state bits and the action of the step that touched a wall (or "cap" for
    a circuit that ran out of steps), the map node nearest to where the robot stood before it,
    its compass heading then, and the two actions before it."""
    trace: list = []
    passed = _drive_evaluation(
        dict(enumerate(table)),
        world,
        cfg.wall_threshold,
        _eval_seed(seed),
        circuits=cfg.eval_circuits,
        cap=cfg.episode_steps,
        trace=trace,
    )
    if passed is True:
        return None
    (x, y, heading), s, a, contact = trace[-1]
    nodes = world.map.nodes
    node = min(nodes, key=lambda n: (nodes[n][0] - x) ** 2 + (nodes[n][1] - y) ** 2)
    compass = "ENWS"[round(heading / (np.pi / 2)) % 4]
    previous = "".join(_NAMES[t[2]] for t in trace[-3:-1]) or "-"
    where = f"at {node} heading {compass} after {previous}"
    return f"{s:03b} {_NAMES[a]} {where}" if contact else f"cap {where}"


def _ceiling(args: tuple[tuple[int, ...], PrioritizedSweepingConfig, str, bool, int]) -> tuple:
    table, cfg, map_name, noisy, seed = args
    corridor_map = load_map(map_name)
    world_config = WorldConfig.legged_robot() if noisy else WorldConfig()
    found = passing_tables(corridor_map, cfg, world_config=world_config, seed=seed)
    fail = _first_failure(table, cfg, CorridorWorld(corridor_map, world_config), seed)
    return len(found), fail


def _map_name(text: str) -> str:
    """--map: a shipped map's name or a map JSON file that loads (argparse's error otherwise)."""
    try:
        load_map(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--map", type=_map_name, default="figure2")
    ap.add_argument(
        "--penalties",
        type=numbers_at_least_zero,
        default="1,2",
        help="contact penalties, comma-separated",
    )
    ap.add_argument(
        "--steps", type=int_at_least(1), default=1000, help="learning steps scored per table"
    )
    ap.add_argument("--top", type=int, default=5)
    ap.add_argument("--noisy-seeds", type=int, default=0)
    ap.add_argument("--noisy-top", type=int, default=10)
    ap.add_argument("--model-check", type=int, default=0, metavar="N")
    ap.add_argument("--ceiling-seeds", type=int, default=0, metavar="N")
    args = ap.parse_args()
    t0 = time.perf_counter()
    base = CorridorExperimentConfig().ps
    out: dict[str, dict] = {}
    for penalty in args.penalties:
        cfg = dataclasses.replace(base, contact_penalty=penalty)
        scores = score_tables(load_map(args.map), cfg, steps=args.steps)
        routes = [i for i, sc in enumerate(scores, 1) if sc.drives_route]
        be = _break_even(scores, penalty, args.steps)
        print(f"\n## contact penalty {penalty:g}: {len(scores)} behaviours, {args.steps} steps")
        be_text = "none (no behaviour drives the route)" if be is None else f"{be:.3f}"
        print(f"route-driving behaviours at ranks {routes}; break-even penalty {be_text}")
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
            for sc in scores[: args.noisy_top]:
                fixed = dict(sc.table)
                free = [st for st in range(8) if st not in fixed]
                for combo in itertools.product(range(N_ACTIONS), repeat=len(free)):
                    full = {**fixed, **dict(zip(free, combo, strict=True))}
                    tables.append(tuple(full[st] for st in range(8)))
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
            print(
                f"\nnoisy robot, {n} seeds of {args.steps} steps: {len(rows)} tables (the "
                f"{args.noisy_top} best exact behaviours, every completion)"
            )
            print("| rank | reward/step | contacts | circuits | table (states 000..111) |")
            print("|---|---|---|---|---|")
            for i, r in enumerate(rows[: args.top], 1):
                print(f"| {i} | {r[0]:.4f} | {r[1]} | {r[2]} | {r[3]} |")
            row["noisy"] = [
                {"table": r[3], "reward": round(r[0], 6), "contacts": r[1], "circuits": r[2]}
                for r in rows[: args.top]
            ]
        if args.model_check:
            best = [_FILL] * 8
            for st, a in scores[0].table:
                best[st] = a
            on_route = {st for st, _ in scores[0].table}
            row["model_check"] = {}
            print(f"\nthe 8-state model of {args.model_check} steps of the best table (10% random)")
            print(
                "| motion | seed | model's greedy table | states where it differs (best table's) |"
            )
            print("|---|---|---|---|")
            for motion in ("exact", "noisy"):
                for seed in range(3):
                    greedy, reached = _model_greedy(
                        tuple(best), cfg, args.map, motion == "noisy", seed, args.model_check
                    )
                    diff = [
                        f"{st:03b}:{_NAMES[greedy[st]]} ({_NAMES[best[st]]})"
                        for st in range(8)
                        if st in on_route and reached[st] and greedy[st] != best[st]
                    ]
                    text = "".join(_NAMES[a] for a in greedy)
                    print(f"| {motion} | {seed} | {text} | {', '.join(diff) or 'none'} |")
                    row["model_check"][f"{motion}_{seed}"] = {"greedy": text, "differs": diff}
        out[f"{penalty:g}"] = row
    if args.ceiling_seeds:
        drives = [sc for sc in scores if sc.drives_route]
        if not drives:
            raise SystemExit(f"no 8-state table drives the route of {args.map}")
        route = [_FILL] * 8
        for st, a in drives[0].table:
            route[st] = a
        out["ceiling"] = {"route_table": "".join(_NAMES[a] for a in route)}
        for motion in ("noisy", "exact"):
            jobs = [
                (tuple(route), cfg, args.map, motion == "noisy", k)
                for k in range(args.ceiling_seeds)
            ]
            with ProcessPoolExecutor(2) as ex:
                res = list(ex.map(_ceiling, jobs))
            fails = [r[1] for r in res if r[1] is not None]
            places: dict[str, int] = {}
            for key in fails:
                places[key] = places.get(key, 0) + 1
            passable = [k for k, r in enumerate(res) if r[0] > 0]
            none_0_9 = [k for k in range(min(10, len(res))) if res[k][0] == 0]
            print(
                f"\n{motion} motion, PS runs 0-{args.ceiling_seeds - 1}: some table passes the "
                f"evaluation on {len(passable)}, the route's table "
                f"({out['ceiling']['route_table']}) on {args.ceiling_seeds - len(fails)}; runs "
                f"no table passes among 0-9: {none_0_9}"
            )
            if places:
                print(
                    "the route's table's first contacts: "
                    + ", ".join(
                        f"{k}: {v}" for k, v in sorted(places.items(), key=lambda kv: -kv[1])
                    )
                )
            out["ceiling"][motion] = {
                "seeds": args.ceiling_seeds,
                "passable": len(passable),
                "route_passes": args.ceiling_seeds - len(fails),
                "route_failures": places,
            }
    out["seconds"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
