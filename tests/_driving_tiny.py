"""The driving experiment at a size that runs in seconds, shared by the tests that run it."""

from __future__ import annotations

from sumo_scenarios.experiment import DrivingExperimentConfig


def tiny_config(**overrides) -> DrivingExperimentConfig:
    """The experiment at a size that runs in seconds (one seed, short phases and episodes)."""
    settings = dict(
        seeds=(0,),
        eval_steps=100,
        accuracy_window=20,
        max_noninteractive=100,  # seed 0 reaches 80 % over 20 at 63 demonstrations
        confident_demos=20,
        stage_every=10,
        burst=5,
        arm_b_stages=(60, 80),
        max_new=10,
        max_components=3,
        train_episode_steps=100,
        ni_stage_every=20,
    )
    return DrivingExperimentConfig(**{**settings, **overrides})
