"""The corridor's entry in the strategy benchmark (:mod:`torchcbl.benchmark`).

:func:`teacher` is the teacher factory the benchmark imports by path
(``"corridor.benchmark:teacher"``); :func:`env_spec` is the corridor's
:class:`~torchcbl.benchmark.EnvSpec` (the paper's teaching settings: refit after every label,
window 20, target 90 %; performance = share of clean greedy circuits on held-out noise seeds).
"""

from __future__ import annotations

from typing import Any

__all__ = ["env_spec", "teacher"]


def teacher(env: Any) -> Any:
    """The scripted teleoperator of the env's map and robot (:class:`CorridorExpert`)."""
    from corridor.expert import CorridorExpert

    u = env.unwrapped
    return CorridorExpert(u.corridor_map, u.world.config)


def env_spec(quick: bool = True) -> Any:
    """The corridor benchmark entry; ``quick`` = budgets up to 150 labels, 2 x 5 eval circuits
    (else up to 300 labels, 4 x 5 circuits)."""
    from torchcbl.benchmark import EnvSpec

    budgets = (10, 20, 30, 40, 50, 60, 80, 100, 120, 150)
    if not quick:
        budgets += (200, 250, 300)
    return EnvSpec(
        name="corridor",
        env_id="corridor:torchcbl/Corridor-v0",
        teacher="corridor.benchmark:teacher",
        budgets=budgets,
        max_steps=600 if quick else 1500,
        score="torchcbl.benchmark:success_rate",
        eval_seeds=tuple(range(1_000_000, 1_000_002 if quick else 1_000_004)),
        eval_episodes=5,
        teaching={"max_new": 1, "accuracy_window": 20, "target_accuracy": 0.9},
    )
