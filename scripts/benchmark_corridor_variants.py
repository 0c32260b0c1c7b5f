"""Does anything separate the strategies in the corridor? The quick benchmark in three variants.

``torchcbl benchmark --quick`` evaluates the corridor on the registered env (exact motion) from
the map's start pose: the evaluation drives the taught route again and every strategy reaches
the teacher's 1.00. This runs the benchmark's Python API (:func:`torchcbl.benchmark.
run_benchmark`) on the corridor's quick :class:`~torchcbl.benchmark.EnvSpec`
(:func:`corridor.benchmark.env_spec`) in up to three variants, with the same 6 strategies,
seeds, budgets, teacher, model and teaching settings:

* ``shipped``: the spec as shipped (env name ``corridor``: its cells are those of
  ``torchcbl benchmark --quick``, so its rows are the README's).
* ``perturbed``: evaluation from perturbed starts, ``eval_env_kwargs={"start_perturbation":
  ...}`` with the reproduction's offsets (``CorridorExperimentConfig().eval_perturbation``,
  0.1 m and 10 degrees); teaching as shipped. Env name ``corridor-perturbed-eval``.
* ``noisy``: the reproduction's robot (``CorridorExperimentConfig().world``, the motion noise
  of ``WorldConfig.legged_robot()``) for teaching and evaluation, ``env_kwargs={"world_config":
  ...}``, and the perturbed starts in evaluation. Env name ``corridor-noisy``.

Nothing else changes: the model, confidence rules and teaching settings stay the benchmark's
(not the reproduction's ``var_floor``, ``max_components`` and coverage threshold). Writes the
sweep into ``--out`` (``results.json``: the benchmark's, one table entry per variant's env;
``cells/``, ``learning_curves.png``), prints the benchmark's Markdown table and ends with one
JSON line: per variant and strategy, final performance, final labels, requests, monitored
steps and the teacher's performance (means over the seeds).

    PYTHONPATH=$PWD python scripts/benchmark_corridor_variants.py \\
        [--variants shipped,perturbed,noisy] [--seeds 0-2] [--workers 2] [--full] \\
        [--out runs/benchmark-corridor-variants]

About a minute on two cores for the three variants (54 cells); ``shipped`` alone, about 12 s;
``--full --seeds 0-9`` with two variants (120 cells), about 5 minutes.
Running again into the same ``--out`` reuses its finished cells (:func:`run_benchmark`).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # _args, also when loaded by path
from _args import int_at_least  # noqa: E402
from _args import seeds as seed_list  # noqa: E402

VARIANTS = ("shipped", "perturbed", "noisy")


def variants_arg(text: str) -> list[str]:
    names = text.split(",")
    if not names or any(n not in VARIANTS for n in names) or len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(
            f"expected distinct comma-separated names from {','.join(VARIANTS)}, got {text!r}"
        )
    return names


def variant_specs(names: list[str], full: bool = False) -> list[Any]:
    """The corridor's EnvSpec (quick, or ``full``: the budgets and evaluation of
    ``torchcbl benchmark`` without ``--quick``) in each named variant (see the module
    docstring)."""
    from corridor.benchmark import env_spec
    from corridor.experiment import CorridorExperimentConfig

    shipped = env_spec(quick=not full)
    reproduction = CorridorExperimentConfig()  # its robot and its perturbed starts
    perturbed = {"start_perturbation": list(reproduction.eval_perturbation)}
    noisy = {"world_config": dataclasses.asdict(reproduction.world)}
    specs = {
        "shipped": shipped,
        "perturbed": dataclasses.replace(
            shipped, name="corridor-perturbed-eval", eval_env_kwargs=perturbed
        ),
        "noisy": dataclasses.replace(
            shipped, name="corridor-noisy", env_kwargs=noisy, eval_env_kwargs=perturbed
        ),
    }
    return [specs[n] for n in names]


def run_sweep(envs: list[Any], args: argparse.Namespace, prog: str) -> tuple[dict, dict]:
    """The 6 strategies of ``torchcbl benchmark`` on ``envs`` (``args.seeds``, ``args.out``,
    ``args.workers``): prints the table and the cells' count and times; returns the summary and
    the start of the JSON line (wall and CPU seconds). A failed cell ends the script with one
    line (its finished cells are kept)."""
    from torchcbl.benchmark import STRATEGY_PATHS, StrategySpec, format_table, run_benchmark

    t0 = time.perf_counter()
    try:
        summary = run_benchmark(
            [StrategySpec(s) for s in STRATEGY_PATHS],  # the 6 of torchcbl benchmark
            envs,
            seeds=args.seeds,
            out_dir=args.out,
            workers=args.workers,
        )
    except (RuntimeError, ValueError) as exc:  # a CellError names the cell; the rest is kept
        raise SystemExit(f"{prog}: {' '.join(str(exc).split())}") from None
    wall = time.perf_counter() - t0
    print(format_table(summary))
    sweep = summary["sweep"]
    print(
        f"\n{sweep['computed']} cells computed, {sweep['cached']} cached; {wall:.0f} s wall, "
        f"{sweep['cell_cpu_s_total']:.0f} s CPU in the cells ({args.out}/results.json)"
    )
    out: dict[str, Any] = {"wall_s": round(wall, 1), "cpu_s": round(sweep["cell_cpu_s_total"], 1)}
    return summary, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", type=variants_arg, default=list(VARIANTS))
    ap.add_argument("--seeds", type=seed_list, default="0-2")
    ap.add_argument("--workers", type=int_at_least(1), default=2)
    ap.add_argument(
        "--full",
        action="store_true",
        help="the full benchmark's corridor spec (budgets to 300 labels, at most 1500 steps, "
        "4 x 5 evaluation circuits) instead of the quick one",
    )
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        help="the sweep's directory (default runs/benchmark-corridor-variants, with --full "
        "runs/benchmark-corridor-variants-full)",
    )
    args = ap.parse_args()
    if args.out is None:  # a quick and a full sweep do not share a directory
        args.out = Path("runs/benchmark-corridor-variants" + ("-full" if args.full else ""))
    if args.out.is_dir() and any(args.out.iterdir()) and not (args.out / "cells").is_dir():
        # (as torchcbl benchmark --out: a sweep writes results.json, cells/ and its plot there)
        ap.error(
            f"--out {args.out} holds files and is not a benchmark's directory (no cells/); "
            "choose a new or empty directory, or one an earlier run of this script wrote (its "
            "finished cells are reused)"
        )

    envs = variant_specs(args.variants, full=args.full)
    summary, out = run_sweep(envs, args, "benchmark_corridor_variants")
    for name, spec in zip(args.variants, envs, strict=True):
        rows = summary["table"][spec.name]
        out[name] = {
            strategy: {
                "final_performance": r["final_performance"]["mean"],
                "final_labels": r["final_labels"]["mean"],
                "requests": r["attention"]["requests"]["mean"],
                "monitored": r["attention"]["monitored_steps"]["mean"],
                "teacher_performance": r["teacher_performance"]["mean"],
            }
            for strategy, r in rows.items()
        }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
