"""The baselines (BC, DAgger, HG-DAgger, novelty-gated) against hand-computable cases."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from _toy_envs import four_d_world, oracle, rare_regions_world

from torchcbl import ConfidentTeacher, GaussianMixtureSet, TeachingConfig, evaluate_policy
from torchcbl.gmm import Classification
from torchcbl.records import StepRecord
from torchcbl.strategies import correcting, strategy_from_config
from torchcbl.strategies.bc import BehaviourCloning
from torchcbl.strategies.dagger import DAgger
from torchcbl.strategies.hg_dagger import HGDAgger
from torchcbl.strategies.novelty import NoveltyGated


def _teach(env, strategy, steps, *, teacher=None, max_new=1, run_dir=None, seed=3):
    ct = ConfidentTeacher(
        env,
        teacher or oracle(env),
        strategy=strategy,
        model=GaussianMixtureSet(env.action_space.n, env.observation_space.shape[0], 3, seed=0),
        config=TeachingConfig(max_new=max_new),
        run_dir=run_dir,
        seed=seed,
        progress=False,
    )
    ct.run(max_steps=steps)
    return ct


def _classification(action: int, distance: float) -> Classification:
    d = torch.tensor([distance], dtype=torch.float64)
    return Classification(
        torch.tensor([action]), torch.exp(-(d**2) / 2), d, torch.full((1, 3), 1 / 3)
    )


def _driven(step: int, distance: float, actor: str, phase: str = "confident") -> StepRecord:
    """A step the teacher (labelled, its label executed) or the learner drove."""
    teacher = actor == "teacher"
    return StepRecord(
        step=step,
        episode=0,
        observation=(float(step), 0.0),
        model_action=0,
        confidence=None,
        distance=distance,
        posterior=None,
        teacher_action=1 if teacher else None,
        executed_action=1 if teacher else 0,
        phase=phase,
        autonomous=not teacher,
        reward=0.0,
        terminated=False,
        truncated=False,
        info={},
        actor=actor,
    )


def _record(step: int, distance: float) -> StepRecord:
    """A step the learner drove in the confident phase."""
    return _driven(step, distance, "agent")


# -- behaviour cloning ---------------------------------------------------------------------------


def test_bc_learns_exactly_the_teachers_own_trajectory():
    env = four_d_world(episode_length=15)
    ct = _teach(env, BehaviourCloning(), 45, max_new=5)
    # The teacher rolled out alone from the same reset seed visits the same states.
    alone = evaluate_policy(oracle(env), env, n_steps=45, seed=3, uses_info=True)
    assert [r.observation for r in ct.records] == [r.observation for r in alone]
    assert all(r.actor == "teacher" and r.teacher_action is not None for r in ct.records)
    assert [r.executed_action for r in ct.records] == [r.executed_action for r in alone]
    # ... and the model is the GMM set fitted on that trajectory and its labels.
    ref = GaussianMixtureSet(3, 4, 3, seed=0)
    ref.fit(np.array([r.observation for r in alone]), np.array([r.executed_action for r in alone]))
    assert torch.equal(ct.model.means_, ref.means_)
    assert torch.equal(ct.model.covariances_, ref.covariances_)


# -- DAgger --------------------------------------------------------------------------------------


def test_dagger_with_beta_one_is_behaviour_cloning():
    env = four_d_world(episode_length=15)
    bc = _teach(env, BehaviourCloning(), 45, max_new=5)
    env2 = four_d_world(episode_length=15)
    dg = _teach(env2, DAgger(beta0=1.0, decay=1.0, iteration_steps=7, seed=11), 45, max_new=5)
    assert [(r.observation, r.teacher_action, r.executed_action) for r in dg.records] == [
        (r.observation, r.teacher_action, r.executed_action) for r in bc.records
    ]
    assert all(r.actor == "teacher" for r in dg.records)
    for k, v in bc.model.state_dict().items():
        assert torch.equal(v, dg.model.state_dict()[k]), k


def test_dagger_beta_schedule_and_coins_by_hand():
    d = DAgger(beta0=0.8, decay=0.5, iteration_steps=10, seed=4)
    assert [d.beta(t) for t in (0, 9, 10, 19, 20, 35)] == [0.8, 0.8, 0.4, 0.4, 0.2, 0.1]
    coin = np.random.default_rng(np.random.SeedSequence([4, 17])).random()
    assert d.coin(17) == coin
    # actor: the teacher's action iff coin < beta; always the teacher's before any model
    from torchcbl.strategies import Decision

    for t in range(40):
        want = "teacher" if d.coin(t) < d.beta(t) else "agent"
        assert d.actor(Decision(True, "noninteractive", t), 1, 2) == want
        assert d.actor(Decision(True, "noninteractive", t), -1, 2) == "teacher"


def test_dagger_labels_every_state_and_executes_by_coin():
    env = rare_regions_world(episode_length=10)
    s = DAgger(beta0=1.0, decay=0.5, iteration_steps=10, seed=2)
    ct = _teach(env, s, 50, max_new=5)
    assert all(r.teacher_action is not None for r in ct.records)  # every state labelled
    assert ct.n_demonstrations == 50
    for r in ct.records:
        teacher_acts = r.model_action < 0 or s.coin(r.step) < s.beta(r.step)
        assert r.actor == ("teacher" if teacher_acts else "agent"), r.step
        assert r.executed_action == (r.teacher_action if teacher_acts else r.model_action)
    assert {r.actor for r in ct.records[30:]} == {"teacher", "agent"}  # beta 0.125 .. 0.0625


def test_dagger_resumes_with_the_same_coins(tmp_path):
    env = rare_regions_world(episode_length=10)
    s = DAgger(decay=0.5, iteration_steps=5, seed=1)
    part = _teach(env, s, 12, max_new=4, run_dir=tmp_path / "b")
    part.close()
    env3 = rare_regions_world(episode_length=10)
    assert part.strategy._steps == 12
    resumed = ConfidentTeacher.resume(tmp_path / "b", env3, oracle(env3), progress=False)
    assert isinstance(resumed.strategy, DAgger)  # rebuilt from the run directory
    assert resumed.strategy._steps == 12 and resumed.strategy.to_config() == s.to_config()
    resumed.run(max_steps=30)
    # the resumed env starts a new episode, so states differ; the coins follow the step index
    for r in resumed.records[12:]:
        s = resumed.strategy
        teacher_acts = r.model_action < 0 or s.coin(r.step) < s.beta(r.step)
        assert r.actor == ("teacher" if teacher_acts else "agent")


# -- HG-DAgger -----------------------------------------------------------------------------------


def test_hg_dagger_state_machine_by_hand():
    s = HGDAgger(warmup=2)
    c = _classification(0, 1.0)
    assert s.decide(np.zeros(2), c).ask  # warm-up
    s.observe_label(np.zeros(2), 1, model_action=-1, kind="demonstration")
    s.observe_label(np.zeros(2), 1, model_action=0, kind="demonstration")
    assert s.decide(np.zeros(2), c) == (False, "confident", None)  # the learner drives
    assert s.decide(np.zeros(2), _classification(-1, np.inf)).ask  # no model: ask
    s.observe_label(np.zeros(2), 2, model_action=0, kind="correction")  # the teacher takes over
    assert s.teacher_in_control and s.decide(np.zeros(2), c).ask
    s.observe_label(np.zeros(2), 2, model_action=0, kind="demonstration")  # still disagree
    assert s.teacher_in_control
    s.observe_label(np.zeros(2), 2, model_action=2, kind="demonstration")  # agree: hand back
    assert not s.teacher_in_control and not s.decide(np.zeros(2), c).ask


def test_hg_dagger_labels_only_corrections_and_takeovers():
    env = rare_regions_world(episode_length=10, spread=2.0)
    s = HGDAgger(warmup=3)
    ct = _teach(env, s, 200, teacher=correcting(oracle(env)))
    recs, corr = ct.records, ct.corrections
    assert ct.n_corrections > 0
    by_step = {c.step: c for c in corr}
    for r in recs[3:]:
        right = env.optimal_action(r.observation_array)
        if r.autonomous:
            # the gate: a correction exactly where the learner's executed action was wrong
            assert (r.step in by_step) == (r.executed_action != right)
        else:
            assert r.actor == "teacher" and r.executed_action == right
    # every takeover starts right after a correction and lasts until the learner agreed
    for r in recs[4:]:
        if not r.autonomous:
            prev = recs[r.step - 1]
            assert prev.step in by_step or (
                not prev.autonomous and prev.model_action != prev.teacher_action
            )
    assert ct.n_demonstrations == sum(1 for r in recs if not r.autonomous) + len(corr)


def test_hg_dagger_with_a_teacher_that_cannot_correct_says_so():
    env = rare_regions_world(episode_length=10, spread=2.0)
    with pytest.warns(UserWarning, match=r"never correct one.*correcting\(teacher\)"):
        _teach(env, HGDAgger(warmup=3), 5)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _teach(env, HGDAgger(warmup=3), 5, teacher=correcting(oracle(env)))
        _teach(env, DAgger(), 5)  # asks no corrections: nothing to say


# -- novelty-gated (ThriftyDAgger style) ---------------------------------------------------------


def test_novelty_threshold_is_the_quantile_of_recent_scores_by_hand():
    s = NoveltyGated(target_rate=0.1, window=20, warmup=0, min_history=5)
    for t in range(4):
        s.observe_step(_record(t, float(t + 1)), None)
    assert s.threshold() is None and s.decide(np.zeros(2), _classification(0, 0.0)).ask
    for t in range(4, 20):
        s.observe_step(_record(t, float(t + 1)), None)
    # scores 1..20: linear 0.9 quantile at position 0.9 * 19 = 17.1 -> 18 + 0.1 = 18.1
    assert s.threshold() == pytest.approx(18.1)
    assert s.decide(np.zeros(2), _classification(0, 18.2)).ask
    assert not s.decide(np.zeros(2), _classification(0, 18.0)).ask
    assert s.decide(np.zeros(2), _classification(-1, 0.0)).ask  # no model yet
    for t in range(20, 30):  # the window slides: scores 11..30 -> 28.1
        s.observe_step(_record(t, float(t + 1)), None)
    assert s.threshold() == pytest.approx(28.1)
    s.observe_step(_record(30, float("inf")), None)  # non-finite scores are not kept
    assert s.threshold() == pytest.approx(28.1)


def test_novelty_rescores_recent_states_with_the_new_model():
    class Model:
        def classify(self, x):
            return _classification(0, 0.0)._replace(
                distance=torch.as_tensor(np.asarray(x)[:, 0] * 0 + 0.5, dtype=torch.float64)
            )

    s = NoveltyGated(target_rate=0.5, window=4, warmup=0, min_history=1)
    for t in range(4):
        s.observe_step(_record(t, 10.0 + t), None)
    assert s.threshold() == pytest.approx(11.5)
    s.observe_refit(Model(), np.zeros((1, 2)), np.zeros(1))
    assert s.threshold() == pytest.approx(0.5)  # every recent state scored by the new model
    s.observe_step(_record(4, 99.0), None)  # the refit's own step: rescored too
    assert list(s._scores) == [0.5] * 4


def test_novelty_scores_from_agent_takes_the_quantile_over_the_steps_the_learner_drove():
    """ThriftyDAgger's code adds a novelty score only while the robot drives; the shipped gate
    ("all") adds every step's, the asked ones included. With scores_from="agent" the window
    keeps the warm-up's steps (ThriftyDAgger seeds from offline data), the steps the learner
    drove, and an asked step only while it holds fewer than min_history observations (the
    gate asks while the history is short: it would never fill it otherwise)."""
    steps = [  # (distance, actor, phase)
        (1.0, "teacher", "noninteractive"),  # the warm-up: kept
        (2.0, "teacher", "noninteractive"),
        (50.0, "teacher", "confident"),  # asked, 2 < min_history observations: kept
        (3.0, "agent", "confident"),
        (40.0, "teacher", "confident"),  # asked, 3 observations: not kept
        (4.0, "agent", "confident"),
        (30.0, "teacher", "confident"),  # not kept
        (5.0, "agent", "confident"),
    ]
    gates = {
        how: NoveltyGated(target_rate=0.25, window=10, warmup=2, min_history=3, scores_from=how)
        for how in ("all", "agent")
    }
    for s in gates.values():
        for t, (d, actor, phase) in enumerate(steps):
            if actor == "teacher":
                s.observe_label(np.zeros(2), 1, model_action=0, kind="demonstration")
            s.observe_step(_driven(t, d, actor, phase), None)
    # agent: 1, 2, 3, 4, 5, 50 -> position 0.75 * 5 = 3.75 -> 4 + 0.75 * (5 - 4) = 4.75
    assert gates["agent"].threshold() == pytest.approx(4.75)
    # all: 1, 2, 3, 4, 5, 30, 40, 50 -> position 0.75 * 7 = 5.25 -> 30 + 0.25 * 10 = 32.5
    assert gates["all"].threshold() == pytest.approx(32.5)
    assert gates["agent"].decide(np.zeros(2), _classification(0, 10.0)).ask
    assert not gates["all"].decide(np.zeros(2), _classification(0, 10.0)).ask

    class Model:  # scores an observation by its first feature (the step index)
        def classify(self, x):
            d = torch.as_tensor(np.asarray(x)[:, 0], dtype=torch.float64)
            return _classification(0, 0.0)._replace(distance=d)

    for s in gates.values():  # the refit rescores the window's observations, and only those
        s.observe_refit(Model(), np.zeros((1, 2)), np.zeros(1))
    # agent: steps 0, 1, 2, 3, 5, 7 -> 3 + 0.75 * (5 - 3) = 4.5; all: 0..7 -> 5.25
    assert gates["agent"].threshold() == pytest.approx(4.5)
    assert gates["all"].threshold() == pytest.approx(5.25)


def test_novelty_scores_from_is_checked_and_kept_in_the_config():
    for bad in ("robot", "Agent", None, 1):
        with pytest.raises(ValueError, match=r"scores_from must be one of \('all', 'agent'\)"):
            NoveltyGated(scores_from=bad)
    assert NoveltyGated().to_config()["scores_from"] == "all"
    s = strategy_from_config(NoveltyGated(scores_from="agent").to_config())
    assert s.scores_from == "agent" and "scores_from='agent'" in repr(s)


@pytest.mark.parametrize("how", ["all", "agent"])
def test_novelty_threshold_in_a_session_is_the_quantile_of_the_kept_steps(tmp_path, how):
    """Live and resumed, the threshold is the (1 - target_rate) quantile of the final model's
    scores of the window's steps: the last ``window`` steps ("all"), or of those the learner
    drove, after the first ``min_history`` ("agent"); with warmup=0 the gate asks until it has
    them, and then lets the learner drive."""
    env = rare_regions_world(episode_length=10, spread=1.5)
    s = NoveltyGated(target_rate=0.2, window=30, warmup=0, min_history=5, scores_from=how)
    ct = _teach(env, s, 80, run_dir=tmp_path / "r")
    kept = []
    for r in ct.records:
        if how == "all" or r.actor == "agent" or len(kept) < 5:
            kept.append(r.observation_array)
    assert len(kept) > 30 and any(r.actor == "agent" for r in ct.records)
    d = ct.model.classify(np.stack(kept[-30:])).distance.numpy()
    want = np.quantile(d[np.isfinite(d)], 0.8)
    assert s.threshold() == pytest.approx(want)
    ct.close()
    again = ConfidentTeacher.resume(tmp_path / "r", env, oracle(env), progress=False)
    assert again.strategy.to_config() == s.to_config()  # rebuilt from the run directory
    assert again.strategy.threshold() == pytest.approx(want)
    again.close()


def test_a_novelty_session_stored_without_scores_from_resumes_as_all(tmp_path):
    """Sessions stored before NoveltyGated took scores_from lack the key in config.json; they
    taught with every step's score, so they read as "all": rebuilt so, resumed by a
    NoveltyGated() given, and refused to one given scores_from="agent", as any other setting
    of the strategy that differs."""
    import json

    from torchcbl.errors import IncompatibleRunDirError

    env = rare_regions_world(episode_length=10)
    _teach(env, NoveltyGated(warmup=3, min_history=3), 12, run_dir=tmp_path / "r").close()
    path = tmp_path / "r" / "config.json"
    config = json.loads(path.read_text())
    assert config["strategy"].pop("scores_from") == "all"
    path.write_text(json.dumps(config))
    ct = ConfidentTeacher.resume(tmp_path / "r", env, oracle(env), progress=False)
    assert ct.strategy.scores_from == "all"
    ct.close()
    given = NoveltyGated(warmup=3, min_history=3)
    ConfidentTeacher.resume(
        tmp_path / "r", env, oracle(env), strategy=given, progress=False
    ).close()
    with pytest.raises(IncompatibleRunDirError, match=r"strategy: stored .*'scores_from': 'all'"):
        ConfidentTeacher.resume(
            tmp_path / "r",
            env,
            oracle(env),
            strategy=NoveltyGated(warmup=3, min_history=3, scores_from="agent"),
            progress=False,
        )


def test_novelty_asks_about_its_target_rate_after_warmup():
    env = rare_regions_world(episode_length=20, spread=1.5)
    s = NoveltyGated(target_rate=0.2, window=100, warmup=10, min_history=10)
    ct = _teach(env, s, 300, max_new=5)
    asked = np.mean([not r.autonomous for r in ct.records[100:]])
    assert 0.1 <= asked <= 0.3, asked
    assert all(r.executed_action == r.teacher_action for r in ct.records if not r.autonomous)


def test_baselines_roundtrip_through_their_config():
    for s in (
        BehaviourCloning(),
        DAgger(beta0=0.9, decay=0.7, iteration_steps=3, seed=5),
        HGDAgger(warmup=4),
        NoveltyGated(target_rate=0.05, window=50, warmup=2, min_history=7),
        NoveltyGated(min_history=3, scores_from="agent"),
    ):
        again = strategy_from_config(s.to_config())
        assert type(again) is type(s) and again.to_config() == s.to_config()


@pytest.mark.parametrize(
    "make",
    [
        lambda: DAgger(beta0=1.5),
        lambda: DAgger(iteration_steps=0),
        lambda: HGDAgger(warmup=-1),
        lambda: NoveltyGated(target_rate=1.0),
        lambda: NoveltyGated(window=0),
    ],
)
def test_baselines_reject_bad_settings(make):
    with pytest.raises(ValueError, match="must be"):
        make()


def test_numpy_scalar_arguments_are_taken_as_the_python_numbers_they_hold():
    """np.int64 / np.float32 arguments (a sweep over np.arange) were refused with a message
    that contradicted itself ("window must be an int >= 1, got np.int64(100)", before
    2026-11-27); they are stored as Python numbers, so to_config stays JSON."""
    import json

    from torchcbl.strategies.cba import ConfidenceBasedAutonomy

    built = [
        DAgger(beta0=np.float32(0.5), decay=np.float64(0.25), iteration_steps=np.int64(7),
               seed=np.uint8(3)),
        HGDAgger(warmup=np.int32(4)),
        NoveltyGated(target_rate=np.float32(0.25), window=np.int64(50), warmup=np.int64(2),
                     min_history=np.int16(5)),
        ConfidenceBasedAutonomy(distance_multiplier=np.float32(2.0),
                                clean_threshold=np.int64(0)),
    ]  # fmt: skip
    for s in built:
        config = s.to_config()
        assert all(type(v) in (int, float, str, bool) for v in config.values()), config
        assert strategy_from_config(json.loads(json.dumps(config))).to_config() == config
    assert built[0].iteration_steps == 7 and built[2].window == 50
    for bad in (lambda: HGDAgger(warmup=np.bool_(True)), lambda: DAgger(beta0=np.float32(2))):
        with pytest.raises(ValueError):
            bad()


@pytest.mark.parametrize(
    "make",
    [BehaviourCloning, DAgger, lambda: HGDAgger(warmup=5), lambda: NoveltyGated(warmup=5)],
    ids=["bc", "dagger", "hg_dagger", "novelty"],
)
def test_the_loops_phase_is_the_phase_of_the_next_step_for_every_baseline(make):
    """ConfidentTeacher.phase (and the progress bar) reads the strategy's phase; the baselines
    had none, so it said "confident" while BC and DAgger recorded every step, and HG-DAgger and
    the novelty gate their warmup, as "noninteractive"."""
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        env,
        correcting(oracle(env)),
        strategy=make(),
        config=TeachingConfig(max_new=1),
        progress=False,
    )
    said = []
    for _ in range(30):
        before = ct.phase
        said.append((before, ct.step().phase))
    assert all(before == recorded for before, recorded in said), said
