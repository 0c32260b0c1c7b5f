"""The strategy seam: who asks and who acts, configured from the run directory on resume."""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest
from _toy_envs import oracle, rare_regions_world

from torchcbl import (
    AutoThresholdRule,
    ConfidentTeacher,
    DistanceRule,
    PosteriorRule,
    TeachingConfig,
)
from torchcbl.errors import IncompatibleRunDirError
from torchcbl.session import load_config, load_records
from torchcbl.strategies import (
    ConfidenceBasedAutonomy,
    ConfidentExecution,
    Decision,
    Strategy,
    correcting,
    strategy_from_config,
)
from torchcbl.strategies.bc import BehaviourCloning
from torchcbl.strategies.dagger import DAgger
from torchcbl.strategies.hg_dagger import HGDAgger
from torchcbl.strategies.novelty import NoveltyGated


class AlwaysAskAgentActs:
    """DAgger with beta = 0: label every step, execute the agent's action once it has one."""

    relabel = False
    wants_corrections = False

    def __init__(self) -> None:
        self.labels: list[tuple[int, str]] = []
        self.refits: list[int] = []
        self.steps = 0

    def bind(self, *, n_actions, n_features, config):
        self.bound = (n_actions, n_features)

    def episode_start(self):
        pass

    def decide(self, observation, c):
        return Decision(True, "confident")

    def actor(self, decision, model_action, teacher_action):
        return "agent" if model_action >= 0 else "teacher"

    def observe_label(self, observation, action, *, model_action, kind):
        self.labels.append((action, kind))

    def observe_refit(self, model, observations, actions):
        self.refits.append(len(actions))

    def observe_step(self, record, decision):
        self.steps += 1


def test_custom_strategy_labels_every_step_and_the_agent_acts(tmp_path):
    env = rare_regions_world(episode_length=10)
    s = AlwaysAskAgentActs()
    ct = ConfidentTeacher(
        env,
        oracle(env),
        strategy=s,
        config=TeachingConfig(max_new=5),
        run_dir=tmp_path / "run",
        progress=False,
    )
    ct.run(max_steps=40)
    ct.close()
    recs = load_records(tmp_path / "run")
    assert s.bound == (3, 2) and s.steps == 40 and len(s.labels) == 40
    assert s.refits == [5, 10, 15, 20, 25, 30, 35, 40]
    assert all(r.teacher_action is not None and not r.autonomous for r in recs)
    assert [r.actor for r in recs[:5]] == ["teacher"] * 5  # no model before the 5th label
    after = recs[5:]
    assert {r.actor for r in after} == {"agent"}
    assert all(r.executed_action == r.model_action for r in after)
    assert any(r.executed_action != r.teacher_action for r in after)  # the agent's, not the label
    assert load_config(tmp_path / "run")["strategy"]["custom"] is True
    env2 = rare_regions_world(episode_length=10)
    with pytest.raises(IncompatibleRunDirError, match="Pass strategy="):
        ConfidentTeacher.resume(tmp_path / "run", env2, oracle(env2), progress=False)
    s2 = AlwaysAskAgentActs()
    back = ConfidentTeacher.resume(
        tmp_path / "run", env2, oracle(env2), strategy=s2, progress=False
    )
    back.close()
    assert len(s2.labels) == 40 and s2.refits == [40] and s2.steps == 40  # replayed, refit once


def test_default_strategy_is_confident_execution_and_is_rebuilt_on_resume(tmp_path):
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        env,
        oracle(env),
        rule=PosteriorRule(0.8),
        config=TeachingConfig(max_new=2, accuracy_window=10),
        run_dir=tmp_path / "run",
        progress=False,
    )
    assert isinstance(ct.strategy, ConfidentExecution) and ct.rule.min_posterior == 0.8
    ct.run(max_steps=120)
    ct.close()
    stored = load_config(tmp_path / "run")["strategy"]
    assert stored == {
        "type": "ConfidentExecution",
        "rule": {"type": "PosteriorRule", "min_posterior": 0.8},
        "relabel": False,
    }
    back = ConfidentTeacher.resume(tmp_path / "run", env, oracle(env), progress=False)
    assert isinstance(back.strategy, ConfidentExecution)
    assert back.rule.to_config() == stored["rule"]
    assert back.phase == ct.phase == "confident"
    with pytest.raises(IncompatibleRunDirError, match="strategy: stored"):
        ConfidentTeacher.resume(
            tmp_path / "run", env, oracle(env), strategy=ConfidentExecution(DistanceRule(3.0))
        )
    with pytest.raises(ValueError, match="not both"):
        ConfidentTeacher(env, oracle(env), rule=DistanceRule(), strategy=ConfidentExecution())
    with pytest.raises(ValueError, match="not one of"):
        strategy_from_config({"type": "Nope"})


def test_a_failed_rebuild_names_the_call_made_and_advises_on_keys_only_when_they_are_wrong(
    monkeypatch,
):
    """strategy_from_config turned every TypeError into "as X(**params): ...; the keys of its
    to_config() must be its constructor's keyword arguments", also when a registered function
    (called with the dict) or the shipped ConfidentExecution builder (which rebuilds the rule)
    was the call, or when the constructor took the keys and refused a value's type. Now the
    message names the call made, and gives the key advice only where the keys do not fit."""
    from torchcbl import strategies

    class Picky:
        def __init__(self, k: int = 1) -> None:
            if not isinstance(k, int):
                raise TypeError(f"k must be an int, got {k!r}")

    def build(params):
        return Picky(**params)

    monkeypatch.setitem(strategies.STRATEGIES, "Picky", Picky)
    monkeypatch.setitem(strategies.STRATEGIES, "PickyFn", build)
    advice = "must be its constructor's keyword arguments"
    with pytest.raises(TypeError) as err:  # the keys fit, a value does not
        strategy_from_config({"type": "Picky", "k": "a"})
    msg = str(err.value)
    assert "Picky(**{'k': 'a'}) raised TypeError: k must be an int, got 'a'" in msg, msg
    assert advice not in msg and "strategy=<your strategy>" in msg, msg
    with pytest.raises(TypeError) as err:  # a key the constructor does not take
        strategy_from_config({"type": "Picky", "j": 1})
    msg = str(err.value)
    assert "as Picky(**{'j': 1})" in msg and advice in msg, msg
    with pytest.raises(TypeError) as err:  # a function, called with the dict
        strategy_from_config({"type": "PickyFn", "j": 1, "relabel": False})
    msg = str(err.value)
    assert "STRATEGIES['PickyFn']({'j': 1})" in msg and "PickyFn(**" not in msg, msg
    assert advice not in msg and "unexpected keyword argument 'j'" in msg, msg
    with pytest.raises(TypeError) as err:  # the shipped builder rebuilds the rule
        strategy_from_config(
            {"type": "ConfidentExecution", "rule": {"type": "DistanceRule", "j": 1}}
        )
    msg = str(err.value)
    assert "ConfidentExecution(rule_from_config({'type': 'DistanceRule', 'j': 1}))" in msg, msg
    assert advice not in msg and "unexpected keyword argument 'j'" in msg, msg


def test_a_rule_that_takes_observations_gets_them():
    seen: list[np.ndarray] = []

    class FarFromOriginAsks(DistanceRule):
        def is_confident(self, c, observations=None):
            seen.append(np.asarray(observations))
            near = np.linalg.norm(observations, axis=1) < 4.0
            return super().is_confident(c) & __import__("torch").from_numpy(near)

    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        env,
        oracle(env),
        rule=FarFromOriginAsks(3.0),
        config=TeachingConfig(max_new=2, noninteractive=False),
        progress=False,
    )
    ct.run(max_steps=200)
    assert seen and all(o.shape == (1, 2) for o in seen)
    far_auto = [r for r in ct.records if r.autonomous and np.linalg.norm(r.observation) >= 4.0]
    assert not far_auto and any(r.autonomous for r in ct.records)


class _ActorSays(AlwaysAskAgentActs):
    def __init__(self, says):
        super().__init__()
        self.says = says

    def actor(self, decision, model_action, teacher_action):
        return self.says


@pytest.mark.parametrize("says", ["banana", "agent"])
def test_an_impossible_actor_answer_is_a_clear_error_before_the_env_steps(says):
    # "agent" before any model exists would execute action -1
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(env, oracle(env), strategy=_ActorSays(says), progress=False)
    with pytest.raises(RuntimeError, match=f"actor\\(\\) returned '{says}'"):
        ct.run(max_steps=3)
    assert ct.n_steps == 0


def test_a_used_strategy_instance_given_to_resume_replays_from_scratch(tmp_path):
    """bind() starts a strategy afresh: the live instance handed to resume() replays the log
    instead of adding it to what it had counted (HG-DAgger's warmup was cut short)."""
    from torchcbl.strategies import correcting
    from torchcbl.strategies.hg_dagger import HGDAgger

    env = rare_regions_world(episode_length=10)
    s = HGDAgger(warmup=10)
    teacher = correcting(oracle(env))
    ct = ConfidentTeacher(env, teacher, strategy=s, run_dir=tmp_path / "r", progress=False)
    ct.run(max_steps=6)
    ct.close()
    env2 = rare_regions_world(episode_length=10)
    teacher2 = correcting(oracle(env2))
    back = ConfidentTeacher.resume(tmp_path / "r", env2, teacher2, strategy=s, progress=False)
    back.run(max_steps=12)
    back.close()
    phases = [r.phase for r in load_records(tmp_path / "r")]
    assert phases[:10] == ["noninteractive"] * 10 and phases[10] == "confident"


def test_strategy_parameters_that_could_never_work_are_refused():
    from torchcbl.strategies.dagger import DAgger
    from torchcbl.strategies.novelty import NoveltyGated

    with pytest.raises(ValueError, match="min_history must be <= window"):
        NoveltyGated(window=5, min_history=10)  # would ask on every step
    with pytest.raises(ValueError, match="seed must be an int >= 0"):
        DAgger(seed=-1)  # its first coin would fail after the teacher was asked


class _NoEpisodeStart:
    """A strategy of one's own that forgot the protocol's episode_start."""

    relabel = False
    wants_corrections = False

    def bind(self, *, n_actions, n_features, config):
        pass

    def decide(self, observation, c):
        return Decision(True, "confident")

    def actor(self, decision, model_action, teacher_action):
        return "teacher"

    def observe_label(self, observation, action, *, model_action, kind):
        pass

    def observe_refit(self, model, observations, actions):
        pass

    def observe_step(self, record, decision):
        pass


def test_a_strategy_without_episode_start_is_refused_before_a_session_exists(tmp_path):
    """The loop calls episode_start() after every reset; a strategy without it passed the
    check and failed with a bare AttributeError at the first reset, a run directory already
    written."""
    env = rare_regions_world(episode_length=10)
    with pytest.raises(TypeError, match=r"without episode_start\(\)"):
        ConfidentTeacher(
            env, oracle(env), strategy=_NoEpisodeStart(), run_dir=tmp_path / "r", progress=False
        )
    assert not (tmp_path / "r").exists()


class _SubclassedProtocol(Strategy):
    """A strategy that subclasses the Strategy protocol and inherits its empty to_config()."""

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


def test_a_subclass_of_the_protocol_without_to_config_is_stored_as_custom(tmp_path):
    """Subclassing Strategy gives the protocol's to_config, which returns None: a session
    with such a strategy failed to start (TypeError: 'NoneType' object is not iterable)."""
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        env, oracle(env), strategy=_SubclassedProtocol(), run_dir=tmp_path / "r", progress=False
    )
    ct.run(max_steps=15)
    ct.close()
    assert load_config(tmp_path / "r")["strategy"]["custom"] is True
    env2 = rare_regions_world(episode_length=10)
    with pytest.raises(IncompatibleRunDirError, match="Pass strategy="):
        ConfidentTeacher.resume(tmp_path / "r", env2, oracle(env2), progress=False)
    back = ConfidentTeacher.resume(
        tmp_path / "r", env2, oracle(env2), strategy=_SubclassedProtocol(), progress=False
    )
    back.run(max_steps=20)
    back.close()
    assert len(load_records(tmp_path / "r")) == 20


def test_a_to_config_that_returns_no_dict_is_a_clear_error(tmp_path):
    class Listy(_SubclassedProtocol):
        def to_config(self):
            return ["Listy"]

    env = rare_regions_world(episode_length=10)
    with pytest.raises(TypeError, match=r"Listy.to_config\(\) returned \['Listy'\]; expected"):
        ConfidentTeacher(env, oracle(env), strategy=Listy(), run_dir=tmp_path / "r")


class _Swept(_SubclassedProtocol):
    """A strategy of one's own built from a sweep's numpy numbers, with a tuple parameter."""

    def __init__(self, margin, sizes):
        self.margin, self.sizes = margin, sizes

    def to_config(self):
        return {"type": "_Swept", "margin": self.margin, "sizes": self.sizes, "relabel": False}


class _SweptRule:
    def __init__(self, max_std):
        self.max_std = max_std

    def is_confident(self, c):
        return c.distance <= float(self.max_std)

    def update(self, model, observations, actions):
        pass

    def to_config(self):
        return {"type": "_SweptRule", "max_std": self.max_std}


def test_numpy_numbers_and_tuples_in_to_config_are_stored_and_resume(tmp_path):
    """A strategy or rule of one's own whose to_config() holds a numpy number (a sweep's
    np.float32(0.5)) failed to start a session with json's bare 'Object of type float32 is not
    JSON serializable'; one holding a tuple started, but config.json read it back as a list,
    so resuming with the same strategy was refused ('strategy: stored ..., given ...'). Both
    are stored as JSON holds them and resume; a value JSON cannot hold is named."""
    for name, kw in [
        ("strategy", {"strategy": _Swept(np.float32(0.5), (np.int64(2), 3))}),
        ("rule", {"rule": _SweptRule(np.float32(2.5))}),
    ]:
        env = rare_regions_world(episode_length=10)
        ct = ConfidentTeacher(env, oracle(env), run_dir=tmp_path / name, progress=False, **kw)
        ct.run(max_steps=15)
        ct.close()
        stored = load_config(tmp_path / name)["strategy"]
        if name == "strategy":
            assert stored == {"type": "_Swept", "margin": 0.5, "sizes": [2, 3], "relabel": False}
        else:
            assert stored["rule"] == {"type": "_SweptRule", "max_std": 2.5}
        kw = {
            "strategy": _Swept(np.float32(0.5), (2, 3))
            if name == "strategy"
            else ConfidentExecution(_SweptRule(2.5))
        }
        back = ConfidentTeacher.resume(tmp_path / name, env, oracle(env), progress=False, **kw)
        back.run(max_steps=20)
        back.close()
        assert len(load_records(tmp_path / name)) == 20
    env = rare_regions_world(episode_length=10)
    with pytest.raises(TypeError, match=r"_Swept.to_config\(\) returned .*config.json cannot hold"):
        ConfidentTeacher(
            env, oracle(env), strategy=_Swept({1, 2}, ()), run_dir=tmp_path / "s", progress=False
        )
    with pytest.raises(TypeError, match=r"_SweptRule.to_config\(\) returned .*cannot hold"):
        ConfidentTeacher(
            env, oracle(env), rule=_SweptRule(object()), run_dir=tmp_path / "r", progress=False
        )


class _OneBool:
    """A rule of one's own answering one bool (or a 0-d tensor) instead of one per row."""

    def __init__(self, zero_d):
        self.zero_d = zero_d

    def is_confident(self, c):
        near = c.distance[0] <= 2.0
        return near if self.zero_d else bool(near)

    def update(self, model, observations, actions):
        pass


@pytest.mark.parametrize("zero_d", [False, True], ids=["bool", "0-d-tensor"])
def test_a_rule_answering_one_bool_is_told_it_answers_one_per_row(tmp_path, zero_d):
    """It failed in the loop with "'bool' object is not subscriptable" or torch's "invalid index
    of a 0-dim tensor", which name neither the rule nor what it should return."""
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        env,
        oracle(env),
        rule=_OneBool(zero_d),
        config=TeachingConfig(noninteractive=False, max_new=3),
        run_dir=tmp_path / "r",
        progress=False,
    )
    with pytest.raises(
        TypeError, match=r"_OneBool object .*is_confident\(\) returned .*expected one bool per "
    ):
        ct.run(max_steps=20)
    ct.close()
    assert len(load_records(tmp_path / "r")) == 3  # the steps before the first fit, asked


def _right_of_zero(observation, info):
    return int(observation[0] > 0)


def test_a_correcting_teacher_pickles_like_the_teacher_it_wraps():
    """correcting() built its wrapper class inside the function, so the wrapper of a picklable
    teacher could not be pickled ("Can't pickle local object") and could not be sent to a
    process pool that runs sessions in parallel."""
    import pickle

    from torchcbl.strategies import correcting

    back = pickle.loads(pickle.dumps(correcting(_right_of_zero)))
    obs = np.array([0.5, -1.0])
    assert back(obs, {}) == 1 and back.correct(obs, {}, 0) == 1 and back.correct(obs, {}, 1) is None


def test_a_strategy_class_instead_of_an_instance_is_a_clear_error(tmp_path):
    """A class has the protocol's methods, unbound: it passed the check and failed in bind()
    with "missing 1 required positional argument: 'self'"."""
    from torchcbl.strategies.cba import ConfidenceBasedAutonomy

    env = rare_regions_world(episode_length=10)
    with pytest.raises(
        TypeError,
        match=r"got the class ConfidenceBasedAutonomy.*"
        r"strategy=ConfidenceBasedAutonomy\(\)",
    ):
        ConfidentTeacher(
            env,
            oracle(env),
            strategy=ConfidenceBasedAutonomy,
            run_dir=tmp_path / "r",
            progress=False,
        )
    assert not (tmp_path / "r").exists()


def test_a_rule_class_instead_of_an_instance_is_a_clear_error(tmp_path):
    """A rule class has is_confident and update, unbound: it passed the check and failed at
    bind() with "missing 1 required positional argument: 'self'"."""
    env = rare_regions_world(episode_length=10)
    with pytest.raises(TypeError, match=r"got the class DistanceRule.*DistanceRule\(\)"):
        ConfidentExecution(DistanceRule)
    with pytest.raises(TypeError, match=r"got the class PosteriorRule.*PosteriorRule\(\)"):
        ConfidentTeacher(
            env, oracle(env), rule=PosteriorRule, run_dir=tmp_path / "r", progress=False
        )
    assert not (tmp_path / "r").exists()


class _EveryNth(_SubclassedProtocol):
    """Ask every n-th step (and while there is no model), else act; rebuilt from its config."""

    def __init__(self, n: int = 3) -> None:
        self.n = n
        self.steps = 0

    def decide(self, observation, c):
        return Decision(int(c.action[0]) < 0 or self.steps % self.n == 0, "confident")

    def actor(self, decision, model_action, teacher_action):
        return "teacher" if teacher_action is not None else "agent"

    def observe_step(self, record, decision):
        self.steps += 1

    def to_config(self):
        return {"type": "EveryNth", "n": self.n, "relabel": False}


def test_a_strategy_class_registered_in_strategies_is_rebuilt_on_resume(tmp_path, monkeypatch):
    """The module docstring says to register a new class in STRATEGIES; registering the class
    built it with the config dict as its first argument (n = {'n': 4}), so a resumed session
    without strategy= failed at its first step with a TypeError from deep inside decide()."""
    from torchcbl import strategies

    monkeypatch.setitem(strategies.STRATEGIES, "EveryNth", _EveryNth)
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        env, oracle(env), strategy=_EveryNth(4), run_dir=tmp_path / "r", progress=False
    )
    ct.run(max_steps=12)
    ct.close()
    env2 = rare_regions_world(episode_length=10)
    back = ConfidentTeacher.resume(tmp_path / "r", env2, oracle(env2), progress=False)
    assert isinstance(back.strategy, _EveryNth) and back.strategy.n == 4
    assert back.strategy.steps == 12  # the log was replayed into it
    back.run(max_steps=20)
    back.close()
    recs = load_records(tmp_path / "r")
    asked = [r.step for r in recs if r.teacher_action is not None and r.model_action >= 0]
    assert asked and all(s % 4 == 0 for s in asked)
    assert any(s >= 12 for s in asked)


def test_a_shipped_strategy_in_ones_own_loop_says_when_it_was_not_bound():
    """Driven by a loop of one's own, ConfidentExecution (and CBA) never bound asked on every
    step forever without a word (its phase never left the non-interactive one), and bound with
    config=None failed with AttributeError: 'NoneType' object has no attribute
    'noninteractive'. Both now say what bind() wants."""
    from torchcbl import ConfidenceBasedAutonomy, GaussianMixtureSet

    x = np.array([[0.0, 0.0], [0.1, 0.0], [3.0, 3.0], [3.1, 3.0]])
    model = GaussianMixtureSet(2, 2, max_components=1).fit(x, np.array([0, 0, 1, 1]))
    c = model.classify(x[:1])
    for strategy in (ConfidentExecution(DistanceRule(quantile=0.95)), ConfidenceBasedAutonomy()):
        with pytest.raises(RuntimeError, match=r"bind\(n_actions=.*config=TeachingConfig"):
            strategy.decide(x[0], c)
        for bad in (None, {"noninteractive": False}):
            with pytest.raises(TypeError, match=r"expected a TeachingConfig.*got"):
                strategy.bind(n_actions=2, n_features=2, config=bad)
        strategy.bind(n_actions=2, n_features=2, config=TeachingConfig(noninteractive=False))
        strategy.decide(x[0], c)  # bound: it decides


@pytest.mark.parametrize(
    "make",
    [
        ConfidentExecution,
        ConfidenceBasedAutonomy,
        BehaviourCloning,
        DAgger,
        lambda: HGDAgger(warmup=0),
        lambda: NoveltyGated(warmup=0, min_history=1),
    ],
    ids=["confident execution", "cba", "bc", "dagger", "hg-dagger", "novelty"],
)
def test_an_unbound_shipped_strategy_never_fails_on_an_attribute_of_bind(make):
    """A loop of one's own that replays a log before deciding (the protocol's resume order:
    labels, steps, a refit, then decide) without calling bind() got, from CBA's observe_refit,
    a bare AttributeError: 'ConfidenceBasedAutonomy' object has no attribute 'n_actions'.
    Every shipped strategy's public hook either works unbound (the baselines: their state is
    set by __init__, and bind only resets it) or says to call bind, as decide does."""
    from torchcbl import GaussianMixtureSet

    x = np.array([[0.0, 0.0], [0.1, 0.0], [3.0, 3.0], [3.1, 3.0]])
    y = np.array([0, 0, 1, 1])
    model = GaussianMixtureSet(2, 2, max_components=1).fit(x, y)
    step = SimpleNamespace(
        step=0,
        phase="confident",
        terminated=False,
        truncated=False,
        observation_array=x[0],
        distance=0.5,
    )
    calls = {
        "observe_label": lambda s: s.observe_label(x[0], 0, model_action=0, kind="demonstration"),
        "observe_step": lambda s: s.observe_step(step, None),
        "observe_refit": lambda s: s.observe_refit(model, x, y),
        "episode_start": lambda s: s.episode_start(),
        "decide": lambda s: s.decide(x[0], model.classify(x[:1])),
    }
    refused = []
    strategy = make()
    for name, call in calls.items():
        try:
            call(strategy)
        except RuntimeError as exc:
            assert re.search(rf"\.{name}: the strategy was not bound; call bind\(", str(exc))
            refused.append(name)
    needs_bind = isinstance(strategy, (ConfidentExecution, ConfidenceBasedAutonomy))
    assert ("decide" in refused) == needs_bind
    strategy = make()
    strategy.bind(n_actions=2, n_features=2, config=TeachingConfig(noninteractive=False))
    for call in calls.values():
        call(strategy)  # bound: every hook works


@pytest.mark.parametrize(
    "damage",
    [
        lambda s: s.pop("rule"),
        lambda s: s.update(rule="DistanceRule"),
        lambda s: s.update(max_std=3.0),
    ],
    ids=["no rule", "rule not a dict", "a key it does not take"],
)
def test_a_damaged_confident_execution_entry_is_refused_on_resume_saying_so(tmp_path, damage):
    """A config.json whose confident-execution entry lost its "rule" (or holds a rule that is
    not a dict) failed resume with a bare KeyError / AttributeError; one with a key the
    strategy does not take resumed as if it were not there. Each is refused as the session's
    other mismatches are, naming the stored entry."""
    import json

    env = rare_regions_world(episode_length=10)
    with ConfidentTeacher(env, oracle(env), run_dir=tmp_path, progress=False) as ct:
        ct.run(max_steps=5)
    path = tmp_path / "config.json"
    config = json.loads(path.read_text())
    damage(config["strategy"])
    path.write_text(json.dumps(config))
    with pytest.raises(IncompatibleRunDirError, match=r"ConfidentExecution.*\"rule\""):
        ConfidentTeacher.resume(tmp_path, env, oracle(env), progress=False)


@pytest.mark.parametrize("entry", [None, "ConfidentExecution", ["ConfidentExecution"]])
def test_a_config_whose_strategy_entry_is_not_a_strategy_dict_is_a_corrupt_session(tmp_path, entry):
    """A config.json whose "strategy" entry is not a dict (null, a string, a list) failed
    resume with a bare TypeError or ValueError (given a
    strategy) or "'NoneType' object is not iterable" (without), and load_demonstrations and
    load_model with an AttributeError. It is a damaged session, said as the other damaged
    config.json entries are."""
    import json

    from torchcbl.errors import CorruptSessionError
    from torchcbl.session import load_demonstrations, load_model

    env = rare_regions_world(episode_length=10)
    with ConfidentTeacher(env, oracle(env), run_dir=tmp_path, progress=False) as ct:
        ct.run(max_steps=5)
    path = tmp_path / "config.json"
    config = json.loads(path.read_text())
    config["strategy"] = entry
    path.write_text(json.dumps(config))
    for call in (
        lambda: ConfidentTeacher.resume(tmp_path, env, oracle(env), progress=False),
        lambda: ConfidentTeacher.resume(
            tmp_path, env, oracle(env), strategy=ConfidentExecution(), progress=False
        ),
        lambda: load_demonstrations(tmp_path),
        lambda: load_model(tmp_path),
    ):
        with pytest.raises(CorruptSessionError, match="'strategy'"):
            call()


class _CountsSteps:
    """Put before a shipped strategy: adds behaviour to observe_step without calling super()
    (as a researcher would)."""

    def observe_step(self, record, decision):
        self.seen = getattr(self, "seen", 0) + 1


class _CountsLabels:
    """The same for observe_label."""

    def observe_label(self, observation, action, *, model_action, kind):
        self.labels = getattr(self, "labels", 0) + 1


class _StepCounting(_CountsSteps, ConfidentExecution):
    pass


class _LabelCounting(_CountsLabels, ConfidentExecution):
    pass


class _BothCountingCBA(_CountsSteps, _CountsLabels, ConfidenceBasedAutonomy):
    pass


class _CallingSuper(ConfidentExecution):
    def observe_step(self, record, decision):
        super().observe_step(record, decision)
        self.seen = getattr(self, "seen", 0) + 1

    def observe_label(self, observation, action, *, model_action, kind):
        self.labels = getattr(self, "labels", 0) + 1
        super().observe_label(observation, action, model_action=model_action, kind=kind)


def _decisions(tmp_path, name, strategy, steps=120):
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        env,
        correcting(oracle(env)),  # CBA learns from corrections too
        strategy=strategy,
        config=TeachingConfig(max_new=2, accuracy_window=10, burst=2),
        run_dir=tmp_path / name,
        progress=False,
    )
    ct.run(max_steps=steps)
    ct.close()
    return ct, [(r.phase, r.actor) for r in load_records(tmp_path / name)]


@pytest.mark.parametrize(
    "make, parent",
    [
        (lambda: _StepCounting(), ConfidentExecution),
        (lambda: _LabelCounting(), ConfidentExecution),
        (lambda: _CallingSuper(), ConfidentExecution),
        (lambda: _BothCountingCBA(), ConfidenceBasedAutonomy),
    ],
    ids=["observe_step", "observe_label", "calling super", "cba both"],
)
def test_a_subclass_overriding_an_observe_hook_keeps_the_phase_schedule(tmp_path, make, parent):
    """A subclass overriding observe_step or observe_label without calling super() asked at
    every step and never left the non-interactive phase, silently, though its accuracy was
    100 %: the schedule was kept in those hooks. The loop now keeps it whether or not an
    override calls super() (once, also when it does), so the subclass decides as its parent
    does, live and on resume, and its hook still runs at every step and label."""
    _, want = _decisions(tmp_path, "parent", parent())
    mine = make()
    ct, got = _decisions(tmp_path, "mine", mine)
    assert got == want and ("confident", "agent") in got
    assert getattr(mine, "seen", 120) == 120
    assert getattr(mine, "labels", ct.n_demonstrations) == ct.n_demonstrations
    assert (len(ct.corrections) > 0) == (parent is ConfidenceBasedAutonomy)
    env = rare_regions_world(episode_length=10)
    again = make()
    back = ConfidentTeacher.resume(
        tmp_path / "mine", env, correcting(oracle(env)), strategy=again, progress=False
    )
    back.close()
    assert back.phase == ct.phase == "confident"
    assert getattr(again, "seen", 120) == 120


def test_the_public_observe_hooks_keep_the_schedule_in_ones_own_loop():
    """A loop of one's own calls the public hooks only: they still keep the schedule."""
    s = ConfidentExecution()
    s.bind(n_actions=2, n_features=1, config=TeachingConfig(accuracy_window=2))
    for _ in range(2):
        s.observe_label(np.zeros(1), 1, model_action=1, kind="demonstration")
    assert s.phase == "noninteractive"
    step = SimpleNamespace(phase="noninteractive", terminated=False, truncated=False)
    s.observe_step(step, Decision(True, "noninteractive"))
    assert s.phase == "confident"


class _Lenient(ConfidentExecution):
    """Counts every demonstration as one the model got right, through super()'s arguments."""

    def observe_label(self, observation, action, *, model_action, kind):
        super().observe_label(observation, action, model_action=action, kind=kind)


def test_a_super_call_with_arguments_of_its_own_is_honoured(tmp_path):
    """An override that calls super() with arguments of its own (here: every demonstration
    counted as right) steered the schedule through them; the loop's bookkeeping first took the
    loop's arguments and ignored super()'s (review, 2026-11-27), so a lenient subclass stayed
    non-interactive under a random teacher. The loop keeps the schedule itself only where the
    override never reached the base hook."""
    env = rare_regions_world(episode_length=10)
    rng = np.random.default_rng(0)

    def random_teacher(observation, info):
        return int(rng.integers(env.action_space.n))

    mine = _Lenient()
    ct = ConfidentTeacher(
        env,
        random_teacher,
        strategy=mine,
        config=TeachingConfig(accuracy_window=5, target_accuracy=1.0),
        run_dir=tmp_path / "r",
        progress=False,
    )
    ct.run(max_steps=12)
    ct.close()
    assert ct.phase == "confident"


class _NoSuperInit(ConfidentExecution):
    def __init__(self, rule, verbose=False):
        self.rule, self.verbose = rule, verbose


class _NoSuperInitCBA(ConfidenceBasedAutonomy):
    def __init__(self, tag="x"):
        self.tag = tag


class _InheritsTheSkippingInit(_NoSuperInit):
    pass


class _NoSuperInitDAgger(DAgger):
    def __init__(self, beta0=1.0):
        self.beta0 = beta0


class _NoSuperInitHGDAgger(HGDAgger):
    def __init__(self, tag="x"):
        self.tag = tag


class _NoSuperInitNovelty(NoveltyGated):
    def __init__(self, target_rate=0.2):
        self.target_rate = target_rate


@pytest.mark.parametrize(
    "make, named",
    [
        (lambda: _NoSuperInit(DistanceRule(2.0)), "_NoSuperInit"),
        (lambda: _NoSuperInitCBA(), "_NoSuperInitCBA"),
        (lambda: _InheritsTheSkippingInit(DistanceRule(2.0)), "_NoSuperInit"),
        (lambda: _NoSuperInitDAgger(), "_NoSuperInitDAgger"),
        (lambda: _NoSuperInitHGDAgger(), "_NoSuperInitHGDAgger"),
        (lambda: _NoSuperInitNovelty(), "_NoSuperInitNovelty"),
    ],
    ids=["confident execution", "cba", "inherited __init__", "dagger", "hg-dagger", "novelty"],
)
def test_a_subclass_init_that_skips_super_is_refused_when_given_to_a_session(tmp_path, make, named):
    """A subclass whose __init__ did not call super().__init__() was taken, and failed at its
    first confident step (step 21) with AttributeError: 'Mine' object has no attribute
    '_with_obs' (CBA: 'distance_multiplier', as the session was written). It is now refused
    when given to ConfidentTeacher or resume, and when bound in a loop of one's own, naming
    the __init__ to fix; nothing is written. The baselines (DAgger, HG-DAgger, the novelty
    gate) were taken too, and failed later (HG-DAgger: AttributeError 'warmup' from to_config
    as the session was written)."""
    env = rare_regions_world(episode_length=10)
    want = rf"{named}\.__init__ did not call super\(\)\.__init__\(\.\.\.\)"
    with pytest.raises(TypeError, match=want):
        ConfidentTeacher(env, oracle(env), strategy=make(), run_dir=tmp_path / "r")
    assert not (tmp_path / "r").exists()
    ct = ConfidentTeacher(env, oracle(env), run_dir=tmp_path / "ok", progress=False)
    ct.run(max_steps=3)
    ct.close()
    with pytest.raises(TypeError, match=want):
        ConfidentTeacher.resume(tmp_path / "ok", env, oracle(env), strategy=make())
    with pytest.raises(TypeError, match=want):
        make().bind(n_actions=3, n_features=2, config=TeachingConfig())


class _RaisesAtTheFifthLabel(ConfidentExecution):
    calls = 0

    def observe_label(self, observation, action, *, model_action, kind):
        type(self).calls += 1
        if type(self).calls == 5:
            raise ValueError("strategy bug")
        super().observe_label(observation, action, model_action=model_action, kind=kind)


def test_an_override_that_raises_before_super_leaves_the_schedule_as_a_resume_reads_it(tmp_path):
    """An override that raised before reaching the base hook left that label uncounted in the
    running strategy, though the label is logged and a resume counts it: going on in the same
    process then left the non-interactive phase a step later than the resumed session did
    (review, 2026-11-27). The loop keeps the schedule where the hook raised too."""
    config = TeachingConfig(max_new=2, accuracy_window=10)
    phases = {}
    for how in ("same process", "resumed"):
        env = rare_regions_world()
        run = tmp_path / how.replace(" ", "_")
        _RaisesAtTheFifthLabel.calls = 0
        ct = ConfidentTeacher(
            env,
            oracle(env),
            strategy=_RaisesAtTheFifthLabel(),
            config=config,
            run_dir=run,
            progress=False,
        )
        with pytest.raises(ValueError, match="strategy bug"):
            ct.run(max_steps=40)
        if how == "resumed":
            ct.close()
            ct = ConfidentTeacher.resume(
                run, env, oracle(env), strategy=_RaisesAtTheFifthLabel(), progress=False
            )
        ct.run(max_steps=40)
        ct.close()
        phases[how] = [r.phase for r in load_records(run)]
    assert "confident" in phases["resumed"]
    assert phases["same process"] == phases["resumed"]


class _DAggerCounting(_CountsSteps, DAgger):
    pass


class _HGDAggerCounting(_CountsLabels, HGDAgger):
    pass


class _NoveltyCounting(_CountsSteps, _CountsLabels, NoveltyGated):
    pass

    def observe_refit(self, model, observations, actions):
        self.refits = getattr(self, "refits", 0) + 1


class _CountingRefitsCE(ConfidentExecution):
    def observe_refit(self, model, observations, actions):
        self.refits = getattr(self, "refits", 0) + 1


class _CountingRefitsCBA(ConfidenceBasedAutonomy):
    def observe_refit(self, model, observations, actions):
        self.refits = getattr(self, "refits", 0) + 1


@pytest.mark.parametrize(
    "make, parent",
    [
        (lambda: _DAggerCounting(iteration_steps=10), lambda: DAgger(iteration_steps=10)),
        (lambda: _HGDAggerCounting(warmup=5), lambda: HGDAgger(warmup=5)),
        (lambda: _NoveltyCounting(warmup=5, window=20), lambda: NoveltyGated(warmup=5, window=20)),
        (
            lambda: _CountingRefitsCE(AutoThresholdRule()),
            lambda: ConfidentExecution(AutoThresholdRule()),
        ),
        (_CountingRefitsCBA, ConfidenceBasedAutonomy),
    ],
    ids=["dagger observe_step", "hg-dagger observe_label", "novelty all", "ce refit", "cba refit"],
)
def test_a_baseline_subclass_overriding_an_observe_hook_decides_as_its_parent(
    tmp_path, make, parent
):
    """The baselines kept their state in their public hooks, so a subclass overriding one
    without super() broke them silently: DAgger's beta schedule stayed at step 0 (the teacher
    drove forever), HG-DAgger never left its warmup, the novelty gate never filled its window
    (it asked at every step). So did an observe_refit without super() in confident execution
    (the rule was never updated) and CBA (no thresholds: it never acted). The loop keeps their
    state where an override never reaches the base hook, as it does the phase schedule, so the
    subclass decides as its parent, live and on resume, and its hooks still run."""
    _, want = _decisions(tmp_path, "parent", parent(), steps=60)
    mine = make()
    ct, got = _decisions(tmp_path, "mine", mine, steps=60)
    assert got == want and any(actor == "agent" for _, actor in got)
    assert getattr(mine, "seen", 60) == 60
    assert getattr(mine, "labels", ct.n_demonstrations) == ct.n_demonstrations
    assert getattr(mine, "refits", 1) >= 1
    if isinstance(mine, ConfidentExecution):  # its rule was updated at the refits
        assert mine.rule.thresholds is not None
    env = rare_regions_world(episode_length=10)
    again, before = make(), parent()
    for name, s in (("mine", again), ("parent", before)):
        ConfidentTeacher.resume(
            tmp_path / name, env, correcting(oracle(env)), strategy=s, progress=False
        ).close()
    assert again.phase == before.phase
    assert getattr(again, "seen", 60) == 60


class _FailingRule(DistanceRule):
    """A rule whose update fails (a bug of one's own, a GPU out of memory), counting calls."""

    updates = 0

    def update(self, model, observations, actions):
        type(self).updates += 1
        raise RuntimeError(f"update #{type(self).updates}")


def test_a_strategy_update_that_raises_is_not_run_again_by_the_loop(tmp_path):
    """Where a shipped strategy's own update raised inside its base hook, the loop took the
    hook for one that never reached the base one and ran the update again with its own
    arguments: a rule updated twice, and the error the user saw was the second call's
    (review, 2026-11-27). The update runs once and its error is the one raised."""
    env = rare_regions_world()
    _FailingRule.updates = 0
    ct = ConfidentTeacher(
        env,
        oracle(env),
        strategy=ConfidentExecution(_FailingRule()),
        config=TeachingConfig(max_new=3),
        run_dir=tmp_path / "r",
        progress=False,
    )
    with pytest.raises(RuntimeError, match=r"^update #1$"):
        ct.run(max_steps=10)
    assert _FailingRule.updates == 1
    ct.close()


def _class_help(cls: type) -> str:
    """The class's own part of ``help(cls)`` (its docstring as pydoc renders it), without the
    method listing that follows."""
    import pydoc

    text = pydoc.render_doc(cls, renderer=pydoc.plaintext)
    head = text.split("Method resolution order:")[0]
    return "\n".join(line.removeprefix(" |  ").removeprefix(" |") for line in head.splitlines())


def _hooks_keeping_state(cls: type) -> list[str]:
    """The public hooks under which ``cls`` keeps state of its own, read from its class tree:
    a ``_track_<hook>`` below the protocol's defaults, or a ``bind`` / ``episode_start`` of
    its own (ConfidentTeacher calls these; what they do is the strategy's behaviour)."""
    from torchcbl.strategies._phased import _StrategyDefaults

    keeps = [
        f"observe_{hook}"
        for hook in ("label", "step", "refit")
        if getattr(cls, f"_track_{hook}") is not getattr(_StrategyDefaults, f"_track_{hook}")
    ]
    keeps += [
        h for h in ("bind", "episode_start") if getattr(cls, h) is not vars(_StrategyDefaults)[h]
    ]
    return keeps


@pytest.mark.parametrize(
    "cls",
    [
        ConfidentExecution,
        ConfidenceBasedAutonomy,
        BehaviourCloning,
        DAgger,
        HGDAgger,
        NoveltyGated,
    ],
    ids=lambda c: c.__name__,
)
def test_help_on_a_shipped_strategy_says_what_each_of_its_hooks_does(cls):
    """help(DAgger) and help(DAgger.observe_step) showed only the protocol defaults' generic
    text ("keeps the shipped strategy's state"): nowhere did help() say that DAgger's
    observe_step advances the step count behind its beta and coins, HG-DAgger's observe_label
    the takeover, the novelty gate's observe_step / observe_refit its window and rescoring, or
    CE's / CBA's observe_refit the rule's update and the thresholds. Each hook under which a
    shipped class keeps state (found from the class tree, not from the text) is now named in
    the class's help, and so is decide (when it asks); the generic hook text sends the reader
    there."""
    import pydoc

    shown = _class_help(cls)
    for hook in ["decide", *_hooks_keeping_state(cls)]:
        assert f"``{hook}``" in shown, (cls.__name__, hook)
    from torchcbl.strategies._phased import _StrategyDefaults

    for hook in ("observe_label", "observe_step", "observe_refit", "episode_start", "bind"):
        if getattr(cls, hook) is vars(_StrategyDefaults)[hook]:  # the generic text: it must
            text = pydoc.render_doc(getattr(cls, hook), renderer=pydoc.plaintext)
            assert "class docstring" in " ".join(text.split()), (cls.__name__, hook)  # say where


_SHIPPED = [
    ConfidentExecution,
    ConfidenceBasedAutonomy,
    BehaviourCloning,
    DAgger,
    lambda: HGDAgger(warmup=0),
    lambda: NoveltyGated(warmup=0, min_history=1),
]
_SHIPPED_IDS = ["confident execution", "cba", "bc", "dagger", "hg-dagger", "novelty"]


@pytest.mark.parametrize("make", _SHIPPED, ids=_SHIPPED_IDS)
def test_observe_label_refuses_an_unknown_kind_or_an_action_out_of_range(make):
    """A loop of one's own that passed kind="demo" kept confident execution in its
    non-interactive phase for ever (only "demonstration" was counted), and a label outside
    [0, n_actions) was taken; every shipped strategy now refuses both, saying what it takes."""
    s = make()
    s.bind(n_actions=3, n_features=1, config=TeachingConfig(accuracy_window=2))
    x = np.zeros(1)
    for kind in ("demo", "Demonstration", None):
        with pytest.raises(ValueError, match=r"kind: expected one of .*'demonstration'.*got"):
            s.observe_label(x, 1, model_action=1, kind=kind)
    for action in (-1, 3, np.int64(7), 1.5, True):
        with pytest.raises(ValueError, match=r"action: expected an int in \[0, 3\)"):
            s.observe_label(x, action, model_action=1, kind="demonstration")
    s.observe_label(x, np.int64(2), model_action=1, kind="demonstration")
    s.observe_label(x, 0, model_action=1, kind="correction")


@pytest.mark.parametrize(
    "make",
    [
        ConfidentExecution,
        ConfidenceBasedAutonomy,
        lambda: HGDAgger(warmup=0),
        lambda: NoveltyGated(warmup=0, min_history=1),
    ],
    ids=["ce", "cba", "hg-dagger", "novelty"],
)
def test_decide_refuses_an_observation_that_is_not_one_d_vector_or_a_batch_of_c(make):
    """In a loop of one's own, decide(obs [1, D], c) failed inside numpy for CBA ('matmul:
    Input operand 1 has a mismatch') and was taken by confident execution; a wrong D gave a
    Decision (CE) or a broadcast error (CBA); a c of 2 rows was read as its row 0 (also by
    HG-DAgger and the novelty gate, which read c's first row)."""
    from torchcbl import GaussianMixtureSet

    x = np.array([[0.0, 0.0], [0.1, 0.0], [3.0, 3.0], [3.1, 3.0]])
    y = np.array([0, 0, 1, 1])
    model = GaussianMixtureSet(2, 2, max_components=1).fit(x, y)
    s = make()
    s.bind(n_actions=2, n_features=2, config=TeachingConfig(noninteractive=False))
    s.observe_refit(model, x, y)
    c = model.classify(x[:1])
    assert isinstance(s.decide(x[0], c), Decision)
    for obs in (x[:1], x[0, :1], np.zeros(3)):
        shape = re.escape(str(obs.shape))
        with pytest.raises(
            ValueError, match=rf"expected one observation of shape \(2,\), got shape {shape}"
        ):
            s.decide(obs, c)
    with pytest.raises(ValueError, match=r"decide: expected c of batch 1 .* got a batch of 2"):
        s.decide(x[0], model.classify(x[:2]))
