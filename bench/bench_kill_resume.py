"""SIGKILL teaching sessions at random instants and resume them each time: labels lost.

Each cycle starts (or resumes) the session of ``tests/_toy_envs.py:kill_child_main`` in a
subprocess, kills it with SIGKILL after a random delay, and checks that every demonstration
whose action reached the env is in the step log (the log stays a gap-free prefix). Mode
``cba`` teaches with Confidence-Based Autonomy and a teacher that corrects every wrong
autonomous action: there it also checks that every correction followed by a later action is
in the log (a correction is durable before the next decision, like a demonstration). At the
end each session is resumed in-process and its model compared with one fitted on the log.

Usage: python bench/bench_kill_resume.py [--kills 20] [--seed 0] [--mode both|ce|cba].
The last line is JSON.
"""

from __future__ import annotations

import json
import random
import sys
import tempfile
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import test_session as ts  # noqa: E402
from _parser import Parser  # noqa: E402
from _toy_envs import check_corrections_kept, oracle, overlap_world  # noqa: E402

from torchcbl import ConfidentTeacher, PosteriorRule  # noqa: E402
from torchcbl.strategies import correcting  # noqa: E402


def _one_mode(mode: str, kills: int, rng: random.Random, tmp: Path) -> dict:
    run = tmp / f"run-{mode}"
    lost = lost_corrections = caught_unacknowledged = 0
    n_corr = 0
    print(f"-- mode {mode}")
    # "lost": this cycle lost a label, "lost corr": a correction (cba); -1: not counted
    print(
        f"{'kill':>4}{'delay s':>9}{'steps':>8}{'demos':>8}{'corr':>6}{'lost':>6}{'lost corr':>11}"
    )
    for i in range(kills):
        side = tmp / f"side-{mode}-{i}.log"
        delay = rng.uniform(0.05, 1.0)
        ts._kill_cycle(run, side, delay, mode)
        bad = bad_corr = 0
        try:
            n_demos = ts._check_nothing_lost(run, side)
        except AssertionError as exc:
            print(exc)
            n_demos, bad = -1, 1
        if mode == "cba":
            try:
                n_corr, unack = check_corrections_kept(run, side)
                caught_unacknowledged += unack
            except AssertionError as exc:
                print(exc)
                n_corr, bad_corr = -1, 1
        lost += bad
        lost_corrections += bad_corr
        n_steps = len(ts.load_records(run))
        print(f"{i:>4}{delay:>9.2f}{n_steps:>8}{n_demos:>8}{n_corr:>6}{bad:>6}{bad_corr:>11}")
    env = overlap_world(episode_length=25)
    if mode == "cba":
        back = ConfidentTeacher.resume(run, env, correcting(oracle(env)), progress=False)
    else:
        back = ConfidentTeacher.resume(
            run, env, oracle(env), rule=PosteriorRule(0.9), progress=False
        )
    try:
        ts.assert_model_is_fit_on_log(back.model, run)
        model_ok = True
    except AssertionError:
        model_ok = False
    out = {
        "kills": kills,
        "cycles_with_lost_labels": lost,
        "cycles_with_lost_corrections": lost_corrections,
        "steps": back.n_steps,
        "labels": back.n_demonstrations,  # demonstrations plus corrections
        "demonstrations": back.n_demonstrations - back.n_corrections,
        "corrections": back.n_corrections,
        "corrections_killed_before_acknowledged": caught_unacknowledged,
        "model_equals_fit_on_log": model_ok,
    }
    back.close()
    return out


def main() -> None:
    parser = Parser(__doc__)
    parser.add_argument(
        "--kills", type=int, default=20, help="SIGKILLs per mode (default %(default)s)"
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="seed of the kill delays (default %(default)s)"
    )
    parser.add_argument(
        "--mode",
        choices=("both", "ce", "cba"),
        default="both",
        help="confident execution, CBA with corrections, or both (default %(default)s)",
    )
    args = parser.parse_args()
    if args.kills < 1:
        parser.error(f"--kills: expected an int >= 1, got {args.kills}")
    torch.set_num_threads(1)
    rng = random.Random(args.seed)
    modes = ("ce", "cba") if args.mode == "both" else (args.mode,)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        results = {m: _one_mode(m, args.kills, rng, Path(tmp)) for m in modes}
    result = {
        "bench": "kill_resume",
        "kills_per_mode": args.kills,
        "lost_anything": any(
            r["cycles_with_lost_labels"]
            or r["cycles_with_lost_corrections"]
            or not r["model_equals_fit_on_log"]
            for r in results.values()
        ),
        **results,
        "seconds": round(time.perf_counter() - t0, 1),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
