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
    in on both sides (both side readings below 0.5 m);
- the readings at those places, and where the expert turns right and u-turns;
- each seed's demonstrations per action.

Ends with one JSON line. About 12 s for 1,000 circuits::

    PYTHONPATH=$PWD python scripts/corridor_final_policy_check.py runs/reproduce/corridor \\
        [--circuits 1000] [--first-seed 3000000]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import torch

from corridor.env import CorridorEnv
from corridor.expert import CorridorExpert
from corridor.maps import load_map
from corridor.world import Action, WorldConfig
from torchcbl import DistanceRule, load_model
from torchcbl.session import load_demonstrations

_NEAR = 0.5  # metres: a side reading below this is a wall beside the robot


def _expert_states(
    map_name: str, world: WorldConfig, circuits: int, first_seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Readings [N, 3], expert actions [N], circuit index [N] and the place tags [N] (0 none,
    1 "after right", 2 "before corner") of ``circuits`` expert circuits."""
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
    tag = np.zeros(len(a), dtype=int)
    after_right = np.r_[False, (a[:-1] == Action.TURN_RIGHT) & (c[1:] == c[:-1])]
    tag[after_right & (x[:, 0] < _NEAR)] = 1
    before_left = np.r_[(a[1:] == Action.TURN_LEFT) & (c[1:] == c[:-1]), False]
    tag[before_left & (a == Action.FORWARD) & (x[:, 0] < _NEAR) & (x[:, 2] < _NEAR)] = 2
    return x, a, c, tag


def _nearest_neighbour(train_x: np.ndarray, train_y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """1-NN labels of ``x`` [N, D] (Euclidean; ties to the first training point)."""
    d = torch.cdist(torch.as_tensor(x), torch.as_tensor(train_x))
    return train_y[d.argmin(dim=1).numpy()]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--circuits", type=int, default=1000)
    ap.add_argument("--first-seed", type=int, default=3_000_000)
    args = ap.parse_args()
    torch.set_num_threads(1)
    results = args.run_dir / "results.json"
    sessions = sorted((args.run_dir / "sessions").glob("seed*"), key=lambda p: int(p.name[4:]))
    if not results.is_file() or not sessions:
        raise SystemExit(
            f"no results.json and sessions/seed* under {args.run_dir}: expected a corridor run "
            "directory (bash scripts/reproduce.sh writes runs/reproduce/corridor)"
        )
    if args.circuits < 2:
        raise SystemExit(f"--circuits must be >= 2 (half fit, half test), got {args.circuits}")
    config = json.loads(results.read_text())["config"]
    world = WorldConfig(**config["world"])
    if config["threshold_reading"] == "literal":
        rule = DistanceRule(config["max_std"])
    else:
        rule = DistanceRule(quantile=math.erf(config["max_std"] / math.sqrt(2.0)))
    threshold = rule.threshold(3)
    x, a, c, tag = _expert_states(config["map_name"], world, args.circuits, args.first_seed)
    places = {
        "all": np.ones(len(a), dtype=bool),
        "after right": tag == 1,
        "before corner": tag == 2,
    }

    scale = x.std(axis=0)
    fit, test = c < args.circuits // 2, c >= args.circuits // 2
    nn = _nearest_neighbour(x[fit] / scale, a[fit], x[test] / scale)
    print(
        f"{args.circuits} expert circuits ({len(a)} states; 'after right' "
        f"{places['after right'].sum()}, 'before corner' {places['before corner'].sum()}); "
        f"threshold {threshold:.2f} std"
    )
    reference = {}
    for name, where in places.items():
        w = where[test]
        reference[name] = {"states": int(w.sum()), "error": float(np.mean(nn[w] != a[test][w]))}
    print(
        "1-NN on the readings, fitted on the first half, tested on the second: error "
        + ", ".join(
            f"{name} {r['error']:.3f} ({r['states']} states)" for name, r in reference.items()
        )
    )
    readings = {
        "turns right": a == Action.TURN_RIGHT,
        "after right": places["after right"],
        "u-turns": a == Action.U_TURN,
        "before corner": places["before corner"],
    }
    print("\n| the expert's states | n | readings left, front, right: mean (sd), m |")
    print("|---|---|---|")
    for name, where in readings.items():
        mean, sd = x[where].mean(axis=0), x[where].std(axis=0)
        cells = ", ".join(f"{m:.2f} ({v:.3f})" for m, v in zip(mean, sd, strict=True))
        print(f"| {name} | {where.sum()} | {cells} |")
    names = [act.name.lower() for act in Action]
    print(
        "\n| seed | demonstrations: " + ", ".join(names) + " | another action, confident: "
        "all | after right | before corner | its actions after right |"
    )
    print("|---|---|---|---|---|---|")
    per_seed = []
    for session in sessions:
        model = load_model(session)
        cls = model.classify(torch.as_tensor(x))
        act = cls.action.numpy()
        confident_wrong = (act != a) & (cls.distance.numpy() <= threshold)
        _, y = load_demonstrations(session)
        demos = np.bincount(y, minlength=len(names)).tolist()
        shares = {name: float(confident_wrong[w].mean()) for name, w in places.items()}
        after = np.bincount(act[places["after right"]], minlength=len(names)).tolist()
        per_seed.append(
            {
                "seed": session.name,
                "demonstrations": demos,
                "confident_wrong": shares,
                "actions_after_right": after,
            }
        )
        print(
            f"| {session.name[4:]} | {', '.join(map(str, demos))} | {shares['all']:.3f} | "
            f"{shares['after right']:.2f} | {shares['before corner']:.2f} | "
            f"{', '.join(map(str, after))} |",
            flush=True,
        )
    print(
        json.dumps(
            {
                "run_dir": str(args.run_dir),
                "circuits": args.circuits,
                "first_seed": args.first_seed,
                "threshold": threshold,
                "nearest_neighbour": reference,
                "per_seed": per_seed,
            }
        )
    )


if __name__ == "__main__":
    main()
