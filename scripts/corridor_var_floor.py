"""The corridor GMM's variance floor, chosen on the fits alone (issue 12; the driving
experiment's criterion, ``docs/data/driving_var_floor_2026-11-26.md``).

For every seed's teaching session under ``RUN_DIR/sessions/seed*`` (a corridor run directory),
fits a fresh ``GaussianMixtureSet`` (AIC, the given cap) to every tenth prefix of its
demonstrations (20, 30, ... and the whole set) for each floor asked, and prints per floor how
many of those training sets have a mixture at the cap and the most components each action took.
The criterion: the smallest floor at which no mixture reaches the cap. Ends with one JSON line.

    PYTHONPATH=$PWD python scripts/corridor_var_floor.py runs/reproduce/corridor \\
        [--floors 1e-3,3e-3,0.01,0.02,0.03,0.05] [--cap 10]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

from corridor.world import Action
from torchcbl import GaussianMixtureSet
from torchcbl.session import load_demonstrations

sys.path.insert(0, str(Path(__file__).resolve().parent))  # _args, also when loaded by path
from _args import int_at_least, numbers_at_least_zero  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--floors", type=numbers_at_least_zero, default="1e-3,3e-3,0.01,0.02,0.03,0.05")
    ap.add_argument("--cap", type=int_at_least(1), default=10)
    args = ap.parse_args()
    torch.set_num_threads(1)
    sessions = sorted((args.run_dir / "sessions").glob("seed*"), key=lambda p: int(p.name[4:]))
    if not sessions:
        raise SystemExit(
            f"no sessions/seed* under {args.run_dir}: expected a corridor run directory"
        )
    data = [load_demonstrations(s) for s in sessions]
    names = [a.name.lower() for a in Action]
    out = []
    print(
        f"| var_floor | training sets with a mixture at the cap of {args.cap} | most components: "
        + ", ".join(names)
        + " |"
    )
    print("|---|---|---|")
    for floor in args.floors:
        at_cap = n_sets = 0
        most = [0] * len(names)
        for x, y in data:
            for n in [*range(20, len(y), 10), len(y)]:
                model = GaussianMixtureSet(len(names), x.shape[1], args.cap, var_floor=floor)
                k = model.fit(x[:n], y[:n]).n_components_.tolist()
                n_sets += 1
                at_cap += any(v >= args.cap for v in k)
                most = [max(a, b) for a, b in zip(most, k, strict=True)]
        print(f"| {floor:g} | {at_cap} of {n_sets} | {', '.join(map(str, most))} |", flush=True)
        out.append({"var_floor": floor, "at_cap": at_cap, "sets": n_sets, "most": most})
    print(json.dumps({"cap": args.cap, "sessions": len(sessions), "floors": out}))


if __name__ == "__main__":
    main()
