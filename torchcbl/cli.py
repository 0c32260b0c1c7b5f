"""The ``torchcbl`` command line.

This is the only core module that reaches the domains (``corridor``, ``sumo_scenarios``), and it
imports them lazily, inside the command that needs them, so ``torchcbl --help`` stays fast and the
core never depends on a simulator.

Commands::

    torchcbl reproduce [corridor|driving|all] [--full] [--seeds N] [--workers N] [--out DIR]
    torchcbl evaluate RUN_DIR --domain corridor|driving [--steps N] [--seed S]
    torchcbl replay EPISODES.json [--episode N | --label TEXT] [--gif OUT] [--fcd OUT]
    torchcbl plot RUN_DIR
    torchcbl teach corridor|driving [--run-dir DIR] [--resume]
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

_DOMAINS = {
    "corridor": "corridor.experiment",
    "driving": "sumo_scenarios.experiment",
}


def _experiment_module(domain: str) -> Any:
    return importlib.import_module(_DOMAINS[domain])


def _cmd_reproduce(args: argparse.Namespace) -> int:
    domains = list(_DOMAINS) if args.domain == "all" else [args.domain]
    out = _fresh_dir(Path(args.out))
    summaries: list[str] = []
    for domain in domains:
        module = _experiment_module(domain)
        config_cls = next(
            getattr(module, name)
            for name in dir(module)
            if name.endswith("ExperimentConfig") and isinstance(getattr(module, name), type)
        )
        config = config_cls.full() if args.full else config_cls()
        if args.seeds is not None:
            config = _replace_seeds(config, args.seeds)
        run_dir = out / domain
        print(f"== {domain}: {'full' if args.full else 'quick'} run into {run_dir}", flush=True)
        t0 = time.perf_counter()
        results = module.run_experiment(
            config, run_dir, workers=args.workers, progress=not args.no_progress
        )
        elapsed = time.perf_counter() - t0
        summary = module.format_summary(results)
        summaries.append(f"## {domain} ({elapsed:.0f} s, run directory `{run_dir}`)\n\n{summary}")
        print(summary, flush=True)
    text = "\n\n".join(summaries) + "\n"
    (out / "summary.md").write_text(text)
    print(f"\nSummary written to {out / 'summary.md'}")
    return 0


def _fresh_dir(out: Path) -> Path:
    """``out`` if it is new or empty, else the first free ``out-2``, ``out-3``, ... (a run
    directory is never overwritten)."""
    candidate, n = out, 1
    while candidate.exists() and any(candidate.iterdir()):
        n += 1
        candidate = out.with_name(f"{out.name}-{n}")
    candidate.mkdir(parents=True, exist_ok=True)
    return candidate


def _replace_seeds(config: Any, n_seeds: int) -> Any:
    import dataclasses

    fields = {f.name for f in dataclasses.fields(config)}
    if "seeds" in fields:
        return dataclasses.replace(config, seeds=tuple(range(n_seeds)))
    if "n_seeds" in fields:
        return dataclasses.replace(config, n_seeds=n_seeds)
    raise SystemExit(f"--seeds is not supported by {type(config).__name__}")


def _cmd_evaluate(args: argparse.Namespace) -> int:
    module = _experiment_module(args.domain)
    report = module.evaluate_saved_policy(Path(args.run_dir), n_steps=args.steps, seed=args.seed)
    print(json.dumps(report, indent=2))
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    replay = importlib.import_module("sumo_scenarios.replay")
    path = Path(args.episodes)
    episodes = replay.load_records(path)
    if args.list:
        for i, ep in enumerate(episodes):
            print(f"{i:4d}  {ep.label or '-':50s} {len(ep.actions):6d} steps")
        return 0
    matches = [i for i, ep in enumerate(episodes) if args.label and args.label in (ep.label or "")]
    index = matches[0] if matches else args.episode
    if args.label and not matches:
        raise SystemExit(f"No episode label contains {args.label!r}; see --list.")
    if not 0 <= index < len(episodes):
        raise SystemExit(f"--episode must be in [0, {len(episodes)}), got {index}; see --list.")
    record = episodes[index]
    stem = path.with_suffix("")
    gif = Path(args.gif) if args.gif else stem.with_name(f"{stem.name}-{index}.gif")
    fcd = Path(args.fcd) if args.fcd else stem.with_name(f"{stem.name}-{index}.fcd.xml")
    print(f"episode {index}: {record.label or '-'} ({len(record.actions)} steps)")
    replay.export_fcd(record, fcd)
    print(f"FCD written to {fcd}")
    cfg = replay.write_sumocfg(
        record, fcd, fcd.with_name(fcd.name.replace(".fcd.xml", "") + ".sumocfg")
    )
    print(f"SUMO configuration written to {cfg} (open with: sumo-gui -c {cfg})")
    replay.render_gif(record, gif, every=args.every, max_frames=args.max_frames)
    print(f"GIF written to {gif} (every {args.every} timestep(s) of {len(record.actions)})")
    return 0


def _cmd_plot(args: argparse.Namespace) -> int:
    run_dir = Path(args.run_dir)
    results_path = run_dir / "results.json"
    if not results_path.exists():
        raise SystemExit(f"Expected {results_path} (a run directory written by reproduce).")
    results = json.loads(results_path.read_text())
    domain = results.get("domain")
    if domain not in _DOMAINS:
        raise SystemExit(f"Expected results.json to name a domain in {sorted(_DOMAINS)}")
    written = _experiment_module(domain).plot_results(results, run_dir)
    for path in written:
        print(path)
    return 0


# What the teach command needs per domain: the gymnasium id (registered on importing the
# package), the module with the text view / key map, and the paper's teaching settings.
_TEACH = {
    "corridor": (
        "corridor",
        "torchcbl/Corridor-v0",
        "corridor.human",
        dict(accuracy_window=20, target_accuracy=0.9, autonomous_episodes_to_stop=10),
    ),
    "driving": (
        "sumo_scenarios",
        "torchcbl/Driving-v0",
        "sumo_scenarios.human",
        dict(
            accuracy_window=150, target_accuracy=0.8, burst=10, max_new=10, max_demonstrations=650
        ),
    ),
}


def _cmd_teach(args: argparse.Namespace) -> int:
    import gymnasium as gym

    from torchcbl.teaching import ConfidentTeacher, TeachingConfig, TeachingInterrupted

    package, env_id, human_module, settings = _TEACH[args.domain]
    importlib.import_module(package)  # registers the env id
    human = importlib.import_module(human_module)
    teacher = human.make_teacher(title=f"torchcbl teach {args.domain}")
    env = gym.make(env_id)
    run_dir = Path(args.run_dir)
    asked = 0

    def status(record: Any) -> None:
        nonlocal asked
        asked += record.teacher_action is not None
        rate = ct.autonomy_rate
        acc = ct.windowed_accuracy
        teacher.set_status(
            f"step {record.step + 1} | phase {ct.phase} | demonstrations {ct.n_demonstrations}"
            f" | prediction accuracy {'-' if acc is None else f'{100 * acc:.0f}%'}"
            f" | autonomy {'-' if rate is None else f'{100 * rate:.0f}%'}"
        )

    if args.resume:
        ct = ConfidentTeacher.resume(run_dir, env, teacher, progress=False, on_step=status)
    else:
        config = TeachingConfig(noninteractive=not args.skip_noninteractive, **settings)
        ct = ConfidentTeacher(
            env,
            teacher,
            config=config,
            run_dir=run_dir,
            seed=args.seed,
            progress=False,
            on_step=status,
        )
    try:
        ct.run(max_steps=ct.n_steps + args.steps)
    except TeachingInterrupted:
        print("\nStopped by the teacher.")
    finally:
        ct.close()
        env.close()
    print(
        f"{ct.n_demonstrations} demonstrations over {ct.n_steps} steps saved in {run_dir}; "
        f"continue with: torchcbl teach {args.domain} --run-dir {run_dir} --resume"
    )
    return 0


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="torchcbl",
        description="Confidence-based learning from demonstration with Gaussian mixture sets "
        "(Chernova & Veloso, AAMAS 2007).",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser(
        "reproduce",
        help="reproduce the paper's experiments (quick by default)",
        description="Run the corridor (Section 5.1) and/or driving (Section 5.2) experiment "
        "over several seeds and write results.json, figures and a summary table into --out.",
    )
    p.add_argument("domain", nargs="?", default="all", choices=["all", *_DOMAINS])
    p.add_argument("--full", action="store_true", help="the paper's full sizes (slow)")
    p.add_argument("--seeds", type=int, default=None, help="number of seeds (default: config's)")
    p.add_argument("--workers", type=int, default=2, help="parallel processes (default 2)")
    p.add_argument(
        "--out",
        default="runs/reproduce",
        help="output directory (default runs/reproduce; never overwritten: -2, -3, ... added)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_reproduce)

    p = sub.add_parser(
        "evaluate",
        help="evaluate a saved policy (a teaching session directory)",
        description="Load the latest model of a teaching session and run it greedily.",
    )
    p.add_argument("run_dir")
    p.add_argument("--domain", required=True, choices=list(_DOMAINS))
    p.add_argument("--steps", type=int, default=1000, help="timesteps to run (default 1000)")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=_cmd_evaluate)

    p = sub.add_parser(
        "replay",
        help="replay a recorded SUMO episode to GIF and FCD XML",
        description="Re-simulate a recorded driving episode bit-identically and export it.",
    )
    p.add_argument("episodes", help="an episodes.json written by the driving experiment")
    p.add_argument("--episode", type=int, default=0, help="index of the episode (default 0)")
    p.add_argument("--label", default=None, help="the first episode whose label contains this")
    p.add_argument("--list", action="store_true", help="list the recorded episodes and stop")
    p.add_argument("--gif", default=None, help="GIF output path (default beside the JSON)")
    p.add_argument("--fcd", default=None, help="SUMO FCD XML output path (default beside it)")
    p.add_argument(
        "--max-frames", type=int, default=None, help="GIF frames at most (default: whole episode)"
    )
    p.add_argument("--every", type=int, default=1, help="GIF: draw every N-th timestep")
    p.set_defaults(func=_cmd_replay)

    p = sub.add_parser(
        "plot",
        help="redraw the figures of a run directory",
        description="Read RUN_DIR/results.json and write its figures as PNG.",
    )
    p.add_argument("run_dir")
    p.set_defaults(func=_cmd_plot)

    p = sub.add_parser(
        "teach",
        help="teach an agent yourself from the terminal",
        description="You are the teacher: the agent shows you its situation and asks for an "
        "action (one key) whenever it is unsure; every demonstration is saved to --run-dir.",
    )
    p.add_argument("domain", choices=list(_DOMAINS))
    p.add_argument("--run-dir", default="runs/teach", help="session directory")
    p.add_argument("--resume", action="store_true", help="continue the session in --run-dir")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--steps", type=int, default=2000, help="stop after this many steps")
    p.add_argument(
        "--skip-noninteractive",
        action="store_true",
        help="start directly in confident execution (no teleoperation phase)",
    )
    p.set_defaults(func=_cmd_teach)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``torchcbl`` console script."""
    args = _parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
