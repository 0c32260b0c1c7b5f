"""What ConfidentTeacher.resume compares before it goes on, and that a refused resume touches
no file of the session."""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import re
import sqlite3
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch
from _toy_envs import oracle, rare_regions_world
from gymnasium import spaces
from test_session_faults import crash
from test_session_faults import resume as fault_resume
from test_session_faults import session as fault_session

from torchcbl import ConfidentTeacher, GaussianMixtureSet, TeachingConfig
from torchcbl.errors import CorruptSessionError, IncompatibleRunDirError
from torchcbl.session import COMPARE_ON_RESUME, RESUME_AS, load_config, load_records

LINE_ID = "torchcbl_tests/ResumeLine-v0"


class Line(gym.Env):
    """1-D: walk right to the end of a line of ``n`` cells; no step cap of its own."""

    metadata = {"render_modes": ["human"]}

    def __init__(self, n: int = 10, render_mode: str | None = None) -> None:
        self.n = n
        self.render_mode = render_mode
        self.observation_space = spaces.Box(0, n, (1,), np.float32)
        self.action_space = spaces.Discrete(2)
        self.x = 0.0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x = float(self.np_random.integers(0, self.n))
        return np.array([self.x], np.float32), {}

    def step(self, action):
        self.x = max(0.0, self.x + (1 if action == 1 else -1))
        done = self.x >= self.n
        return np.array([self.x], np.float32), float(done), done, False, {}


class Other(gym.Env):
    """Another env of the same sizes (1 feature, 2 actions), other bounds, no cap."""

    def __init__(self, high: float = 5.0) -> None:
        self.observation_space = spaces.Box(-high, high, (1,), np.float32)
        self.action_space = spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(1, np.float32), {}

    def step(self, action):
        return np.zeros(1, np.float32), 0.0, False, False, {}


if LINE_ID not in gym.registry:
    gym.register(LINE_ID, entry_point=Line)  # no time limit of its own


def teacher(obs, info):
    return 1


def _teach(run: Path, env: gym.Env) -> None:
    config = TeachingConfig(max_steps=12, max_new=4)
    with ConfidentTeacher(env, teacher, config=config, run_dir=run, progress=False) as ct:
        ct.run()


def _resumes(run: Path, env: gym.Env) -> None:
    ConfidentTeacher.resume(run, env, teacher, progress=False).close()


def _refused(run: Path, env: gym.Env, *patterns: str) -> str:
    before = _files_of(run)
    with pytest.raises(IncompatibleRunDirError) as err:
        ConfidentTeacher.resume(run, env, teacher, progress=False)
    msg = str(err.value)
    for pattern in patterns:
        assert pattern in msg, msg
    assert _files_of(run) == before  # a refusal touches no file
    return msg


def _files_of(run: Path) -> dict[str, tuple[int, str]]:
    """{relative path: (mtime_ns, sha256)} of every file under a run directory."""
    return {
        str(p.relative_to(run)): (p.stat().st_mtime_ns, hashlib.sha256(p.read_bytes()).hexdigest())
        for p in sorted(run.rglob("*"))
        if p.is_file()
    }


# -- 1. the env: another env is refused, whether made by gymnasium.make or directly ------------


def test_a_session_made_with_an_id_refuses_an_env_made_directly_that_is_not_its_own(tmp_path):
    """A session made with gymnasium.make(id, max_episode_steps=30) resumed with an env of
    another class (other bounds, no cap), made directly: it resumed, as the id, kwargs and cap
    were compared only where both sides had an id. The same env without the cap, made
    directly, resumed too, although gymnasium.make(id) without it was refused."""
    run = tmp_path / "run"
    _teach(run, gym.make(LINE_ID, max_episode_steps=30))
    msg = _refused(run, Other(), "Line", "Other", "Box(0.0, 10.0, (1,), float32)", "Box(-5.0")
    assert msg.startswith(f"cannot resume the session in {run}: ") and "\n" not in msg
    # no cap: not the session's env (a cap of None is written "no cap", not None)
    _refused(run, Line(), "'max_episode_steps': (30, no cap)")
    _refused(run, gym.make(LINE_ID), "max_episode_steps")  # (as before)
    _refused(run, gym.wrappers.TimeLimit(Line(), 31), "max_episode_steps", "31")
    # the session's env made again resumes: by gymnasium.make, wrapped in what leaves its
    # spaces as they are, or the same class with the same cap made directly
    _resumes(run, gym.make(LINE_ID, max_episode_steps=30))
    _resumes(run, gym.make(LINE_ID, max_episode_steps=30, render_mode="human"))
    _resumes(run, gym.wrappers.RecordEpisodeStatistics(gym.make(LINE_ID, max_episode_steps=30)))
    _resumes(run, gym.wrappers.TimeLimit(Line(), 30))
    assert len(load_records(run)) == 12


def test_a_session_made_directly_refuses_another_env(tmp_path):
    """A session whose env was made directly (no gymnasium id) compared the sizes of the
    spaces alone: an env of another class, other bounds or another step cap resumed it."""
    run = tmp_path / "run"
    _teach(run, gym.wrappers.TimeLimit(Line(), 30))
    stored = load_config(run)["env"]
    assert stored["id"] is None and stored["max_episode_steps"] == 30
    assert stored["class"].endswith(".Line")
    _refused(run, Other(), "Line", "Other")
    _refused(run, gym.wrappers.TimeLimit(Other(high=10.0), 30), "Line", "Other")
    _refused(run, Line(), "max_episode_steps", "30")
    _refused(run, gym.wrappers.TimeLimit(Line(), 31), "max_episode_steps")
    # no cap is written so, not None (which reads as an argument left out)
    _refused(run, Line(), "env step cap (max_episode_steps, stored, given): (30, no cap)")
    _refused(run, gym.wrappers.TimeLimit(Line(n=12), 30), "Box(0.0, 12.0")
    _resumes(run, gym.wrappers.TimeLimit(Line(), 30))
    _resumes(run, gym.make(LINE_ID, max_episode_steps=30))  # the same env, made by make
    # the class as a module defines it again (a script's class moved to a package)
    moved = type("Line", (Line,), {})
    moved.__module__ = "pkg.envs"
    _resumes(run, gym.wrappers.TimeLimit(moved(), 30))


def test_a_session_made_with_arguments_refuses_an_env_whose_arguments_cannot_be_read(
    tmp_path,
):
    """gymnasium.make's arguments are compared; an env made directly shows none, so it cannot
    be told from one made with other arguments: refused, saying how to make it."""
    run = tmp_path / "run"
    _teach(run, gym.make(LINE_ID, n=12, max_episode_steps=30))
    _refused(
        run,
        gym.wrappers.TimeLimit(Line(n=12), 30),
        "'n': 12",
        f"gymnasium.make('{LINE_ID}', max_episode_steps=30, n=12)",
    )
    _resumes(run, gym.make(LINE_ID, n=12, max_episode_steps=30))


def test_a_refusal_says_an_argument_one_side_did_not_give_was_not_given(tmp_path):
    """A gymnasium.make argument one side left to the env's default was written None in the
    refusal, ``'n': (None, 12)``, though the session ran with the default (10), not None; it
    says "not given (the env's default)" there. A step cap of None (no cap) was written None
    too, which reads as not given: it says "no cap"."""
    run = tmp_path / "run"
    _teach(run, gym.make(LINE_ID, max_episode_steps=30))
    msg = _refused(run, gym.make(LINE_ID, n=12, max_episode_steps=30), "env kwargs (stored, ")
    assert "'n': (not given (the env's default), 12)" in msg, msg
    assert "None" not in msg, msg
    other = tmp_path / "other"
    _teach(other, gym.make(LINE_ID, n=12, max_episode_steps=30))
    msg = _refused(other, gym.make(LINE_ID, max_episode_steps=30))
    assert "'n': (12, not given (the env's default))" in msg, msg
    msg = _refused(other, gym.make(LINE_ID, n=12, render_mode=None, max_episode_steps=31))
    assert "'max_episode_steps': (30, 31)" in msg, msg  # (render_mode is not compared)
    msg = _refused(run, gym.make(LINE_ID, render_mode="human", max_episode_steps=None))
    assert "'max_episode_steps': (30, no cap)" in msg and "None" not in msg, msg


def test_a_refusal_of_an_env_of_other_sizes_counts_one_feature_as_one(tmp_path):
    """A resume with an env of other sizes said "the session has 1 features" of a one-feature
    session; it says "1 feature"."""

    class Wide(Other):
        def __init__(self) -> None:
            super().__init__()
            self.observation_space = spaces.Box(-5.0, 5.0, (2,), np.float32)

    run = tmp_path / "run"
    _teach(run, gym.make(LINE_ID, max_episode_steps=30))
    _refused(run, Wide(), "the session has 1 feature and 2 actions, the given env 2 and 2")


class Stride(Line):
    """A Line whose step is an argument of its constructor the observation space does not
    show; ``described`` (a class attribute): whether its ``describe_inputs()`` gives it."""

    described = False

    def __init__(self, stride: float = 1.0) -> None:
        super().__init__()
        self.stride = stride

    def describe_inputs(self) -> dict:
        return {"stride": self.stride} if self.described else {}


def test_an_env_made_directly_is_compared_on_what_it_shows_alone(tmp_path):
    """What README's resume table says: of an env made directly, only its class, spaces, step
    cap and describe_inputs() are compared, so one made with another constructor argument of
    the same class, space and cap resumes; given in describe_inputs(), the argument refuses."""
    run = tmp_path / "run"
    _teach(run, gym.wrappers.TimeLimit(Stride(), 30))
    _resumes(run, gym.wrappers.TimeLimit(Stride(stride=3.0), 30))
    described = type("Stride", (Stride,), {"described": True})
    told = tmp_path / "told"
    _teach(told, gym.wrappers.TimeLimit(described(), 30))
    _refused(told, gym.wrappers.TimeLimit(described(stride=3.0), 30), "'stride': (1.0, 3.0)")
    _resumes(told, gym.wrappers.TimeLimit(described(), 30))


def test_the_observation_space_is_compared_whatever_numpy_prints(tmp_path):
    """config.json keeps the observation space as gymnasium writes it, which numpy's print
    options change (a notebook's np.set_printoptions): the same env resumes under others."""
    run = tmp_path / "run"
    bounds = dict(low=np.array([0.0, -2.5], np.float32), high=np.array([1 / 3, 2.5], np.float32))

    class Plane(Line):
        def __init__(self) -> None:
            super().__init__()
            self.observation_space = spaces.Box(**bounds, dtype=np.float32)

        def reset(self, *, seed=None, options=None):
            return np.zeros(2, np.float32), {}

        def step(self, action):
            return np.zeros(2, np.float32), 0.0, False, False, {}

    _teach(run, Plane())
    with np.printoptions(precision=2):
        _resumes(run, Plane())
    with np.printoptions(precision=2):
        _teach(tmp_path / "run2", Plane())
    _resumes(tmp_path / "run2", Plane())
    assert (
        load_config(run)["env"]["observation_space"]
        == load_config(tmp_path / "run2")["env"]["observation_space"]
    )


def test_a_session_stored_before_the_class_and_cap_were_kept_compares_what_it_kept(tmp_path):
    """Sessions made directly kept neither the env's class nor its step cap: they still resume
    with an env of the same spaces, whatever its class and cap; the observation space, kept
    since the first version, is compared."""
    run = tmp_path / "run"
    _teach(run, Other(high=10.0))
    config = json.loads((run / "config.json").read_text())
    del config["env"]["class"], config["env"]["max_episode_steps"]
    (run / "config.json").write_text(json.dumps(config))
    _resumes(run, gym.wrappers.TimeLimit(Other(high=10.0), 30))
    _refused(run, Other(), "Box(-10.0")


# -- 1b. gymnasium.make's arguments given as objects (frozen dataclasses) ---------------------


@dataclasses.dataclass(frozen=True)
class Start:
    """Where a Walk starts: a nested frozen dataclass, as DrivingConfig holds a SimConfig."""

    cell: int = 0


@dataclasses.dataclass(frozen=True)
class Course:
    """A Walk's settings, a frozen dataclass as a domain's are (a TrafficScenario say)."""

    start: Start = Start()
    slip: float = 0.0
    # what changes nothing the env does (a CorridorMap's name): not compared on resume
    label: str = dataclasses.field(default="", metadata={COMPARE_ON_RESUME: False})


class Walk(Line):
    """Line, made with a Course: its start cell (spaces and cap do not depend on it)."""

    def __init__(self, course: Course = Course(), render_mode: str | None = None) -> None:
        super().__init__(render_mode=render_mode)
        self.course = course

    def reset(self, *, seed=None, options=None):
        gym.Env.reset(self, seed=seed)
        self.x = float(self.course.start.cell)
        return np.array([self.x], np.float32), {}


WALK_ID = "torchcbl_tests/ResumeWalk-v0"
if WALK_ID not in gym.registry:
    gym.register(WALK_ID, entry_point=Walk)


def test_a_session_made_with_an_object_argument_refuses_another_object(tmp_path):
    """An argument gymnasium.make was given as an object was kept only as its repr, which
    resume did not compare: a session resumed on other settings (a driving session on another
    TrafficScenario) without a word. Where both the session (env.kwargs_objects) and the
    given env keep it whole, the two are compared: a difference is refused in one line naming
    the argument, the field and both values, touching no file."""
    run = tmp_path / "run"
    course = Course(Start(3), slip=0.25)
    _teach(run, gym.make(WALK_ID, course=course))
    assert load_config(run)["env"]["kwargs_objects"]["course"]["fields"]["slip"] == 0.25
    msg = _refused(
        run,
        gym.make(WALK_ID, course=Course(Start(4), slip=0.25)),
        "course",
        "start.cell",
        "(3, 4)",
        "Course(start=Start(cell=3)",  # both values, as text
        "Course(start=Start(cell=4)",
    )
    assert "\n" not in msg and "start a new session" in msg
    _refused(run, gym.make(WALK_ID, course=Course(Start(3), slip=0.5)), "slip", "(0.25, 0.5)")
    # the same settings resume: an equal object, one differing only where its class says a
    # field changes nothing, and one of the class as another module defines it
    _resumes(run, gym.make(WALK_ID, course=Course(Start(3), slip=0.25)))
    _resumes(run, gym.make(WALK_ID, course=Course(Start(3), slip=0.25, label="mine")))
    # a class moved to another module since (compared by name, as the env's class is)
    config = json.loads((run / "config.json").read_text())
    config["env"]["kwargs_objects"]["course"]["class"] = "pkg.settings:Course"
    (run / "config.json").write_text(json.dumps(config))
    _resumes(run, gym.make(WALK_ID, course=course))
    assert len(load_records(run)) == 12


def test_the_domains_mark_their_names_not_compared_with_torchcbls_key():
    """corridor.maps and sumo_scenarios.scenarios spell COMPARE_ON_RESUME as a literal (taking
    it from torchcbl.session would import torch with them): a literal that drifted from the
    constant would make a map's or a scenario's name compared on resume again, unnoticed.
    sumo_scenarios.env spells RESUME_AS alike, for DrivingConfig's scenario (a name or the
    TrafficScenario)."""
    from corridor.maps import CorridorMap
    from sumo_scenarios.env import DrivingConfig
    from sumo_scenarios.scenarios import TrafficScenario, get_scenario

    for cls, expected in ((CorridorMap, {"name", "description"}), (TrafficScenario, {"name"})):
        fields = dataclasses.fields(cls)
        marked = {f.name for f in fields if f.metadata.get(COMPARE_ON_RESUME) is False}
        assert marked == expected, cls
        assert all(set(f.metadata) <= {COMPARE_ON_RESUME} for f in fields), cls
    spelt = {f.name: dict(f.metadata) for f in dataclasses.fields(DrivingConfig) if f.metadata}
    assert spelt == {"scenario": {RESUME_AS: get_scenario}}


def test_an_object_argument_kept_only_as_text_on_one_side_resumes_as_before(tmp_path):
    """A session written before env.kwargs_objects existed (or a given object that cannot be
    kept whole) keeps today's comparison: an argument kept only as text is not compared, so
    such a session resumes as it did."""
    run = tmp_path / "run"
    _teach(run, gym.make(WALK_ID, course=Course(Start(3))))
    config = json.loads((run / "config.json").read_text())
    del config["env"]["kwargs_objects"]  # as written before 2026-11-27
    (run / "config.json").write_text(json.dumps(config))
    _resumes(run, gym.make(WALK_ID, course=Course(Start(4))))
    # a given object that cannot be kept whole (a list where a tuple is kept) resumes too
    run2 = tmp_path / "run2"
    _teach(run2, gym.make(WALK_ID, course=Course(Start(3))))
    _resumes(run2, gym.make(WALK_ID, course=Course(Start([3]))))


@dataclasses.dataclass(frozen=True)
class Settings:
    """A frozen dataclass of one field, holding whatever a test gives it."""

    value: Any = None


class Anything(Line):
    """Line, made with Settings it does not read."""

    def __init__(self, settings: Settings = Settings(), render_mode: str | None = None) -> None:
        super().__init__(render_mode=render_mode)
        self.settings = settings


ANYTHING_ID = "torchcbl_tests/ResumeAnything-v0"
if ANYTHING_ID not in gym.registry:
    gym.register(ANYTHING_ID, entry_point=Anything)


_STARTS = {"home": Start(0), "far": Start(5)}


def _start_named(value: Any) -> Start:
    """A Start, or the one a name spells."""
    return value if isinstance(value, Start) else _STARTS[value]


@dataclasses.dataclass(frozen=True)
class Trail:
    """Settings whose start is a Start or its name, as DrivingConfig's scenario is."""

    start: Any = dataclasses.field(default="home", metadata={RESUME_AS: _start_named})


def test_a_field_taking_a_name_or_its_object_resumes_either_spelling(tmp_path):
    """A field whose class gives it a RESUME_AS function (DrivingConfig's scenario: a name or
    the TrafficScenario) was compared as kept, the name against the object's fields: a
    session was refused the same settings spelled the other way. A plain value against an
    object is compared as the object it spells: the same resumes, another is refused naming
    the fields that differ; a name the function refuses, and a name against a name, are
    compared as they are."""
    home = tmp_path / "home"
    _teach(home, gym.make(ANYTHING_ID, settings=Trail("home")))
    _resumes(home, gym.make(ANYTHING_ID, settings=Trail(Start(0))))
    _refused(home, gym.make(ANYTHING_ID, settings=Trail(Start(5))), "'settings.start.cell': (0, 5)")
    _refused(
        home, gym.make(ANYTHING_ID, settings=Trail("far")), "'settings.start': ('home', 'far')"
    )
    far = tmp_path / "far"
    _teach(far, gym.make(ANYTHING_ID, settings=Trail(Start(5))))
    _resumes(far, gym.make(ANYTHING_ID, settings=Trail("far")))
    _refused(far, gym.make(ANYTHING_ID, settings=Trail("home")), "'settings.start.cell': (5, 0)")
    _refused(far, gym.make(ANYTHING_ID, settings=Trail("nowhere")), "'settings.start': ('{")
    assert len(load_records(home)) == len(load_records(far)) == 12


def _kept_whole(run: Path, value: Any) -> dict[str, Any]:
    """config.json's env.kwargs_objects of a new session of Anything(Settings(value))."""
    env = gym.make(ANYTHING_ID, settings=Settings(value))
    ConfidentTeacher(env, teacher, run_dir=run, progress=False).close()
    return load_config(run)["env"].get("kwargs_objects", {})


def test_an_object_argument_is_kept_whole_up_to_its_bound_of_values(tmp_path):
    """An object is kept whole up to _KEPT_VALUES values in all (the object, its field, each
    number of its tuple: a tuple of _KEPT_VALUES - 2 numbers); one value more and it is kept
    as text alone."""
    from torchcbl.session import _KEPT_VALUES

    most = tuple(range(_KEPT_VALUES - 2))
    kept = _kept_whole(tmp_path / "most", most)
    assert kept["settings"]["fields"]["value"] == list(most)
    assert _kept_whole(tmp_path / "past", (*most, 0)) == {}


def test_an_object_argument_holding_what_json_reads_back_otherwise_is_not_kept(tmp_path):
    """A field JSON would give back as another value is not kept whole (the object is kept as
    text alone): a StrEnum member (a str subclass, read back as the plain str) and a number
    that is not finite (JSON has no inf or nan)."""
    import enum

    class Mode(enum.StrEnum):
        FAST = "fast"

    for name, value in [
        ("enum", Mode.FAST),
        ("inf", math.inf),
        ("-inf", -math.inf),
        ("nan", math.nan),
    ]:
        assert _kept_whole(tmp_path / name, value) == {}, name
    assert _kept_whole(tmp_path / "str", "fast")["settings"]["fields"] == {"value": "fast"}
    assert _kept_whole(tmp_path / "float", 1e308)["settings"]["fields"] == {"value": 1e308}


def test_an_object_argument_is_compared_field_by_field_as_the_rule_says(tmp_path):
    """True and 1 are not the same field (1 and 1.0 are), and a dict field with a key more or
    less is another field: each is refused, naming the field and both values."""
    run = tmp_path / "one"
    _teach(run, gym.make(ANYTHING_ID, settings=Settings(1)))
    _refused(run, gym.make(ANYTHING_ID, settings=Settings(True)), "'settings.value': (1, True)")
    _resumes(run, gym.make(ANYTHING_ID, settings=Settings(1.0)))
    run = tmp_path / "dict"
    _teach(run, gym.make(ANYTHING_ID, settings=Settings({"a": 1})))
    extra = Settings({"a": 1, "b": 2})
    _refused(run, gym.make(ANYTHING_ID, settings=extra), "'settings.value.b': ('(absent)', 2)")
    _refused(
        run, gym.make(ANYTHING_ID, settings=Settings({})), "'settings.value.a': (1, '(absent)')"
    )
    _resumes(run, gym.make(ANYTHING_ID, settings=Settings({"a": 1.0})))


# -- 1c. the driving domain's traffic: a name or the TrafficScenario -------------------------


@contextlib.contextmanager
def _driving(**kwargs: Any):
    """gymnasium.make of the driving env (a few SUMO steps a session), closed after."""
    import sumo_scenarios

    env = gym.make(sumo_scenarios.ENV_ID, **kwargs)
    try:
        yield env
    finally:
        env.close()


def test_a_refusal_of_other_arguments_and_inputs_says_once_how_to_make_the_env(tmp_path):
    """Traffic taught by name and resumed by another name differs in its argument and in the
    env's description of its inputs: the refusal names both, and says how to make the
    session's env once (not once for each)."""
    run = tmp_path / "run"
    with _driving(scenario="train") as env:
        _teach(run, env)
    with _driving(scenario="light") as env:
        msg = _refused(run, env, "'scenario': ('train', 'light')", "env inputs (stored, given)")
    assert msg.count("gymnasium.make(") == 1, msg


def test_driving_traffic_kept_as_an_object_resumes_by_the_name_of_the_same_traffic(tmp_path):
    """DrivingConfig's scenario kept as a TrafficScenario of its own name ("mine") and given
    as the name of the same traffic ("light"): the name spells the shipped object, whose
    name is not compared (TrafficScenario marks it so), so the session resumes."""
    from sumo_scenarios.env import DrivingConfig
    from sumo_scenarios.scenarios import LIGHT

    run = tmp_path / "run"
    mine = DrivingConfig(scenario=dataclasses.replace(LIGHT, name="mine"))
    with _driving(config=mine) as env:
        _teach(run, env)
    with _driving(config=DrivingConfig(scenario="light")) as env:
        _resumes(run, env)
    assert len(load_records(run)) == 12


def test_a_kept_traffic_name_this_version_does_not_ship_is_refused_in_one_line(tmp_path):
    """A DrivingConfig session whose kept scenario name is none this version ships (edited
    in config.json, or a scenario since dropped), resumed with the traffic given as an
    object: the name cannot spell an object and is compared as it is, so the resume is
    refused naming config.scenario, in one line, not with get_scenario's ValueError."""
    from sumo_scenarios.env import DrivingConfig
    from sumo_scenarios.scenarios import LIGHT

    run = tmp_path / "run"
    with _driving(config=DrivingConfig(scenario="light")) as env:
        _teach(run, env)
    config = json.loads((run / "config.json").read_text())
    config["env"]["kwargs_objects"]["config"]["fields"]["scenario"] = "nowhere"
    (run / "config.json").write_text(json.dumps(config))
    with _driving(config=DrivingConfig(scenario=LIGHT)) as env:
        msg = _refused(run, env, "'config.scenario': ('nowhere', ")
    assert "\n" not in msg, msg


# -- 1d. how a refusal says to make the session's env ----------------------------------------

CAPPED_ID = "torchcbl_tests/ResumeWalkCapped-v0"
if CAPPED_ID not in gym.registry:
    gym.register(CAPPED_ID, entry_point=Walk, max_episode_steps=50)


def _compiles(text: str) -> bool:
    try:
        compile(text, "<advice>", "eval")
    except SyntaxError:
        return False
    return True


def _advised(msg: str, **names: Any) -> gym.Env:
    """The env a refusal's advice makes: its ``gymnasium.make(...)`` call, run as Python after
    the imports the advice names (``from M import C, D``), with ``names`` (run_dir) in scope."""
    start = msg.index("gymnasium.make(")
    ends = [k + 1 for k in range(start, len(msg)) if msg[k] == ")"]
    call = next(msg[start:end] for end in ends if _compiles(msg[start:end]))
    scope: dict[str, Any] = {"gymnasium": gym, **names}
    for module, classes in re.findall(r"from ([\w.]+) import (\w+(?:, \w+)*)", msg):
        exec(f"from {module} import {classes}", scope)
    return eval(call, scope)


def test_a_refusal_writes_the_sessions_objects_as_a_call_one_can_run(tmp_path):
    """A refusal ended "gymnasium.make('id', max_episode_steps=-1, **{'course': {'repr':
    'Course(...'}}) with each object as its config.json keeps it in env.kwargs_objects": the
    object as a text cut at 200 characters, not a call one can run. An object the session
    keeps whole is now written as its constructor call from the kept fields (nested objects
    alike), with the import of each class once; that call makes an env the session resumes
    with."""
    run = tmp_path / "run"
    course = Course(Start(3), slip=0.25, label="mine")
    _teach(run, gym.make(WALK_ID, course=course, render_mode="human"))
    msg = _refused(run, gym.make(WALK_ID, course=Course(Start(4))), "start.cell")
    assert "\n" not in msg and "'repr'" not in msg and "kwargs_objects" not in msg, msg
    assert "from test_resume_checks import Course, Start" in msg, msg
    assert "course=Course(" in msg and "start=Start(cell=3)" in msg, msg
    assert "render_mode='human'" in msg, msg
    # neither the session nor the id has a step cap: none is given
    assert "max_episode_steps" not in msg[msg.index("gymnasium.make(") :], msg
    env = _advised(msg)
    assert env.spec.kwargs == {"course": course, "render_mode": "human"}
    _resumes(run, env)


def test_a_refusal_names_a_class_made_in_a_function_as_one_can_write_it(tmp_path):
    """A settings class defined inside a function (a test, a notebook cell's helper) was
    written as "f.<locals>.Cfg(...)" with "from M import f": advice that is a SyntaxError.
    It is now written by its own name, with a note that it must be in scope; with that class
    in scope, the call makes an env the session resumes with."""

    def settings():
        @dataclasses.dataclass(frozen=True)
        class MyCourse:
            start: Start = Start(3)

        return MyCourse

    mine = settings()
    run = tmp_path / "run"
    _teach(run, gym.make(WALK_ID, course=mine(Start(3))))
    msg = _refused(run, gym.make(WALK_ID, course=mine(Start(4))), "start.cell")
    call = msg[msg.index("gymnasium.make(") :]
    assert "<locals>" not in call[: call.index("))") + 2], msg
    assert "course=MyCourse(start=Start(cell=3))" in msg and "in scope" in msg, msg
    _resumes(run, _advised(msg, MyCourse=mine))


def test_a_refusal_gives_the_step_cap_as_gymnasium_make_takes_it(tmp_path, monkeypatch):
    """A session without a step cap was advised max_episode_steps=-1 whatever its id: needless
    for an id that registers no cap (torchcbl/Driving-v0), and before gymnasium 1.0 a
    TimeLimit of -1 steps (every step truncated). -1 is now given only where the id registers
    a cap, saying it needs gymnasium 1.0 where the one installed is older; a cap is given as
    it was."""
    run = tmp_path / "run"
    _teach(run, gym.make(CAPPED_ID, course=Course(Start(3)), max_episode_steps=-1))
    assert load_config(run)["env"]["max_episode_steps"] is None
    other = gym.make(CAPPED_ID, course=Course(Start(4)))
    msg = _refused(run, other, "start.cell", "'max_episode_steps': (no cap, 50)")
    assert f"gymnasium.make('{CAPPED_ID}', max_episode_steps=-1, course=" in msg, msg
    assert "gymnasium 1.0" not in msg, msg
    _resumes(run, _advised(msg))
    monkeypatch.setattr(gym, "__version__", "0.29.1")
    msg = _refused(run, other, "max_episode_steps=-1")
    assert "gymnasium 1.0" in msg and "0.29.1" in msg, msg
    monkeypatch.undo()
    capped = tmp_path / "capped"
    _teach(capped, gym.make(CAPPED_ID, course=Course(Start(3)), max_episode_steps=20))
    msg = _refused(capped, other, f"gymnasium.make('{CAPPED_ID}', max_episode_steps=20, course=")
    _resumes(capped, _advised(msg))


def test_a_refusal_names_the_call_that_makes_an_object_too_long_to_print(tmp_path):
    """An object of thousands of values is not written out in a one-line refusal: the advice
    says it is too long to print and gives the env_make_argument call that makes it from the
    session's config, which makes an env the session resumes with."""
    many = tuple(range(5000))
    run = tmp_path / "run"
    _teach(run, gym.make(ANYTHING_ID, settings=Settings(many)))
    given = gym.make(ANYTHING_ID, settings=Settings((*many[:-1], 0)))
    msg = _refused(run, given, "'settings.value[4999]': (4999, 0)", "too long to print")
    assert len(msg) < 3000 and "\n" not in msg, msg
    assert "from torchcbl.session import env_make_argument, load_config" in msg, msg
    env = _advised(msg, run_dir=run)
    assert env.spec.kwargs["settings"] == Settings(many)
    _resumes(run, env)


def test_a_driving_refusal_says_how_to_make_the_env_on_the_sessions_own_traffic(tmp_path):
    """A session taught on traffic of one's own (gymnasium.make(Driving-v0, scenario=
    TrafficScenario(...))) resumed on other traffic was advised gymnasium.make(...,
    max_episode_steps=-1, **{'scenario': {'repr': "TrafficScenario(...start_clear"}}): the
    scenario is now written out whole, and the call resumes the session."""
    from sumo_scenarios.scenarios import TrafficScenario

    rush = TrafficScenario(name="rushhour", seed=11, mean_spacing_m=(50, 40, 120))
    run = tmp_path / "run"
    with _driving(scenario=rush) as env:
        _teach(run, env)
    with _driving(scenario=dataclasses.replace(rush, seed=12)) as env:
        msg = _refused(run, env, "'scenario.seed': (11, 12)")
    advice = msg[msg.index("gymnasium.make(") :]
    assert "from sumo_scenarios.scenarios import TrafficScenario" in msg, msg
    assert "start_clear_m=30.0" in advice and "max_episode_steps" not in advice, msg
    env = _advised(msg)
    try:
        assert env.spec.kwargs == {"scenario": rush}
        _resumes(run, env)
    finally:
        env.close()


# -- 2. a refused resume touches no file ------------------------------------------------------


def _fitted_session(run: Path, **cfg) -> None:
    """A session started from a fitted model (its checkpoint 0), taught 30 steps."""
    env = rare_regions_world()
    x, y = env.sample(120, np.random.default_rng(0))
    fitted = GaussianMixtureSet(3, 2, seed=0).fit(x, y)
    config = TeachingConfig(noninteractive=False, **cfg)
    with ConfidentTeacher(
        env, oracle(env), model=fitted, config=config, run_dir=run, progress=False
    ) as ct:
        ct.run(max_steps=30)


def _refused_untouched(run: Path, error: type[Exception], match: str) -> None:
    before = _files_of(run)
    env = rare_regions_world()
    with pytest.raises(error, match=match):
        ConfidentTeacher.resume(run, env, oracle(env), progress=False)
    assert _files_of(run) == before


def test_a_resume_refused_for_a_lost_starting_model_touches_no_file(tmp_path):
    """The starting model's checkpoint 0 lost while the session still stands on it: resume
    was refused only after it had opened the session, noting a writer in writers.jsonl and
    rewriting writer.lock and the journal."""
    run = tmp_path / "run"
    _fitted_session(run, max_new=50)
    (run / "checkpoints" / "model-00000000.pt").unlink()
    _refused_untouched(run, CorruptSessionError, "no refit came since")


def test_a_resume_refused_for_a_lost_starting_model_sets_no_checkpoint_aside(tmp_path):
    """Incremental refits start from the starting model: with checkpoint 0 lost and the later
    ones damaged, resume renamed the damaged ones to .damaged, then refused."""
    run = tmp_path / "run"
    _fitted_session(run, max_new=4, refit="incremental")
    zero, *later = sorted((run / "checkpoints").glob("model-*.pt"))
    assert later
    zero.unlink()
    for path in later:
        path.write_bytes(b"not a checkpoint")
    _refused_untouched(run, CorruptSessionError, "incremental refits start from it")


def test_a_resume_refitting_past_damaged_checkpoints_keeps_the_starting_model_as_it_is(tmp_path):
    """Full refits since the fitted start: with every checkpoint damaged the model is refitted
    from the log, each damaged checkpoint set aside as .damaged, but checkpoint 0, the one
    copy of the model the session started from, is left as it is, where it is."""
    run = tmp_path / "run"
    _fitted_session(run, max_new=4)
    zero, *later = sorted((run / "checkpoints").glob("model-*.pt"))
    assert zero.name == "model-00000000.pt" and later
    for path in (zero, *later):
        path.write_bytes(b"not a checkpoint")
    env = rare_regions_world()
    ConfidentTeacher.resume(run, env, oracle(env), progress=False).close()
    assert zero.read_bytes() == b"not a checkpoint"
    assert not zero.with_name(zero.name + ".damaged").exists()
    for path in later:
        assert path.with_name(path.name + ".damaged").read_bytes() == b"not a checkpoint"


def test_a_resume_refused_for_a_damaged_step_touches_no_file(tmp_path):
    """A logged step that cannot be read was refused after the session had been opened for
    writing (writer.lock and the journal rewritten)."""
    run = tmp_path / "run"
    _teach(run, gym.make(LINE_ID, max_episode_steps=30))
    with contextlib.closing(sqlite3.connect(run / "steps.sqlite")) as db:
        db.execute("UPDATE steps SET observation = ? WHERE step = 3", (b"abc",))
        db.commit()
    before = _files_of(run)
    with pytest.raises(CorruptSessionError, match="the logged step 3 is not a valid step"):
        ConfidentTeacher.resume(run, gym.make(LINE_ID, max_episode_steps=30), teacher)
    assert _files_of(run) == before


# -- 3. sessions stored before the class was kept, under a program's numpy print options -------


def _as_old_session(run: Path, space_text: str) -> None:
    """Rewrite config.json as a session stored before the env's class was kept would be, its
    observation space as gymnasium printed it then."""
    config = json.loads((run / "config.json").read_text())
    config["env"].pop("class", None)
    config["env"]["observation_space"] = space_text
    (run / "config.json").write_text(json.dumps(config))


def _cartpole_space_text(scale: float = 1.0, **options) -> str:
    """CartPole's observation space (its bounds times ``scale``) as gymnasium printed it
    under numpy's print ``options`` (its repr follows the options in force when built)."""
    space = gym.make("CartPole-v1").observation_space
    with np.printoptions(**options):
        return repr(spaces.Box(space.low * scale, space.high * scale, dtype=space.dtype))


@pytest.mark.parametrize(
    "options",
    [dict(precision=3, suppress=True), dict(precision=1), dict(precision=5, floatmode="fixed")],
)
def test_an_old_session_resumes_whatever_numpy_printed_its_space_with(tmp_path, options):
    """A session stored before the env's class was kept holds its observation space as
    gymnasium printed it under the writer's numpy print options: one written after
    np.set_printoptions(precision=3, suppress=True) (Box([-4.8 -inf -0.419 -inf], ...)) was
    refused, as neither the default nor the current options print it so."""
    run = tmp_path / "run"
    _teach(run, gym.make("CartPole-v1"))
    _as_old_session(run, _cartpole_space_text(**options))
    _resumes(run, gym.make("CartPole-v1"))


def test_an_old_session_refuses_another_space_whatever_numpy_printed_it_with(tmp_path):
    """Another space (other bounds, shape or dtype) is still refused, printed as it was."""
    run = tmp_path / "run"
    _teach(run, gym.make("CartPole-v1"))
    _as_old_session(run, _cartpole_space_text(scale=2.0, precision=3, suppress=True))
    _refused(run, gym.make("CartPole-v1"), "-0.838")
    _as_old_session(run, _cartpole_space_text(precision=3).replace("float32", "float64"))
    _refused(run, gym.make("CartPole-v1"), "float64")


def test_an_old_session_whose_space_cannot_be_read_resumes_as_it_did(tmp_path):
    """An observation space text that cannot be read back as a Box (a Dict of Boxes, printed
    under other options) was not compared before the class was kept: it resumes."""
    run = tmp_path / "run"
    _teach(run, gym.make("CartPole-v1"))
    _as_old_session(run, "Dict('x': " + _cartpole_space_text(precision=2) + ")")
    _resumes(run, gym.make("CartPole-v1"))


class _LoggedGMM(GaussianMixtureSet):
    """A model holding what cannot be copied (a lock, as a logger or a writer's handle)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.log_lock = threading.Lock()


def _session_started_fitted(run: Path, model_class: type, **cfg: Any) -> GaussianMixtureSet:
    """A session of 30 steps started from a ``model_class(3, 2, seed=0)`` fitted on 120
    labelled points of the toy world (checkpoint 0 holds it), with the TeachingConfig fields
    ``cfg``; returns that model."""
    env = rare_regions_world()
    fitted = model_class(3, 2, seed=0)
    fitted.fit(*env.sample(120, np.random.default_rng(0)))
    config = TeachingConfig(noninteractive=False, **cfg)
    with ConfidentTeacher(
        env, oracle(env), model=fitted, config=config, run_dir=run, progress=False
    ) as ct:
        ct.run(max_steps=30)
    return fitted


def test_a_model_that_cannot_be_copied_resumes_its_fitted_session(tmp_path):
    """Resume tried the starting model's checkpoint on a deep copy of the given model, so one
    holding a lock failed with TypeError: cannot pickle '_thread.lock' object."""
    run = tmp_path / "run"
    env = rare_regions_world()
    fitted = _session_started_fitted(run, _LoggedGMM)
    model = _LoggedGMM(3, 2, seed=0)
    ConfidentTeacher.resume(run, env, oracle(env), model=model, progress=False).close()
    assert model.is_fitted
    assert torch.equal(model.means_, fitted.means_)


def test_a_model_that_cannot_be_copied_is_refused_a_lost_start_before_a_file_is_touched(
    tmp_path,
):
    """A session started from a fitted model whose checkpoint 0 reads but does not load into
    the model (a key missing): resume tried it on a deep copy of the given model, and of one
    that cannot be copied (a lock) not at all, so the refusal came only after the session was
    opened, writers.jsonl, writer.lock and the journal touched. It now comes before, and the
    given model is left as it was."""
    run = tmp_path / "run"
    env = rare_regions_world()
    _session_started_fitted(run, _LoggedGMM, max_new=50)  # no refit: it stands on checkpoint 0
    zero = run / "checkpoints" / "model-00000000.pt"
    payload = torch.load(zero, weights_only=True)
    del payload["state_dict"]["means_"]
    torch.save(payload, zero)
    before = _files_of(run)
    model = _LoggedGMM(3, 2, seed=0)
    state = {k: v.clone() for k, v in model.state_dict().items()}
    with pytest.raises(CorruptSessionError, match="unreadable as this model's state"):
        ConfidentTeacher.resume(run, env, oracle(env), model=model, progress=False)
    assert _files_of(run) == before
    assert not model.is_fitted
    assert all(torch.equal(v, state[k]) for k, v in model.state_dict().items())


class _MadeWithArgumentsGMM(_LoggedGMM):
    """An uncopyable model whose class cannot be made without its arguments (its __new__
    takes them): neither a deep copy nor a shadow of it can be made."""

    def __new__(cls, n_components: int, *args: Any, **kwargs: Any) -> _MadeWithArgumentsGMM:
        return super().__new__(cls)


def test_a_model_whose_class_needs_its_arguments_to_be_made_resumes_its_session(tmp_path):
    """Resume tries checkpoint 0 on a shadow of a model that cannot be copied, made by its
    class's __new__ without arguments: of a class whose __new__ needs them, there is no
    shadow, and restore_model's own load decides (the session resumes)."""
    run = tmp_path / "run"
    env = rare_regions_world()
    fitted = _session_started_fitted(run, _MadeWithArgumentsGMM, max_new=50)
    model = _MadeWithArgumentsGMM(3, 2, seed=0)
    ConfidentTeacher.resume(run, env, oracle(env), model=model, progress=False).close()
    assert torch.equal(model.means_, fitted.means_)


class _SlottedGMM(_LoggedGMM):
    """An uncopyable model keeping state in a slot that its own load reads."""

    __slots__ = ("extra",)

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.extra = 1

    def _load_from_state_dict(self, *args, **kwargs) -> None:
        assert self.extra == 1
        super()._load_from_state_dict(*args, **kwargs)


class _SlotSizedGMM(_LoggedGMM):
    """An uncopyable model of the library's own load path, keeping in a slot a size that
    load reads (GaussianMixtureSet's load compares the state's sizes with its own)."""

    __slots__ = ("n_actions",)


def test_an_uncopyable_model_whose_own_load_reads_a_slot_resumes_its_healthy_session(tmp_path):
    """The trial load of checkpoint 0 on a shadow of the model (made without its constructor,
    its __dict__ shared) failed where the model's own load reads what the shadow lacks (a
    slot): a healthy session was refused as corrupt. A model of a class whose load path is
    not the library's own is left to restore_model's own load, and so is one of the
    library's load path with a slot."""
    env = rare_regions_world()
    for model_class in (_SlottedGMM, _SlotSizedGMM):
        run = tmp_path / model_class.__name__
        fitted = _session_started_fitted(run, model_class, max_new=50)
        model = model_class(3, 2, seed=0)
        ConfidentTeacher.resume(run, env, oracle(env), model=model, progress=False).close()
        assert torch.equal(model.means_, fitted.means_)


class _CountingGMM(GaussianMixtureSet):
    """A model counting the loads into itself with a load hook that holds the model."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.loads = 0
        self._register_load_state_dict_pre_hook(_count_load, with_module=True)


class _LockedCountingGMM(_CountingGMM):
    """The same, holding what cannot be copied."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.log_lock = threading.Lock()


def _count_load(module, *args, **kwargs) -> None:
    module.loads += 1


class _PostCountingGMM(GaussianMixtureSet):
    """A model counting the loads into itself with a load post-hook, its own bound method."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.loads = 0
        self.register_load_state_dict_post_hook(self._loaded)

    def _loaded(self, module, incompatible_keys) -> None:
        self.loads += 1


class _LockedPostCountingGMM(_PostCountingGMM):
    """The same, holding what cannot be copied."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.log_lock = threading.Lock()


def test_a_trial_load_never_runs_a_load_hook_on_the_given_model(tmp_path):
    """A load hook registered with ``with_module=True`` holds the given model; the trial load
    on a shadow of a model that cannot be copied ran it on the given model, which so counted
    one load more than the same model that can be copied (whose trial runs on a copy). So too
    a load post-hook that is the model's own bound method."""
    env = rare_regions_world()
    for pair in ((_CountingGMM, _LockedCountingGMM), (_PostCountingGMM, _LockedPostCountingGMM)):
        loads = []
        for model_class in pair:
            run = tmp_path / model_class.__name__
            _session_started_fitted(run, model_class, max_new=50)
            model = model_class(3, 2, seed=0)
            ConfidentTeacher.resume(run, env, oracle(env), model=model, progress=False).close()
            loads.append(model.loads)
        assert loads[1] == loads[0] >= 1, pair


# -- 4. a resume goes on from the log as it is once locked, not as it was read before ----------


class _HookedGMM(GaussianMixtureSet):
    """A model whose first ``load_state_dict`` runs ``between`` (then cleared): in a resume of a
    session started fitted, that is the trial of the starting model, which comes after the log
    was read read-only and before the session is locked. There it stands for a writer that
    ran on, or came and went, between the two."""

    between: Callable[[], None] | None = None

    def load_state_dict(self, *args: Any, **kwargs: Any) -> Any:
        hook, type(self).between = type(self).between, None
        if hook is not None:
            hook()
        return super().load_state_dict(*args, **kwargs)


def _hooked_session(run: Path) -> None:
    _session_started_fitted(run, _HookedGMM)


def _resume_hooked(run: Path, between: Callable[[], None]) -> ConfidentTeacher:
    env = rare_regions_world()
    _HookedGMM.between = between
    try:
        ct = ConfidentTeacher.resume(
            run, env, oracle(env), model=_HookedGMM(3, 2, seed=0), progress=False
        )
    finally:
        ran, _HookedGMM.between = _HookedGMM.between is None, None
    assert ran  # (the hook came between the read and the lock, or the test tests nothing)
    return ct


def test_a_resume_goes_on_from_the_steps_a_writer_logged_after_its_read_only_read(tmp_path):
    """Another writer resumed the session and logged 15 steps after this resume had read the
    log and before it took the lock: this one goes on from step 45, not 30 (where it would
    log new steps under numbers the log holds)."""
    run = tmp_path / "run"
    _hooked_session(run)

    def other_writer() -> None:
        env = rare_regions_world()
        model = _HookedGMM(3, 2, seed=0)
        with ConfidentTeacher.resume(run, env, oracle(env), model=model, progress=False) as ct:
            ct.run(max_steps=45)

    with _resume_hooked(run, other_writer) as ct:
        assert ct.n_steps == 45
        assert ct.records == load_records(run)
        ct.run(max_steps=50)
    assert [r.step for r in load_records(run)] == list(range(50))


def test_a_resume_reads_a_demonstration_finished_after_its_read_only_read(tmp_path):
    """A demonstration pending in the log (logged, its outcome not yet written) when the
    resume read it, which its writer finished before the resume took the lock: the resume
    has its outcome, not the interrupted demonstration it read."""
    run = tmp_path / "run"
    _hooked_session(run)
    done = [r for r in load_records(run) if r.teacher_action is not None][-1]
    log = run / "steps.sqlite"
    with contextlib.closing(sqlite3.connect(log)) as db:  # as a writer between the two leaves it
        db.execute(
            "UPDATE steps SET pending = 1, reward = NULL, terminated = 0, truncated = 0, "
            "info = '{}' WHERE step = ?",
            (done.step,),
        )
        db.commit()
    assert load_records(run)[done.step].info == {"torchcbl_interrupted": True}

    def finish() -> None:  # what the writer's finish() commits
        with contextlib.closing(sqlite3.connect(log)) as db:
            db.execute(
                "UPDATE steps SET reward = ?, terminated = ?, truncated = ?, info = ?, "
                "pending = 0 WHERE step = ?",
                (
                    done.reward,
                    int(done.terminated),
                    int(done.truncated),
                    json.dumps(done.info),
                    done.step,
                ),
            )
            db.commit()

    with _resume_hooked(run, finish) as ct:
        assert ct.records[done.step] == done
        assert ct.records == load_records(run)


class _SignedZero(gym.Wrapper):
    """An env of no reward that returns it as -0.0 (as ``-sum([])`` gives it)."""

    def step(self, action):
        obs, _, terminated, truncated, info = self.env.step(action)
        return obs, -0.0, terminated, truncated, info


def _as_json(records: list) -> list[str]:
    return [json.dumps(r.to_dict()) for r in records]  # (tells -0.0 from 0.0)


def test_a_resume_has_the_steps_its_journal_held_as_the_log_stores_them(tmp_path):
    """A killed writer's last steps only in its journal, with a reward of -0.0: read
    before the lock, from the journal, it is -0.0; replayed into SQLite by the resume, 0.0.
    The resumed records are what the log holds then, as every reader reads it after."""
    run = tmp_path / "run"
    ct, _ = fault_session(run, world=_SignedZero(rare_regions_world()))
    ct.run(max_steps=20)
    ct._store.commit_every = 10**6
    for _ in range(30):
        ct.step()
    crash(ct)
    signs = [math.copysign(1, r.reward) for r in load_records(run) if r.reward is not None]
    assert -1 in signs  # the journal's steps, read before the lock: -0.0
    back, _ = fault_resume(run, world=_SignedZero(rare_regions_world()))
    with back:
        assert back.n_steps == 50
        assert _as_json(back.records) == _as_json(load_records(run))
