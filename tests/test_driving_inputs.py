"""Driving-domain settings and inputs a user may plausibly give: numpy numbers, unusual but
valid settings, mistakes. Each test closes its env: libsumo holds one simulation per process."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from sumo_scenarios import metrics
from sumo_scenarios.env import DrivingConfig, DrivingEnv
from sumo_scenarios.render import render_frame
from sumo_scenarios.replay import (
    EpisodeRecorder,
    load_records,
    render_gif,
    replay,
    save_records,
)
from sumo_scenarios.scenarios import CAR_LENGTH_M, TrafficScenario
from sumo_scenarios.sim import SimConfig


@pytest.mark.parametrize(
    "step", [np.float64(0.25), np.float32(0.25), 0.25], ids=["float64", "float32", "float"]
)
def test_sim_config_takes_numpy_numbers_and_sumo_starts(step):
    # numpy 2's repr of a numpy float ("np.float64(0.25)") was passed to SUMO as the step
    # length: libsumo.start failed with "Invalid Number Format"
    env = DrivingEnv(DrivingConfig(sim=SimConfig(step_length_s=step, ego_start_m=np.int64(300))))
    try:
        obs, info = env.reset(seed=1)
        assert info["step_length_s"] == 0.25 and type(info["step_length_s"]) is float
        env.step(0)
    finally:
        env.close()
    with pytest.raises(ValueError, match="step_length_s must be a number"):
        SimConfig(step_length_s="0.25")
    with pytest.raises(ValueError, match="shift_margin_m must be a number"):
        SimConfig(shift_margin_m=True)


def test_a_step_long_enough_to_pass_through_a_car_unseen_is_refused():
    # contact is checked once a step; the ego passes a 20 mph car's 10 m contact window in
    # 0.56 s, so steps up to 1.0 s (allowed before) could miss a contact
    for step in (0.75, 1.0):
        with pytest.raises(ValueError, match=r"\[0.01, 0.5\] seconds, got .*unseen"):
            SimConfig(step_length_s=step)
    assert SimConfig(step_length_s=0.5).step_length_s == 0.5


def test_a_scenario_of_numpy_numbers_drives_records_and_replays(tmp_path):
    # a float32 spacing made every car position float32 (libsumo's moveTo refused it: "argument
    # 3 of type 'double'"), and a numpy int seed made save_records fail (not JSON serializable)
    scenario = TrafficScenario(
        name="mine",
        seed=np.int64(7),
        min_spacing_m=np.float32(15.0),
        mean_spacing_m=np.array([40.0, 35.0, 100.0], dtype=np.float32),
        speed_ranges_mph=[[20, 30], [25, 35], [30, 40]],
    )
    env = EpisodeRecorder(DrivingEnv(scenario=scenario, max_episode_steps=30))
    try:
        obs, _ = env.reset(seed=3)
        observations = [obs]
        for k in range(30):
            obs, *_ = env.step(k % 3)
            observations.append(obs)
    finally:
        env.close()
    save_records(env.episodes, tmp_path / "episodes.json")
    (record,) = load_records(tmp_path / "episodes.json")
    assert record.scenario == scenario
    result, _ = replay(record)
    np.testing.assert_array_equal(result.observations, np.stack(observations))
    assert scenario.speed_ranges_mph == ((20.0, 30.0), (25.0, 35.0), (30.0, 40.0))
    hash(scenario)  # a frozen dataclass of tuples, as the named scenarios are


def test_a_shift_margin_too_small_for_the_scenario_is_refused_and_the_least_one_drives():
    # a margin below the farthest a new car is placed ahead let cars reach the end of the edge
    # before the shift; SUMO removed them and step() failed after about 1,400 steps with
    # libsumo's "Vehicle 'c51' is not known" (seed 3 of this sparse traffic, default SimConfig)
    sparse = TrafficScenario(
        name="sparse", seed=0, min_spacing_m=200.0, mean_spacing_m=(300.0, 300.0, 300.0)
    )
    with pytest.raises(ValueError, match="shift_margin_m = 400.0 m is too small"):
        DrivingEnv(scenario=sparse, max_episode_steps=3000)
    with pytest.raises(ValueError, match="at least 268.7 m"):
        DrivingEnv(sim=SimConfig(shift_margin_m=100.0))
    least = 200.0 + 250.0 + 60 * 0.44704 * 0.25
    env = DrivingEnv(scenario=sparse, max_episode_steps=3000, sim=SimConfig(shift_margin_m=least))
    try:
        env.reset(seed=3)
        truncated = False
        while not truncated:
            _, _, _, truncated, info = env.step(0)
    finally:
        env.close()
    assert info["position_m"] > 20_000  # 20 km on the 10 km road: past at least one shift


def _orange_pixels(image: np.ndarray) -> int:
    return int(np.all(image == np.array([255, 165, 0]), axis=-1).sum())


def test_render_outlines_a_car_in_contact_in_the_lane_the_ego_just_left():
    # contact counts the cars of the lane the ego left in this step, but the drawing looked
    # for a prev_lane the Frame did not have: such a car was drawn as if nothing touched it
    env = DrivingEnv(render_mode="rgb_array", max_episode_steps=10_000)
    rng = np.random.default_rng(1)
    try:
        env.reset(seed=1)
        for _ in range(2000):
            _, _, _, _, info = env.step(int(rng.integers(3)))
            rel, lanes = np.asarray(info["car_rel_m"]), np.asarray(info["car_lane"])
            near = np.abs(rel) < CAR_LENGTH_M
            if info["contact"] and not np.any(lanes[near] == info["lane"]):
                break
        else:
            pytest.fail("no contact with a car of the lane just left")
        frame = env.frame()
        image = env.render()
    finally:
        env.close()
    keep = np.abs(frame.car_pos - frame.ego_pos) >= CAR_LENGTH_M
    without = dataclasses.replace(frame, car_pos=frame.car_pos[keep], car_lane=frame.car_lane[keep])
    # the ego is outlined either way; the car it touches adds its own outline
    assert _orange_pixels(image) > _orange_pixels(render_frame(without)) > 0
    assert frame.prev_lane != frame.ego_lane and frame.prev_lane in lanes[near]


def test_lane_distribution_refuses_lanes_that_are_not_whole_indices():
    # 2.7 was truncated to lane 2 without a word
    with pytest.raises(ValueError, match="whole lane indices"):
        metrics.lane_distribution([2.7, 3.2, 4.9])
    with pytest.raises(ValueError, match="whole lane indices"):
        metrics.lane_distribution([2.0, np.nan])
    with pytest.raises(ValueError, match="1-D"):
        metrics.lane_distribution([[1, 2], [3, 4]])
    # the observation's lane column (float32 whole numbers) and ints are lanes
    obs_lanes = np.array([2.0, 3.0, 3.0, 4.0], dtype=np.float32)
    np.testing.assert_array_equal(metrics.lane_distribution(obs_lanes), [0, 0, 0.25, 0.5, 0.25])
    np.testing.assert_array_equal(metrics.lane_distribution([0, 4]), [0.5, 0, 0, 0, 0.5])


def test_per_step_flags_that_are_not_flags_are_refused():
    # a None (a step without a teacher's answer) made every later accuracy window NaN, a NaN
    # counted as a contact, and a float window was numpy's IndexError
    with pytest.raises(ValueError, match="correct must be True / False"):
        metrics.windowed_accuracy([True, None, True], window=2)
    with pytest.raises(ValueError, match="correct must be True / False"):
        metrics.windowed_accuracy([1.0, np.nan, 1.0], window=2)
    with pytest.raises(ValueError, match="window must be an int"):
        metrics.windowed_accuracy([True, False], window=2.0)
    with pytest.raises(ValueError, match="contacts must be True / False"):
        metrics.collision_rate([np.nan, 0.0])
    np.testing.assert_allclose(
        metrics.windowed_accuracy(np.array([1, 0, 1]), window=2), [1, 0.5, 0.5]
    )
    assert metrics.collision_rate(np.array([True, False, False, False])) == 0.25


_ONE = ["--seeds", "1", "--steps", "1"]  # were a mistake let through: one short measurement


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--seeds", "1", "--steps", "0"], "--steps and --keep"),  # collision_rate's ValueError
        (["--seeds", "1", "--first-seed", "-1"], "--first-seed must be >= 0"),  # numpy's
        (["--search", "2", "--keep", "0", "--first-seed", "100"], "--steps and --keep"),  # % 0
        (["--search", "1", "--left-spacings", "abc", "--first-seed", "100"], "--left-spacings"),
        (["--search", "1", "--left-spacings", "5", "--first-seed", "100"], "at least 12"),
        # the check's segments are 0-99: a search or rescore from 99 would share segment 99
        (["--search", "1", *_ONE, "--first-seed", "99"], "other segments than the check's 0-99"),
        (["--rescore", "1", *_ONE, "--first-seed", "99"], "other segments than the check's 0-99"),
        (["--rescore", "1", *_ONE, "--first-seed", "100"], "needs a search history"),  # other
    ],
)
def test_calibration_command_reports_a_mistake_in_one_line(argv, says, tmp_path, capsys):
    # each was a traceback (from the first measurement or a pool worker), not a usage error
    from sumo_scenarios.calibrate_teacher import main

    history = tmp_path / "history.jsonl"
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--history", str(history)])
    assert exc.value.code == 2
    assert says in capsys.readouterr().err
    assert not history.exists()


@pytest.mark.parametrize(
    ("content", "says"),
    [
        (None, "is not a file"),  # a directory: IsADirectoryError
        ("garbage\n", "line 1: not JSON"),  # JSONDecodeError
        ('{"t": 3, "episode": 0}\n', "line 1: not a measurement"),  # a session's log: KeyError
        ("[1, 2]\n", "line 1: not a measurement"),
        # settings today's HumanDriverConfig does not take (a history of an older teacher):
        # a TypeError in a search worker
        ("STALE", "line 1: not a measurement of today's teacher"),
    ],
)
@pytest.mark.parametrize("mode", ["--search", "--rescore"])
def test_calibration_command_names_a_history_that_is_not_one(content, says, mode, tmp_path, capsys):
    # each was a traceback, from reading the history or from a worker
    from sumo_scenarios.calibrate_teacher import _defaults, main

    good = {"driver": _defaults(), "spacing": [40.0, 31.0, 120.0], "collisions": 0.0}
    good.update(lanes=[0.02, 0.03, 0.15, 0.4, 0.4], stay=0.7)
    if content == "STALE":
        stale = dict(good, driver={**_defaults(), "patience_s": 1.0})
        content = json.dumps(stale) + "\n"
    history = tmp_path / "history.jsonl"
    if content is None:
        history.mkdir()
    else:
        history.write_text(json.dumps(good) + "\n" + content)
        says = says.replace("line 1", "line 2")  # the bad line, after a good one
    with pytest.raises(SystemExit) as exc:
        main(
            [
                mode,
                "1",
                "--seeds",
                "1",
                "--steps",
                "1",
                "--first-seed",
                "100",
                "--history",
                str(history),
            ]
        )
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert says in err and str(history) in err and "Traceback" not in err
    if content is not None:  # nothing appended to it
        assert history.read_text() == json.dumps(good) + "\n" + content


def test_a_refused_reset_changes_no_later_road(tmp_path):
    # a reset refused for its ego_lane or fcd_output had already drawn the next road's seed
    # from the env's RNG (or reseeded it): the user's next reset() drove another road
    first, second = DrivingEnv(), DrivingEnv()
    try:
        first.reset(seed=3)
        want = [first.reset()[1]["episode_seed"], first.reset()[1]["episode_seed"]]
        second.reset(seed=3)
        with pytest.raises(ValueError, match="ego_lane"):
            second.reset(options={"ego_lane": 9})
        with pytest.raises(ValueError, match="fcd_output"):
            second.reset(options={"fcd_output": str(tmp_path / "missing" / "ep.fcd.xml")})
        with pytest.raises(ValueError, match="ego_lane"):
            second.reset(seed=11, options={"ego_lane": -1})
        got = [second.reset()[1]["episode_seed"], second.reset()[1]["episode_seed"]]
        assert got == want
    finally:
        first.close()
        second.close()


def test_render_fps_is_real_time_for_the_step_length():
    # it was 4 whatever the step length: a video of 0.1 s steps (e.g. gymnasium's RecordVideo,
    # which plays frames at metadata["render_fps"]) ran at 0.4 times real time
    fast = DrivingEnv(sim=SimConfig(step_length_s=0.1), render_mode="rgb_array")
    default = DrivingEnv(render_mode="rgb_array")
    try:
        assert fast.metadata["render_fps"] == pytest.approx(10.0)
        assert default.metadata["render_fps"] == 4.0
        assert DrivingEnv.metadata["render_fps"] == 4  # the class's own is left alone
    finally:
        fast.close()
        default.close()


def test_reset_seeds_and_drawing_settings_are_checked(tmp_path):
    env = DrivingEnv(max_episode_steps=40)
    try:
        # True was seed 1; a numpy int was refused by gymnasium's own seeding
        for bad in (True, -1, 1.5, "3"):
            with pytest.raises(ValueError, match="seed: expected None or an int >= 0"):
                env.reset(seed=bad)
        # libsumo's own exception before; the env goes on after the message
        with pytest.raises(ValueError, match="fcd_output: .* is a directory"):
            env.reset(seed=3, options={"fcd_output": str(tmp_path)})
        first = env.reset(seed=np.int64(3))[0]
        np.testing.assert_array_equal(first, env.reset(seed=3)[0])
        recorder = EpisodeRecorder(env, label="check")
        recorder.reset(seed=3)
        for _ in range(6):
            recorder.step(0)
        frame = env.frame()
    finally:
        env.close()
    for bad in ({"behind_m": -5.0}, {"ahead_m": float("nan")}, {"dpi": 0}):
        with pytest.raises(ValueError, match="must be a number > 0"):
            render_frame(frame, **bad)
    record = recorder.episodes[-1]
    for bad in ({"every": 1.5}, {"every": 0}, {"max_frames": True}, {"fps": float("inf")}):
        with pytest.raises(ValueError, match="every and max_frames must be ints"):
            render_gif(record, tmp_path / "x.gif", **bad)
    assert not (tmp_path / "x.gif").exists()


def test_a_clear_start_beyond_the_traffic_window_is_refused_and_one_up_to_it_drives():
    # the first car of each lane went past the clear stretch, beyond the window the road's
    # margin is sized for: with 10 km it was placed past the road's end, SUMO dropped it, and
    # the first step failed with libsumo's "Vehicle 'c2' is not known"
    for clear in (201.0, 1e4):
        with pytest.raises(
            ValueError, match=rf"start_clear_m must be at most ahead_m = 200.0 m .*got {clear}"
        ):
            TrafficScenario("clear", 0, start_clear_m=clear)
    env = DrivingEnv(
        scenario=TrafficScenario("clear", 0, start_clear_m=200.0), max_episode_steps=60
    )
    try:
        _, info = env.reset(seed=0)
        rel = np.asarray(info["car_rel_m"])
        assert not np.any((rel > -15.0) & (rel < 200.0))
        for _ in range(60):
            _, _, _, truncated, info = env.step(0)
        assert truncated and len(info["car_rel_m"]) > 0
    finally:
        env.close()


def test_total_variation_refuses_what_is_not_two_distributions():
    # percentages gave 20.0 (a "distance in [0, 1]"), a NaN share gave nan, counts above 1
    p = metrics.lane_distribution([1, 2, 2, 3, 3, 3, 3, 3, 3, 3])
    q = metrics.lane_distribution([3, 3, 3, 4, 4, 4, 4, 4, 2, 2])
    assert metrics.total_variation(p, q) == pytest.approx(0.5)
    assert metrics.total_variation(p.tolist(), tuple(q)) == metrics.total_variation(p, q)
    for bad, says in (
        ((100 * p, 100 * q), "p must sum to 1 .* sums to 100: .* percentages by 100"),
        ((p, np.bincount([2, 3, 3], minlength=5)), "q must sum to 1 .* sums to 3: divide counts"),
        (([np.nan, 1.0], [0.0, 1.0]), "p must be a 1-D sequence of finite shares >= 0"),
        (([1.5, -0.5], [0.0, 1.0]), "p must be a 1-D sequence of finite shares >= 0"),
        ((0.5, 0.5), "p must be a 1-D sequence"),
        (([], []), "p must be a 1-D sequence"),
        ((["a"], [1.0]), "p must be a sequence of shares"),
        ((p, [0.5, 0.5]), "shapes differ"),
    ):
        with pytest.raises(ValueError, match=says):
            metrics.total_variation(*bad)


def test_with_seed_checks_the_seed_as_the_field_is():
    # with_seed(2.7) was the scenario of base seed 2 and with_seed(True) of seed 1, silently
    base = TrafficScenario("mine", 0)
    assert base.with_seed(np.int64(5)) == TrafficScenario("mine", 5)
    assert type(base.with_seed(np.int64(5)).seed) is int
    for bad in (2.7, True, -1, "3"):
        with pytest.raises(ValueError, match=rf"seed must be an int >= 0, got {bad!r}"):
            base.with_seed(bad)


@pytest.mark.parametrize(
    "field, bad, says",
    [
        # each was a TypeError of Python's own ('Value after * must be an iterable, not
        # float', "'int' object is not iterable") or a message without the value given
        ("mean_spacing_m", 40.0, r"mean_spacing_m needs one entry per normal lane .* got 40.0"),
        ("mean_spacing_m", (40.0, 31.0), r"3 in all, got \(40.0, 31.0\)"),
        ("mean_spacing_m", "abc", r"mean_spacing_m needs one entry .* got 'abc'"),
        ("mean_spacing_m", (5.0, 31.0, 120.0), r">= min_spacing_m \(12.0\), got \(5.0, 31"),
        ("mean_spacing_m", (None, 31.0, 120.0), r"finite number of metres .* got \(None"),
        ("speed_ranges_mph", (20.0, 30.0), r"speed_ranges_mph needs one entry .* \(20.0, 30.0\)"),
        ("speed_ranges_mph", None, r"speed_ranges_mph needs one entry .* got None"),
        ("speed_ranges_mph", ((20, 30), (25, 35), 30), r"range must be \(low, high\) .* got 30"),
        ("speed_ranges_mph", ((20, None), (25, 35), (30, 40)), r"got \(20, None\)"),
        ("speed_ranges_mph", ((10, 30), (25, 35), (30, 40)), r"20 <= low <= high <= 40 mph"),
        ("min_spacing_m", 8.0, r"min_spacing_m must exceed 10 m \(two car lengths\), got 8.0"),
        ("min_spacing_m", "12", r"min_spacing_m must be a finite number of metres, got '12'"),
        ("behind_m", 10.0, r"behind_m >= 30 m and ahead_m >= 60 m, got behind_m=10.0"),
        ("ahead_m", 50.0, r"got behind_m=60.0, ahead_m=50.0"),
    ],
)
def test_a_malformed_scenario_field_is_named_with_its_value(field, bad, says):
    with pytest.raises(ValueError, match=says):
        TrafficScenario("mine", 0, **{field: bad})


def test_per_lane_fields_take_lists_and_arrays():
    plain = TrafficScenario("mine", 0, mean_spacing_m=(40.0, 31.0, 60.0))
    assert TrafficScenario("mine", 0, mean_spacing_m=[40, 31, 60]) == plain
    assert TrafficScenario("mine", 0, mean_spacing_m=np.array([40.0, 31.0, 60.0])) == plain
    ranges = np.array([[20.0, 30.0], [25.0, 35.0], [30.0, 40.0]])
    assert TrafficScenario("mine", 0, speed_ranges_mph=ranges).speed_ranges_mph == (
        (20.0, 30.0),
        (25.0, 35.0),
        (30.0, 40.0),
    )


def test_a_scenario_that_is_neither_a_name_nor_a_traffic_scenario_is_named():
    # a dict (say, from a config file) or a list was Python's "unhashable type: 'dict'"
    for bad in ({"name": "mine", "seed": 0}, ["train"]):
        with pytest.raises(ValueError, match=r"scenario must be a name \(eval, light, train\) or"):
            DrivingConfig(scenario=bad)
    # DrivingEnv takes a dict of TrafficScenario fields (gymnasium's EnvSpec.to_json writes
    # one; tests/test_driving.py); a list is no scenario there either
    with pytest.raises(ValueError, match=r"got list \['train'\]"):
        DrivingEnv(scenario=["train"])
    with pytest.raises(ValueError, match="unknown scenario 'busy'; known: eval, light, train"):
        DrivingConfig(scenario="busy")


def test_the_human_like_teacher_takes_only_a_whole_seed():
    # make_teacher int()-ed its seed: 1.5 and True gave seed 1's teacher, None a TypeError
    from sumo_scenarios.teacher import make_teacher

    obs = np.array([12.0, -25.0, 25.0, 2.0], dtype=np.float32)
    info = {"closing_speed_ms": {1: 8.0, 2: 0.0, 3: 0.0}, "step_length_s": 0.25, "t": 0}

    def answers(teacher):
        return [teacher(obs, dict(info, t=t)) for t in range(40)]

    assert answers(make_teacher(np.int64(7))) == answers(make_teacher(7))
    for bad in (1.5, True, None, -1, "1"):
        with pytest.raises(ValueError, match=rf"seed: expected an int >= 0, got {bad!r}"):
            make_teacher(bad)


def test_expert_settings_out_of_order_or_not_numbers_are_named_with_their_values():
    # the order was refused without the values given; text was a TypeError of a comparison
    from sumo_scenarios.expert import ExpertConfig

    with pytest.raises(ValueError, match=r"change_far_m <= 25 .* got min_gap_m=10.0, "):
        ExpertConfig(change_far_m=30.0)
    with pytest.raises(ValueError, match=r"got min_gap_m=4.0, enter_ahead_m=16.0, change_far"):
        ExpertConfig(min_gap_m=4.0)
    for field, bad in (("min_gap_m", "10"), ("enter_ahead_m", None), ("change_far_m", np.nan)):
        with pytest.raises(ValueError, match=rf"{field} must be a finite number of metres"):
            ExpertConfig(**{field: bad})
    with pytest.raises(ValueError, match="return_spread_m must be a finite number of metres"):
        ExpertConfig(return_spread_m="1")
    assert ExpertConfig(min_gap_m=np.float64(10.0)) == ExpertConfig()


def test_expert_settings_are_kept_as_plain_numbers():
    """DrivingConfig, SimConfig and WorldConfig keep numpy numbers as plain ones; ExpertConfig
    kept them as given, so a config from a numpy sweep failed json.dumps (found in review)."""
    import json

    from sumo_scenarios.expert import ExpertConfig

    config = ExpertConfig(min_gap_m=np.float32(12.0), change_far_m=np.int64(24))
    assert type(config.min_gap_m) is float and type(config.change_far_m) is float
    assert json.loads(json.dumps(dataclasses.asdict(config)))["min_gap_m"] == 12.0


def test_load_records_names_a_file_that_holds_no_episode_records(tmp_path):
    # a JSON object was "string indices must be integers", an item without an episode's keys
    # KeyError('scenario'), a list of numbers "'int' object is not subscriptable"
    good = EpisodeRecorder(DrivingEnv(max_episode_steps=3))
    try:
        good.reset(seed=1)
        for _ in range(3):
            good.step(0)
    finally:
        good.close()
    save_records(good.episodes, tmp_path / "ok.json")
    assert load_records(tmp_path / "ok.json") == good.episodes
    record = good.episodes[0].to_dict()
    cases = {
        "object.json": ({"episodes": []}, r"object.json holds a JSON dict, not a list of episode"),
        "numbers.json": ([1, 2], r"numbers.json: an episode record is a dict with keys .* got 1"),
        "steps.json": ([{"step": 0}], r"keys \['scenario', .*got a dict with keys \['step'\]"),
        "scenario.json": (
            [dict(record, scenario="train")],
            r"scenario and sim are dicts of their fields, got 'train'",
        ),
        "field.json": (
            [dict(record, sim=dict(record["sim"], speed=1.0))],
            r"field.json: .*unexpected keyword argument 'speed'",
        ),
    }
    for name, (data, says) in cases.items():
        (tmp_path / name).write_text(json.dumps(data))
        with pytest.raises(ValueError, match=says):
            load_records(tmp_path / name)
    (tmp_path / "text.json").write_text("not json")
    with pytest.raises(ValueError, match=r"text.json is not JSON \(Expecting value"):
        load_records(tmp_path / "text.json")


def test_a_driving_config_of_numpy_ints_keeps_plain_ints():
    # kept as numpy ints, they made json.dumps of the config's asdict fail ("Object of type
    # int64 is not JSON serializable")
    config = DrivingConfig(start_lane=np.int64(3), max_episode_steps=np.int32(20))
    assert config == DrivingConfig(start_lane=3, max_episode_steps=20)
    assert type(config.start_lane) is int and type(config.max_episode_steps) is int
    assert json.loads(json.dumps(dataclasses.asdict(config)))["start_lane"] == 3
    env = DrivingEnv(config)
    try:
        assert env.reset(seed=0)[1]["lane"] == 3
    finally:
        env.close()


def test_drawing_before_a_reset_is_refused_not_an_empty_road():
    # render() and frame() before any reset (or after a failed one) drew a road with no car and
    # the ego at 0 m, as if that were the scene
    env = DrivingEnv(render_mode="rgb_array")
    try:
        for draw in (env.render, env.frame):
            with pytest.raises(RuntimeError, match="reset\\(\\) first: there is no scene to draw"):
                draw()
        with pytest.raises(ValueError, match="fcd_output"):
            env.reset(seed=1, options={"fcd_output": "/nonexistent-dir/x.xml"})
        with pytest.raises(RuntimeError, match="reset\\(\\) first"):
            env.render()
        env.reset(seed=1)
        assert env.render().shape[2] == 3 and env.frame().ego_pos == 300.0
    finally:
        env.close()
    assert env.render().shape[2] == 3  # the last scene stays drawable after close()


def test_render_without_a_render_mode_warns_and_says_what_to_pass():
    """DrivingEnv.render() of an env made without render_mode (gymnasium.make(ENV_ID)) returned
    None and said nothing, where gymnasium's own envs and CorridorEnv warn: a user drawing
    frames got None with no hint why. It warns now, naming render_mode='rgb_array'."""
    import gymnasium as gym

    import sumo_scenarios

    env = gym.make(sumo_scenarios.ENV_ID)
    try:
        env.reset(seed=1)
        with pytest.warns(UserWarning, match="render_mode=None; pass render_mode='rgb_array'"):
            assert env.render() is None
    finally:
        env.close()


def test_the_figure_helpers_refuse_data_that_does_not_line_up():
    # plot_lane_bars drew one distribution for two labels (numpy broadcast it) and failed with
    # an IndexError on 3 lanes; plot_confidence_trace failed with an IndexError on a contact
    # list one short and drew a NaN contact as a contact
    from matplotlib.figure import Figure

    ax = Figure().add_subplot()
    share = [0.1, 0.2, 0.3, 0.4, 0.0]
    metrics.plot_lane_bars(ax, ["a", "b"], [share, share], [0.01, 0.02])
    for labels, dists, rates in (
        (["a", "b"], [share], [0.01, 0.02]),
        (["a"], [[0.5, 0.5, 0.0]], [0.01]),
        (["a", "b"], [share, share], [0.01]),
    ):
        with pytest.raises(ValueError, match="one distribution over the 5 lanes and one"):
            metrics.plot_lane_bars(ax, labels, dists, rates)
    metrics.plot_confidence_trace(ax, [1.0, np.inf, 2.0], [False, True, False])
    with pytest.raises(ValueError, match=r"one entry per timestep each, got \(3,\) and \(2,\)"):
        metrics.plot_confidence_trace(ax, [1.0, 2.0, 3.0], [True, False])
    with pytest.raises(ValueError, match="contacts must be True / False per timestep"):
        metrics.plot_confidence_trace(ax, [1.0, 2.0], [np.nan, 1])


def test_render_gif_checks_its_path_before_replaying(tmp_path, monkeypatch):
    # a missing directory, a directory, or a name imageio cannot place failed only after the
    # whole replay and drawing; a name without a suffix left an empty file behind
    import sumo_scenarios.replay as replay_module

    env = EpisodeRecorder(DrivingEnv(max_episode_steps=3))
    try:
        env.reset(seed=1)
        for _ in range(3):
            env.step(0)
    finally:
        env.close()
    (record,) = env.episodes
    replays = []
    real = replay_module.replay
    monkeypatch.setattr(replay_module, "replay", lambda *a, **k: replays.append(1) or real(*a, **k))
    (tmp_path / "dir.gif").mkdir()
    for bad, says in (
        (tmp_path / "absent" / "ep.gif", "the directory of .* does not exist; create it first"),
        (tmp_path / "dir.gif", "is a directory; give the GIF's file path"),
        (tmp_path / "ep", "render_gif writes a GIF: give a path ending in .gif"),
        (tmp_path / "ep.mp4", "render_gif writes a GIF: give a path ending in .gif, got .*ep.mp4"),
    ):
        with pytest.raises(ValueError, match=says):
            render_gif(record, bad)
    assert not replays and not (tmp_path / "ep").exists()
    assert render_gif(record, tmp_path / "ep.GIF").stat().st_size > 0


def test_an_unknown_render_mode_is_named():
    # "render_mode must be one of ['rgb_array']" did not say what was given
    for bad in ("human", "rgb"):
        with pytest.raises(ValueError, match=rf"one of \['rgb_array'\] .* got '{bad}'"):
            DrivingEnv(render_mode=bad)


def test_a_step_length_sumo_cannot_run_is_refused_and_a_float32_one_runs_exactly():
    # SUMO counts whole milliseconds: 0.0125 s ran as 0.013 s (the ego moved 0.3487 m a step,
    # not 0.3353) while speeds were measured over, and the teachers told, 0.0125 s
    from sumo_scenarios.scenarios import EGO_SPEED_MS

    for bad, near in ((0.0125, 0.012), (0.2505, 0.25)):
        with pytest.raises(
            ValueError, match=rf"whole number of milliseconds .* got {bad}; e.g. {near}"
        ):
            SimConfig(step_length_s=bad)
    assert SimConfig(step_length_s=np.float32(0.1)).step_length_s == 0.1
    env = DrivingEnv(sim=SimConfig(step_length_s=np.float32(0.013)))
    try:
        _, info = env.reset(seed=1)
        start = info["position_m"]
        for _ in range(10):
            _, _, _, _, info = env.step(0)
    finally:
        env.close()
    assert info["step_length_s"] == 0.013
    moved = (info["position_m"] - start) / 10
    assert moved == pytest.approx(EGO_SPEED_MS * info["step_length_s"], rel=1e-9)


def test_the_keyboard_teachers_row_height_is_checked_when_it_is_made():
    # make_teacher took any metres_per_row and the session failed at its first question
    # ("'<' not supported between instances of 'int' and 'str'"); True drew 1 m rows
    from sumo_scenarios.human import describe, make_teacher

    obs = np.array([10.0, -5.0, 25.0, 2.0], dtype=np.float32)
    for bad in ("2", None, True, 0, 30, np.nan):
        with pytest.raises(ValueError, match=r"metres_per_row must be metres in \(0, 25\], got"):
            make_teacher(metres_per_row=bad)
        with pytest.raises(ValueError, match="metres_per_row must be metres"):
            describe(obs, metres_per_row=bad)
    assert describe(obs, metres_per_row=np.float32(5.0)) == describe(obs, metres_per_row=5.0)
    make_teacher(metres_per_row=5)


def test_a_record_made_with_a_scenario_name_is_saved_as_one_load_records_reads(tmp_path):
    # EpisodeRecord took scenario="train" and replayed it, and save_records wrote it as the name,
    # which load_records (and torchcbl replay) then refused: "scenario and sim are dicts of
    # their fields, got 'train'"; a sim that is no SimConfig failed only in the replay
    from sumo_scenarios.replay import EpisodeRecord
    from sumo_scenarios.scenarios import TRAIN

    record = EpisodeRecord("train", SimConfig(), episode_seed=5, start_lane=2, actions=(0, 1))
    assert record.scenario == TRAIN
    save_records([record], tmp_path / "mine.json")
    assert load_records(tmp_path / "mine.json") == [record]
    with pytest.raises(ValueError, match=r"unknown scenario 'trian'"):
        EpisodeRecord("trian", SimConfig(), episode_seed=5, start_lane=2, actions=(0,))
    with pytest.raises(ValueError, match=r"sim: expected a SimConfig .* got dict"):
        EpisodeRecord(TRAIN, {"step_length_s": 0.25}, episode_seed=5, start_lane=2, actions=(0,))


def test_an_episode_record_takes_the_three_actions_and_refuses_a_fourth():
    """The driving env has three actions, 0 (stay), 1 (left), 2 (right): a record holding
    each is taken and reads back as itself; one holding 3 is refused, made or read."""
    from sumo_scenarios.replay import EpisodeRecord

    record = EpisodeRecord("train", SimConfig(), episode_seed=5, start_lane=2, actions=(0, 1, 2))
    assert EpisodeRecord.from_dict(json.loads(json.dumps(record.to_dict()))) == record
    says = r"actions: expected 0 \(stay\), 1 \(left\) or 2 \(right\) at every step, got \[3\]"
    with pytest.raises(ValueError, match=says):
        EpisodeRecord("train", SimConfig(), episode_seed=5, start_lane=2, actions=(0, 3))
    with pytest.raises(ValueError, match=says):
        EpisodeRecord.from_dict({**record.to_dict(), "actions": [2, 3]})


def test_the_recorder_keeps_recording_an_episode_a_refused_reset_left_running():
    # a reset the env refuses (an unknown option) leaves its episode running, and stepping on
    # is allowed; the recorder had closed that episode before the env's reset refused, so the
    # steps that followed were recorded nowhere (and the record ended two steps early)
    env = EpisodeRecorder(DrivingEnv(max_episode_steps=10))
    try:
        env.reset(seed=1)
        env.step(0)
        with pytest.raises(ValueError, match="unknown reset options"):
            env.reset(seed=2, options={"ego_lan": 3})
        env.step(1)
        env.step(2)
        (record,) = env.episodes
        assert (record.episode_seed, record.actions) == (1, (0, 1, 2))
        env.reset(seed=3)
        env.step(0)
    finally:
        env.close()
    assert [(e.episode_seed, e.actions) for e in env.episodes] == [(1, (0, 1, 2)), (3, (0,))]


def test_a_config_that_is_no_driving_config_is_named():
    # DrivingEnv("eval") (the scenario given where the config goes) and gymnasium.make(...,
    # config={...}) were AttributeError: "'str' object has no attribute 'scenario'"
    import gymnasium

    import sumo_scenarios

    with pytest.raises(
        TypeError, match=r"expected a DrivingConfig .*, got str 'eval'; .*scenario='eval'"
    ):
        DrivingEnv("eval")
    # a dict of DrivingConfig fields is taken (gymnasium's EnvSpec.to_json writes one); a list
    # is no config
    with pytest.raises(
        TypeError, match=r"expected a DrivingConfig .* or a dict of its fields, got list"
    ):
        gymnasium.make(sumo_scenarios.ENV_ID, config=["eval"])
    # with keyword settings beside it, too (it said "not both" of a DrivingConfig never given)
    with pytest.raises(TypeError, match=r"expected a DrivingConfig .*, got str 'eval'"):
        DrivingEnv("eval", max_episode_steps=200)


def test_load_records_names_a_damaged_scenario_of_a_record(tmp_path):
    # a record whose scenario lacked mean_spacing_m escaped load_records as KeyError
    # ('mean_spacing_m'), and a per-lane field that is no list read "'int' object is not
    # iterable"
    from sumo_scenarios.replay import EpisodeRecord

    record = EpisodeRecord("train", SimConfig(), episode_seed=5, start_lane=2, actions=(0,))
    good = record.to_dict()
    cases = (
        ("mean_spacing_m", None, r"bad.json: .*scenario lacks mean_spacing_m"),
        ("speed_ranges_mph", 5, r"bad.json: speed_ranges_mph needs one entry per normal lane"),
    )
    for field, value, says in cases:
        scenario = {k: v for k, v in good["scenario"].items() if k != field}
        if value is not None:
            scenario[field] = value
        (tmp_path / "bad.json").write_text(json.dumps([dict(good, scenario=scenario)]))
        with pytest.raises(ValueError, match=says):
            load_records(tmp_path / "bad.json")


def _package_copy(tmp_path):
    """A copy of the sumo_scenarios package in ``tmp_path/site`` (a test may damage its data
    files; the checkout's stay as they are)."""
    import shutil

    import sumo_scenarios

    site = tmp_path / "site"
    shutil.copytree(
        Path(sumo_scenarios.__file__).parent,
        site / "sumo_scenarios",
        ignore=shutil.ignore_patterns("__pycache__"),
    )
    return site


def _run_on(site, tmp_path, code, *args):
    """The lines ``code`` prints, run by a process of its own on the package copy ``site``
    (in ``tmp_path``); it must exit 0."""
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-c", code, *args],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin"},
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stdout + out.stderr[-2000:]
    return out.stdout.splitlines()


def test_an_fcd_output_naming_a_shipped_data_file_is_refused(tmp_path):
    """reset(options={"fcd_output": <the shipped road.net.xml or driving.add.xml>}): SUMO read
    the file and then wrote the episode's FCD over it, which broke the install for good (every
    later DrivingEnv failed with KeyError 'road'). Now the reset refuses, naming the file, and
    the file is unchanged. Run on a copy of the package, in a process of its own."""
    site = _package_copy(tmp_path)
    data = site / "sumo_scenarios" / "data"
    before = {n: (data / n).read_bytes() for n in ("road.net.xml", "driving.add.xml")}
    (tmp_path / "link.xml").symlink_to(data / "driving.add.xml")
    code = (
        "import sys\n"
        "from sumo_scenarios.env import DrivingEnv\n"
        "env = DrivingEnv(scenario='light')\n"
        "for path in sys.argv[1:]:\n"
        "    try:\n"
        "        env.reset(seed=0, options={'fcd_output': path})\n"
        "        env.step(0)\n"
        "        print('accepted', path)\n"
        "    except ValueError as exc:\n"
        "        print(exc)\n"
        "env.reset(seed=0)\n"
        "env.close()\n"
    )
    lines = _run_on(site, tmp_path, code, str(data / "road.net.xml"), str(tmp_path / "link.xml"))
    assert len(lines) == 2, lines
    for line, name in zip(lines, ("road.net.xml", "link.xml"), strict=True):
        assert line.startswith("fcd_output: "), line
        assert name in line and "shipped" in line, line
    assert {n: (data / n).read_bytes() for n in before} == before


def test_a_damaged_shipped_network_is_named_with_the_way_to_rebuild_it(tmp_path):
    """The shipped road.net.xml overwritten (by an FCD, as an fcd_output naming it once did) or
    truncated: DrivingEnv() failed with a bare KeyError 'road' or sumolib's SAXParseException.
    Now a RuntimeError names the file and the command that rebuilds it. Run on a copy of the
    package, in a process of its own."""
    site = _package_copy(tmp_path)
    code = (
        "from sumo_scenarios.env import DrivingEnv\n"
        "from sumo_scenarios.scenarios import data_path\n"
        "for text in ('<fcd-export/>', '<net version=', ''):\n"
        "    data_path('road.net.xml').write_text(text)\n"
        "    try:\n"
        "        DrivingEnv(scenario='light')\n"
        "        print('accepted')\n"
        "    except RuntimeError as exc:\n"
        "        print(exc)\n"
    )
    lines = _run_on(site, tmp_path, code)
    assert len(lines) == 3, lines
    for line in lines:
        assert str(site / "sumo_scenarios" / "data" / "road.net.xml") in line, line
        assert "python -m sumo_scenarios.build_network" in line, line


def test_a_missing_shipped_data_file_is_named_with_the_way_to_restore_it(tmp_path):
    """A shipped data file deleted: DrivingEnv() (road.net.xml) or reset() (driving.add.xml,
    also when the fcd_output check compares a path with it) raises a FileNotFoundError naming
    the file and how to restore it. (For driving.add.xml it said "regenerate it with `python -m
    sumo_scenarios.build_network`", which writes only the network: the vehicle types are
    hand-written, and the advice left the install broken.) Run on a copy of the package, in a
    process of its own."""
    site = _package_copy(tmp_path)
    data = site / "sumo_scenarios" / "data"
    (tmp_path / "old.fcd.xml").write_text("<fcd-export/>")
    code = (
        "import os\n"
        "from sumo_scenarios.env import DrivingEnv\n"
        "from sumo_scenarios.scenarios import data_path\n"
        "env = DrivingEnv(scenario='light')\n"
        "for options in ({'fcd_output': 'old.fcd.xml'}, {}):\n"
        "    try:\n"
        "        env.reset(seed=0, options=options)\n"
        "        print('accepted')\n"
        "    except FileNotFoundError as exc:\n"
        "        print(exc)\n"
        "env.close()\n"
        "os.remove(data_path('road.net.xml'))\n"
        "try:\n"
        "    DrivingEnv(scenario='light')\n"
        "    print('accepted')\n"
        "except FileNotFoundError as exc:\n"
        "    print(exc)\n"
    )
    (data / "driving.add.xml").unlink()
    lines = _run_on(site, tmp_path, code)
    assert len(lines) == 3, lines
    for line in lines[:2]:
        assert line.startswith(f"{data / 'driving.add.xml'} is missing"), line
        assert "reinstall" in line and "build_network" not in line, line
    assert lines[2].startswith(f"{data / 'road.net.xml'} is missing"), lines[2]
    assert "python -m sumo_scenarios.build_network" in lines[2], lines[2]


def test_a_name_that_is_no_shipped_data_file_is_named_with_the_shipped_ones():
    """data_path("mynet.net.xml") said the file "is missing: the install is damaged" and gave
    the git checkout that restores it, for a file that never shipped. It now says the name is
    no shipped data file and lists the shipped ones; a shipped name still gives its path."""
    from sumo_scenarios.scenarios import data_path

    for name in ("mynet.net.xml", "src/mine.nod.xml"):
        with pytest.raises(FileNotFoundError) as caught:
            data_path(name)
        message = str(caught.value)
        assert message.startswith(f"{name!r} is not a data file sumo_scenarios ships"), message
        assert "road.net.xml, driving.add.xml, src/road.nod.xml, src/road.edg.xml" in message
        assert "damaged" not in message and "git checkout" not in message, message
    assert data_path("road.net.xml").name == "road.net.xml"
    assert data_path("src/road.nod.xml").is_file()


def test_no_lane_is_ever_empty_and_a_far_lane_reads_its_nearest_cars_side():
    """DrivingEnv's docstring said a lane reads "+25 if a lane were empty", yet no lane can be:
    the sparsest traffic a scenario allows (every spacing at its cap, the narrowest window)
    still keeps a car in every normal lane at every step, and a lane whose nearest car is out
    of sensing range reads +-25 with that car's side, as the docstring now says."""
    sparse = TrafficScenario(
        name="sparse", seed=0, mean_spacing_m=(1e6, 1e6, 1e6), ahead_m=60.0, behind_m=30.0
    )
    env = DrivingEnv(scenario=sparse, max_episode_steps=200)
    try:
        obs, info = env.reset(seed=0)
        sides = set()
        for t in range(201):
            lanes, rel = np.asarray(info["car_lane"]), np.asarray(info["car_rel_m"])
            for k, lane in enumerate((1, 2, 3)):
                mine = rel[lanes == lane]
                assert mine.size, (t, lane)
                near = mine[np.argmin(np.abs(mine))]
                assert obs[k] == pytest.approx(np.clip(near, -25.0, 25.0), abs=1e-4), (t, lane)
                if abs(near) >= 25.0:
                    sides.add(float(np.sign(near)))
            if t < 200:
                obs, _, _, _, info = env.step(0)
        assert sides == {-1.0, 1.0}  # both far sides were seen
    finally:
        env.close()


def test_a_step_cap_given_to_gymnasium_make_only_shortens_a_drive_as_documented():
    """gymnasium.make keeps its max_episode_steps for a TimeLimit outside DrivingEnv, so a cap
    above the env's own changes nothing (the env truncates first), without a warning; the
    env's own cap goes through make in a DrivingConfig. The docstring now says so."""
    import warnings

    import gymnasium as gym

    import sumo_scenarios

    def steps(env):
        env.reset(seed=0)
        try:
            for n in range(1, 100):
                if env.step(0)[3]:
                    return n
        finally:
            env.close()

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        own = DrivingConfig(scenario="light", max_episode_steps=5)
        assert steps(gym.make(sumo_scenarios.ENV_ID, config=own, max_episode_steps=50)) == 5
        assert steps(gym.make(sumo_scenarios.ENV_ID, scenario="light", max_episode_steps=3)) == 3
    assert "which the env cannot see" in " ".join(sumo_scenarios.env.__doc__.split())
