"""A strategy torchcbl does not ship, written from the docs as a user would (the seam's
regression test): taught through ConfidentTeacher, resumed after a close and after a SIGKILL,
and benchmarked by its import path (``test_user_strategy:SafeAsk``; the tests put tests/ on
sys.path)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from _toy_envs import oracle, rare_regions_world

from torchcbl import ConfidentTeacher, TeachingConfig
from torchcbl import benchmark as bm
from torchcbl.cli import main
from torchcbl.errors import IncompatibleRunDirError
from torchcbl.session import load_config, load_records
from torchcbl.strategies import (
    STRATEGIES,
    ConfidenceBasedAutonomy,
    ConfidentExecution,
    Decision,
    correcting,
)

TESTS = Path(__file__).resolve().parent


class SafeAsk:
    """SafeDAgger-style (Zhang & Cho 2017), a simple stand-in: ask where a learned estimate of
    "the learner would deviate from the teacher here" exceeds ``threshold``. The estimate is
    the share of deviations (the model's prediction differed from the label) among the ``k``
    labels nearest to the observation; until ``k`` labels are in, it asks."""

    relabel = False
    wants_corrections = False

    def __init__(self, threshold: float = 0.3, k: int = 5) -> None:
        self.threshold, self.k = float(threshold), int(k)

    def bind(self, *, n_actions, n_features, config):
        self.seen = np.zeros((0, n_features))  # labelled observations [L, D]
        self.deviated = np.zeros(0, dtype=bool)  # [L]: the model's prediction was not the label

    def episode_start(self):
        pass

    def risk(self, observation: np.ndarray) -> float:
        if len(self.deviated) < self.k:
            return 1.0
        d2 = ((self.seen - observation) ** 2).sum(1)
        return float(self.deviated[np.argsort(d2, kind="stable")[: self.k]].mean())

    def decide(self, observation, c):
        ask = int(c.action[0]) < 0 or self.risk(observation) > self.threshold
        return Decision(ask, "confident")

    def actor(self, decision, model_action, teacher_action):
        return "teacher" if decision.ask else "agent"

    def observe_label(self, observation, action, *, model_action, kind):
        self.seen = np.vstack([self.seen, np.asarray(observation, dtype=np.float64)[None]])
        self.deviated = np.append(self.deviated, model_action != action)

    def observe_refit(self, model, observations, actions):
        pass

    def observe_step(self, record, decision):
        pass

    def to_config(self):
        return {"type": "SafeAsk", "threshold": self.threshold, "k": self.k, "relabel": False}


def _teach(run_dir, strategy, steps, on_step=None):
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        env,
        oracle(env),
        strategy=strategy,
        config=TeachingConfig(max_new=4),
        run_dir=run_dir,
        progress=False,
        on_step=on_step,
    )
    ct.run(max_steps=steps)
    ct.close()
    return ct


def _resume(run_dir, **kw):
    env = rare_regions_world(episode_length=10)
    return ConfidentTeacher.resume(run_dir, env, oracle(env), progress=False, **kw)


def _state_from_log(run_dir):
    """What SafeAsk knows, read back from the session's step log."""
    labelled = [r for r in load_records(run_dir) if r.teacher_action is not None]
    seen = np.array([r.observation for r in labelled], dtype=np.float64)
    return seen, np.array([r.model_action != r.teacher_action for r in labelled])


def test_a_strategy_of_ones_own_teaches_and_resumes_from_a_closed_session(tmp_path, monkeypatch):
    live = SafeAsk(threshold=0.2)
    ct = _teach(tmp_path / "r", live, 60)
    recs = load_records(tmp_path / "r")
    assert 0 < ct.n_demonstrations < 60  # it asks where it is unsure, not everywhere
    assert {r.actor for r in recs} == {"teacher", "agent"}
    assert load_config(tmp_path / "r")["strategy"] == live.to_config()
    # a fresh process knows no SafeAsk: it is passed again, or registered as documented
    with pytest.raises(IncompatibleRunDirError, match="Pass strategy=") as caught:
        _resume(tmp_path / "r")
    # (it said only that; registering, which the module docstring tells, was not named)
    assert "torchcbl.strategies.STRATEGIES['SafeAsk'] = " in str(caught.value)
    monkeypatch.setitem(STRATEGIES, "SafeAsk", SafeAsk)
    back = _resume(tmp_path / "r")
    assert isinstance(back.strategy, SafeAsk) and back.strategy.threshold == 0.2
    # the log replayed into it: it knows what the live one knew
    np.testing.assert_array_equal(back.strategy.seen, live.seen)
    np.testing.assert_array_equal(back.strategy.deviated, live.deviated)
    back.run(max_steps=80)
    back.close()
    assert len(load_records(tmp_path / "r")) == 80
    with pytest.raises(IncompatibleRunDirError, match="strategy: stored"):
        _resume(tmp_path / "r", strategy=SafeAsk(threshold=0.5))


_KILLED_AT = 33
_CHILD = f"""
import os, signal, sys
sys.path.insert(0, {str(TESTS)!r})
from test_user_strategy import SafeAsk, _teach

def on_step(record):
    if record.step == {_KILLED_AT}:
        os.kill(os.getpid(), signal.SIGKILL)

_teach(sys.argv[1], SafeAsk(threshold=0.2), 100, on_step)
"""


def test_a_strategy_of_ones_own_resumes_from_a_killed_session(tmp_path):
    # the child also sees what this process was given on PYTHONPATH (where its packages live)
    _inherited = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    child = subprocess.run(
        [sys.executable, "-c", _CHILD, str(tmp_path / "r")],
        env={
            **os.environ,
            "PYTHONPATH": os.pathsep.join([str(TESTS.parent), str(TESTS), *_inherited]),
        },
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert child.returncode == -signal.SIGKILL, child.stderr
    back = _resume(tmp_path / "r", strategy=SafeAsk(threshold=0.2))
    assert back.n_steps == _KILLED_AT + 1
    seen, deviated = _state_from_log(tmp_path / "r")
    assert len(deviated) == back.n_demonstrations > 0
    np.testing.assert_array_equal(back.strategy.seen, seen)
    np.testing.assert_array_equal(back.strategy.deviated, deviated)
    back.run(max_steps=50)
    back.close()
    assert len(load_records(tmp_path / "r")) == 50


_TOY_SWEEP = ["benchmark", "--envs", "", "--gym-env", "_bench_env:BenchCluster-v0"]
_TOY_SWEEP += ["--teacher", "_bench_env:teacher", "--seeds", "1", "--budgets", "5"]
_TOY_SWEEP += ["--max-steps", "20", "--eval-episodes", "1", "--workers", "1"]


def test_a_strategy_of_ones_own_runs_in_the_benchmark_by_its_import_path(tmp_path, capsys):
    argv = [*_TOY_SWEEP, "--strategies", "test_user_strategy:SafeAsk"]
    argv += ["--strategy-param", "test_user_strategy:SafeAsk.threshold=0.2"]
    assert main([*argv, "--out", str(tmp_path / "b")]) == 0, capsys.readouterr().err
    results = json.loads((tmp_path / "b" / "results.json").read_text())
    spec = results["strategies"]["test_user_strategy:SafeAsk"]
    assert spec["params"] == {"threshold": 0.2}
    row = results["table"]["_bench_env:BenchCluster-v0"]["test_user_strategy:SafeAsk"]
    assert row["final_labels"]["mean"] == 5


class AskWhileUnsure:
    """The smallest strategy of one's own: no ``to_config`` (the docs: stored as custom, passed
    again to resume), ask until a model exists or where its distance is above 2 std."""

    relabel = False
    wants_corrections = False

    def bind(self, *, n_actions, n_features, config):
        pass

    def episode_start(self):
        pass

    def decide(self, observation, c):
        return Decision(int(c.action[0]) < 0 or float(c.distance[0]) > 2.0, "confident")

    def actor(self, decision, model_action, teacher_action):
        return "teacher" if decision.ask else "agent"

    def observe_label(self, observation, action, *, model_action, kind):
        pass

    def observe_refit(self, model, observations, actions):
        pass

    def observe_step(self, record, decision):
        pass


class WithoutEpisodeStart(SafeAsk):
    episode_start = None


def test_the_benchmark_takes_the_strategies_the_loop_takes(tmp_path, capsys):
    """`torchcbl benchmark` refused a strategy without to_config ("AskWhileUnsure is not a
    strategy; expected a class with the methods of torchcbl.strategies.Strategy (bind, decide,
    actor, observe_label, observe_refit, observe_step, ...)", every one of which it has),
    though ConfidentTeacher runs it and the docs make to_config optional; and a class that
    does lack a method was not told which."""
    argv = [*_TOY_SWEEP, "--strategies", "test_user_strategy:AskWhileUnsure"]
    assert main([*argv, "--out", str(tmp_path / "b")]) == 0, capsys.readouterr().err
    assert (tmp_path / "b" / "results.json").exists()
    capsys.readouterr()
    argv = [*_TOY_SWEEP, "--strategies", "test_user_strategy:WithoutEpisodeStart"]
    assert main([*argv, "--out", str(tmp_path / "c")]) == 2
    out, err = capsys.readouterr()
    assert not out and err.count("\n") == 1, err
    assert "test_user_strategy:WithoutEpisodeStart" in err and "episode_start()" in err, err
    assert not (tmp_path / "c").exists()


def test_run_benchmark_refuses_a_class_that_is_not_a_strategy_before_any_cell_runs(tmp_path):
    """In Python, a strategy lacking a method of the protocol was refused only when its first
    cell ran (a CellError), after every cell of the strategies before it had run (hours, in a
    real sweep); a misspelt parameter is refused before anything runs, and so is it now."""
    env = bm.EnvSpec(
        name="toy",
        env_id="_bench_env:BenchCluster-v0",
        teacher="_bench_env:teacher",
        budgets=(5,),
        max_steps=10,
        eval_episodes=1,
    )
    specs = [bm.StrategySpec("bc"), bm.StrategySpec("test_user_strategy:WithoutEpisodeStart")]
    with pytest.raises(ValueError, match=r"WithoutEpisodeStart.*without episode_start\(\)"):
        bm.run_benchmark(specs, [env], [0], tmp_path / "b", workers=1, plots=False)
    assert not (tmp_path / "b").exists()  # bc's cell did not run


class RelabellingSafeAsk(SafeAsk):
    """Relabels (a label for a stored observation replaces it), but its to_config, written
    from SafeAsk's, does not say so."""

    relabel = True


def test_a_to_config_that_misstates_relabel_is_refused_before_the_session_starts(tmp_path):
    """The session's readers take "relabel" from the stored to_config(), the loop from the
    strategy's attribute. A relabelling strategy whose to_config() left it out (or said false)
    ran, and then load_demonstrations handed back another training set than the one the live
    model was fitted on (a probe on rounded observations: 60 labels where the loop,
    relabelling repeated observations, had 30), with no word; the session now refuses to
    start, saying what to return."""
    env = rare_regions_world(episode_length=10)
    with pytest.raises(TypeError, match=r'RelabellingSafeAsk.*"relabel": True'):
        ConfidentTeacher(
            env, oracle(env), strategy=RelabellingSafeAsk(), run_dir=tmp_path / "r", progress=False
        )
    assert not (tmp_path / "r").exists()


class RenamedArgument(SafeAsk):
    """Its constructor calls k ``neighbours``; its to_config, SafeAsk's, stores ``k``."""

    def __init__(self, threshold: float = 0.3, neighbours: int = 5) -> None:
        super().__init__(threshold, neighbours)

    def to_config(self):
        return {**super().to_config(), "type": "RenamedArgument"}


def test_a_registered_class_its_stored_config_does_not_fit_is_told_why(tmp_path, monkeypatch):
    """A registered class whose to_config() keys are not its constructor's arguments failed
    to resume with "RenamedArgument.__init__() got an unexpected keyword argument 'k'. Resume
    with matching arguments", which says neither where the 'k' came from nor what to change."""
    monkeypatch.setitem(STRATEGIES, "RenamedArgument", RenamedArgument)
    _teach(tmp_path / "r", RenamedArgument(), 12)
    with pytest.raises(IncompatibleRunDirError) as caught:
        _resume(tmp_path / "r")
    text = str(caught.value)
    assert "unexpected keyword argument 'k'" in text, text
    assert "to_config()" in text and "constructor" in text and "strategy=" in text, text


def test_a_session_stored_before_the_relabel_check_still_resumes_with_a_warning(tmp_path):
    """Sessions made before the check above may hold a to_config() that misstates "relabel"
    (here: stored by SafeAsk, resumed by RelabellingSafeAsk, whose to_config() is the same
    dict). Such a session resumed before the check; it then failed with a bare TypeError
    that no change of the class could get past (the stored dict is compared exactly). It
    resumes as before, with a warning that the session's readers do not relabel."""
    _teach(tmp_path / "r", SafeAsk(threshold=0.2), 30)
    with pytest.warns(UserWarning, match=r'"relabel": False.*load_demonstrations'):
        ct = _resume(tmp_path / "r", strategy=RelabellingSafeAsk(threshold=0.2))
    ct.run(max_steps=40)  # the session's total
    ct.close()
    assert len(load_records(tmp_path / "r")) == 40


class DAgger(SafeAsk):
    """A user's class that happens to share a shipped strategy's name, and describes itself
    with settings the shipped DAgger also takes."""

    def to_config(self):
        return {"type": "DAgger", "beta0": 1.0, "decay": 0.5, "iteration_steps": 50, "seed": 0}


def test_a_to_config_type_that_names_another_shipped_class_is_refused_at_start(
    tmp_path, monkeypatch
):
    """strategy_from_config rebuilds by the stored "type" alone: a session of a user's class
    whose to_config() said "type": "DAgger" resumed (without strategy=) as the shipped DAgger,
    another strategy, with no word. The session now refuses to start, saying what to rename;
    a subclass of the shipped class is still taken (it is stored as custom, see
    test_a_subclass_keeping_its_parents_to_config_does_not_resume_as_its_parent), and so is
    the user's class once registered under that name."""
    from torchcbl.strategies.dagger import DAgger as ShippedDAgger

    env = rare_regions_world(episode_length=10)
    with pytest.raises(TypeError, match=r'"type": \'DAgger\'.*test_user_strategy\.DAgger'):
        ConfidentTeacher(
            env, oracle(env), strategy=DAgger(), run_dir=tmp_path / "r", progress=False
        )
    assert not (tmp_path / "r").exists()

    class Mine(ShippedDAgger):  # keeps the parent's to_config
        pass

    ConfidentTeacher(env, oracle(env), strategy=Mine(), run_dir=tmp_path / "s", progress=False)
    # the same through the shipped builder functions (ConfidentExecution's, CBA's)
    for shipped in (ConfidentExecution(), ConfidenceBasedAutonomy()):
        config = shipped.to_config()
        kind = config["type"]
        user = type(kind, (SafeAsk,), {"to_config": lambda self, c=config: dict(c)})()
        user.relabel = shipped.relabel
        with pytest.raises(TypeError, match=f"\"type\": '{kind}'"):
            ConfidentTeacher(
                env, oracle(env), strategy=user, run_dir=tmp_path / "u", progress=False
            )
        sub = type("Sub", (type(shipped),), {})()
        ConfidentTeacher(
            env, correcting(oracle(env)), strategy=sub, run_dir=tmp_path / kind, progress=False
        )
    assert not (tmp_path / "u").exists()
    monkeypatch.setitem(STRATEGIES, "DAgger", DAgger)
    ConfidentTeacher(env, oracle(env), strategy=DAgger(), run_dir=tmp_path / "t", progress=False)


def test_an_instance_made_before_its_module_was_reloaded_still_starts_a_session(
    tmp_path, monkeypatch
):
    """importlib.reload (or IPython's autoreload) puts a new class object in the module, and
    instances made before keep the old one. The check above compared class objects, so such
    a DAgger (and, after a reload of torchcbl.strategies, the default ConfidentExecution)
    was refused with "torchcbl.strategies.dagger.DAgger is neither that class nor a
    subclass of it". A class of the same module and qualified name is the same strategy."""
    import torchcbl.strategies.dagger as dagger_module

    old = dagger_module.DAgger
    skip = ("__dict__", "__weakref__")
    reloaded = type(
        old.__name__, old.__bases__, {k: v for k, v in vars(old).items() if k not in skip}
    )
    made_before = old()
    monkeypatch.setattr(dagger_module, "DAgger", reloaded)
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        env, oracle(env), strategy=made_before, run_dir=tmp_path / "r", progress=False
    )
    ct.run(max_steps=5)
    ct.close()
    assert len(load_records(tmp_path / "r")) == 5


@pytest.mark.parametrize("kind", [None, 3, ["SafeAsk"]])
def test_a_to_config_whose_type_is_not_a_name_is_refused_before_the_session_starts(tmp_path, kind):
    """A to_config() whose "type" was not a string (None, a number, a list) started a
    session whose config.json its own readers then could not use as one (the type names the
    class to rebuild and to compare on resume). It is refused at the start, nothing written."""

    class Typed(SafeAsk):
        def to_config(self):
            return {**super().to_config(), "type": kind}

    env = rare_regions_world(episode_length=10)
    with pytest.raises(TypeError, match=r'Typed.to_config\(\) gives "type": .*a string'):
        ConfidentTeacher(env, oracle(env), strategy=Typed(), run_dir=tmp_path / "r", progress=False)
    assert not (tmp_path / "r").exists()


class AlwaysAsks(ConfidentExecution):
    """A user's confident execution that asks at every step; it keeps ConfidentExecution's
    to_config(), whose "type" is "ConfidentExecution"."""

    def decide(self, observation, c):
        return super().decide(observation, c)._replace(ask=True)


def test_a_subclass_keeping_its_parents_to_config_does_not_resume_as_its_parent(tmp_path):
    """A subclass of a shipped strategy that kept the parent's to_config() was stored as the
    parent ("type": "ConfidentExecution"), and a resume without strategy= rebuilt the parent
    and went on teaching with another strategy, with no word. It is stored as custom (its own
    class, the parent's dict kept under "inherited"): the resume asks for it, the parent is
    refused, and so is the subclass with other settings. A session stored as the parent (as
    before) still resumes with the subclass passed."""
    from torchcbl.confidence import DistanceRule

    run = tmp_path / "r"
    _teach(run, AlwaysAsks(), 12)
    with pytest.raises(IncompatibleRunDirError, match=r"AlwaysAsks.*strategy=") as caught:
        _resume(run)
    assert "ConfidentExecution" in str(caught.value), caught.value
    stored = load_config(run)["strategy"]
    assert stored["type"] == "test_user_strategy.AlwaysAsks" and stored["custom"], stored
    assert stored["inherited"] == ConfidentExecution().to_config(), stored
    for other in (ConfidentExecution(), AlwaysAsks(DistanceRule(3.0))):
        with pytest.raises(IncompatibleRunDirError, match="strategy: stored"):
            _resume(run, strategy=other)
    ct = _resume(run, strategy=AlwaysAsks())
    ct.run(max_steps=24)
    ct.close()
    assert all(r.teacher_action is not None for r in load_records(run))
    _teach(tmp_path / "old", ConfidentExecution(), 12)  # stored as the parent
    _resume(tmp_path / "old", strategy=AlwaysAsks()).close()


def test_a_session_stored_before_as_the_parent_with_a_rule_of_ones_own_resumes_with_the_subclass(
    tmp_path,
):
    """Before subclasses keeping their parent's to_config were stored as custom (abcd59b),
    Mine(ConfidentExecution) with a user's rule that has no to_config was stored as the
    parent's dict, custom for its rule's sake: {"type": "ConfidentExecution", "rule":
    {"type": "...Lenient", "custom": true}, "custom": true}, the dict ConfidentExecution
    (Lenient()) still stores. Resuming such a session with strategy=Mine(Lenient()), the same
    objects, was refused ("strategy: stored ..."), though a session stored as the parent
    resumes with the subclass passed. It resumes; the subclass with another rule class is
    refused, and so is a subclass of ConfidenceBasedAutonomy with other settings on a session
    stored as ConfidenceBasedAutonomy (only custom dicts are compared by class name)."""

    class Lenient:  # a user's rule without to_config
        def is_confident(self, c):
            return (c.distance <= 2.0) & (c.action >= 0)

        def update(self, *args):
            pass

    class Other(Lenient):
        pass

    class Mine(ConfidentExecution):
        pass

    class MyCBA(ConfidenceBasedAutonomy):
        pass

    old = tmp_path / "old"
    _teach(old, ConfidentExecution(Lenient()), 12)  # what Mine(Lenient()) was stored as
    stored = load_config(old)["strategy"]
    assert stored["type"] == "ConfidentExecution" and stored["custom"], stored
    assert stored["rule"]["type"].endswith("Lenient") and "inherited" not in stored, stored
    for other in (Mine(Other()), Mine()):
        with pytest.raises(IncompatibleRunDirError, match="strategy: stored"):
            _resume(old, strategy=other)
    ct = _resume(old, strategy=Mine(Lenient()))
    ct.run(max_steps=16)
    ct.close()
    assert len(load_records(old)) == 16
    cba = tmp_path / "cba"
    # the oracle has no correct(): CBA says it will never be corrected (expected here)
    with pytest.warns(UserWarning, match="never correct"):
        _teach(cba, ConfidenceBasedAutonomy(), 4)
    with pytest.raises(IncompatibleRunDirError, match="strategy: stored"):
        _resume(cba, strategy=MyCBA(distance_multiplier=3.0))
    with pytest.warns(UserWarning, match="never correct"):
        _resume(cba, strategy=MyCBA()).close()


def test_a_rule_subclass_keeping_its_parents_to_config_does_not_resume_as_its_parent(tmp_path):
    """The same for a confidence rule: a subclass of DistanceRule that kept its to_config()
    was stored as {"type": "DistanceRule", ...} and a resume without rule= or strategy= went
    on with the plain DistanceRule. Its session now asks for rule= on resume, and refuses
    the parent and the subclass with another threshold."""
    import torch

    from torchcbl.confidence import DistanceRule

    class NeverSure(DistanceRule):
        def is_confident(self, c, observations=None):
            return torch.zeros(len(c.action), dtype=torch.bool)

    run = tmp_path / "r"
    _teach(run, ConfidentExecution(NeverSure()), 12)
    with pytest.raises(IncompatibleRunDirError, match=r"NeverSure.*rule="):
        _resume(run)
    rule = load_config(run)["strategy"]["rule"]
    assert rule["custom"] and rule["type"].endswith("NeverSure"), rule
    assert rule["inherited"] == {"type": "DistanceRule", "max_std": 2.0}, rule
    for other in (DistanceRule(), NeverSure(3.0)):
        with pytest.raises(IncompatibleRunDirError, match="strategy: stored"):
            _resume(run, rule=other)
    _resume(run, rule=NeverSure()).close()
    _teach(tmp_path / "old", ConfidentExecution(), 12)  # stored as the parent
    _resume(tmp_path / "old", rule=NeverSure()).close()


def test_the_library_classes_are_stored_as_before(tmp_path):
    """Storing subclasses as custom leaves the shipped classes' dicts as they were: a plain
    session's strategy and rule entries, and every shipped strategy's to_config()."""
    from torchcbl.confidence import AutoThresholdRule, DistanceRule, PosteriorRule
    from torchcbl.strategies import strategy_to_config
    from torchcbl.strategies.bc import BehaviourCloning
    from torchcbl.strategies.dagger import DAgger as ShippedDAgger
    from torchcbl.strategies.hg_dagger import HGDAgger
    from torchcbl.strategies.novelty import NoveltyGated

    _teach(tmp_path / "r", ConfidentExecution(), 4)
    config = load_config(tmp_path / "r")
    plain = {"type": "DistanceRule", "max_std": 2.0}
    assert config["rule"] == plain
    assert config["strategy"] == {"type": "ConfidentExecution", "rule": plain, "relabel": False}
    rules = [PosteriorRule(0.8), AutoThresholdRule(3.0, 1.0), DistanceRule(quantile=0.9)]
    others = (ConfidenceBasedAutonomy, BehaviourCloning, ShippedDAgger, HGDAgger, NoveltyGated)
    shipped = [ConfidentExecution(r) for r in rules] + [cls() for cls in others]
    for strategy in shipped:
        assert strategy_to_config(strategy) == strategy.to_config(), strategy
        assert "custom" not in strategy.to_config(), strategy
