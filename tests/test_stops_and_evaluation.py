"""When teaching stops (budgets, streaks, success never assumed) and what an evaluation's
records come to per episode (issue 16 item 3, issue 13 item 5)."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import shutil
import signal
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from _processes import exists, kill_left
from _toy_envs import FaultyWorld, oracle, rare_regions_world

from torchcbl import (
    ConfidentTeacher,
    EnvError,
    EpisodeResult,
    TeacherError,
    TeachingConfig,
    describe,
    episode_results,
    evaluate_policy,
    load_records,
)
from torchcbl.session import repair_journal


class _Unjudged(gym.Wrapper):
    """The world with ``info["is_success"]`` removed (or forced to ``always``)."""

    def __init__(self, env: gym.Env, always: bool | None = None) -> None:
        super().__init__(env)
        self.always = always

    def step(self, action):
        obs, r, term, trunc, info = self.env.step(action)
        info = {k: v for k, v in info.items() if k != "is_success"}
        if self.always is not None and (term or trunc):
            info["is_success"] = self.always
        return obs, r, term, trunc, info


def _teacher(env, **cfg) -> ConfidentTeacher:
    world = env.unwrapped
    return ConfidentTeacher(
        env, oracle(world), config=TeachingConfig(noninteractive=False, **cfg), progress=False
    )


def test_no_stop_criterion_is_refused_with_the_papers_stops_named():
    with pytest.raises(ValueError, match="no default stop") as exc:
        _teacher(rare_regions_world()).run()
    assert "autonomous_episodes_to_stop=10" in str(exc.value)
    assert "max_episodes" in str(exc.value)


def test_an_episode_counts_as_a_success_only_when_the_env_says_so():
    # The env says: as before, the streak stops the run.
    ct = _teacher(rare_regions_world(episode_length=10), max_steps=600)
    ct.run(autonomous_episodes_to_stop=3)
    assert ct.stop_reason == "autonomous_episodes"
    # The env never says: no episode counts (the old code assumed success and stopped), and a
    # warning names the way out.
    ct = _teacher(_Unjudged(rare_regions_world(episode_length=10)), max_steps=600)
    with pytest.warns(UserWarning, match="time_limit_is_success"):
        ct.run(autonomous_episodes_to_stop=3)
    assert ct.stop_reason == "max_steps" and ct.n_steps == 600
    assert ct.autonomous_episodes_streak == 0
    # ... unless the user says reaching the time limit is success.
    ct = _teacher(
        _Unjudged(rare_regions_world(episode_length=10)), max_steps=600, time_limit_is_success=True
    )
    ct.run(autonomous_episodes_to_stop=3)
    assert ct.stop_reason == "autonomous_episodes" and ct.n_steps < 600
    assert all(r.autonomous for r in ct.records[-30:]) and ct.records[-1].truncated
    # The env says "failure" every time: it never counts, whatever the user says, no warning.
    ct = _teacher(
        _Unjudged(rare_regions_world(episode_length=10), always=False),
        max_steps=300,
        time_limit_is_success=True,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ct.run(autonomous_episodes_to_stop=1)
    assert ct.stop_reason == "max_steps"


class _ToGoal(gym.Env):
    """Walk right to x = 3: the episode ends there (terminated: the goal, as MountainCar's and
    Acrobot's end), or is cut by its time limit (10 steps); the env never sets is_success."""

    observation_space = gym.spaces.Box(-20, 20, shape=(1,), dtype=np.float32)
    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x = 0.0
        return np.array([self.x], np.float32), {}

    def step(self, action):
        self.x += 1.0 if action == 1 else -1.0
        return np.array([self.x], np.float32), -1.0, self.x >= 3, False, {}


def _to_goal(**cfg) -> ConfidentTeacher:
    env = gym.wrappers.TimeLimit(_ToGoal(), 10)
    config = TeachingConfig(noninteractive=False, autonomous_episodes_to_stop=3, **cfg)
    return ConfidentTeacher(env, lambda obs, info: 1, config=config, progress=False)


def test_an_env_whose_episodes_end_at_their_goal_is_told_how_to_say_so():
    """MountainCar taught all its steps: its episodes end (terminated) at the goal, and an
    episode the env does not judge never counts. The warning said to set
    time_limit_is_success=True (wrong for such an env: its failures are the time-limit ends)
    and pointed at teaching.py's `return self._step()`. It names both kinds of env and what
    each does (a goal reached by termination: set info["is_success"]; a time limit to survive:
    time_limit_is_success), and points at the caller's line, from run() or step()."""
    ct = _to_goal(max_steps=200)
    with pytest.warns(UserWarning) as caught:
        ct.run()
    assert ct.stop_reason == "max_steps" and len(caught) == 1
    msg = str(caught[0].message)
    assert caught[0].filename == __file__, caught[0].filename
    assert "ended (terminated) without info['is_success']" in msg, msg
    assert "info['is_success'] = terminated" in msg and "(MountainCar, Acrobot)" in msg, msg
    assert "(CartPole), set TeachingConfig(time_limit_is_success=True)" in msg, msg
    ct = _to_goal()
    with pytest.warns(UserWarning, match="without info") as caught:
        for _ in range(60):
            ct.step()
    assert caught[0].filename == __file__, caught[0].filename
    # the advice followed the wrong way round: goal episodes count as failures, and it says so
    ct = _to_goal(max_steps=200, time_limit_is_success=True)
    with pytest.warns(UserWarning) as caught:
        ct.run()
    assert ct.stop_reason == "max_steps" and len(caught) == 1
    msg = str(caught[0].message)
    assert "with time_limit_is_success=True it counts as a failure" in msg, msg
    assert "leave time_limit_is_success False" in msg and "= terminated" in msg, msg


@pytest.mark.parametrize("time_limit_is_success", [False, True])
def test_an_episode_that_reaches_its_goal_on_its_last_step_is_no_time_limit_success(
    tmp_path, time_limit_is_success
):
    """An episode that ends both terminated and truncated (the goal reached on the step its
    time limit cuts) ended at its goal: the warning names it "(terminated)", and with
    time_limit_is_success it is no time-limit success (a failure, as the warning says), so
    no streak of such episodes stops the run, nor makes a resume of it done."""
    env = gym.wrappers.TimeLimit(_ToGoal(), 3)  # x = 3 on the 3rd step: both ends at once
    config = TeachingConfig(
        noninteractive=False,
        autonomous_episodes_to_stop=3,
        max_steps=90,
        time_limit_is_success=time_limit_is_success,
    )
    run_dir = tmp_path / "s"
    ct = ConfidentTeacher(env, lambda obs, info: 1, config=config, run_dir=run_dir, progress=False)
    with ct, pytest.warns(UserWarning) as caught:
        ct.run()
    assert ct.records[2].terminated and ct.records[2].truncated
    assert ct.stop_reason == "max_steps" and ct.n_steps == 90 and len(caught) == 1
    msg = str(caught[0].message)
    assert re.match(r"episode \d+ ended \(terminated\) without info\['is_success'\]", msg), msg
    assert ("counts as a failure" in msg) == time_limit_is_success, msg
    env = gym.wrappers.TimeLimit(_ToGoal(), 3)
    streak_only = dataclasses.replace(config, max_steps=None)
    with ConfidentTeacher.resume(
        run_dir, env, lambda obs, info: 1, config=streak_only, progress=False
    ) as ct:
        assert ct.stop_reason is None


def test_an_is_success_of_none_is_the_env_not_saying_as_episode_results_reads_it():
    """info["is_success"] = None counted as a failure the env reported (no warning, and
    time_limit_is_success ignored), where episode_results reads None as "not said"."""

    class SaysNone(gym.Wrapper):
        def step(self, action):
            obs, r, term, trunc, info = self.env.step(action)
            return obs, r, term, trunc, {**info, "is_success": None}

    env = SaysNone(rare_regions_world(episode_length=10))
    ct = _teacher(env, max_steps=600)
    with pytest.warns(UserWarning, match="time_limit_is_success"):
        ct.run(autonomous_episodes_to_stop=3)
    assert ct.stop_reason == "max_steps"
    assert {e.success for e in episode_results(ct.records)} == {None}
    ct = _teacher(env, max_steps=600, time_limit_is_success=True)
    ct.run(autonomous_episodes_to_stop=3)
    assert ct.stop_reason == "autonomous_episodes" and ct.n_steps < 600


def test_max_episodes_is_a_session_budget_that_survives_resume(tmp_path):
    world = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        world,
        oracle(world),
        config=TeachingConfig(max_episodes=4),
        run_dir=tmp_path / "s",
        progress=False,
    )
    with ct:  # the context manager closes the step log
        ct.run()
        assert (ct.stop_reason, ct.n_episodes, ct.n_steps) == ("max_episodes", 4, 40)
        ct.run(max_episodes=6)
        assert (ct.n_episodes, ct.n_steps) == (6, 60)
    world = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher.resume(tmp_path / "s", world, oracle(world), progress=False)
    with ct:
        assert ct.n_episodes == 6
        ct.run(max_episodes=7)
        assert (ct.n_episodes, ct.n_steps, ct.stop_reason) == (7, 70, "max_episodes")


def _streak_session(run_dir: Path, *, stop: int = 3, **run_kw) -> int:
    """A session in ``run_dir`` taught until ``run(**run_kw)`` returns (by default on its
    streak of ``stop`` successful autonomous episodes) and closed; its step count."""
    world = rare_regions_world(episode_length=10)
    config = TeachingConfig(noninteractive=False, autonomous_episodes_to_stop=stop)
    with ConfidentTeacher(
        world, oracle(world), config=config, run_dir=run_dir, progress=False
    ) as ct:
        ct.run(**run_kw)
        return ct.n_steps


def _resumed(run_dir: Path, **kw) -> ConfidentTeacher:
    world = rare_regions_world(episode_length=10)
    return ConfidentTeacher.resume(run_dir, world, oracle(world), progress=False, **kw)


def test_a_resumed_session_that_had_met_its_streak_takes_no_step_and_says_so(tmp_path):
    """A session that stopped on autonomous_episodes_to_stop, resumed, taught on: run() began
    a new streak from zero and taught until another one, with no word, as often as it was
    resumed. A resume knows its stop from its log (the episodes its last writer ended on):
    stop_reason says it; run() takes no step and warns, as for a budget already reached;
    a raised stop goes on until it holds."""
    run_dir = tmp_path / "s"
    n = _streak_session(run_dir)
    for _ in range(2):  # every resume of it, not only the first
        with _resumed(run_dir) as ct:
            assert ct.stop_reason == "autonomous_episodes"
            with pytest.warns(UserWarning) as caught:
                ct.run()
            assert (ct.n_steps, ct.stop_reason, len(caught)) == (n, "autonomous_episodes", 1)
            msg = str(caught[0].message)
            assert msg.startswith("run() took no step: autonomous_episodes_to_stop=3"), msg
            assert (
                "ends on 3 successful episodes" in msg
                and "run(autonomous_episodes_to_stop=13)" in msg
            )
            assert caught[0].filename == __file__  # points at the caller's line
    # a stop the log has not met (a raised one, here for one call) teaches until it holds,
    # its streak counted within the call as in every run()
    with _resumed(run_dir) as ct, warnings.catch_warnings():
        warnings.simplefilter("error")
        ct.run(autonomous_episodes_to_stop=4)
        assert ct.stop_reason == "autonomous_episodes" and ct.n_steps >= n + 40
        assert ct.autonomous_episodes_streak == 4
    # a resume with a raised stop in its config has met nothing yet
    with _resumed(
        run_dir, config=TeachingConfig(noninteractive=False, autonomous_episodes_to_stop=9)
    ) as ct:
        assert ct.stop_reason is None


def test_a_resumed_session_that_had_met_its_autonomous_steps_takes_no_step(tmp_path):
    """The same for autonomous_steps_to_stop: a resume of a session that stopped on it takes
    no step, and its warning counts the autonomous steps its log ends on (not its episodes);
    the longer stop it suggests teaches on."""
    run_dir = tmp_path / "s"
    world = rare_regions_world(episode_length=10)
    config = TeachingConfig(noninteractive=False, autonomous_steps_to_stop=15)
    with ConfidentTeacher(
        world, oracle(world), config=config, run_dir=run_dir, progress=False
    ) as ct:
        ct.run()
        n = ct.n_steps
    assert all(r.teacher_action is None for r in ct.records[-15:])
    with _resumed(run_dir) as ct:
        assert ct.stop_reason == "autonomous_steps"
        with pytest.warns(UserWarning) as caught:
            ct.run()
        assert ct.n_steps == n and ct.stop_reason == "autonomous_steps"
        (msg,) = [str(w.message) for w in caught]
        assert msg.startswith("run() took no step: autonomous_steps_to_stop=15 was already met")
        assert "this resumed session's log ends on 15 autonomous steps in a row" in msg, msg
        assert msg.endswith("e.g. run(autonomous_steps_to_stop=115)."), msg
        ct.run(autonomous_steps_to_stop=115)
        assert ct.stop_reason == "autonomous_steps" and ct.n_steps >= n + 115


def test_a_resumed_done_session_teaches_on_in_a_run_after_one_that_took_steps(tmp_path):
    """A done session is done only until this writer takes a step: once a run() with a
    longer streak has taught on, a later run() counts its streak within itself, as every
    run() does, and teaches until it holds (the log of the last writer before the resume,
    which still ends on its old streak, is not read again)."""
    run_dir = tmp_path / "s"
    _streak_session(run_dir)
    with _resumed(run_dir) as ct, warnings.catch_warnings():
        warnings.simplefilter("error")  # no "took no step" warning
        ct.run(autonomous_episodes_to_stop=4)
        n = ct.n_steps
        ct.run()
        assert ct.stop_reason == "autonomous_episodes" and ct.n_steps >= n + 30
        assert ct.autonomous_episodes_streak == 3


def test_a_session_whose_env_raised_on_the_step_that_met_its_streak_is_not_done(tmp_path):
    """A run() whose env raised on the step that would have met autonomous_steps_to_stop ended
    by the error, not the streak (the step is logged, the episode cut): a resume has met no
    streak and teaches on, its streak counted from zero."""
    config = TeachingConfig(noninteractive=False, autonomous_steps_to_stop=15)
    world = rare_regions_world(episode_length=10)
    clean = ConfidentTeacher(world, oracle(world), config=config, progress=False).run()
    n = clean.n_steps  # the same session, deterministic: its step n - 1 meets the streak
    run_dir = tmp_path / "s"
    world = rare_regions_world(episode_length=10)
    faulty = FaultyWorld(world, fail_at=n, mode="raise")
    with ConfidentTeacher(
        faulty, oracle(world), config=config, run_dir=run_dir, progress=False
    ) as ct:
        with pytest.raises(EnvError, match="simulator connection lost"):
            ct.run()
    records = load_records(run_dir)
    assert len(records) == n and "torchcbl_error" in records[-1].info
    assert all(r.teacher_action is None for r in records[-15:])  # 15 unasked, the last failed
    with _resumed(run_dir) as ct, warnings.catch_warnings():
        warnings.simplefilter("error")
        assert ct.stop_reason is None
        ct.run()
        assert ct.stop_reason == "autonomous_steps" and ct.n_steps >= n + 15


def test_a_session_stopped_mid_streak_starts_its_streak_again_on_resume(tmp_path):
    """What a resume did before, kept: a session stopped (Ctrl-C, a kill: its log is the same)
    before its streak reached the stop has not met it, and the resumed run() counts its streak
    from zero; nor do episodes of two writers, each short of the stop, add up to it."""
    run_dir = tmp_path / "s"
    holder: dict[str, ConfidentTeacher] = {}

    def stop_at(k: int):
        def on_step(record):
            if holder["ct"].autonomous_episodes_streak == k and record.step % 10 == 4:
                raise KeyboardInterrupt  # mid-episode, k episodes into the streak

        return on_step

    world = rare_regions_world(episode_length=10)
    config = TeachingConfig(noninteractive=False, autonomous_episodes_to_stop=3)
    ct = ConfidentTeacher(
        world, oracle(world), config=config, run_dir=run_dir, progress=False, on_step=stop_at(2)
    )
    holder["ct"] = ct
    with ct, pytest.raises(KeyboardInterrupt):
        ct.run()
    world = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher.resume(run_dir, world, oracle(world), progress=False, on_step=stop_at(1))
    holder["ct"] = ct
    with ct:
        assert ct.stop_reason is None
        with pytest.raises(KeyboardInterrupt):
            ct.run()
    with _resumed(run_dir) as ct, warnings.catch_warnings():
        warnings.simplefilter("error")
        n = ct.n_steps
        assert ct.stop_reason is None
        ct.run()
        assert ct.stop_reason == "autonomous_episodes" and ct.n_steps >= n + 30
        assert all(r.autonomous for r in ct.records[-30:])


#: Where :func:`_streak_session` (its stop of 3 episodes met in one run()) stops on its own.
_STREAK_AT = 190


def _chunked_session(run_dir: Path, *calls: dict) -> ConfidentTeacher:
    """The session of :func:`_streak_session` (a stop of 3 episodes) taught by one process in
    several run() calls, ``run(**kw)`` for each of ``calls``, and closed."""
    world = rare_regions_world(episode_length=10)
    config = TeachingConfig(noninteractive=False, autonomous_episodes_to_stop=3)
    with ConfidentTeacher(
        world, oracle(world), config=config, run_dir=run_dir, progress=False
    ) as ct:
        for kw in calls:
            ct.run(**kw)
    return ct


def _runs(run_dir: Path) -> list[dict]:
    return [json.loads(line) for line in (run_dir / "runs.jsonl").read_text().splitlines()]


def test_a_session_taught_in_several_run_calls_is_done_only_by_its_last_runs_streak(tmp_path):
    """A streak counts within one run(), but a resume and describe() counted it over the
    steps of the session's last writer, as if a run() ended with its writer: a session taught
    in chunks by one process, run(max_steps=180) (2 episodes in a row) then run(max_steps=190)
    (1), read as one streak of 3, was "done" (show printed done:, the resume took no step,
    teach --resume refused it) though no run() of it met its stop. Each run() now records the
    step it began at (runs.jsonl) before its first step, and the count starts there."""
    n = _STREAK_AT  # where the same session taught in one run() stops on its own
    run_dir = tmp_path / "chunks"
    world = rare_regions_world(episode_length=10)
    config = TeachingConfig(noninteractive=False, autonomous_episodes_to_stop=3)
    with ConfidentTeacher(
        world, oracle(world), config=config, run_dir=run_dir, progress=False
    ) as ct:
        ct.run(max_steps=n - 10)
        assert (ct.stop_reason, ct.autonomous_episodes_streak) == ("max_steps", 2)
        ct.run(max_steps=n)
        assert (ct.stop_reason, ct.autonomous_episodes_streak) == ("max_steps", 1)
    assert [(r["first_step"], r["stops"]["max_steps"]) for r in _runs(run_dir)] == [
        (0, n - 10),
        (n - 10, n),
    ]
    assert describe(run_dir).streak_met is None
    with _resumed(run_dir) as ct, warnings.catch_warnings():
        warnings.simplefilter("error")  # no "took no step" warning
        assert ct.stop_reason is None
        ct.run()
        assert ct.stop_reason == "autonomous_episodes" and ct.n_steps >= n + 30


def test_a_session_that_met_its_streak_in_the_last_of_several_run_calls_is_done(tmp_path):
    """The other side: a session whose last run() of several stopped on its streak is done,
    for describe() and a resume, as one taught in a single run() is."""
    run_dir = tmp_path / "s"
    ct = _chunked_session(run_dir, {"max_steps": 100}, {"max_steps": 150}, {})
    assert ct.stop_reason == "autonomous_episodes"
    assert [r["first_step"] for r in _runs(run_dir)] == [0, 100, 150]
    assert describe(run_dir).streak_met == "autonomous_episodes"
    with _resumed(run_dir) as back:
        assert back.stop_reason == "autonomous_episodes"


def test_a_session_without_runs_jsonl_is_counted_over_its_last_writers_steps(tmp_path):
    """A session of a torchcbl before runs.jsonl is read as before: its streak counted over
    the steps of its last writer (which cannot tell that writer's run() calls apart)."""
    run_dir = tmp_path / "s"  # the session of the test above, of the same two run() calls
    _chunked_session(run_dir, {"max_steps": _STREAK_AT - 10}, {"max_steps": _STREAK_AT})
    (run_dir / "runs.jsonl").unlink()
    assert describe(run_dir).streak_met == "autonomous_episodes"
    with _resumed(run_dir) as back:
        assert back.stop_reason == "autonomous_episodes"


def test_a_session_without_runs_jsonl_is_counted_from_its_last_writers_first_step(tmp_path):
    """The same two run() calls made by two writers (the second a resume) in a session
    without runs.jsonl: the streak is counted from where the last writer began (step
    _STREAK_AT - 10: 1 episode in a row), not from step 0 (which reads the 2 episodes of the
    first writer and the 1 of the second as a streak of 3 the session never met)."""
    run_dir = tmp_path / "s"
    _chunked_session(run_dir, {"max_steps": _STREAK_AT - 10})
    with _resumed(run_dir) as ct:
        ct.run(max_steps=_STREAK_AT)
        assert (ct.stop_reason, ct.autonomous_episodes_streak) == ("max_steps", 1)
    (run_dir / "runs.jsonl").unlink()
    assert describe(run_dir).streak_met is None
    with _resumed(run_dir) as back:
        assert back.stop_reason is None


def test_a_log_cut_back_and_taught_on_counts_its_streak_from_the_last_run_recorded(tmp_path):
    """runs.jsonl's last record says where the last run() began, not its highest: a log cut
    back by repair_journal below where a run() had begun, then taught on, holds that run()'s
    record (now inside the log again) before the new one's, which begins lower. The session
    is copied while a run() from step 230 is under way with steps 170 on only in the journal
    (as a kill leaves it); the copy's journal loses step 170's line, repair_journal cuts the
    log back to 170 steps, and a resume's run() from 170 meets its streak of 3 episodes, the
    first of which began before step 230: done, counted from 170 (from 230: 2 episodes)."""
    source, copy = tmp_path / "a", tmp_path / "b"
    world = rare_regions_world(episode_length=10)
    config = TeachingConfig(noninteractive=False, autonomous_episodes_to_stop=3)

    def copy_while_running(record):
        if record.step == 231:
            shutil.copytree(source, copy)

    with ConfidentTeacher(
        world,
        oracle(world),
        config=config,
        run_dir=source,
        progress=False,
        commit_every=10**6,  # the steps after run()'s flush stay in the journal alone
        on_step=copy_while_running,
    ) as ct:
        ct.run(max_steps=170)
        while ct.n_steps < 230:
            ct.step()
        ct.run()
    assert [r["first_step"] for r in _runs(copy)] == [0, 230]
    journal = copy / "steps.journal"
    lines = journal.read_bytes().split(b"\n")
    assert lines[0].startswith(b'["s",170,'), lines[0]
    journal.write_bytes(b"\n".join(lines[1:]))  # step 170's line is gone
    repair_journal(copy)
    with _resumed(copy) as ct:
        assert (ct.n_steps, ct.stop_reason) == (170, None)
        ct.run()
        n = ct.n_steps
        assert ct.stop_reason == "autonomous_episodes"
    assert n - 30 < 230 < n  # (the premise: the streak's first episode began before 230)
    assert [r["first_step"] for r in _runs(copy)] == [0, 230, 170]
    assert describe(copy).streak_met == "autonomous_episodes"
    with _resumed(copy) as back:
        assert back.stop_reason == "autonomous_episodes"


class _ResetFails(gym.Wrapper):
    def reset(self, **kw):
        raise OSError("simulator connection lost")


def test_a_run_record_past_the_logs_end_is_passed_over(tmp_path):
    """A run() records where it begins before its first step: one that took no step (its
    first step failed with nothing logged, or the process was killed in between) leaves a
    record past the log's end, which is passed over: the session is read as it was, done
    here. A line torn by a kill (no newline) is passed over too, without a note, and the next
    run()'s record starts on a line of its own."""
    run_dir = tmp_path / "s"
    n = _streak_session(run_dir)
    assert n == _STREAK_AT  # (the premise of the tests above)
    world = rare_regions_world(episode_length=10)
    with ConfidentTeacher.resume(run_dir, _ResetFails(world), oracle(world), progress=False) as ct:
        with pytest.raises(EnvError, match="simulator connection lost"):
            ct.run(autonomous_episodes_to_stop=4)
    assert ct.n_steps == n and [r["first_step"] for r in _runs(run_dir)] == [0, n]
    with (run_dir / "runs.jsonl").open("a") as f:
        f.write('{"first_step": ')  # torn
    s = describe(run_dir)
    assert (s.streak_met, s.n_steps, s.notes) == ("autonomous_episodes", n, ())
    with _resumed(run_dir) as back:
        assert back.stop_reason == "autonomous_episodes"
        back.run(autonomous_episodes_to_stop=4)
        assert back.n_steps >= n + 40
    assert [r["first_step"] for r in _runs(run_dir)] == [0, n, n]
    assert describe(run_dir).streak_met == "autonomous_episodes"  # 4 in a row: 3 met
    with (run_dir / "runs.jsonl").open("a") as f:
        f.write("not json\n")  # a whole line that is no record: noted, passed over
    s = describe(run_dir)
    assert s.streak_met == "autonomous_episodes"
    assert s.notes == (f"{run_dir / 'runs.jsonl'}: lines [4] are not a run()'s record",)


@pytest.mark.parametrize(
    "torn, noted",
    [(b'{"first_step": ', []), (b"x" * 5000, [1])],
    ids=["torn-first-line", "torn-line-over-4kb"],
)
def test_a_run_records_itself_on_a_line_of_its_own_after_a_torn_last_line(tmp_path, torn, noted):
    """A runs.jsonl ending in a line with no newline (a kill mid-append): a torn line of a
    run() record (here the file's only line, which has no newline before it) is cut off
    without a note; a line over 4 KB, longer than any record, is kept, as a bad line noted,
    and the new record starts a line of its own after it. Either way the next run()'s
    record is read."""
    run_dir = tmp_path / "s"
    _chunked_session(run_dir, {"max_steps": 10})
    runs = run_dir / "runs.jsonl"
    runs.write_bytes(torn)
    with _resumed(run_dir) as ct:
        ct.run(max_steps=20)
    lines = runs.read_bytes().split(b"\n")
    assert lines[-1] == b"" and lines[-2].startswith(b'{"first_step": 10, '), lines[-2][:80]
    assert json.loads(lines[-2])["stops"]["max_steps"] == 20
    assert lines[:-2] == ([torn] if noted else [])
    said = (f"{runs}: lines {noted} are not a run()'s record",) if noted else ()
    assert describe(run_dir).notes == said


@pytest.mark.parametrize(
    "budget, says",
    [
        (
            "max_steps",
            r"max_steps=5 was already reached \(the session holds 10 steps.*"
            r"run\(max_steps=ct\.n_steps \+ 100\), here run\(max_steps=110\)",
        ),
        ("max_demonstrations", r"max_demonstrations=3 was already reached \(the session holds "),
        ("max_episodes", r"max_episodes=1 was already reached \(the session holds 1 finished"),
    ],
)
def test_a_run_that_takes_no_step_because_a_budget_was_reached_says_so(budget, says):
    """Budgets count over the whole session, so run(max_steps=5) on a session of 10 steps
    (where a user expects 5 more) returned at once with no word; it warns, once, with the
    budget, the session's count and how to ask for more. A run that took a step says nothing."""
    world = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(world, oracle(world), progress=False)
    ct.run(max_steps=10)
    limit = {"max_steps": 5, "max_demonstrations": 3, "max_episodes": 1}[budget]
    with pytest.warns(UserWarning, match=says) as caught:
        ct.run(**{budget: limit})
    assert ct.n_steps == 10 and ct.stop_reason == budget and len(caught) == 1
    assert caught[0].filename == __file__  # points at the caller's line
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ct.run(max_steps=12)
    assert ct.n_steps == 12


def test_a_step_after_a_run_that_took_no_step_records_no_run(tmp_path):
    """A run() records where it begins before its first step; one that took none (its
    budget already reached) records nothing, and a step() taken after it, outside any
    run(), records no run() either: runs.jsonl holds the run() calls that took steps."""
    run_dir = tmp_path / "s"
    world = rare_regions_world(episode_length=10)
    with ConfidentTeacher(world, oracle(world), run_dir=run_dir, progress=False) as ct:
        ct.run(max_steps=10)
        with pytest.warns(UserWarning, match="max_steps=5 was already reached"):
            ct.run(max_steps=5)
        ct.step()
        assert ct.n_steps == 11
    assert [(r["first_step"], r["stops"]["max_steps"]) for r in _runs(run_dir)] == [(0, 10)]


def test_evaluate_policy_seeds_every_episode_from_a_list():
    env = rare_regions_world(episode_length=5)
    records = evaluate_policy(oracle(env), env, seed=[3, 7, 3], uses_info=True)
    assert len(records) == 15 and [r.episode for r in records[::5]] == [0, 1, 2]
    obs = [np.array([r.observation for r in records if r.episode == e]) for e in range(3)]
    assert np.array_equal(obs[0], obs[2]) and not np.array_equal(obs[0], obs[1])
    alone = evaluate_policy(oracle(env), env, seed=7, n_episodes=1, uses_info=True)
    assert np.array_equal(obs[1], np.array([r.observation for r in alone]))
    # n_episodes may take fewer seeds than given, never more
    assert len(evaluate_policy(oracle(env), env, seed=range(5), n_episodes=2, uses_info=True)) == 10
    for bad in ([], [1.5], [True], "ab"):
        with pytest.raises(ValueError, match="seed"):
            evaluate_policy(oracle(env), env, seed=bad, uses_info=True)
    with pytest.raises(ValueError, match="only 2 seeds"):
        evaluate_policy(oracle(env), env, seed=[1, 2], n_episodes=3, uses_info=True)


class _ExpertOfObsAndInfo:
    def __call__(self, obs: np.ndarray, info: dict) -> int:
        return 0


def test_evaluate_policy_names_uses_info_for_a_policy_of_observation_and_info():
    """A teacher-style callable (obs, info) given to evaluate_policy without uses_info=True
    was called as policy(obs) and failed with Python's own "missing 1 required positional
    argument: 'info'" from inside the loop. Its signature is read first: the error says how
    it will be called, what it takes and to pass uses_info=True. A callable that can be
    called with the observation alone is run; a TypeError of its own is not reworded."""
    env = rare_regions_world(episode_length=5)
    for policy, name in ((oracle(env), "teacher"), (_ExpertOfObsAndInfo(), "_ExpertOfObsAndInfo")):
        with pytest.raises(TypeError) as e:
            evaluate_policy(policy, env, seed=0, n_steps=5)
        msg = str(e.value)
        assert msg.startswith("evaluate_policy: ") and "policy(observation)" in msg, msg
        assert name in msg and "(obs, info)" in msg and "pass uses_info=True" in msg, msg
    records = evaluate_policy(oracle(env), env, seed=0, n_steps=5, uses_info=True)
    assert len(records) == 5
    assert len(evaluate_policy(lambda obs, info=None: 0, env, seed=0, n_steps=5)) == 5

    def wrong(obs):
        return len(None)  # the policy's own TypeError

    with pytest.raises(TypeError, match="has no len"):
        evaluate_policy(wrong, env, seed=0, n_steps=5)


def test_evaluate_policy_with_uses_info_names_a_policy_of_the_observation_alone():
    """uses_info=True calls policy(observation, info); a policy of the observation alone failed
    with Python's "takes 1 positional argument but 2 were given". Its signature is read
    first: the error says how it is called, what it takes and to leave uses_info out."""
    env = rare_regions_world(episode_length=5)
    with pytest.raises(TypeError) as e:
        evaluate_policy(lambda obs: 0, env, seed=0, n_steps=5, uses_info=True)
    msg = str(e.value)
    assert msg.startswith("evaluate_policy: ") and "policy(observation, info)" in msg, msg
    assert "<lambda> takes (obs)" in msg and "leave uses_info out" in msg, msg


def test_evaluate_policy_refuses_a_negative_seed_before_it_runs():
    """A negative seed reached gymnasium's reset, whose error ("Seed must be greater or equal
    to zero") named neither evaluate_policy nor the argument; one in a list did so only at
    that episode's reset, after the episodes before it had run."""
    env = rare_regions_world(episode_length=5)
    calls = []
    for bad, says in (
        (-1, "got seed=-1"),
        (np.int64(-3), "got seed=-3"),
        ([3, -1], r"got -1 in seed=\[3, -1\]"),
        (range(-2, 3), r"got -2 in seed=range\(-2, 3\)"),
    ):
        with pytest.raises(ValueError, match=r"evaluate_policy: seeds must be ints >= 0.*" + says):
            evaluate_policy(lambda obs: calls.append(obs) or 0, env, seed=bad, n_steps=20)
    assert calls == []  # refused before the policy was asked anything
    assert len(evaluate_policy(lambda obs: 0, env, seed=0, n_steps=5)) == 5


def test_evaluate_policy_takes_a_numpy_int_seed_as_the_int_it_holds():
    """A seed drawn from a numpy array (np.int64(3)) passed evaluate_policy's check and was
    handed as it was to env.reset, where gymnasium refused it ("Seed must be a python
    integer, actual type: <class 'numpy.int64'>"); a list of numpy ints was converted. It is
    now the episode the Python int gives."""
    env = rare_regions_world(episode_length=5)
    want = evaluate_policy(lambda obs: 0, env, seed=3, n_episodes=1)
    for seed in (np.int64(3), np.uint32(3), np.arange(3, 4)[0]):
        assert evaluate_policy(lambda obs: 0, env, seed=seed, n_episodes=1) == want


def test_evaluate_policy_stops_at_n_steps_without_another_reset():
    """The step budget ends the run at its last step: no reset or observation check after it,
    so a bad observation the env would give next cannot cost the records taken."""

    class BadSecondReset(gym.Wrapper):
        resets = 0

        def reset(self, **kw):
            BadSecondReset.resets += 1
            obs, info = self.env.reset(**kw)
            return (obs * np.nan if BadSecondReset.resets > 1 else obs), info

    env = BadSecondReset(rare_regions_world(episode_length=5))
    records = evaluate_policy(lambda obs: 0, env, seed=1, n_steps=np.int64(5))  # numpy ints too
    assert len(records) == 5 and records[-1].truncated and BadSecondReset.resets == 1
    with pytest.raises(ValueError, match="n_steps must be an int >= 1"):
        evaluate_policy(lambda obs: 0, env, n_steps=np.bool_(True))


def test_evaluating_a_policy_taught_on_another_env_names_the_mismatch():
    from _toy_envs import four_d_world

    from torchcbl import GaussianMixtureSet, GreedyPolicy

    env = rare_regions_world(episode_length=5)  # 2 features, 3 actions
    model = GaussianMixtureSet(3, 4, 2, seed=0)  # taught on 4 features
    model.fit(np.random.default_rng(0).normal(size=(30, 4)), np.arange(30) % 3)
    with pytest.raises(ValueError, match="n_features=4 but the env has 2 features"):
        evaluate_policy(GreedyPolicy(model), env, n_steps=5)
    records = evaluate_policy(GreedyPolicy(model), four_d_world(episode_length=5), n_steps=5)
    assert len(records) == 5
    with pytest.raises(ValueError, match=r"one observation of shape \(4,\), got shape \(2, 4\)"):
        GreedyPolicy(model)(np.zeros((2, 4)))  # a batch: model.classify is the way


def test_a_teacher_answering_with_a_0d_torch_tensor_is_understood():
    """``logits.argmax()`` is a 0-d tensor: its integer is the action, as for numpy's."""
    import torch

    env = rare_regions_world(episode_length=5)
    teach = oracle(env)
    ct = ConfidentTeacher(
        env,
        lambda obs, info: torch.tensor(teach(obs, info)),
        config=TeachingConfig(max_new=2, max_steps=20),
        progress=False,
    )
    ct.run()
    assert [r.teacher_action for r in ct.records[:3]] == [
        env.optimal_action(r.observation_array) for r in ct.records[:3]
    ]
    assert all(type(r.teacher_action) is int for r in ct.records if r.teacher_action is not None)
    env2 = rare_regions_world(episode_length=5)
    bad = ConfidentTeacher(
        env2,
        lambda obs, info: torch.tensor(1.0),
        progress=False,
        config=TeachingConfig(max_new=2, max_steps=5),
    )
    with pytest.raises(TeacherError, match="expected an int action"):
        bad.run()


def test_episode_results_are_the_per_episode_returns_and_successes():
    env = rare_regions_world(episode_length=5)
    # always action 0: right in the frequent region only, so some episodes fail
    records = evaluate_policy(lambda obs: 0, env, seed=range(12), n_steps=58)
    results = episode_results(records)
    assert [e.episode for e in results] == list(range(12))
    for e in results:  # by hand from the records' own info: reward 1 for each right action
        steps = [r for r in records if r.episode == e.episode]
        right = [bool(r.info["optimal"]) for r in steps]
        assert e.steps == len(steps) and e.episode_return == sum(right)
        if e.finished:
            assert e.success is all(right) and e.truncated and not e.terminated
    assert {e.success for e in results[:11]} == {True, False}  # both outcomes occur
    last = results[-1]  # cut by n_steps after 3 of its 5 steps
    assert last == EpisodeResult(
        episode=11,
        steps=3,
        episode_return=last.episode_return,
        success=None,
        terminated=False,
        truncated=False,
        finished=False,
    )
    assert episode_results([]) == []


class _SaysSuccessAtEveryStep(gym.Wrapper):
    """The world with ``info["is_success"] = True`` at every step, not only at an episode's
    end (as some envs report a running judgement)."""

    def step(self, action):
        obs, r, term, trunc, info = self.env.step(action)
        return obs, r, term, trunc, {**info, "is_success": True}


def test_an_episode_cut_by_n_steps_has_no_success_whatever_its_info_said():
    """EpisodeResult.success is the env's is_success at the episode's end, None where the
    episode did not end in the records: an is_success the env gives at every step is not read
    off the last step of an episode n_steps cut."""
    env = _SaysSuccessAtEveryStep(rare_regions_world(episode_length=5))
    records = evaluate_policy(lambda obs: 0, env, seed=0, n_steps=8)
    assert all(r.info["is_success"] is True for r in records)
    done, cut = episode_results(records)
    assert (done.steps, done.finished, done.success) == (5, True, True)
    assert (cut.steps, cut.finished, cut.success) == (3, False, None)
    assert not cut.terminated and not cut.truncated


def test_episode_results_of_joined_evaluations_keep_their_episodes_apart():
    """Joining the records of several evaluations (one per seed, each numbering its episodes
    from 0) made episode_results merge them into one episode: 3 circuits of 10 steps came out
    as one of 30 steps with the three returns summed and the last one's success."""
    world = rare_regions_world(episode_length=10)
    teacher = oracle(world)
    records, alone = [], []
    for s in range(3):
        one = evaluate_policy(teacher, world, n_episodes=1, seed=s, uses_info=True)
        records += one
        alone += episode_results(one)
    assert [r.episode for r in records] == [0] * 30
    assert episode_results(records) == alone and len(alone) == 3
    assert [e.steps for e in alone] == [10, 10, 10]
    # evaluations cut by n_steps (their episode unfinished) are told apart by their steps
    cut = [evaluate_policy(teacher, world, n_steps=4, seed=s, uses_info=True) for s in (0, 1)]
    got = episode_results(cut[0] + cut[1])
    assert got == episode_results(cut[0]) + episode_results(cut[1])
    assert [(e.steps, e.finished) for e in got] == [(4, False), (4, False)]
    # evaluations of one step each: two episodes of one step, not one of two
    ones = [evaluate_policy(teacher, world, n_steps=1, seed=s, uses_info=True) for s in (0, 1)]
    assert [(r.step, r.episode) for r in ones[0] + ones[1]] == [(0, 0), (0, 0)]
    assert [(e.steps, e.finished) for e in episode_results(ones[0] + ones[1])] == [
        (1, False),
        (1, False),
    ]


class _OneBuffer(gym.Env):
    """An env that returns its one state buffer (float64) and rewrites it in place each step;
    the reward is the state's first value as the env holds it when the action runs."""

    observation_space = gym.spaces.Box(-10, 10, (2,), np.float64)
    action_space = gym.spaces.Discrete(2)

    def __init__(self) -> None:
        self.buf = np.zeros(2)
        self.t = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        self.buf[:] = self.np_random.uniform(-1, 1, 2)
        return self.buf, {}

    def step(self, action):
        reward = float(self.buf[0])
        self.t += 1
        self.buf[:] = self.np_random.uniform(-1, 1, 2)
        return self.buf, reward, False, self.t >= 4, {}


@pytest.mark.parametrize("uses_info", [False, True])
def test_an_evaluation_records_and_the_env_keep_the_state_the_policy_was_given(uses_info):
    """evaluate_policy gives the policy a copy of the observation and records its own: on an
    env that rewrites its observation buffer in place, each record holds the state the action
    was chosen on (not the next one, which step wrote into the same buffer), and a policy that
    writes into its observation (normalising it in place, here zeroing it) leaves the env's
    state as it was (the reward, read from it, is the state the policy saw)."""
    seen = []

    def policy(obs, info=None):
        seen.append(tuple(obs.tolist()))
        obs[:] = 0.0
        return 0

    records = evaluate_policy(policy, _OneBuffer(), n_steps=6, seed=3, uses_info=uses_info)
    assert [r.observation for r in records] == seen
    assert [r.reward for r in records] == [o[0] for o in seen]
    assert len(set(seen)) == 6 and 0.0 not in {o[0] for o in seen}


def test_evaluate_policy_calls_a_greedypolicy_subclass_of_ones_own():
    """A GreedyPolicy subclass that answers in its own __call__ (an action mask, exploration)
    is called, as evaluate_policy says a policy is; its action was ignored for the model's,
    so evaluating a masked policy measured the unmasked one. The confidence fields stay."""
    from torchcbl import GreedyPolicy

    env = rare_regions_world(episode_length=10)
    ct = _teacher(env, max_steps=200)
    ct.run()

    class NeverZero(GreedyPolicy):
        def __call__(self, observation):
            action = super().__call__(observation)
            return 1 if action == 0 else action

    plain = evaluate_policy(ct.policy, rare_regions_world(episode_length=10), n_steps=60, seed=4)
    assert 0 in {r.executed_action for r in plain}  # the model does answer 0 on these
    masked = evaluate_policy(
        NeverZero(ct.model), rare_regions_world(episode_length=10), n_steps=60, seed=4
    )
    assert 0 not in {r.executed_action for r in masked}
    assert all(r.distance is not None and r.posterior is not None for r in masked)
    first = masked[0]
    assert first.observation == plain[0].observation and first.distance == plain[0].distance


def _sleep_then_write(path: str) -> None:
    import time

    time.sleep(2.0)
    Path(path).write_text("done", encoding="utf-8")


def test_worker_pool_stops_its_workers_when_the_block_raises(tmp_path):
    """A Ctrl-C in the parent (or any error) must not leave workers computing tasks nobody will
    read: the queued task never starts and the running one is killed before it finishes."""
    import multiprocessing as mp
    import time

    from torchcbl.evaluation import worker_pool

    running, queued = tmp_path / "running", tmp_path / "queued"
    with pytest.raises(KeyboardInterrupt):
        with worker_pool(1, mp.get_context("spawn")) as pool:
            first = pool.submit(_sleep_then_write, str(running))
            pool.submit(_sleep_then_write, str(queued))
            while not first.running():
                time.sleep(0.05)
            raise KeyboardInterrupt
    time.sleep(3.0)  # past the time the running task would have finished
    assert not running.exists() and not queued.exists()
    # a block that ends normally waits for its tasks
    with worker_pool(1, mp.get_context("spawn")) as pool:
        pool.submit(_sleep_then_write, str(running))
    assert running.read_text() == "done"


def _alive(pid: int) -> bool:
    """Whether process ``pid`` still runs (a zombie, dead but not yet reaped, does not)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text(encoding="utf-8").rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_worker_pool_workers_die_with_a_main_process_killed_alone(tmp_path):
    """A main process killed alone (kill -9, the out-of-memory killer) left its workers
    computing their tasks: a stopped reproduction's seeds went on writing into the seed
    directories that a resumed run clears and runs again. They now die with it."""
    import subprocess
    import time

    script = tmp_path / "main.py"
    script.write_text(
        "import multiprocessing as mp, os, time\n"
        "from torchcbl.evaluation import worker_pool\n"
        "if __name__ == '__main__':\n"
        "    with worker_pool(1, mp.get_context('spawn')) as pool:\n"
        "        print(pool.submit(os.getpid).result(), flush=True)\n"
        "        pool.submit(time.sleep, 60)\n"
        "        time.sleep(0.5)\n"
        "        os.kill(os.getpid(), 9)\n"
    )
    out = tmp_path / "out.txt"  # not a pipe: a worker left alive would hold it open
    with open(out, "w", encoding="utf-8") as f:
        proc = subprocess.run([sys.executable, str(script)], stdout=f, timeout=60)
    assert proc.returncode == -9
    worker = int(out.read_text().split()[0])
    try:
        deadline = time.monotonic() + 5.0
        while _alive(worker) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _alive(worker)
    finally:
        if _alive(worker):
            os.kill(worker, 9)


def test_a_worker_that_dies_mid_task_is_said_as_it_died():
    """A worker's death broke the pool; every caller said "died abruptly (killed by a signal,
    or out of memory)", wrong for a worker that exited with a code of its own or sent back an
    exception that cannot be unpickled. The pool's error now names the signal, the code or
    the unpickling, the task and what to do; the other worker, which the broken pool stops
    with SIGTERM, is not taken for the dead one."""
    import multiprocessing as mp
    import time

    from _scripts import end_this_process

    from torchcbl.evaluation import worker_pool

    for how, says in (
        ("kill", "a worker process was killed by SIGKILL (the out-of-memory killer sends it)"),
        ("exit", "a worker process exited with code 3 in the middle of a task"),
        ("exit-0", "a worker process exited with code 0 in the middle of a task"),
        ("unpicklable", "a worker process sent back a result or an exception that cannot be"),
    ):
        with pytest.raises(RuntimeError) as caught:
            with worker_pool(2, mp.get_context("spawn"), running="seed 7", after="go on") as p:
                p.submit(time.sleep, 0.5)  # the other worker: terminated by the broken pool
                p.submit(end_this_process, how).result()
        assert str(caught.value).startswith(says), caught.value
        assert str(caught.value).endswith(" while it ran seed 7; go on")


def test_a_worker_that_dies_while_tasks_are_still_submitted_is_said_as_it_died(monkeypatch):
    """A worker that died while the block was still submitting tasks (a pool of two: the first
    died as the second started) broke the pool between submit's look at it and the second
    worker's start, which then pickled the call queue the broken pool had closed: CPython's
    bare "OSError: handle is closed" came out of submit, not the pool's own error naming the
    signal. Here the second worker's start waits until the pool has seen the first one die,
    as the race does; the pool's error names SIGKILL, the task and what to do."""
    import multiprocessing as mp
    import time
    from concurrent.futures.process import _process_worker
    from multiprocessing.context import SpawnProcess

    from torchcbl.evaluation import worker_pool

    real_start = SpawnProcess.start
    workers = []

    def start(proc):
        if getattr(proc, "_target", None) is not _process_worker:  # the start-up check
            return real_start(proc)
        if workers:  # the second worker: the first dies, and the pool sees it, first
            os.kill(workers[0].pid, signal.SIGKILL)
            call_queue = proc._args[0]  # the broken pool closes its reading end
            deadline = time.monotonic() + 10.0
            while not call_queue._reader.closed and time.monotonic() < deadline:
                time.sleep(0.01)
        real_start(proc)
        workers.append(proc)

    monkeypatch.setattr(SpawnProcess, "start", start)
    with pytest.raises(RuntimeError) as caught:
        with worker_pool(2, mp.get_context("spawn"), running="seed 7", after="go on") as pool:
            for _ in range(4):
                pool.submit(time.sleep, 0.1)
    says = "a worker process was killed by SIGKILL (the out-of-memory killer sends it)"
    assert str(caught.value) == f"{says} while it ran seed 7; go on", caught.value
    assert len(workers) == 1  # the second never started


@pytest.mark.skipif(not hasattr(signal, "pthread_kill"), reason="signals a thread (POSIX)")
def test_a_ctrl_c_as_a_worker_starts_leaves_no_worker_behind(monkeypatch):
    """A Ctrl-C (SIGINT) that came while submit started a worker, after the process was
    started but before the pool had kept it, raised KeyboardInterrupt there; the pool's
    Ctrl-C handling terminated the workers it knew of, and that one ran on (in a notebook,
    for as long as the kernel; or it died printing a traceback). Here the SIGINT comes as
    the second worker's start returns; every worker the pool started is gone (terminated and
    reaped: signal 0 finds no process) when the block's KeyboardInterrupt comes out."""
    import multiprocessing as mp
    import threading
    import time
    from concurrent.futures.process import _process_worker
    from multiprocessing.context import SpawnProcess

    from torchcbl.evaluation import worker_pool

    real_start = SpawnProcess.start
    pids = []

    def start(proc):
        worker = getattr(proc, "_target", None) is _process_worker  # not the start-up check
        real_start(proc)
        if worker:
            pids.append(proc.pid)
            if len(pids) == 2:  # a Ctrl-C to this thread: its handler runs before this returns
                signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    monkeypatch.setattr(SpawnProcess, "start", start)
    try:
        with pytest.raises(KeyboardInterrupt):
            with worker_pool(3, mp.get_context("spawn")) as pool:
                for _ in range(6):
                    pool.submit(time.sleep, 5)
        assert len(pids) == 2
        assert [p for p in pids if exists(p)] == []
    finally:
        kill_left(pids)


@pytest.mark.skipif(not hasattr(signal, "pthread_kill"), reason="signals a thread (POSIX)")
def test_a_ctrl_c_as_the_start_up_check_starts_leaves_no_process_behind(monkeypatch):
    """check_workers_start (every worker pool's first step) started its probe process, then
    entered the try that joins it: a Ctrl-C (SIGINT) as the start returned raised
    KeyboardInterrupt in between, and the probe was left to itself, never terminated nor
    reaped. Here the SIGINT comes as the probe's start returns; the probe is gone (reaped:
    signal 0 finds no process) when the KeyboardInterrupt comes out."""
    import multiprocessing as mp
    import threading
    from multiprocessing.context import SpawnProcess

    from torchcbl.evaluation import check_workers_start

    real_start = SpawnProcess.start
    pids = []

    def start(proc):
        real_start(proc)
        pids.append(proc.pid)  # a Ctrl-C to this thread: its handler runs before this returns
        signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    monkeypatch.setattr(SpawnProcess, "start", start)
    try:
        with pytest.raises(KeyboardInterrupt):
            check_workers_start(mp.get_context("spawn"))
        assert len(pids) == 1
        assert [p for p in pids if exists(p)] == []
    finally:
        kill_left(pids)
        mp.active_children()  # reaps what was left


@pytest.mark.skipif(
    not hasattr(signal, "pthread_kill") or not Path("/proc/self/fd").is_dir(),
    reason="signals a thread (POSIX), lists open fds through /proc",
)
@pytest.mark.parametrize("how", ["exits-3", "ctrl-c"])
def test_a_start_up_check_that_raises_leaves_no_pipe_open(monkeypatch, how):
    """check_workers_start never closed its probe process: when it raised (the probe exited
    with code 3, or a Ctrl-C came as it started), the probe's two pipe handles stayed open
    for as long as the exception's traceback was kept (a notebook keeps the last one), as the
    traceback's frame holds the probe. With the exception (and its traceback) kept, the
    process has the descriptors it had before."""
    import multiprocessing as mp
    import threading
    from multiprocessing.context import SpawnProcess

    from torchcbl.evaluation import check_workers_start

    real_start = SpawnProcess.start
    pids = []

    def start(proc):
        if how == "exits-3":  # the probe fails, as one that cannot import the main module does
            proc._target, proc._args = sys.exit, (3,)
        real_start(proc)
        pids.append(proc.pid)
        if how == "ctrl-c":  # to this thread: its handler runs as the start-up's hold ends
            signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    ctx = mp.get_context("spawn")
    check_workers_start(ctx)  # once first: what opens once per process
    monkeypatch.setattr(SpawnProcess, "start", start)
    stops = RuntimeError if how == "exits-3" else KeyboardInterrupt
    try:
        before = sorted(os.listdir("/proc/self/fd"))
        with pytest.raises(stops) as caught:
            check_workers_start(ctx)
        after = sorted(os.listdir("/proc/self/fd"))
        assert caught.value.__traceback__ is not None  # kept, with the check's frame
        if how == "exits-3":
            assert "exited with code 3" in str(caught.value)
        assert len(pids) == 1
        assert [p for p in pids if exists(p)] == []
        assert after == before
    finally:
        kill_left(pids)


def _ctrl_c_handler_here() -> str:
    return repr(signal.getsignal(signal.SIGINT))


@pytest.mark.skipif(not hasattr(os, "fork"), reason="the fork start method (POSIX)")
def test_a_forked_worker_takes_ctrl_c_as_the_parent_did_before_it_started_it():
    """worker_pool holds a Ctrl-C while it starts a worker. A worker forked then (the fork
    start method, multiprocessing's default on Linux before Python 3.14) inherited the
    temporary holding handler and never left the hold: its first Ctrl-C was swallowed. Each
    worker now starts with the handler the parent had before the hold (here Python's
    default, which raises KeyboardInterrupt)."""
    import multiprocessing as mp

    from torchcbl.evaluation import worker_pool

    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with worker_pool(2, mp.get_context("fork")) as pool:
            seen = {pool.submit(_ctrl_c_handler_here).result() for _ in range(4)}
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, before)
    assert seen == {repr(signal.default_int_handler)}, seen


@pytest.mark.parametrize(
    ("answer", "says"),
    [
        (lambda o, r, te, tr, i: (o, r, te or tr, i), r"expected the gymnasium 5-tuple"),
        (lambda o, r, te, tr, i: (o, r, te, tr, "ok"), r"returned info 'ok'; expected a dict"),
        (lambda o, r, te, tr, i: (o, r, np.array([te, te]), tr, i), r"terminated=.*a bool"),
        (lambda o, r, te, tr, i: (o, r, 2, tr, i), r"terminated=2; expected a bool"),
        (
            lambda o, r, te, tr, i: (np.full(np.shape(o), np.inf), r, te, tr, i),
            r"env.step: the observation has non-finite values \[inf, inf\]",
        ),
    ],
    ids=["gym-4-tuple", "info-not-a-dict", "vector-flag", "flag-2", "infinite-observation"],
)
def test_evaluate_policy_checks_the_env_step_answer_as_teaching_does(answer, says):
    """evaluate_policy unpacked env.step's answer unchecked: a gym < 0.26 4-tuple was a bare
    'not enough values to unpack', a string info an AttributeError from deep inside, and a
    flag array was read with bool() (two elements: a numpy ValueError)."""
    from torchcbl import EnvError

    class Odd(gym.Wrapper):
        def step(self, action):
            return answer(*self.env.step(action))

    env = Odd(rare_regions_world())
    with pytest.raises(EnvError, match=says):
        evaluate_policy(lambda obs: 0, env, n_steps=5, seed=0)


def test_evaluate_policy_refuses_an_action_one_past_the_last():
    """An answer of n_actions is no action of the env's (indices run 0..n_actions-1): it is
    refused before env.step is called with it, as -1 is; n_actions - 1 is taken."""
    env = rare_regions_world(episode_length=5)
    n = int(env.action_space.n)
    for answer in (n, -1):
        with pytest.raises(ValueError, match=rf"answered {answer}; expected an int in \[0, {n}\)"):
            evaluate_policy(lambda obs, a=answer: a, env, n_steps=3, seed=0)
    records = evaluate_policy(lambda obs: n - 1, env, n_steps=3, seed=0)
    assert [r.executed_action for r in records] == [n - 1] * 3


def test_evaluate_policy_with_uses_info_refuses_a_pytorch_module_of_the_observation_alone():
    """``evaluate_policy(Net(), env, uses_info=True)`` with ``Net.forward(self, x)`` raised
    Python's raw "forward() takes 2 positional arguments but 3 were given" at the first step:
    an nn.Module's ``__call__`` shows ``(*args, **kwargs)``. Its forward is read first."""
    import torch

    class Net(torch.nn.Module):
        def forward(self, x):
            return 0

    env = rare_regions_world(episode_length=5)
    with pytest.raises(TypeError) as e:
        evaluate_policy(Net(), env, seed=0, n_steps=5, uses_info=True)
    msg = str(e.value)
    assert msg.startswith("evaluate_policy: ") and "Net.forward takes (x)" in msg, msg
    assert "leave uses_info out" in msg, msg
    assert len(evaluate_policy(Net(), env, seed=0, n_steps=3)) == 3


def test_evaluate_policy_names_an_extra_required_argument():
    """A policy with a required argument the call never passes, ``def p(obs, info, k)`` with
    uses_info=True, was told to leave uses_info out, which would not help."""

    def p(obs, info, k):
        return 0

    env = rare_regions_world(episode_length=5)
    with pytest.raises(TypeError) as e:
        evaluate_policy(p, env, seed=0, n_steps=5, uses_info=True)
    msg = str(e.value)
    assert "p takes (obs, info, k)" in msg and "give k a default" in msg, msg
    assert "leave uses_info out" not in msg, msg
    with pytest.raises(TypeError) as e:
        evaluate_policy(p, env, seed=0, n_steps=5)
    msg = str(e.value)
    assert "give info, k defaults" in msg or "give k a default" in msg, msg
