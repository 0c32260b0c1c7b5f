"""`torchcbl show` and torchcbl.session.describe: what a session directory holds, read-only."""

from __future__ import annotations

import hashlib
import json
import math
import shutil
from collections import Counter
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from _toy_envs import oracle, overlap_world, rare_regions_world

from torchcbl import ConfidentTeacher, TeachingConfig
from torchcbl.cli import main
from torchcbl.session import (
    SessionSummary,
    build_model,
    describe,
    load_config,
    load_corrections,
    load_demonstrations,
    load_labels,
    load_records,
)
from torchcbl.strategies import correcting
from torchcbl.strategies.cba import ConfidenceBasedAutonomy

CUT_AT = 37  # the env call a Ctrl-C lands in: step 36 is logged as interrupted


class _CtrlCAt(gym.Wrapper):
    """A Ctrl-C inside the env's ``at``-th step."""

    def __init__(self, env: gym.Env, at: int) -> None:
        super().__init__(env)
        self.at, self.calls = at, 0

    def step(self, action: int):
        self.calls += 1
        if self.calls == self.at:
            raise KeyboardInterrupt
        return self.env.step(action)


@pytest.fixture(scope="module")
def taught(tmp_path_factory) -> Path:
    """A CBA session with corrections, one step cut by a Ctrl-C, and a second writer (resume):
    150 steps of 1-D episodes of 10 steps."""
    run = tmp_path_factory.mktemp("show") / "run"
    world = overlap_world(episode_length=10)
    ct = ConfidentTeacher(
        _CtrlCAt(world, CUT_AT),
        correcting(oracle(world)),
        strategy=ConfidenceBasedAutonomy(),
        config=TeachingConfig(max_new=3, accuracy_window=10),
        run_dir=run,
        seed=0,
        progress=False,
    )
    with pytest.raises(KeyboardInterrupt):
        ct.run(max_steps=80)
    ct.close()
    world = overlap_world(episode_length=10)
    ct = ConfidentTeacher.resume(run, world, correcting(oracle(world)), progress=False)
    ct.run(max_steps=150)
    ct.close()
    return run


def _small_session(run: Path, steps: int = 20) -> None:
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        env, oracle(env), config=TeachingConfig(max_new=3), run_dir=run, seed=0, progress=False
    )
    ct.run(max_steps=steps)
    ct.close()


def _open_session(run: Path, steps: int) -> ConfidentTeacher:
    """A session left open after ``steps`` steps, every one in its journal and none committed
    to SQLite."""
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        env,
        oracle(env),
        config=TeachingConfig(max_new=3),
        run_dir=run,
        seed=0,
        progress=False,
        commit_every=10**6,
    )
    for _ in range(steps):
        ct.step()
    return ct


def _files_of(run: Path) -> dict[str, tuple[int, int, str]]:
    """{relative path: (mode, mtime_ns, sha256)} of every file and folder under ``run``."""
    return {
        str(p.relative_to(run)): (
            p.stat().st_mode,
            p.stat().st_mtime_ns,
            hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "",
        )
        for p in sorted([run, *run.rglob("*")])
    }


def test_describe_counts_what_the_log_holds(taught):
    records = load_records(taught)
    corrections = load_corrections(taught)
    _, labels = load_labels(taught)
    s = describe(taught)
    episodes = sorted({r.episode for r in records})
    assert episodes == list(range(len(episodes)))
    asked = Counter(r.episode for r in records if r.teacher_action is not None)
    assert s.n_steps == len(records) == 150
    assert s.n_episodes == len(episodes)
    assert s.n_episodes_ended == sum(1 for r in records if r.terminated or r.truncated)
    assert s.steps_per_episode == tuple(Counter(r.episode for r in records)[e] for e in episodes)
    assert s.requests_per_episode == tuple(asked[e] for e in episodes)
    assert s.n_requests == s.n_demonstrations == sum(asked.values())
    assert s.n_requests_confident == sum(
        1 for r in records if r.teacher_action is not None and r.phase == "confident"
    )
    assert 0 < s.n_requests_confident < s.n_requests  # both phases are in this session
    assert s.n_corrections == len(corrections) > 0
    assert s.n_labels == len(labels) == s.n_demonstrations + s.n_corrections
    assert s.n_autonomous == sum(r.autonomous for r in records) > 0
    assert s.n_interrupted == 1
    assert records[CUT_AT - 1].info == {"torchcbl_interrupted": True}
    assert s.block_steps == 100 and len(s.requests_per_block) == math.ceil(150 / 100)
    assert s.requests_per_block[0] == sum(1 for r in records[:100] if r.teacher_action is not None)
    assert sum(s.requests_per_block) == s.n_requests
    checkpoints = [int(p.stem.split("-")[1]) for p in (taught / "checkpoints").glob("model-*.pt")]
    assert s.last_checkpoint == max(checkpoints)
    writers = [json.loads(ln) for ln in (taught / "writers.jsonl").read_text().splitlines()]
    assert list(s.writers) == writers and [w["first_step"] for w in writers] == [0, CUT_AT]
    config = load_config(taught)
    assert s.format == config["format"] == "torchcbl.session/2"
    assert s.strategy == config["strategy"] and s.strategy["type"] == "ConfidenceBasedAutonomy"
    assert (s.model_class, s.model_args) == ("GaussianMixtureSet", config["model"]["args"])
    assert (s.n_features, s.n_actions, s.seed, s.n_prior) == (1, 2, 0, 0)
    assert s.env_id is None and s.env_kwargs == {}
    assert (s.state, s.writer_running, s.notes) == ("closed", False, ())
    assert s.last_writer is not None and s.last_writer.startswith("process ")


def test_show_prints_the_summary_and_the_same_fields_as_json(taught, capsys):
    s = describe(taught)
    assert main(["show", str(taught)]) == 0
    out = capsys.readouterr().out
    assert len(out.splitlines()) < 25  # one screen
    for text in (
        "ConfidenceBasedAutonomy(",
        f"{s.n_steps} in {s.n_episodes} episodes ({s.n_episodes_ended} ended); "
        f"{s.n_autonomous} autonomous",
        f"{s.n_labels} ({s.n_demonstrations} demonstrations, {s.n_corrections} corrections)",
        f"{s.n_requests} steps the teacher was asked",
        f"0: {s.requests_per_episode[0]}/{s.steps_per_episode[0]}, ",  # the first episodes
        f"{s.n_episodes - 1}: {s.requests_per_episode[-1]}/{s.steps_per_episode[-1]}\n",
        "interrupted: 1 step",
        "\nenv:        made directly (no gymnasium id), 1 feature, 2 actions\n",  # not "1 features"
        f"the newest fitted on {s.last_checkpoint} labels",
        f"from step {CUT_AT}: torch ",
        "closed by its last writer (process ",
    ):
        assert text in out, (text, out)
    assert main(["show", str(taught), "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown == s.to_dict()
    assert set(shown) == set(SessionSummary.__dataclass_fields__)
    assert shown["requests_per_episode"] == list(s.requests_per_episode)


def test_show_reads_a_read_only_session_and_changes_nothing(taught, tmp_path, capsys):
    """Closed, and killed with steps only in its journal: both read on a directory no one may
    write, every file, mode and mtime left as it was."""
    closed = tmp_path / "closed"
    shutil.copytree(taught, closed)
    killed = tmp_path / "killed"
    ct = _open_session(killed, steps=25)
    _as_if_killed(ct)
    for run in (closed, killed):
        for p in run.rglob("*"):
            p.chmod(0o444 if p.is_file() else 0o555)
        run.chmod(0o555)
    try:
        before = {run: _files_of(run) for run in (closed, killed)}
        assert main(["show", str(closed)]) == 0
        assert "150 in " in capsys.readouterr().out
        assert main(["show", str(killed), "--json"]) == 0
        shown = json.loads(capsys.readouterr().out)
        assert (shown["n_steps"], shown["state"]) == (25, "killed")
        assert describe(closed).to_dict() == {**describe(taught).to_dict(), "run_dir": str(closed)}
        assert {run: _files_of(run) for run in (closed, killed)} == before
    finally:
        for run in (closed, killed):
            for p in [run, *run.rglob("*")]:
                p.chmod(0o755 if p.is_dir() else 0o644)


def _as_if_killed(ct: ConfidentTeacher) -> None:
    """Leave the directory as a SIGKILL would: journal not committed, lock released (as
    tests/test_session_faults.py's crash())."""
    ct._store._release()
    ct._store = None


def test_show_says_whether_a_writer_holds_the_session_or_was_killed(tmp_path, capsys):
    run = tmp_path / "run"
    ct = _open_session(run, steps=25)
    s = describe(run)
    assert (s.state, s.writer_running, s.n_steps) == ("running", True, 25)
    assert main(["show", str(run)]) == 0
    assert "a writer holds it now (process " in capsys.readouterr().out
    _as_if_killed(ct)
    s = describe(run)
    assert (s.state, s.writer_running, s.n_steps) == ("killed", False, 25)
    assert main(["show", str(run)]) == 0
    assert "stopped without closing it (killed" in capsys.readouterr().out
    env = rare_regions_world(episode_length=10)
    back = ConfidentTeacher.resume(run, env, oracle(env), progress=False)
    back.run(max_steps=30)
    back.close()
    s = describe(run)
    assert (s.state, s.writer_running, s.n_steps, len(s.writers)) == ("closed", False, 30, 2)


def test_show_of_a_folder_lists_the_sessions_below_it(tmp_path, capsys):
    """A reproduction's layouts (corridor sessions/seed<k>; driving seed_<k>/sessions/arm_a, 4
    levels below the reproduction's --out) and a benchmark's OUT/sessions/<key>, one line each;
    a session that cannot be read is said so in its line."""
    sessions = [
        tmp_path / "corridor" / "sessions" / "seed0",
        tmp_path / "driving" / "seed_0" / "sessions" / "arm_a",
        tmp_path / "bench" / "sessions" / "0123abcd",
    ]
    for i, run in enumerate(sessions):
        _small_session(run, steps=20 + i)
    broken = tmp_path / "bench" / "sessions" / "broken"
    shutil.copytree(sessions[2], broken)
    (broken / "config.json").write_text("{not json")
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "config.json").write_text("{}")  # no steps.sqlite: not a session
    assert main(["show", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"{tmp_path} holds 4 teaching sessions:"
    assert len(lines) == 5
    for i, run in enumerate(sessions):
        (line,) = [ln for ln in lines if ln.startswith(f"{run}: ")]
        assert f", {20 + i} steps, " in line and "closed" in line, line
        assert ", seed 0, " in line, line  # (a benchmark's folders are hashes: say its seed)
    (line,) = [ln for ln in lines if ln.startswith(f"{broken}: ")]
    assert "cannot be read" in line and "config.json" in line
    assert main(["show", str(tmp_path), "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    by_dir = {e["run_dir"]: e for e in shown["sessions"]}
    assert set(by_dir) == {str(p) for p in [*sessions, broken]}
    assert by_dir[str(sessions[1])] == describe(sessions[1]).to_dict()
    assert "error" in by_dir[str(broken)]
    assert main(["show", str(tmp_path / "driving")]) == 0
    assert str(sessions[1]) in capsys.readouterr().out


@pytest.mark.parametrize("json_flag", [[], ["--json"]])
@pytest.mark.parametrize("what", ["empty", "missing", "file"])
def test_show_of_what_is_not_a_session_is_one_line_and_exit_2(tmp_path, capsys, what, json_flag):
    """An error is one line on stderr and exit 2, also with --json (no JSON is printed), as
    show's --help says."""
    folder = tmp_path / "folder"
    folder.mkdir()
    (folder / "results.json").write_text("{}")
    path = {"empty": folder, "missing": tmp_path / "nope", "file": folder / "results.json"}[what]
    assert main(["show", str(path), *json_flag]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    (line,) = captured.err.splitlines()
    assert line.startswith("torchcbl show: error: ") and str(path) in line
    assert "teaching session" in line
    with pytest.raises(SystemExit):
        main(["show", "--help"])
    assert "errors go to stderr as one line (exit 2), also with --json" in " ".join(
        capsys.readouterr().out.split()
    )


def test_show_reads_a_format1_session(tmp_path):
    from test_architecture import _downgrade_to_format1

    run = tmp_path / "run"
    _small_session(run, steps=30)
    want = describe(run)
    _downgrade_to_format1(run)
    got = describe(run)
    assert got.format == "torchcbl.session/1"
    assert got.strategy == {
        "type": "ConfidentExecution",
        "rule": load_config(run)["rule"],
        "relabel": False,
    }
    fields = ("n_steps", "n_labels", "n_requests", "n_autonomous", "requests_per_episode")
    assert [getattr(got, f) for f in fields] == [getattr(want, f) for f in fields]
    assert main(["show", str(run)]) == 0


def test_show_of_a_session_whose_checkpoints_cannot_be_listed(tmp_path, capsys, monkeypatch):
    """A ``checkpoints/`` this user may not list (another user's, mode 0o700): the folder's
    listing goes on and says so in that session's line; the session alone is one line on
    stderr and exit 2. (Tests run as root, who may list any directory, so listing it raises
    here what it raises for a user without read access.)"""
    import errno
    import os

    good, locked = tmp_path / "sessions" / "good", tmp_path / "sessions" / "locked"
    for run in (good, locked):
        _small_session(run)
    real_iterdir = Path.iterdir

    def iterdir(self: Path):
        if self == locked / "checkpoints":
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(self))
        return real_iterdir(self)

    monkeypatch.setattr(Path, "iterdir", iterdir)
    assert main(["show", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"{tmp_path} holds 2 teaching sessions:"
    (line,) = [ln for ln in lines if ln.startswith(f"{good}: ")]
    assert ", 20 steps, " in line
    (line,) = [ln for ln in lines if ln.startswith(f"{locked}: ")]
    assert "cannot be read" in line and str(locked / "checkpoints") in line
    assert main(["show", str(locked)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    (line,) = captured.err.splitlines()
    assert line.startswith("torchcbl show: error: ") and str(locked / "checkpoints") in line
    assert "permission denied" in line and "Traceback" not in captured.err


def test_show_of_a_folder_lists_every_session_when_one_fails_to_read(tmp_path, capsys, monkeypatch):
    """A file of one session the file system fails to read (an I/O error on its journal):
    that session's line says so and the others are listed still."""
    import errno
    import os

    good, failing = tmp_path / "sessions" / "good", tmp_path / "sessions" / "failing"
    for run in (good, failing):
        _small_session(run)
    real_stat = Path.stat

    def stat(self: Path, **kwargs):
        if self == failing / "steps.journal":
            raise OSError(errno.EIO, os.strerror(errno.EIO), str(self))
        return real_stat(self, **kwargs)

    monkeypatch.setattr(Path, "stat", stat)
    assert main(["show", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"{tmp_path} holds 2 teaching sessions:"
    (line,) = [ln for ln in lines if ln.startswith(f"{good}: ")]
    assert ", 20 steps, " in line
    (line,) = [ln for ln in lines if ln.startswith(f"{failing}: ")]
    assert "cannot be read" in line and os.strerror(errno.EIO) in line


def test_show_of_a_folder_names_the_folders_it_cannot_search(tmp_path, capsys, monkeypatch):
    """A folder below DIR this user may not list (another user's runs, mode 0o700): the
    sessions in it cannot be counted, so the listing says so rather than count fewer in
    silence. (Tests run as root, who may list any directory: listing it raises here what it
    raises for a user without read access.)"""
    import errno
    import os

    seen, hidden = tmp_path / "mine" / "sessions" / "seed0", tmp_path / "theirs" / "seed0"
    for run in (seen, hidden):
        _small_session(run)
    denied, real_scandir = tmp_path / "theirs", os.scandir

    def scandir(path=".", /):
        if isinstance(path, (str, os.PathLike)) and Path(path) == denied:
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
        return real_scandir(path)

    monkeypatch.setattr(os, "scandir", scandir)
    assert main(["show", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == (
        f"{tmp_path} holds 1 teaching session in the folders it could search (1 folder it "
        "could not, listed last):"
    )
    assert lines[1].startswith(f"{seen}: ")
    assert lines[2].startswith(f"{denied}: cannot be searched: ") and len(lines) == 3
    assert main(["show", str(tmp_path), "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert [e["run_dir"] for e in shown["sessions"]] == [str(seen)]
    assert [e["folder"] for e in shown["not_searched"]] == [str(denied)]
    monkeypatch.setattr(os, "scandir", real_scandir)
    assert main(["show", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"{tmp_path} holds 2 teaching sessions:" and len(lines) == 3


def test_show_of_a_lock_it_cannot_tie_to_the_session_says_running_or_killed(
    tmp_path, capsys, monkeypatch
):
    """An flock on writer.lock's inode number whose device is not the one stat gives (overlay,
    btrfs subvolumes report another) and whose process cannot be matched with writer.lock's
    note (/proc/locks shows pid 0 for a holder in another PID namespace): whether a writer
    runs cannot be told, so a session left unclosed is "running or killed", not "killed"."""
    import os

    run = tmp_path / "run"
    ct = _open_session(run, steps=25)
    _as_if_killed(ct)
    st = (run / "writer.lock").stat()
    major, minor = os.major(st.st_dev), os.minor(st.st_dev)

    def proc_locks(pid: int, device: tuple[int, int]) -> str:
        return (
            f"1: FLOCK  ADVISORY  WRITE {pid} {device[0]:02x}:{device[1]:02x}:{st.st_ino} 0 EOF\n"
        )

    real_read_text = Path.read_text

    def read_text(self: Path, *args, **kwargs) -> str:
        if self == Path("/proc/locks"):
            return locks
        return real_read_text(self, *args, **kwargs)

    monkeypatch.setattr(Path, "read_text", read_text)
    for locks, running, state in [
        ("", False, "killed"),  # no lock on it
        (proc_locks(os.getpid(), (major, minor)), True, "running"),
        (proc_locks(0, (major + 1, minor)), None, "running or killed"),
    ]:
        s = describe(run)
        assert (s.writer_running, s.state) == (running, state), locks
    assert main(["show", str(run)]) == 0
    assert "running or killed" in capsys.readouterr().out


def test_show_clips_the_last_block_to_the_last_step(tmp_path, capsys):
    """With fewer than 4 episodes show counts requests per block of steps; the last block's
    label ran to the block's end ("100-199" for a log of 150 steps), past the last step. It
    ends at the last step logged."""
    run = tmp_path / "run"
    env = rare_regions_world(episode_length=1000)
    ct = ConfidentTeacher(
        env, oracle(env), config=TeachingConfig(max_new=3), run_dir=run, seed=0, progress=False
    )
    ct.run(max_steps=150)
    ct.close()
    s = describe(run)
    assert (s.n_steps, s.n_episodes, s.block_steps) == (150, 1, 100)
    assert main(["show", str(run)]) == 0
    out = capsys.readouterr().out
    blocks = f"0-99: {s.requests_per_block[0]}, 100-149: {s.requests_per_block[1]}\n"
    assert f"per block of 100 steps (requests): {blocks}" in out, out


def test_show_names_a_strategy_and_rule_of_ones_own_once_each(tmp_path, capsys):
    """A strategy subclass with a rule subclass was shown as its stored dict, nesting
    custom=true twice and the parent's dict under inherited= ("MyCE(custom=true,
    inherited=ConfidentExecution(custom=true, ..., rule=MyRule(custom=true, inherited=..."):
    each class of one's own is now named once, with the class whose config it keeps, and the
    fields of that config."""
    from torchcbl.confidence import AutoThresholdRule
    from torchcbl.strategies import ConfidentExecution

    class MyRule(AutoThresholdRule):
        pass

    class MyCE(ConfidentExecution):
        pass

    run = tmp_path / "run"
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        env,
        oracle(env),
        strategy=MyCE(MyRule()),
        config=TeachingConfig(max_new=3),
        run_dir=run,
        seed=0,
        progress=False,
    )
    ct.run(max_steps=5)
    ct.close()
    assert main(["show", str(run)]) == 0
    (line,) = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("strategy:")]
    own = "test_show.test_show_names_a_strategy_and_rule_of_ones_own_once_each.<locals>"
    assert line == (
        f"strategy:   {own}.MyCE[custom, as ConfidentExecution](relabel=false, "
        f"rule={own}.MyRule[custom, as AutoThresholdRule](max_std=2.0, min_std=0.0))"
    ), line


# what is put in checkpoints/ beside a session's own (3, 6, ..., 18 of its 20 labels), and
# what show notes of it (None: no note: no reader takes it for a checkpoint)
_ODD_CHECKPOINTS = {
    "more-labels": ("model-00000099.pt", "names 99 labels, more than the 20 the log holds"),
    "directory": ("model-00000019.pt", "is a directory"),
    "empty": ("model-00000019.pt", "is an empty file"),
    "stale": ("model-00000019.pt", "is stale"),
    "killed-write": (".model-00000019.pt.tmp", None),
    "not-a-count": ("model-abc.pt", None),
}


@pytest.mark.parametrize("odd", list(_ODD_CHECKPOINTS))
def test_show_reports_the_checkpoint_resume_loads_not_the_newest_name(tmp_path, capsys, odd):
    """describe / `torchcbl show` took the newest name in checkpoints/ for the session's
    newest checkpoint: a model-00000099.pt of more labels than the log holds (which resume
    and load_model pass over), or a directory, an empty file or a stale checkpoint named as
    the newest (which resume sets aside as .damaged / .stale) were shown as "the newest fitted
    on N labels". It now reports the checkpoint resume loads (the newest readable one fitted
    on the log's labels) and notes each file resume passes over, what it is and what resume
    does with it; it still reads only. What no reader takes for a checkpoint (the .tmp of a
    killed write, model-abc.pt) is not mentioned. An empty file, which a writer never leaves
    but a checkpoint truncated to nothing is, still records by its name a refit on 19 labels
    (one asked by hand would be off the schedule): resume refits the model there, as its note
    says, and writes that model's checkpoint in its place. The one of more labels than the log
    holds resume sets aside as .stale, as its note says."""
    import torch

    run = tmp_path / "run"
    _small_session(run)
    ckpts = run / "checkpoints"
    newest = ckpts / "model-00000018.pt"
    assert sorted(p.name for p in ckpts.iterdir())[-1] == newest.name
    name, noted = _ODD_CHECKPOINTS[odd]
    path = ckpts / name
    if odd == "directory":
        path.mkdir()
    elif odd == "empty":
        path.touch()
    else:  # a complete model (stale: the one of 18 labels under the name of 19)
        shutil.copy(newest, path)
    before = _files_of(run)
    s = describe(run)
    assert s.last_checkpoint == 18
    notes = [n for n in s.notes if name in n]
    if noted is None:
        assert notes == [] and s.notes == ()
    else:
        (note,) = notes
        assert f"checkpoints/{name} {noted}" in note and "resume" in note, note
        if odd == "more-labels":
            assert f"resume renames it {name}.stale" in note, note
    assert main(["show", str(run)]) == 0
    out = capsys.readouterr().out
    assert "\ncheckpoint: the newest fitted on 18 labels\n" in out
    assert (noted is None) == ("note:" not in out)
    assert _files_of(run) == before  # show reads only
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher.resume(run, env, oracle(env), progress=False)
    state = ct.model.state_dict()  # resume loaded the checkpoint show reported
    ct.close()
    if odd == "empty":
        assert "records a refit on 19 labels" in note, note
        x, y = load_demonstrations(run)
        want = build_model(load_config(run)).fit(x[:19], y[:19]).state_dict()
    else:
        want = torch.load(newest, weights_only=True)["state_dict"]
    assert state.keys() == want.keys() and all(torch.equal(state[k], want[k]) for k in want)
    set_aside = odd in ("more-labels", "directory", "empty", "stale")
    assert path.with_name(path.name + ".damaged").exists() is (odd in ("directory", "empty"))
    # of labels the log lost: renamed, so no reader takes it for a refit once taught that far
    assert path.with_name(path.name + ".stale").exists() is (odd in ("more-labels", "stale"))
    # set aside, then (empty) the refit on 19 labels written in its place
    assert path.exists() is (not set_aside or odd == "empty")
    # what resume set aside is no checkpoint any more; what it passed over is still there
    assert (describe(run).notes == ()) is (noted is None or set_aside)


def _prior_session(run: Path, env, prior, *, steps: int) -> None:
    """A session in ``run`` begun from ``prior`` demonstrations (refit every 3 labels), taught
    ``steps`` steps (none: only its starting checkpoint) and closed."""
    with ConfidentTeacher(
        env,
        oracle(env),
        prior_demonstrations=prior,
        config=TeachingConfig(max_new=3),
        run_dir=run,
        seed=0,
        progress=False,
    ) as ct:
        if steps:
            ct.run(max_steps=steps)


def test_show_of_a_session_with_prior_demonstrations_reports_its_newest_checkpoint(tmp_path):
    """The checkpoints of a session with prior demonstrations carry the digest of the prior's
    labels and then the session's: show checks them as resume does, prior first."""
    env = rare_regions_world(episode_length=10)
    prior = env.sample(30, np.random.default_rng(1))
    run = tmp_path / "run"
    _prior_session(run, env, prior, steps=20)
    s = describe(run)
    assert (s.n_prior, s.n_labels, s.last_checkpoint, s.notes) == (30, 20, 18, ())


def test_show_says_the_checkpoints_of_a_session_with_prior_demonstrations_include_them(
    tmp_path, capsys
):
    """show said "checkpoint: the newest fitted on 0 labels" and "on disk: 1 (0 labels)" of a
    session started from prior demonstrations, whose every model was fitted on them too: it
    reads as an untrained model. The checkpoint lines add the prior."""
    env = rare_regions_world(episode_length=10)
    prior = env.sample(30, np.random.default_rng(1))
    runs = {0: tmp_path / "fresh", 20: tmp_path / "taught"}
    for steps, run in runs.items():
        _prior_session(run, env, prior, steps=steps)
    assert main(["show", str(runs[0])]) == 0
    out = capsys.readouterr().out
    assert "\ncheckpoint: the newest fitted on 0 labels + 30 prior demonstrations\n" in out, out
    assert "\n            on disk: 1 (0 labels + 30 prior demonstrations), " in out, out
    on_disk = describe(runs[20]).checkpoints_on_disk
    assert len(on_disk) > 1, on_disk
    assert main(["show", str(runs[20])]) == 0
    out = capsys.readouterr().out
    assert "\ncheckpoint: the newest fitted on 18 labels + 30 prior demonstrations\n" in out, out
    assert f"{on_disk[-1]} labels, each + 30 prior demonstrations), " in out, out
    _small_session(tmp_path / "plain")  # a session without a prior says labels alone
    assert main(["show", str(tmp_path / "plain")]) == 0
    out = capsys.readouterr().out
    assert "prior" not in out and " labels)" in out, out


def test_show_of_a_session_without_journal_whose_checkpoints_cannot_be_listed(
    tmp_path, capsys, monkeypatch
):
    """A session with no journal and no writers file (read as possibly left by a killed
    creation, which lists its ``checkpoints/``) whose ``checkpoints/`` this user may not list:
    the session alone is one line on stderr naming ``checkpoints/`` and exit 2, as for the
    other files of a session this user may not read; the folder's listing says the same in
    that session's line. (Tests run as root: listing it raises here what it raises for a
    user without read access.)"""
    import errno
    import os

    run = tmp_path / "sessions" / "locked"
    _small_session(run)
    for name in ("steps.journal", "writers.jsonl"):
        (run / name).unlink()
    assert main(["show", str(run)]) == 0  # readable as it is
    capsys.readouterr()
    real_iterdir = Path.iterdir

    def iterdir(self: Path):
        if self == run / "checkpoints":
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(self))
        return real_iterdir(self)

    monkeypatch.setattr(Path, "iterdir", iterdir)
    assert main(["show", str(run)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    (line,) = captured.err.splitlines()
    assert line.startswith("torchcbl show: error: ") and str(run / "checkpoints") in line
    assert "permission denied" in line and "Traceback" not in captured.err
    assert main(["show", str(tmp_path)]) == 0
    (line,) = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith(f"{run}: ")]
    assert "cannot be read by this user" in line and str(run / "checkpoints") in line


class _GmmWithMore:
    """The state of a model of another class: a GaussianMixtureSet subclass with a buffer of
    its own (``temperature_``), or a module that is no mixture at all."""

    @staticmethod
    def subclass_state(n_actions: int, n_features: int):
        import torch

        from torchcbl import GaussianMixtureSet

        model = GaussianMixtureSet(n_actions, n_features, seed=0)
        model.register_buffer("temperature_", torch.ones(()))
        return model.state_dict()

    @staticmethod
    def linear_state(n_actions: int, n_features: int):
        import torch

        return torch.nn.Linear(n_features, n_actions).state_dict()


def _with_state_of(path: Path, state) -> None:
    """Rewrite the checkpoint at ``path`` with ``state``, its count and label digest kept: a
    checkpoint torchcbl would take for the session's, holding another model's state."""
    import torch

    payload = torch.load(path, weights_only=True)
    payload["state_dict"] = state
    torch.save(payload, path)


@pytest.mark.parametrize("other", ["subclass", "linear"])
def test_show_notes_a_checkpoint_holding_another_model_classes_state(tmp_path, capsys, other):
    """describe / `torchcbl show` reported a checkpoint holding the state of another model
    class than the session's (a file of another session's, of a subclass) as the one resume
    starts from: resume cannot load it into the session's GaussianMixtureSet, sets it aside as
    .damaged and refits from the log, which only resume found out. Show now tries the state
    on the session's model, as resume loads it, and notes the file, still reading only."""
    run = tmp_path / "run"
    _small_session(run)
    newest = run / "checkpoints" / "model-00000018.pt"
    _with_state_of(newest, getattr(_GmmWithMore, f"{other}_state")(3, 2))
    before = _files_of(run)
    s = describe(run)
    (note,) = s.notes
    assert note.startswith("checkpoints/model-00000018.pt holds the state of another model"), note
    assert "GaussianMixtureSet" in note and "model-00000018.pt.damaged" in note, note
    assert s.last_checkpoint is None  # resume starts from none: it refits on the log's labels
    assert main(["show", str(run)]) == 0
    out = capsys.readouterr().out
    assert "\ncheckpoint: none\n" in out and "holds the state of another model" in out
    assert _files_of(run) == before  # show reads only
    env = rare_regions_world(episode_length=10)
    ConfidentTeacher.resume(run, env, oracle(env), progress=False).close()  # as noted:
    assert (run / "checkpoints" / "model-00000018.pt.damaged").is_file()
    assert describe(run).notes == ()


def test_show_notes_the_starting_model_of_another_class_that_resume_refuses(tmp_path, capsys):
    """A session started from a fitted model stands on its checkpoint 0 until the first
    refit; one holding another class's state makes resume refuse the session. Show says so
    beforehand, as it does for a damaged checkpoint 0."""
    from torchcbl import GaussianMixtureSet
    from torchcbl.errors import CorruptSessionError

    env = rare_regions_world(episode_length=10)
    model = GaussianMixtureSet(3, 2, seed=0).fit(*env.sample(40, np.random.default_rng(2)))
    run = tmp_path / "run"
    ct = ConfidentTeacher(
        env,
        oracle(env),
        model=model,
        config=TeachingConfig(max_new=1000),
        run_dir=run,
        seed=0,
        progress=False,
    )
    ct.run(max_steps=5)
    ct.close()
    _with_state_of(run / "checkpoints" / "model-00000000.pt", _GmmWithMore.subclass_state(3, 2))
    (note,) = describe(run).notes
    assert note.startswith("checkpoints/model-00000000.pt holds the state of another model"), note
    assert "refuse the session" in note, note
    assert main(["show", str(run)]) == 0
    assert "refuse the session" in capsys.readouterr().out
    with pytest.raises(CorruptSessionError, match="unreadable as this model's state"):
        ConfidentTeacher.resume(run, env, oracle(env), progress=False)


def _writing_while_read(monkeypatch, write, times: int = 1) -> list[int]:
    """Make describe's log read (the first ``times`` of them) let ``write`` run right after
    it has read the log, before describe looks at the lock and the checkpoints: a writer that
    commits, saves checkpoints and closes between the two. Returns the count of reads."""
    import torchcbl.session as session

    real, reads = session._read_log, []

    def read_log(*args, **kwargs):
        got = real(*args, **kwargs)
        reads.append(1)
        if len(reads) <= times:
            write()
        return got

    monkeypatch.setattr(session, "_read_log", read_log)
    return reads


def _steps_then_close(ct: ConfidentTeacher, steps: int):
    def write() -> None:
        for _ in range(steps):
            ct.step()
        ct.close()

    return write


def _resume_steps_close(run: Path, steps: int):
    def write() -> None:
        env = rare_regions_world(episode_length=10)
        ct = ConfidentTeacher.resume(run, env, oracle(env), progress=False)
        _steps_then_close(ct, steps)()

    return write


@pytest.mark.parametrize("writer", ["closes", "starts-and-closes"])
def test_show_of_a_session_a_writer_wrote_while_it_was_read(tmp_path, capsys, monkeypatch, writer):
    """describe read the log, then asked /proc/locks whether a writer runs, then listed the
    checkpoints: a writer that logged more, saved a checkpoint of more labels and closed
    between the log's read and the rest (one running at the read and closing, or one started
    and closed in between) left a session described as closed with the steps read before
    it finished, and its newest checkpoint noted as "more than the N the log holds ... labels
    the log lost, or a file put there by hand". A writer that ran at any point of the read
    now has describe read the session again, so what it reports is one consistent moment."""
    run = tmp_path / "run"
    if writer == "closes":
        write = _steps_then_close(_open_session(run, steps=20), 12)
    else:
        _small_session(run)
        write = _resume_steps_close(run, 12)
    reads = _writing_while_read(monkeypatch, write)
    s = describe(run)
    assert reads  # (the writer ran)
    assert not [n for n in s.notes if "more than the" in n], s.notes
    want = describe(run)  # (nothing runs now)
    assert (s.n_steps, s.n_labels, s.last_checkpoint) == (32, want.n_labels, want.last_checkpoint)
    assert want.last_checkpoint > 20  # the writer saved checkpoints the first read had no labels of
    assert (s.state, s.writer_running, s.notes) == ("closed", False, ())


def test_show_of_a_session_a_writer_writes_to_at_every_read_says_so(tmp_path, capsys, monkeypatch):
    """A session that writers keep opening, logging to and closing as describe reads it, at
    every read it makes: what was read is a moment of a session being written, so it is
    described as running (no writer holds it at the end: "wrote to it while it was read"),
    and a checkpoint of more labels than the log it read is not called one of labels the log
    lost or a file put there by hand."""
    run = tmp_path / "run"
    _small_session(run)
    reads = _writing_while_read(monkeypatch, _resume_steps_close(run, 4), times=100)
    s = describe(run)
    assert (s.state, s.writer_running) == ("running", False)
    assert len(s.writers) > 1 and s.n_steps >= 24
    assert not [n for n in s.notes if "more than the" in n], s.notes
    assert main(["show", str(run)]) == 0
    out = capsys.readouterr().out
    assert "a writer wrote to it while it was read (process " in out
    assert "put there by hand" not in out
    monkeypatch.undo()
    n = len(reads)
    assert (describe(run).state, len(reads)) == ("closed", n)  # (nothing writes now)


def _kept_session(run: Path, keep, steps: int = 20, **cfg) -> None:
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        env,
        oracle(env),
        config=TeachingConfig(**cfg),
        run_dir=run,
        seed=0,
        progress=False,
        keep_checkpoints=keep,
    )
    ct.run(max_steps=steps)
    ct.close()


def _on_disk(run: Path) -> tuple[int, ...]:
    return tuple(sorted(int(p.stem.split("-")[1]) for p in (run / "checkpoints").glob("*.pt")))


def test_show_says_which_checkpoints_are_kept_and_how_an_earlier_stage_is_rebuilt(tmp_path, capsys):
    """show said only "checkpoint: the newest fitted on N labels": nothing of the earlier
    stages' checkpoints that the session's keep_checkpoints removed, nor how to get such a
    stage back. describe now gives the checkpoints on disk and the last writer's retention,
    and show says them in one line after the checkpoint's, with load_model's call where
    earlier ones may be gone: one fit with full refits, a replay with incremental ones."""
    from torchcbl.session import kept_checkpoints

    hint = "earlier stages: load_model(run_dir, n_demonstrations=k) rebuilds one from the log"
    full, incremental, every = tmp_path / "full", tmp_path / "incremental", tmp_path / "every"
    _kept_session(full, 2, max_new=3)
    _kept_session(incremental, 3, max_new=1, refit="incremental")
    _kept_session(every, None, max_new=3)
    besides = "besides 0 and hand refits)"
    for run, keep, text in (
        (full, 2, f"labels), keep_checkpoints=2 (the newest 2, {besides}; {hint} (one fit)\n"),
        (incremental, 3, f"keep_checkpoints=3 (the newest 3, {besides}; {hint} (replaying"),
        (every, None, "labels), keep_checkpoints=None (every one)\n"),
    ):
        s = describe(run)
        assert s.keep_checkpoints == keep == kept_checkpoints(run)
        assert s.checkpoints_on_disk == _on_disk(run) and s.checkpoints_on_disk
        assert s.last_checkpoint == s.checkpoints_on_disk[-1]
        assert main(["show", str(run)]) == 0
        out = capsys.readouterr().out
        assert f"\ncheckpoint: the newest fitted on {s.last_checkpoint} labels\n" in out, out
        (line,) = [ln for ln in out.splitlines() if ln.startswith("            on disk: ")]
        on_disk = s.checkpoints_on_disk
        assert line.startswith(f"            on disk: {len(on_disk)} ("), line
        assert text in line + "\n", line
        assert (hint in line) is (keep is not None), line
        assert main(["show", str(run), "--json"]) == 0
        shown = json.loads(capsys.readouterr().out)
        assert shown["checkpoints_on_disk"] == list(on_disk)
        assert shown["keep_checkpoints"] == keep
    assert describe(full).checkpoints_on_disk == (15, 18)
    assert "on disk: 2 (15, 18 labels)" in describe(full).text()
    # every one: their range, not a list of all
    assert describe(every).checkpoints_on_disk == (3, 6, 9, 12, 15, 18)
    assert "on disk: 6 (3, 6, ..., 15, 18 labels)" in describe(every).text()
    # a session kept whole, then resumed keeping every one: the stages its first writer
    # removed are still gone, and show still says how to rebuild them
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher.resume(full, env, oracle(env), progress=False, keep_checkpoints=None)
    ct.run(max_steps=30)
    ct.close()
    text = describe(full).text()
    assert "keep_checkpoints=None (every one); " + hint in text, text


def _kwargs_shown(out: str) -> tuple[dict, str]:
    """The ``gymnasium.make`` arguments `torchcbl show` prints (its ``kwargs:`` lines, run as
    the Python they write after the imports they name), and those lines."""
    import re

    lines = out.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("kwargs:     "))
    block = [lines[start][12:]]
    for line in lines[start + 1 :]:
        if not line.startswith(" " * 12):
            break
        block.append(line[12:])
    text = "\n".join(block)
    source = "\n".join(line for line in block if not line.startswith("("))
    scope: dict = {}
    for module, classes in re.findall(r"from ([\w.]+) import (\w+(?:, \w+)*)", text):
        exec(f"from {module} import {classes}", scope)
    return eval(f"dict({source})", scope), text


def test_show_prints_an_object_the_session_keeps_whole_in_full(tmp_path, capsys):
    """`torchcbl show` printed an object given to gymnasium.make (a CorridorMap of one's own)
    as the text config.json keeps beside it, cut at 200 characters with no ellipsis, and
    --json alike, as if that were the whole object. An object kept whole is now printed as
    its constructor call from the kept fields, wrapped, with its imports, and --json gives
    the kept fields; where only the text was kept (a session written before 2026-11-27), a
    cut text ends with "..."."""
    import dataclasses

    import corridor
    from corridor.maps import load_map
    from corridor.world import WorldConfig

    mine = dataclasses.replace(load_map("figure2"), name="mine", start_offset=0.3)
    robot = WorldConfig.legged_robot()
    run = tmp_path / "runs" / "mine"
    env = gym.make(corridor.ENV_ID, corridor_map=mine, world_config=robot)
    ConfidentTeacher(env, lambda o, i: 0, run_dir=run, progress=False).run(max_steps=2).close()
    config = load_config(run)
    assert len(config["env"]["kwargs"]["corridor_map"]["repr"]) == 200  # the text is cut
    assert main(["show", str(run)]) == 0
    shown, text = _kwargs_shown(capsys.readouterr().out)
    assert shown == {"corridor_map": mine, "world_config": robot}, text
    assert "from corridor.maps import CorridorMap" in text, text
    assert max(len(line) for line in text.splitlines() if "description=" not in line) <= 100
    kept = config["env"]["kwargs_objects"]
    assert main(["show", str(run), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["env_kwargs"] == kept
    assert describe(run).env_kwargs["corridor_map"]["fields"]["description"] == mine.description
    assert main(["show", str(tmp_path / "runs"), "--json"]) == 0
    (entry,) = json.loads(capsys.readouterr().out)["sessions"]
    assert entry["env_kwargs"] == kept
    # as a session written before the objects were kept: the text, said to be cut
    del config["env"]["kwargs_objects"]
    (run / "config.json").write_text(json.dumps(config))
    cut = config["env"]["kwargs"]["corridor_map"]["repr"] + "..."
    assert main(["show", str(run)]) == 0
    out = capsys.readouterr().out
    assert f"corridor_map=<{cut}>" in out and "keeps only as this text" in out, out
    assert main(["show", str(run), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["env_kwargs"]["corridor_map"] == {"repr": cut}


def test_show_prints_traffic_of_ones_own_in_full(tmp_path, capsys):
    """A driving session on a TrafficScenario of one's own: show printed the scenario cut
    before its last field; it now prints every field, as a call that makes it again."""
    import sumo_scenarios
    from sumo_scenarios.scenarios import TrafficScenario

    rush = TrafficScenario(name="rushhour", seed=11, mean_spacing_m=(50, 40, 120))
    run = tmp_path / "run"
    env = gym.make(sumo_scenarios.ENV_ID, scenario=rush)
    try:
        ConfidentTeacher(env, lambda o, i: 1, run_dir=run, progress=False).run(max_steps=3).close()
    finally:
        env.close()
    assert main(["show", str(run)]) == 0
    shown, text = _kwargs_shown(capsys.readouterr().out)
    assert shown == {"scenario": rush} and "start_clear_m=30.0" in text, text
    assert "from sumo_scenarios.scenarios import TrafficScenario" in text, text
    assert main(["show", str(run), "--json"]) == 0
    fields = json.loads(capsys.readouterr().out)["env_kwargs"]["scenario"]["fields"]
    assert fields["start_clear_m"] == 30.0 and fields["mean_spacing_m"] == [50.0, 40.0, 120.0]


class Dial(gym.Env):
    """An env of one's own, made directly (no gymnasium id): 1 feature, 2 actions."""

    def __init__(self) -> None:
        self.observation_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.np_random.uniform(-1, 1, 1).astype(np.float32), {}

    def step(self, action):
        return self.np_random.uniform(-1, 1, 1).astype(np.float32), 0.0, False, False, {}


def _taught_in(run: Path, env: gym.Env) -> None:
    with ConfidentTeacher(
        env,
        lambda o, i: int(o[-1] > 0),
        config=TeachingConfig(max_new=3),
        run_dir=run,
        progress=False,
    ) as ct:
        ct.run(max_steps=6)


def test_show_names_the_env_class_and_step_cap_resume_compares(tmp_path, capsys):
    """A session of gymnasium.make("CartPole-v1", max_episode_steps=100) (as the benchmark's
    env_kwargs={"max_episode_steps": 100} makes it) showed "CartPole-v1", its env_kwargs {},
    yet a resume with gymnasium.make("CartPole-v1") is refused on its cap; one made directly
    showed "made directly (no gymnasium id)", though resume compares its class. show, its
    --json and describe() now give the class and the cap as config.json keeps them; a session
    written before they were kept says "not recorded"."""
    made = tmp_path / "made"
    _taught_in(made, gym.make("CartPole-v1", max_episode_steps=100))
    s = describe(made)
    assert s.env_class == "gymnasium.envs.classic_control.cartpole.CartPoleEnv"
    assert (s.env_max_episode_steps, s.env_max_episode_steps_recorded) == (100, True)
    assert main(["show", str(made)]) == 0
    out = capsys.readouterr().out
    assert "\nclass:      gymnasium.envs.classic_control.cartpole.CartPoleEnv\n" in out, out
    assert "\nstep cap:   100 (max_episode_steps)\n" in out, out
    assert main(["show", str(made), "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown == s.to_dict()
    assert (shown["env_class"], shown["env_max_episode_steps"]) == (s.env_class, 100)
    direct = tmp_path / "direct"
    _taught_in(direct, Dial())  # no TimeLimit, no cap of its own
    s = describe(direct)
    assert (s.env_id, s.env_class) == (None, f"{Dial.__module__}.Dial")
    assert (s.env_max_episode_steps, s.env_max_episode_steps_recorded) == (None, True)
    assert main(["show", str(direct)]) == 0
    out = capsys.readouterr().out
    assert f"\nclass:      {Dial.__module__}.Dial\n" in out, out
    assert "\nstep cap:   none (no TimeLimit, and no cap of its own)\n" in out, out
    assert main(["show", str(tmp_path)]) == 0  # a folder's listing names the class
    assert f"{direct}: closed, Dial made directly, " in capsys.readouterr().out
    # a session written before the class and the cap were kept
    config = json.loads((direct / "config.json").read_text())
    del config["env"]["class"], config["env"]["max_episode_steps"]
    (direct / "config.json").write_text(json.dumps(config))
    s = describe(direct)
    assert (s.env_class, s.env_max_episode_steps, s.env_max_episode_steps_recorded) == (
        None,
        None,
        False,
    )
    assert main(["show", str(direct)]) == 0
    out = capsys.readouterr().out
    assert "\nclass:      not recorded (an older session: resume does not compare it)\n" in out
    assert "\nstep cap:   not recorded (an older session: resume does not compare it)\n" in out
    assert main(["show", str(direct), "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert (shown["env_class"], shown["env_max_episode_steps_recorded"]) == (None, False)


def test_evaluate_names_the_class_of_an_env_made_directly(tmp_path, capsys):
    """evaluate refused a session of an env of one's own made directly saying "env id None";
    it names the env's class, which resume compares, where there is no id (and counts its one
    feature as one: it said "1 features")."""
    run = tmp_path / "run"
    _taught_in(run, Dial())
    assert main(["evaluate", str(run)]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert f"env {Dial.__module__}.Dial made directly (no gymnasium id), 1 feature, 2" in line
    assert "None" not in line, line
    config = json.loads((run / "config.json").read_text())
    del config["env"]["class"]
    (run / "config.json").write_text(json.dumps(config))
    assert main(["evaluate", str(run)]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert "env made directly (no gymnasium id; its class not recorded)" in line, line


def _streak_session(run: Path, config: TeachingConfig, **run_kw) -> ConfidentTeacher:
    """A session of ``config`` taught until ``run(**run_kw)`` returns, closed."""
    world = rare_regions_world(episode_length=10)
    with ConfidentTeacher(
        world, oracle(world), config=config, run_dir=run, seed=0, progress=False
    ) as ct:
        ct.run(**run_kw)
    return ct


def test_show_says_a_session_that_met_its_streak_is_done_as_resume_counts_it(tmp_path, capsys):
    """show and describe() could not say that a session had met its streak stop (what makes
    resume take no step and teach --resume refuse it). streak_met names the stop met, as
    resume's stop_reason does, counted the same way; None for a session stopped short of it,
    and for a session with no streak stop; the stops are those config.json keeps."""
    episodes = TeachingConfig(noninteractive=False, autonomous_episodes_to_stop=3)
    steps = TeachingConfig(noninteractive=False, autonomous_steps_to_stop=15)
    runs = {
        "autonomous_episodes": (tmp_path / "episodes", episodes, {}),
        "autonomous_steps": (tmp_path / "steps", steps, {}),
        None: (tmp_path / "short", episodes, {"max_steps": 25}),  # stopped short of its streak
        "budget": (tmp_path / "budget", TeachingConfig(noninteractive=False, max_steps=40), {}),
    }
    for want, (run, config, run_kw) in runs.items():
        ct = _streak_session(run, config, **run_kw)
        s = describe(run)
        world = rare_regions_world(episode_length=10)
        with ConfidentTeacher.resume(run, world, oracle(world), progress=False) as back:
            resumed = back.stop_reason
        met = None if want == "budget" else want
        assert s.streak_met == met, (want, s.streak_met)
        assert resumed == (want if want != "budget" else "max_steps")  # the same count
        if met is not None:
            assert ct.stop_reason == met
        stored = load_config(run)["teaching"]
        assert s.stops == {
            k: stored[k]
            for k in (
                "autonomous_steps_to_stop",
                "autonomous_episodes_to_stop",
                "max_demonstrations",
                "max_steps",
                "max_episodes",
                "time_limit_is_success",
            )
        }
        assert main(["show", str(run), "--json"]) == 0
        shown = json.loads(capsys.readouterr().out)
        assert shown["streak_met"] == met and shown["stops"] == s.stops
        assert main(["show", str(run)]) == 0
        out = capsys.readouterr().out
        if met is None:
            assert "done:" not in out, out
        else:
            (line,) = [ln for ln in out.splitlines() if ln.startswith("done:")]
            field = f"{met}_to_stop"
            assert line.startswith(f"done:       {field}={getattr(config, field)} met ("), line
            assert "teaching is done; a resume takes no step (teach --resume refuses it)" in line
        kept = {
            "autonomous_episodes": "autonomous_episodes_to_stop=3",
            "autonomous_steps": "autonomous_steps_to_stop=15",
            None: "autonomous_episodes_to_stop=3",
            "budget": "max_steps=40",
        }[want]
        assert f"\nstops:      {kept}\n" in out, out
    # the resumes above (a writer each, none of which took a step) leave it done
    assert describe(tmp_path / "episodes").streak_met == "autonomous_episodes"
    # a folder's listing tells the done sessions from the others (it listed them alike)
    assert main(["show", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.splitlines()[1:]
    by_run = {ln.split(": ", 1)[0]: ln for ln in lines}
    assert set(by_run) == {str(run) for run, _, _ in runs.values()}, lines
    for want, (run, config, _) in runs.items():
        line = by_run[str(run)]
        if want in ("autonomous_episodes", "autonomous_steps"):
            field = f"{want}_to_stop"
            assert line.endswith(f"; done: {field}={getattr(config, field)} met"), line
        else:
            assert "done" not in line, line


def test_show_of_a_format1_session_with_no_writers_says_its_streak(tmp_path):
    """An older session (format 1, no writers.jsonl) is counted over its whole log, as resume
    counts it."""
    from test_architecture import _downgrade_to_format1

    run = tmp_path / "run"
    _streak_session(run, TeachingConfig(noninteractive=False, autonomous_episodes_to_stop=3))
    _downgrade_to_format1(run)
    (run / "writers.jsonl").unlink()
    config = json.loads((run / "config.json").read_text())
    del config["teaching"]["time_limit_is_success"]  # a field older sessions do not keep
    (run / "config.json").write_text(json.dumps(config))
    s = describe(run)
    assert s.format == "torchcbl.session/1" and s.writers == ()
    assert s.streak_met == "autonomous_episodes" and s.stops["time_limit_is_success"] is False
    assert main(["show", str(run)]) == 0
    world = rare_regions_world(episode_length=10)
    with ConfidentTeacher.resume(run, world, oracle(world), progress=False) as back:
        assert back.stop_reason == s.streak_met
