"""Why the driving GMM's "stay" mixture reaches any component cap: clipped readings.

The driving observation clips each lane's distance to [-25, 25] m, so a demonstration with no
car in range in a lane carries exactly +-25 there: a point mass. This script loads the
demonstrations of one kept teaching session (by default seed 0, arm (a), of the newest
finished reproduction among runs/reproduce, runs/reproduce-2, ...),
reports the share of readings at the clip, refits the GMM set at each cap and counts the
"stay" components whose variance in some distance is within 5x the variance floor, and how
many of those are centred on the clip.

Usage: python scripts/driving_components_at_clip.py [RUN_DIR] [--caps 30,60] [--var-floor F]
``--var-floor`` is the GMM's relative variance floor (default 1e-3, the library's; the driving
experiment uses 0.03, see ``DrivingExperimentConfig.var_floor``).
The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from torchcbl.cli import latest_run
from torchcbl.gmm import GaussianMixtureSet
from torchcbl.session import load_records

sys.path.insert(0, str(Path(__file__).resolve().parent))  # _args, also when loaded by path
from _args import ints_at_least  # noqa: E402

CLIP_M = 25.0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "run_dir",
        nargs="?",
        default=str(latest_run() / "driving" / "seed_0" / "sessions" / "arm_a"),
    )
    p.add_argument("--caps", type=ints_at_least(1), default="30,60")
    p.add_argument(
        "--action", type=int, choices=(0, 1, 2), default=0, help="0 stay, 1 left, 2 right"
    )
    p.add_argument("--var-floor", type=float, default=1e-3, help="relative variance floor")
    a = p.parse_args(argv)
    if not (np.isfinite(a.var_floor) and a.var_floor >= 0):
        print(
            f"error: --var-floor must be a finite number >= 0, got {a.var_floor}", file=sys.stderr
        )
        return 2
    try:
        records = load_records(a.run_dir)
    except Exception as exc:  # a missing or unreadable session: one line, exit code 2
        print(f"error: cannot read a teaching session in {a.run_dir}: {exc}", file=sys.stderr)
        return 2
    demos = [r for r in records if r.teacher_action is not None]
    if not demos:
        print(f"error: {a.run_dir} holds no demonstrations", file=sys.stderr)
        return 2
    x = np.array([r.observation for r in demos], dtype=np.float64)
    y = np.array([r.teacher_action for r in demos])
    at_clip = np.abs(x[:, :3]) >= CLIP_M - 1e-9
    out: dict = {
        "run_dir": a.run_dir,
        "demonstrations": len(x),
        "per_action": np.bincount(y, minlength=3).tolist(),
        "share_at_clip_per_lane": at_clip.mean(0).round(4).tolist(),
        "share_rows_any_at_clip": round(float(at_clip.any(1).mean()), 4),
        "var_floor": a.var_floor,
        "caps": {},
    }
    print(
        f"{len(x)} demonstrations; readings at +-{CLIP_M:g} m per lane (right, middle, left): "
        f"{out['share_at_clip_per_lane']}; rows with one: {out['share_rows_any_at_clip']}"
    )
    for cap in a.caps:
        m = GaussianMixtureSet(3, x.shape[1], cap, var_floor=a.var_floor, tol=1e-4, seed=0).fit(
            x, y
        )
        k = int(m.n_components_[a.action])
        var = np.diagonal(m.covariances_[a.action, :k].numpy(), axis1=1, axis2=2)[:, :3]
        mu = m.means_[a.action, :k].numpy()[:, :3]
        small = var <= 5 * m.var_floor_.numpy()[:3]
        on_clip = (small & (np.abs(mu) > CLIP_M - 0.1)).any(1)
        row = {
            "components": m.n_components_.tolist(),
            "floor_sized": int(small.any(1).sum()),
            "floor_sized_on_clip": int(on_clip.sum()),
            "weight_on_clip": round(float(m.weights_[a.action, :k].numpy()[on_clip].sum()), 4),
        }
        out["caps"][cap] = row
        print(
            f"cap {cap}: components per action {row['components']}; action {a.action}: "
            f"{row['floor_sized']} of {k} with a floor-sized distance variance, "
            f"{row['floor_sized_on_clip']} of them centred on the clip "
            f"(weight {row['weight_on_clip']})"
        )
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
