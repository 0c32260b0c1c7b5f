"""The strategy benchmark's GMM variance floor and component cap, chosen on the fits alone.

Both reproduction experiments raised the floor by a criterion on their demonstrations, before
any learning run (``docs/data/corridor_var_floor_2026-11-26.md``,
``docs/data/driving_var_floor_2026-11-26.md``); the benchmark's shipped ``EnvSpec`` s keep the
library's floor (1e-3) and a cap of 10. This script applies the same criterion to the
benchmark's own label sets. No policy is evaluated for the choice.

1. **Label sets.** For each label set asked (``--sets``; ``corridor``: the shipped quick spec,
   ``corridor-full``: the full one, ``driving``: the quick driving spec), teaches the cells of
   every strategy of ``torchcbl benchmark`` on ``--seeds`` through ``run_benchmark(...,
   keep_sessions=True)`` into ``OUT/<set>`` (its cells are also evaluated, as every benchmark
   cell is; nothing here reads those figures). From each kept session, the training set the
   model was fitted on at each curve point (the first ``labels`` labels; relabelled for CBA, as
   its model is), identical sets counted once.
2. **Fits.** Each training set is fitted from scratch, as a cell's snapshot is (the spec's
   model arguments, the cell's seed), with each floor of ``--floors`` at the shipped cap
   (10), counting the sets with a mixture at the cap and the most components each action took.
3. **The criterion, per domain** (fixed before any fit was looked at): the smallest floor at
   which no mixture reaches the shipped cap of 10 on any of the domain's sets. Where it is the
   library's 1e-3 (at the cap of 10), the domain keeps its spec. Where no floor of the grid
   meets it, it is applied at the cap the domain's experiment uses (corridor 20, driving 40),
   as each experiment applied it at the cap it had then.
4. **The cap**, as the experiments set it, whenever the spec changes (a floor above 1e-3, or
   1e-3 met only at the experiment's cap): with the chosen floor, fits again at
   ``--search-cap`` (default 60) and takes the smallest of 10, 20, 40 (the shipped cap and the
   experiments') above the most components any action took there, so that the AIC's choice is
   not cut (a count equal to the search cap is reported as unsettled; a count of 40 or more
   below it has no cap of the ladder above it: the rule settles none).

Prints Markdown tables and ends with one JSON line (``--json`` writes it to a file too).

    PYTHONPATH=$PWD python scripts/benchmark_var_floor.py [--sets corridor,corridor-full,driving]
        [--seeds 0-2] [--floors 1e-3,3e-3,0.01,0.02,0.03,0.05] [--search-cap 60]
        [--workers 2] [--out runs/benchmark-var-floor]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))  # _args, also when loaded by path
from _args import int_at_least, numbers_at_least_zero  # noqa: E402
from _args import seeds as seed_list  # noqa: E402

SETS = ("corridor", "corridor-full", "driving")
SHIPPED_CAP = 10
EXPERIMENT_CAP = {"corridor": 20, "driving": 40}  # each experiment's cap (its var_floor md)
CAP_LADDER = (10, 20, 40)


def _sets(text: str) -> list[str]:
    names = text.split(",")
    if not names or any(n not in SETS for n in names) or len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(
            f"expected distinct comma-separated names from {','.join(SETS)}, got {text!r}"
        )
    return names


def _spec(name: str) -> Any:
    if name.startswith("corridor"):
        from corridor.benchmark import env_spec

        return env_spec(quick=name == "corridor")
    from sumo_scenarios.benchmark import env_spec as driving_spec

    return driving_spec(quick=True)


def _domain(name: str) -> str:
    return "corridor" if name.startswith("corridor") else "driving"


def teach(name: str, seeds: list[int], workers: int, out: Path) -> tuple[Any, list[dict]]:
    """The spec of label set ``name`` and its cells, each with its kept session."""
    from torchcbl.benchmark import STRATEGY_PATHS, StrategySpec, run_benchmark

    spec = _spec(name)
    run_benchmark(
        [StrategySpec(s) for s in STRATEGY_PATHS],
        [spec],
        seeds=seeds,
        out_dir=out,
        workers=workers,
        plots=False,
        keep_sessions=True,
    )
    cells = [
        json.loads(p.read_text(encoding="utf-8")) for p in sorted((out / "cells").glob("*.json"))
    ]
    return spec, [c for c in cells if c["env"] == spec.name and c["seed"] in seeds]


def training_sets(out: Path, cells: list[dict], seen: set[str]) -> list[dict[str, Any]]:
    """The training sets of the cells' curve points, {x, y, seed, labels, where}, but those
    already ``seen`` (a digest of the set and the seed the fit takes; updated)."""
    from torchcbl.records import training_set
    from torchcbl.session import load_config, load_labels

    sets = []
    for cell in cells:
        session = out / "sessions" / cell["key"]
        xs, ys = load_labels(session)
        relabel = bool(load_config(session).get("strategy", {}).get("relabel", False))
        for point in cell["curve"]:
            n = int(point["labels"])
            x, y = training_set(list(xs[:n]), ys[:n].tolist(), relabel=relabel)
            digest = hashlib.sha256(
                x.tobytes() + y.tobytes() + str(cell["seed"]).encode()
            ).hexdigest()
            if digest in seen:
                continue
            seen.add(digest)
            where = f"{cell['strategy']} seed {cell['seed']} @ {n}"
            sets.append({"x": x, "y": y, "seed": cell["seed"], "labels": n, "where": where})
    return sets


def fit_counts(
    sets: list[dict], n_actions: int, model: dict[str, Any], floor: float, cap: int
) -> dict[str, Any]:
    """Fits every set at ``floor`` and ``cap``: sets with a mixture at the cap, the most
    components per action, the mean total, and where the cap was reached."""
    from torchcbl import GaussianMixtureSet

    at_cap, most, totals, where = 0, [0] * n_actions, [], []
    for s in sets:
        gmm = GaussianMixtureSet(
            n_actions,
            s["x"].shape[1],
            **{**model, "max_components": cap, "var_floor": floor},
            seed=s["seed"],
        )
        k = gmm.fit(torch.as_tensor(s["x"]), torch.as_tensor(s["y"])).n_components_.tolist()
        totals.append(sum(k))
        most = [max(a, b) for a, b in zip(most, k, strict=True)]
        if any(v >= cap for v in k):
            at_cap += 1
            where.append(s["where"])
    return {
        "var_floor": floor,
        "cap": cap,
        "at_cap": at_cap,
        "sets": len(sets),
        "most": most,
        "mean_total": round(float(np.mean(totals)), 1),
        "at_cap_where": where,
    }


def _no_cap(top: int, search_cap: int) -> str:
    """Why the cap search settled no cap, given its most components ``top``."""
    if top >= search_cap:  # the search cap may have cut the AIC's choice: a higher one may not
        return "unsettled (raise --search-cap)"
    ladder = ", ".join(map(str, CAP_LADDER))
    return (
        f"none: no cap of the ladder {ladder} is above {top} (the rule settles no cap; "
        "a higher --search-cap cannot change that)"
    )


def _row(r: dict[str, Any], chosen: bool) -> str:
    cells = [f"{r['var_floor']:g}", f"{r['at_cap']} of {r['sets']}"]
    if chosen:
        cells = [f"**{c}**" for c in cells]
    most = ", ".join(map(str, r["most"]))
    return f"| {' | '.join(cells)} | {most} | {r['mean_total']} |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", type=_sets, default=list(SETS))
    ap.add_argument("--seeds", type=seed_list, default="0-2")
    ap.add_argument("--floors", type=numbers_at_least_zero, default="1e-3,3e-3,0.01,0.02,0.03,0.05")
    ap.add_argument("--search-cap", type=int_at_least(CAP_LADDER[-1] + 1), default=60)
    ap.add_argument("--workers", type=int_at_least(1), default=2)
    ap.add_argument("--out", type=Path, default=Path("runs/benchmark-var-floor"))
    ap.add_argument("--json", type=Path, default=None, help="also write the JSON line here")
    args = ap.parse_args()
    floors = sorted(args.floors)
    torch.set_num_threads(1)
    t0 = time.perf_counter()

    by_domain: dict[str, dict[str, Any]] = {}
    for name in args.sets:
        out = args.out / name
        try:
            spec, cells = teach(name, args.seeds, args.workers, out)
        except (RuntimeError, ValueError) as exc:
            raise SystemExit(f"benchmark_var_floor: {' '.join(str(exc).split())}") from None
        d = by_domain.setdefault(
            _domain(name), {"spec": spec, "sets": [], "from": {}, "seen": set()}
        )
        sets = training_sets(out, cells, d["seen"])  # (a quick set already seen is not new)
        d["sets"] += sets
        d["from"][name] = len(sets)
        print(f"{name}: {len(cells)} cells, {len(sets)} new distinct training sets", flush=True)
    teach_s = time.perf_counter() - t0

    result: dict[str, Any] = {"seeds": args.seeds, "sets": args.sets, "domains": {}}
    for domain, d in by_domain.items():
        spec, sets = d["spec"], d["sets"]
        n_actions = 4 if domain == "corridor" else 3  # the envs' action counts
        model = {k: v for k, v in spec.model.items() if k not in ("max_components", "var_floor")}
        rows = [fit_counts(sets, n_actions, model, f, SHIPPED_CAP) for f in floors]
        chosen_cap_for_criterion = SHIPPED_CAP
        ok = [r for r in rows if r["at_cap"] == 0]
        if not ok:  # the experiment's cap, as each experiment applied it at its own
            chosen_cap_for_criterion = EXPERIMENT_CAP[domain]
            rows_exp = [
                fit_counts(sets, n_actions, model, f, chosen_cap_for_criterion) for f in floors
            ]
            ok = [r for r in rows_exp if r["at_cap"] == 0]
        else:
            rows_exp = []
        floor = ok[0]["var_floor"] if ok else None
        search = cap = None
        # the cap is searched whenever the spec changes: a floor above the library's, or the
        # library's floor met only at the experiment's cap (the cap of 10 then cuts the AIC)
        if floor is not None and (floor > 1e-3 or chosen_cap_for_criterion != SHIPPED_CAP):
            search = fit_counts(sets, n_actions, model, floor, args.search_cap)
            top = max(search["most"])
            above = [c for c in CAP_LADDER if c > top]
            cap = above[0] if above and top < args.search_cap else None
        names = (
            "forward, turn_left, turn_right, u_turn"
            if domain == "corridor"
            else "stay, left, right"
        )
        print(f"\n## {domain} ({', '.join(f'{k}: {v} sets' for k, v in d['from'].items())})\n")
        for table_cap, table in ((SHIPPED_CAP, rows), (chosen_cap_for_criterion, rows_exp)):
            if not table:
                continue
            print(
                f"| var_floor | training sets with a mixture at the cap of {table_cap} | "
                f"most components: {names} | mean total components |"
            )
            print("|---|---|---|---|")
            for r in table:
                is_chosen = r["var_floor"] == floor and table_cap == chosen_cap_for_criterion
                print(_row(r, is_chosen))
            print()
        if floor is None:
            print("No floor of the grid meets the criterion: the domain keeps its spec.")
        elif floor <= 1e-3 and chosen_cap_for_criterion == SHIPPED_CAP:
            print(
                f"The criterion (no mixture at the cap of {chosen_cap_for_criterion}) picks "
                f"{floor:g}, the library's default: the domain keeps its spec."
            )
        else:
            print(
                f"Criterion (no mixture at the cap of {chosen_cap_for_criterion}): "
                f"var_floor {floor:g}. At a cap of {args.search_cap} with it: "
                f"{search['at_cap']} sets at that cap, most components {search['most']}; "
                f"cap {cap if cap is not None else _no_cap(top, args.search_cap)}."
            )
        result["domains"][domain] = {
            "sets_from": d["from"],
            "model_shipped": dict(spec.model),
            "criterion_cap": chosen_cap_for_criterion,
            "at_shipped_cap": rows,
            "at_experiment_cap": rows_exp,
            "var_floor": floor,
            "search": search,
            "max_components": cap,
        }
    result["wall_s"] = {"teach": round(teach_s, 1), "all": round(time.perf_counter() - t0, 1)}
    line = json.dumps(result)
    print(line)
    if args.json is not None:
        args.json.write_text(line + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
