"""SIGKILL a teaching session at random instants and resume it each time: demonstrations lost.

Each cycle starts (or resumes) the session of ``tests/_toy_envs.py:kill_child_main`` in a
subprocess, kills it with SIGKILL after a random delay, and checks that every demonstration
whose action reached the env is in the step log (the log stays a gap-free prefix). At the end
the session is resumed in-process and its model compared with one fitted on the logged
demonstrations.

Usage: python bench/bench_kill_resume.py [--kills 20] [--seed 0]. The last line is JSON.
"""

from __future__ import annotations

import argparse
import json
import random
import sys
import tempfile
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import test_session as ts  # noqa: E402
from _toy_envs import oracle, overlap_world  # noqa: E402

from torchcbl import ConfidentTeacher, PosteriorRule  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    torch.set_num_threads(1)
    rng = random.Random(args.seed)
    lost = 0
    print(f"{'kill':>4}{'delay s':>9}{'steps':>8}{'demos':>8}{'lost':>6}")
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run"
        t0 = time.perf_counter()
        for i in range(args.kills):
            side = Path(tmp) / f"side{i}.log"
            delay = rng.uniform(0.05, 1.0)
            ts._kill_cycle(run, side, delay)
            try:
                n_demos = ts._check_nothing_lost(run, side)
                bad = 0
            except AssertionError as exc:
                print(exc)
                n_demos, bad = -1, 1
            lost += bad
            n_steps = len(ts.load_records(run))
            print(f"{i:>4}{delay:>9.2f}{n_steps:>8}{n_demos:>8}{bad:>6}")
        env = overlap_world(episode_length=25)
        back = ConfidentTeacher.resume(
            run, env, oracle(env), rule=PosteriorRule(0.9), progress=False
        )
        try:
            ts.assert_model_is_fit_on_log(back.model, run)
            model_ok = True
        except AssertionError:
            model_ok = False
        elapsed = time.perf_counter() - t0
        result = {
            "bench": "kill_resume",
            "kills": args.kills,
            "cycles_with_lost_demonstrations": lost,
            "steps": back.n_steps,
            "demonstrations": back.n_demonstrations,
            "model_equals_fit_on_log": model_ok,
            "seconds": round(elapsed, 1),
        }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
