"""Where the corridor's final policies differ from the teacher, and whether the readings could
have told the places apart (issue 12).

For a corridor run directory (``RUN_DIR/results.json`` and ``RUN_DIR/sessions/seed*``): the
expert drives ``--circuits`` fresh circuits of the run's map, from the paper's start, with the
run's motion and sensor noise (env seeds ``--first-seed`` on, none of them teaching's or the
evaluation's). On the expert's own states it prints:

- the reference: a 1-nearest-neighbour classifier on the readings (each reading scaled by its
  standard deviation), fitted on the first half of the circuits and tested on the second half.
  Its error is how often three readings fail to tell the expert's action; a place where it is
  right and the learned policy is not is a mistake of the learner, not aliasing of the world;
- each seed's final model (:func:`torchcbl.load_model`): the share of the expert's states at
  which it picks another action, and picks it confident (within the run's threshold, so the
  policy would act without asking), overall and at two named places:

  * "after right": the step right after the expert's right turn out of the spur, with a wall
    nearer than 0.5 m on the left (the corner of the corridor that leads into the junction),
  * "before corner": the expert's last forward step before a left turn, where the walls close
    in on both sides (both side readings below 0.5 m),
  * "left, walls near": the expert's left turns with both side readings below 0.5 m (a step
    that fell short of the corner's opening);
- the readings at those places, and where the expert turns right and u-turns;
- each seed's demonstrations per action.

Ends with one JSON line. About 12 s for 1,000 circuits::

    PYTHONPATH=$PWD python scripts/corridor_final_policy_check.py runs/reproduce/corridor \\
        [--circuits 1000] [--first-seed 3000000]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

from corridor.baseline import PrioritizedSweepingConfig
from corridor.env import CorridorEnv
from corridor.experiment import CorridorExperimentConfig
from corridor.expert import CorridorExpert
from corridor.maps import load_map
from corridor.world import SENSOR_NAMES, Action, WorldConfig
from torchcbl import load_model
from torchcbl.session import load_demonstrations

sys.path.insert(0, str(Path(__file__).resolve().parent))  # _args, also when loaded by path
from _args import int_at_least  # noqa: E402

_NEAR = 0.5  # metres: a side reading below this is a wall beside the robot


def _expert_states(
    map_name: str, world: WorldConfig, circuits: int, first_seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Readings [N, 3], expert actions [N], circuit index [N] and the named places (bool masks
    [N]) of ``circuits`` expert circuits."""
    corridor_map = load_map(map_name)
    env = CorridorEnv(corridor_map, world, max_episode_steps=200)
    expert = CorridorExpert(corridor_map, world)
    xs: list[np.ndarray] = []
    acts: list[int] = []
    circ: list[int] = []
    for i in range(circuits):
        obs, info = env.reset(seed=first_seed + i)
        done = False
        while not done:
            xs.append(obs.astype(np.float64))
            acts.append(expert(obs, info))
            circ.append(i)
            obs, _, terminated, truncated, info = env.step(acts[-1])
            done = terminated or truncated
    x, a, c = np.array(xs), np.array(acts), np.array(circ)
    walls_near = (x[:, 0] < _NEAR) & (x[:, 2] < _NEAR)
    after_right = np.r_[False, (a[:-1] == Action.TURN_RIGHT) & (c[1:] == c[:-1])]
    before_left = np.r_[(a[1:] == Action.TURN_LEFT) & (c[1:] == c[:-1]), False]
    places = {
        "all": np.ones(len(a), dtype=bool),
        "after right": after_right & (x[:, 0] < _NEAR),
        "before corner": before_left & (a == Action.FORWARD) & walls_near,
        "left, walls near": (a == Action.TURN_LEFT) & walls_near,
    }
    return x, a, c, places


def _nearest_neighbour(train_x: np.ndarray, train_y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """1-NN labels of ``x`` [N, D] (Euclidean; ties to the first training point)."""
    d = torch.cdist(torch.as_tensor(x), torch.as_tensor(train_x))
    return train_y[d.argmin(dim=1).numpy()]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--circuits", type=int, default=1000)
    ap.add_argument("--first-seed", type=int_at_least(0), default=3_000_000)
    args = ap.parse_args()
    torch.set_num_threads(1)
    results = args.run_dir / "results.json"
    sessions = sorted(
        (p for p in (args.run_dir / "sessions").glob("seed*") if p.name[4:].isdigit()),
        key=lambda p: int(p.name[4:]),
    )
    if not results.is_file() or not sessions:
        raise SystemExit(
            f"no results.json and sessions/seed<N> under {args.run_dir}: expected a corridor run "
            "directory (bash scripts/reproduce.sh writes runs/reproduce/corridor)"
        )
    if args.circuits < 2:
        raise SystemExit(f"--circuits must be >= 2 (half fit, half test), got {args.circuits}")
    try:
        config = json.loads(results.read_text(encoding="utf-8"))["config"]
        world = WorldConfig(**config["world"])
        map_name = config["map_name"]
        # the run's threshold, read as the experiment reads it
        rule = CorridorExperimentConfig(
            map_name=map_name,
            world=world,
            max_std=config["max_std"],
            threshold_reading=config["threshold_reading"],
            ps=PrioritizedSweepingConfig(**config.get("ps", {})),  # a long map's cap, as run
        ).rule()
    except (ValueError, KeyError, TypeError) as exc:
        raise SystemExit(f"{results} is not a corridor run's results.json ({exc!r})") from None
    threshold = rule.threshold(len(SENSOR_NAMES))
    x, a, c, places = _expert_states(map_name, world, args.circuits, args.first_seed)
    names = [act.name.lower() for act in Action]
    named = [p for p in places if p != "all"]

    scale = x.std(axis=0)
    fit, test = c < args.circuits // 2, c >= args.circuits // 2
    nn = _nearest_neighbour(x[fit] / scale, a[fit], x[test] / scale)
    print(f"{args.circuits} expert circuits, {len(a)} states; threshold {threshold:.2f} std")
    reference = {}
    for name, where in places.items():
        w = where[test]
        reference[name] = {"states": int(w.sum()), "error": _share(nn[w] != a[test][w])}
    print(
        "1-NN on the readings, fitted on the first half of the circuits, tested on the second: "
        "error "
        + ", ".join(
            f"{name} {_fmt(r['error'], 3)} ({r['states']} states)" for name, r in reference.items()
        )
    )
    rows = {
        "turns right": a == Action.TURN_RIGHT,
        "u-turns": a == Action.U_TURN,
        **{p: places[p] for p in named},
    }
    print("\n| the expert's states | n | its actions | readings left, front, right: mean (sd), m |")
    print("|---|---|---|---|")
    for name, where in rows.items():
        acts = ", ".join(map(str, np.bincount(a[where], minlength=len(names))))
        if where.any():
            mean, sd = x[where].mean(axis=0), x[where].std(axis=0)
            cells = ", ".join(f"{m:.2f} ({v:.3f})" for m, v in zip(mean, sd, strict=True))
        else:
            cells = "-"
        print(f"| {name} | {where.sum()} | {acts} | {cells} |")
    print(
        "\n| seed | demonstrations: "
        + ", ".join(names)
        + " | another action, confident: all | "
        + " | ".join(named)
        + " | its actions: "
        + " | ".join(named)
        + " |"
    )
    print("|---" * (3 + 2 * len(named)) + "|")
    per_seed = []
    for session in sessions:
        try:
            model = load_model(session)
            _, y = load_demonstrations(session)
        except Exception as exc:  # noqa: BLE001 - one line for any unreadable session
            raise SystemExit(f"cannot read the session {session}: {exc}") from None
        cls = model.classify(torch.as_tensor(x))
        act = cls.action.numpy()
        confident_wrong = (act != a) & (cls.distance.numpy() <= threshold)
        demos = np.bincount(y, minlength=len(names)).tolist()
        shares = {name: _share(confident_wrong[w]) for name, w in places.items()}
        chosen = {p: np.bincount(act[places[p]], minlength=len(names)).tolist() for p in named}
        per_seed.append(
            {
                "seed": int(session.name[4:]),
                "demonstrations": demos,
                "confident_wrong": shares,
                "actions": chosen,
            }
        )
        print(
            f"| {session.name[4:]} | {', '.join(map(str, demos))} | "
            + " | ".join(_fmt(shares[p], 3) for p in places)
            + " | "
            + " | ".join(", ".join(map(str, chosen[p])) for p in named)
            + " |",
            flush=True,
        )
    print(
        json.dumps(
            {
                "run_dir": str(args.run_dir),
                "circuits": args.circuits,
                "first_seed": args.first_seed,
                "threshold": threshold,
                "actions": names,
                "nearest_neighbour": reference,
                "per_seed": per_seed,
            }
        )
    )


def _share(flags: np.ndarray) -> float | None:
    """The share of True in ``flags``; None (not NaN) when there are none."""
    return float(flags.mean()) if len(flags) else None


def _fmt(value: float | None, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


if __name__ == "__main__":
    main()
