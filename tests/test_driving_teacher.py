"""Calibration of the driving domain and the generic human timing of a teacher."""

from __future__ import annotations

import numpy as np
import pytest

from sumo_scenarios import metrics
from sumo_scenarios.env import STAY, DrivingEnv
from sumo_scenarios.expert import ScriptedExpert
from sumo_scenarios.teacher import HumanDriver, make_teacher
from torchcbl.teachers import HumanTiming, HumanTimingConfig


@pytest.fixture
def eval_env():
    env = DrivingEnv(scenario="eval", max_episode_steps=10**6)
    yield env
    env.close()


def test_always_straight_in_the_middle_lane_collides_28_to_32_percent(eval_env):
    """The paper's calibration point (30.4 %): 8 held-out segments x 400 steps (100 s each)."""
    rates = []
    for seed in range(8):
        eval_env.reset(seed=seed)
        rates.append(
            metrics.collision_rate([eval_env.step(STAY)[4]["contact"] for _ in range(400)])
        )
    assert 0.28 <= np.mean(rates) <= 0.32, rates


def test_consistent_expert_collides_at_most_half_a_percent_in_the_left_lanes(eval_env):
    """3 segments x 400 steps: <= 0.5 % contact, >= 85 % in the left three lanes."""
    contacts, lanes = [], []
    for seed in range(3):
        expert = ScriptedExpert(seed=seed)
        obs, info = eval_env.reset(seed=seed)
        for _ in range(400):
            obs, _, _, _, info = eval_env.step(expert(obs, info))
            contacts.append(info["contact"])
            lanes.append(info["lane"])
    assert metrics.collision_rate(contacts) <= 0.005
    assert metrics.lane_distribution(lanes)[2:].sum() >= 0.85


def _replies(timing: HumanTiming, wanted: list[int]) -> list[int]:
    it = iter(wanted)

    def teacher(obs, info):
        return next(it)

    timing.teacher = teacher
    return [timing(np.zeros(2), {"t": t}) for t in range(len(wanted))]


def test_human_timing_delays_by_the_drawn_number_of_steps_and_is_seeded():
    cfg = HumanTimingConfig(delay_probs=(0.0, 0.0, 1.0), miss_prob=0.0, double_prob=0.0)
    # asked for "1" from step 3 on: pressed two steps late, at step 5; each press is its own event
    assert _replies(HumanTiming(lambda o, i: 0, cfg), [0, 0, 0, 1, 1, 1, 1]) == [
        0,
        0,
        0,
        0,
        0,
        1,
        0,
    ]
    # the reason to press went away before the key was due: nothing is pressed
    assert _replies(HumanTiming(lambda o, i: 0, cfg), [0, 1, 0, 0, 0]) == [0] * 5
    # a gap in the steps (the learner drove on its own) drops the pending press
    h = HumanTiming(lambda o, i: 1, cfg)
    assert [h(np.zeros(2), {"t": t}) for t in (0, 5, 9, 10, 11)] == [0, 0, 0, 0, 1]
    mixed = HumanTimingConfig(delay_probs=(0.35, 0.45, 0.2), miss_prob=0.1, double_prob=0.1)
    wanted = [int(x) for x in np.random.default_rng(0).integers(0, 3, 400)]
    a = _replies(HumanTiming(lambda o, i: 0, mixed, seed=3), wanted)
    assert a == _replies(HumanTiming(lambda o, i: 0, mixed, seed=3), wanted)
    assert a != _replies(HumanTiming(lambda o, i: 0, mixed, seed=4), wanted)


def test_human_timing_misses_and_doubles_presses_at_the_given_rates():
    cfg = HumanTimingConfig(delay_probs=(1.0,), miss_prob=0.2, double_prob=0.0)
    h = HumanTiming(lambda o, i: 0, cfg, seed=0)
    got = _replies(h, [1, 0] * 2000)
    assert abs(got[::2].count(0) / 2000 - 0.2) < 0.03  # missed presses answer the default
    cfg = HumanTimingConfig(delay_probs=(1.0,), miss_prob=0.0, double_prob=0.25)
    h = HumanTiming(lambda o, i: 0, cfg, seed=0)
    got = _replies(h, [2, 0, 0] * 2000)
    assert abs(sum(got[1::3]) / 2 / 2000 - 0.25) < 0.03  # repeated at the next step
    assert h.stats()["doubled"] == sum(got[1::3]) // 2
    with pytest.raises(ValueError, match="summing to 1"):
        HumanTimingConfig(delay_probs=(0.5, 0.2))


def test_human_driver_reads_only_what_a_driver_sees():
    """Same observation + closing speeds -> same answer, whatever the hidden per-car state."""
    obs = np.array([25.0, 12.0, -25.0, 2.0], dtype=np.float32)
    base = {"closing_speed_ms": {1: 0.0, 2: 13.0, 3: 0.0}, "step_length_s": 0.25, "t": 0}
    a = HumanDriver(seed=1)(obs, dict(base))
    b = HumanDriver(seed=1)(
        obs, dict(base, car_rel_m=np.array([1.0]), car_lane=np.array([2]), car_closing_ms=[0.0])
    )
    assert a == b
    with pytest.raises(ValueError, match="closing_speed_ms"):
        HumanDriver()(obs, {"t": 0})
    teacher = make_teacher(0)
    assert isinstance(teacher, HumanTiming) and isinstance(teacher.teacher, HumanDriver)
