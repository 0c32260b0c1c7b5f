"""Corridor: motion noise, perturbed starts, the expert's recovery off the route, the map cache,
the figures' palette and legends."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from corridor.env import CorridorEnv
from corridor.expert import CorridorExpert
from corridor.maps import load_map
from corridor.world import Action, CorridorWorld, WorldConfig

F, L, R, U = (int(a) for a in Action)
NOISY = WorldConfig.legged_robot()


# ---------------------------------------------------------------- map cache
def test_replace_gives_a_map_with_its_own_cache():
    m = load_map("figure2")
    m.route_polyline()  # fill the cache
    back = dataclasses.replace(m, route=tuple(reversed(m.route)))
    # The reversed map starts from P0 toward P3 (north), not toward P1 (east).
    assert back.start_pose() == pytest.approx((0.0, 0.2, math.pi / 2))
    np.testing.assert_allclose(back.route_polyline().points[0], [0.0, 0.2])
    np.testing.assert_allclose(m.route_polyline().points[0], [0.2, 0.0])
    assert back.manoeuvres() != m.manoeuvres()
    assert back.walls() == m.walls()  # same corridors, same walls


# ---------------------------------------------------------------- motion noise
def test_legged_robot_noise_magnitudes_are_documented_values():
    assert NOISY.forward_noise == 0.10
    assert NOISY.heading_noise == pytest.approx(math.radians(3.0))
    assert NOISY.forward_heading_noise == pytest.approx(math.radians(1.5))
    assert NOISY.noisy_motion and not WorldConfig().noisy_motion


def test_forward_step_length_and_heading_spread_match_the_config():
    """400 single forward steps in the open: length sd 10% of 0.2 m, heading sd 1.5 degrees,
    means unbiased (each within 4 standard errors)."""
    w = CorridorWorld(load_map("figure2"), NOISY)
    rng = np.random.default_rng(0)
    lengths, headings = [], []
    for _ in range(400):
        w.set_pose(0.2, 0.0, 0.0)  # 1.5 m of free corridor ahead
        assert w.step(F, rng) is False
        x, y, h = w.pose
        lengths.append(math.hypot(x - 0.2, y))
        headings.append(h)
    lengths, headings = np.array(lengths), np.array(headings)
    n = len(lengths)
    assert abs(lengths.mean() - 0.2) < 4 * 0.02 / math.sqrt(n)
    assert lengths.std() == pytest.approx(0.02, rel=0.15)
    assert abs(headings.mean()) < 4 * math.radians(1.5) / math.sqrt(n)
    assert headings.std() == pytest.approx(math.radians(1.5), rel=0.15)
    # A forward step walks along its erred heading: the sideways drift is length * sin(error).
    w.set_pose(0.2, 0.0, 0.0)
    w.step(F, np.random.default_rng(7))
    x, y, h = w.pose
    assert y == pytest.approx((x - 0.2) * math.tan(h), abs=1e-12)


class _Draws:
    """A generator stand-in whose ``standard_normal`` gives the same draws every call."""

    def __init__(self, *z: float) -> None:
        self.z = np.array(z, dtype=float)

    def standard_normal(self, size: int) -> np.ndarray:
        assert size == len(self.z)
        return self.z.copy()


@pytest.mark.parametrize("z, length", [(100.0, 0.3), (-100.0, 0.1)])
def test_a_forward_steps_length_factor_is_clipped_to_half_and_one_and_a_half(z, length):
    """The module docstring's clip of the length factor 1 + forward_noise * z to [0.5, 1.5]:
    a draw 100 sd out makes a 0.2 m step 0.3 m (or 0.1 m), straight ahead, not 2.2 m into
    the wall (or 1.8 m backwards)."""
    w = CorridorWorld(load_map("figure2"), WorldConfig(forward_noise=0.1))
    w.set_pose(0.2, 0.0, 0.0)  # 1.5 m of free corridor ahead
    assert w.step(F, _Draws(z, 0.0)) is False
    assert w.pose == pytest.approx((0.2 + length, 0.0, 0.0))


def test_heading_errors_do_not_add_up():
    """After 100 u-turns (3 degrees sd each) the heading is still within 3 sd of the commanded
    one: the error is redrawn around the commanded heading, not accumulated (a random walk would
    have an sd of 30 degrees)."""
    w = CorridorWorld(load_map("figure2"), NOISY)
    w.set_pose(0.0, 0.6, math.pi / 2)
    rng = np.random.default_rng(1)
    errors = []
    for _ in range(100):
        w.step(U, rng)
        errors.append(math.remainder(w.pose[2] - w.commanded_heading, 2 * math.pi))
    errors = np.abs(np.array(errors))
    assert errors.max() <= 3 * NOISY.heading_noise + 1e-12
    assert np.degrees(errors).mean() > 1.0  # the noise is there


def test_noisy_world_needs_a_generator_and_bad_noise_is_refused():
    w = CorridorWorld(load_map("figure2"), NOISY)
    with pytest.raises(ValueError, match="pass a numpy Generator"):
        w.step(F)
    with pytest.raises(ValueError, match="fraction"):
        WorldConfig(forward_noise=0.5)
    with pytest.raises(ValueError, match="math.radians"):
        WorldConfig(heading_noise=3.0)  # degrees given where radians are expected


def test_a_forward_heading_noise_alone_is_motion_noise():
    """forward_heading_noise is motion noise by itself: the world then needs a generator, and
    a forward step ends off its commanded heading (turns stay exact, heading_noise being 0)."""
    cfg = WorldConfig(forward_heading_noise=0.01)
    assert cfg.noisy_motion
    w = CorridorWorld(load_map("figure2"), cfg)
    w.set_pose(0.2, 0.0, 0.0)
    with pytest.raises(ValueError, match="pass a numpy Generator"):
        w.step(F)
    rng = np.random.default_rng(0)
    assert w.step(F, rng) is False
    x, y, h = w.pose
    assert 0 < abs(h) <= 3 * 0.01 and y != 0.0
    assert math.hypot(x - 0.2, y) == pytest.approx(cfg.forward_distance)  # no length noise


def test_noisy_env_same_seed_same_run():
    def run(seed: int) -> np.ndarray:
        env = CorridorEnv("figure2", NOISY)
        expert = CorridorExpert(env.corridor_map, NOISY)
        obs, info = env.reset(seed=seed)
        poses = []
        for _ in range(60):
            obs, _, term, trunc, info = env.step(expert(obs, info))
            poses.append(info["pose"])
            if term or trunc:
                obs, info = env.reset()
        return np.array(poses)

    np.testing.assert_array_equal(run(3), run(3))
    assert not np.array_equal(run(3), run(4))


# ---------------------------------------------------------------- perturbed starts
def test_perturbed_starts_are_seeded_bounded_and_free():
    env = CorridorEnv("figure2", NOISY, start_perturbation=(0.1, math.radians(10)))
    x0, y0, h0 = env.corridor_map.start_pose()
    poses = []
    for seed in range(50):
        _, info = env.reset(seed=seed)
        poses.append(info["pose"])
        assert min(info["true_ranges"]) >= env.world.config.robot_radius - 1e-9  # no overlap
    poses = np.array(poses)
    assert np.abs(poses[:, 0] - x0).max() <= 0.1 and np.abs(poses[:, 1] - y0).max() <= 0.1
    assert np.abs(poses[:, 2] - h0).max() <= math.radians(10)
    assert poses[:, 1].std() > 0.03  # they do vary
    _, again = env.reset(seed=7)
    np.testing.assert_array_equal(again["pose"], poses[7])
    with pytest.raises(ValueError, match="start_perturbation"):
        CorridorEnv("figure2", start_perturbation=(0.3, 0.1))


# ---------------------------------------------------------------- the expert
@pytest.mark.parametrize("map_name", ["figure2", "lshape"])
def test_expert_with_noisy_motion_drives_clean_circuits(map_name):
    """Measured: 149 of 150 clean circuits on each map (30 seeds x 5); here 40 circuits."""
    env = CorridorEnv(map_name, NOISY)
    expert = CorridorExpert(env.corridor_map, NOISY)
    clean = completed = 0
    for seed in range(8):
        obs, info = env.reset(seed=seed)
        for _ in range(5):
            while True:
                obs, _, term, trunc, info = env.step(expert(obs, info))
                if term or trunc:
                    break
            completed += term
            clean += info["is_success"]
            obs, info = env.reset()
    assert completed == 40 and clean >= 39


def test_expert_recovers_from_detours_off_the_route():
    """A learner's mistakes: 1-4 random actions at a random point of the circuit, with motion
    noise. The expert then brings the robot back and completes the circuit every time."""
    env = CorridorEnv("figure2", NOISY, max_episode_steps=120)
    expert = CorridorExpert(env.corridor_map, NOISY)
    rng = np.random.default_rng(0)
    off_route = 0
    for seed in range(30):
        obs, info = env.reset(seed=seed)
        detour_at, n_random = int(rng.integers(2, 24)), int(rng.integers(1, 5))
        steps = 0
        while True:
            if detour_at <= steps < detour_at + n_random:
                a = int(rng.integers(4))
            else:
                a = expert(obs, info)
            steps += 1
            obs, _, term, trunc, info = env.step(a)
            if steps == detour_at + n_random:
                off_route += bool(
                    env.world.progress.lateral > expert.on_route_tolerance or expert(obs, info) != F
                )
            if term or trunc:
                break
        assert term, f"seed {seed}: the expert did not finish the circuit after a detour"
    assert off_route >= 10  # the detours did take the robot off its way


def test_blocked_says_which_ways_a_wall_stops_the_robot_at_once():
    """Hand-placed on figure2 (corridors 0.6 m wide, robot radius 0.12 m): for the robot's
    heading and after a turn left, a turn right and a u-turn, 0 if a forward step is free for
    half its length, else the side of the wall met (+1 left, -1 right or ahead)."""
    world = CorridorWorld(load_map("figure2"), WorldConfig())
    turns = (0.0, math.pi / 2, -math.pi / 2, math.pi)
    cases = {
        # west, below the junction J: the corner (1.1, 0.9) at its front-left, all rays open
        (1.2, 0.969, math.pi): [1, -1, 0, 0],
        (1.2, 1.2, math.pi): [0, 0, 0, 0],  # the junction's middle: free every way
        (1.17, 1.03, -math.pi / 2): [-1, 0, 0, 0],  # south, the same corner at its front-right
        (1.55, 0.2, 0.0): [-1, 0, 0, 0],  # east, 3 cm from the wall straight ahead
        (0.4, 0.0, 0.0): [0, 0, 0, 0],  # the start
    }
    for (x, y, h), want in cases.items():
        world.set_pose(x, y, h)
        assert [world.blocked(t) for t in turns] == want, (x, y, h)
        assert world.pose == (x, y, h)  # probing does not move it
    world.set_pose(1.2, 0.969, math.pi)
    assert min(world.true_ranges()) > 1.2  # the rays see none of it
    env = CorridorEnv("figure2", NOISY)
    _, info = env.reset(seed=0)
    assert info["blocked"] == [0, 0, 0, 0]  # reported after a contact only


def test_expert_stopped_by_a_wall_turns_the_free_way_nearest_the_route():
    """Hand-placed on figure2 (route segment 4 runs west along y = 1.2 from the junction J,
    segment 0 east along y = 0); the expert is told of the walls as after a contact."""
    world = CorridorWorld(load_map("figure2"), WorldConfig())
    expert = CorridorExpert(world.map, WorldConfig())
    turns = (0.0, math.pi / 2, -math.pi / 2, math.pi)

    def answer(x: float, y: float, heading: float, segment: int, contact: bool) -> int:
        world.set_pose(x, y, heading)
        info = {
            "pose": np.array(world.pose),
            "segment": segment,
            "true_ranges": world.true_ranges(),
            "blocked": [world.blocked(t) for t in turns] if contact else [0, 0, 0, 0],
        }
        return expert(world.sense(np.random.default_rng(0)), info)

    assert answer(0.8, 1.2, math.pi, 4, True) == F  # along the route, nothing in the way
    # Against the corner (1.1, 0.9) below J, all rays open: forward would push on. North is
    # free and across the route's way (west), east free but against it, south stopped.
    assert answer(1.2, 0.969, math.pi, 4, False) == F  # no contact reported: forward
    assert answer(1.2, 0.969, math.pi, 4, True) == R
    # In the junction's north-west corner facing north (the corner (1.1, 1.5) at its
    # front-left): west is stopped, east leads back against the route, south is free.
    assert answer(1.17, 1.39, math.pi / 2, 4, True) == U
    # Facing east at P0's north edge, the corner (0.3, 0.3) straight ahead, in the route's
    # corridor and heading its way (segment 0, east): north and south are both free and
    # equally across it; the tie goes away from the wall, to the left.
    assert answer(0.1, 0.3, 0.0, 0, False) == F
    assert answer(0.1, 0.3, 0.0, 0, True) == L
    # Facing east at P3's south-east edge, off the route (segment 0 runs east along y = 0):
    # the way back is west to P3, south to P0 and east, so a u-turn. (A right turn from here
    # would end against the east wall of the corridor P3-P0.)
    assert answer(0.09, 0.91, 0.0, 0, False) == U


def test_expert_off_the_route_takes_the_shortest_way_back_on_the_map():
    """Hand-placed on figure2 with the route's progress at the start of segment 5 (P3 -> P0,
    south along x = 0), as after a detour past the junction P3: the expert drives back by the
    map's corridors, the shortest way, to where the progress stands."""
    world = CorridorWorld(load_map("figure2"), WorldConfig())
    expert = CorridorExpert(world.map, WorldConfig())
    at_p3 = float(np.sum(expert.route.segment_lengths[:5]))

    def answer(x: float, y: float, heading: float) -> int:
        world.set_pose(x, y, heading)
        info = {
            "pose": np.array(world.pose),
            "segment": 5,
            "lap_position": at_p3,
            "true_ranges": world.true_ranges(),
            "blocked": [0, 0, 0, 0],
        }
        return expert(world.sense(np.random.default_rng(0)), info)

    # East along J - P3, away from P3: back west (a u-turn, 0.6 m and a left turn at P3)
    # rather than round by J, P1 and P0.
    assert answer(0.6, 1.2, 0.0) == U
    # South from J towards P1: back north to J and west to P3 (2.6 m with the turns) rather
    # than on round P1 and P0 to P3 (3.8 m).
    assert answer(1.4, 0.6, -math.pi / 2) == U
    # West along P0 - P1: on to P0 and north (2.6 m) rather than back round P1, J (3.8 m).
    assert answer(1.0, 0.0, math.pi) == F
    # At P0's decision point: turn north now. (The reactive rule the expert had before saw
    # the end wall 0.6 m ahead and no opening yet, and u-turned.)
    assert answer(0.3, 0.0, math.pi) == R


def test_expert_past_the_node_by_more_than_half_a_step_takes_the_way_back():
    """The route's left turn at P1 (figure2, exact motion) made two steps late: the second
    forward step stops against P1's end wall, 0.18 m past the node with the progress still on
    segment 0. A turn from there would sweep the robot into that wall again; the expert takes
    the way back (a u-turn, then right at P1) and the circuit ends with the learner's contact
    only."""
    env = CorridorEnv("figure2", WorldConfig(), max_episode_steps=80)
    expert = CorridorExpert(env.corridor_map, WorldConfig())
    obs, info = env.reset(seed=0)
    for _ in range(5):  # to the decision point, 0.2 m before P1
        obs, _, _, _, info = env.step(expert(obs, info))
    assert expert(obs, info) == L
    for _ in range(2):  # the learner drives on
        obs, _, _, _, info = env.step(F)
    assert info["contact"] and info["segment"] == 0
    assert info["pose"][0] - 1.4 == pytest.approx(0.18)
    assert expert(obs, info) == U
    while True:
        obs, _, terminated, truncated, info = env.step(expert(obs, info))
        if terminated or truncated:
            break
    assert terminated and info["laps"] == 1 and info["contacts"] == 1


def test_expert_way_back_counts_a_step_for_every_turn():
    """The way back's cost is metres driven plus one step (0.2 m) per turn, the turn made now
    as well as those at the nodes; hand-placed with exact motion, where the two ways differ by
    less than a step in metres."""

    def answer(map_name, x, y, heading, segment, lap) -> int:
        world = CorridorWorld(load_map(map_name), WorldConfig())
        world.set_pose(x, y, heading)
        info = {
            "pose": np.array(world.pose),
            "segment": segment,
            "lap_position": lap,
            "true_ranges": world.true_ranges(),
            "blocked": [0, 0, 0, 0],
        }
        return CorridorExpert(world.map, WorldConfig())(world.sense(np.random.default_rng(0)), info)

    # figure2, 0.3 m above P0 heading south, the progress at J on segment 2 (into the spur,
    # north): left now and on by P1 is 2.4 m and two turns (now, P1); back up by P3 is 2.3 m
    # and three turns (the u-turn, P3, J). Counted in metres alone the u-turn would win.
    assert answer("figure2", 0.0, 0.3, -math.pi / 2, 2, 2.4) == L
    # lshape's corridors are one 8 m loop; heading east on A - B with the progress at E on
    # segment 4 (west to F), either way round is four turns (on: B, C, D, E; back: the u-turn
    # now, A, F and a u-turn at E) and the nearer way wins: on from x = 1.05 (3.95 m against
    # 4.05 m), back from x = 0.95.
    assert answer("lshape", 1.05, 0.0, 0.0, 4, 4.8) == F
    assert answer("lshape", 0.95, 0.0, 0.0, 4, 4.8) == U


def test_expert_way_back_goal_walls_and_contacts():
    """The way back's goal is where the route's progress stands, and its first action is one
    the walls allow. Hand-placed on figure2 with exact motion; the headings 0.5 rad off the
    corridor's make the route rule hand over to the way back."""
    world = CorridorWorld(load_map("figure2"), WorldConfig())
    expert = CorridorExpert(world.map, WorldConfig())
    start = np.concatenate([[0.0], np.cumsum(expert.route.segment_lengths)])  # of each segment

    def answer(x, y, heading, segment, lap, blocked=(0, 0, 0, 0)) -> int:
        world.set_pose(x, y, heading)
        info = {
            "pose": np.array(world.pose),
            "segment": segment,
            "lap_position": lap,
            "true_ranges": world.true_ranges(),
            "blocked": list(blocked),
        }
        return expert(world.sense(np.random.default_rng(0)), info)

    south = -math.pi / 2 + 0.5
    # Down P3 - P0 (segment 5), 0.6 m below P3: on with the progress 0.4 m along, but with the
    # progress still at P3 the robot is past where it can follow (0.5 m): back up to P3.
    assert answer(0.0, 0.6, south, 5, start[5] + 0.4) == F
    assert answer(0.0, 0.6, south, 5, start[5]) == U
    # Progress on segment 4 (J -> P3, west): within half a metre of its end the goal is the
    # next segment, so a robot already heading down P3 - P0 drives on; far from the end it
    # must go back and come along segment 4.
    assert answer(0.0, 0.8, -math.pi / 2, 4, start[5] - 0.3) == F
    assert answer(0.0, 0.8, -math.pi / 2, 4, start[4]) == U
    # Facing east on P0 - P1 with its body touching the north wall, segment 1 (P1 -> J, north)
    # ahead: a left turn now would sweep the robot through that wall, so it is not taken (the
    # way back checked only where a turn ended, and took it).
    assert answer(1.04, 0.18, 0.0, 1, start[1]) != L
    # North up P1 - J, 0.5 m below J, segment 4 (J -> P3, west) to come: a left turn now would
    # end at the edge of J - P3, against the corner (1.1, 0.9); drive on and turn at J.
    assert answer(1.4, 0.7, math.pi / 2, 4, start[4]) == F
    # After a contact that stops forward (info["blocked"]), forward is not taken.
    assert answer(1.0, 0.0, math.pi, 5, start[5]) == F
    assert answer(1.0, 0.0, math.pi, 5, start[5], blocked=(1, 0, 0, 0)) == U
    # Facing the east wall of P3 - P0, too near it to start a turn or a step, and a u-turn would
    # face the corridor's west wall: the turn that heads the shortest way (south, the progress
    # 0.4 m down), made where the robot stands.
    # (Left first, as the reactive rule would, heads north, away from it.)
    assert answer(0.15, 0.6, 0.0, 5, start[5] + 0.4) == R


def test_expert_gets_the_robot_out_of_a_corner():
    """A detour on lshape with exact motion (seed 566, five actions at step 14) leaves the
    robot at the corner C, against the inside corner (1.7, 0.7) of the turn from B-C into C-D,
    where forward is stopped by that corner and no turn lands it clear of the walls. The way
    back that counted a u-turn as always possible rocked it between two u-turns for the rest of
    the episode; a u-turn counts only where half a step is then free, and the circuit ends."""
    env = CorridorEnv("lshape", WorldConfig(), max_episode_steps=150)
    expert = CorridorExpert(env.corridor_map, WorldConfig())
    obs, info = env.reset(seed=566)
    forced = {14: R, 15: R, 16: F, 17: R, 18: L}
    for step in range(150):
        obs, _, terminated, truncated, info = env.step(forced.get(step, expert(obs, info)))
        if terminated or truncated:
            break
    assert terminated and step < 60


def test_expert_brings_the_robot_back_when_the_progress_is_left_behind():
    """A detour measured on the noisy robot (seed 56 of ``scripts/corridor_expert_recovery.py``):
    four actions at P3 leave the route's progress on segment 5 (P3 -> P0) while the robot heads
    back east along the corridor it came by, farther from the route's point than the progress
    follows. The expert before the map-based way back drove a loop of the corridors for the
    rest of the episode (150 actions); now the circuit ends soon after."""
    env = CorridorEnv("figure2", NOISY, max_episode_steps=150)
    expert = CorridorExpert(env.corridor_map, NOISY)
    obs, info = env.reset(seed=56)
    forced = {21: F, 22: R, 23: U, 24: L}
    for step in range(150):
        obs, _, terminated, truncated, info = env.step(forced.get(step, expert(obs, info)))
        if step == 24:
            assert info["segment"] == 5 and math.cos(info["pose"][2]) > 0.9  # east, left behind
        if terminated or truncated:
            break
    assert terminated and step < 40


def test_expert_gets_out_when_a_late_turn_leaves_it_against_a_corner():
    """A learner's mistake the random detours rarely make: one of the route's manoeuvres one or
    two steps late. Under motion noise the robot may then rest against a corner that stops every
    forward step while all three rays read open. The expert finishes the circuit every time and
    never keeps pushing: at most a few forward steps in a row that do not move the robot (the
    noise of the heading frees some). Without ``info["blocked"]`` (the expert before it had
    that rule) it pushed on, for up to the rest of the episode, and some circuits never ended
    (measured: 20 of 400 with the reactive off-route rule the expert had then, 27 of 400 with
    its way back on the map)."""
    env = CorridorEnv("figure2", NOISY, max_episode_steps=150)
    expert = CorridorExpert(env.corridor_map, NOISY)
    n_turns = sum(1 for k in env.corridor_map.manoeuvres() if k != "straight")

    def drive(turn: int, late: int, seed: int, see_blocked: bool) -> tuple[bool, int]:
        obs, info = env.reset(seed=seed)
        seen, pending, pushes, longest = 0, None, 0, 0
        while True:
            shown = info if see_blocked else {k: v for k, v in info.items() if k != "blocked"}
            a = expert(obs, shown)
            if pending is None and a != F:
                if seen == turn:
                    pending = [late, a]
                seen += 1
            if pending and pending[0] >= 0:
                a, pending[0] = (F if pending[0] > 0 else pending[1]), pending[0] - 1
            before = info["pose"][:2].copy()
            obs, _, terminated, truncated, info = env.step(a)
            stuck = a == F and np.array_equal(before, info["pose"][:2])
            pushes = pushes + 1 if stuck else 0
            longest = max(longest, pushes)
            if terminated or truncated:
                return terminated, longest

    runs = [(t, late, s) for t in range(n_turns) for late in (1, 2) for s in range(8)]
    results = [drive(*r, see_blocked=True) for r in runs]
    assert all(done for done, _ in results)
    assert max(longest for _, longest in results) <= 5
    before = [drive(*r, see_blocked=False) for r in runs]
    assert not all(done for done, _ in before)
    assert max(longest for _, longest in before) > 20  # the scenario does corner the robot


def test_figure2_spur_does_not_read_like_a_left_corner_under_motion_noise():
    """Where the expert drives forward into the dead-end spur while its left sensor still sees
    the side corridor, the front range is well beyond every front range at which it turns left,
    so no sensor reading asks for both. With the spur 0.6 m long (before issue 12) the gap was
    0.03 m and learned policies turned left there into the corner wall."""

    def ranges(corridor_map):
        env = CorridorEnv(corridor_map, NOISY)
        expert = CorridorExpert(corridor_map, NOISY)
        fwd_front, left_front = [], []
        for seed in range(15):
            obs, info = env.reset(seed=seed)
            while True:
                a = expert(obs, info)
                left, front, _ = info["true_ranges"]
                if a == L:
                    left_front.append(front)
                elif a == F and info["segment"] == 2 and left >= 1.0:
                    fwd_front.append(front)
                obs, _, term, trunc, info = env.step(a)
                if term or trunc:
                    break
        return min(fwd_front), max(left_front)

    m = load_map("figure2")
    fwd, left = ranges(m)
    assert fwd - left >= 0.15
    short = dataclasses.replace(m, nodes={**m.nodes, "S": (1.4, 1.8)})
    fwd, left = ranges(short)
    assert fwd - left < 0.05  # the aliasing this map avoids


# ---------------------------------------------------------------- the experiment's defaults
def test_experiment_runs_the_noisy_robot_with_the_coverage_threshold_by_default():
    """Chosen before any result with it: the paper's "two standard deviations" as the share of
    a 1-D Gaussian within 2 std (0.9545), a chi-square quantile with D = 3 degrees of freedom."""
    from scipy.stats import chi2

    from corridor.experiment import CorridorExperimentConfig

    cfg = CorridorExperimentConfig()
    assert cfg.world == NOISY and cfg.max_std == 2.0 and cfg.threshold_reading == "coverage"
    coverage = chi2.cdf(4.0, 1)  # P(|z| <= 2), 0.9545
    assert cfg.rule().threshold(3) == pytest.approx(math.sqrt(chi2.ppf(coverage, 3)), rel=1e-9)
    assert cfg.rule().threshold(3) == pytest.approx(2.8328, abs=1e-4)
    literal = dataclasses.replace(cfg, threshold_reading="literal").rule()
    assert literal.threshold(3) == 2.0
    assert chi2.cdf(4.0, 3) == pytest.approx(0.739, abs=1e-3)  # what 2 std holds in 3-D
    assert not CorridorExperimentConfig.exact_motion().world.noisy_motion
    with pytest.raises(ValueError, match="threshold_reading"):
        CorridorExperimentConfig(threshold_reading="2std")


def _tiny_experiment(**overrides):
    """The corridor experiment at a size that runs in seconds (exact motion, no CBA arm)."""
    from corridor.baseline import PrioritizedSweepingConfig
    from corridor.experiment import CorridorExperimentConfig

    settings = dict(
        seeds=(0,), cba=False, eval_circuits=2, ps=PrioritizedSweepingConfig(max_steps=300)
    )
    return CorridorExperimentConfig.exact_motion(**{**settings, **overrides})


def test_a_run_dir_left_by_a_stopped_run_is_refused_before_any_seed_runs(tmp_path):
    """A run stopped before results.json leaves its seeds' sessions: a new run into that
    directory is refused at once, naming them, instead of failing on the session it would
    overwrite (after the seeds before it ran) with a pointer to ConfidentTeacher.resume."""
    from corridor.experiment import run_experiment

    run_experiment(_tiny_experiment(), tmp_path, workers=1, progress=False)
    (tmp_path / "results.json").unlink()  # as if stopped before it was written
    with pytest.raises(FileExistsError, match=r"sessions/seed0\), left by an earlier run"):
        run_experiment(_tiny_experiment(seeds=(1, 0)), tmp_path, workers=1, progress=False)
    assert not (tmp_path / "sessions" / "seed1").exists()


def _untimed(value):
    """A results.json without its timing keys (which a resumed run cannot share)."""
    if isinstance(value, dict):
        return {k: _untimed(v) for k, v in value.items() if k not in ("seconds", "wall")}
    if isinstance(value, list):
        return [_untimed(v) for v in value]
    return value


def test_a_stopped_run_resumes_to_the_results_and_figures_of_a_run_never_stopped(
    tmp_path, monkeypatch
):
    """resume=True takes a finished seed from its seed_result.json, runs again the seed that
    was stopped part-way (its session there, no result), and writes the results.json, summary
    and figures of the run never stopped; a resume with another config, or of a finished run,
    is refused, naming what differs."""
    import json
    import shutil

    import corridor.experiment
    from corridor.experiment import run_experiment
    from torchcbl.evaluation import ResumeError

    # for time: the reward's table ranking over 50 steps, not 1000 (both runs alike)
    score = corridor.experiment.score_tables
    monkeypatch.setattr(
        corridor.experiment, "score_tables", lambda *a, **k: score(*a, steps=50, **k)
    )
    cfg = _tiny_experiment(seeds=(0, 1))
    whole, stopped = tmp_path / "whole", tmp_path / "stopped"
    run_experiment(cfg, whole, workers=1, progress=False)
    # as if killed while seed 1 ran: seed 0 finished, seed 1's session has no result yet
    shutil.copytree(whole, stopped)
    for name in ("results.json", "summary.txt", "figure3.png", "figure4.png", "map.png"):
        (stopped / name).unlink()
    (stopped / "sessions" / "seed1" / "seed_result.json").unlink()
    kept = stopped / "sessions" / "seed0" / "seed_result.json"
    marked = json.loads(kept.read_text())
    marked["result"]["seconds"] = -1.0  # taken from the file, not run again
    kept.write_text(json.dumps(marked))
    run_experiment(cfg, stopped, workers=1, progress=False, resume=True)
    resumed = json.loads((stopped / "results.json").read_text())
    assert resumed["per_seed"][0]["seconds"] == -1.0
    assert _untimed(resumed) == _untimed(json.loads((whole / "results.json").read_text()))
    for name in ("summary.txt", "figure3.png", "figure4.png", "map.png"):
        assert (stopped / name).read_bytes() == (whole / name).read_bytes(), name
    with pytest.raises(FileExistsError, match="its run finished, there is nothing to resume"):
        run_experiment(cfg, stopped, workers=1, progress=False, resume=True)
    (stopped / "results.json").unlink()
    other = dataclasses.replace(cfg, eval_circuits=3)
    with pytest.raises(ResumeError, match=r"seed 0's .* eval_circuits \(2 there, 3 here\); resume"):
        run_experiment(other, stopped, workers=1, progress=False, resume=True)
    with pytest.raises(
        ResumeError, match=r"seeds that this config does not run \(sessions/seed1\)"
    ):
        run_experiment(_tiny_experiment(), stopped, workers=1, progress=False, resume=True)
    assert kept.is_file() and (stopped / "sessions" / "seed1" / "seed_result.json").is_file()
    # a seed computed by other code (another commit, torch, pymunk) is not mixed in
    marked = json.loads(kept.read_text())
    marked["versions"]["torchcbl_source"] = "git 0000000"
    kept.write_text(json.dumps(marked))
    with pytest.raises(ResumeError, match=r"seed 0's .* other code: torchcbl_source \('git 0000"):
        run_experiment(cfg, stopped, workers=1, progress=False, resume=True)
    # nor is a run directory another run is writing into (a resume from a second shell)
    import fcntl

    from torchcbl.evaluation import RunDirLockedError

    with open(stopped / ".run.lock", "a", encoding="utf-8") as held:
        fcntl.flock(held.fileno(), fcntl.LOCK_EX)
        with pytest.raises(RunDirLockedError, match="is being written by another run"):
            run_experiment(cfg, stopped, workers=1, progress=False, resume=True)
    assert kept.is_file() and (stopped / "sessions" / "seed1" / "seed_result.json").is_file()


def test_the_summary_names_the_variants_own_circuit_counts(tmp_path):
    """summary.txt's rows say the circuits this run evaluated and stopped on, not the paper's
    10 and 3 whatever the config said."""
    from corridor.baseline import PrioritizedSweepingConfig
    from corridor.experiment import CorridorExperimentConfig, run_experiment

    teaching = dataclasses.replace(
        CorridorExperimentConfig().teaching, autonomous_episodes_to_stop=3
    )
    ps = PrioritizedSweepingConfig(max_steps=300, eval_circuits=2)
    cfg = _tiny_experiment(teaching=teaching, ps=ps, cba=True)
    run_experiment(cfg, tmp_path, workers=1, progress=False)
    text = (tmp_path / "summary.txt").read_text()
    assert "| final policy: clean circuits out of 2, paper's start | 10 |" in text
    assert "| teaching finished (3 clean circuits, no request) | yes |" in text
    assert "| PS steps, first greedy table driving 2 clean circuits | 275 |" in text
    assert "CBA: final policy, clean circuits out of 2" in text
    assert "CBA: teaching finished (3 clean circuits" in text
    assert "out of 10" not in text and "(10 clean circuits" not in text


def test_a_run_in_this_process_gives_torchs_threads_back():
    """workers=1 runs the seed here on one torch thread (as the workers do); the caller's
    thread count is restored after, not left at 1 for whatever it runs next."""
    import torch

    from corridor.experiment import run_seed

    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        out = run_seed(_tiny_experiment(eval_circuits=1), 0, None)
        assert out["seed"] == 0 and out["finished"]
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)


@pytest.mark.parametrize("workers", ["2", 2.5, None, 0, True])
def test_workers_must_be_a_whole_number_of_processes(tmp_path, workers):
    from corridor.experiment import run_experiment

    with pytest.raises(ValueError, match=r"workers must be an int >= 1, got "):
        run_experiment(_tiny_experiment(), tmp_path / "run", workers=workers, progress=False)
    assert not (tmp_path / "run").exists()


def test_a_run_on_a_map_file_given_by_a_relative_path_redraws_from_elsewhere(tmp_path, monkeypatch):
    """results.json records a map file by its absolute path: the run's figures redraw and its
    sessions evaluate from another working directory (the relative path named no file there)."""
    import json
    from importlib import resources

    from corridor.experiment import evaluate_saved_policy, plot_results, run_experiment

    work, elsewhere = tmp_path / "work", tmp_path / "elsewhere"
    (work / "maps").mkdir(parents=True)
    elsewhere.mkdir()
    shipped = resources.files("corridor") / "maps" / "figure2.json"
    (work / "maps" / "mine.json").write_text(shipped.read_text())
    monkeypatch.chdir(work)
    cfg = _tiny_experiment(map_name="maps/mine.json")
    assert cfg.map_name == str(work / "maps" / "mine.json")
    run_experiment(cfg, tmp_path / "run", workers=1, progress=False)
    monkeypatch.chdir(elsewhere)
    results = json.loads((tmp_path / "run" / "results.json").read_text())
    assert results["config"]["map_name"] == str(work / "maps" / "mine.json")
    (tmp_path / "run" / "map.png").unlink()
    plot_results(results, tmp_path / "run")
    assert (tmp_path / "run" / "map.png").stat().st_size > 1000
    report = evaluate_saved_policy(tmp_path / "run" / "sessions" / "seed0", n_steps=30)
    assert report["steps"] == 30 and report["map"] == str(work / "maps" / "mine.json")
    # a shipped map keeps its name
    assert _tiny_experiment(map_name="lshape").map_name == "lshape"


def test_plot_results_redraws_a_run_with_its_own_perturbed_starts(tmp_path):
    """A bigger robot needs narrower perturbed starts than the default 0.1 m: the run takes
    them, and plot_results redraws it with them (it refused it with the default's message)."""
    import json

    from corridor.experiment import plot_results, run_experiment

    cfg = _tiny_experiment(
        world=WorldConfig(robot_radius=0.2), eval_perturbation=(0.05, 0.1), eval_circuits=1
    )
    run_experiment(cfg, tmp_path, workers=1, progress=False)
    (tmp_path / "figure3.png").unlink()
    results = json.loads((tmp_path / "results.json").read_text())
    assert tmp_path / "figure3.png" in plot_results(results, tmp_path)
    assert (tmp_path / "figure3.png").stat().st_size > 1000


def test_a_seed_replays_from_the_config_in_results_json(tmp_path):
    """results.json's config reads back into the config that ran (from_dict), and run_seed on
    it gives that seed's figures again; what is not such a config is refused by name."""
    import json

    from corridor.baseline import PrioritizedSweepingConfig
    from corridor.experiment import CorridorExperimentConfig, run_experiment, run_seed

    cfg = _tiny_experiment(
        seeds=(1,), eval_perturbation=(0.05, 0.1), ps=PrioritizedSweepingConfig(max_steps=200)
    )
    run_experiment(cfg, tmp_path, workers=1, progress=False)
    results = json.loads((tmp_path / "results.json").read_text())
    again = CorridorExperimentConfig.from_dict(results["config"])
    assert again == cfg and again.to_dict() == results["config"]
    replay = run_seed(again, 1, None)
    stored = results["per_seed"][0]
    assert {k: replay[k] for k in stored if k != "seconds"} == {
        k: v for k, v in stored.items() if k != "seconds"
    }
    assert CorridorExperimentConfig.from_dict({"seeds": [4]}).seeds == (4,)  # the rest: defaults
    with pytest.raises(ValueError, match=r"unknown CorridorExperimentConfig fields \['seed'\]"):
        CorridorExperimentConfig.from_dict({"seed": 1})
    with pytest.raises(ValueError, match="world: not WorldConfig's fields"):
        CorridorExperimentConfig.from_dict({"world": {"radius": 0.1}})
    with pytest.raises(ValueError, match="expected a dict of CorridorExperimentConfig's fields"):
        CorridorExperimentConfig.from_dict(results)  # the whole results.json


def test_eval_perturbation_must_be_a_pair_up_front():
    """None passed the config (the env takes it) and the run then failed writing results.json
    after every seed had run; now the config refuses it. A list or array is kept as a pair."""
    import json

    for bad in (None, 0.1, (0.1,), "ab"):
        with pytest.raises(ValueError, match=r"eval_perturbation must be a \(metres, radians\)"):
            _tiny_experiment(eval_perturbation=bad)
    for given in ([0.05, 0.1], np.array([0.05, 0.1])):
        cfg = _tiny_experiment(eval_perturbation=given)
        assert cfg.eval_perturbation == (0.05, 0.1)
        assert json.loads(json.dumps(cfg.to_dict(), default=float))["eval_perturbation"] == [
            0.05,
            0.1,
        ]


def test_an_unknown_or_broken_map_is_named_as_the_map(tmp_path):
    """The map's own fault is the map_name's, not 'eval_perturbation on map ...'."""
    from corridor.experiment import CorridorExperimentConfig

    with pytest.raises(ValueError, match=r"^map_name: unknown map 'nomap'; shipped maps"):
        CorridorExperimentConfig(map_name="nomap")
    broken = tmp_path / "broken.json"
    broken.write_text("{not json")
    with pytest.raises(ValueError, match=r"^map_name: map .*broken.json' is not valid JSON"):
        CorridorExperimentConfig(map_name=str(broken))
    with pytest.raises(ValueError, match=r"^eval_perturbation on map 'figure2'"):
        CorridorExperimentConfig(eval_perturbation=(0.3, 0.1))  # still the perturbation's


@pytest.mark.parametrize(
    "argv, says",
    [
        (["--workers", "0"], "--workers: expected >= 1, got 0"),
        ([], "exists and is not an empty directory"),
    ],
)
def test_the_module_command_refuses_a_mistake_before_writing(tmp_path, argv, says):
    """`python -m corridor.experiment RUN_DIR`: a mistake is argparse's one line and exit code
    2 (as sumo_scenarios.experiment's), not run_experiment's traceback."""
    import subprocess
    import sys

    run = tmp_path / "run"
    if not argv:  # a RUN_DIR that already holds a run
        run.mkdir()
        (run / "results.json").write_text("{}")
    proc = subprocess.run(
        [sys.executable, "-m", "corridor.experiment", str(run), *argv],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2 and says in proc.stderr and "Traceback" not in proc.stderr
    assert sorted(p.name for p in tmp_path.rglob("*")) == ([] if argv else ["results.json", "run"])


# ---------------------------------------------------------------- figures
def test_one_colour_per_action_and_map_legend():
    from corridor.render import ACTION_COLORS, PATH_COLOR, RAY_COLOR, map_figure

    assert len(ACTION_COLORS) == len(Action) == len(set(ACTION_COLORS))
    assert RAY_COLOR not in ACTION_COLORS and PATH_COLOR not in ACTION_COLORS
    w = CorridorWorld(load_map("figure2"))
    fig = map_figure(w, [(0.2, 0.0), (0.4, 0.0)])
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    for expected in ("route", "path", "left sensor ray", "front sensor ray", "right sensor ray"):
        assert any(expected in label for label in labels), (expected, labels)


# ---------------------------------------------------------------- the logged confidence
def _investigation_script():
    """scripts/investigate_corridor_requests.py as a module (its ``_hand`` is the numpy
    oracle of a classification: Eq. 7's action and the distance to the most likely component
    of its mixture, from the model's buffers by inverse covariances and log densities)."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "investigate_corridor_requests.py"
    spec = importlib.util.spec_from_file_location("_investigate_requests", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_logged_distance_is_to_the_most_likely_component_of_the_model_of_that_step():
    """Every step of a noisy corridor session logs the model's action and distance for the
    observation it recorded, under the model fitted on exactly the labels before that step
    (not a stale or a later one), measured to the most likely component of the chosen mixture:
    checked against a hand computation (issue 12: the confident phase's requests)."""
    import copy

    import torch

    from corridor.experiment import CorridorExperimentConfig
    from torchcbl import ConfidentTeacher
    from torchcbl.gmm import GaussianMixtureSet

    cfg = CorridorExperimentConfig()
    corridor_map = load_map(cfg.map_name)
    snapshots: dict[int, object] = {}
    teacher = ConfidentTeacher(
        CorridorEnv(corridor_map, cfg.world),
        CorridorExpert(corridor_map, cfg.world),
        rule=cfg.rule(),
        config=dataclasses.replace(cfg.teaching, max_steps=160),
        seed=3,
        progress=False,
        on_refit=lambda model, n: snapshots.__setitem__(n, copy.deepcopy(model)),
    )
    teacher.run()
    oracle = _investigation_script()._hand
    records = teacher.records
    labelled = [r for r in records if r.teacher_action is not None]
    asked_confident = [r for r in labelled if r.phase == "confident"]
    assert len(asked_confident) >= 3 and any(r.autonomous for r in records)  # both kinds seen
    # The model is fitted on the recorded observations and labels (a fresh fit, deterministic).
    fresh = GaussianMixtureSet(4, 3, seed=3).fit(
        np.array([r.observation for r in labelled]), [r.teacher_action for r in labelled]
    )
    for name in ("means_", "covariances_", "component_mask_"):
        assert torch.equal(getattr(fresh, name), getattr(teacher.model, name)), name
    checked = 0
    for r in records:
        fitted_on = r.n_demonstrations - (0 if r.autonomous else 1)  # max_new = 1
        if fitted_on == 0:
            assert r.model_action == -1 and math.isinf(r.distance)
            continue
        hand = oracle(snapshots[fitted_on], np.asarray(r.observation, float))
        assert r.model_action == hand["action"]
        assert r.distance == pytest.approx(hand["dist"], rel=1e-9, abs=1e-12)
        checked += 1
    assert checked == len(records) - 1


def test_request_investigation_script_runs_and_finds_few_requests_with_exact_motion():
    """scripts/investigate_corridor_requests.py (the issue-12 investigation) stays runnable; it
    asserts at every request that the logged distance is its hand computation. With exact
    motion every circuit repeats, so the confident phase asks at most a few times."""
    module = _investigation_script()
    run = module.run_one("exact", 0)
    summary = module.summarise([run])
    assert len(run["requests"]) <= 3 and run["teleoperated"] >= 30
    assert run["finished"] and run["eval_clean"] == 10
    assert summary["demonstrations"][0] == run["demonstrations"] <= 45
    assert 0.0 <= summary["fresh_request_free_share"] <= 1.0


def test_plot_results_redraws_a_run_on_a_map_whose_circuit_is_longer_than_81_actions(tmp_path):
    """A run on a map whose circuit takes 96 actions needs the baseline's episode_steps above
    them (CorridorExperimentConfig refuses the default 81 there): plot_results rebuilt the
    run's config from the fields the figures read, without ps, and so refused the run it was
    redrawing ("ps.episode_steps=81 is less than the about 96 actions ..."). It now keeps the
    run's episode_steps and redraws."""
    import json

    from corridor.baseline import PrioritizedSweepingConfig
    from corridor.experiment import plot_results, run_experiment
    from torchcbl import TeachingConfig

    big = {
        "name": "big",
        "corridor_width": 0.6,
        "nodes": {"A": [0, 0], "B": [6.0, 0], "C": [6.0, 4.0], "D": [0, 4.0]},
        "corridors": [["A", "B"], ["B", "C"], ["C", "D"], ["D", "A"]],
        "route": ["A", "B", "C", "D", "A"],
    }
    (tmp_path / "big.json").write_text(json.dumps(big))
    cfg = _tiny_experiment(
        map_name=str(tmp_path / "big.json"),
        ps=PrioritizedSweepingConfig(max_steps=50, episode_steps=192),
        teaching=TeachingConfig(accuracy_window=20, autonomous_episodes_to_stop=1, max_steps=200),
        eval_circuits=1,
    )
    run_experiment(cfg, tmp_path / "run", workers=1, progress=False)
    (tmp_path / "run" / "map.png").unlink()
    results = json.loads((tmp_path / "run" / "results.json").read_text())
    assert tmp_path / "run" / "map.png" in plot_results(results, tmp_path / "run")
    assert (tmp_path / "run" / "map.png").stat().st_size > 1000


def test_plot_results_redraws_a_run_whose_sensors_reach_less_than_the_default_threshold(tmp_path):
    """A robot whose sensors reach 0.5 m runs the baseline with a wall threshold below it
    (the config refuses the default 0.6 m there): plot_results rebuilt the run's config without
    the run's threshold and so refused the run it was redrawing ("ps.wall_threshold (0.6 m)
    must be less than ... world.max_range (0.5 m)"). It now keeps the run's threshold."""
    import json

    from corridor.baseline import PrioritizedSweepingConfig
    from corridor.experiment import plot_results, run_experiment

    cfg = _tiny_experiment(
        world=WorldConfig(max_range=0.5),
        ps=PrioritizedSweepingConfig(max_steps=50, wall_threshold=0.4),
        eval_circuits=1,
    )
    run_experiment(cfg, tmp_path, workers=1, progress=False)
    (tmp_path / "figure3.png").unlink()
    results = json.loads((tmp_path / "results.json").read_text())
    assert tmp_path / "figure3.png" in plot_results(results, tmp_path)
    assert (tmp_path / "figure3.png").stat().st_size > 1000


_KILLS_A_SEED_WORKER = """
import threading
from _scripts import kill_a_worker_when
from test_corridor_noise import _tiny_experiment
from corridor.experiment import run_experiment

if __name__ == "__main__":
    marker = "run/sessions/seed0/config.json"  # a seed is teaching
    threading.Thread(target=kill_a_worker_when, args=(marker,), daemon=True).start()
    run_experiment(_tiny_experiment(seeds=(0, 1)), "run", workers=2, progress=False)
"""


def test_a_seed_worker_killed_by_a_signal_is_named_as_such(tmp_path):
    """A seed's worker killed mid-seed (the out-of-memory killer) broke the process pool, and
    the run ended with concurrent.futures' bare BrokenProcessPool ("A process in the process
    pool was terminated abruptly ..."). It now says a worker died, and what to do."""
    from _scripts import run_script, skip_without_proc_children

    skip_without_proc_children()
    code, err = run_script(tmp_path, _KILLS_A_SEED_WORKER, timeout=120)
    last = err.strip().splitlines()[-1]
    assert code == 1, err
    assert last.startswith("RuntimeError: a worker process was killed by SIGKILL"), err[-2000:]
    assert "while it ran one of the seeds; the run stops without a results.json" in last
    assert not (tmp_path / "run" / "results.json").exists()


def test_plot_results_redraws_a_run_made_with_a_heading_offset_now_refused(tmp_path):
    """Start-heading offsets of pi/4 or more are refused since 2026-11-27 (the expert steers
    by the wrong axis there), but a run made before with one must still redraw: the figures
    do not read eval_perturbation, and plot_results refused it ("results.json lacks what the
    corridor figures need")."""
    import json
    import math

    from corridor.experiment import plot_results, run_experiment

    run_experiment(_tiny_experiment(eval_circuits=1), tmp_path, workers=1, progress=False)
    results = json.loads((tmp_path / "results.json").read_text())
    results["config"]["eval_perturbation"] = [0.1, math.radians(60)]
    (tmp_path / "figure3.png").unlink()
    assert tmp_path / "figure3.png" in plot_results(results, tmp_path)


def test_a_seed_rerun_from_the_stored_config_gives_its_entry_again(tmp_path, monkeypatch):
    """docs/reproduction.md's *Rerunning one seed*: run_seed of a run's stored config gives the
    seed's per_seed entry again, timing aside, plus the four private keys of the figures'
    inputs that results.json does not keep (so `out == per_seed[k]` alone is False)."""
    import json

    import corridor.experiment
    from corridor.baseline import PrioritizedSweepingConfig
    from corridor.experiment import CorridorExperimentConfig, run_experiment, run_seed

    score = corridor.experiment.score_tables  # for time: its ranking over 50 steps, not 1000
    monkeypatch.setattr(
        corridor.experiment, "score_tables", lambda *a, **k: score(*a, steps=50, **k)
    )
    cfg = _tiny_experiment(seeds=(1,), eval_circuits=1, ps=PrioritizedSweepingConfig(max_steps=50))
    cfg = dataclasses.replace(cfg, teaching=dataclasses.replace(cfg.teaching, max_steps=40))
    run_experiment(cfg, tmp_path, workers=1, progress=False)
    results = json.loads((tmp_path / "results.json").read_text())
    out = run_seed(CorridorExperimentConfig.from_dict(results["config"]), 1, None)
    entry = results["per_seed"][results["seeds"].index(1)]
    assert sorted(set(out) - set(entry)) == ["_demo_x", "_demo_y", "_model", "_path"]
    kept = {k: v for k, v in out.items() if not k.startswith("_") and k != "seconds"}
    assert kept == {k: v for k, v in entry.items() if k != "seconds"}
