"""Teaching sessions on disk: layout, resume, durability under SIGKILL, bad input."""

from __future__ import annotations

import collections
import copy
import dataclasses
import enum
import json
import os
import random
import signal
import sqlite3
import subprocess
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch
from _toy_envs import FaultyWorld, oracle, overlap_world, rare_regions_world

from torchcbl import (
    ConfidentTeacher,
    DistanceRule,
    GaussianMixtureSet,
    PosteriorRule,
    TeachingConfig,
)
from torchcbl.session import (
    IncompatibleRunDirError,
    build_model,
    fit_count,
    load_config,
    load_demonstrations,
    load_model,
    load_policy,
    load_records,
)
from torchcbl.teaching import EnvError, TeacherError

TESTS = Path(__file__).parent


def make(env, run_dir, teacher=None, seed=0, keep_checkpoints=3, **cfg):
    return ConfidentTeacher(
        env,
        teacher or oracle(env),
        config=TeachingConfig(**cfg),
        run_dir=run_dir,
        seed=seed,
        progress=False,
        keep_checkpoints=keep_checkpoints,
    )


def same_state(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    sa, sb = a.state_dict(), b.state_dict()
    return sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)


def assert_model_is_fit_on_log(model, run_dir):
    config = load_config(run_dir)
    x, y = load_demonstrations(run_dir)
    k = fit_count(len(y), config["teaching"]["max_new"])
    fresh = build_model(config)
    if k:
        fresh.fit(x[:k], y[:k])
    assert same_state(model, fresh)


def test_layout_and_log_round_trip(tmp_path):
    run = tmp_path / "run"
    ct = make(rare_regions_world(), run, noninteractive=False, max_new=2)
    ct.run(max_steps=120)
    assert (run / "config.json").is_file() and (run / "steps.sqlite").is_file()
    ckpts = sorted(p.name for p in (run / "checkpoints").iterdir())
    n = ct.n_demonstrations - ct.n_demonstrations % 2  # the last refit's labels
    assert n >= 8 and ckpts == [f"model-{k:08d}.pt" for k in (n - 4, n - 2, n)]  # newest 3
    config = json.loads((run / "config.json").read_text())
    assert config["teaching"]["max_new"] == 2 and config["rule"] == DistanceRule().to_config()
    assert config["model"]["args"]["n_actions"] == 3 and config["env"]["n_features"] == 2
    assert load_records(run) == ct.records  # every field survives the store
    db = sqlite3.connect(run / "steps.sqlite")
    assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    policy = load_policy(run)
    obs = np.array([0.2, 7.5])
    assert policy(obs) == ct.policy(obs) == 2


def _checkpoint_numbers(run: Path) -> list[int]:
    return sorted(int(p.name[6:14]) for p in (run / "checkpoints").glob("model-*.pt"))


def _recorded(
    env, run: Path, *, keep_checkpoints: int | None, **cfg
) -> tuple[ConfidentTeacher, dict[int, dict[str, torch.Tensor]]]:
    """A session in ``run`` (no non-interactive phase) and the live model's state at each
    refit, by its label count (filled by ``on_refit`` as the session runs)."""
    live: dict[int, dict[str, torch.Tensor]] = {}
    ct = ConfidentTeacher(
        env,
        oracle(env),
        config=TeachingConfig(noninteractive=False, **cfg),
        run_dir=run,
        progress=False,
        keep_checkpoints=keep_checkpoints,
        on_refit=lambda m, n: live.__setitem__(n, copy.deepcopy(m.state_dict())),
    )
    return ct, live


@pytest.mark.parametrize("refit", ["full", "incremental"])
def test_a_session_keeps_its_newest_checkpoints_and_rebuilds_any_stage_from_its_log(
    tmp_path, refit
):
    """keep_checkpoints=2: the older checkpoints go as new ones come (a session refitting
    after every label would otherwise write ~2 MB per label); load_model at a stage whose
    checkpoint went is the model the loop had then, bit for bit; None keeps every one."""
    run = tmp_path / "run"
    env = rare_regions_world()
    ct, live = _recorded(env, run, keep_checkpoints=2, max_new=2, refit=refit)
    ct.run(max_steps=120)
    ct.close()
    refits = sorted(live)
    assert len(refits) >= 5 and _checkpoint_numbers(run) == refits[-2:]
    for early in refits[1], refits[-3]:  # their checkpoints were removed
        rebuilt = load_model(run, n_demonstrations=early).state_dict()
        assert all(torch.equal(rebuilt[k], live[early][k]) for k in rebuilt), early
    assert _checkpoint_numbers(run) == refits[-2:]  # a reader writes nothing back

    if refit == "incremental":
        return
    everything = tmp_path / "all"
    ct = make_kept(env, everything, keep_checkpoints=None)
    ct.run(max_steps=120)
    ct.close()
    assert _checkpoint_numbers(everything) == refits  # the same session, every refit kept


@pytest.mark.parametrize("refit", ["full", "incremental"])
def test_a_hand_refit_off_the_schedule_keeps_its_checkpoint(tmp_path, refit):
    """A refit by hand (ConfidentTeacher.refit) moves the schedule: the loop refits max_new
    labels after it. Its checkpoint is the only record of where it fell, and pruning removed
    it: load_model at every stage after it rebuilt another model than the loop had (at 9
    labels one fitted on 8, not on 6). A checkpoint off the schedule of the one kept before it
    is now kept; every stage rebuilds as the loop had it, the hand refit's checkpoint and the
    newest ones alone on disk."""
    run = tmp_path / "run"
    env = rare_regions_world()
    ct, live = _recorded(env, run, keep_checkpoints=1, max_new=4, refit=refit)
    while ct.n_demonstrations < 6:
        ct.step()
    assert ct.refit()
    while ct.n_demonstrations < 40:
        ct.step()
    ct.close()
    refits = sorted(live)
    assert refits[:3] == [4, 6, 10] and refits[-1] == 38
    assert _checkpoint_numbers(run) == [6, 38]
    for n in range(4, 41):
        stood_on = max(r for r in refits if r <= n)
        rebuilt = load_model(run, n_demonstrations=n).state_dict()
        assert all(torch.equal(rebuilt[k], live[stood_on][k]) for k in rebuilt), (n, stood_on)


def make_kept(env, run_dir, **kwargs):
    return ConfidentTeacher(
        env,
        oracle(env),
        config=TeachingConfig(noninteractive=False, max_new=2),
        run_dir=run_dir,
        progress=False,
        **kwargs,
    )


def test_a_resumed_writer_removes_what_earlier_writers_kept_beyond_its_own_count(tmp_path):
    """A session written keeping every checkpoint and resumed with keep_checkpoints=1 keeps
    the newest alone once it refits; checkpoint 0 of a fitted start is never removed."""
    run = tmp_path / "run"
    env = rare_regions_world()
    start = GaussianMixtureSet(3, 2, seed=0)
    start.fit(
        np.array([[0.1, 7.0], [0.3, 7.2], [5.0, 0.0], [5.2, 0.1], [9.0, 9.0], [9.1, 8.9]]),
        np.array([0, 0, 1, 1, 2, 2]),
    )
    ct = ConfidentTeacher(
        env,
        oracle(env),
        model=start,
        config=TeachingConfig(noninteractive=False, max_new=2),
        run_dir=run,
        progress=False,
        keep_checkpoints=None,
    )
    ct.run(max_steps=60)
    ct.close()
    before = _checkpoint_numbers(run)
    assert before[0] == 0 and len(before) >= 4
    again = ConfidentTeacher.resume(run, env, oracle(env), progress=False, keep_checkpoints=1)
    again.run(max_steps=120)
    again.close()
    newest = again.n_demonstrations - again.n_demonstrations % 2
    assert newest > before[-1] and _checkpoint_numbers(run) == [0, newest]
    policy = load_policy(run)  # the newest checkpoint, the live model
    obs = np.array([0.2, 7.5])
    assert policy(obs) == again.policy(obs)


def test_a_resume_keeps_what_the_session_kept_unless_told_otherwise(tmp_path):
    """A session that kept every checkpoint, resumed without keep_checkpoints, lost all but
    the newest three at its first refit, without a word (the resume's default was the
    constructor's 3). Each writer now records its retention in writers.jsonl and a resume
    keeps the last one's by default; a session of a torchcbl that did not record it kept every
    checkpoint, and so does its resume."""
    env = rare_regions_world()
    runs = {keep: tmp_path / f"keep-{keep}" for keep in (None, 2)}
    for keep, run in runs.items():
        ct = make_kept(env, run, keep_checkpoints=keep)
        ct.run(max_steps=60)
        ct.close()
    before = _checkpoint_numbers(runs[None])
    assert len(before) >= 6 and len(_checkpoint_numbers(runs[2])) == 2
    for keep, run in runs.items():
        again = ConfidentTeacher.resume(run, env, oracle(env), progress=False)
        again.run(max_steps=120)
        again.close()
        after = _checkpoint_numbers(run)
        assert after[-1] > before[-1]
        assert after[: len(before)] == before if keep is None else len(after) == 2, (keep, after)
        writers = [json.loads(line) for line in (run / "writers.jsonl").read_text().splitlines()]
        assert [w["keep_checkpoints"] for w in writers] == [keep, keep]

    # a session written before writers recorded it: every checkpoint kept, on resume too
    old = runs[None]
    lines = (old / "writers.jsonl").read_text().splitlines()
    stripped = [json.loads(line) for line in lines]
    for w in stripped:
        del w["keep_checkpoints"]
    (old / "writers.jsonl").write_text("".join(json.dumps(w) + "\n" for w in stripped))
    kept = _checkpoint_numbers(old)
    again = ConfidentTeacher.resume(old, env, oracle(env), progress=False)
    again.run(max_steps=180)
    again.close()
    now = _checkpoint_numbers(old)
    assert now[: len(kept)] == kept and len(now) > len(kept)


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "3"])
def test_keep_checkpoints_is_none_or_a_positive_int(tmp_path, bad):
    env = rare_regions_world()
    with pytest.raises(ValueError, match=r"keep_checkpoints: expected None .* or an int >= 1"):
        make_kept(env, tmp_path / "run", keep_checkpoints=bad)
    assert not (tmp_path / "run").exists()  # refused before the session is made


def _files_state(run: Path) -> dict[str, tuple[int, bytes]]:
    """{relative path: (mtime_ns, bytes)} of every file under a run directory."""
    return {
        str(p.relative_to(run)): (p.stat().st_mtime_ns, p.read_bytes())
        for p in sorted(run.rglob("*"))
        if p.is_file()
    }


@pytest.mark.parametrize("bad", [0, "3"])
def test_resume_refuses_a_keep_checkpoints_it_cannot_take_before_touching_the_session(
    tmp_path, bad
):
    """resume(keep_checkpoints=) takes what the constructor takes and "as_before"; anything
    else is refused saying so, before the session is opened (no file of it touched)."""
    run = tmp_path / "run"
    env = rare_regions_world()
    ct = make_kept(env, run)
    ct.run(max_steps=30)
    ct.close()
    before = _files_state(run)
    with pytest.raises(ValueError, match=r'keep_checkpoints: expected None .*"as_before"') as err:
        ConfidentTeacher.resume(run, env, oracle(env), progress=False, keep_checkpoints=bad)
    assert f"got {bad!r}" in str(err.value)
    assert _files_state(run) == before


def test_a_writers_record_of_keep_checkpoints_that_is_no_count_reads_as_every_one(tmp_path):
    """writers.jsonl edited by hand (or by another program) to keep_checkpoints true, 0 or
    "2" is no count of checkpoints: read as every one kept (None), True not taken as 1, and
    a resume keeps every one by default."""
    from torchcbl.session import describe, kept_checkpoints

    run = tmp_path / "run"
    ct = make_kept(rare_regions_world(), run, keep_checkpoints=2)
    ct.run(max_steps=10)
    ct.close()
    assert kept_checkpoints(run) == describe(run).keep_checkpoints == 2
    writers = run / "writers.jsonl"
    record = json.loads(writers.read_text().splitlines()[-1])
    for edited in (True, 0, "2"):
        writers.write_text(json.dumps({**record, "keep_checkpoints": edited}) + "\n")
        assert kept_checkpoints(run) is None, edited
        assert describe(run).keep_checkpoints is None, edited
    env = rare_regions_world()  # and a resume as before keeps every one (True was refused)
    ConfidentTeacher.resume(run, env, oracle(env), progress=False).close()
    assert json.loads(writers.read_text().splitlines()[-1])["keep_checkpoints"] is None


def test_a_session_refitting_after_every_label_keeps_only_its_newest_checkpoints(tmp_path):
    """max_new=1 (a refit after every label, the case keep_checkpoints is for: ~2 MB a
    label) prunes as any other schedule: the newest keep_checkpoints alone stay on disk, and
    every stage still rebuilds from the log."""
    run = tmp_path / "run"
    env = rare_regions_world()
    ct, live = _recorded(env, run, keep_checkpoints=2, max_new=1)
    while ct.n_demonstrations < 8:
        ct.step()
    ct.close()
    refits = sorted(live)
    assert refits == list(range(1, 9))
    assert _checkpoint_numbers(run) == [7, 8]
    rebuilt = load_model(run, n_demonstrations=3).state_dict()
    assert all(torch.equal(rebuilt[k], live[3][k]) for k in rebuilt)


def test_pruning_leaves_a_checkpoint_linked_by_hand_and_what_it_links_to(tmp_path):
    """A checkpoint a person moved elsewhere and linked back (``model-<n>.pt`` a symlink to,
    say, an archive) is not one the writer wrote: pruning removes the writer's files alone,
    so the link stays (removing it would free nothing) and its target is never touched."""
    run = tmp_path / "run"
    ct = make_kept(rare_regions_world(), run, keep_checkpoints=2)
    while ct.n_demonstrations < 2:
        ct.step()
    archive = tmp_path / "archive" / "model-00000002.pt"
    archive.parent.mkdir()
    link = run / "checkpoints" / archive.name
    os.replace(link, archive)
    link.symlink_to(archive)
    saved = archive.read_bytes()
    while ct.n_demonstrations < 10:
        ct.step()
    ct.close()
    assert archive.read_bytes() == saved
    assert link.is_symlink() and link.resolve() == archive.resolve()
    assert _checkpoint_numbers(run) == [2, 8, 10]  # the newest 2, and the link


def test_checkpoints_that_cannot_be_removed_are_warned_of_once_and_the_session_goes_on(
    tmp_path, monkeypatch
):
    """An old checkpoint that cannot be removed (no permission) stays, harmless: one
    UserWarning names the first such file, the later ones are not reported again, and the
    session goes on with nothing lost."""
    real_unlink = Path.unlink

    def refuse_checkpoints(self, missing_ok=False):
        if self.parent.name == "checkpoints" and self.name.startswith("model-"):
            raise PermissionError(13, "Permission denied", str(self))
        return real_unlink(self, missing_ok=missing_ok)

    run = tmp_path / "run"
    ct = make_kept(rare_regions_world(), run, keep_checkpoints=1)
    ct.step()  # the session made first (its start clears leftovers with unlink too)
    monkeypatch.setattr(Path, "unlink", refuse_checkpoints)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        while ct.n_demonstrations < 10:  # refits at 2, 4, ..., 10: four prunes refused
            ct.step()
        ct.close()
    said = [w for w in caught if "could not remove" in str(w.message)]
    assert len(said) == 1, [str(w.message) for w in said]
    assert said[0].category is UserWarning
    assert str(run / "checkpoints" / "model-00000002.pt") in str(said[0].message)
    assert _checkpoint_numbers(run) == [2, 4, 6, 8, 10]  # every one still there
    assert load_records(run) == ct.records
    assert len(load_demonstrations(run)[1]) == 10


def test_a_checkpoint_gone_since_the_listing_is_passed_over_without_a_note(tmp_path, monkeypatch):
    """A checkpoint listed in checkpoints/ but removed before it is read (a running writer's
    pruning) is no damaged file: describe notes nothing about it and reports the next older
    checkpoint, and load_model gives the loop's model."""
    import torchcbl.session as session

    run = tmp_path / "run"
    ct = make_kept(rare_regions_world(), run, keep_checkpoints=None)
    while ct.n_demonstrations < 10:
        ct.step()
    ct.close()
    assert _checkpoint_numbers(run) == [2, 4, 6, 8, 10]
    gone = run / "checkpoints" / "model-00000010.pt"
    gone.unlink()
    listed = session._checkpoint_entries

    def listed_before_it_went(directory):
        entries = listed(directory)
        if directory == gone.parent and gone not in [p for _, p in entries]:
            entries.append((10, gone))
        return entries

    monkeypatch.setattr(session, "_checkpoint_entries", listed_before_it_went)
    summary = session.describe(run)
    assert summary.n_labels == 10 and summary.last_checkpoint == 8
    assert not [n for n in summary.notes if gone.name in n], summary.notes
    assert same_state(load_model(run), ct.model)


def test_steps_not_yet_in_sqlite_are_in_the_journal_and_readers_see_them(tmp_path):
    run = tmp_path / "run"
    ct = make(rare_regions_world(), run, noninteractive=False, max_new=4)
    ct._store.commit_every = 10**6  # keep everything in the journal: a writer mid-batch
    for _ in range(25):
        ct.step()
    db = sqlite3.connect(run / "steps.sqlite")
    assert db.execute("SELECT COUNT(*) FROM steps").fetchone()[0] == 0  # nothing committed
    db.close()
    assert (run / "steps.journal").stat().st_size > 0
    assert load_records(run) == ct.records  # the journal's lines, read back exactly
    x, y = load_demonstrations(run)
    assert len(y) == ct.n_demonstrations
    # a line torn by a kill mid-write (no newline) was never acknowledged: ignored
    with open(run / "steps.journal", "ab") as f:
        f.write(b'["s",25,0,"00')
    assert load_records(run) == ct.records
    ct.flush()  # a commit moves the rows to SQLite and empties the journal
    assert (run / "steps.journal").stat().st_size == 0
    assert load_records(run) == ct.records


def test_resume_same_counters_and_model(tmp_path):
    run = tmp_path / "run"
    ct = make(rare_regions_world(), run, accuracy_window=10, max_new=3)
    ct.run(max_steps=90)
    ct.close()
    back = ConfidentTeacher.resume(
        run, rare_regions_world(), oracle(rare_regions_world()), progress=False
    )
    assert back.records == ct.records
    for name in ("n_demonstrations", "autonomy_rate", "windowed_accuracy", "phase", "n_steps"):
        assert getattr(back, name) == getattr(ct, name), name
    assert same_state(back.model, ct.model)
    back.run(max_steps=150)
    assert back.records[90].episode == ct.records[-1].episode + 1  # resumed into a new episode
    assert [r.step for r in load_records(run)] == list(range(150))
    assert_model_is_fit_on_log(back.model, run)


def test_a_session_stopped_at_its_first_request_resumes_as_it_would_have_gone_on(tmp_path):
    """Nothing logged yet (the person stopped at the first request, or the process was killed
    there): the resumed session's first reset is the new session's (seeded with its seed), so
    it teaches exactly what the session would have taught uninterrupted. It was seeded from
    (seed, episode 0) and started from another observation."""
    from torchcbl import TeachingInterrupted

    def stops_at_once(obs, info):
        raise TeachingInterrupted("not now")

    config = dict(max_new=1, accuracy_window=10, target_accuracy=0.8)
    ref = make(rare_regions_world(), tmp_path / "ref", seed=7, **config)
    ref.run(max_steps=60)
    run = tmp_path / "run"
    ct = make(rare_regions_world(), run, teacher=stops_at_once, seed=7, **config)
    with pytest.raises(TeachingInterrupted):
        ct.run(max_steps=60)
    ct.close()
    assert load_records(run) == []
    env = rare_regions_world()
    back = ConfidentTeacher.resume(run, env, oracle(env), progress=False)
    back.run(max_steps=60)
    assert back.records == ref.records
    assert same_state(back.model, ref.model)


def test_a_session_written_before_refit_growth_resumes_with_a_given_model(tmp_path):
    """Model arguments added later (refit_growth) take their default for an older session, so
    resuming it with an explicitly built model of the same settings is not a mismatch; a model
    that differs in such an argument still is."""
    from torchcbl import GaussianMixtureSet

    run = tmp_path / "run"
    ct = make(rare_regions_world(), run, max_new=3)
    ct.run(max_steps=40)
    ct.close()
    config = json.loads((run / "config.json").read_text())
    args = dict(config["model"]["args"])
    del config["model"]["args"]["refit_growth"]
    (run / "config.json").write_text(json.dumps(config))
    env = rare_regions_world()
    back = ConfidentTeacher.resume(
        run, env, oracle(env), model=GaussianMixtureSet(**args), progress=False
    )
    assert same_state(back.model, ct.model)
    back.close()
    other = {**args, "refit_growth": args["refit_growth"] * 2}
    with pytest.raises(IncompatibleRunDirError, match="model args"):
        ConfidentTeacher.resume(run, env, oracle(env), model=GaussianMixtureSet(**other))


def test_a_session_written_before_n_init_resumes_and_loads_as_n_init_1(tmp_path):
    """config.json keeps the model's n_init only where it is not the default 1: a plain
    session's config is the one written before n_init existed (which an older torchcbl, whose
    GaussianMixtureSet takes no n_init, reads). Such a session resumes and loads as n_init=1,
    the fit it was taught with, with or without a model given; a model of another n_init is
    refused. A session taught with n_init=3 keeps it, and is rebuilt and resumed with
    n_init=3."""
    from torchcbl import GaussianMixtureSet

    run = tmp_path / "run"
    ct = make(rare_regions_world(), run, max_new=3)
    ct.run(max_steps=40)
    ct.close()
    config = json.loads((run / "config.json").read_text())
    args = dict(config["model"]["args"])
    assert ct.model.n_init == 1 and "n_init" not in args
    assert "refit_growth" in args  # kept, as before n_init existed
    assert load_model(run).n_init == 1 and same_state(load_model(run), ct.model)
    assert build_model(load_config(run)).n_init == 1
    env = rare_regions_world()
    for model in (None, GaussianMixtureSet(**args)):
        back = ConfidentTeacher.resume(run, env, oracle(env), model=model, progress=False)
        assert back.model.n_init == 1 and same_state(back.model, ct.model)
        back.close()
    with pytest.raises(IncompatibleRunDirError, match=r"'n_init': \(1, 2\)"):
        ConfidentTeacher.resume(
            run, env, oracle(env), model=GaussianMixtureSet(**{**args, "n_init": 2})
        )

    three = tmp_path / "three"
    env = rare_regions_world()
    d, n_actions = env.observation_space.shape[0], int(env.action_space.n)
    model = GaussianMixtureSet(n_actions, d, seed=0, n_init=3)
    ct = ConfidentTeacher(
        env, oracle(env), model=model, config=TeachingConfig(max_new=3), run_dir=three,
        progress=False,
    )  # fmt: skip
    ct.run(max_steps=40)
    ct.close()
    assert load_config(three)["model"]["args"]["n_init"] == 3
    loaded = load_model(three)
    assert loaded.n_init == 3 and same_state(loaded, ct.model)
    back = ConfidentTeacher.resume(three, env, oracle(env), progress=False)
    assert back.model.n_init == 3 and same_state(back.model, ct.model)
    back.close()


def test_stale_checkpoint_is_refitted_from_the_log(tmp_path):
    run = tmp_path / "run"
    ct = make(rare_regions_world(), run, noninteractive=False)
    ct.run(max_steps=60)
    ct.close()
    last = max((run / "checkpoints").iterdir())
    last.unlink()
    back = ConfidentTeacher.resume(
        run, rare_regions_world(), oracle(rare_regions_world()), progress=False
    )
    assert same_state(back.model, ct.model)
    assert same_state(load_model(run), ct.model)


def test_existing_or_incompatible_run_dir_is_a_clear_error(tmp_path):
    run = tmp_path / "run"
    env = rare_regions_world()
    make(env, run, max_new=2).run(max_steps=20)
    with pytest.raises(IncompatibleRunDirError, match="already holds a teaching session"):
        make(env, run)
    with pytest.raises(IncompatibleRunDirError, match="features"):
        ConfidentTeacher.resume(run, overlap_world(), oracle(overlap_world()))
    with pytest.raises(IncompatibleRunDirError, match="max_new"):
        ConfidentTeacher.resume(run, env, oracle(env), config=TeachingConfig(max_new=3))
    with pytest.raises(IncompatibleRunDirError, match="rule"):
        ConfidentTeacher.resume(run, env, oracle(env), rule=PosteriorRule())
    with pytest.raises(IncompatibleRunDirError, match="model args") as err:
        ConfidentTeacher.resume(run, env, oracle(env), model=GaussianMixtureSet(3, 2, 4))
    assert "{'max_components': (10, 4)}" in str(err.value)  # only what differs
    from torchcbl.session import restore_model

    with pytest.raises(ValueError, match="max_new must be an int >= 1"):
        restore_model(run, GaussianMixtureSet(3, 2, 4), [], [], max_new=0, relabel=False)
    with pytest.raises(IncompatibleRunDirError, match="is a file"):
        make(env, run / "config.json")  # a file where a directory should be
    with pytest.raises(IncompatibleRunDirError, match=f"directory: {run / 'config.json'} is a"):
        make(env, run / "config.json" / "below" / "deeper")  # the file named, not the path
    with pytest.raises(IncompatibleRunDirError, match="nowhere does not exist"):
        ConfidentTeacher.resume(tmp_path / "nowhere", env, oracle(env))
    # Stop fields may change; the failed attempts did not touch the session.
    back = ConfidentTeacher.resume(
        run, env, oracle(env), config=TeachingConfig(max_new=2, max_steps=25), progress=False
    )
    back.run()
    assert back.n_steps == 25


@pytest.mark.parametrize(
    "answer", [7, -1, 1.0, None, "1", True], ids=["big", "neg", "float", "none", "str", "bool"]
)
def test_teacher_invalid_action_is_clear_and_harmless(tmp_path, answer):
    run = tmp_path / "run"
    env = rare_regions_world()
    good = oracle(env)
    state = {"bad": False}

    def teacher(obs, info):
        return answer if state["bad"] else good(obs, info)

    ct = make(env, run, teacher)
    ct.run(max_steps=5)
    state["bad"] = True
    with pytest.raises(TeacherError, match=r"expected an int action in \[0, 3\)"):
        ct.run(max_steps=10)
    assert ct.n_steps == 5 and load_records(run) == ct.records
    state["bad"] = False
    ct.run(max_steps=10)  # the same session goes on
    assert [r.step for r in load_records(run)] == list(range(10))


def test_teacher_raising_is_clear_and_resumable(tmp_path):
    run = tmp_path / "run"
    env = rare_regions_world()
    calls = {"n": 0}

    def teacher(obs, info):
        calls["n"] += 1
        if calls["n"] == 8:
            raise KeyError("joystick unplugged")
        return env.optimal_action(obs)

    ct = make(env, run, teacher)
    with pytest.raises(TeacherError, match="joystick unplugged") as err:
        ct.run(max_steps=20)
    assert isinstance(err.value.__cause__, KeyError)
    assert ct.n_steps == 7 and load_records(run) == ct.records
    ct.close()
    back = ConfidentTeacher.resume(run, env, teacher, progress=False)
    back.run(max_steps=20)
    assert back.n_steps == 20


@pytest.mark.parametrize("mode", ["nan", "raise"])
def test_env_failure_mid_step_keeps_the_log_resumable(tmp_path, mode):
    run = tmp_path / "run"
    env = FaultyWorld(rare_regions_world(), fail_at=12, mode=mode)
    ct = make(env, run, oracle(env.unwrapped), noninteractive=False)
    match = "non-finite" if mode == "nan" else "simulator connection lost"
    with pytest.raises(EnvError, match=match):
        ct.run(max_steps=40)
    bad = ct.records[-1]
    assert bad.step == 11 and bad.truncated and "torchcbl_error" in bad.info
    assert (bad.reward is None) == (mode == "raise")
    assert load_records(run) == ct.records
    cut = ct.n_episodes  # the cut episode counts, as a resume counts it (max_episodes)
    assert cut == sum(r.terminated or r.truncated for r in ct.records) >= 1
    ct.run(max_steps=40)  # goes on in a fresh episode
    assert ct.records[12].episode == bad.episode + 1
    assert all(np.isfinite(r.observation).all() for r in ct.records)
    ct.close()
    back = ConfidentTeacher.resume(
        run, rare_regions_world(), oracle(rare_regions_world()), progress=False
    )
    assert back.records == ct.records
    assert back.n_episodes == ct.n_episodes


def test_a_failed_refit_still_lets_the_strategy_see_its_step(tmp_path):
    """The step whose refit raised is logged; the strategy is told of it as a resume would
    tell it, so the live session goes on as the resumed one (here DAgger's coins)."""
    from torchcbl.strategies.dagger import DAgger

    def session(run_dir, fail):
        env = rare_regions_world(episode_length=10)
        calls = []

        def on_refit(model, n):
            calls.append(n)
            if fail and len(calls) == 2:
                raise RuntimeError("callback failed")

        ct = ConfidentTeacher(
            env,
            oracle(env),
            strategy=DAgger(beta0=0.5, decay=1.0, iteration_steps=5, seed=3),
            config=TeachingConfig(max_new=2),
            run_dir=run_dir,
            on_refit=on_refit,
            progress=False,
        )
        if fail:
            with pytest.raises(RuntimeError, match="callback failed"):
                ct.run(max_steps=30)
        ct.run(max_steps=30)
        ct.close()
        return [(r.teacher_action is None, r.actor) for r in load_records(run_dir)]

    assert session(tmp_path / "a", fail=True) == session(tmp_path / "b", fail=False)


def _check_nothing_lost(run: Path, side_log: Path) -> int:
    """Every demonstration whose action reached the env is in the log; returns #demos."""
    records = {r.step: r for r in load_records(run)}
    taught, executed = {}, {}
    for line in side_log.read_text(encoding="utf-8").splitlines():
        kind, step, action = line.split()
        (taught if kind == "T" else executed)[int(step)] = int(action)
    for step, action in executed.items():
        if step in taught:
            assert step in records, f"demonstration at step {step} was executed but is lost"
            assert records[step].teacher_action == taught[step] == action
    assert sorted(records) == list(range(len(records)))  # a prefix, no holes
    return sum(r.is_demonstration for r in records.values())


def _kill_cycle(run: Path, side_log: Path, delay: float, mode: str = "ce") -> None:
    proc = subprocess.Popen(
        [sys.executable, str(TESTS / "_toy_envs.py"), str(run), str(side_log), mode],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = proc.stdout.readline()
        assert line.strip() == "ready", proc.stderr.read()
        time.sleep(delay)
        assert proc.poll() is None, proc.stderr.read()
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert proc.returncode == -signal.SIGKILL


def test_sigkill_at_random_instants_then_resume_loses_nothing(tmp_path):
    run = tmp_path / "run"
    rng = random.Random(7)
    n_demos = []
    for i in range(4):
        side = tmp_path / f"side{i}.log"
        _kill_cycle(run, side, rng.uniform(0.05, 0.6))
        n_demos.append(_check_nothing_lost(run, side))
    assert n_demos == sorted(n_demos) and n_demos[-1] > n_demos[0]
    env = overlap_world(episode_length=25)
    back = ConfidentTeacher.resume(run, env, oracle(env), rule=PosteriorRule(0.9), progress=False)
    assert back.n_demonstrations == n_demos[-1]
    assert_model_is_fit_on_log(back.model, run)
    back.run(max_steps=back.n_steps + 30)
    assert [r.step for r in load_records(run)] == list(range(back.n_steps))


def test_a_refit_by_hand_is_honoured_by_resume_and_load_model(tmp_path):
    """refit() at a count off the max_new schedule: resume and load_model rebuild the model
    the live loop had, not the one the plain schedule would give."""
    run = tmp_path / "run"
    ct = make(rare_regions_world(), run, noninteractive=False, max_new=5)
    ct.run(max_demonstrations=7)
    assert ct.refit()  # by hand, at 7
    ct.run(max_demonstrations=13)  # the loop refits at 12
    assert ct.n_demonstrations == 13
    live = copy.deepcopy(ct.model)
    ct.close()
    assert int(live.n_points_.sum()) == 12
    assert same_state(load_model(run), live)
    back = ConfidentTeacher.resume(
        run, rare_regions_world(), oracle(rare_regions_world()), progress=False
    )
    assert same_state(back.model, live)
    # and the schedule goes on from 12: the next refit is at 17
    back.run(max_demonstrations=16)
    assert int(back.model.n_points_.sum()) == 12
    back.run(max_demonstrations=17)
    assert int(back.model.n_points_.sum()) == 17


def test_load_model_at_a_count_of_labels(tmp_path):
    run = tmp_path / "run"
    ct = make(rare_regions_world(), run, noninteractive=False, max_new=5)
    ct.run(max_demonstrations=13)
    ct.close()
    assert int(load_model(run, n_demonstrations=7).n_points_.sum()) == 5  # refitted at 5
    assert int(load_model(run, n_demonstrations=np.int64(10)).n_points_.sum()) == 10
    assert not load_model(run, n_demonstrations=0).is_fitted
    for bad in (-1, 14, 2.7, "3", True):
        with pytest.raises(ValueError, match=r"expected an int from 0 to 13 .*got"):
            load_model(run, n_demonstrations=bad)


def test_snapshot_leaves_the_session_alone(tmp_path):
    ct = make(rare_regions_world(), None, noninteractive=False, max_new=5)
    ct.run(max_demonstrations=7)
    before = copy.deepcopy(ct.model)
    snap = ct.snapshot()
    assert int(snap.n_points_.sum()) == 7 and int(ct.model.n_points_.sum()) == 5
    assert same_state(ct.model, before)
    ct.run(max_demonstrations=10)
    assert int(ct.model.n_points_.sum()) == 10  # the schedule was not moved


def test_a_failing_refit_leaves_a_whole_step(tmp_path):
    run = tmp_path / "run"
    calls = []

    def on_refit(model, n):
        calls.append(n)
        if len(calls) == 2:
            raise RuntimeError("refit callback failed")

    ct = ConfidentTeacher(
        rare_regions_world(),
        oracle(rare_regions_world()),
        config=TeachingConfig(noninteractive=False, max_new=2),
        run_dir=run,
        progress=False,
        on_refit=on_refit,
    )
    with pytest.raises(RuntimeError, match="callback failed"):
        ct.run(max_steps=50)
    n = ct.n_steps
    assert n == len(ct.records) and ct.records[-1].reward is not None  # the step is complete
    ct.run(max_steps=n + 10)  # and the session simply goes on
    assert [r.step for r in ct.records] == list(range(n + 10))
    ct.close()
    assert [r.step for r in load_records(run)] == list(range(n + 10))


def test_a_refit_cut_short_is_done_first_at_the_next_step(tmp_path):
    """Ctrl-C inside a refit: the next step refits on the labels the refit was due on, so the
    live model stays the one load_model and a resume rebuild (the schedule does not slip)."""
    from torchcbl import GaussianMixtureSet
    from torchcbl.session import load_model

    env = rare_regions_world(episode_length=10)
    model = GaussianMixtureSet(3, 2, 3, seed=0)
    fitted_on, original = [], model.fit

    def fit(x, y):
        fitted_on.append(len(y))
        if len(fitted_on) == 2:
            raise KeyboardInterrupt
        return original(x, y)

    model.fit = fit
    ct = ConfidentTeacher(
        env,
        oracle(env),
        model=model,
        config=TeachingConfig(max_new=4),
        run_dir=tmp_path / "r",
        progress=False,
    )
    with pytest.raises(KeyboardInterrupt):
        ct.run(max_steps=30)
    ct.run(max_steps=30)
    ct.close()
    assert fitted_on[:4] == [4, 8, 8, 12]  # the owed refit, on the 8 labels it was due on
    rebuilt = load_model(tmp_path / "r")
    for name, t in ct.model.state_dict().items():
        assert torch.equal(t, rebuilt.state_dict()[name]), name


def test_a_session_that_could_not_be_created_leaves_no_half_session(tmp_path, monkeypatch):
    import torchcbl.session as session_module
    from torchcbl.errors import SessionWriteError

    run = tmp_path / "r"
    real_write = session_module.write_json_atomic

    def write_then_block(path, data):  # config.json written, then a file where the
        real_write(path, data)  # checkpoint folder goes: the store cannot open the session
        (run / "checkpoints").write_text("")

    monkeypatch.setattr(session_module, "write_json_atomic", write_then_block)
    env = rare_regions_world()
    with pytest.raises(SessionWriteError):
        ConfidentTeacher(env, oracle(env), run_dir=run, progress=False)
    monkeypatch.undo()
    assert not (run / "config.json").exists() and not (run / "steps.sqlite").exists()
    (run / "checkpoints").unlink()
    ct = ConfidentTeacher(env, oracle(env), run_dir=run, progress=False)  # starts afresh
    ct.run(max_steps=3)
    ct.close()
    assert len(load_records(run)) == 3


def test_a_fitted_starting_model_that_cannot_be_saved_leaves_no_half_session(tmp_path, monkeypatch):
    """A session may start from a fitted model, kept as checkpoint 0. When that checkpoint
    could not be written (disk full), the error said the session was intact and a missing
    checkpoint is refitted from the log; but with no label logged there is nothing to refit
    on: creating the teacher again said the directory held a session, and its resume started
    from an unfitted model, the starting model lost. Nothing is recorded at that point, so
    the directory is now left without a session and creating the teacher again starts it."""
    import errno

    from torchcbl.errors import SessionWriteError

    env = rare_regions_world()
    x, y = env.sample(300, np.random.default_rng(0))
    fitted = GaussianMixtureSet(3, 2, seed=0).fit(x, y)
    run = tmp_path / "r"
    real_save = torch.save

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(torch, "save", full)
    with pytest.raises(SessionWriteError, match="No space left") as err:
        ConfidentTeacher(env, oracle(env), model=fitted, run_dir=run, progress=False)
    assert "left without a session" in "\n".join(getattr(err.value, "__notes__", []))
    assert sorted(p.name for p in run.iterdir()) == ["writer.lock"]
    monkeypatch.setattr(torch, "save", real_save)
    ct = ConfidentTeacher(env, oracle(env), model=fitted, run_dir=run, progress=False)
    ct.close()
    assert load_model(run).is_fitted and same_state(load_model(run), fitted)
    back = ConfidentTeacher.resume(run, env, oracle(env), progress=False)
    assert back.model.is_fitted
    back.close()


def test_a_full_disk_while_creating_the_log_is_a_write_error_not_a_corrupt_file(
    tmp_path, monkeypatch
):
    import sqlite3

    import torchcbl.session as session_module
    from torchcbl.errors import SessionWriteError

    def full(*args, **kwargs):
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(session_module.sqlite3, "connect", full)
    env = rare_regions_world()
    with pytest.raises(SessionWriteError, match="Free space"):
        ConfidentTeacher(env, oracle(env), run_dir=tmp_path / "r", progress=False)
    assert not (tmp_path / "r" / "config.json").exists()  # no half session left behind


def test_a_reader_racing_a_short_writer_reads_again(tmp_path, monkeypatch):
    """A reader that opened a closed session (immutable, no WAL) while a writer then resumed,
    committed and closed (checkpointing into the log, deleting its WAL) reads the log again
    instead of returning what it had read before the writer's commits."""
    import torchcbl.session as session_module

    run = tmp_path / "r"
    env = rare_regions_world()
    ct = ConfidentTeacher(env, oracle(env), run_dir=run, progress=False)
    ct.run(max_steps=5)
    ct.close()
    original, calls = session_module._rows, []

    def rows_then_a_writer(*args):
        out = original(*args)
        calls.append(1)
        if len(calls) == 1:  # the reader's first read (the writer's own reads come after)
            env2 = rare_regions_world()
            back = ConfidentTeacher.resume(run, env2, oracle(env2), progress=False)
            back.run(max_steps=8)
            back.close()
            assert not (run / "steps.sqlite-wal").exists()
        return out

    monkeypatch.setattr(session_module, "_rows", rows_then_a_writer)
    assert len(load_records(run)) == 8


def test_readers_say_what_is_wrong_with_a_path_that_is_no_session_directory(tmp_path, monkeypatch):
    """A file of a session, a file elsewhere, a path that does not exist and an empty directory
    are each refused with what they are, not all as 'config.json is missing'."""
    run = tmp_path / "run"
    make(rare_regions_world(), run, max_new=2).run(max_steps=10)
    for name in ("steps.sqlite", "config.json"):
        with pytest.raises(IncompatibleRunDirError) as err:
            load_records(run / name)
        msg = str(err.value)
        assert f"{run / name} is a file; expected a teaching session directory" in msg
        assert f"give the directory it is in, {str(run)!r}" in msg
        assert "missing" not in msg
    stray = tmp_path / "notes.txt"
    stray.write_text("x")
    with pytest.raises(IncompatibleRunDirError, match=r"notes\.txt is a file; expected a") as err:
        load_model(stray)
    assert "give the directory" not in str(err.value)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(IncompatibleRunDirError) as err:
        load_records("runs/nowhere")
    msg = str(err.value)
    assert "runs/nowhere does not exist" in msg and f"working directory, {tmp_path}" in msg
    with pytest.raises(IncompatibleRunDirError, match="'~' is not expanded"):
        load_records("~/runs/nowhere-at-all")
    (tmp_path / "empty").mkdir()
    with pytest.raises(IncompatibleRunDirError, match="empty is not a teaching session directory"):
        load_records(tmp_path / "empty")
    assert load_records(run) == load_records(str(run) + "/")  # a session still reads


def test_readers_given_a_directory_of_sessions_name_the_sessions_in_it(tmp_path):
    """load_records("runs/reproduce/corridor"), a reproduction's run directory whose sessions are
    in sessions/seed<k>, said "config.json is missing. Start a session with
    ConfidentTeacher(..., run_dir=...) first": advice to teach anew, for a directory that holds
    the sessions asked for. It names them (as torchcbl evaluate does) and says to pass one."""
    run = tmp_path / "corridor"
    for seed in (0, 1):
        make(rare_regions_world(), run / "sessions" / f"seed{seed}", max_new=2).run(
            max_steps=3
        ).close()
    for reader in (load_records, load_model, load_demonstrations):
        with pytest.raises(IncompatibleRunDirError) as err:
            reader(run)
        msg = str(err.value)
        assert f"{run} is not a teaching session directory but holds sessions: " in msg, msg
        assert f"{run / 'sessions' / 'seed0'}, {run / 'sessions' / 'seed1'}; pass one" in msg
        assert "ConfidentTeacher" not in msg
    with pytest.raises(IncompatibleRunDirError) as err:
        ConfidentTeacher.resume(run, rare_regions_world(), lambda o, i: 0)
    assert "holds sessions" in str(err.value)


def test_a_session_without_labels_reads_them_as_zero_rows_of_its_features(tmp_path):
    """load_labels and load_demonstrations of a session with no label are [0, D], D the
    session's feature count, so they stack with another session's (they were [0, 0])."""
    from torchcbl.session import load_labels

    rng = np.random.default_rng(0)
    x = rng.normal(size=(300, 2))
    fitted = GaussianMixtureSet(3, 2, seed=0).fit(x, (x[:, 0] > 0).astype(int) + (x[:, 1] > 1))
    env = rare_regions_world()
    quiet = tmp_path / "quiet"  # a fitted start and a rule that never asks: steps, no label
    with ConfidentTeacher(
        env,
        oracle(env),
        model=fitted,
        rule=DistanceRule(1e6),
        config=TeachingConfig(noninteractive=False, max_steps=15),
        run_dir=quiet,
        progress=False,
    ) as ct:
        ct.run()
    assert len(load_records(quiet)) == 15 and ct.n_demonstrations == 0
    empty = tmp_path / "empty"  # created and closed before its first step
    make(rare_regions_world(), empty, max_steps=5).close()
    taught = tmp_path / "taught"
    make(rare_regions_world(), taught, max_new=2).run(max_steps=20)
    for run in (quiet, empty):
        for xs, ys in (load_labels(run), load_demonstrations(run)):
            assert xs.shape == (0, 2) and xs.dtype == np.float64
            assert ys.shape == (0,) and ys.dtype == np.int64
    xs = np.concatenate([load_demonstrations(r)[0] for r in (quiet, taught, empty)])
    assert xs.shape == (len(load_demonstrations(taught)[1]), 2)


def test_records_keep_numpy_integers_as_ints_and_go_through_json():
    """StepRecord and CorrectionRecord took numpy integers as ints but kept them as numpy, so
    to_dict (and the step log) failed with 'Object of type int64 is not JSON serializable'."""
    from torchcbl.records import CorrectionRecord, StepRecord

    def step(i):
        return StepRecord(
            step=i(4),
            episode=i(1),
            observation=(0.5, -0.25),
            model_action=i(2),
            confidence=0.5,
            distance=1.2,
            posterior=(0.2, 0.3, 0.5),
            teacher_action=i(2),
            executed_action=i(2),
            phase="confident",
            autonomous=False,
            reward=1.0,
            terminated=False,
            truncated=False,
            n_demonstrations=i(3),
        )

    plain = step(int)
    for kind in (np.int64, np.int32, np.uint8):
        r = step(kind)
        assert r == plain and json.loads(json.dumps(r.to_dict())) == plain.to_dict()
        for name in ("step", "episode", "model_action", "teacher_action", "executed_action"):
            assert type(getattr(r, name)) is int
        assert type(r.n_demonstrations) is int
        assert type(r.with_outcome(0.0, True, False, {}).step) is int
        c = CorrectionRecord(
            step=kind(4),
            episode=kind(1),
            observation=(0.5,),
            executed_action=kind(0),
            action=kind(1),
        )
        assert c == CorrectionRecord(4, 1, (0.5,), 0, 1)
        assert all(type(v) is int for v in (c.step, c.episode, c.executed_action, c.action))
    with pytest.raises(ValueError, match=r"StepRecord\.step: expected an int >= 0"):
        step(np.float64)  # floats are still refused


def test_latest_checkpoint_of_a_path_that_is_no_session_is_an_error_not_none(tmp_path):
    """latest_checkpoint answered None ('no checkpoint') for a mistyped path or a file, where
    the other readers say what the path is."""
    from torchcbl.session import latest_checkpoint

    run = tmp_path / "run"
    make(rare_regions_world(), run, max_new=2).run(max_steps=40)
    n, path = latest_checkpoint(run)
    assert path == run / "checkpoints" / f"model-{n:08d}.pt" and n >= 2
    assert latest_checkpoint(run, at_most=1) is None  # a session without such a checkpoint
    with pytest.raises(IncompatibleRunDirError, match="does not exist"):
        latest_checkpoint(tmp_path / "rnu")
    with pytest.raises(IncompatibleRunDirError, match="is a file"):
        latest_checkpoint(run / "steps.sqlite")


def test_latest_checkpoint_refuses_an_at_most_that_is_no_count(tmp_path):
    """at_most="5" failed inside the comparison with TypeError "'<=' not supported between
    instances of 'int' and 'str'"; -1 answered None (no checkpoint) and 2.5 the checkpoint
    at 2, both without a word. Each is now a ValueError saying what at_most takes."""
    from torchcbl.session import latest_checkpoint

    run = tmp_path / "run"
    make(rare_regions_world(), run, max_new=2, keep_checkpoints=None).run(max_steps=40)
    for bad in ("5", -1, 2.5, True):
        with pytest.raises(ValueError, match=r"at_most must be None .* or an int >= 0"):
            latest_checkpoint(run, at_most=bad)
    assert latest_checkpoint(run, at_most=np.int64(2)) == (
        2,
        run / "checkpoints" / "model-00000002.pt",
    )
    assert latest_checkpoint(run, at_most=0) is None


# -- gymnasium.make arguments that are objects -------------------------------------------------


@dataclasses.dataclass(frozen=True)
class _Reach:
    """A toy env's settings, a frozen dataclass as the domains' are."""

    n: int = 6
    start: tuple[int, ...] = (0, 1)


@dataclasses.dataclass(frozen=True)
class _Layout:
    reach: _Reach
    name: str = "x"


@dataclasses.dataclass
class _Loose:  # not frozen: it may change after make, so it is kept only as text
    n: int = 6


class _Reacher(gym.Env):
    """Walk right to the end of ``reach.n`` cells."""

    def __init__(self, reach: _Reach | None = None, layout: Any = None, loose: Any = None):
        self.reach = reach or _Reach()
        self.observation_space = gym.spaces.Box(0, self.reach.n, (1,), np.float32)
        self.action_space = gym.spaces.Discrete(2)
        self.x = 0.0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x = float(self.reach.start[0])
        return np.array([self.x], np.float32), {}

    def step(self, action):
        self.x = max(0.0, self.x + (1 if action == 1 else -1))
        done = self.x >= self.reach.n
        return np.array([self.x], np.float32), float(done), done, False, {}


_REACH_ID = "torchcbl_tests/Reacher-v0"
if _REACH_ID not in gym.registry:
    gym.register(_REACH_ID, entry_point=_Reacher)


def test_a_session_keeps_each_frozen_dataclass_make_argument_rebuildably(tmp_path):
    """An object given to gymnasium.make was kept only as its repr cut at 200 characters, so
    nothing could make the session's env again (a domain's evaluate drove other settings or
    refused). A frozen dataclass is now also kept as {"class", "fields"} (its init fields,
    nested dataclasses alike), which env_make_argument rebuilds with the classes it is given;
    the text stays beside it, and the session resumes as before."""
    from torchcbl.session import env_make_argument, env_make_arguments, kept_as_repr

    reach = _Reach(n=4, start=(1, 2))
    made = dict(reach=reach, layout=_Layout(reach, "mine"), loose=_Loose(3))
    run = tmp_path / "run"
    with ConfidentTeacher(
        gym.make(_REACH_ID, **made), lambda o, i: 1, run_dir=run, progress=False
    ) as ct:
        ct.run(max_steps=6)
    config = load_config(run)
    assert config["env"]["kwargs"]["reach"]["repr"].startswith("_Reach(n=4")  # as before
    assert kept_as_repr(config["env"]["kwargs"]["loose"])
    assert not any(map(kept_as_repr, (4, "text", {"repr": "x", "n": 1}, None)))
    builders = {f"{__name__}:_Reach": _Reach, f"{__name__}:_Layout": _Layout}
    assert env_make_argument(config, "reach", builders) == reach
    assert env_make_argument(config, "layout", builders) == _Layout(reach, "mine")
    assert env_make_argument(config, "absent", builders, default=7) == 7
    with pytest.raises(ValueError, match=r"loose given as an object \(_Loose\(n=3\)\), which"):
        env_make_argument(config, "loose", builders)
    with pytest.raises(ValueError, match=r"layout given as a .*:_Layout, which .*rebuilds only"):
        env_make_argument(config, "layout", {f"{__name__}:_Reach": _Reach})
    # all of them at once (what teach --resume makes the env with), and why each other not
    again, unknown = env_make_arguments(config, builders)
    assert again == {"reach": reach, "layout": _Layout(reach, "mine")}
    assert list(unknown) == ["loose"] and "loose given as an object" in unknown["loose"]
    # render_mode (drawing only: each caller picks its own) is left out unless asked for
    config["env"]["kwargs"]["render_mode"] = "human"
    assert env_make_arguments(config, builders) == (again, unknown)
    with_mode, _ = env_make_arguments(config, builders, skip=())
    assert with_mode == {**again, "render_mode": "human"}
    assert "reach" not in env_make_arguments(config, builders, skip=("reach",))[0]
    ConfidentTeacher.resume(
        run, gym.make(_REACH_ID, **made), lambda o, i: 1, progress=False
    ).close()


class _Kind(enum.IntEnum):
    A = 1


@dataclasses.dataclass(frozen=True)
class _Odd:
    """Settings the kept form cannot hold as they are: an enum, a namedtuple, a dict holding
    itself, a long table."""

    kind: Any = None
    pair: Any = None
    nest: Any = None
    table: tuple = ()


_Pair = collections.namedtuple("_Pair", "a b")


def test_a_make_argument_the_kept_form_cannot_hold_as_it_is_stays_text_only(tmp_path):
    """The kept form held an IntEnum as its int and a namedtuple as a list (rebuilt equal,
    so kept, but env_make_argument gave back an int and a tuple: code reading ``.name``
    broke); a dict holding itself raised RecursionError at the start of the session; a
    table of a million numbers was kept whole (seconds, megabytes of config.json). Each is
    now kept as text alone (env_make_argument refuses it in one line), and the session
    starts."""
    from torchcbl.session import env_make_argument

    loop: dict = {}
    loop["x"] = loop
    made = dict(
        kind=_Odd(kind=_Kind.A),
        pair=_Odd(pair=_Pair(1, 2)),
        nest=_Odd(nest=loop),
        table=_Odd(table=tuple(range(1_000_000))),
    )
    run = tmp_path / "run"
    env = gym.make(_REACH_ID)
    env.spec.kwargs.update(made)  # as gymnasium.make keeps them (the env takes none of them)
    with ConfidentTeacher(env, lambda o, i: 1, run_dir=run, progress=False) as ct:
        ct.run(max_steps=2)
    config = load_config(run)
    assert config["env"].get("kwargs_objects", {}) == {}
    assert (run / "config.json").stat().st_size < 20_000
    for name in made:
        with pytest.raises(ValueError, match=f"{name} given as an object"):
            env_make_argument(config, name, {f"{__name__}:_Odd": _Odd})
    # the text kept is cut at 200 characters: the message says it may be cut
    with pytest.raises(ValueError, match=r"table given as an object \(_Odd\(.{150,}\.\.\.\), "):
        env_make_argument(config, "table", {f"{__name__}:_Odd": _Odd})
