"""A benchmark cell can keep its teaching session (run_benchmark(keep_sessions=True),
``torchcbl benchmark --keep-sessions``): the same figures and keys, a session the public readers
read as the cell's teaching, and a stale session of a stopped cell set aside on rerun."""

from __future__ import annotations

import json
import os
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from _bench_env import toy_spec

from torchcbl import benchmark as bm
from torchcbl.cli import main
from torchcbl.gmm import GaussianMixtureSet
from torchcbl.policy import GreedyPolicy, evaluate_policy
from torchcbl.session import (
    fit_count,
    load_config,
    load_corrections,
    load_demonstrations,
    load_labels,
    load_model,
    load_records,
)

TESTS = Path(__file__).resolve().parent
TIMINGS = ("wall_s", "cpu_s", "teach_wall_s")


def _env(**kw):
    """The toy env of tests/_bench_env.py (at most 60 steps, budgets 5, 10, 20)."""
    return toy_spec(**kw)


HG = [bm.StrategySpec("hg_dagger", {"warmup": 3})]


def _cells(out: Path) -> dict[str, dict]:
    return {p.stem: json.loads(p.read_text()) for p in (out / "cells").glob("*.json")}


def _untimed(cell: dict) -> dict:
    return {k: v for k, v in cell.items() if k not in TIMINGS}


def test_keeping_sessions_changes_no_figure_and_no_key(tmp_path):
    plain = bm.run_benchmark(HG, [_env()], [0, 1], tmp_path / "plain", workers=1, plots=False)
    kept = bm.run_benchmark(
        HG, [_env()], [0, 1], tmp_path / "kept", workers=1, plots=False, keep_sessions=True
    )
    a, b = _cells(tmp_path / "plain"), _cells(tmp_path / "kept")
    keys = sorted(bm.cell_key(c) for c in bm.cell_configs(HG, [_env()], [0, 1]))
    assert sorted(a) == sorted(b) == keys and len(keys) == 2
    for key in keys:
        assert _untimed(a[key]) == _untimed(b[key])
        assert b[key]["config"]["format"] == bm.CELL_FORMAT
    rows = plain["table"]["toy"]["hg_dagger"], kept["table"]["toy"]["hg_dagger"]
    assert _untimed(rows[0]) == _untimed(rows[1])
    assert sorted(p.name for p in (tmp_path / "kept" / "sessions").iterdir()) == keys
    assert not (tmp_path / "plain" / "sessions").exists()


def _performance(model, spec: bm.EnvSpec) -> float:
    """A model's greedy performance as a cell measures it (success_rate over the eval seeds)."""
    env = gym.make(spec.env_id, **{**spec.env_kwargs, **spec.eval_env_kwargs})
    try:
        return float(
            np.mean(
                [
                    bm.success_rate(
                        evaluate_policy(
                            GreedyPolicy(model), env, n_episodes=spec.eval_episodes, seed=s
                        )
                    )
                    for s in spec.eval_seeds
                ]
            )
        )
    finally:
        env.close()


def test_a_kept_session_is_the_cells_teaching(tmp_path):
    spec = _env()
    bm.run_benchmark(HG, [spec], [0], tmp_path, workers=1, plots=False, keep_sessions=True)
    ((key, cell),) = _cells(tmp_path).items()
    session = tmp_path / "sessions" / key
    a = cell["attention"]
    assert not (session / "steps.sqlite-wal").exists()  # closed as the cell ended
    records = load_records(session)
    assert 0 < len(records) == a["steps"] <= spec.max_steps
    assert sum(r.teacher_action is not None for r in records) == a["requests"]
    assert len(load_corrections(session)) == a["corrections"] > 0
    assert len(load_labels(session)[1]) == len(load_demonstrations(session)[1]) == a["labels"]
    config = load_config(session)  # the env it was taught on, not the auditing wrapper
    assert config["env"]["id"] == "BenchCluster-v0" and config["env"]["kwargs"] == {"spread": 2.0}
    assert config["seed"] == 0 and config["teaching"]["max_new"] == 5
    assert config["strategy"]["type"] == "HGDAgger"
    # the curve from the session: the loop's model at each refit point, and a snapshot
    # between refits (fitted on every label so far) as a fit on the labels up to it
    curve = [(p["labels"], p["performance"]) for p in cell["curve"]]
    labels, max_new = [n for n, _ in curve], config["teaching"]["max_new"]
    # before the first fit there is no model to act, so the teacher gives each of the first
    # max_new labels: the first point is the first refit, whatever the fits
    assert labels[0] == spec.budgets[0] == max_new
    assert labels == sorted(set(labels)) and labels[-1] == a["labels"]
    x, y = load_demonstrations(session)
    shape = config["env"]["n_actions"], config["env"]["n_features"]
    for n, performance in curve:
        if fit_count(n, max_new) == n:  # a refit point: the loop's model, from the session
            model = load_model(session, n_demonstrations=n)
        else:  # the loop's model stood on fewer labels than the snapshot
            model = GaussianMixtureSet(*shape, seed=config["seed"], **spec.model)
            model.fit(x[:n], y[:n])
        assert _performance(model, spec) == performance, (n, curve)


def test_a_stopped_cells_session_is_set_aside_and_a_cached_cells_kept(tmp_path, monkeypatch):
    spec = _env(teacher="_bench_env:teacher_failing_while_told")
    (config,) = bm.cell_configs(HG, [spec], [0])
    session = tmp_path / "sessions" / bm.cell_key(config)
    run = lambda: bm.run_benchmark(  # noqa: E731
        HG, [spec], [0], tmp_path, workers=1, plots=False, keep_sessions=True
    )
    monkeypatch.setenv("BENCH_TEACHER_FAILS", "1")
    with pytest.raises(bm.CellError, match="stopped part-way"):
        run()
    assert len(load_records(session)) == 2  # what the stopped cell taught
    monkeypatch.delenv("BENCH_TEACHER_FAILS")
    run()  # not "already holds a teaching session", nor those 2 steps and then 60 more
    (cell,) = _cells(tmp_path).values()
    assert len(load_records(session)) == cell["attention"]["steps"] == 60
    assert len(load_records(session.with_name(session.name + ".stale-1"))) == 2
    before = {p: p.read_bytes() for p in session.rglob("*") if p.is_file()}
    seen = []
    bm.run_benchmark(
        HG,
        [spec],
        [0],
        tmp_path,
        workers=1,
        plots=False,
        keep_sessions=True,
        on_cell=lambda c, cached: seen.append(cached),
    )
    assert seen == [True]  # cached: its session as it was, nothing else set aside
    assert {p: p.read_bytes() for p in session.rglob("*") if p.is_file()} == before
    assert sorted(p.name for p in session.parent.iterdir()) == [
        session.name,
        f"{session.name}.stale-1",
    ]


def test_a_stale_session_is_set_aside_without_keep_sessions_too(tmp_path, monkeypatch):
    """A stopped cell computed again without keep_sessions: its stale session must not be left
    where a later keep_sessions run would take it for the cached cell's."""
    spec = _env(teacher="_bench_env:teacher_failing_while_told")
    (config,) = bm.cell_configs(HG, [spec], [0])
    session = tmp_path / "sessions" / bm.cell_key(config)
    monkeypatch.setenv("BENCH_TEACHER_FAILS", "1")
    with pytest.raises(bm.CellError):
        bm.run_benchmark(HG, [spec], [0], tmp_path, workers=1, plots=False, keep_sessions=True)
    monkeypatch.delenv("BENCH_TEACHER_FAILS")
    bm.run_benchmark(HG, [spec], [0], tmp_path, workers=1, plots=False)
    assert not session.exists() and len(load_records(f"{session}.stale-1")) == 2
    with pytest.warns(UserWarning, match=r"keep_sessions: 1 of the 1 cached cells have no session"):
        bm.run_benchmark(HG, [spec], [0], tmp_path, workers=1, plots=False, keep_sessions=True)
    assert not session.exists()  # cached: not computed again


def test_the_command_keeps_sessions_and_says_where(tmp_path, capsys, monkeypatch, recwarn):
    monkeypatch.syspath_prepend(str(TESTS))
    argv = ["benchmark", "--envs", "", "--gym-env", "_bench_env:BenchCluster-v0"]
    argv += ["--teacher", "_bench_env:teacher", "--strategies", "bc", "--seeds", "1"]
    argv += ["--workers", "1", "--budgets", "5", "--max-steps", "10", "--eval-episodes", "1"]
    out = tmp_path / "b"
    assert main([*argv, "--out", str(out)]) == 0  # without: no session
    capsys.readouterr()
    assert main([*argv, "--out", str(out), "--keep-sessions"]) == 0
    err = capsys.readouterr().err  # the cached cell is said to have none, in one line
    assert err.startswith("\nwarning: --keep-sessions: 1 cached cell has no session in ")
    assert err.count("\n") == 2  # (not also as a Python warning, with its file and line)
    assert not [w for w in recwarn if "keep_sessions" in str(w.message)]
    out2 = tmp_path / "c"
    assert main([*argv, "--out", str(out2), "--keep-sessions"]) == 0
    text = capsys.readouterr()
    assert f"teaching sessions in {out2 / 'sessions'}" in text.out and not text.err
    ((key, cell),) = _cells(out2).items()
    assert len(load_labels(out2 / "sessions" / key)[1]) == cell["attention"]["labels"] == 5
    with pytest.raises(SystemExit):
        main(["benchmark", "--help"])
    assert "--keep-sessions" in capsys.readouterr().out


def test_a_cell_killed_in_a_worker_leaves_a_session_set_aside_on_rerun(tmp_path, monkeypatch):
    """A worker killed outright mid-cell (SIGKILL: its session's lock, journal and -wal left as
    they were) leaves a readable session; the rerun sets it aside and teaches the cell anew."""
    monkeypatch.setenv(
        "PYTHONPATH",
        os.pathsep.join([str(TESTS), str(TESTS.parent), os.environ.get("PYTHONPATH", "")]),
    )
    spec = _env(teacher="_bench_env:teacher_killed_while_told")
    (config,) = bm.cell_configs(HG, [spec], [0])
    session = tmp_path / "sessions" / bm.cell_key(config)
    monkeypatch.setenv("BENCH_TEACHER_KILLED", "1")
    with pytest.raises(RuntimeError, match="killed"):
        bm.run_benchmark(HG, [spec], [0], tmp_path, workers=2, plots=False, keep_sessions=True)
    assert len(load_records(session)) == 2
    monkeypatch.delenv("BENCH_TEACHER_KILLED")
    bm.run_benchmark(HG, [spec], [0], tmp_path, workers=1, plots=False, keep_sessions=True)
    assert len(load_records(session)) == 60
    assert len(load_records(f"{session}.stale-1")) == 2


@pytest.mark.parametrize("domain", ["corridor", "driving"])
def test_torchcbl_teach_resumes_a_session_the_benchmark_kept(domain, tmp_path, monkeypatch, capsys):
    """`torchcbl teach DOMAIN --resume` goes on with a corridor or driving benchmark cell's kept
    session (the --keep-sessions help calls them what torchcbl teach writes). A driving one was
    refused: the benchmark makes its env with gymnasium.make's max_episode_steps=1000 (a
    TimeLimit, which the session records as its cap) and teach made it without, so resume said
    "make the env as the session did, gymnasium.make(...)", Python's words at the terminal.
    (The driving entry at budget 5 over 20 steps: a SUMO run of a second or two.)"""
    import importlib
    from dataclasses import replace

    package = "sumo_scenarios" if domain == "driving" else domain
    human = importlib.import_module(f"{package}.human")

    class Scripted:  # the person at the terminal, answering "stay" / "forward" to every request
        def __call__(self, observation, info):
            return 0

        def set_status(self, text):
            pass

    monkeypatch.setattr(human, "make_teacher", lambda **kw: Scripted())
    entry = importlib.import_module(f"{package}.benchmark")
    spec = replace(entry.env_spec(True), budgets=(5,), max_steps=20, eval_steps=10)
    confident = [bm.StrategySpec("confident", {})]
    bm.run_benchmark(confident, [spec], [0], tmp_path, workers=1, plots=False, keep_sessions=True)
    (session,) = (tmp_path / "sessions").iterdir()
    before = len(load_records(session))
    capsys.readouterr()
    argv = ["teach", domain, "--resume", "--run-dir", str(session), "--steps", "3"]
    assert main(argv) == 0, capsys.readouterr().err
    assert len(load_records(session)) == before + 3
    assert load_config(session)["env"]["max_episode_steps"] == (1000 if domain == "driving" else 81)


def _checkpoints_of(session: Path) -> list[int]:
    return sorted(int(p.stem.split("-")[1]) for p in (session / "checkpoints").glob("model-*.pt"))


def test_kept_sessions_keep_the_checkpoints_asked_for_with_the_same_figures_and_keys(tmp_path):
    """run_benchmark(keep_sessions=True) wrote each session with ConfidentTeacher's default
    retention (the newest 3 checkpoints) and no way to choose another; keep_checkpoints= now
    says it (None: every one), and changes neither a figure nor a cell's key."""
    from torchcbl.teaching import DEFAULT_KEEP_CHECKPOINTS

    spec = _env(teaching={"max_new": 2})  # refits at 2, 4, ... labels
    runs = {}
    for name, keep in (("default", ()), ("every", (None,)), ("one", (1,))):
        kwargs = {"keep_checkpoints": keep[0]} if keep else {}
        out = tmp_path / name
        bm.run_benchmark(HG, [spec], [0], out, workers=1, plots=False, keep_sessions=True, **kwargs)
        ((key, cell),) = _cells(out).items()
        runs[name] = (key, _untimed(cell), _checkpoints_of(out / "sessions" / key))
    every = runs["every"][2]
    assert len(every) > DEFAULT_KEEP_CHECKPOINTS
    assert runs["default"][2] == every[-DEFAULT_KEEP_CHECKPOINTS:]
    assert runs["one"][2] == every[-1:]
    assert runs["default"][:2] == runs["every"][:2] == runs["one"][:2]


def test_kept_sessions_of_a_process_pool_keep_the_checkpoints_asked_for(tmp_path):
    """keep_checkpoints= reaches the cells run in worker processes (workers=2), as it does
    those run in the caller's: None keeps every refit's checkpoint, not the newest 3."""
    from torchcbl.teaching import DEFAULT_KEEP_CHECKPOINTS

    spec = _env(teaching={"max_new": 2})  # refits at 2, 4, ... labels
    bm.run_benchmark(
        HG, [spec], [0], tmp_path, workers=2, plots=False, keep_sessions=True, keep_checkpoints=None
    )
    ((key, cell),) = _cells(tmp_path).items()
    every = _checkpoints_of(tmp_path / "sessions" / key)
    last = cell["attention"]["labels"] // 2 * 2
    assert len(every) > DEFAULT_KEEP_CHECKPOINTS and every == list(range(2, last + 1, 2)), every


@pytest.mark.parametrize("bad", [0, -2, True, 2.0, "all"])
def test_run_benchmark_refuses_a_keep_checkpoints_before_anything_runs(tmp_path, bad):
    out = tmp_path / "b"
    with pytest.raises(ValueError, match=r"keep_checkpoints: expected None .* or an int >= 1"):
        bm.run_benchmark(
            HG, [_env()], [0], out, workers=1, plots=False, keep_sessions=True, keep_checkpoints=bad
        )
    assert not out.exists()


def test_the_command_says_how_many_checkpoints_kept_sessions_keep(tmp_path, capsys, monkeypatch):
    monkeypatch.syspath_prepend(str(TESTS))
    argv = ["benchmark", "--envs", "", "--gym-env", "_bench_env:BenchCluster-v0"]
    argv += ["--teacher", "_bench_env:teacher", "--strategies", "bc", "--seeds", "1"]
    argv += ["--workers", "1", "--budgets", "5,10", "--max-steps", "20", "--eval-episodes", "1"]
    out = tmp_path / "b"
    assert main([*argv, "--out", str(out), "--keep-sessions", "--keep-checkpoints", "all"]) == 0
    ((key, cell),) = _cells(out).items()
    every = _checkpoints_of(out / "sessions" / key)
    assert len(every) == cell["attention"]["labels"] == 10  # bc: a refit per label
    capsys.readouterr()
    for bad, says in (
        (["--keep-checkpoints", "2"], "--keep-checkpoints 2 applies only with --keep-sessions"),
        (["--keep-sessions", "--keep-checkpoints", "0"], "expected a whole number >= 1"),
    ):
        try:
            code = main([*argv, "--out", str(tmp_path / "x"), *bad])
        except SystemExit as exc:  # argparse's own refusal
            code = exc.code
        stdout, err = capsys.readouterr()
        assert code == 2 and stdout == "" and err.count("\n") == 1, (bad, stdout, err)
        assert says in err, err
        assert not (tmp_path / "x").exists()


def test_the_command_goes_on_after_its_first_cell_stopped_with_keep_sessions(
    tmp_path, capsys, monkeypatch
):
    """A sweep with --keep-sessions stopped before its first cell finished (Ctrl-C, a failed
    cell) left OUT holding only sessions/ (its empty cells/ removed), and the same command run
    again, as the error and the docs say to, was refused: "--out ... is not a benchmark's
    directory (no cells/)". It goes on, and the stopped cell's session is set aside."""
    monkeypatch.syspath_prepend(str(TESTS))
    argv = ["benchmark", "--envs", "", "--gym-env", "_bench_env:BenchCluster-v0"]
    argv += ["--teacher", "_bench_env:teacher_failing_while_told", "--strategies", "bc"]
    argv += ["--seeds", "1", "--workers", "1", "--budgets", "5", "--max-steps", "10"]
    argv += ["--eval-episodes", "1", "--keep-sessions"]
    out = tmp_path / "b"
    monkeypatch.setenv("BENCH_TEACHER_FAILS", "1")
    assert main([*argv, "--out", str(out)]) == 2
    assert "fix the cause and run it again" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["sessions"]
    monkeypatch.delenv("BENCH_TEACHER_FAILS")
    assert main([*argv, "--out", str(out)]) == 0, capsys.readouterr().err
    ((key, cell),) = _cells(out).items()
    assert len(load_labels(out / "sessions" / key)[1]) == cell["attention"]["labels"] == 5
    assert len(load_records(out / "sessions" / f"{key}.stale-1")) == 2
