"""Calibrate the human-like driving teacher to the issue's observable targets (issue 11, item 2).

``python -m sumo_scenarios.calibrate_teacher`` measures the default teacher (:func:`make_teacher`
on the ``train`` traffic) the way ``tests/test_driving_teacher.py`` does: 100 training segments
x 1000 steps (0-99; 30 until 2026-11-25, whose standard error of about 0.09 point was too coarse
for the 0.5 % target), reaction delay and slips included, and prints the targets beside the
measurement.
``--seeds 100 --first-seed 1000`` measures it out of sample, ``--scenario eval`` on the
evaluation traffic, ``--no-delay`` / ``--no-slips`` without its reaction delay or its missed
and doubled key presses (what each adds to the collisions).

``--search N`` runs the systematic search the defaults came from: N random perturbations
(each float parameter x U(0.85, 1.15), a range's width x U(0.7, 1.3), home weights x U(0.85,
1.18) renormalised, counts such as ``cross_steps`` kept; the left lane's mean spacing from
``--left-spacings``) of the best ``--keep`` settings found so far (``--history``, JSON lines,
appended to), each measured on ``--seeds`` segments from ``--first-seed`` (use other segments
than the final check), in 2 processes (libsumo holds one simulation per process). The objective
is the calibration targets only (:func:`penalty`), never a learning result. A search ranks
settings on few segments, so its best is partly luck: ``--rescore K`` re-measures the K best of
the history on ``--seeds`` other segments and ranks them by those. The defaults came from
``--search 48 --seeds 30 --first-seed 200 --left-spacings 120 --rng R`` for R = 1-10 (480
settings, a fresh history started from the previous defaults, after the ego's decel was made a
normal car's on 2026-11-25), then ``--rescore 10 --seeds 100 --first-seed 300`` (the history
and the rescore are in ``docs/data/``, ``teacher_*_2026-11-25``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from concurrent.futures import as_completed
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np

from torchcbl.evaluation import worker_pool

CHECK_SEGMENTS = 100  # training segments 0-99: the calibration check (and the tests')

TARGETS = (
    ("collisions %", "<= 0.5"),
    ("left three lanes %", ">= 85"),
    ("each of middle, left, left shoulder %", ">= 10"),
    ("right lane + right shoulder %", "> 0 and <= 15"),
    ('"stay" share of answers %', "< 80"),
)


def measure(
    driver: dict[str, Any],
    spacing: tuple[float, float, float] | None = None,
    seeds: range = range(CHECK_SEGMENTS),
    steps: int = 1000,
    *,
    scenario: str = "train",
    timing: Any = None,
) -> dict[str, Any]:
    """Drive the teacher (``HumanDriverConfig(**driver)``; ``timing`` a
    :class:`~torchcbl.teachers.HumanTimingConfig`, None for the default) alone on segments
    ``seeds`` of ``scenario`` (``train``, or ``eval`` with the teacher seeded as the experiment
    seeds it there, 10,000 + segment) for ``steps`` steps each (with the lanes' mean spacings
    ``spacing``, m; None: the scenario's). Returns collision share, lane shares [5] and "stay"
    share."""
    from sumo_scenarios import metrics
    from sumo_scenarios.env import DrivingEnv
    from sumo_scenarios.scenarios import SCENARIOS
    from sumo_scenarios.teacher import HumanDriverConfig, make_teacher

    base = SCENARIOS[scenario]
    chosen = base if spacing is None else dataclasses.replace(base, mean_spacing_m=spacing)
    offset = 10_000 if scenario == "eval" else 0
    cfg = HumanDriverConfig(**driver)
    env = DrivingEnv(scenario=chosen, max_episode_steps=10**6)
    contacts, lanes, answers = [], [], []
    try:
        for seed in seeds:
            teacher = make_teacher(offset + seed, driver=cfg, timing=timing)
            obs, info = env.reset(seed=seed)
            for _ in range(steps):
                a = teacher(obs, info)
                answers.append(a)
                obs, _, _, _, info = env.step(a)
                contacts.append(info["contact"])
                lanes.append(info["lane"])
    finally:
        env.close()
    return {
        "driver": driver,
        "spacing": list(chosen.mean_spacing_m),
        "collisions": metrics.collision_rate(contacts),
        "lanes": metrics.lane_distribution(lanes).tolist(),
        "stay": float(np.mean(np.asarray(answers) == 0)),
    }


def timing_config(no_delay: bool = False, no_slips: bool = False) -> Any:
    """The teacher's default :class:`~torchcbl.teachers.HumanTimingConfig`, without its reaction
    delay (``no_delay``) or its missed and doubled key presses (``no_slips``)."""
    from torchcbl.teachers import HumanTimingConfig

    timing: dict[str, Any] = {}
    if no_delay:
        timing["delay_probs"] = (1.0,)
    if no_slips:
        timing.update(miss_prob=0.0, double_prob=0.0)
    return HumanTimingConfig(**timing)


def penalty(r: dict[str, Any]) -> float:
    """How far a measurement misses the targets: collisions per 0.05 point above 0.42 % (a margin
    under 0.5 % for the move from search segments to the check's), every share per point."""
    lanes = np.asarray(r["lanes"])
    p = max(0.0, r["collisions"] - 0.0042) / 0.0005
    p += max(0.0, 0.85 - lanes[2:].sum()) / 0.01
    p += sum(max(0.0, 0.10 - lanes[k]) / 0.01 for k in (2, 3, 4))
    p += max(0.0, lanes[:2].sum() - 0.15) / 0.01 + (10.0 if lanes[:2].sum() == 0 else 0.0)
    return p + max(0.0, r["stay"] - 0.795) / 0.01


def _perturb(base: dict[str, Any], rng: np.random.Generator) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in base.items():
        if k == "home_weights":
            w = np.clip(np.asarray(v) * rng.uniform(0.85, 1.18, 3), 0.01, None)
            out[k] = (w / w.sum()).tolist()
        elif isinstance(v, int) and not isinstance(v, bool):
            out[k] = v  # a count (cross_steps): structural, not searched
        elif isinstance(v, list | tuple):
            lo = v[0] * rng.uniform(0.85, 1.15)
            out[k] = [lo, lo + (v[1] - v[0]) * rng.uniform(0.7, 1.3)]
        else:
            out[k] = v * rng.uniform(0.85, 1.15)
    out["urgent_ttc_s"] = min(out["urgent_ttc_s"], out["enter_ttc_s"])
    out["home_every_s"] = max(out["home_every_s"], 0.5)
    out["return_behind_m"][0] = max(out["return_behind_m"][0], 5.0)
    out["behind_m"] = max(out["behind_m"], 5.0)
    out["margin_s"][0] = 0.0
    return out


def _defaults() -> dict[str, Any]:
    from sumo_scenarios.teacher import HumanDriverConfig

    cfg = HumanDriverConfig()
    return {f.name: getattr(cfg, f.name) for f in dataclasses.fields(HumanDriverConfig)}


def _pool(running: str, after: str) -> Any:
    """Two spawned workers (libsumo holds one simulation per process); a worker that dies (the
    out-of-memory killer) stops the command with a RuntimeError saying so, where a
    ``multiprocessing.Pool`` would have waited for its result for ever."""
    return worker_pool(2, get_context("spawn"), running=running, after=after)


def _job(args: tuple) -> dict[str, Any]:
    driver, spacing, seeds, steps = args
    return measure(driver, tuple(spacing), seeds, steps)


_HISTORY_KEYS = ("driver", "spacing", "collisions", "lanes", "stay")


def _read_history(path: Path) -> list[dict[str, Any]]:
    """The measurements of a search history (JSON lines, as a search appends them), [] when
    ``path`` does not exist. ValueError, naming the file and the line, for anything else: a
    directory, a line that is not JSON, or one that is not a measurement of a
    :class:`HumanDriverConfig` (another file given by mistake, or a history of an older teacher
    whose settings have other names)."""
    from sumo_scenarios.teacher import HumanDriverConfig

    if not path.exists():
        return []
    what = "a search history (JSON lines, one measurement each, as --search appends them)"
    if not path.is_file():
        raise ValueError(f"--history {path} is not a file: expected {what}")
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"--history {path} cannot be read ({exc}): expected {what}") from None
    history = []
    for n, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            r = json.loads(line)
        except json.JSONDecodeError:
            raise ValueError(f"--history {path}, line {n}: not JSON; expected {what}") from None
        if not isinstance(r, dict) or not set(_HISTORY_KEYS) <= r.keys():
            got = f"keys {sorted(map(str, r))}" if isinstance(r, dict) else type(r).__name__
            raise ValueError(
                f"--history {path}, line {n}: not a measurement (needs {list(_HISTORY_KEYS)}, "
                f"got {got:.100}); expected {what}"
            )
        try:
            HumanDriverConfig(**r["driver"])
            penalty(r)
        except (TypeError, ValueError, IndexError) as exc:
            raise ValueError(
                f"--history {path}, line {n}: not a measurement of today's teacher ({exc}); "
                "start a new history"
            ) from None
        history.append(r)
    return history


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--search", type=int, default=0, help="random perturbations to measure")
    mode.add_argument(
        "--rescore", type=int, default=0,
        help="re-measure the best N settings of --history on --seeds segments, pick by those",
    )  # fmt: skip
    p.add_argument("--history", type=Path, default=Path("runs/teacher_calibration.jsonl"))
    p.add_argument("--keep", type=int, default=6)
    p.add_argument("--seeds", type=int, default=CHECK_SEGMENTS)
    p.add_argument("--first-seed", type=int, default=0)
    p.add_argument("--steps", type=int, default=1000)
    p.add_argument("--left-spacings", default="120,150")
    p.add_argument("--rng", type=int, default=0)
    p.add_argument("--scenario", choices=("train", "eval"), default="train")
    p.add_argument("--no-delay", action="store_true", help="measure without reaction delay")
    p.add_argument("--no-slips", action="store_true", help="... without missed/doubled keys")
    a = p.parse_args(argv)
    seeds = range(a.first_seed, a.first_seed + a.seeds)
    if a.search < 0 or a.rescore < 0 or a.seeds < 1:
        p.error("--search, --rescore and --seeds take a positive count")
    # mistakes as one usage line, not a traceback from a worker or the first measurement
    if a.steps < 1 or a.keep < 1:
        p.error(f"--steps and --keep take a count >= 1, got {a.steps} and {a.keep}")
    if a.first_seed < 0:
        p.error(f"--first-seed must be >= 0 (a segment seed), got {a.first_seed}")
    try:
        spacings = [float(s) for s in a.left_spacings.split(",")]
    except ValueError:
        spacings = []
    from sumo_scenarios.scenarios import TRAIN

    if not spacings or not all(TRAIN.min_spacing_m <= s < float("inf") for s in spacings):
        p.error(
            f"--left-spacings takes comma-separated mean spacings in metres, each at least "
            f"{TRAIN.min_spacing_m:g}, got {a.left_spacings!r}"
        )
    if (a.search or a.rescore) and a.first_seed < CHECK_SEGMENTS:
        p.error(
            f"a search or rescore must use other segments than the check's 0-"
            f"{CHECK_SEGMENTS - 1}: pass --first-seed {CHECK_SEGMENTS} or more"
        )
    if a.rescore and (a.scenario != "train" or a.no_delay or a.no_slips):
        p.error("--rescore measures as the search does: no --scenario, --no-delay, --no-slips")
    if a.rescore and not a.history.exists():
        p.error(f"--rescore needs a search history, and {a.history} does not exist")
    if not (a.search or a.rescore):
        r = measure(
            _defaults(), None, seeds, a.steps, scenario=a.scenario,
            timing=timing_config(a.no_delay, a.no_slips),
        )  # fmt: skip
        lanes = np.asarray(r["lanes"]) * 100
        got = (
            f"{100 * r['collisions']:.2f}",
            f"{lanes[2:].sum():.1f}",
            f"{lanes[2]:.1f}, {lanes[3]:.1f}, {lanes[4]:.1f}",
            f"{lanes[:2].sum():.1f}",
            f"{100 * r['stay']:.1f}",
        )
        for (name, target), value in zip(TARGETS, got, strict=True):
            print(f"{name:40s} target {target:14s} measured {value}")
        print(json.dumps({k: v for k, v in r.items() if k != "driver"}))
        return 0
    try:
        history = _read_history(a.history)
    except ValueError as exc:
        p.error(str(exc))
    if not history:  # start from the defaults
        history = [{"driver": _defaults(), "spacing": list(TRAIN.mean_spacing_m)}]
        history[0].update(collisions=0.0, lanes=[0.2] * 5, stay=1.0)
        a.history.parent.mkdir(parents=True, exist_ok=True)
    if a.rescore:
        top = sorted(history, key=penalty)[: a.rescore]
        jobs = [(r["driver"], r["spacing"], seeds, a.steps) for r in top]
        with _pool("one of the drivers it rescores", "run the rescore again") as pool:
            again = list(pool.map(_job, jobs))
        for old, new in sorted(zip(top, again, strict=True), key=lambda p: penalty(p[1])):
            print(
                f"{penalty(old):6.2f} -> {penalty(new):6.2f}",
                json.dumps({k: v for k, v in new.items() if k != "driver"}),
                json.dumps(new["driver"]),
            )
        return 0
    best = sorted(history, key=penalty)[: a.keep]
    rng = np.random.default_rng(a.rng)
    jobs = []
    for i in range(a.search):
        base = best[i % len(best)]
        spacing = [*base["spacing"][:2], float(rng.choice(spacings))]
        jobs.append((_perturb(base["driver"], rng), spacing, seeds, a.steps))
    kept = f"{a.history} keeps the drivers measured before: run the search again to go on"
    with (
        _pool("one of the drivers it measures", kept) as pool,
        a.history.open("a", encoding="utf-8") as f,
    ):
        for done in as_completed([pool.submit(_job, job) for job in jobs]):
            f.write(json.dumps(done.result()) + "\n")
            f.flush()
    for r in sorted(
        [json.loads(x) for x in a.history.read_text(encoding="utf-8").splitlines() if x],
        key=penalty,
    )[:5]:
        print(f"{penalty(r):6.2f}", json.dumps({k: v for k, v in r.items() if k != "driver"}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
