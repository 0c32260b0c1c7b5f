"""Why does CBA keep asking on the noisy corridor? Which of its two gates says no, and where.

Runs the corridor experiment's CBA arm (``CorridorExperimentConfig().cba``: the experiment's
config, env, expert, model and stop; :class:`torchcbl.strategies.cba.ConfidenceBasedAutonomy`
with the library's defaults) per seed in ONE process. The strategy is a subclass that notes,
at every confident-phase decision, whether each gate passed: the margin gate (the log-posterior
margin between the chosen action and the runner-up above ``thresholds[chosen, runner-up]``)
and the distance gate (the standardised distance to the nearest stored demonstration below
``distance_threshold``). Its decisions are the library's own (asserted at each one).

Prints per seed: labels, corrections, confident steps, requests and which gate refused them
(margin only, distance only, both), the share of requests at which the model's own action
was the teacher's, requests per whole circuit of confident execution (as the experiment
counts them: not the circuit in which the non-interactive phase ended) over the first and last
20, the margin thresholds of the boundaries the last 20 circuits' margin refusals fell on,
and the distance threshold at the start of the confident phase and at the end. Ends with one
JSON line.

    PYTHONPATH=$PWD python scripts/corridor_cba_gates.py [--seeds 0-9]

About 2 minutes for 10 seeds on one core (each seed runs to the 4,000-step cap).
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import torch

from corridor.env import CorridorEnv
from corridor.experiment import CorridorExperimentConfig, make_model
from corridor.expert import CorridorExpert
from corridor.maps import load_map
from corridor.world import Action
from torchcbl import ConfidentTeacher
from torchcbl.strategies import correcting
from torchcbl.strategies.cba import ConfidenceBasedAutonomy, posterior_margin

sys.path.insert(0, str(Path(__file__).resolve().parent))  # _args, also when loaded by path
from _args import seeds as seed_list  # noqa: E402

_NAMES = [a.name.lower() for a in Action]
_LAST = 20  # circuits at each end of the confident phase


class _Noting(ConfidenceBasedAutonomy):
    """CBA that notes each confident-phase gate check (margin passed, distance passed, the
    boundary) without changing what it decides."""

    def __init__(self) -> None:
        super().__init__()
        self.notes: list[tuple[bool, bool, int, int]] = []

    def _confident(self, observation: np.ndarray, c: Any) -> bool:
        decided = super()._confident(observation, c)
        if self.thresholds is None:
            return decided
        picked, second, margin = posterior_margin(np.asarray(c.posterior, dtype=np.float64))
        chosen, runner = int(picked[0]), int(second[0])
        margin_ok = bool(margin[0] > self.thresholds[chosen, runner])
        distance_ok = self.nn_distance(observation) < self.distance_threshold
        assert decided == (margin_ok and distance_ok)
        self.notes.append((margin_ok, distance_ok, chosen, runner))
        return decided


def _seed(config: CorridorExperimentConfig, seed: int) -> dict[str, Any]:
    corridor_map = load_map(config.map_name)
    env = CorridorEnv(corridor_map, config.world)
    strategy = _Noting()
    loop = ConfidentTeacher(
        env,
        correcting(CorridorExpert(corridor_map, config.world)),
        model=make_model(config, seed),
        strategy=strategy,
        config=config.teaching,
        seed=seed,
        progress=False,
    )
    # the distance gate when the confident phase begins
    first_threshold: list[float] = []

    def on_step(record: Any) -> None:
        if record.phase == "confident" and not first_threshold:
            first_threshold.append(strategy.distance_threshold)

    loop.on_step = on_step
    loop.run()
    records = loop.records
    conf = [r for r in records if r.phase == "confident"]
    # one note per confident-phase decision after the first refit, in step order
    assert len(strategy.notes) == len(conf)
    asked = [
        (n, r) for n, r in zip(strategy.notes, conf, strict=True) if r.teacher_action is not None
    ]
    kinds = collections.Counter(
        "both" if not m and not d else "margin" if not m else "distance"
        for (m, d, _, _), _ in asked
    )
    agreed = sum(1 for _, r in asked if r.model_action == r.teacher_action)
    per_circuit = collections.Counter(r.episode for _, r in asked)
    # whole circuits of confident execution, as the experiment counts them: not the one in
    # which the non-interactive phase ended
    switching = {r.episode for r in records if r.phase == "noninteractive"}
    circuits = sorted(
        {r.episode for r in conf if (r.terminated or r.truncated) and r.episode not in switching}
    )
    counts = [per_circuit[e] for e in circuits]
    late = set(circuits[-_LAST:])
    boundaries = collections.Counter(
        (c, b) for (m, _, c, b), r in asked if not m and r.episode in late
    )
    thr = strategy.thresholds
    return {
        "seed": seed,
        "labels": loop.n_demonstrations,
        "corrections": loop.n_corrections,
        "finished": loop.stop_reason == "autonomous_episodes",
        "confident_steps": len(conf),
        "requests": len(asked),
        "refused_by_margin_only": kinds["margin"],
        "refused_by_distance_only": kinds["distance"],
        "refused_by_both": kinds["both"],
        "model_agreed_share": agreed / len(asked) if asked else None,
        "requests_per_circuit_first": float(np.mean(counts[:_LAST])) if counts else None,
        "requests_per_circuit_last": float(np.mean(counts[-_LAST:])) if counts else None,
        "circuits": len(counts),
        "late_margin_boundaries": [
            {
                "chosen": _NAMES[c],
                "runner_up": _NAMES[b],
                "refusals": n,
                "threshold": float(thr[c, b]),
            }
            for (c, b), n in boundaries.most_common()
        ],
        "distance_threshold_first": first_threshold[0] if first_threshold else None,
        "distance_threshold_last": strategy.distance_threshold,
    }


def _text(value: float | None, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--seeds", type=seed_list, default="0-9", help="e.g. 0-9 or 0,3,5 (default 0-9)"
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    config = CorridorExperimentConfig()
    rows = [_seed(config, s) for s in args.seeds]
    print(
        "| seed | labels | corrections | finished | confident steps | requests | margin only "
        "| distance only | both | model = teacher | per circuit, first 20 / last 20 |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['seed']} | {r['labels']} | {r['corrections']} | {r['finished']} "
            f"| {r['confident_steps']} | {r['requests']} | {r['refused_by_margin_only']} "
            f"| {r['refused_by_distance_only']} | {r['refused_by_both']} "
            f"| {_text(r['model_agreed_share'], '.0%')} "
            f"| {_text(r['requests_per_circuit_first'], '.2f')} / "
            f"{_text(r['requests_per_circuit_last'], '.2f')} |"
        )
    total = {
        k: sum(r[k] for r in rows)
        for k in (
            "requests",
            "refused_by_margin_only",
            "refused_by_distance_only",
            "refused_by_both",
        )
    }
    print()
    n = max(total["requests"], 1)
    print(
        f"All seeds: {total['requests']} confident-phase requests, refused by the margin gate "
        f"alone {total['refused_by_margin_only'] / n:.0%}, by the distance gate "
        f"alone {total['refused_by_distance_only'] / n:.0%}, by both "
        f"{total['refused_by_both'] / n:.0%}."
    )
    late = collections.Counter()
    thresholds = collections.defaultdict(list)
    for r in rows:
        for b in r["late_margin_boundaries"]:
            key = f"{b['chosen']} vs {b['runner_up']}"
            late[key] += b["refusals"]
            thresholds[key].append(b["threshold"])
    print("Margin refusals in each seed's last 20 circuits, by boundary (threshold at the end):")
    for key, n in late.most_common():
        t = thresholds[key]
        print(f"  {key}: {n} (thresholds {min(t):.2f}-{max(t):.2f} over {len(t)} seeds)")
    d0 = [r["distance_threshold_first"] for r in rows if r["distance_threshold_first"]]
    d1 = [r["distance_threshold_last"] for r in rows]
    print(
        f"Distance gate (standardised units): {np.mean(d0):.3f} when the confident phase "
        f"begins, {np.mean(d1):.3f} at the end (means over seeds)."
    )
    print(json.dumps({"seeds": rows, "totals": total}))


if __name__ == "__main__":
    main()
