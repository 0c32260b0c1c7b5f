"""Tests of the driving domain (sumo_scenarios). Each test closes its env: libsumo holds one
simulation per process."""

from __future__ import annotations

import gc
import os
import re

import gymnasium as gym
import libsumo
import numpy as np
import pytest
import sumolib
from gymnasium.envs.registration import EnvSpec
from gymnasium.utils.env_checker import check_env

import sumo_scenarios
from sumo_scenarios import metrics
from sumo_scenarios.env import LEFT, RIGHT, STAY, DrivingConfig, DrivingEnv
from sumo_scenarios.expert import ExpertConfig, ScriptedExpert
from sumo_scenarios.replay import EpisodeRecorder, export_fcd, render_gif, replay
from sumo_scenarios.scenarios import CAR_LENGTH_M, TrafficScenario, data_path
from sumo_scenarios.sim import SimConfig


@pytest.fixture
def env():
    e = DrivingEnv(scenario="train")
    yield e
    e.close()


def test_network_lane_order_and_shoulders():
    net = sumolib.net.readNet(str(data_path("road.net.xml")))
    lanes = net.getEdge("road").getLanes()
    assert len(lanes) == 5
    ys = [lane.getShape()[0][1] for lane in lanes]
    assert ys == sorted(ys), "lane 0 must be the rightmost (lowest y when driving along +x)"
    for lane in lanes:
        allowed = lane.getPermissions()
        if lane.getIndex() in (0, 4):
            assert "custom1" in allowed and "passenger" not in allowed
        else:
            assert {"custom1", "passenger"} <= set(allowed)
        assert lane.getSpeed() > 26.8224


def test_check_env_and_registration(env):
    check_env(env, skip_render_check=True)
    env.close()
    e = gym.make(sumo_scenarios.ENV_ID, scenario="eval")
    try:
        obs, info = e.reset(seed=0)
        assert e.observation_space.contains(obs) and info["lane"] == 2
        assert e.unwrapped.scenario.name == "eval"
    finally:
        e.close()


def test_check_env_in_full_on_the_registered_env():
    """gymnasium's checker makes second envs from the spec (its render and close checks)
    while the first is live: each takes the one libsumo simulation over in turn."""
    e = gym.make(sumo_scenarios.ENV_ID, render_mode="rgb_array")
    try:
        check_env(e.unwrapped)
    finally:
        e.close()


_MINE = TrafficScenario(name="mine", seed=7, mean_spacing_m=(50.0, 40.0, 90.0))


@pytest.mark.parametrize(
    "kwargs",
    [
        {
            "config": DrivingConfig(
                scenario=_MINE, max_episode_steps=40, start_lane=3, sim=SimConfig(0.1)
            )
        },
        {"scenario": _MINE, "sim": SimConfig(step_length_s=0.1), "start_lane": 1},
    ],
    ids=["config", "scenario-and-sim"],
)
def test_the_env_is_made_again_from_its_spec_as_json(kwargs):
    """gymnasium's ``EnvSpec.to_json`` writes an argument that is a dataclass as a dict of its
    fields (``dataclasses.asdict``), and ``gymnasium.make(EnvSpec.from_json(text))`` (what
    Minari's ``recover_environment`` does with a dataset's env) gives the env that dict: a
    ``DrivingConfig``, ``TrafficScenario`` or ``SimConfig`` came back as "expected a
    DrivingConfig, got dict" or "sim must be a SimConfig, got dict". The env made again is the
    same env: its settings and, from the same seed and actions, its observations."""
    made = gym.make(sumo_scenarios.ENV_ID, **kwargs)
    try:
        again = gym.make(EnvSpec.from_json(made.spec.to_json()))
        try:
            assert again.unwrapped.config == made.unwrapped.config
            runs = []
            for e in (made, again):  # each reset takes the one simulation over in turn
                obs = [e.reset(seed=3)[0]] + [e.step(a)[0] for a in (LEFT, STAY, RIGHT, STAY)]
                runs.append(np.stack(obs))
            np.testing.assert_array_equal(runs[0], runs[1])
        finally:
            again.close()
    finally:
        made.close()


def test_settings_given_as_a_dict_of_fields_name_a_field_that_is_not_there():
    """A dict that is not the fields of the setting it stands for is refused naming the key
    and the fields there are, before any simulation starts."""
    for kwargs, what in (
        ({"sim": {"step_length": 0.1}}, r"sim: 'step_length' is no SimConfig field"),
        ({"config": {"scenario": "eval", "steps": 5}}, r"config: 'steps' is no DrivingConfig"),
        (
            {"config": {"sim": {"step": 0.1}}},
            r"config\.sim: 'step' is no SimConfig field; the fields are step_length_s, ",
        ),
        ({"scenario": {"name": "mine"}}, r"scenario: no 'seed'.*TrafficScenario"),
    ):
        with pytest.raises(ValueError, match=what):
            gym.make(sumo_scenarios.ENV_ID, **kwargs)


def test_the_info_goes_through_gymnasiums_vector_info_wrappers():
    """gymnasium's vector envs merge the envs' infos key by key, nested dicts too, and its
    ``DictInfoToList`` splits them again by key name: ``closing_speed_ms``, keyed by the lane as
    an int, failed there ("'int' object has no attribute 'startswith'"). Its keys are the
    lanes' numbers as text, as a session's JSON log holds them; the human-like teacher reads
    either."""
    from gymnasium.wrappers.vector import DictInfoToList

    from sumo_scenarios.teacher import HumanDriver

    venv = DictInfoToList(gym.make_vec(sumo_scenarios.ENV_ID, num_envs=1))  # one per process
    try:
        obs, infos = venv.reset(seed=3)
        obs, _, _, _, infos = venv.step(np.array([LEFT]))
    finally:
        venv.close()
    single = DrivingEnv()
    try:
        single.reset(seed=3)
        single_obs, _, _, _, info = single.step(LEFT)
    finally:
        single.close()
    np.testing.assert_array_equal(obs[0], single_obs)
    assert infos[0]["closing_speed_ms"] == info["closing_speed_ms"]
    assert list(info["closing_speed_ms"]) == ["1", "2", "3"]
    # the human-like driver answers the same to either key: a drive on its own answers
    drivers, answers = (HumanDriver(seed=1), HumanDriver(seed=1)), []
    env = DrivingEnv()
    try:
        obs, info = env.reset(seed=3)
        for _ in range(200):
            as_ints = {int(k): v for k, v in info["closing_speed_ms"].items()}
            pair = (drivers[0](obs, info), drivers[1](obs, {**info, "closing_speed_ms": as_ints}))
            answers.append(pair)
            obs, _, _, _, info = env.step(pair[0])
    finally:
        env.close()
    assert all(a == b for a, b in answers) and {a for a, _ in answers} >= {STAY, LEFT}


def test_a_second_env_takes_the_simulation_over_and_the_first_says_so(env):
    a_obs = env.reset(seed=4)[0]
    other = DrivingEnv()  # may exist beside a live one
    try:
        b_obs = other.reset(seed=5)[0]
        with pytest.raises(RuntimeError, match="took this one's road over"):
            env.step(STAY)
        other.step(STAY)  # the new owner drives on
        env.close()  # closing the taken-over env leaves the other's simulation running
        other.step(STAY)
        np.testing.assert_array_equal(other.reset(seed=4)[0], a_obs)  # same seed, same road
        assert not np.array_equal(a_obs, b_obs)
    finally:
        other.close()
    # a taken-over env resets, takes the simulation back and drives the same road again
    first, second = DrivingEnv(), DrivingEnv()
    try:
        x = first.reset(seed=7)[0]
        second.reset(seed=8)
        np.testing.assert_array_equal(first.reset(seed=7)[0], x)
        first.step(STAY)
        with pytest.raises(RuntimeError, match="took this one's road over"):
            second.step(STAY)
        del second  # dropped without close(): its finaliser must not close first's simulation
        import gc

        gc.collect()
        first.step(STAY)
    finally:
        first.close()


def test_an_async_vector_env_of_driving_envs_runs_and_matches_single_envs():
    """Two driving envs in an AsyncVectorEnv (the documented way to run two at once): their
    info's per-car entries used to be arrays whose length (the number of cars) differs between
    segments, and gymnasium stacks an array info into one fixed-shape array: the first reset
    failed ('could not broadcast input array from shape (18,) into shape (22,)')."""
    seeds, actions = [1, 2], [[STAY, LEFT], [RIGHT, STAY], [STAY, STAY]]
    expected = []
    for k, seed in enumerate(seeds):
        single = DrivingEnv()
        try:
            obs, info = single.reset(seed=seed)
            run, cars = [obs], [len(info["car_rel_m"])]
            for a in actions:
                run.append(single.step(a[k])[0])
        finally:
            single.close()
        expected.append((np.stack(run), cars[0]))
    assert expected[0][1] != expected[1][1]  # segments with different numbers of cars
    venv = gym.vector.AsyncVectorEnv(
        [lambda: gym.make(sumo_scenarios.ENV_ID) for _ in seeds], context="spawn"
    )
    try:
        obs, info = venv.reset(seed=seeds)
        run = [obs]
        for a in actions:
            obs, _, _, _, info = venv.step(np.array(a))
            run.append(obs)
    except BaseException:
        venv.close(terminate=True)  # a plain close waits for the failed call's answer forever
        raise
    venv.close()
    got = np.stack(run)  # [T, env, 4]
    for k in range(len(seeds)):
        np.testing.assert_array_equal(got[:, k], expected[k][0])
        rel = np.asarray(info["car_rel_m"][k])
        lanes = np.asarray(info["car_lane"][k])
        assert rel.shape == lanes.shape and rel.size > 0
        assert info["lane"][k] == got[-1, k, 3]


def test_a_failed_reset_a_closed_env_and_a_dropped_env_never_crash_sumo(env, tmp_path):
    """step() after a reset that SUMO refused (here: FCD output to a file it cannot create) or
    after close() is a clear error (on libsumo both used to reach a dead simulation: a
    segmentation fault, or another env's); an env dropped without close() frees the process's
    one slot."""
    unwritable = "/proc/torchcbl-test.fcd.xml"  # its directory exists; no file can be made there
    env.reset(seed=1)
    env.step(STAY)
    with pytest.raises(Exception, match="Could not build output file"):
        env.reset(seed=2, options={"fcd_output": unwritable})
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(STAY)
    obs, _ = env.reset(seed=2)  # and it recovers
    with pytest.raises(ValueError, match="does not exist"):
        env.reset(seed=2, options={"fcd_output": str(tmp_path / "no" / "x.xml")})
    with pytest.raises(ValueError, match="is a directory"):  # named before SUMO starts
        env.reset(seed=2, options={"fcd_output": str(tmp_path)})
    env.close()
    assert not libsumo.isLoaded()  # closing the owner closed SUMO
    with pytest.raises(RuntimeError, match="closed"):
        env.step(STAY)
    # a first start that SUMO refuses: the env recovers, and its close() closes SUMO
    starting = DrivingEnv()
    with pytest.raises(Exception, match="Could not build output file"):
        starting.reset(seed=2, options={"fcd_output": unwritable})
    assert starting.reset(seed=2)[0].shape == (4,)
    starting.close()
    assert not libsumo.isLoaded()
    dropped = DrivingEnv()
    first = dropped.reset(seed=2)[0]
    del dropped  # no close()
    import gc

    gc.collect()
    assert not libsumo.isLoaded()  # its finaliser closed SUMO
    fresh = DrivingEnv()
    try:
        np.testing.assert_array_equal(fresh.reset(seed=2)[0], first)
        np.testing.assert_array_equal(first, obs)
    finally:
        fresh.close()


def _reset_a_driving_env(queue) -> None:
    try:
        e = DrivingEnv()
        e.reset(seed=0)
        e.close()
        queue.put("reset")
    except RuntimeError as exc:
        queue.put(str(exc))


def test_a_process_forked_from_a_running_simulation_is_refused(env):
    """A forked child holds a copy of the parent's libsumo simulation (its FCD file too):
    it must not load a new road into it."""
    import multiprocessing as mp

    env.reset(seed=0)
    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_reset_a_driving_env, args=(queue,))
    child.start()
    said = queue.get(timeout=60)
    child.join(timeout=60)
    assert "forked" in said and "spawn" in said
    env.step(STAY)  # the parent's simulation is untouched


def test_a_start_off_the_road_is_refused_and_keeps_no_slot():
    from sumo_scenarios.sim import SimConfig

    with pytest.raises(ValueError, match="ego_start_m"):
        SimConfig(ego_start_m=-1.0)
    with pytest.raises(ValueError, match="must stay below the road"):
        DrivingEnv(sim=SimConfig(ego_start_m=9950.0))
    with pytest.raises(ValueError, match="no room"):
        DrivingEnv(sim=SimConfig(ego_start_m=10.0))
    env = DrivingEnv()  # the refused ones left nothing behind
    env.reset(seed=0)
    env.close()


def test_bad_action_and_options(env):
    env.reset(seed=0)
    lane = env.step(0)[4]["lane"]
    for bad in (3, -1, 1.7, np.float64(2.0), "1", True, None):  # refused, never rounded
        with pytest.raises(ValueError, match="action must be 0"):
            env.step(bad)
    # a 0-d tensor (GaussianMixtureSet.classify(...).action[0]) is told what to pass, as the
    # corridor tells it (the message named the tensor and no way out)
    torch = pytest.importorskip("torch")
    with pytest.raises(ValueError, match=r"torch tensor is not taken as an action: pass int"):
        env.step(torch.tensor(1))
    assert env.step(np.int64(0))[4]["lane"] == lane and env.step(np.array(0))[4]["lane"] == lane
    with pytest.raises(ValueError, match="unknown reset options"):
        env.reset(seed=0, options={"lane": 1})
    for bad in (2.7, 5, -1, "2"):
        with pytest.raises(ValueError, match="ego_lane: expected a lane index 0-4"):
            env.reset(seed=0, options={"ego_lane": bad})
    assert env.reset(seed=0, options={"ego_lane": np.int64(3)})[1]["lane"] == 3
    with pytest.raises(ValueError):
        TrafficScenario(name="x", seed=0, speed_ranges_mph=((10.0, 30.0), (25, 35), (30, 40)))
    for bad in (
        {"seed": -1},
        {"seed": "a"},
        {"min_spacing_m": float("nan")},
        {"ahead_m": float("inf")},
        {"start_clear_m": -50.0},
    ):
        with pytest.raises(ValueError, match="seed|finite|start_clear_m"):
            TrafficScenario(name="x", **{"seed": 0, **bad})
    from sumo_scenarios.env import DrivingConfig

    for bad in (
        {"max_episode_steps": float("nan")},
        {"max_episode_steps": 2.5},
        {"start_lane": 1.5},
        {"sim": {}},
    ):
        with pytest.raises(ValueError, match=next(iter(bad))):
            DrivingConfig(**bad)


def test_contact_matches_hand_overlap_and_actions_clamp(env):
    obs, info = env.reset(seed=3, options={"ego_lane": 4})
    assert info["lane"] == 4
    _, _, _, _, info = env.step(LEFT)  # clamped: stays on the left shoulder
    assert info["lane"] == 4
    n_contact = 0
    for t in range(400):
        a = [STAY, RIGHT, RIGHT, LEFT, STAY, STAY][t % 6]
        prev = info["lane"]
        obs, _, _, _, info = env.step(a)
        rel, lanes = np.asarray(info["car_rel_m"]), np.asarray(info["car_lane"])
        lanes_checked = {prev, info["lane"]}
        hand = bool(np.any((np.abs(rel) < CAR_LENGTH_M) & np.isin(lanes, list(lanes_checked))))
        assert info["contact"] == hand
        n_contact += hand
        # the observation is the clipped nearest car per normal lane
        for k, lane in enumerate((1, 2, 3)):
            r = rel[lanes == lane]
            assert obs[k] == pytest.approx(np.clip(r[np.argmin(np.abs(r))], -25, 25), abs=1e-4)
        assert obs[3] == info["lane"]
    assert n_contact > 0  # the weaving drive did touch cars: the check was exercised


def test_straight_contact_share_is_ten_times_density(env):
    env.reset(seed=11)
    sim = env._sim
    dens = (
        np.mean(sim.car_lane == 2)
        * len(sim.car_lane)
        / (sim.scenario.ahead_m + sim.scenario.behind_m)
    )
    contacts = [env.step(STAY)[4]["contact"] for _ in range(1000)]
    rate = metrics.collision_rate(contacts)
    assert 0.2 < rate < 0.4
    assert dens > 0  # traffic exists in the middle lane


def test_sumo_speeds_span_20_to_40_mph_and_cars_slow_behind_slower_leaders(env):
    """SUMO's own vehicle speeds (libsumo.vehicle.getSpeed) during a 400-step episode: desired
    speeds are drawn per car inside 20-40 mph, and car-following slows a faster car that has
    closed up behind a slower leader in its lane."""
    import libsumo

    env.reset(seed=3, options={"ego_lane": 4})
    sim = env._sim
    mph = 0.44704
    speeds, slowed = [], 0
    for _ in range(400):
        env.step(STAY)
        v = np.array([libsumo.vehicle.getSpeed(c) for c in sim.car_ids])
        speeds.append(v)
        for lane in (1, 2, 3):
            m = np.flatnonzero(sim.car_lane == lane)
            order = m[np.argsort(sim.car_pos[m])]
            for back, front in zip(order[:-1], order[1:], strict=True):
                gap = sim.car_pos[front] - sim.car_pos[back] - 5.0
                # closed up (within 2 s headway), below its own desired speed, near its leader's
                if (
                    gap < 2.0 * v[back]
                    and v[back] < sim.car_vdes[back] - 1.0
                    and abs(v[back] - v[front]) < 1.0
                ):
                    slowed += 1
    allv = np.concatenate(speeds) / mph
    assert allv.max() <= 40.0 + 1e-6 and allv.min() >= 0.0
    assert np.percentile(allv, 99) > 37.0  # fast cars reach near 40 mph
    assert np.percentile(allv, 1) < 22.0  # slow cars near 20 mph
    assert slowed > 100  # followers slowed to their leader's speed, many times
    desired = sim.car_vdes / mph
    assert desired.min() >= 20.0 and desired.max() <= 40.0


def test_road_is_long_enough_that_a_1000_step_episode_has_no_jump(env):
    env.reset(seed=1, options={"ego_lane": 0})
    sim = env._sim
    dt = env.config.sim.step_length_s
    last = dict(zip(sim.car_ids, sim.car_pos.copy(), strict=True))
    ego_last = sim.ego_pos
    for _ in range(1000):
        env.step(STAY)
        assert sim.ego_pos - ego_last == pytest.approx(26.8224 * dt, rel=1e-9)
        ego_last = sim.ego_pos
        for cid, x in zip(sim.car_ids, sim.car_pos, strict=True):
            if cid in last:  # every car moves forward by at most 40 mph x dt, never back
                assert -1e-9 <= x - last[cid] <= 40 * 0.44704 * dt + 1e-6
        last = dict(zip(sim.car_ids, sim.car_pos.copy(), strict=True))
    assert sim.n_shifts == 0 and sim.n_recycled > 100
    sumo_view = sim.vehicle_positions()
    assert len(sumo_view) == len(sim.car_ids) + 1  # nothing lost, nothing pending
    for i, cid in enumerate(sim.car_ids):
        assert sumo_view[cid] == (pytest.approx(sim.car_pos[i]), sim.car_lane[i])
    for _ in range(500):  # past the end of the 10 km edge the road is moved back, once
        env.step(STAY)
    assert sim.n_shifts >= 1
    assert sim.distance_m == pytest.approx(1500 * dt * 26.8224, rel=1e-6)


def test_reset_leaves_no_car_from_15_m_behind_to_start_clear_m_ahead(env):
    """At reset no car is within 15 m behind or start_clear_m (30 m) ahead of the ego, in any
    lane, over 30 road segments (the cars beyond that zone lie close to it)."""
    clear = env.scenario.start_clear_m
    nearest_behind = []
    for seed in range(30):
        _, info = env.reset(seed=seed)
        rel = np.asarray(info["car_rel_m"])
        assert not np.any((rel > -15.0) & (rel < clear)), seed
        nearest_behind.append(rel[rel <= -15.0].max())
    assert max(nearest_behind) > -20.0  # the zone's edge is where traffic starts


def _drive_past_shifts(steps: int = 130):
    """(each step's info, n_shifts) for ``steps`` steps of STAY from 9 km along the
    10 km edge: the road is moved back about every 60 steps (by about 400 m)."""
    from sumo_scenarios.sim import SimConfig

    env = DrivingEnv(sim=SimConfig(ego_start_m=9000.0), max_episode_steps=10**6)
    try:
        env.reset(seed=0)
        infos = [env.step(STAY)[4] for _ in range(steps)]
        return infos, env._sim.n_shifts
    finally:
        env.close()


def test_lanes_stay_filled_ahead_across_a_shift_back():
    """After every step, shifts included, each traffic lane has a car ahead within ahead_m
    (200 m): the lanes' fronts, where new cars enter, move back with the road."""
    infos, n_shifts = _drive_past_shifts()
    assert n_shifts >= 2
    for info in infos:
        rel, lanes = np.asarray(info["car_rel_m"]), np.asarray(info["car_lane"])
        for lane in (1, 2, 3):
            r = rel[lanes == lane]
            assert np.any((r > 0) & (r <= 200.0)), (info["t"], lane)


def test_car_speeds_stay_within_0_to_40_mph_across_a_shift_back():
    """The speeds measured over each step (info's car_closing_ms = ego speed - car speed) stay
    inside the traffic's 0-40 mph at the steps where the road is moved back as elsewhere."""
    from sumo_scenarios.scenarios import EGO_SPEED_MS, MPH

    infos, n_shifts = _drive_past_shifts()
    assert n_shifts >= 2
    speeds = np.concatenate([EGO_SPEED_MS - np.asarray(i["car_closing_ms"]) for i in infos])
    assert speeds.min() >= 0.0 and speeds.max() <= 40.0 * MPH + 1e-6


def test_new_cars_enter_far_ahead_never_beside_the_ego(env):
    """Regression: a lane that ran out of cars ahead used to get a recycled car dropped right
    next to the ego (eval segment 0, lane 3, step 350: a car appeared at -2.3 m, a spurious
    contact). Every car a step adds must enter beyond the horizon."""
    env.close()
    env = DrivingEnv(scenario="eval", max_episode_steps=10**6)
    env.reset(seed=0, options={"ego_lane": 3})
    sim = env._sim
    ids = set(sim.car_ids)
    n_new = 0
    for _ in range(1300):  # within one 10 km edge (no shift back)
        env.step(STAY)
        for cid, pos in zip(sim.car_ids, sim.car_pos, strict=True):
            if cid not in ids:
                n_new += 1
                assert pos - sim.ego_pos > sim.scenario.ahead_m - 1.0
        ids = set(sim.car_ids)
    env.close()
    assert n_new > 50


def test_determinism_and_train_eval_segments_differ(env):
    def run(seed):
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for t in range(80):
            out.append(env.step((t // 7) % 3)[0])
        return np.stack(out)

    a, b, c = run(4), run(4), run(5)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    env.close()
    ev = DrivingEnv(scenario="eval")
    try:
        obs, _ = ev.reset(seed=4)
        e_obs = [obs] + [ev.step((t // 7) % 3)[0] for t in range(80)]
    finally:
        ev.close()
    assert not np.array_equal(np.stack(e_obs), a)  # same seed, other segment: eval is held out
    assert sumo_scenarios.scenarios.TRAIN.seed != sumo_scenarios.scenarios.EVAL.seed


def test_expert_avoids_contact_and_keeps_ten_metres(env):
    expert = ScriptedExpert(seed=0)
    obs, info = env.reset(seed=2)
    contacts, lanes, near = [], [], 0
    for _ in range(1500):
        obs, _, _, _, info = env.step(expert(obs, info))
        contacts.append(info["contact"])
        lanes.append(info["lane"])
        lane = int(obs[3])
        near += 1 <= lane <= 3 and abs(obs[lane - 1]) < 10
    assert metrics.collision_rate(contacts) <= 0.005
    dist = metrics.lane_distribution(lanes)
    assert dist[2:].sum() > 0.9  # prefers the left three lanes
    assert near <= 5


def _closing_in(seed: int) -> float:
    """Gap (m) to a car closing in ahead in the left lane at which ScriptedExpert(seed) leaves."""
    expert = ScriptedExpert(seed=seed)
    obs = np.zeros(4, dtype=np.float32)
    for t in range(40):
        gap = 30.0 - 2.2 * t
        info = {
            "lane": 3,
            "t": t,
            "car_rel_m": np.array([gap, 200.0]),
            "car_lane": np.array([3, 2]),
            "car_closing_ms": np.array([8.9, 13.4]),
            "step_length_s": 0.25,
        }
        if expert(obs, info) == LEFT:  # passes on the left shoulder
            return gap
    raise AssertionError("the expert never left the lane of a closing car")


def test_expert_timing_varies_inside_the_safe_window_and_is_seeded():
    gaps = [_closing_in(s) for s in range(20)]
    assert gaps == [_closing_in(s) for s in range(20)]  # same seed, same moment
    assert len(set(gaps)) >= 4  # human-like: the moment varies from event to event
    last_safe = 10.0 + 2 * 8.9 * 0.25
    assert min(gaps) >= last_safe - 2.2 and max(gaps) <= 24.0  # but always inside the window
    with pytest.raises(ValueError, match="missing"):
        ScriptedExpert()(np.zeros(4), {})


def _decides(expert: ScriptedExpert, lane: int, cars: list[tuple[int, float, float]], t=0) -> int:
    """The expert's action in ``lane`` among hand-placed ``cars`` (lane, metres relative to the
    ego, closing speed m/s: ego speed minus the car's), as DrivingEnv's info gives them."""
    info = {
        "lane": lane,
        "t": t,
        "car_rel_m": np.array([c[1] for c in cars], dtype=np.float64),
        "car_lane": np.array([c[0] for c in cars], dtype=np.int64),
        "car_closing_ms": np.array([c[2] for c in cars], dtype=np.float64),
        "step_length_s": 0.25,
    }
    return expert(np.zeros(4, dtype=np.float32), info)


def test_expert_a_car_closing_within_two_steps_of_min_gap_forces_a_squeeze():
    """A car 13 m ahead closing at 8.9 m/s (2.2 m a step) leaves no safe step (13 < 10 + 2 x
    2.2): the expert squeezes into the left shoulder, whose car 13 m ahead is nearer than
    enter_ahead_m (16 m) but beyond min_gap_m, whatever its timing draw."""
    cars = [(3, 13.0, 8.9), (4, 13.0, 0.0), (2, 0.0, 0.0)]
    assert [_decides(ScriptedExpert(seed=s), 3, cars) for s in range(20)] == [LEFT] * 20


def test_expert_pressed_squeezes_in_beyond_min_gap_but_never_nearer():
    """Pressed (a car 11 m ahead closing at 4 m/s), with no lane open to enter_ahead_m, the
    expert takes a lane whose nearest car is beyond min_gap_m (12 m ahead; left first, then
    right) and stays when that car is within it (9 m)."""
    pressed = (3, 11.0, 4.0)
    for squeeze, action in [((4, 12.0, 0.0), LEFT), ((4, 9.0, 0.0), STAY)]:
        cars = [pressed, squeeze, (2, 0.0, 0.0)]
        assert [_decides(ScriptedExpert(seed=s), 3, cars) for s in range(10)] == [action] * 10
    cars = [pressed, (4, 5.0, 0.0), (2, 12.0, 0.0)]
    assert [_decides(ScriptedExpert(seed=s), 3, cars) for s in range(10)] == [RIGHT] * 10


def test_expert_judges_a_lane_by_where_its_cars_will_be_after_the_step():
    """A car 12 m behind on the left shoulder, 10 m/s faster than the ego, will be 9.5 m behind
    after the step (within min_gap_m): it blocks the change; as fast as the ego, it does not."""
    for closing, action in [(-10.0, STAY), (0.0, LEFT)]:
        cars = [(3, 11.0, 4.0), (4, -12.0, closing), (2, 0.0, 0.0)]
        assert [_decides(ScriptedExpert(seed=s), 3, cars) for s in range(10)] == [action] * 10


def _leaves_for_car_b(seed: int, before: list[tuple[int, list[tuple[int, float, float]]]]) -> float:
    """Gap at which ScriptedExpert(seed) leaves the left lane for a car B closing in from 30 m
    at 8.9 m/s, after the consecutive steps ``before`` (lane, cars)."""
    expert = ScriptedExpert(seed=seed)
    for t, (lane, cars) in enumerate(before):
        assert _decides(expert, lane, cars, t) == STAY
    for k in range(20):
        gap = 30.0 - 2.225 * k
        if _decides(expert, 3, [(3, gap, 8.9)], len(before) + k) == LEFT:
            return gap
    raise AssertionError("the expert never left the lane of a closing car")


def test_expert_draws_a_new_moment_for_a_new_car_ahead():
    """Car A closes in from 30 to 25.5 m and changes lane before the expert acts; car B then
    arrives at 30 m: a new event, whose moment is drawn afresh (as after a lane change), not
    the one drawn for A."""
    car_a = [(3, [(3, 30.0 - 2.225 * k, 8.9)]) for k in range(3)]
    after_a = [_leaves_for_car_b(s, car_a) for s in range(20)]
    after_lane_change = [_leaves_for_car_b(s, [(4, [(3, 0.0, 0.0)])]) for s in range(20)]
    fresh = [_leaves_for_car_b(s, []) for s in range(20)]
    assert after_a == after_lane_change
    assert after_a != fresh


def test_expert_returns_home_after_a_passed_car_by_a_drawn_margin():
    """On the left shoulder, a passed car 12 m behind in the home lane is min_gap_m plus 2 of
    the return_spread_m's 4 m behind: across seeds some return home now, some wait."""
    acts = {_decides(ScriptedExpert(seed=s), 4, [(3, -12.0, 0.0)]) for s in range(20)}
    assert acts == {RIGHT, STAY}
    assert _decides(ScriptedExpert(seed=0), 4, [(3, -9.0, 0.0)]) == STAY  # never within min_gap


def test_expert_on_an_empty_road_heads_for_the_home_lane_from_either_side():
    """Home is the left lane (3): from the left shoulder it moves right, from the lanes to its
    right it moves left, and at home it stays."""
    acts = [_decides(ScriptedExpert(seed=0), lane, []) for lane in range(5)]
    assert acts == [LEFT, LEFT, LEFT, STAY, RIGHT]


def test_expert_with_middle_pass_passes_in_a_free_middle_lane_first():
    """With middle_pass, a car closing in ahead is passed in the middle lane (2) when it is
    visibly free, though the left shoulder is free too; a car 20 m ahead in the middle lane
    sends the pass to the shoulder. Without middle_pass the shoulder is always first."""
    ahead = (3, 11.0, 4.0)
    middle = ExpertConfig(middle_pass=True)
    assert [_decides(ScriptedExpert(middle, seed=s), 3, [ahead]) for s in range(5)] == [RIGHT] * 5
    cars = [ahead, (2, 20.0, 0.0)]
    assert [_decides(ScriptedExpert(middle, seed=s), 3, cars) for s in range(5)] == [LEFT] * 5
    assert [_decides(ScriptedExpert(seed=s), 3, [ahead]) for s in range(5)] == [LEFT] * 5


def test_replay_bit_identical_fcd_and_gif(tmp_path):
    env = EpisodeRecorder(DrivingEnv(scenario="train", max_episode_steps=40), label="t")
    expert = ScriptedExpert(seed=1)
    try:
        obs, info = env.reset(seed=9)
        seen = [obs]
        for _ in range(40):
            obs, _, _, _, info = env.step(expert(obs, info))
            seen.append(obs)
    finally:
        env.close()
    (rec,) = env.episodes
    assert len(rec.actions) == 40
    res, _ = replay(rec)
    assert np.array_equal(res.observations, np.stack(seen))
    fcd = export_fcd(rec, tmp_path / "ep.fcd.xml")
    steps = list(sumolib.xml.parse(str(fcd), "timestep"))
    assert len(steps) >= 40
    ids = {v.id for v in steps[-1].vehicle}
    assert "ego" in ids and len(ids) > 5
    gif = render_gif(rec, tmp_path / "ep.gif", every=10, fps=4)
    assert gif.stat().st_size > 1000
    from PIL import Image

    with Image.open(gif) as im:
        assert im.n_frames == 5  # steps 0, 10, 20, 30, 40: the whole episode, not a prefix
        assert im.info["duration"] == 250  # 4 frames per second, in milliseconds
    import subprocess
    import sys
    from pathlib import Path

    from sumo_scenarios.replay import write_sumocfg

    cfg = write_sumocfg(rec, fcd, tmp_path / "ep.sumocfg")
    sumo = Path(sys.executable).with_name("sumo")
    out = subprocess.run(
        [str(sumo), "-c", str(cfg)], capture_output=True, text=True, timeout=60, check=False
    )
    assert out.returncode == 0, out.stderr
    assert "teleport" not in (out.stdout + out.stderr).lower()
    assert "error" not in (out.stdout + out.stderr).lower()


def test_recorder_labels_episodes_at_reset_and_skips_empty_ones():
    env = EpisodeRecorder(DrivingEnv(scenario="train", max_episode_steps=5), label="first")
    try:
        env.reset(seed=1)
        for _ in range(5):
            env.step(0)
        env.reset()  # as evaluate_policy does after an episode ends: no step follows
        env.label = "second"
        env.reset(seed=2)
        for _ in range(3):
            env.step(1)
    finally:
        env.close()
    assert [(e.label, e.episode_seed, len(e.actions)) for e in env.episodes] == [
        ("first", 1, 5),
        ("second", 2, 3),
    ]


def test_figure_8_writes_each_policys_collision_rate_as_a_percent():
    """plot_lane_bars takes collision rates as shares and writes each beside its bar as a
    percent with one decimal (0.025 is "2.5%", not "0.0%")."""
    from matplotlib.figure import Figure

    ax = Figure().add_subplot()
    share = [0.1, 0.2, 0.3, 0.4, 0.0]
    metrics.plot_lane_bars(ax, ["expert", "learned"], [share, share], [0.025, 0.0])
    assert sorted(t.get_text() for t in ax.texts) == ["0.0%", "2.5%"]


def test_metrics():
    assert metrics.total_variation([1, 0, 0, 0, 0], [0, 1, 0, 0, 0]) == 1.0
    assert metrics.total_variation([0.5, 0.5], [0.5, 0.5]) == 0.0
    acc = metrics.windowed_accuracy([1, 0, 1, 1], window=2)
    assert np.allclose(acc, [1, 0.5, 0.5, 1])
    assert np.allclose(metrics.lane_distribution([0, 4, 4, 2]), [0.25, 0, 0.25, 0, 0.5])
    with pytest.raises(ValueError):
        metrics.lane_distribution([5])


def test_rebuilding_the_network_reproduces_the_shipped_files(tmp_path):
    """Byte for byte with the netconvert that made the shipped file (its header names it); with
    another admitted one (pyproject.toml's floor is older) all but the version it names."""
    import re

    from sumo_scenarios.build_network import build

    net = build(tmp_path)
    made_by = re.compile(rb"\(Eclipse SUMO netconvert (\d+\.\d+\.\d+)\)\. -->")
    rebuilt, shipped = net.read_bytes(), data_path("road.net.xml").read_bytes()
    ours, theirs = made_by.search(rebuilt), made_by.search(shipped)
    assert ours is not None and theirs is not None, rebuilt[:300]
    assert rebuilt.replace(ours.group(0), theirs.group(0), 1) == shipped
    for name in ("road.nod.xml", "road.edg.xml"):
        shipped = data_path("road.net.xml").parent / "src" / name
        assert (tmp_path / "src" / name).read_bytes() == shipped.read_bytes()


def _fake_netconvert(tmp_path, script: str, where: str = "bin"):
    """A stand-in netconvert, ``tmp_path/where/netconvert``, running the shell ``script``."""
    fake = tmp_path / where / "netconvert"
    fake.parent.mkdir()
    fake.write_text("#!/bin/sh\n" + script)
    fake.chmod(0o755)
    return fake


def _as_this_pythons(monkeypatch, folder):
    """Make ``folder`` this Python's own (the eclipse-sumo wheel's netconvert is looked up
    beside ``sys.executable``)."""
    import sys

    monkeypatch.setattr(sys, "executable", str(folder / "python"))


def _first_on_path(monkeypatch, fake):
    monkeypatch.setenv("PATH", f"{fake.parent}{os.pathsep}{os.environ['PATH']}")


_WRITES_THE_1_24_HEADER = (
    'while [ $# -gt 0 ]; do [ "$1" = --output-file ] && out=$2; shift; done\n'
    "cat > \"$out\" <<'EOF'\n"
    '<?xml version="1.0" encoding="UTF-8"?>\n\n'
    "<!-- generated on 2025-05-01 10:00:00 by Eclipse SUMO netconvert Version 1.24.0\n"
    "<netconvertConfiguration>\n</netconvertConfiguration>\n-->\n\n"
    '<net version="1.20"/>\n'
    "EOF\n"
)
_BUILT_FROM_THE_1_24_HEADER = (
    '<?xml version="1.0" encoding="UTF-8"?>\n\n'
    "<!-- Generated by python -m sumo_scenarios.build_network "
    "(Eclipse SUMO netconvert 1.24.0). -->\n\n"
    '<net version="1.20"/>\n'
)


def test_the_network_builds_with_a_netconvert_that_writes_version_in_its_header(
    tmp_path, monkeypatch
):
    """netconvert before 1.25 writes "by Eclipse SUMO netconvert Version 1.24.0" in its header,
    1.25 on "by Eclipse SUMO netconvert 1.25.0"; build() took only the second and raised
    "netconvert's header comment was not found" with the first (SUMO 1.22-1.24 are admitted).
    A stand-in for this Python's eclipse-sumo netconvert writes the older header."""
    from sumo_scenarios.build_network import build

    fake = _fake_netconvert(tmp_path, _WRITES_THE_1_24_HEADER)
    _as_this_pythons(monkeypatch, fake.parent)
    net = build(tmp_path / "out")
    assert net.read_text() == _BUILT_FROM_THE_1_24_HEADER


def test_this_pythons_netconvert_is_run_before_the_first_on_path(tmp_path, monkeypatch):
    """build() ran the first netconvert on PATH, ahead of this Python's eclipse-sumo one (the
    declared dependency, matched to libsumo): an older system SUMO on PATH (apt's 1.12) would
    rewrite the shipped road.net.xml, the command's default --out, in its older format. With
    this Python's netconvert present, the one on PATH is not run."""
    from sumo_scenarios.build_network import build

    ran = tmp_path / "the one on PATH ran"
    on_path = _fake_netconvert(tmp_path, f"touch '{ran}'\nexit 1\n", where="system")
    _first_on_path(monkeypatch, on_path)
    wheel = _fake_netconvert(tmp_path, _WRITES_THE_1_24_HEADER, where="venv")
    _as_this_pythons(monkeypatch, wheel.parent)
    net = build(tmp_path / "out")
    assert not ran.exists()
    assert net.read_text() == _BUILT_FROM_THE_1_24_HEADER


# What the real netconvert writes on stderr when it fails (here: two node files it cannot open):
# its errors, then always "Quitting (on error)."
_FAILS_AS_NETCONVERT_DOES = (
    "echo \"Error: Could not open nodes-file 'missing.nod.xml'.\" >&2\n"
    "echo 'Error: No nodes loaded.' >&2\n"
    "echo 'Quitting (on error).' >&2\n"
)
_NETCONVERT_SAID = "Error: Could not open nodes-file 'missing.nod.xml'.; Error: No nodes loaded."


@pytest.mark.parametrize("which", ["this Python's", "the first on PATH"])
def test_a_netconvert_that_fails_is_named_with_its_own_error(tmp_path, monkeypatch, which):
    """build() runs this Python's eclipse-sumo netconvert, else (none beside this Python) the
    first on PATH, which may be another SUMO install's (older than the 1.22 floor, say). When
    it failed, the user got subprocess's CalledProcessError listing the whole command, with
    netconvert's own message swallowed (captured, never shown). The error names the netconvert
    that ran and where it came from, its exit status and message, and what to do.

    The stand-in fails as the real one does: its "Error:" lines, then "Quitting (on error).";
    the message kept only that last line, dropping the errors. It keeps every "Error:" line."""
    from sumo_scenarios.build_network import build

    fake = _fake_netconvert(tmp_path, _FAILS_AS_NETCONVERT_DOES + "exit 3\n")
    if which == "this Python's":  # it ran, and rejected its files: no reinstall mends that
        _as_this_pythons(monkeypatch, fake.parent)
        out = tmp_path / "out"
        where = "this Python's eclipse-sumo"
        fix = f"its input ({out / 'src'}) is rewritten on every run"
    else:
        _as_this_pythons(monkeypatch, tmp_path / "no-sumo")
        _first_on_path(monkeypatch, fake)
        where, fix = "the first on PATH", f"its netconvert (beside {tmp_path / 'no-sumo'}"
    with pytest.raises(RuntimeError) as e:
        build(tmp_path / "out")
    msg = str(e.value)
    assert "\n" not in msg, msg
    assert f"{fake} ({where}" in msg, msg
    assert f"exit status 3: {_NETCONVERT_SAID}; " in msg, msg
    assert "Quitting" not in msg, msg
    assert fix in msg, msg
    assert which != "this Python's" or "reinstall" not in msg, msg
    assert which != "this Python's" or "check eclipse-sumo's version" in msg, msg


def test_a_network_file_netconvert_cannot_write_is_named_and_not_blamed_on_the_install(
    tmp_path, capsys
):
    """This Python's netconvert (the real one) that ran and refused to write the network (the
    out directory's road.net.xml is a directory) was reported with "reinstall eclipse-sumo",
    which mends nothing. The command says, in one line on stderr and exit code 1, netconvert's
    own error about the file and, where an error names the output, to give an out directory
    where that file can be written, with no reinstall. (Its input, OUT/src, is not to be
    edited: build() writes it afresh on every run.)"""
    from sumo_scenarios.build_network import main

    (tmp_path / "road.net.xml").mkdir()
    assert main(["--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    # netconvert's own Error: line, whatever this eclipse-sumo (>= 1.22) words it as
    assert re.search(r"exit status [1-9]\d*: Error: \S.*; netconvert ran and rejected", err), err
    assert (
        "names the output" in err and "give an out directory where that file can be written" in err
    ), err
    assert "edits to it are lost" in err, err
    assert "reinstall" not in err, err


@pytest.mark.parametrize(
    "script, said",
    [
        (None, "No such file or directory"),  # its interpreter gone (the wheel's is a script)
        ("kill -SEGV $$\n", "exit status -11"),  # crashed
        (  # a shared library missing: the loader's words, exit status 127
            "echo 'netconvert: error while loading shared libraries: libxerces-c-3.2.so: "
            "cannot open shared object file: No such file or directory' >&2\nexit 127\n",
            "exit status 127: netconvert: error while loading shared libraries",
        ),
    ],
)
def test_this_pythons_netconvert_that_cannot_run_is_to_be_reinstalled(
    tmp_path, monkeypatch, script, said
):
    """Where this Python's netconvert could not run at all (the interpreter its script names is
    gone, killed by a signal, a shared library missing), the error says how, and to reinstall
    eclipse-sumo."""
    from sumo_scenarios.build_network import build

    fake = _fake_netconvert(tmp_path, script or "")
    if script is None:
        fake.write_text(f"#!{tmp_path / 'gone' / 'python'}\n")
    _as_this_pythons(monkeypatch, fake.parent)
    with pytest.raises(RuntimeError) as e:
        build(tmp_path / "out")
    msg = str(e.value)
    assert said in msg and "reinstall eclipse-sumo" in msg, msg
    assert "its input" not in msg, msg


def test_an_interpreter_that_does_not_know_its_own_path_builds_with_path_s_netconvert(
    tmp_path, monkeypatch
):
    """An embedded interpreter may have an empty ``sys.executable``; looking beside it for this
    Python's eclipse-sumo netconvert raised ValueError ("PosixPath('.') has an empty name")
    before PATH was looked at. There is none beside it, so the first on PATH runs."""
    import sys

    from sumo_scenarios.build_network import build

    fake = _fake_netconvert(tmp_path, _WRITES_THE_1_24_HEADER)
    monkeypatch.setattr(sys, "executable", "")
    _first_on_path(monkeypatch, fake)
    net = build(tmp_path / "out")
    assert net.read_text() == _BUILT_FROM_THE_1_24_HEADER


@pytest.mark.parametrize(
    "stderr, said",
    [
        ("Warning: odd input\nsegfault in loader\nQuitting (on error).\n", "segfault in loader"),
        ("Quitting (on error).\n", "no message"),
        ("", "no message"),
    ],
)
def test_a_netconvert_failing_without_error_lines_is_named_by_its_last_words(
    tmp_path, monkeypatch, stderr, said
):
    """With no "Error:" line, the message gives netconvert's last line that says something,
    not its closing "Quitting (on error).", or "no message" where there is none."""
    from sumo_scenarios.build_network import build

    fake = _fake_netconvert(tmp_path, f"printf '{stderr}' >&2\nexit 1\n")
    _as_this_pythons(monkeypatch, fake.parent)
    with pytest.raises(RuntimeError) as e:
        build(tmp_path / "out")
    assert f"exit status 1: {said}; reinstall" in str(e.value), str(e.value)


_BUILD_NETWORK_AS_IF_BESIDE = """
import runpy, sys
sys.executable = sys.argv.pop(1)  # where this Python's eclipse-sumo netconvert is looked up
runpy.run_module("sumo_scenarios.build_network", run_name="__main__", alter_sys=True)
"""


@pytest.mark.parametrize("case", ["netconvert fails", "--out is a file"])
def test_the_build_network_command_fails_in_one_line_not_a_traceback(tmp_path, case):
    """`python -m sumo_scenarios.build_network` (the fix other errors name for a damaged
    network) answered a netconvert that failed, or an --out it cannot write into, with a
    Python traceback. Now one line on stderr, naming what failed, and exit code 1. (The
    module is run as -m runs it, with this Python's netconvert looked up beside a stand-in.)"""
    import subprocess
    import sys

    out = tmp_path / "out"
    fake = _fake_netconvert(tmp_path, _FAILS_AS_NETCONVERT_DOES + "exit 1\n")
    if case == "netconvert fails":
        says = (
            f"netconvert failed: {fake} (this Python's eclipse-sumo), exit status 1: "
            f"{_NETCONVERT_SAID}; netconvert ran and rejected its files"
        )
    else:
        out.write_text("")
        says = f"cannot write into --out {out} ("
    proc = subprocess.run(
        [
            sys.executable,
            "-c",
            _BUILD_NETWORK_AS_IF_BESIDE,
            str(fake.with_name("python")),
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.startswith("build_network.py: error: ") and says in proc.stderr
    assert case == "netconvert fails" or "give a directory you can write to" in proc.stderr
    assert proc.stdout == ""


def test_a_driving_env_refuses_to_be_copied_or_pickled(env):
    """A copy would drive the same libsumo simulation with its own bookkeeping (deepcopy), or
    lack it (pickle): refused with a message that says what to do."""
    import copy
    import pickle

    env.reset(seed=5)
    for clone in (copy.copy, copy.deepcopy, pickle.dumps):
        with pytest.raises(TypeError, match="cannot be copied or pickled; make a new DrivingEnv"):
            clone(env)
    assert env.step(0)[4]["position_m"] == pytest.approx(6.7056, abs=1e-6)  # one step, no more


def test_the_env_runs_from_a_directory_whose_path_holds_a_comma(tmp_path):
    """A checkout or install under a path with a comma ("OneDrive - Acme, Inc/..."): the env
    resets and steps. (SUMO splits the file lists -n and -a at commas: every reset failed with
    'TraCIException: Process Error' after "Error: File '.../Acme' is not accessible".) The
    copies SUMO is given there are removed as soon as it has loaded them."""
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    site = tmp_path / "Acme, Inc"
    shutil.copytree(
        Path(sumo_scenarios.__file__).parent,
        site / "sumo_scenarios",
        ignore=shutil.ignore_patterns("__pycache__"),
    )
    (tmp_path / "tmp").mkdir()
    code = (
        "import os\n"
        "import sumo_scenarios.env as E\n"
        "assert ',' in E.__file__, E.__file__\n"
        "env = E.DrivingEnv(scenario='light')\n"
        "obs, _ = env.reset(seed=0)\n"
        "left = os.listdir(os.environ['TMPDIR'])\n"  # the copies SUMO loaded: gone at once
        "obs, _ = env.reset(seed=1)\n"
        "obs, *_ = env.step(1)\n"
        "env.close()\n"
        "print(int(obs[3]), left + os.listdir(os.environ['TMPDIR']))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin", "TMPDIR": str(tmp_path / "tmp")},
        cwd=tmp_path,
    )
    # (a forked worker ends without atexit: copies kept until the process ended stayed)
    assert out.returncode == 0 and out.stdout.strip() == "3 []", out.stdout + out.stderr[-2000:]


# a simulation of the researcher's own, on the shipped road
_THEIRS = ["sumo", "-n", str(data_path("road.net.xml")), "--no-step-log", "true"]


@pytest.fixture
def libsumo_free():
    """libsumo holds no simulation as the test starts (an env an earlier test dropped
    unclosed releases it when collected)."""
    gc.collect()
    assert not libsumo.simulation.isLoaded(), "an earlier test left an env's simulation running"


def test_a_simulation_started_outside_the_env_is_not_silently_replaced(libsumo_free):
    """A researcher's own libsumo simulation in the same process (libsumo.start by hand): the
    env's reset refuses, saying what to do, and the researcher's simulation runs on. (It was
    replaced without a word: libsumo holds one simulation per process, and a second
    libsumo.start replaces the first; its clock went from 3 s back to 0.25 s.)"""
    libsumo.start(_THEIRS)
    try:
        for _ in range(3):
            libsumo.simulationStep()
        env = DrivingEnv(scenario="light")
        try:
            with pytest.raises(RuntimeError, match=r"not started by sumo_scenarios.*close it"):
                env.reset(seed=0)
        finally:
            env.close()
        assert libsumo.simulation.getTime() == 3.0
        libsumo.simulationStep()  # still the researcher's
    finally:
        libsumo.close()
    env = DrivingEnv(scenario="light")  # once it is closed, the env starts its own
    try:
        env.reset(seed=0)
        env.step(STAY)
    finally:
        env.close()


def test_a_simulation_started_over_the_envs_own_is_not_silently_replaced(libsumo_free):
    """The researcher closes the env's libsumo simulation and starts one of their own: the
    env's next reset refuses, saying what to do, and theirs runs on. (The env still counted
    libsumo as running its own and loaded over theirs without a word: their clock went from 3 s
    back to 0 s.) Once theirs is closed, the env resets again."""
    env = DrivingEnv(scenario="light")
    try:
        env.reset(seed=0)
        env.step(STAY)
        libsumo.close()
        libsumo.start(_THEIRS)
        try:
            for _ in range(3):
                libsumo.simulationStep()
            with pytest.raises(RuntimeError, match=r"not started by sumo_scenarios.*close it"):
                env.reset(seed=1)
            assert libsumo.simulation.getTime() == 3.0
            libsumo.simulationStep()  # still the researcher's
        finally:
            libsumo.close()
        env.reset(seed=1)  # theirs closed: the env starts its own again
        assert env.step(STAY)[4]["position_m"] == pytest.approx(6.7056, abs=1e-6)
    finally:
        env.close()


def test_a_step_after_the_user_closed_the_envs_simulation_says_so(libsumo_free):
    """The researcher closes the env's libsumo simulation (and maybe starts their own): the
    env's step raises a RuntimeError saying what happened and what to do, and leaves their
    simulation untouched. (It stepped theirs once and then failed inside libsumo, "Vehicle
    'ego' is not known."; with none running, "A network was not yet constructed.")"""
    env = DrivingEnv(scenario="light")
    try:
        env.reset(seed=0)
        env.step(STAY)
        libsumo.close()
        with pytest.raises(RuntimeError, match=r"closed outside this env.*reset\(\)"):
            env.step(STAY)
        libsumo.start(_THEIRS)
        try:
            libsumo.simulationStep()
            with pytest.raises(RuntimeError, match=r"not started by sumo_scenarios.*close it"):
                env.step(STAY)
            assert libsumo.simulation.getTime() == 1.0  # theirs was not stepped
        finally:
            libsumo.close()
        env.reset(seed=1)  # theirs closed: the env starts its own again
        env.step(STAY)
    finally:
        env.close()


def test_a_step_over_a_user_simulation_with_the_envs_seed_and_vehicle_types_says_so(libsumo_free):
    """The researcher closes the env's libsumo simulation and starts one of their own with the
    env's vehicle types and SUMO's default seed, 23423 (as sumo -c on a write_sumocfg
    configuration does), which is also the env's SUMO seed for reset(seed=23423): the env's
    step raises the RuntimeError saying what happened, at once after the reset or later, and
    leaves theirs untouched. (Both options the step compared matched, so theirs passed as the
    env's: it was stepped, and the env then failed inside libsumo, "Vehicle 'ego' is not
    known".)"""
    env = DrivingEnv(scenario="light")
    theirs = ["sumo", "-n", str(data_path("road.net.xml")), "-a", str(data_path("driving.add.xml"))]
    try:
        for steps in (0, 2):
            env.reset(seed=23423)
            for _ in range(steps):
                env.step(STAY)
            libsumo.close()
            libsumo.start([*theirs, "--step-length", "0.25", "--no-step-log", "true"])
            try:
                assert libsumo.simulation.getOption("seed") == "23423"
                with pytest.raises(RuntimeError, match=r"not started by sumo_scenarios.*close it"):
                    env.step(STAY)
                assert libsumo.simulation.getTime() == 0.0, steps  # theirs was not stepped
            finally:
                libsumo.close()
        env.reset(seed=1)  # theirs closed: the env starts its own again
        env.step(STAY)
    finally:
        env.close()


def test_a_step_after_the_user_stepped_the_envs_simulation_says_so(libsumo_free):
    """libsumo.simulationStep() called by hand on the env's own simulation: the env's next step
    raises a RuntimeError saying so (its cars' speeds, measured over one step, and its road
    bookkeeping would be off), not that another simulation replaced it; a reset goes on."""
    env = DrivingEnv(scenario="light")
    try:
        env.reset(seed=0)
        env.step(STAY)
        libsumo.simulationStep()
        with pytest.raises(RuntimeError, match=r"stepped outside this env.*reset\(\)"):
            env.step(STAY)
        env.reset(seed=1)
        env.step(STAY)
    finally:
        env.close()


def test_closing_the_env_leaves_a_simulation_the_user_started_in_its_place_running(libsumo_free):
    """The researcher closes the env's libsumo simulation and starts one of their own: the
    env's close(), or its collection when dropped unclosed, leaves theirs running. (Both
    closed it: libsumo.close() on a simulation that was no longer the env's.)"""
    try:
        for how in ("close", "collect"):
            env = DrivingEnv(scenario="light")
            env.reset(seed=0)
            libsumo.close()
            libsumo.start(_THEIRS)
            libsumo.simulationStep()
            if how == "close":
                env.close()
            del env
            gc.collect()
            assert libsumo.simulation.isLoaded(), how
            libsumo.simulationStep()  # still the researcher's
            assert libsumo.simulation.getTime() == 2.0
            libsumo.close()
    finally:
        libsumo.close()
    env = DrivingEnv(scenario="light")  # theirs closed: an env starts its own
    try:
        env.reset(seed=0)
        env.step(STAY)
    finally:
        env.close()


@pytest.mark.parametrize("call", ["simulationStep", "vehicle.getLanePosition", "vehicle.remove"])
def test_a_step_after_one_cut_short_says_so_and_a_reset_goes_on(monkeypatch, call):
    """A Ctrl-C (KeyboardInterrupt) that lands inside a step: while SUMO steps (Python raises
    it as the C call returns), while the cars are read back, or while cars are recycled
    (removed and added). The next step raises a RuntimeError saying the last step did not
    finish (not that the user stepped the simulation by hand) instead of going on from
    half-updated bookkeeping; a reset then goes on."""
    import gc

    gc.collect()  # an env an earlier test dropped unclosed releases libsumo when collected
    owner, _, name = call.rpartition(".")
    where = libsumo.vehicle if owner else libsumo
    real = getattr(where, name)
    fired = []

    def once(*args):
        if fired:
            return real(*args)
        fired.append(args)
        if name == "simulationStep":
            real(*args)  # SUMO stepped; the signal is raised as the call returns
        raise KeyboardInterrupt

    env = DrivingEnv(scenario="train")
    try:
        env.reset(seed=0)
        env.step(STAY)
        monkeypatch.setattr(where, name, once)
        with pytest.raises(KeyboardInterrupt):
            for _ in range(400):  # a car falls behind and is recycled within a few dozen steps
                env.step(STAY)
        monkeypatch.setattr(where, name, real)
        for _ in range(2):  # and again: the step that refused changed nothing
            with pytest.raises(RuntimeError, match=r"last step did not finish.*reset\(\)") as e:
                env.step(STAY)
            assert "stepped outside" not in str(e.value)
        env.reset(seed=1)
        for _ in range(5):
            env.step(LEFT)
    finally:
        env.close()


def test_drawing_after_a_step_cut_short_is_refused_like_the_next_step(monkeypatch):
    """render() and frame() after a step cut short (a Ctrl-C while the cars were read back)
    drew the half-updated scene: the ego moved, the cars partly where they were, and the step
    count of the new step. Like the next step they raise, saying the last step did not finish
    and to reset(); a reset draws again. After close() too (the scene is still half updated),
    but the message said "reset() to draw again" while reset() on a closed env raises "this
    DrivingEnv is closed; create a new one": closed, it says to create a new env."""
    import gc
    import re

    gc.collect()  # an env an earlier test dropped unclosed releases libsumo when collected
    real = libsumo.vehicle.getLanePosition
    calls = []

    def cut(vid):
        calls.append(vid)
        if len(calls) == 3:  # the ego and one car read back, then the Ctrl-C
            raise KeyboardInterrupt
        return real(vid)

    for close_first in (False, True):
        calls.clear()
        env = DrivingEnv(scenario="train", render_mode="rgb_array")
        try:
            env.reset(seed=0)
            env.step(STAY)
            monkeypatch.setattr(libsumo.vehicle, "getLanePosition", cut)
            with pytest.raises(KeyboardInterrupt):
                env.step(STAY)
            monkeypatch.setattr(libsumo.vehicle, "getLanePosition", real)
            if close_first:
                env.close()
            says = r"closed.*create a new" if close_first else r"reset\(\) to draw again"
            for draw in (env.frame, env.render):
                with pytest.raises(RuntimeError, match=r"last step did not finish") as e:
                    draw()
                assert re.search(says, str(e.value)), e.value
                assert not close_first or "reset()" not in str(e.value), e.value
            if not close_first:
                env.reset(seed=1)
                assert env.frame().step == 0 and env.render().shape[2] == 3
        finally:
            env.close()


def test_a_ctrl_c_right_after_the_simulation_stepped_does_not_delay_truncation(monkeypatch):
    """A Ctrl-C that lands as HighwaySim.step returns, before DrivingEnv.step counted the step:
    the env kept its own counter beside the simulation's, so it missed that step and every
    later info["t"] and the truncation came one step late. The env's count is the
    simulation's: the step after the interrupted one is step 3 of 3, truncated."""
    from sumo_scenarios.sim import HighwaySim

    real = HighwaySim.step
    fired = []

    def then_interrupt(self, target_lane):
        real(self, target_lane)  # the simulation stepped; the signal comes as it returns
        if not fired:
            fired.append(target_lane)
            raise KeyboardInterrupt

    env = DrivingEnv(scenario="train", max_episode_steps=3)
    try:
        env.reset(seed=0)
        assert env.step(STAY)[4]["t"] == 1
        monkeypatch.setattr(HighwaySim, "step", then_interrupt)
        with pytest.raises(KeyboardInterrupt):
            env.step(STAY)
        monkeypatch.setattr(HighwaySim, "step", real)
        *_, truncated, info = env.step(STAY)
        assert (info["t"], truncated) == (3, True)
        assert env.frame().step == 3
    finally:
        env.close()


@pytest.mark.parametrize("stepped", [True, False])
def test_a_frame_after_a_ctrl_c_around_the_simulation_step_names_its_own_action(
    monkeypatch, stepped
):
    """A Ctrl-C that lands as HighwaySim.step returns, before DrivingEnv.step kept the step's
    action: the new scene (step 2, after a stay) was drawn labelled with the previous step's
    action (left). Here the KeyboardInterrupt comes as the simulation's step returns (the scene
    is step 2's: its action is the stay), or before the simulation stepped (the scene is still
    step 1's: its action is the left)."""
    from sumo_scenarios.sim import HighwaySim

    real = HighwaySim.step

    def interrupted(self, target_lane):
        if stepped:
            real(self, target_lane)  # the simulation stepped; the signal comes as it returns
        raise KeyboardInterrupt

    env = DrivingEnv(scenario="train", render_mode="rgb_array")
    try:
        env.reset(seed=0)
        env.step(LEFT)
        assert (env.frame().step, env.frame().action) == (1, LEFT)
        monkeypatch.setattr(HighwaySim, "step", interrupted)
        with pytest.raises(KeyboardInterrupt):
            env.step(STAY)
        monkeypatch.setattr(HighwaySim, "step", real)
        want = (2, STAY) if stepped else (1, LEFT)
        assert (env.frame().step, env.frame().action) == want
        env.step(RIGHT)  # and the env goes on
        assert (env.frame().step, env.frame().action) == (want[0] + 1, RIGHT)
    finally:
        env.close()


def test_a_lane_that_is_not_a_whole_number_is_refused_before_the_step_starts(env):
    """HighwaySim.step(2.5) passed the range check and then failed inside libsumo after the
    step had begun, so every later step refused ("the env's last step did not finish")
    until a reset. A lane that is not a whole number is refused first; the simulation goes
    on."""
    env.reset(seed=3)
    sim = env._sim
    for lane in (2.5, np.float64(2.0), "2"):
        with pytest.raises(TypeError, match="target_lane must be a whole lane number"):
            sim.step(lane)
    sim.step(np.int64(2))
    sim.step(2)
