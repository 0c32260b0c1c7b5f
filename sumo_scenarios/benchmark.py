"""The driving domain's entry in the strategy benchmark (:mod:`torchcbl.benchmark`).

:func:`teacher` is the teacher factory the benchmark imports by path
(``"sumo_scenarios.benchmark:teacher"``). It is the human-like teacher
(:func:`sumo_scenarios.teacher.make_teacher`), the driving experiment's default; to benchmark
another teacher (the consistent scripted expert: ``sumo_scenarios.expert:ScriptedExpert``),
pass its import path as ``EnvSpec.teacher`` (``torchcbl benchmark --driving-teacher
module:factory``).

:func:`env_spec` uses the paper's Section 5.2 settings where they are cheap enough (window 150,
target 80 %, bursts of 10, up to 10 components) with a refit every 5 labels; performance is
the share of contact-free steps of a greedy drive on the held-out ``eval`` road segment 0
(1 - the paper's collision rate).
"""

from __future__ import annotations

from typing import Any

__all__ = ["env_spec", "teacher"]


def teacher(seed: int = 0, env: Any = None) -> Any:
    """The driving teacher for a run seed: the human-like one
    (:func:`sumo_scenarios.teacher.make_teacher`), made for ``env``'s step length (a
    ``DrivingEnv``, wrapped or not; None: the default 0.25 s)."""
    from sumo_scenarios.teacher import make_teacher

    if env is None:
        return make_teacher(seed)
    return make_teacher(seed, step_length_s=env.unwrapped.config.sim.step_length_s)


def env_spec(quick: bool = True) -> Any:
    """The driving benchmark entry; ``quick`` = budgets up to 400 labels and a 500-step
    evaluation drive (else up to 1000 labels, 1000 steps on 3 segments)."""
    from torchcbl.benchmark import EnvSpec

    budgets = (50, 100, 150, 200, 300, 400)
    if not quick:
        budgets += (500, 600, 800, 1000)
    return EnvSpec(
        name="driving",
        env_id="sumo_scenarios:torchcbl/Driving-v0",
        teacher="sumo_scenarios.benchmark:teacher",
        budgets=budgets,
        max_steps=1500 if quick else 4000,
        env_kwargs={"scenario": "train", "max_episode_steps": 1000},
        eval_env_kwargs={"scenario": "eval"},
        score="torchcbl.benchmark:no_penalty_share",
        eval_seeds=(0,) if quick else (0, 1, 2),
        eval_steps=500 if quick else 1000,
        teaching={"max_new": 5, "accuracy_window": 150, "target_accuracy": 0.8, "burst": 10},
        model={"max_components": 10, "criterion": "aic", "tol": 1e-4},
    )
