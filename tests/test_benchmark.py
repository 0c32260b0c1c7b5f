"""The benchmark: per-cell cache, resume after a kill, Ray equals the process pool, the table."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from _bench_env import toy_spec

from torchcbl import benchmark as bm
from torchcbl.cli import main

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent


def _env(**kw):
    return toy_spec(**kw)


STRATEGIES = [bm.StrategySpec("bc"), bm.StrategySpec("dagger", {"iteration_steps": 10})]

# `torchcbl benchmark` on the registered toy env alone (tests/_bench_env.py; the tests put
# tests/ on sys.path), and the smallest sweep of it: one seed, one budget of 5 labels
_TOY_SWEEP = ("benchmark", "--envs", "", "--gym-env", "_bench_env:BenchCluster-v0")
_ONE_TINY_CELL = ["--seeds", "1", "--budgets", "5", "--max-steps", "10", "--eval-episodes", "1"]


def _figures(cell):
    return {k: cell[k] for k in ("key", "curve", "teacher_performance", "attention", "config")}


def test_a_cell_reports_curve_attention_and_times():
    (config,) = bm.cell_configs([bm.StrategySpec("hg_dagger", {"warmup": 3})], [_env()], [0])
    cell = bm.run_cell(config)
    assert [p["labels"] for p in cell["curve"]][:2] == [5, 10]
    assert cell["teacher_performance"] == 1.0  # the oracle is optimal
    a = cell["attention"]
    assert a["steps"] == 60 and a["monitored_steps"] == 60  # the gate watches every step
    assert a["labels"] == a["requests"] + a["corrections"]
    # every wrong autonomous action was corrected by the (deterministic) gating teacher
    assert a["wrong_autonomous_actions"] == a["corrections"] > 0
    assert a["wrong_autonomous_rate"] == a["wrong_autonomous_actions"] / a["agent_actions"]
    assert a["auditor_disagreement"] == 0.0  # a deterministic teacher agrees with itself
    assert cell["wall_s"] > 0 and cell["cpu_s"] > 0
    assert bm.run_cell(config)["curve"] == cell["curve"]  # deterministic


def test_dagger_counts_its_learner_executed_labelled_steps_as_wrong_actions():
    strategy = bm.StrategySpec("dagger", {"beta0": 0.0})  # the learner acts once it has a model
    (config,) = bm.cell_configs([strategy], [_env(env_kwargs={"spread": 3.0})], [0])
    a = bm.run_cell(config)["attention"]
    assert a["autonomous_steps"] == 0 and a["labels"] == a["requests"] == a["steps"] == 20
    assert a["agent_actions"] == 20 - 5  # all but the steps before the first fit (max_new 5)
    assert 0 < a["wrong_autonomous_actions"] < a["agent_actions"]


def test_a_stochastic_teachers_disagreement_with_its_auditor_is_reported_beside_the_rate():
    """Wrong autonomous actions are counted against a second teacher instance asked at every
    step; a stochastic teacher (the driving domain's person) disagrees with itself, so a count
    alone ranked learners by how long they drove (review: per learner action the driving
    rates were 0.18-0.28, the auditor's disagreement with the real teacher 0.22-0.28). A cell
    reports the rate per learner action and that disagreement on the steps the teacher
    answered, and the table shows both."""
    spec = _env(
        teacher="_bench_env:noisy_teacher",
        env_kwargs={"spread": 1.0},
        teaching={"noninteractive": False, "max_new": 5},
    )
    # (a teacher asked at every step, as a gating one is, draws in step with its auditor)
    (config,) = bm.cell_configs([bm.StrategySpec("confident")], [spec], [0])
    a = bm.run_cell(config)["attention"]
    assert 0.05 < a["auditor_disagreement"] < 0.6, a  # two draws of 20 % noise, 2 actions
    assert a["agent_actions"] > 0, a
    assert a["wrong_autonomous_rate"] == a["wrong_autonomous_actions"] / a["agent_actions"]
    cells = [bm.run_cell(config)]
    table = bm.format_table(bm.summarize(cells, envs=[spec.name], strategies=["confident"]))
    assert "wrong auto. actions (rate) | auditor ≠ teacher |" in table
    row = table.splitlines()[-1]
    assert f"({a['wrong_autonomous_rate']:.2f}) | {a['auditor_disagreement']:.2f} |" in row, row


def test_labels_to_95pct_with_censoring_by_hand():
    def cell(seed, perfs, teacher=1.0):
        labels = [5, 10, 20]
        return {
            "env": "e",
            "strategy": "s",
            "seed": seed,
            "teacher_performance": teacher,
            "curve": [{"labels": n, "performance": p} for n, p in zip(labels, perfs, strict=True)],
            "config": {"env": {"budgets": labels}},
            "attention": {
                k: 1
                for k in (
                    "requests",
                    "monitored_steps",
                    "context_switches",
                    "wrong_autonomous_actions",
                )
            },
            "wall_s": 1.0,
            "cpu_s": 1.0,
        }

    cells = [cell(0, [0.5, 0.96, 1.0]), cell(1, [0.95, 1, 1]), cell(2, [0.2, 0.5, 0.9])]
    # a newer cell beside older ones (summarize is public): its extra keys are averaged over
    # the cells that have them, not a KeyError
    cells[1]["attention"] = {**cells[1]["attention"], "wrong_autonomous_rate": 0.25}
    r = bm.summarize(cells, envs=["e"], strategies=["s"])["table"]["e"]["s"]
    assert r["attention"]["wrong_autonomous_rate"] == {"mean": 0.25, "sd": None, "n": 1}
    lt = r["labels_to_95pct"]
    assert [p["labels"] for p in lt["per_seed"]] == [10, 5, 20]
    assert [p["censored"] for p in lt["per_seed"]] == [False, False, True]
    assert lt["mean"] == pytest.approx(35 / 3) and lt["n"] == 3 and lt["n_censored"] == 1
    assert lt["lower_bound"] is True
    assert r["final_performance"]["mean"] == pytest.approx((1 + 1 + 0.9) / 3)
    assert r["performance_at_budget"]["10"]["mean"] == pytest.approx((0.96 + 1 + 0.5) / 3)
    assert "| ≥ 12 ± 8 (1/3) | 0.82 ± 0.28 @ 10 |" in bm.format_table({"table": {"e": {"s": r}}})


def test_rerun_uses_the_cache_and_a_changed_config_is_a_new_cell(tmp_path):
    seen = []
    bm.run_benchmark(STRATEGIES[:1], [_env()], [0], tmp_path, workers=1, plots=False)
    bm.run_benchmark(
        STRATEGIES[:1],
        [_env(), _env(name="toy2", budgets=(5, 10))],
        [0],
        tmp_path,
        workers=1,
        on_cell=lambda c, cached: seen.append((c["env"], cached)),
    )
    assert seen == [("toy", True), ("toy2", False)]
    res = json.loads((tmp_path / "results.json").read_text())
    assert res["sweep"] == {**res["sweep"], "cells": 2, "computed": 1, "cached": 1}
    assert set(res["table"]) == {"toy", "toy2"}
    assert (tmp_path / "learning_curves.png").stat().st_size > 0


_CHILD = """
import sys
sys.path[:0] = [{tests!r}, {root!r}]
from torchcbl import benchmark as bm
from test_benchmark import STRATEGIES, _env
bm.run_benchmark(STRATEGIES, [_env(max_steps=150, budgets=(5, 10, 20, 40))], [0, 1],
                 {out!r}, workers=1, plots=False)
"""


def test_killed_sweep_resumes_without_recomputing_a_finished_cell(tmp_path):
    out = tmp_path / "bench"
    code = _CHILD.format(tests=str(TESTS), root=str(ROOT), out=str(out))
    child = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT)
    cells_dir = out / "cells"
    deadline = time.monotonic() + 300
    try:
        while time.monotonic() < deadline and child.poll() is None:
            if cells_dir.exists() and list(cells_dir.glob("*.json")):
                break
            time.sleep(0.05)
        assert child.poll() is None, "the sweep ended before it could be killed"
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.wait()
    finished = {p.name: p.read_bytes() for p in cells_dir.glob("*.json")}
    assert 1 <= len(finished) < 4
    computed, cached = [], []
    bm.run_benchmark(
        STRATEGIES,
        [_env(max_steps=150, budgets=(5, 10, 20, 40))],
        [0, 1],
        out,
        workers=1,
        plots=False,
        on_cell=lambda c, was: (cached if was else computed).append(f"{c['key']}.json"),
    )
    assert sorted(cached) == sorted(finished)  # no finished cell recomputed ...
    assert not set(computed) & set(finished) and len(computed) == 4 - len(finished)
    for name, data in finished.items():  # ... nor rewritten
        assert (cells_dir / name).read_bytes() == data
    res = json.loads((out / "results.json").read_text())
    assert res["sweep"]["cells"] == 4 and res["sweep"]["cached"] == len(finished)


def test_local_ray_gives_the_same_cells_as_the_process_pool(tmp_path, monkeypatch):
    pytest.importorskip("ray")
    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join([str(TESTS), str(ROOT), os.environ.get("PYTHONPATH", "")])
    )
    grid = (STRATEGIES[1:], [_env()], [0, 1])
    # the sessions kept too, one checkpoint each beside checkpoint 0: a Ray task is given the
    # retention as a pool worker is (keep_checkpoints reaches run_cell through ray.remote)
    kept = {"plots": False, "keep_sessions": True, "keep_checkpoints": 1}
    pool = bm.run_benchmark(*grid, tmp_path / "pool", workers=2, **kept)
    ray = bm.run_benchmark(*grid, tmp_path / "ray", workers=2, use_ray=True, **kept)
    assert pool["sweep"]["engine"] == "process_pool" and ray["sweep"]["engine"] == "ray"
    for key in pool["cells"]:
        a = json.loads((tmp_path / "pool" / "cells" / f"{key}.json").read_text())
        b = json.loads((tmp_path / "ray" / "cells" / f"{key}.json").read_text())
        assert _figures(a) == _figures(b)
        on_disk = [
            sorted(p.name for p in (tmp_path / engine / "sessions" / key / "checkpoints").iterdir())
            for engine in ("pool", "ray")
        ]
        assert on_disk[0] == on_disk[1] and 1 <= len(on_disk[0]) <= 2, on_disk
        writers = (tmp_path / "ray" / "sessions" / key / "writers.jsonl").read_text()
        assert [json.loads(w)["keep_checkpoints"] for w in writers.splitlines()] == [1]
    strip = ("wall_s", "cpu_s")
    for env, rows in pool["table"].items():
        for s, r in rows.items():
            other = ray["table"][env][s]
            assert {k: v for k, v in r.items() if k not in strip} == {
                k: v for k, v in other.items() if k not in strip
            }


def test_cli_benchmark_on_a_registered_gym_env(tmp_path, capsys, monkeypatch):
    monkeypatch.syspath_prepend(str(TESTS))
    code = main(
        [
            "benchmark",
            "--envs",
            "",
            "--gym-env",
            "_bench_env:BenchCluster-v0",
            "--teacher",
            "_bench_env:teacher",
            "--strategies",
            "bc,novelty",
            "--seeds",
            "1",
            "--workers",
            "1",
            "--budgets",
            "5,10",
            "--max-steps",
            "40",
            "--eval-episodes",
            "2",
            "--out",
            str(tmp_path / "b"),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0 and "| _bench_env:BenchCluster-v0 | novelty |" in out
    assert "wall" in out and "CPU" in out
    env = json.loads((tmp_path / "b" / "results.json").read_text())["envs"]
    assert env["_bench_env:BenchCluster-v0"]["eval_episodes"] == 2
    # --eval-steps alone is the evaluation's length: the default 10 episodes cut it short before
    argv = list(_TOY_SWEEP)
    argv += ["--teacher", "_bench_env:teacher", "--strategies", "bc", "--seeds", "1"]
    argv += ["--workers", "1", "--budgets", "5,10", "--max-steps", "40", "--eval-steps", "60"]
    assert main([*argv, "--out", str(tmp_path / "c")]) == 0
    env = json.loads((tmp_path / "c" / "results.json").read_text())["envs"]
    spec = env["_bench_env:BenchCluster-v0"]
    assert spec["eval_steps"] == 60 and spec["eval_episodes"] is None


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--strategies", "bc,nope"], "--strategies: unknown ['nope']"),
        # "" names no strategy (as --envs "" names no env), not all six
        (["--strategies", "", "--envs", "", "--gym-env", "X-v0"], "--strategies '' names no"),
        (["--envs", "mars"], "--envs: unknown ['mars']"),
        # a repeated name: the Python API's "give each EnvSpec its own name=", after the header
        (["--envs", "corridor,corridor"], "--envs corridor,corridor: ['corridor'] given more"),
        (["--strategies", "bc,dagger,bc"], "--strategies bc,dagger,bc: ['bc'] given more than"),
        (["--envs", "", "--gym-env", "X-v0"], "--gym-env needs --teacher"),
        (
            ["--quick", "--envs", "corridor", "--strategies", "bc,torchcbl.strategies:Nope"],
            "cannot import 'torchcbl.strategies:Nope'",
        ),
        (
            ["--envs", "", "--gym-env", "X-v0", "--teacher", "_bench_env:teacher"]
            + ["--eval-episodes", "0"],
            "argument --eval-episodes: expected a whole number >= 1",
        ),
        # the --gym-env options, without --gym-env, or with a bad value, name themselves
        (["--quick", "--envs", "corridor", "--budgets", "5,10"], "--budgets apply only to"),
        (["--quick", "--envs", "corridor", "--teacher", "m:f"], "--teacher apply only to"),
        (["--budgets", "10,x"], "argument --budgets: expected increasing comma-separated"),
        (["--budgets", "20,10"], "argument --budgets: expected increasing comma-separated"),
        (["--envs", "corridor", "--driving-teacher", "expert"], "--driving-teacher applies only"),
        (
            ["--envs", "", "--gym-env", "CartPole-v1", "--teacher", ".rel:fn"],
            "--teacher .rel:fn:",
        ),
        (["--max-steps", "-5"], "argument --max-steps: expected a whole number >= 1"),
        # 0 ran the default 10 seeds (a long sweep) where reproduce --seeds 0 is refused
        (
            ["--quick", "--envs", "corridor", "--seeds", "0"],
            "argument --seeds: expected a whole number from 1 to 10000, got '0' (leave --seeds "
            "out for the default: 3 with --quick, else 10)",
        ),
        (  # it ended in a one-line "MemoryError" with exit 1 (a list of 1e11 seeds)
            ["--quick", "--envs", "corridor", "--seeds", "99999999999"],
            "argument --seeds: expected a whole number from 1 to 10000, got '99999999999' "
            "(leave --seeds out for the default: 3 with --quick, else 10)",
        ),
        (
            ["--envs", "", "--gym-env", "_bench_env:BenchCluster-v0", "--teacher"]
            + ["_bench_env:teacher", "--max-steps", "50"],
            "--budgets 10,20,40,80 (the default): [80] above --max-steps 50",
        ),
        (
            ["--envs", "", "--gym-env", "CartPole-v1", "--teacher", "nomod:fn"],
            "--teacher nomod:fn: No module named 'nomod'",
        ),
        (
            ["--envs", "", "--gym-env", "CartPole-v1", "--teacher", "_bench_env:pole_teacher"]
            + ["--score", "_bench_env:nope"],
            "--score _bench_env:nope: cannot import",
        ),
    ],
)
def test_cli_benchmark_user_mistakes_are_one_line(argv, message, tmp_path, capsys):
    out = tmp_path / "b"
    try:
        code = main(["benchmark", "--out", str(out), *argv])
    except SystemExit as exc:  # argparse's own refusals
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(f"torchcbl benchmark: error: {message}") and err.count("\n") == 1
    assert not out.exists()  # refused before anything was written or run


def test_every_import_path_is_resolved_before_a_cell_runs(tmp_path):
    """A misspelt strategy, teacher or score fails at once with the name in the message,
    not in a worker after other cells have run; nothing is written."""
    cases = {
        "torchcbl.strategies.bc:Nope": ([bm.StrategySpec("torchcbl.strategies.bc:Nope")], _env()),
        "_bench_env:no_teacher": (STRATEGIES, _env(teacher="_bench_env:no_teacher")),
        "no_such_module": (STRATEGIES, _env(score="no_such_module:score")),
    }
    for name, (strategies, env) in cases.items():
        with pytest.raises(ImportError, match=name):
            bm.run_benchmark(strategies, [env], [0], tmp_path / "out", workers=1)
    assert not (tmp_path / "out").exists()
    # a misspelt env id of a second env: gymnasium's NameNotFound came from its first cell,
    # after the first env's cells had run
    with pytest.raises(ValueError, match=r"EnvSpec 'x': env_id '_bench_env:BenchClustr-v0': "):
        bm.run_benchmark(
            STRATEGIES[:1],
            [_env(), _env(name="x", env_id="_bench_env:BenchClustr-v0")],
            [0],
            tmp_path / "out",
            workers=1,
        )
    assert not (tmp_path / "out").exists()
    # a repeated env name or seed would be merged or counted twice in the tables
    with pytest.raises(ValueError, match=r"env names must be distinct.*\['toy', 'toy'\]"):
        bm.run_benchmark(STRATEGIES, [_env(), _env(budgets=(5,))], [0], tmp_path / "out")
    with pytest.raises(ValueError, match=r"seeds must be distinct.*\[0, 0\]"):
        bm.run_benchmark(STRATEGIES, [_env()], [0, 0], tmp_path / "out")
    assert not (tmp_path / "out").exists()
    with pytest.raises(ValueError, match="eval_episodes must be None or an int >= 1, got 0"):
        _env(eval_episodes=0)
    with pytest.raises(ValueError, match="score must be an import path"):
        _env(score="success_rate")


def test_seeds_are_checked_before_anything_is_written_and_a_numpy_array_is_read(tmp_path):
    """seeds=np.arange(2) raised numpy's "truth value of an array is ambiguous"; float or
    string seeds were truncated (0.5 and 0.7 ran the same cells twice, counted twice) and a
    negative one failed in the cell's model (before 2026-11-27)."""
    import numpy as np

    for seeds, shown in (([0.5, 0.7], r"\[0.5, 0.7\]"), (["0"], r"\['0'\]"), ([-1], r"\[-1\]"),
                         ([True], r"\[True\]"), (3, "got 3")):  # fmt: skip
        with pytest.raises(ValueError, match=rf"seeds must be .*ints.*{shown}"):
            bm.run_benchmark(STRATEGIES[:1], [_env()], seeds, tmp_path / "out", workers=1)
    assert not (tmp_path / "out").exists()
    with pytest.raises(ValueError, match=r"seeds must be distinct"):
        bm.run_benchmark(STRATEGIES[:1], [_env()], np.array([1, 1]), tmp_path / "out")
    env = _env(budgets=(5,), max_steps=10, eval_episodes=1, eval_seeds=(100,))
    out = bm.run_benchmark(
        STRATEGIES[:1], [env], np.arange(2), tmp_path / "o", workers=1, plots=False
    )
    assert out["sweep"]["seeds"] == [0, 1] and out["sweep"]["computed"] == 2


def test_a_score_the_env_never_feeds_is_called_out_not_read_as_instant_learning(
    tmp_path, capsys, monkeypatch
):
    """CartPole never sets info["is_success"]: with the default success_rate every performance,
    the teacher's too, is 0, so "labels to 95 %" would read as the first budget. It is left
    undefined, and the command says why."""
    monkeypatch.syspath_prepend(str(TESTS))
    argv = ["benchmark", "--envs", "", "--gym-env", "CartPole-v1"]
    argv += ["--teacher", "_bench_env:pole_teacher", "--strategies", "bc", "--seeds", "1"]
    argv += ["--workers", "1", "--budgets", "5,10", "--max-steps", "30", "--eval-episodes", "1"]
    assert main([*argv, "--out", str(tmp_path / "b")]) == 0
    err = capsys.readouterr().err
    assert "warning: the teacher scores 0 on CartPole-v1" in err and "--score" in err
    row = json.loads((tmp_path / "b" / "results.json").read_text())["table"]["CartPole-v1"]["bc"]
    assert row["teacher_performance"]["mean"] == 0.0
    assert row["labels_to_95pct"]["mean"] is None
    assert [s["labels"] for s in row["labels_to_95pct"]["per_seed"]] == [None]


@pytest.mark.parametrize(
    "bad, message",
    [
        ({"teaching": {"max_nwe": 2}}, "teaching: .*max_nwe"),
        ({"teaching": {"max_new": 0}}, "teaching: .*max_new"),
        # stop settings: max_episodes cut a cell short of its budgets and max_steps, and
        # max_demonstrations / max_steps were overridden by the budgets, all without a word
        ({"teaching": {"max_episodes": 2}}, r"teaching: \['max_episodes'\] say when to stop"),
        ({"teaching": {"max_steps": 50}}, r"teaching: \['max_steps'\] say when to stop"),
        (
            {"teaching": {"max_demonstrations": 9, "autonomous_steps_to_stop": 3}},
            r"\['autonomous_steps_to_stop', 'max_demonstrations'\] say when",
        ),
        ({"model": {"max_componets": 2}}, "model: .*max_componets"),
        ({"model": {"seed": 1}}, r"model: \['seed'\] come from"),
        ({"eval_seeds": "abc"}, "eval_seeds must be a non-empty tuple of ints"),
        ({"eval_seeds": (1.5,)}, "eval_seeds must be a non-empty tuple of ints"),
        ({"budgets": (True,)}, "budgets must be increasing ints"),
        ({"max_steps": True}, "max_steps must be an int"),
        # one label per step at most: budget 20 of 15 steps is never reached by any strategy
        ({"max_steps": 15}, r"budgets \[20\] are above max_steps 15; .* raise max_steps"),
    ],
)
def test_an_env_spec_refuses_what_every_worker_would_fail_on(bad, message):
    with pytest.raises(ValueError, match=message):
        _env(**bad)


def test_an_env_spec_takes_numpy_ints_as_the_ints_they_hold():
    np = pytest.importorskip("numpy")
    sweep = _env(
        budgets=tuple(np.arange(5, 25, 5)),
        max_steps=np.int64(60),
        eval_episodes=np.int32(3),
        eval_seeds=np.arange(100, 102),
    )
    plain = _env(budgets=(5, 10, 15, 20))
    assert sweep == plain
    # the spec's JSON (the cache key of its cells) is the plain spec's
    assert json.dumps(sweep.to_dict(), sort_keys=True) == json.dumps(
        plain.to_dict(), sort_keys=True
    )
    for bad in ("5", 5):
        with pytest.raises(ValueError, match="budgets must be increasing ints"):
            _env(budgets=bad)
    with pytest.raises(ValueError, match="eval_seeds must be a non-empty tuple"):
        _env(eval_seeds=7)


def test_a_cells_seed_seeds_daggers_coins_unless_its_params_do():
    # format 1 built DAgger() with its default seed 0 in every cell: the coins deciding who acts
    # were the same for every seed of a sweep, so its spread was understated (48 +- 0 context
    # switches on the corridor)
    spec = bm.StrategySpec("dagger", {"iteration_steps": 10})
    coins = [[spec.build(seed).coin(t) for t in range(20)] for seed in (0, 1)]
    assert coins[0] != coins[1]
    assert spec.build(3).seed == 3 and spec.build().seed == 0
    assert bm.StrategySpec("dagger", {"seed": 7}).build(3).seed == 7  # the params' seed wins
    assert bm.StrategySpec("bc").build(3) is not None  # a strategy without a seed is as before
    assert bm.CELL_FORMAT == 5  # cached cells of formats 1 to 4 are recomputed


def test_a_strategy_takes_its_own_teaching_settings_over_the_envs():
    """Every strategy took its env's TeachingConfig, so the `cba` row always had confident
    execution's non-interactive phase, and CBA as JAIR 2009 publishes it (no such phase)
    could not run beside it (science review). StrategySpec(teaching=...) overrides the env's
    learning fields for that strategy's cells; the override is part of their key."""
    published = bm.StrategySpec("cba", label="cba-jair", teaching={"noninteractive": False})
    plain = bm.StrategySpec("cba")
    assert "teaching" not in plain.to_dict()  # a spec without it keeps its cells' key
    spec = _env(teacher="_bench_env:teacher")
    cells = {
        c["strategy"]["label"]: bm.run_cell(c)
        for c in bm.cell_configs([plain, published], [spec], [0])
    }
    a, b = cells["cba"]["attention"], cells["cba-jair"]["attention"]
    # the phase asks at every step until its window is full; without it the learner acts
    assert b["agent_actions"] > a["agent_actions"], (a, b)
    assert cells["cba"]["key"] != cells["cba-jair"]["key"]
    for teaching, says in (
        ({"max_episodes": 3}, "say when to stop"),
        ({"nonintractive": False}, "nonintractive"),
        ({"accuracy_window": 0}, "accuracy_window"),
    ):
        with pytest.raises(ValueError, match=says):
            bm.StrategySpec("cba", teaching=teaching)


def test_strategy_teaching_is_given_on_the_command_line(tmp_path, capsys, monkeypatch):
    monkeypatch.syspath_prepend(str(TESTS))
    argv = list(_TOY_SWEEP)
    argv += ["--teacher", "_bench_env:teacher", "--strategies", "bc,cba"]
    argv += _ONE_TINY_CELL
    argv += ["--workers", "1", "--out", str(tmp_path / "b")]
    given = ["--strategy-teaching", "cba.noninteractive=false"]
    assert main([*argv, *given]) == 0
    cells = [json.loads(p.read_text()) for p in (tmp_path / "b" / "cells").glob("*.json")]
    teaching = {c["strategy"]: c["config"]["strategy"].get("teaching") for c in cells}
    assert teaching == {"bc": None, "cba": {"noninteractive": False}}
    capsys.readouterr()
    for bad, says in (
        ("cba.nonintractive=false", "nonintractive"),
        ("cba.max_episodes=3", "say when to stop"),
        ("dagger.noninteractive=false", "dagger is not among --strategies"),
    ):
        assert main([*argv, "--strategy-teaching", bad, "--out", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and says in err and "--strategy-teaching" in err, err
    assert not (tmp_path / "x").exists()


def test_a_strategy_spec_is_a_known_name_or_an_import_path():
    for name in ("dagerr", 5):
        with pytest.raises(ValueError, match="StrategySpec: name must be one of"):
            bm.StrategySpec(name)
    bm.StrategySpec("torchcbl.strategies.bc:BehaviourCloning")  # a path is resolved later


def test_run_benchmark_refuses_a_worker_count_below_one(tmp_path):
    for workers in (0, -2, True):
        with pytest.raises(ValueError, match="workers must be None"):
            bm.run_benchmark(STRATEGIES, [_env()], [0], tmp_path / "out", workers=workers)
    assert not (tmp_path / "out").exists()


def test_numpy_parameters_are_the_plain_cell_and_a_non_json_one_is_refused(tmp_path):
    """A sweep over numpy values (np.arange, np.float32) in a strategy's params or an env's
    kwargs got a cache key of its own (str(np.int64(10)) is '"10"') and then failed writing the
    cell it had just computed ("Object of type int64 is not JSON serializable")."""
    np = pytest.importorskip("numpy")
    swept = bm.StrategySpec("dagger", {"iteration_steps": np.int64(10), "decay": np.float32(0.5)})
    plain = bm.StrategySpec("dagger", {"iteration_steps": 10, "decay": 0.5})
    env = _env(
        budgets=(5,), max_steps=10, eval_episodes=1, eval_seeds=(100,),
        env_kwargs={"spread": np.float32(2.0)}, teaching={"max_new": np.int64(5)},
    )  # fmt: skip
    env_plain = _env(budgets=(5,), max_steps=10, eval_episodes=1, eval_seeds=(100,))
    assert bm.cell_configs([swept], [env], [0]) == bm.cell_configs([plain], [env_plain], [0])
    res = bm.run_benchmark([swept], [env], [0], tmp_path / "o", workers=1, plots=False)
    (key,) = res["cells"]
    assert key == bm.cell_key(bm.cell_configs([plain], [env_plain], [0])[0])
    assert (tmp_path / "o" / "cells" / f"{key}.json").exists()
    with pytest.raises(
        ValueError, match=r"params\['rule'\] = <object object.* is not a JSON value"
    ):
        bm.StrategySpec("torchcbl.strategies:ConfidentExecution", {"rule": object()})
    with pytest.raises(ValueError, match=r"env_kwargs\['size'\]\[1\] = .* is not a JSON value"):
        _env(env_kwargs={"size": [1, np.zeros(2)]})


def test_an_in_process_sweep_leaves_the_callers_torch_threads_and_rng_alone(tmp_path):
    """run_benchmark(workers=1) runs its cells in the caller's process; each cell runs on one
    torch thread from its own seed, and the caller was left with one thread (a notebook's
    later training ran single-threaded), its global torch RNG reseeded to the last cell's seed
    and OMP_NUM_THREADS set in its environment. Its results said the engine was
    "process_pool"; they say "in_process"."""
    import torch

    threads = torch.get_num_threads()
    omp = os.environ.get("OMP_NUM_THREADS")
    torch.set_num_threads(2)
    try:
        torch.manual_seed(1234)
        expected = torch.rand(3)
        torch.manual_seed(1234)
        env = _env(budgets=(5,), max_steps=10, eval_episodes=1, eval_seeds=(100,))
        res = bm.run_benchmark(STRATEGIES[:1], [env], [0, 1], tmp_path, workers=1, plots=False)
        assert res["sweep"]["engine"] == "in_process" and res["sweep"]["workers"] == 1
        assert json.loads((tmp_path / "results.json").read_text())["sweep"]["engine"] == (
            "in_process"
        )
        assert torch.get_num_threads() == 2
        assert torch.equal(torch.rand(3), expected)
        assert os.environ.get("OMP_NUM_THREADS") == omp
    finally:
        torch.set_num_threads(threads)


def test_an_in_process_sweep_leaves_the_callers_cuda_generators_alone(tmp_path, monkeypatch):
    """A cell seeds torch's CPU generator (and gives the caller's back); it reseeded every CUDA
    generator as well (torch.manual_seed), which run_cell does not give back: after
    run_benchmark(workers=1) the caller's CUDA draws followed the last cell's seed (on a machine
    without CUDA, torch queues the seed for when CUDA starts)."""
    import torch

    reseeded = []
    monkeypatch.setattr(torch.cuda, "manual_seed_all", lambda seed: reseeded.append(seed))
    monkeypatch.setattr(torch.cuda, "manual_seed", lambda seed: reseeded.append(seed))
    before = torch.cuda.get_rng_state_all() if torch.cuda.is_initialized() else None
    env = _env(budgets=(5,), max_steps=10, eval_episodes=1, eval_seeds=(100,))
    bm.run_benchmark(STRATEGIES[:1], [env], [0, 1], tmp_path, workers=1, plots=False)
    assert reseeded == []
    if before is not None:
        after = torch.cuda.get_rng_state_all()
        assert all(torch.equal(a, b) for a, b in zip(before, after, strict=True))


def test_an_env_the_loop_cannot_teach_is_named_with_what_it_needs(tmp_path, capsys, monkeypatch):
    """Pendulum's actions are a Box: the cell failed with "AttributeError: 'Box' object has no
    attribute 'n'" (the command: exit code 1, no word of what the benchmark needs)."""
    monkeypatch.syspath_prepend(str(TESTS))
    env = _env(env_id="Pendulum-v1", env_kwargs={}, teacher="_bench_env:pole_teacher")
    with pytest.raises(bm.CellError, match=r"'toy' \(Pendulum-v1\): expected .* Discrete action"):
        bm.run_benchmark(STRATEGIES[:1], [env], [0], tmp_path / "o", workers=1, plots=False)
    argv = ["benchmark", "--envs", "", "--gym-env", "Pendulum-v1", "--strategies", "bc"]
    argv += ["--teacher", "_bench_env:pole_teacher", "--seeds", "1", "--workers", "1"]
    assert main([*argv, "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "Discrete action space" in err and err.count("\n") == 1


@pytest.mark.parametrize("strategy", ["bc", "hg_dagger"])
def test_a_factory_that_returns_a_policy_is_told_to_wrap_it(strategy, tmp_path, monkeypatch):
    """A teacher factory returning a policy of the observation alone: CBA's and HG-DAgger's
    cells wrap the teacher in correcting(), which hid its signature, so the cell failed at the
    first request with "the teacher raised TypeError: <lambda>() takes 1 positional argument
    but 2 were given"; then, once correcting() read it, the advice named correcting(), a call
    the user never made. Every strategy's cell now says how a teacher is called and to wrap
    the policy in the factory (docs/benchmark.md says so)."""
    monkeypatch.syspath_prepend(str(TESTS))
    env = _env(teacher="_bench_env:policy_as_teacher", budgets=(5,), max_steps=10)
    spec = [bm.StrategySpec(strategy)]
    with pytest.raises(bm.CellError) as caught:
        bm.run_benchmark(spec, [env], [0], tmp_path / "o", workers=1, plots=False)
    text = str(caught.value)
    assert "teacher(observation, info)" in text and "takes (obs)" in text, text
    assert "lambda obs, info: policy(obs)" in text and "correcting(" not in text, text


@pytest.mark.parametrize("workers", [1, 2])
def test_a_failing_cell_is_named_and_the_finished_cells_are_kept(
    workers, tmp_path, monkeypatch, capsys
):
    """A teacher that raised on one seed stopped the sweep with its bare message ("the teacher
    raised ValueError: sensor glitch (step 2) ..."): nothing said which of the cells it was."""
    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join([str(TESTS), str(ROOT), os.environ.get("PYTHONPATH", "")])
    )
    env = _env(teacher="_bench_env:glitchy_teacher", budgets=(5,), max_steps=10)
    seeds = [0, 1] if workers == 1 else [1]
    with pytest.raises(bm.CellError) as caught:
        bm.run_benchmark(STRATEGIES[:1], [env], seeds, tmp_path, workers=workers, plots=False)
    (config,) = bm.cell_configs(STRATEGIES[:1], [env], [1])
    text = str(caught.value)
    assert text.startswith(f"cell {bm.cell_key(config)} (env 'toy', strategy 'bc', seed 1) failed")
    assert "sensor glitch" in text
    assert caught.value.config == config and "sensor glitch" in str(caught.value.__cause__)
    kept = [json.loads(p.read_text())["seed"] for p in (tmp_path / "cells").glob("*.json")]
    assert kept == ([0] if workers == 1 else [])  # the cell before it is kept
    if kept:  # (none kept: test_a_sweep_that_stops_before_any_cell_finished_says_so)
        assert f"the 1 finished cell is kept in {tmp_path / 'cells'}" in text
    if workers == 1:  # and at the command line: one line, the cell named
        argv = list(_TOY_SWEEP)
        argv += ["--teacher", "_bench_env:glitchy_teacher", "--strategies", "bc", "--seeds", "2"]
        argv += ["--workers", "1", "--budgets", "5", "--max-steps", "10", "--eval-episodes", "1"]
        monkeypatch.syspath_prepend(str(TESTS))
        assert main([*argv, "--out", str(tmp_path / "cli")]) == 2
        err = capsys.readouterr().err
        assert "(env '_bench_env:BenchCluster-v0', strategy 'bc', seed 1) failed" in err
        assert err.startswith("torchcbl benchmark: error: cell ") and err.count("\n") == 1


def test_a_sweep_that_stops_before_any_cell_finished_says_so_and_leaves_no_empty_folder(
    tmp_path, monkeypatch, capsys
):
    """A sweep whose first cell failed said "the cells finished before it are kept in
    OUT/cells; ... run the same sweep again to compute the rest", though none had finished, and
    left OUT/cells/ empty behind (so did --ray without Ray). It says that no cell finished, and
    the folders it made and left empty are gone; an OUT it did not make stays."""
    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join([str(TESTS), str(ROOT), os.environ.get("PYTHONPATH", "")])
    )
    env = _env(teacher="_bench_env:glitchy_teacher", budgets=(5,), max_steps=10)
    for workers in (1, 2):
        out = tmp_path / f"w{workers}" / "out"
        with pytest.raises(bm.CellError) as caught:
            bm.run_benchmark(STRATEGIES[:1], [env], [1], out, workers=workers, plots=False)
        text = str(caught.value)
        assert "no cell of this sweep has finished (none is kept)" in text, text
        assert "kept in" not in text and "the rest" not in text
        assert not (tmp_path / f"w{workers}").exists()
    mine = tmp_path / "mine"
    mine.mkdir()
    with pytest.raises(bm.CellError):
        bm.run_benchmark(STRATEGIES[:1], [env], [1], mine, workers=1, plots=False)
    assert mine.is_dir() and list(mine.iterdir()) == []
    # Ray missing: the same at the command line, one line, nothing left
    monkeypatch.setitem(sys.modules, "ray", None)
    monkeypatch.syspath_prepend(str(TESTS))
    argv = [*_TOY_SWEEP, "--teacher", "_bench_env:teacher", "--strategies", "bc"]
    argv += [*_ONE_TINY_CELL, "--ray"]
    assert main([*argv, "--out", str(tmp_path / "ray" / "out")]) == 2
    err = capsys.readouterr().err
    assert "Ray is not installed" in err and err.count("\n") == 1
    assert not (tmp_path / "ray").exists()


def test_a_cell_finished_after_another_sweep_removed_the_empty_out_is_kept(tmp_path):
    """Two sweeps started into the same new OUT (the cell cache is shared): the one whose first
    cell failed removed OUT/cells and OUT, still empty, and the other's first finished cell
    was then lost to a raw FileNotFoundError writing cells/<key>.json. The cell writer makes
    its folder again: the sweep finishes, its cell kept."""
    out = tmp_path / "out"
    env = _env(
        teacher="_bench_env:teacher_of_a_cleaned_out",
        teacher_kwargs={"out": str(out)},
        budgets=(5,),
        max_steps=10,
        eval_episodes=1,
    )
    summary = bm.run_benchmark(STRATEGIES[:1], [env], [0], out, workers=1, plots=False)
    (config,) = bm.cell_configs(STRATEGIES[:1], [env], [0])
    kept = json.loads((out / "cells" / f"{bm.cell_key(config)}.json").read_text())
    assert kept["key"] == bm.cell_key(config) and summary["sweep"]["computed"] == 1
    assert (out / "results.json").is_file()


def test_a_teacher_scoring_below_zero_is_not_blamed_on_success_rate(tmp_path, capsys, monkeypatch):
    """With --score a return-like score (the teacher: -14), the warning said "success_rate
    needs an env that sets info["is_success"] ... every performance is 0 ... pass --score",
    none of it true; the plot drew "95 % of teacher" above the teacher's line (0.95 x -14)."""
    monkeypatch.syspath_prepend(str(TESTS))
    argv = list(_TOY_SWEEP)
    argv += ["--teacher", "_bench_env:teacher", "--score", "_bench_env:steps_over_budget"]
    argv += ["--strategies", "bc", "--seeds", "1", "--workers", "1", "--budgets", "5"]
    argv += ["--max-steps", "10", "--eval-episodes", "1", "--out", str(tmp_path / "b")]
    import matplotlib.figure

    drawn = []
    save = matplotlib.figure.Figure.savefig

    def savefig(fig, *args, **kwargs):
        drawn.extend(line.get_label() for ax in fig.axes for line in ax.get_lines())
        return save(fig, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "warning: the teacher scores -10 on _bench_env:BenchCluster-v0" in err
    assert '"labels to 95 %" needs a teacher score above 0' in err
    assert "_bench_env:steps_over_budget" in err and "success_rate" not in err
    assert "teacher" in drawn and "95 % of teacher" not in drawn


def test_a_cell_is_the_same_whatever_the_callers_numpy_and_random_state():
    """A teacher of one's own that draws from numpy's or Python's global RNG made a cell depend
    on what ran before it in the process (HG-DAgger here: 59 steps and 10 wrong actions after
    np.random.seed(1), 75 and 12 after np.random.seed(2)), so the process pool, Ray and an
    in-process sweep could cache different figures for one key. A cell seeds both from its
    seed, and gives the caller its own states back."""
    import random

    import numpy as np

    env = _env(teacher="_bench_env:sloppy_teacher", budgets=(5, 10, 20), max_steps=80)
    (config,) = bm.cell_configs([bm.StrategySpec("hg_dagger")], [env], [0])
    cells = []
    for caller_seed in (1, 2):
        np.random.seed(caller_seed)  # noqa: NPY002
        random.seed(caller_seed)
        cells.append(_figures(bm.run_cell(config)))
        # the caller's global RNGs go on as if the cell had not run
        np.random.seed(caller_seed)  # noqa: NPY002
        random.seed(caller_seed)
        expected = (np.random.random(), random.random())  # noqa: NPY002
        np.random.seed(caller_seed)  # noqa: NPY002
        random.seed(caller_seed)
        bm.run_cell(config)
        assert (np.random.random(), random.random()) == expected  # noqa: NPY002
    assert cells[0] == cells[1]
    assert cells[0]["attention"]["corrections"] > 0  # the sloppy teacher's answers mattered


def test_a_cells_global_numpy_rng_follows_its_seed():
    """A teacher factory of one's own that draws from numpy's global RNG gets draws seeded by
    the cell's seed: the same for two runs of one seed, others for the next seed (not one
    fixed stream for every cell, which would make the seeds' figures share their noise)."""
    import _bench_env

    env = _env(
        teacher="_bench_env:drawing_teacher",
        budgets=(5,),
        max_steps=10,
        eval_seeds=(100,),
        eval_episodes=1,
    )
    configs = bm.cell_configs(STRATEGIES[:1], [env], [0, 1])
    first = []
    for config in (configs[0], configs[0], configs[1]):
        _bench_env.GLOBAL_DRAWS.clear()
        bm.run_cell(config)
        first.append(_bench_env.GLOBAL_DRAWS[0])  # the factory's first call of the cell
    assert first[0] == first[1]
    assert first[0] != first[2]


@pytest.mark.parametrize("workers, says", [("1", "in this process"), ("2", "2 processes")])
def test_the_command_says_where_the_cells_run(workers, says, tmp_path, monkeypatch, capsys):
    """torchcbl benchmark --workers 1 announced "(1 processes)", but such a sweep runs its
    cells in the command's own process, no pool started."""
    monkeypatch.syspath_prepend(str(TESTS))
    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join([str(TESTS), str(ROOT), os.environ.get("PYTHONPATH", "")])
    )
    argv = list(_TOY_SWEEP)
    argv += ["--teacher", "_bench_env:teacher", "--strategies", "bc", "--seeds", "1"]
    argv += ["--workers", workers, "--budgets", "5", "--max-steps", "10", "--eval-episodes", "1"]
    assert main([*argv, "--out", str(tmp_path / "out")]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.endswith(f"cells into {tmp_path / 'out'} ({says})"), first


def test_a_sweep_that_stops_early_leaves_no_earlier_results_that_read_as_its_own(tmp_path):
    """A sweep into an OUT where an earlier (other) sweep had finished, stopped by a failing
    cell (or Ctrl-C), left the earlier results.json and learning_curves.png there: they read
    as the new sweep's results. A sweep now removes them first; one that finishes writes its
    own, and running the earlier sweep again rewrites its results from its cached cells."""
    env = _env(budgets=(5,), max_steps=10, eval_episodes=1, eval_seeds=(100,))
    earlier = bm.run_benchmark(STRATEGIES[:1], [env], [0], tmp_path, workers=1)
    assert (tmp_path / "results.json").is_file() and (tmp_path / "learning_curves.png").is_file()
    glitchy = dataclasses.replace(env, teacher="_bench_env:glitchy_teacher")
    with pytest.raises(bm.CellError, match="seed 1"):
        bm.run_benchmark(STRATEGIES[:1], [glitchy], [0, 1], tmp_path, workers=1)
    assert not (tmp_path / "results.json").exists()
    assert not (tmp_path / "learning_curves.png").exists()
    again = bm.run_benchmark(STRATEGIES[:1], [env], [0], tmp_path, workers=1, plots=False)
    assert again["sweep"]["cached"] == 1 and again["table"] == earlier["table"]
    assert not (tmp_path / "learning_curves.png").exists()  # no plot asked: none of another


def test_a_score_that_is_not_a_finite_number_is_named_not_tabled(tmp_path):
    """A mean over the finished episodes of an evaluation cut before any ended is NaN: the
    sweep went on and wrote "nan ± nan" into every performance column of the table (and NaN,
    not JSON, into results.json), with no word of why; a score returning None failed with
    float()'s TypeError."""
    env = _env(budgets=(5,), max_steps=10, eval_episodes=None, eval_steps=3)
    for score, shown in (("mean_finished_length", "nan"), ("no_score", "None")):
        with pytest.raises(bm.CellError) as caught:
            bm.run_benchmark(
                STRATEGIES[:1],
                [dataclasses.replace(env, score=f"_bench_env:{score}")],
                [0],
                tmp_path / score,
                workers=1,
                plots=False,
            )
        text = str(caught.value)
        assert f"score _bench_env:{score} returned {shown} for the teacher on evaluation" in text
        assert "(3 steps, 0 finished episodes); expected a finite number" in text
        assert not (tmp_path / score / "results.json").exists()
    # a score that is finite once an episode ends: the same env with 10-step episodes
    fine = dataclasses.replace(env, score="_bench_env:mean_finished_length", eval_steps=25)
    out = bm.run_benchmark(STRATEGIES[:1], [fine], [0], tmp_path / "ok", workers=1, plots=False)
    assert out["table"]["toy"]["bc"]["teacher_performance"]["mean"] == 10.0


def test_a_strategys_params_are_checked_before_any_cell_runs(tmp_path):
    """StrategySpec("dagger", {"beta": 0.3}) (DAgger takes beta0) failed in its first cell,
    after every cell of the strategies before it had run; an out-of-range value too."""
    cases = [
        (("dagger", {"beta": 0.3}), r"unexpected keyword argument 'beta'"),
        (("dagger", {"beta0": 3}), r"beta0 must be a number in \[0, 1\], got 3"),
        (("confident", {"max_std": -1}), r"DistanceRule.max_std: expected a value > 0"),
    ]
    for (name, params), cause in cases:
        ran = []
        with pytest.raises(
            ValueError, match=rf"StrategySpec '{name}': cannot make {name} .*{cause}"
        ):
            bm.run_benchmark(
                [bm.StrategySpec("bc"), bm.StrategySpec(name, params)],
                [_env(budgets=(5,), max_steps=10)],
                [0],
                tmp_path / "out",
                workers=1,
                on_cell=lambda cell, cached, ran=ran: ran.append(cell["strategy"]),
            )
        assert ran == [] and not (tmp_path / "out").exists()


def test_teacher_kwargs_that_do_not_fit_the_factory_are_refused_before_any_cell_runs(tmp_path):
    """A misspelt teacher keyword, or a seed the cell passes itself, failed in the env's first
    cell (TypeError: got an unexpected keyword argument / multiple values for 'seed'), after
    every cell of the envs listed before it had run."""
    first = _env(name="first", budgets=(5,), max_steps=10)
    cases = [
        (_env(name="x", teacher_kwargs={"greedy": True}), r"unexpected keyword .*'greedy'"),
        (
            _env(name="x", teacher="_bench_env:glitchy_teacher", teacher_kwargs={"seed": 3}),
            r"\['seed'\] come from the cell; leave them out",
        ),
    ]
    for env, cause in cases:
        ran = []
        with pytest.raises(
            ValueError, match=rf"EnvSpec 'x': teacher_kwargs .* do not fit .*{cause}"
        ):
            bm.run_benchmark(
                STRATEGIES[:1],
                [first, env],
                [0],
                tmp_path / "out",
                workers=1,
                on_cell=lambda cell, cached, ran=ran: ran.append(cell["env"]),
            )
        assert ran == [] and not (tmp_path / "out").exists()


def test_a_worker_killed_mid_sweep_is_not_blamed_on_another_cell(tmp_path, monkeypatch):
    """A worker killed by a signal (the out-of-memory killer) breaks the pool: every unfinished
    cell then fails with BrokenProcessPool, and the error named whichever of them the wait
    returned first (seed 2's cell for a death in seed 1's) as the cell that failed."""
    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join([str(TESTS), str(ROOT), os.environ.get("PYTHONPATH", "")])
    )
    env = _env(teacher="_bench_env:dying_teacher", budgets=(5,), max_steps=10)
    with pytest.raises(RuntimeError) as caught:
        bm.run_benchmark(STRATEGIES[:1], [env], [0, 1, 2], tmp_path, workers=2, plots=False)
    assert not isinstance(caught.value, bm.CellError)
    text = str(caught.value)
    assert text.startswith("a worker process was killed by SIGKILL (the out-of-memory killer")
    assert "while it ran one of the unfinished cells" in text
    assert str(tmp_path / "cells") in text and "run the same sweep again" in text
    kept = [json.loads(p.read_text())["seed"] for p in (tmp_path / "cells").glob("*.json")]
    assert 1 not in kept


def test_a_killed_worker_is_named_when_the_pools_own_thread_reaps_it_first(tmp_path, monkeypatch):
    """The pool's own thread, seeing the pool broken, terminates and joins every worker while
    the sweep's error handling does the same: the two reap the same processes. The thread
    that lost the race to a process's exit got "no such child" and read no exit code, so a
    CI run named SIGTERM (the others' termination) for the SIGKILLed worker. Here the pool's
    thread is slowed between reaping a worker and keeping its code, as the race does."""
    import threading

    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join([str(TESTS), str(ROOT), os.environ.get("PYTHONPATH", "")])
    )
    real = os.waitpid

    killed_reaped = threading.Event()

    def reaped_first_elsewhere(pid, flags):
        if threading.current_thread() is threading.main_thread():
            try:  # a look without reaping: the killed worker is left to the pool's thread
                seen = os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
            except ChildProcessError:
                seen = None
            if seen is not None and seen.si_code == os.CLD_KILLED:
                killed_reaped.wait(timeout=5)
            return real(pid, flags)
        got = real(pid, flags)
        if got[0] == pid and os.WIFSIGNALED(got[1]) and os.WTERMSIG(got[1]) == signal.SIGKILL:
            killed_reaped.set()
            time.sleep(3.0)  # reaped: its code kept only after this
        return got

    monkeypatch.setattr(os, "waitpid", reaped_first_elsewhere)
    env = _env(teacher="_bench_env:dying_teacher", budgets=(5,), max_steps=10)
    with pytest.raises(RuntimeError) as caught:
        bm.run_benchmark(STRATEGIES[:1], [env], [0, 1, 2], tmp_path, workers=2, plots=False)
    text = str(caught.value)
    assert text.startswith("a worker process was killed by SIGKILL (the out-of-memory killer"), text


def test_a_script_without_the_main_guard_is_told_so_not_that_a_worker_was_killed(tmp_path):
    """run_benchmark with a pool, at a script's top level: each spawned worker re-ran the
    script and exited with code 1 at start-up, and the sweep said "a worker process died
    abruptly (killed by a signal, or out of memory)". It now names the script and the guard."""
    from _scripts import run_unguarded

    last = run_unguarded(
        tmp_path,
        "from torchcbl import benchmark as bm\n"
        "from test_benchmark import STRATEGIES, _env\n"
        "bm.run_benchmark(STRATEGIES[:1], [_env(budgets=(5,), max_steps=10)], [0, 1], 'bench',\n"
        "                 workers=2, plots=False)\n",
    )
    assert "killed" not in last
    assert not list((tmp_path / "bench").glob("cells/*.json"))


def test_a_cell_error_comes_back_from_a_process_of_ones_own(tmp_path, monkeypatch):
    """A sweep run in a worker process of one's own (a pool of sweeps, a notebook's executor)
    sends its CellError back pickled; CellError(config, cause, out) could not be rebuilt from
    its message, so the parent got a BrokenProcessPool or an unpickling TypeError instead."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join([str(TESTS), str(ROOT), os.environ.get("PYTHONPATH", "")])
    )
    import _bench_env

    with ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as pool:
        exc = pool.submit(_bench_env.failing_sweep, str(tmp_path)).exception()
    assert isinstance(exc, bm.CellError), repr(exc)
    assert "(env 'toy', strategy 'bc', seed 1) failed: TeacherError" in str(exc)
    assert exc.config["seed"] == 1 and exc.key == bm.cell_key(exc.config)


def test_plot_curves_leaves_the_callers_matplotlib_backend_and_figures_alone(tmp_path):
    """plot_curves called matplotlib.use("Agg"): in a notebook, inline figures stopped showing
    after it (the backend stayed switched). It draws on a bare Figure now, so the caller's
    backend, open figures and rcParams are as they were, and the PNG is still written."""
    import matplotlib
    import matplotlib.pyplot as plt

    cells = [
        {
            "env": "e",
            "strategy": strat,
            "teacher_performance": 1.0,
            "curve": [
                {"labels": n, "performance": p + 0.01 * seed} for n, p in ((5, 0.2), (10, 0.9))
            ],
        }
        for strat in ("cbl", "bc")
        for seed in range(2)
    ]
    old = matplotlib.get_backend()
    plt.switch_backend("svg")  # stands for the caller's own (inline, interactive) backend
    try:
        mine = plt.figure()
        rc = {k: str(v) for k, v in matplotlib.rcParams.items()}
        out = bm.plot_curves(cells, tmp_path / "curves.png", envs=["e"])
        assert matplotlib.get_backend() == "svg"
        assert plt.get_fignums() == [mine.number] and plt.gcf() is mine
        assert {k: str(v) for k, v in matplotlib.rcParams.items()} == rc
        assert out.read_bytes().startswith(b"\x89PNG")
    finally:
        plt.close("all")
        plt.switch_backend(old)


@pytest.mark.parametrize(
    "score, bounded",
    [
        ("torchcbl.benchmark:success_rate", True),
        ("torchcbl.benchmark:no_penalty_share", True),
        ("_bench_env:mean_return", False),  # a score of one's own: its range is not known
    ],
)
def test_plot_curves_keeps_the_sd_band_of_a_share_within_0_and_1(
    tmp_path, monkeypatch, score, bounded
):
    """The learning curves' +-1 sd band was drawn as mean +- sd whatever the score: for the
    shipped scores, shares in [0, 1], it went above 1 (a success rate of 1.08) and below 0.
    The band of a share is clipped to [0, 1]; the mean line is as it was, and the band of a
    score whose range is not known is not clipped."""
    from matplotlib.collections import PolyCollection
    from matplotlib.figure import Figure

    drawn = []
    savefig = Figure.savefig

    def keep(fig, *args, **kwargs):
        drawn.append(fig)
        return savefig(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    # 5 labels: 0.0 and 0.3 (mean - sd < 0); 10 labels: 1.0 and 0.6 (mean + sd > 1)
    cells = [
        {
            "env": "e",
            "strategy": "cbl",
            "config": {"env": {"score": score}},
            "teacher_performance": 1.0,
            "curve": [{"labels": 5, "performance": lo}, {"labels": 10, "performance": hi}],
        }
        for lo, hi in ((0.0, 1.0), (0.3, 0.6))
    ]
    bm.plot_curves(cells, tmp_path / "curves.png", envs=["e"])
    (ax,) = drawn[0].axes
    (band,) = [c for c in ax.collections if isinstance(c, PolyCollection)]
    y = np.concatenate([p.vertices[:, 1] for p in band.get_paths()])
    mean = np.array([0.15, 0.8])
    sd = np.std([[0.0, 1.0], [0.3, 0.6]], axis=0, ddof=1)
    np.testing.assert_allclose(ax.lines[0].get_ydata(), mean)  # the mean line is untouched
    if bounded:
        assert y.min() == pytest.approx(0.0) and y.max() == pytest.approx(1.0)
    else:
        assert y.min() == pytest.approx((mean - sd)[0])
        assert y.max() == pytest.approx((mean + sd)[1])


def test_a_teacher_given_where_its_factory_belongs_is_refused_before_any_cell_runs(
    tmp_path, capsys, monkeypatch
):
    """EnvSpec.teacher (--teacher) names a factory that returns the teacher; naming the teacher
    itself, teacher(obs, info), passed the up-front check and failed in the env's first cell
    (TypeError: teacher() missing 2 required positional arguments), after every cell of the
    envs listed before it had run, with nothing saying that a factory was expected."""
    first = _env(name="first", budgets=(5,), max_steps=10)
    bare = _env(name="x", teacher="_bench_env:bare_teacher")
    ran = []
    with pytest.raises(
        ValueError, match=r"EnvSpec .x.: teacher ._bench_env:bare_teacher. must name a factory"
    ):
        bm.run_benchmark(
            STRATEGIES[:1],
            [first, bare],
            [0],
            tmp_path / "out",
            workers=1,
            on_cell=lambda cell, cached: ran.append(cell["env"]),
        )
    assert ran == [] and not (tmp_path / "out").exists()
    monkeypatch.syspath_prepend(str(TESTS))
    argv = list(_TOY_SWEEP)
    argv += ["--teacher", "_bench_env:bare_teacher", "--out", str(tmp_path / "cli")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "factory" in err and "(obs, info)" in err
    assert not (tmp_path / "cli").exists()


@pytest.mark.parametrize(
    "gym_env, says",
    [
        # a namespaced id whose package was not imported: gymnasium said only "Namespace mygrid
        # not found. Have you installed the proper package for mygrid?"
        ("mygrid/Point-v0", "--gym-env mygrid:mygrid/Point-v0"),
        ("Point-v0", "--gym-env mymodule:Point-v0"),
        # the module was imported, but it does not register that id
        ("_bench_env:Point-v0", "_bench_env was imported but registers no such id"),
        # gymnasium knows the name, only not that version or spelling: no module hint
        ("CartPole-v9", "versioned environments"),
        ("Cartpole-v1", "Did you mean"),
    ],
)
def test_an_env_id_without_its_module_says_how_to_name_the_module(
    gym_env, says, tmp_path, capsys, monkeypatch
):
    """`--gym-env mygrid/Point-v0`, the id without the module that registers it, gave
    gymnasium's bare "Namespace mygrid not found" (or "Environment `Point` doesn't exist"),
    nothing saying that --gym-env takes module:Id."""
    monkeypatch.syspath_prepend(str(TESTS))
    argv = ["benchmark", "--envs", "", "--gym-env", gym_env, "--teacher", "_bench_env:teacher"]
    assert main([*argv, "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--gym-env {gym_env}: " in err
    assert says in err, err
    assert ("name that module first" in err) == (gym_env in ("mygrid/Point-v0", "Point-v0")), err
    assert not (tmp_path / "b").exists()


def test_the_help_says_gym_env_adds_to_the_default_envs(capsys):
    """--gym-env adds an env to --envs, whose default is corridor and driving: a newcomer who
    gave --gym-env alone started the full sweep, the driving domain included, and neither
    --help nor docs/benchmark.md said so (nor that --envs "" leaves the domains out)."""
    with pytest.raises(SystemExit):
        main(["benchmark", "--help"])
    text = " ".join(capsys.readouterr().out.split("options:", 1)[1].split())
    gym_env = text.split("--gym-env MODULE:ID", 1)[1].split("--teacher MODULE:NAME", 1)[0]
    assert "corridor and driving" in gym_env and '--envs ""' in gym_env
    envs = text.split("--envs E,..", 1)[1].split("--seeds N", 1)[0]
    assert "--gym-env" in envs and '""' in envs
    doc = " ".join((ROOT / "docs" / "benchmark.md").read_text().split())
    assert 'without --envs "" it runs beside corridor and driving' in doc.replace("`", "")


def test_strategy_parameters_are_given_on_the_command_line(tmp_path, capsys, monkeypatch):
    """The command gave a strategy no parameters: DAgger with another iteration length, or
    confident execution with another threshold, needed a module of one's own or a Python
    script. --strategy-param S.KEY=VALUE gives them (JSON values, else strings); they are part
    of each cell's key, so a sweep with other values computes its cells again."""
    monkeypatch.syspath_prepend(str(TESTS))
    argv = list(_TOY_SWEEP)
    argv += ["--teacher", "_bench_env:teacher", "--strategies", "bc,dagger,confident"]
    argv += _ONE_TINY_CELL
    argv += ["--workers", "1", "--out", str(tmp_path / "b")]
    given = ["--strategy-param", "dagger.iteration_steps=3"]
    given += ["--strategy-param", "confident.max_std=2.5"]
    assert main([*argv, *given]) == 0
    cells = [json.loads(p.read_text()) for p in (tmp_path / "b" / "cells").glob("*.json")]
    params = {c["config"]["strategy"]["name"]: c["config"]["strategy"]["params"] for c in cells}
    assert params == {"bc": {}, "dagger": {"iteration_steps": 3}, "confident": {"max_std": 2.5}}
    capsys.readouterr()
    given[1] = "dagger.iteration_steps=4"  # another value: that strategy's cell again
    assert main([*argv, *given]) == 0
    out = capsys.readouterr().out
    assert out.count("cached") == 2 and "dagger seed 0: cached" not in out, out
    mistakes = {
        "dagger": "expected S.KEY=VALUE",
        "dagger.=3": "expected S.KEY=VALUE",
        "cba.distance_factor=2": "cba is not among --strategies",
        "dagger.beta=0.3": "unexpected keyword argument 'beta'",
        # Python's spellings and numbers JSON does not read were passed on as strings
        "dagger.iteration_steps=.5": "'.5' is not a JSON value",
        "dagger.iteration_steps=1_0": "'1_0' is not a JSON value",
        "dagger.relabel=False": "'False' is not a JSON value",
    }
    for param, says in mistakes.items():
        assert main([*argv, "--strategy-param", param, "--out", str(tmp_path / "x")]) == 2
        out, err = capsys.readouterr()
        assert err.count("\n") == 1 and f"{says}" in err, (param, err)
        assert out == "", (param, out)  # refused before the sweep's plan is printed
    twice = ["--strategy-param", "dagger.iteration_steps=3"] * 2
    assert main([*argv, *twice, "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "dagger.iteration_steps given twice" in err, err
    assert not (tmp_path / "x").exists()


def test_a_strategy_that_needs_parameters_is_told_how_to_give_them(tmp_path, capsys, monkeypatch):
    """A class of one's own that needs a parameter was refused with "expected module:Class of
    a strategy that takes no arguments", nothing saying how to give it one; it is told
    --strategy-param (or StrategySpec's params in Python), and made when given them."""
    monkeypatch.syspath_prepend(str(TESTS))
    argv = list(_TOY_SWEEP)
    argv += ["--teacher", "_bench_env:teacher", "--strategies", "_bench_env:StrategyWithParams"]
    assert main([*argv, "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "missing 1 required positional argument: 'horizon'" in err
    assert "--strategy-param _bench_env:StrategyWithParams.KEY=VALUE" in err, err
    assert "StrategySpec(" in err and not (tmp_path / "b").exists()
    given = ["--strategy-param", "_bench_env:StrategyWithParams.horizon=5", "--seeds", "1"]
    given += ["--budgets", "5", "--max-steps", "10", "--eval-episodes", "1", "--workers", "1"]
    assert main([*argv, *given, "--out", str(tmp_path / "b")]) == 0  # as told
    capsys.readouterr()
    # a constructor failing for another reason is not told about parameters
    argv[-1] = "_bench_env:StrategyThatFails"
    assert main([*argv, "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "RuntimeError: needs a licence file" in err, err
    assert "--strategy-param" not in err and "StrategySpec" not in err, err


@pytest.mark.timeout(60)
def test_a_ray_address_where_nothing_listens_is_refused_not_waited_on(
    tmp_path, capsys, monkeypatch
):
    """--ray-address host:port with no Ray there (a typo, a cluster not started yet) left the
    command printing Ray's "Failed to connect to GCS" warnings for about a quarter of an hour
    (ray.init's 20 tries of some 40 s each) before any error."""
    pytest.importorskip("ray")
    import socket

    monkeypatch.syspath_prepend(str(TESTS))
    with socket.socket() as s:  # a port nothing listens on (free a moment ago)
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    argv = list(_TOY_SWEEP)
    argv += ["--teacher", "_bench_env:teacher", "--strategies", "bc", "--seeds", "1"]
    argv += ["--budgets", "5", "--max-steps", "10", "--eval-episodes", "1"]
    assert main([*argv, "--workers", "1", "--out", str(tmp_path / "b")]) == 0  # a finished sweep
    capsys.readouterr()
    before = {p.name: p.read_bytes() for p in (tmp_path / "b").iterdir() if p.is_file()}
    assert "results.json" in before
    t0 = time.monotonic()
    argv[argv.index("--seeds") + 1] = "2"  # a cell to compute
    code = main([*argv, "--ray-address", f"127.0.0.1:{port}", "--out", str(tmp_path / "b")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert f"Ray at 127.0.0.1:{port}: nothing answers at " in err and "ray start" in err
    assert time.monotonic() - t0 < 30
    # refused before the sweep's directory is touched: its results and plot are kept
    assert {p.name: p.read_bytes() for p in (tmp_path / "b").iterdir() if p.is_file()} == before


@pytest.mark.timeout(60)
def test_ray_address_auto_with_no_cluster_is_refused_before_the_out_directory(
    tmp_path, capsys, monkeypatch
):
    """--ray-address auto where no Ray cluster runs exited 1 with Ray's ConnectionError (the
    probe skipped "auto") after the output directory had been created; and where a stale
    ray_current_cluster file of a cluster since stopped names an address, Ray retried it for
    about a quarter of an hour."""
    import socket

    ray = pytest.importorskip("ray")
    from ray._private.services import find_gcs_addresses

    if find_gcs_addresses():
        pytest.skip("a Ray cluster runs on this machine")
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setenv("RAY_TMPDIR", str(tmp_path))  # ray start writes into its ray/
    (tmp_path / "ray").mkdir()
    monkeypatch.syspath_prepend(str(TESTS))
    argv = list(_TOY_SWEEP)
    argv += ["--teacher", "_bench_env:teacher", "--strategies", "bc", "--seeds", "1"]
    argv += ["--budgets", "5", "--max-steps", "10", "--eval-episodes", "1"]
    argv += ["--ray-address", "auto", "--out", str(tmp_path / "b")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no running Ray cluster" in err and "ray start" in err, err
    assert not (tmp_path / "b").exists()
    with socket.socket() as s:  # a cluster's address, stopped since
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    (tmp_path / "ray" / "ray_current_cluster").write_text(f"127.0.0.1:{port}\n")
    t0 = time.monotonic()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Ray at auto: nothing answers at " in err, err
    assert time.monotonic() - t0 < 30 and not (tmp_path / "b").exists()
    assert not ray.is_initialized()


def test_a_module_in_the_current_directory_is_said_to_need_pythonpath(
    tmp_path, capsys, monkeypatch
):
    """A teacher (or strategy, or env module) in a file of the current directory, named as
    mine:make, was refused with a bare "No module named 'mine'": the torchcbl console script,
    unlike python -m or a script, does not import from the current directory, and nothing
    said so."""
    (tmp_path / "mine.py").write_text("def make(env):\n    return lambda obs, info: 0\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(TESTS))
    argv = list(_TOY_SWEEP)
    for extra in (["--teacher", "mine:make"], ["--teacher", "_bench_env:teacher"]):
        more = ["--strategies", "mine:Strategy"] if extra[1] != "mine:make" else []
        assert main([*argv, *extra, *more, "--out", str(tmp_path / "b")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "No module named 'mine'" in err, err
        assert "mine.py is in the current directory" in err and "PYTHONPATH=" in err, err
    assert not (tmp_path / "b").exists()
    # a package of the current directory that imports (it is on the path) but lacks a module
    # of its own: no PYTHONPATH hint, the user already gave it
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "teach.py").write_text("import pkg.helpers\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert main([*argv, "--teacher", "pkg.teach:make", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "No module named 'pkg.helpers'" in err, err
    assert "PYTHONPATH" not in err, err


_POOL_CHILD = """
import sys
sys.path[:0] = [{tests!r}, {root!r}]
from torchcbl import benchmark as bm
from test_benchmark import STRATEGIES, _env
if __name__ == "__main__":
    bm.run_benchmark(STRATEGIES, [_env(max_steps=150, budgets=(5, 10, 20, 40))], range(6),
                     {out!r}, workers=2, plots=False)
"""


def _children(pid):
    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            kids.append(int(stat.parent.name))
    return kids


def _running(pid):
    try:  # a zombie has exited (waiting for whoever adopted it to reap it)
        return (
            Path(f"/proc/{pid}/stat").read_text(encoding="utf-8").rsplit(")", 1)[1].split()[0]
            != "Z"
        )
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_a_sweep_killed_outright_leaves_no_worker_processes_behind(tmp_path):
    """A process-pool sweep killed with SIGKILL (kill -9, the OOM killer taking the driver; or
    SIGTERM, SIGHUP, whose default kills Python without its cleanup) left its worker processes
    running for ever, each holding its interpreter, torch and (driving) a SUMO simulation,
    blocked on a queue that nobody would write to again."""
    out = tmp_path / "bench"
    script = tmp_path / "sweep.py"
    script.write_text(_POOL_CHILD.format(tests=str(TESTS), root=str(ROOT), out=str(out)))
    child = subprocess.Popen([sys.executable, str(script)], cwd=tmp_path)
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and child.poll() is None:
            if list((out / "cells").glob("*.json")):  # the workers run cells
                workers = _children(child.pid)
                break
            time.sleep(0.05)
        assert child.poll() is None and workers, "the sweep ended before it could be killed"
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.wait()
    _assert_all_end(workers, "worker processes outlived the killed sweep")


def _assert_all_end(pids: list[int], message: str, within: float = 10.0) -> None:
    """Every process of ``pids`` ends within ``within`` seconds, else ``message``; those still
    running are killed (they are the test's own)."""
    deadline = time.monotonic() + within
    alive = pids
    while alive and time.monotonic() < deadline:
        time.sleep(0.1)
        alive = [p for p in pids if _running(p)]
    try:
        assert not alive, message
    finally:
        for p in alive:
            os.kill(p, signal.SIGKILL)


_FORKSERVER_CHILD = """
import multiprocessing as mp, os, sys, time
sys.path[:0] = [{root!r}]
from torchcbl.evaluation import worker_pool


def task(marker):
    open(f"{{marker}}.{{os.getpid()}}", "w").close()
    time.sleep(600)


if __name__ == "__main__":
    with worker_pool(2, mp.get_context("forkserver")) as pool:
        futures = [pool.submit(task, sys.argv[1]) for _ in range(2)]
        futures[0].result()
"""


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_forkserver_workers_end_while_their_killed_pool_is_not_yet_reaped(tmp_path):
    """Under a forkserver context a worker is no child of the pool's process, so it watches
    that process by its pid; a pool killed outright but not yet reaped by its own parent (a
    zombie) answered that check as alive, and its workers ran on (4 of 4 after 3 s)."""
    script = tmp_path / "pool.py"
    script.write_text(_FORKSERVER_CHILD.format(root=str(ROOT)))
    marker = tmp_path / "started"
    child = subprocess.Popen([sys.executable, str(script), str(marker)], cwd=tmp_path)
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and child.poll() is None and len(workers) < 2:
            workers = [int(p.suffix[1:]) for p in tmp_path.glob("started.*")]
            time.sleep(0.05)
        assert child.poll() is None and len(workers) == 2, "the workers did not start"
        os.kill(child.pid, signal.SIGKILL)  # and not reaped (no wait) until the workers are seen
        _assert_all_end(workers, "worker processes outlived their killed pool")
    finally:
        child.wait()


def test_a_python_spelt_value_is_told_its_json_spelling(tmp_path, capsys, monkeypatch):
    """--strategy-teaching cba.noninteractive=False (Python's spelling, as StrategySpec's
    teaching={"noninteractive": False} is written) was refused with the advice to quote it as
    a string, cba.noninteractive='"False"', which the next run refuses again (a bool is
    wanted); a number JSON does not read (.5, 1_0) was told the same. The advice is the JSON
    spelling of the value meant."""
    monkeypatch.syspath_prepend(str(TESTS))
    argv = list(_TOY_SWEEP)
    argv += ["--teacher", "_bench_env:teacher", "--strategies", "cba,dagger"]
    argv += ["--out", str(tmp_path / "b")]
    for option, given, advice in (
        ("--strategy-teaching", "cba.noninteractive=False", "(cba.noninteractive=false)"),
        ("--strategy-param", "dagger.relabel=True", "(dagger.relabel=true)"),
        ("--strategy-param", "dagger.seed=None", "(dagger.seed=null)"),
        ("--strategy-param", "dagger.decay=.5", "(dagger.decay=0.5)"),
        ("--strategy-param", "dagger.iteration_steps=1_0", "(dagger.iteration_steps=10)"),
    ):
        assert main([*argv, option, given]) == 2, given
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and advice in err, err
    assert not (tmp_path / "b").exists()


def test_a_misspelt_teaching_field_is_told_the_fields_there_are(tmp_path, capsys, monkeypatch):
    """--strategy-teaching cba.noninteractiv=false (or StrategySpec / EnvSpec teaching with a
    misspelt key) was refused with Python's "TeachingConfig.__init__() got an unexpected
    keyword argument 'noninteractiv'", which names no field it takes; the error names the
    unknown key and the learning fields a cell takes."""
    fields = "['accuracy_window', 'burst', 'max_new', 'noninteractive', 'refit', "
    for make in (
        lambda: bm.StrategySpec("cba", teaching={"noninteractiv": False}),
        lambda: _env(teaching={"noninteractiv": False}),
    ):
        with pytest.raises(ValueError) as info:
            make()
        assert "unknown field 'noninteractiv'" in str(info.value), info.value
        assert fields in str(info.value) and "__init__" not in str(info.value), info.value
    monkeypatch.syspath_prepend(str(TESTS))
    argv = list(_TOY_SWEEP)
    argv += ["--teacher", "_bench_env:teacher", "--strategies", "cba"]
    argv += ["--strategy-teaching", "cba.noninteractiv=false", "--out", str(tmp_path / "b")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown field 'noninteractiv'" in err and fields in err, err


def test_two_settings_of_one_strategy_without_labels_are_told_to_label_them(tmp_path):
    """Two StrategySpecs of one strategy with other teaching settings (CBA with and without the
    non-interactive phase, as docs/benchmark.md suggests) and no label: refused with "strategy
    labels must be distinct, got ['cba', 'cba']", not saying what to do; it says to give
    each a label= of its own (as the env names' error does)."""
    plain, published = bm.StrategySpec("cba"), bm.StrategySpec("cba", teaching={"burst": 2})
    with pytest.raises(ValueError, match=r"\['cba', 'cba'\]; give each StrategySpec its own "):
        bm.run_benchmark([plain, published], [_env()], [0], tmp_path / "out")
    assert not (tmp_path / "out").exists()


@pytest.mark.timeout(60)
def test_an_evaluation_whose_episodes_never_end_is_stopped_and_said_not_run_forever(
    tmp_path, capsys, monkeypatch
):
    """An env registered without max_episode_steps whose episodes do not end (the teacher
    never finishes its task), benchmarked without --eval-steps: the greedy evaluation had no
    step cap and ran forever after the plan line. Without eval_steps and with no cap of the
    env's own, an evaluation now gets at most 10,000 steps per episode (max_steps where more)
    in all; one whose episodes do not all end there stops the cell with one line saying what
    to give."""
    monkeypatch.syspath_prepend(str(TESTS))
    argv = ["benchmark", "--envs", "", "--gym-env", "_bench_env:BenchEndless-v0", "--teacher"]
    argv += ["_bench_env:teacher", "--strategies", "bc", "--seeds", "1", "--workers", "1"]
    argv += ["--budgets", "5", "--max-steps", "10", "--eval-episodes", "2"]
    assert main([*argv, "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "the teacher on evaluation seed 1000000 ran 20000 steps in all" in err, err
    assert "0 of its 2 episodes ended" in err and "--eval-steps" in err, err
    assert "max_episode_steps" in err, err
    # the same through the API: the cell fails, naming the fix
    spec = _env(env_id="_bench_env:BenchEndless-v0", budgets=(5,), max_steps=10)
    with pytest.raises(bm.CellError, match="give eval_steps"):
        bm.run_benchmark(STRATEGIES[:1], [spec], [0], tmp_path / "api", workers=1, plots=False)
    # eval_steps bounds it, and so does a TimeLimit longer than max_steps
    capped = dataclasses.replace(spec, eval_steps=12)
    assert "ran 20000 steps" in err and "10000 steps per episode" in err, err
    timed = dataclasses.replace(spec, env_kwargs={"spread": 2.0, "max_episode_steps": 15})
    for s in (capped, timed):
        out = bm.run_benchmark(STRATEGIES[:1], [s], [0], tmp_path / "ok", workers=1, plots=False)
        assert out["table"]["toy"]["bc"]["final_labels"]["mean"] == 5


def test_an_evaluation_of_one_episode_that_never_ends_is_an_error_not_a_score_of_zero(
    monkeypatch,
):
    """eval_episodes=1 on an env with no step cap (no TimeLimit, no eval_steps) whose episode
    never ends: the guard's 10,000 steps pass with 0 of 1 episodes ended, and run_cell stops
    with the guard's error (success_rate would score such an evaluation 0, a figure that
    reads as a failing teacher, not an unbounded one)."""
    monkeypatch.syspath_prepend(str(TESTS))
    spec = _env(
        env_id="_bench_env:BenchEndless-v0",
        budgets=(5,),
        max_steps=10,
        eval_seeds=(7,),
        eval_episodes=1,
    )
    assert spec.eval_steps is None
    (config,) = bm.cell_configs(STRATEGIES[:1], [spec], [0])
    with pytest.raises(ValueError, match="has no step cap") as info:
        bm.run_cell(config)
    message = str(info.value)
    assert "the teacher on evaluation seed 7 ran 10000 steps in all" in message, message
    assert "0 of its 1 episodes ended" in message and "give eval_steps" in message, message


def test_a_teacher_whose_evaluation_ends_no_episode_is_told_so_not_that_the_env_lacks_success(
    tmp_path, capsys, monkeypatch
):
    """With --eval-steps shorter than an episode, no evaluation episode ends, success_rate
    scores 0 for every evaluation, and the warning blamed the env for not setting
    info["is_success"], which it does where an episode ends. A cell counts the teacher's
    finished evaluation episodes, and the warning says none ended within --eval-steps."""
    monkeypatch.syspath_prepend(str(TESTS))
    argv = ["benchmark", "--envs", "", "--gym-env", "_bench_env:BenchEndless-v0", "--teacher"]
    argv += ["_bench_env:teacher", "--strategies", "bc", "--seeds", "1", "--workers", "1"]
    argv += ["--budgets", "5", "--max-steps", "10", "--eval-steps", "12"]
    assert main([*argv, "--out", str(tmp_path / "b")]) == 0
    err = capsys.readouterr().err
    assert "warning: the teacher scores 0 on _bench_env:BenchEndless-v0" in err, err
    assert "no evaluation episode of the teacher ended within its 12 steps" in err, err
    assert "--eval-steps" in err and 'needs an env that sets info["is_success"]' not in err, err
    (cell,) = [json.loads(p.read_text()) for p in (tmp_path / "b" / "cells").glob("*.json")]
    assert cell["teacher_episodes_ended"] == 0
    # where the teacher's episodes end, the count says so and the cause is the score's
    (config,) = bm.cell_configs(STRATEGIES[:1], [_env(budgets=(5,), max_steps=10)], [0])
    assert bm.run_cell(config)["teacher_episodes_ended"] == 2 * 3  # eval seeds x episodes


def test_a_sweep_whose_output_reader_left_finishes_and_writes_its_results(tmp_path, monkeypatch):
    """`torchcbl benchmark ... | head -2`: the sweep removes the results an earlier one left
    (so that one stopped early leaves none that read as its own), and its next line into the
    closed pipe ended the command (exit 141) with no results at all. A closed standard output
    now stops the printing only: the sweep finishes and writes its results and plot."""
    monkeypatch.syspath_prepend(str(TESTS))
    argv = [*_TOY_SWEEP, "--strategies", "bc", "--workers", "1", *_ONE_TINY_CELL]
    out = tmp_path / "b"
    assert main([*argv, "--teacher", "_bench_env:teacher", "--out", str(out)]) == 0
    assert (out / "results.json").is_file() and (out / "learning_curves.png").is_file()
    # a new sweep into it, whose reader leaves after the plan line (its teacher waits for that)
    proc = subprocess.Popen(
        [sys.executable, "-m", "torchcbl", *argv, "--out", str(out)]
        + ["--teacher", "_bench_env:teacher_once_stdout_has_no_reader"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        env={**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS), str(ROOT)])},
    )
    assert proc.stdout.readline().startswith(b"benchmark: 1 strategies")
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 0, err
    assert err == "", err
    results = json.loads((out / "results.json").read_text())
    assert results["envs"]["_bench_env:BenchCluster-v0"]["teacher"].endswith("no_reader")
    assert (out / "learning_curves.png").is_file()


def test_an_env_that_bounds_its_own_episodes_is_evaluated_whatever_max_steps():
    """The corridor ends its own episodes (its max_episode_steps, 81 on its map) without a
    TimeLimit; a cell of it taught for fewer steps than one episode (max_steps 20) and
    evaluated without eval_steps was stopped by the never-ending-evaluation guard (total cap
    eval_episodes x max_steps), the perfect teacher's own evaluation included. The guard
    applies only where the env has no step cap at all."""
    import corridor.benchmark

    spec = dataclasses.replace(
        corridor.benchmark.env_spec(True), budgets=(10,), max_steps=20, eval_seeds=(1000,)
    )
    assert spec.eval_steps is None
    (config,) = bm.cell_configs(STRATEGIES[:1], [spec], [0])
    cell = bm.run_cell(config)
    assert cell["teacher_performance"] == 1.0
    assert cell["teacher_episodes_ended"] == spec.eval_episodes


def _curve_cells():
    return [
        {
            "env": "e",
            "strategy": "cbl",
            "teacher_performance": 1.0,
            "curve": [{"labels": n, "performance": p + 0.1 * s} for n, p in ((5, 0.2), (10, 0.8))],
        }
        for s in range(2)
    ]


def _half_then_fail(monkeypatch):
    """Make Figure.savefig write half its file to whatever it is given, then fail (a sweep
    killed, a disk filled, mid-write)."""
    import io

    from matplotlib.figure import Figure

    savefig = Figure.savefig

    def half(fig, fname, *args, **kwargs):
        buf = io.BytesIO()
        savefig(fig, buf, *args, **{"format": "png", **kwargs})
        data = buf.getvalue()[: len(buf.getvalue()) // 2]
        if hasattr(fname, "write"):
            fname.write(data)
        else:
            Path(fname).write_bytes(data)
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Figure, "savefig", half)


def test_plot_curves_failing_mid_write_leaves_no_partial_png(tmp_path, monkeypatch):
    """plot_curves wrote learning_curves.png straight under its name: a sweep killed (or a
    disk filled) while matplotlib wrote it left a truncated PNG there, while results.json
    is written whole or not at all. The plot is put in place whole now (a temporary file in
    the same folder renamed over it): a write that fails leaves the earlier file as it was,
    and no temporary file."""
    png = tmp_path / "learning_curves.png"
    first = bm.plot_curves(_curve_cells(), png, envs=["e"]).read_bytes()
    assert first.startswith(b"\x89PNG") and first.rstrip(b"\x00").endswith(b"IEND\xaeB`\x82")
    _half_then_fail(monkeypatch)
    with pytest.raises(OSError, match="No space"):
        bm.plot_curves(_curve_cells(), png, envs=["e"])
    assert png.read_bytes() == first  # the earlier plot, whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["learning_curves.png"]


def test_save_whole_writes_what_savefig_writes_and_nothing_when_it_fails(tmp_path, monkeypatch):
    """The helper every PNG writer goes through (the benchmark's plot, the reproduction's
    figures): the same bytes as savefig writing to the path itself, and, where savefig fails
    mid-way, no file under the name nor a temporary one beside it."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from torchcbl.evaluation import save_whole

    fig = Figure(figsize=(3, 2))
    FigureCanvasAgg(fig)
    fig.subplots().plot([0, 1, 3], [2, 0, 1])
    fig.savefig(tmp_path / "direct.png", dpi=77, bbox_inches="tight")
    assert save_whole(tmp_path / "whole.png", fig.savefig, dpi=77, bbox_inches="tight") == (
        tmp_path / "whole.png"
    )
    assert (tmp_path / "whole.png").read_bytes() == (tmp_path / "direct.png").read_bytes()
    # an upper-case extension names the same format, as matplotlib reads it (imsave wrote
    # "PNG" without its metadata chunk)
    from matplotlib.image import imsave

    rgb = np.zeros((4, 5, 3), dtype=np.uint8)
    imsave(tmp_path / "DIRECT.PNG", rgb)
    save_whole(tmp_path / "WHOLE.PNG", lambda fname, **kw: imsave(fname, rgb, **kw))
    assert (tmp_path / "WHOLE.PNG").read_bytes() == (tmp_path / "DIRECT.PNG").read_bytes()
    for name in ("DIRECT.PNG", "WHOLE.PNG"):
        (tmp_path / name).unlink()
    _half_then_fail(monkeypatch)
    with pytest.raises(OSError, match="No space"):
        save_whole(tmp_path / "failed.png", fig.savefig, dpi=77)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["direct.png", "whole.png"]


def test_the_goal_is_success_registration_of_the_docs_makes_success_rate_count_goals(
    tmp_path, monkeypatch
):
    """success_rate scores 0 on an env that never sets info["is_success"] (MountainCar: its
    episodes end, terminated, at the goal). docs/benchmark.md registers MountainCar wrapped in
    the README's GoalIsSuccess under an id of one's own: its command, run on that module
    (fewer labels and evaluation episodes, for time), scores the teacher's goals."""
    import shlex

    import gymnasium as gym

    doc = (ROOT / "docs" / "benchmark.md").read_text()
    (module,) = [b for b in re.findall(r"```python\n(.*?)```", doc, re.S) if "GoalIsSuccess" in b]
    (command,) = [b for b in re.findall(r"```bash\n(.*?)```", doc, re.S) if "goalenvs" in b]
    (tmp_path / "goalenvs.py").write_text(module)
    monkeypatch.syspath_prepend(str(tmp_path))
    argv = shlex.split(command.replace("\\\n", " "))
    assert argv[:3] == ["python", "-m", "torchcbl"]
    fast = {"--budgets": "5,10", "--eval-episodes": "1", "--out": str(tmp_path / "out")}
    argv = argv[3:]
    for option, value in fast.items():
        argv[argv.index(option) + 1] = value
    try:
        assert main([*argv, "--workers", "1"]) == 0
    finally:
        gym.registry.pop("goalenvs/MountainCar-v0", None)
        sys.modules.pop("goalenvs", None)
    results = json.loads((tmp_path / "out" / "results.json").read_text())
    (cell,) = results["table"].values()
    assert cell["bc"]["teacher_performance"]["mean"] == 1.0  # 0.0 without the wrapper


def test_ctrl_c_says_the_finished_cells_are_kept_and_how_to_go_on(tmp_path, monkeypatch, capsys):
    """Ctrl-C during a sweep printed "torchcbl benchmark: interrupted" alone, though the cells
    finished before it are kept and the same command goes on from them (reproduce's line says
    how it goes on). The line says how many are kept and what to run; the rerun computes only
    the rest."""
    monkeypatch.syspath_prepend(str(TESTS))
    argv = ["benchmark", "--envs", "", "--gym-env", "_bench_env:BenchCluster-v0"]
    argv += ["--teacher", "_bench_env:teacher_ctrl_c_on_seed_1", "--strategies", "bc"]
    argv += ["--seeds", "2", "--workers", "1", "--budgets", "5", "--max-steps", "10"]
    out = tmp_path / "b"
    assert main([*argv, "--eval-episodes", "1", "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert err == (
        f"torchcbl benchmark: interrupted (1 finished cell kept in {out / 'cells'}: go on with "
        "the same command)\n"
    )
    assert len(list((out / "cells").glob("*.json"))) == 1


def test_the_learning_curves_say_what_their_line_band_and_axis_are(tmp_path, monkeypatch):
    """learning_curves.png showed a line and a band per strategy, titled with the env's name
    alone and its y axis "performance": nothing on the figure said the line is a mean over
    seeds, over how many, that the band is +-1 sd, nor which score "performance" is (the
    driving panel's contact-free share, the corridor's success rate). A reader of the PNG
    alone (the README's embeds it) could not tell. Each panel now says the seeds and the band,
    and its y axis names the score."""
    from matplotlib.figure import Figure

    drawn = []
    savefig = Figure.savefig

    def keep(fig, *args, **kwargs):
        drawn.append(fig)
        return savefig(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    bm.run_benchmark(STRATEGIES[:2], [_env()], [0, 1, 2], tmp_path / "o", workers=1)
    (ax,) = drawn[0].axes
    assert ax.get_title() == "toy: mean over 3 seeds, band ±1 sd"
    assert ax.get_ylabel() == "success_rate (greedy, held-out eval seeds)"
    assert ax.get_xlabel() == "teacher labels"


def test_the_command_says_what_its_table_figures_are(tmp_path, capsys, monkeypatch):
    """The command printed its table of "30 ± 0" figures with no word of what they are: a mean
    over the seeds, the spread a sample sd, over how many seeds, what "≥" and "(k/n)" mean, and
    that a rate is a mean over the seeds that have one (the README says so in prose above its
    copy; a reviewer of a fresh run had only the numbers). A line under the table says it."""
    monkeypatch.syspath_prepend(str(TESTS))
    argv = [*_TOY_SWEEP, "--teacher", "_bench_env:teacher", "--strategies", "bc,dagger"]
    argv += ["--seeds", "2", "--workers", "1", "--budgets", "5", "--max-steps", "10"]
    assert main([*argv, "--eval-episodes", "1", "--out", str(tmp_path / "b")]) == 0
    out = capsys.readouterr().out
    table_end = out.index("\n\n", out.index("| env | strategy |"))
    note = out[table_end:].strip().splitlines()[0]
    assert note.startswith("Each figure: mean ± sd over the 2 seeds of its row (sample sd, n − 1;")
    assert "≥: a lower bound" in note and "(rate), auditor ≠ teacher:" in note


def test_performance_at_a_budget_says_how_many_seeds_reached_it(tmp_path):
    """results.json's performance_at_budget["20"] of an HG-DAgger that stopped asking at 15
    and 19 labels read {"mean": 0.58, "n": 2}: "at 20 labels, 2 seeds", though neither seed
    held 20 labels (the figure is each seed's last model below the budget). Each entry now
    counts the seeds that reached the budget, n_reached; the figures are as they were."""
    strategies = [bm.StrategySpec("hg_dagger", {"warmup": 3}), bm.StrategySpec("bc")]
    r = bm.run_benchmark(strategies, [_env()], [0, 1], tmp_path, workers=1, plots=False)
    hg, bc = r["table"]["toy"]["hg_dagger"], r["table"]["toy"]["bc"]
    assert hg["final_labels"]["mean"] < 20 and bc["final_labels"]["mean"] == 20
    assert [hg["performance_at_budget"][b]["n_reached"] for b in ("5", "10", "20")] == [2, 2, 0]
    assert [bc["performance_at_budget"][b]["n_reached"] for b in ("5", "10", "20")] == [2, 2, 2]
    assert hg["performance_at_budget"]["20"]["n"] == 2  # the figure itself: as before


def _perf_at_by_hand(cell, budget):
    """A cell's figure at ``budget``: its last curve point at or below it (None: none)."""
    below = [p["performance"] for p in cell["curve"] if p["labels"] <= budget]
    return below[-1] if below else None


def test_every_strategy_is_compared_with_confident_execution_seed_by_seed(tmp_path):
    """Every strategy runs on the same seeds, yet results.json gave only mean ± sd per
    strategy, so two strategies' rows could not be told apart where their spreads overlap even
    when one was ahead on every seed. results.json's ``paired`` now holds, against the paper's
    method (the strategy named "confident", whatever its label), each strategy's per-seed
    difference at each budget: mean, sd, n and a 95 % t interval."""
    cells = []
    strategies = [
        bm.StrategySpec("bc"),
        bm.StrategySpec("hg_dagger", {"warmup": 3}),
        bm.StrategySpec("confident", label="CE"),
    ]
    r = bm.run_benchmark(
        strategies,
        [_env(env_kwargs={"spread": 1.0})],
        [0, 1, 2],
        tmp_path,
        workers=1,
        plots=False,
        on_cell=lambda cell, cached: cells.append(cell),
    )
    paired = r["paired"]
    assert paired["reference"] == "CE"
    assert set(paired["table"]["toy"]) == {"bc", "hg_dagger"}
    by = {(c["strategy"], c["seed"]): c for c in cells}
    moved = False
    for strat in ("bc", "hg_dagger"):
        for b in (5, 10, 20):
            d = [
                _perf_at_by_hand(by[strat, s], b) - _perf_at_by_hand(by["CE", s], b)
                for s in (0, 1, 2)
            ]
            half = 4.303 * np.std(d, ddof=1) / np.sqrt(3)  # t(0.975, 2 df)
            e = paired["table"]["toy"][strat][str(b)]
            assert e["n"] == 3 and e["mean"] == pytest.approx(np.mean(d))
            assert e["sd"] == pytest.approx(np.std(d, ddof=1))
            assert e["ci95"] == pytest.approx([np.mean(d) - half, np.mean(d) + half], abs=1e-3)
            moved |= any(x != 0 for x in d)
    assert moved  # HG-DAgger's curve is not confident execution's: the check can fail
    assert json.loads((tmp_path / "results.json").read_text())["paired"] == paired


def test_a_paired_difference_of_one_seed_has_no_interval_and_one_seed_short_is_left_out():
    """n < 2: no sd and no interval (None, never NaN); a seed where either strategy has no
    figure at a budget is not counted there; a sweep without confident execution has no
    reference and no pairs."""

    def cell(strategy, seed, curve, name=None):
        return {
            "env": "e",
            "strategy": strategy,
            "seed": seed,
            "teacher_performance": 1.0,
            "curve": [{"labels": n, "performance": p} for n, p in curve],
            "config": {"env": {"budgets": [5, 10]}, "strategy": {"name": name or strategy}},
            "attention": {},
            "wall_s": 1.0,
            "cpu_s": 1.0,
        }

    cells = [
        cell("confident", 0, [(5, 0.5), (10, 0.75)]),
        cell("confident", 1, [(10, 0.5)]),  # no model of 5 labels or fewer
        cell("bc", 0, [(5, 0.25), (10, 1.0)]),
        cell("bc", 1, [(5, 0.5), (10, 1.0)]),
    ]
    paired = bm.summarize(cells, envs=["e"], strategies=["bc", "confident"])["paired"]
    assert paired["reference"] == "confident"
    assert paired["table"]["e"]["bc"]["5"] == {"mean": -0.25, "sd": None, "n": 1, "ci95": None}
    ten = paired["table"]["e"]["bc"]["10"]
    assert ten["n"] == 2 and ten["mean"] == pytest.approx(0.375) and ten["ci95"] is not None
    table = bm.format_paired(bm.summarize(cells, envs=["e"], strategies=["bc", "confident"]))
    assert "| e | bc | 5 | -0.25 (n = 1) | 1 | none (n < 2) |" in table
    assert "nan" not in table.lower()
    alone = bm.summarize(cells[2:], envs=["e"], strategies=["bc"])
    assert alone["paired"] == {"reference": None, "table": {}}
    assert "no strategy named confident" in bm.format_paired(alone)


def test_the_command_prints_the_paired_comparison_with_confident(tmp_path, capsys, monkeypatch):
    """The command's output had only the per-strategy table (and said "no difference between
    rows computed"); it now prints each strategy's per-seed difference from confident
    execution at each budget, with its 95 % interval, under the table."""
    monkeypatch.syspath_prepend(str(TESTS))
    argv = [*_TOY_SWEEP, "--teacher", "_bench_env:teacher", "--strategies", "bc,confident"]
    argv += ["--seeds", "2", "--workers", "1", "--budgets", "5,10", "--max-steps", "10"]
    assert main([*argv, "--eval-episodes", "1", "--out", str(tmp_path / "b")]) == 0
    out = capsys.readouterr().out
    r = json.loads((tmp_path / "b" / "results.json").read_text())
    env = "_bench_env:BenchCluster-v0"
    assert "no difference between rows computed" not in out
    head = "| env | strategy − confident | labels | difference (mean ± sd) | n | 95 % interval |"
    assert head in out
    for b in ("5", "10"):
        e = r["paired"]["table"][env]["bc"][b]
        lo, hi = e["ci95"]
        diff = f"{e['mean']:+.2f} ± {e['sd']:.2f}"
        row = f"| {env} | bc | {b} | {diff} | 2 | [{lo:+.2f}, {hi:+.2f}] |"
        assert row in out, out


def test_the_tables_budget_column_names_the_budget_it_shows(tmp_path, capsys, monkeypatch):
    """`--budgets 10` printed its one budget's figure under "perf. at 2nd budget": there is no
    2nd budget. The header now says which budget the column shows: the 2nd where every row has
    two or more, the only one where every row has one, and says both where the rows differ."""
    monkeypatch.syspath_prepend(str(TESTS))
    argv = [*_TOY_SWEEP, "--teacher", "_bench_env:teacher", "--strategies", "bc", "--workers", "1"]
    assert main([*argv, *_ONE_TINY_CELL, "--out", str(tmp_path / "one")]) == 0
    lines = capsys.readouterr().out.splitlines()
    header = next(x for x in lines if x.startswith("| env |"))
    assert "| perf. at its only budget |" in header and "2nd" not in header, header
    row = lines[lines.index(header) + 2]
    assert " @ 5 |" in row, row  # and each row says which budget that is

    def header_of(envs):
        r = bm.run_benchmark(STRATEGIES[:1], envs, [0], tmp_path / "api", workers=1, plots=False)
        return bm.format_table(r).splitlines()[0]

    assert "| perf. at 2nd budget |" in header_of([_env()])
    mixed = header_of([_env(), _env(name="toy1", budgets=(5,))])
    assert "| perf. at 2nd budget (or the only one) |" in mixed, mixed


def test_a_count_below_ten_keeps_its_fraction_in_the_table():
    """The table printed counts with no decimals, and Python rounds half to even: a mean of
    0.5 wrong actions (one seed 0, the other 1) read "0 ± 1", as if none. A count's mean that
    is not whole and below 10 is now printed to two significant digits, its sd to as many
    decimals; whole means and means of 10 or more are printed as before."""

    def cell(seed, wrong, switches, labels):
        return {
            "env": "e",
            "strategy": "s",
            "seed": seed,
            "teacher_performance": 1.0,
            "curve": [{"labels": labels, "performance": 1.0}],
            "config": {"env": {"budgets": [5, 10]}, "strategy": {"name": "s"}},
            "attention": {
                "requests": labels,
                "monitored_steps": 40,
                "context_switches": switches,
                "wrong_autonomous_actions": wrong,
            },
            "wall_s": 1.0,
            "cpu_s": 1.0,
        }

    cells = [cell(0, 0, 44, 10), cell(1, 1, 45, 11)]
    row = bm.format_table(bm.summarize(cells, envs=["e"], strategies=["s"])).splitlines()[-1]
    # requests 10.5 (>= 10: whole, half to even), monitored 40 (whole), switches 44.5
    assert "| 10 ± 1 | 40 ± 0 | 44 ± 1 | 0.50 ± 0.71 (-) |" in row, row
    few = [cell(0, 0, 4, 10), cell(1, 0, 3, 10), cell(2, 0, 3, 10)]
    row = bm.format_table(bm.summarize(few, envs=["e"], strategies=["s"])).splitlines()[-1]
    assert "| 3.3 ± 0.6 | 0 ± 0 (-) |" in row, row  # 10/3 switches: not "3 ± 1"


def test_the_tables_budget_cell_says_when_seeds_stopped_below_that_budget():
    """The README's table read "1.00 ± 0.00 @ 20" for a corridor HG-DAgger whose seeds all
    stopped asking at 18 labels: each seed's model of at most 20 labels, though none held 20.
    results.json's n_reached counted them; the table cell now says so, "(0/3 reached)", where
    some seed stopped below the budget, and nothing where every seed reached it."""

    def cell(seed, labels):
        return {
            "env": "e",
            "strategy": "s",
            "seed": seed,
            "teacher_performance": 1.0,
            "curve": [
                {"labels": 5, "performance": 0.0},
                {"labels": labels, "performance": 1.0},
            ],
            "config": {"env": {"budgets": [5, 20]}, "strategy": {"name": "s"}},
            "attention": {
                "requests": labels,
                "monitored_steps": 40,
                "context_switches": 1,
                "wrong_autonomous_actions": 0,
            },
            "wall_s": 1.0,
            "cpu_s": 1.0,
        }

    def row(labels):
        cells = [cell(s, n) for s, n in enumerate(labels)]
        return bm.format_table(bm.summarize(cells, envs=["e"], strategies=["s"])).splitlines()[-1]

    assert "| 1.00 ± 0.00 @ 20 (0/3 reached) |" in row([18, 18, 18])
    assert "| 1.00 ± 0.00 @ 20 (1/3 reached) |" in row([18, 20, 19])
    assert "| 1.00 ± 0.00 @ 20 |" in row([20, 20, 20])
