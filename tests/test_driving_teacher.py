"""Calibration of the driving domain and the generic human timing of a teacher."""

from __future__ import annotations

import numpy as np
import pytest

from sumo_scenarios import metrics
from sumo_scenarios.calibrate_teacher import CHECK_SEGMENTS, measure
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
    assert HumanTimingConfig(delay_probs=[0.5, 0.5]).delay_probs == (0.5, 0.5)  # hashable
    with pytest.raises(TypeError, match="config must be a HumanTimingConfig, got dict"):
        HumanTiming(lambda obs, info: 0, {"miss_prob": 0.1})
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
    for bad in (-1, 1.0, True, "0"):  # found only when a press was pending, before
        with pytest.raises(ValueError, match="default_action must be an action index"):
            HumanTimingConfig(default_action=bad)
    with pytest.raises(ValueError, match="miss_prob must be a probability in"):
        HumanTimingConfig(miss_prob=float("nan"))


def test_a_person_watching_corrects_only_with_a_key_press():
    """As a correcting teacher (CBA, HG-DAgger: correct() at every autonomous step) the timed
    person answered the default key while a press was pending or after a lost one, so a
    learner that did just what the person wanted was "corrected" to the default: with a
    teacher that always agrees with the learner, 98 of 200 steps came back as corrections.
    A correction is a key press that differs from the learner's action; no press, none; and
    where the learner does what the person wants, nothing is pressed (no doubled press of a
    key pressed for nothing either)."""
    from torchcbl.strategies import correcting

    cfg = HumanTimingConfig(delay_probs=(0.35, 0.45, 0.2), miss_prob=0.1, double_prob=0.1)
    wants = [int(x) for x in np.random.default_rng(1).integers(0, 3, 2000)]
    for teacher in (
        HumanTiming(lambda o, i: int(o[0]), cfg, seed=0),
        correcting(HumanTiming(lambda o, i: int(o[0]), cfg, seed=0)),
    ):
        # the learner does what the person wants at every step: nothing to correct
        got = [teacher.correct(np.array([a, 0.0]), {"t": t}, a) for t, a in enumerate(wants)]
        assert got == [None] * len(wants)
    # the learner stays where the person wants a lane change: the press, when it lands
    h = HumanTiming(lambda o, i: 1, cfg, seed=0)
    got = [h.correct(np.zeros(2), {"t": t}, 0) for t in range(400)]
    assert set(got) == {None, 1} and 0.3 < got.count(1) / 400 < 0.7  # a press per reaction
    # the learner changes lanes where the person wants to stay (the default, no key to
    # wait for): corrected at once, every time
    h = HumanTiming(lambda o, i: 0, cfg, seed=0)
    assert [h.correct(np.zeros(2), {"t": t}, 2) for t in range(50)] == [0] * 50
    # a press decided and still pending does not hold back that correction
    late = HumanTimingConfig(delay_probs=(0.0, 0.0, 1.0), miss_prob=0.0, double_prob=0.0)
    h = HumanTiming(lambda o, i: int(o[0]), late, seed=0)
    steps = [(1, 0), (0, 2), (0, 0)]  # (wanted, learner's action)
    got = [h.correct(np.array([w, 0.0]), {"t": t}, a) for t, (w, a) in enumerate(steps)]
    assert got == [None, 0, None]


@pytest.mark.parametrize("delay", [1, 2])
def test_a_pending_correction_is_dropped_when_the_learner_does_what_the_person_wants(delay):
    """correct(): where the learner does what the person wants, a press decided earlier and
    still pending is dropped. When the learner deviates again, the person reacts afresh: the
    correction comes a whole delay after the new deviation, not sooner on the old press's
    countdown."""
    cfg = HumanTimingConfig(delay_probs=(0.0,) * delay + (1.0,), miss_prob=0.0, double_prob=0.0)
    h = HumanTiming(lambda o, i: 1, cfg, seed=0)  # the person always wants action 1
    # the learner deviates (a press is decided, delayed), complies, then deviates for good
    actions = [2, 1] + [2] * (delay + 1)
    got = [h.correct(np.zeros(2), {"t": t}, a) for t, a in enumerate(actions)]
    assert got == [None, None] + [None] * delay + [1], got
    assert h.stats()["delayed"] == 2  # the first press and the fresh one


def test_human_timing_says_once_when_the_info_has_no_step_counter():
    """HumanTiming tells consecutive steps apart by info["t"]; on an env without it (the
    corridor's info counts "steps") every call is a gap, so each delayed press was silently
    lost and re-drawn at the next call, a teacher far slower than the configured one. It now
    warns, once, saying what to add."""
    import warnings

    cfg = HumanTimingConfig(delay_probs=(0.0, 1.0), miss_prob=0.0, double_prob=0.0)
    h = HumanTiming(lambda o, i: 1, cfg, seed=0)
    with pytest.warns(UserWarning, match=r"no 't'.*step counter") as caught:
        replies = [h(np.zeros(2), {"steps": k}) for k in range(5)]
    assert len(caught) == 1
    assert replies == [0] * 5  # the delay of one step never ends: every call is a gap
    timed = HumanTiming(lambda o, i: 1, cfg, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert [timed(np.zeros(2), {"t": k}) for k in range(3)] == [0, 1, 0]


def test_probabilities_the_configs_accept_are_usable_by_the_teachers():
    """A config accepts probabilities whose sum is within np.isclose of 1; the teacher used to
    pass them to numpy's choice as they were, which wants 1 to about 1e-8, so the first delayed
    press of a session (or building the driver) failed with "Probabilities do not sum to 1"."""
    from sumo_scenarios.teacher import HumanDriverConfig

    thirds = (0.333333, 0.333333, 0.333333)  # sums to 0.999999: accepted
    h = HumanTiming(lambda o, i: 1, HumanTimingConfig(delay_probs=thirds, miss_prob=0.0), seed=0)
    got = [h(np.zeros(2), {"t": t}) for t in range(300)]
    assert 0 < got.count(1) < 300 and h.stats()["delayed"] > 0
    driver = HumanDriver(HumanDriverConfig(home_weights=thirds), seed=0)
    homes = set()
    for t in range(200):
        _call(driver, (25.0, 25.0, 25.0), 4, t)
        homes.add(driver.home)
    assert homes == {2, 3, 4}


def test_driver_config_holds_its_own_tuples_whatever_sequences_it_was_given():
    """A list or an array given to a HumanDriverConfig used to be kept as it was: the frozen
    config was then unhashable (a list), its == raised (an array), and a list changed after
    the check changed every driver built from it, unchecked."""
    from sumo_scenarios.teacher import HumanDriverConfig

    margin = [0.0, 0.2]
    a = HumanDriverConfig(margin_s=margin, home_weights=np.array([0.5, 0.25, 0.25]))
    b = HumanDriverConfig(margin_s=(0.0, 0.2), home_weights=(0.5, 0.25, 0.25))
    assert a == b and hash(a) == hash(b)
    margin[0] = 5.0  # low > high: would fail the check
    assert a.margin_s == (0.0, 0.2)
    c = HumanDriverConfig(leave_room_s=[1.0, 2.0], return_behind_m=[6.0, 8.0])
    assert (c.leave_room_s, c.return_behind_m) == ((1.0, 2.0), (6.0, 8.0))
    assert HumanDriverConfig() == HumanDriverConfig(
        **{k: list(v) if isinstance(v, tuple) else v for k, v in vars(HumanDriverConfig()).items()}
    )


def test_a_driving_teacher_given_a_dict_for_its_config_says_so_at_once():
    """HumanTiming refused a dict config with a TypeError; HumanDriver (and make_teacher's
    driver=) failed with "'dict' object has no attribute 'home_weights'", and ScriptedExpert
    only at its first answer, mid-session, with "... no attribute 'min_gap_m'"."""
    with pytest.raises(TypeError, match="config must be a HumanDriverConfig, got dict"):
        HumanDriver({"home_every_s": 1.0})
    with pytest.raises(TypeError, match="config must be a HumanDriverConfig, got dict"):
        make_teacher(driver={"home_every_s": 1.0})
    with pytest.raises(TypeError, match="config must be an ExpertConfig, got dict"):
        ScriptedExpert({"min_gap_m": 12.0})


def test_timing_config_takes_numpy_probabilities():
    """miss_prob / double_prob given as a numpy float32 or int (e.g. read from an array) were
    refused with "must lie in [0, 1), got 0.03", a value that does lie there."""
    cfg = HumanTimingConfig(miss_prob=np.float32(0.25), double_prob=np.int64(0))
    assert (cfg.miss_prob, cfg.double_prob) == (float(np.float32(0.25)), 0.0)
    h = HumanTiming(
        lambda o, i: 0, HumanTimingConfig(delay_probs=(1.0,), miss_prob=np.float32(0.25))
    )
    got = _replies(h, [1, 0] * 1000)
    assert abs(got[::2].count(0) / 1000 - 0.25) < 0.05
    for bad in (np.float32(1.0), np.bool_(False), "0.1", float("nan")):
        with pytest.raises(ValueError, match="miss_prob must be a probability in"):
            HumanTimingConfig(miss_prob=bad)


def test_a_missed_press_is_pressed_again_after_a_new_reaction_delay():
    """After a miss the person reacts again, with a delay of its own (as the calibration ran);
    the docstring said "presses again at the next step"."""
    cfg = HumanTimingConfig(delay_probs=(0.0, 1.0), miss_prob=0.5, double_prob=0.0)
    h = HumanTiming(lambda o, i: 0, cfg, seed=0)
    got = _replies(h, [1] * 400)
    assert h.stats()["missed"] > 50
    assert got[0] == 0 and all(a == 0 for a, b in zip(got, got[1:], strict=False) if b == 1)
    assert all(got[k] == 0 for k in range(0, 400, 2))  # every press is one step late


def test_driver_config_refuses_nan_and_an_urgent_gap_beyond_the_normal_one():
    from sumo_scenarios.teacher import HumanDriverConfig

    for bad in (
        {"room_cap_s": float("nan")},
        {"margin_s": (0.0, float("inf"))},
        {"margin_s": (1.0,)},  # was an unpacking error
        {"lane_cost_s": -1.0},
        {"box_room_s": -1.0},
    ):
        with pytest.raises(ValueError, match=next(iter(bad))):
            HumanDriverConfig(**bad)
    from sumo_scenarios.expert import ExpertConfig

    for bad in ({"return_spread_m": float("nan")}, {"middle_pass": "yes"}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            ExpertConfig(**bad)
    with pytest.raises(ValueError, match="urgent_ttc_s"):
        HumanDriverConfig(urgent_ttc_s=-1.0)
    assert HumanDriverConfig(return_behind_m=None).return_behind_m is None


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


def test_the_teachers_reaction_times_are_seconds_whatever_the_step_length():
    """HumanTiming counts its delays in steps, made for the driving domain's 0.25 s: an env
    with another step length gave the person other reaction times in seconds, silently.
    make_teacher(step_length_s=) now counts the same reaction times in its steps (mean 0.2125
    s) and the teacher refuses an env whose steps differ; at 0.25 s nothing changes."""
    from sumo_scenarios.teacher import timing_for_step_length

    assert make_teacher(3).config == HumanTimingConfig() == timing_for_step_length(0.25)
    for step, delays in ((0.1, (0.35, 0.0, 0.225, 0.225, 0.0, 0.2)), (0.5, (0.575, 0.425))):
        cfg = make_teacher(3, step_length_s=step).config
        np.testing.assert_allclose(cfg.delay_probs, delays, atol=1e-12)
        mean_s = step * float(np.dot(cfg.delay_probs, np.arange(len(cfg.delay_probs))))
        assert mean_s == pytest.approx(0.2125)
    obs = np.array([25.0, 25.0, 25.0, 2.0], dtype=np.float32)
    info = {"closing_speed_ms": {1: 0.0, 2: 0.0, 3: 0.0}, "step_length_s": 0.25, "t": 0}
    with pytest.raises(ValueError, match=r"made for steps of 0.1 s .* make_teacher\(seed, "):
        make_teacher(3, step_length_s=0.1)(obs, info)
    assert make_teacher(3, step_length_s=0.1)(obs, dict(info, step_length_s=0.1)) in (0, 1, 2)
    with pytest.raises(ValueError, match="step_length_s: expected seconds > 0, got 0"):
        make_teacher(3, step_length_s=0)
    with pytest.raises(ValueError, match="step_length_s: expected seconds > 0, got -0.1"):
        timing_for_step_length(-0.1)
    # the benchmark's teacher factory reads the env's step length
    from sumo_scenarios.benchmark import teacher as bench_teacher
    from sumo_scenarios.sim import SimConfig

    env = DrivingEnv(sim=SimConfig(step_length_s=0.1))
    assert bench_teacher(3, env=env).config == make_teacher(3, step_length_s=0.1).config
    assert bench_teacher(3).config == HumanTimingConfig()
    env.close()


# ---------------------------------------------------------------- the human-like teacher (item 2)


@pytest.fixture(scope="module")
def human_drive():
    """The default human-like teacher alone on the calibration check's 100 training segments x
    1000 steps (``sumo_scenarios.calibrate_teacher``), measured as its calibration is:
    collision share, lane shares [5], "stay" share of its answers. (Ten segments put a teacher
    whose rate over 100 others was 0.46 % at 0.64 %: a standard error of about 0.15 point;
    thirty, the check until 2026-11-25, about 0.09, too coarse for a 0.5 % target: the teacher
    of 2026-11-25 reads 0.55 % on segments 0-29 and 0.445-0.48 % on four sets of 100.)"""
    r = measure({}, seeds=range(CHECK_SEGMENTS), steps=1000)
    return r["collisions"], np.asarray(r["lanes"]), r["stay"]


def test_human_teacher_keeps_to_the_left_three_lanes_and_rarely_the_right(human_drive):
    """The paper: "prefers to use the left three lanes, only rarely using the right lane and
    right shoulder" (issue 11: >= 85 % left three, right two > 0 and <= 15 %)."""
    _, lanes, _ = human_drive
    assert lanes[2:].sum() >= 0.85, lanes
    assert 0.0 < lanes[:2].sum() <= 0.15, lanes
    assert min(lanes[3], lanes[4]) >= 0.10, lanes


def test_human_teacher_collides_at_most_half_a_percent(human_drive):
    collisions, _, _ = human_drive
    assert collisions <= 0.005


@pytest.mark.xfail(
    strict=True,
    reason="calibration gap: the teacher is in the dense middle lane 9.8 % of the time (target "
    "10 %; 9.4-10.0 % on other sets of 100 segments): the traffic's physics (docs/reproduction.md)",
)
def test_human_teacher_uses_the_middle_lane(human_drive):
    _, lanes, _ = human_drive
    assert lanes[2] >= 0.10, lanes


@pytest.mark.xfail(
    strict=True,
    reason="calibration gap: 83.1 % of the teacher's answers are 'stay' (target < 80 %); a car "
    "met costs two lane changes and the traffic meets one every 10-23 steps (docs/reproduction.md)",
)
def test_human_teacher_is_no_always_stay_teacher(human_drive):
    _, _, stay = human_drive
    assert stay < 0.80


def _call(driver, d, lane, t, closing=(10.0, 10.0, 10.0)):
    obs = np.array([*d, lane], dtype=np.float32)
    info = {
        "closing_speed_ms": dict(zip((1, 2, 3), closing, strict=True)),
        "step_length_s": 0.25,
        "t": t,
    }
    return driver(obs, info)


def test_human_driver_home_lane_drifts_among_the_left_three():
    """Redrawn on average every ``home_every_s`` from the left three lanes (a redraw per step with
    probability step / ``home_every_s``)."""
    driver = HumanDriver(seed=0)
    homes = []
    for t in range(4000):
        _call(driver, (25.0, 25.0, 25.0), 4, t)
        homes.append(driver.home)
    assert set(homes) == {2, 3, 4}
    changes = int(np.sum(np.diff(homes) != 0))
    w = np.asarray(driver.config.home_weights)
    per_step = 0.25 / driver.config.home_every_s
    expected = 4000 * per_step * (1 - np.sum(w**2))  # redraws that land on another lane
    assert 0.6 * expected < changes < 1.4 * expected, (changes, expected)


def test_human_driver_breaks_a_tie_between_the_sides_at_random():
    """From the middle lane, its car ahead closing in fast and both neighbours equally free
    (no right-lane cost, home the middle lane): the two ways out tie, and the driver's choice
    is drawn, so over 20 seeds it goes both left and right (not always the first listed)."""
    from sumo_scenarios.teacher import HumanDriverConfig

    cfg = HumanDriverConfig(home_weights=(1.0, 0.0, 0.0), right_cost_s=0.0)
    moves = set()
    for seed in range(20):
        driver = HumanDriver(cfg, seed=seed)
        moves.add(_call(driver, (25.0, 8.0, 25.0), 2, 0))
        assert driver.last_move == "leave"
    assert moves == {1, 2}  # left and right


def test_human_driver_reaction_threshold_is_drawn_per_event():
    """A car closing in ahead, a free shoulder beside: the room (seconds to contact) at which the
    driver moves over spreads over more than the 0.25 s that a fixed threshold would give (the
    room drops by one step, 0.25 s, per step; the start varies within a step)."""
    from sumo_scenarios.teacher import HumanDriverConfig

    # home: the left lane, held to strongly enough (3 s of room per lane away) that only the
    # leave threshold moves the driver, not a better-looking shoulder
    cfg = HumanDriverConfig(home_weights=(0.0, 1.0, 0.0), home_every_s=1e9, lane_cost_s=3.0)
    rooms = []
    for seed in range(40):
        driver = HumanDriver(cfg, seed=seed)
        start = 24.0 - 2.5 * seed / 40
        for t, x in enumerate(np.arange(start, 5.0, -2.5)):
            if _call(driver, (25.0, -25.0, x), 3, t) != STAY:
                rooms.append((x - 5.0 - 2.5) / 10.0)
                break
    assert len(rooms) == 40  # always moved over before contact
    assert min(rooms) >= cfg.leave_room_s[0] - 0.25 - 1e-6
    assert max(rooms) <= cfg.leave_room_s[1] + 1e-6  # the first step below the drawn threshold
    assert max(rooms) - min(rooms) >= 0.4, rooms


def test_human_driver_direction_is_not_always_left_first():
    """In the left lane with a car closing in and both the middle lane and the left shoulder
    free, the way out depends on the drifting home lane: both directions occur."""
    moves = {_call(HumanDriver(seed=s), (25.0, 25.0, 9.0), 3, 0) for s in range(30)}
    assert moves == {1, 2}


def test_human_driver_crosses_a_lane_to_the_shoulder_when_boxed_in_the_middle():
    """In the middle lane with a car 12 m ahead closing at 10 m/s (urgent), a car alongside in
    the right lane and one 11 m ahead in the left lane (too close to stay in: 0.35 s of room
    after a step), the driver crosses the left lane toward the free left shoulder: that car
    leaves more than a car length for the two steps of the crossing. At 8 m it would not
    (3 m after two steps): the driver stays boxed in; with ``cross_steps = 0``, or when not
    urgent, it does not cross; from the left lane the middle lane is no crossing (no shoulder
    beyond it)."""
    from sumo_scenarios.teacher import HumanDriverConfig

    cfg = HumanDriverConfig(home_weights=(0.0, 1.0, 0.0), home_every_s=1e9)
    driver = HumanDriver(cfg, seed=0)
    assert _call(driver, (-1.0, 12.0, 11.0), 2, 0) == 1  # left
    assert driver.last_move == "cross"
    assert _call(HumanDriver(cfg, seed=0), (-1.0, 12.0, 8.0), 2, 0) == STAY
    off = HumanDriverConfig(home_weights=(0.0, 1.0, 0.0), home_every_s=1e9, cross_steps=0)
    assert _call(HumanDriver(off, seed=0), (-1.0, 12.0, 11.0), 2, 0) == STAY
    # not urgent (0.95 s of room): no crossing, though the left lane is as before
    assert _call(HumanDriver(cfg, seed=0), (-1.0, 17.0, 11.0), 2, 0) == STAY
    # in the left lane, home the middle lane, car 12 m ahead; the middle lane 11 m ahead (too
    # close to stay in) and no shoulder beyond it: not a crossing, so the left shoulder,
    # although home is the other way
    home_middle = HumanDriverConfig(home_weights=(1.0, 0.0, 0.0), home_every_s=1e9, lane_cost_s=2.0)
    driver = HumanDriver(home_middle, seed=0)
    assert _call(driver, (-1.0, 11.0, 12.0), 3, 0) == 1
    assert driver.last_move == "leave"
    with pytest.raises(ValueError, match="cross_steps"):
        HumanDriverConfig(cross_steps=-1)
    with pytest.raises(ValueError, match="cross_steps"):
        HumanDriverConfig(cross_steps=True)


def _returns_at(cfg, seeds=40):
    """On the left shoulder beside the left lane (home), that lane's nearest car falling behind
    by 2.5 m a step from a start that varies over 2.5 m: how far behind it is when the driver
    moves back, per seed."""
    back_at = []
    for seed in range(seeds):
        driver = HumanDriver(cfg, seed=seed)
        for t, x in enumerate(np.arange(2.0 - 2.5 * seed / seeds, -30.0, -2.5)):
            if _call(driver, (25.0, 25.0, x), 4, t) != STAY:
                back_at.append(-x)
                break
    return back_at


def test_human_driver_overtakes_and_returns_once_the_car_is_past():
    """Home: the left lane; on the left shoulder beside a slower car of the left lane, the driver
    moves back once that car is behind by a distance drawn per event from ``return_behind_m``
    (not before, and not always at the same distance), and not while a car it sees ahead in the
    left lane leaves less than ``return_room_s`` of room. Nor while a car that may be hidden
    ahead (at least as far ahead as the nearest is behind, closing at ``assumed_closing_ms``)
    would leave less than ``enter_ttc_s``: with the defaults that holds the driver back until
    the car passed is 5 + 8.282 * (0.25 + 0.482) = 11.1 m behind, whatever it drew."""
    from sumo_scenarios.teacher import HumanDriverConfig

    # a driver content with 0.05 s of room in the lane it enters: the drawn distance decides
    cfg = HumanDriverConfig(
        home_weights=(0.0, 1.0, 0.0), home_every_s=1e9, enter_ttc_s=0.05, urgent_ttc_s=0.05
    )
    lo, hi = cfg.return_behind_m
    back_at = _returns_at(cfg)
    assert len(back_at) == 40, back_at
    assert min(back_at) >= lo - 1e-6 and max(back_at) <= hi + 2.5 + 1e-6, back_at
    assert max(back_at) - min(back_at) >= 1.5, back_at
    # the default assumption: no return before the hidden car would leave enter_ttc_s
    default = HumanDriverConfig(home_weights=(0.0, 1.0, 0.0), home_every_s=1e9)
    c = default.assumed_closing_ms
    bound = 5.0 + c * 0.25 + c * default.enter_ttc_s
    back_at = _returns_at(default)
    assert len(back_at) == 40, back_at
    assert min(back_at) >= max(bound, default.return_behind_m[0]) - 1e-6, (bound, back_at)
    assert max(back_at) <= max(bound, default.return_behind_m[1]) + 2.5 + 1e-6, (bound, back_at)
    # a car seen ahead in the home lane, closing at 10 m/s: back only with enough room
    for x in (8.0, 12.0, 25.0):
        room = (x - 5.0 - 2.5) / 10.0
        moved = _call(HumanDriver(cfg, seed=0), (25.0, 25.0, x), 4, 0) != STAY
        assert moved == (x >= 25.0 or room >= cfg.return_room_s), (x, room)


def test_calibration_rescore_remeasures_the_best_of_a_history(tmp_path, capsys):
    """``--rescore K`` re-measures the K best settings of a search history on other segments
    and prints them ranked by the new measurement; it refuses the check's segments 0-99."""
    import json

    from sumo_scenarios.calibrate_teacher import _defaults, main, penalty

    history = tmp_path / "history.jsonl"
    lucky = {"driver": _defaults(), "spacing": [40.0, 31.0, 120.0], "collisions": 0.0}
    lucky.update(lanes=[0.02, 0.03, 0.15, 0.4, 0.4], stay=0.7)  # penalty 0: the search's best
    worse = dict(lucky, stay=0.9)
    history.write_text("".join(json.dumps(r) + "\n" for r in (worse, lucky)))
    args = ["--rescore", "1", "--seeds", "2", "--steps", "40", "--history", str(history)]
    assert main([*args, "--first-seed", "300"]) == 0
    (line,) = capsys.readouterr().out.splitlines()
    again = measure({}, seeds=range(300, 302), steps=40)
    assert line.startswith(f"{0.0:6.2f} -> {penalty(again):6.2f}")
    with pytest.raises(SystemExit) as exit_info:
        main([*args, "--first-seed", "0"])
    assert exit_info.value.code == 2
    assert "other segments than the check's 0-99" in capsys.readouterr().err


def test_calibration_measures_on_eval_with_the_teacher_seeded_as_the_experiment_seeds_it():
    """``measure(scenario="eval")`` drives segment s of eval with the teacher of seed
    10,000 + s, as the driving experiment's evaluation does (not the training seed s)."""
    from sumo_scenarios import metrics
    from sumo_scenarios.env import DrivingEnv
    from sumo_scenarios.teacher import make_teacher

    def by_hand(teacher_seed: int) -> list[float]:
        env = DrivingEnv(scenario="eval", max_episode_steps=10**6)
        teacher = make_teacher(teacher_seed)
        answers, lanes = [], []
        try:
            obs, info = env.reset(seed=1)
            for _ in range(150):
                answers.append(teacher(obs, info))
                obs, _, _, _, info = env.step(answers[-1])
                lanes.append(info["lane"])
        finally:
            env.close()
        return [*metrics.lane_distribution(lanes).tolist(), answers.count(0) / 150]

    r = measure({}, seeds=[1], steps=150, scenario="eval")
    got = [*r["lanes"], r["stay"]]
    assert got == pytest.approx(by_hand(10_001))
    assert got != pytest.approx(by_hand(1))


def test_contact_classification_counts_every_contact_of_the_teacher(capsys):
    """scripts/driving_teacher_contacts.py drives the teacher as its calibration does (same
    seeding: the same contact share as ``measure``) and gives each contact event one cause."""
    import importlib.util
    import json
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "driving_teacher_contacts.py"
    spec = importlib.util.spec_from_file_location("driving_teacher_contacts", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.main(["--seeds", "3", "--first-seed", "0", "--steps", "400"]) == 0
    r = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert r["collisions"] == measure({}, seeds=range(3), steps=400)["collisions"]
    assert r["steps"] == 1200 and r["contact_steps"] > 0  # these segments have contacts
    assert r["events"] == sum(r["causes"].values()) >= 1
    rear = sum(n for c, n in r["causes"].items() if c.startswith("rear-end"))
    assert sum(r["lanes_of_rear_ends"].values()) == rear
    assert mod.main(["--seeds", "0"]) == 2
    assert capsys.readouterr().err.startswith("error: ")


def test_calibration_objective_is_the_targets_only():
    """The search's score: 0 when every target holds, and the misses added up (collisions per
    0.05 point above 0.42 %, shares per point), hand-computed."""
    from sumo_scenarios.calibrate_teacher import penalty

    ok = {"collisions": 0.004, "lanes": [0.02, 0.03, 0.15, 0.4, 0.4], "stay": 0.79}
    assert penalty(ok) == 0.0
    miss = {"collisions": 0.0052, "lanes": [0.02, 0.03, 0.076, 0.474, 0.4], "stay": 0.84}
    assert penalty(miss) == pytest.approx(2.0 + 2.4 + 4.5)
    no_right = {"collisions": 0.0, "lanes": [0.0, 0.0, 0.2, 0.4, 0.4], "stay": 0.7}
    assert penalty(no_right) == pytest.approx(10.0)
