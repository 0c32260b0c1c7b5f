"""Confidence-Based Autonomy, corrections and the chi-square distance rule.

The acceptance runs use a 6-D world with overlapping actions and a known (optimal) teacher;
every method gets the same env, teacher, model and TeachingConfig, and the same seeds (the
first two).
"""

from __future__ import annotations

import contextlib
import math

import numpy as np
import pytest
import torch
from _toy_envs import ClusterWorld, oracle, rare_regions_world, six_d_world

from torchcbl import ConfidentTeacher, DistanceRule, GaussianMixtureSet, TeachingConfig
from torchcbl.confidence import chi2_quantile
from torchcbl.policy import GreedyPolicy, evaluate_policy
from torchcbl.session import load_corrections, load_demonstrations, load_labels, load_model
from torchcbl.strategies import correcting
from torchcbl.strategies.cba import ConfidenceBasedAutonomy, loo_nn_distances, posterior_margin


def test_chi2_quantile_matches_scipy_and_the_dimension_argument():
    stats = pytest.importorskip("scipy.stats")
    for q, d in [(0.95, 6), (0.5, 1), (0.999, 20), (0.01, 3), (0.95, 2), (1e-9, 3), (1e-6, 1)]:
        # relative precision also where the quantile is far below 1
        assert chi2_quantile(q, d) == pytest.approx(stats.chi2.ppf(q, d), rel=1e-11)
    # the numbers: P(within 2 std) of a Gaussian's own points, 2-D / 4-D / 6-D
    coverage = [
        float(torch.special.gammainc(torch.tensor(d / 2.0), torch.tensor(2.0))) for d in (2, 4, 6)
    ]
    assert coverage == pytest.approx([0.8647, 0.5940, 0.3233], abs=1e-4)
    rule = DistanceRule(quantile=0.95)
    assert rule.threshold(6) == pytest.approx(math.sqrt(stats.chi2.ppf(0.95, 6)))
    assert rule.to_config() == {"type": "DistanceRule", "quantile": 0.95}
    for max_std in (3.0, 2.0):  # the paper's value given is given too
        with pytest.raises(ValueError, match="not both"):
            DistanceRule(max_std, quantile=0.9)
    assert DistanceRule(quantile=np.float32(0.95)).quantile == pytest.approx(0.95)
    from torchcbl.confidence import AutoThresholdRule
    from torchcbl.strategies.cba import posterior_margin

    with pytest.raises(ValueError, match="AutoThresholdRule.min_std"):
        AutoThresholdRule(min_std="1.0")
    with pytest.raises(ValueError, match="A >= 2 actions"):
        posterior_margin(np.ones((3, 1)))
    for bad in (1.0, 95, 0.0, float("nan"), True):  # a share, not a percentage
        with pytest.raises(ValueError, match=r"expected a share in \(0, 1\) \(e.g. 0.95"):
            DistanceRule(quantile=bad)


def test_chi2_rule_is_confident_on_the_quantile_share_of_own_points():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((4000, 6))
    model = GaussianMixtureSet(1, 6, max_components=1).fit(x[:2000], np.zeros(2000, dtype=int))
    c = model.classify(x[2000:])
    share95 = DistanceRule(quantile=0.95).is_confident(c, x[2000:]).double().mean()
    share2std = DistanceRule(2.0).is_confident(c).double().mean()
    assert float(share95) == pytest.approx(0.95, abs=0.02)
    assert float(share2std) == pytest.approx(0.32, abs=0.03)


def test_posterior_margin_and_loo_distances_by_hand():
    chosen, runner, margin = posterior_margin(np.array([[0.7, 0.2, 0.1], [0.0, 0.0, 1.0]]))
    assert chosen.tolist() == [0, 2] and runner.tolist() == [1, 0]
    assert margin[0] == pytest.approx(math.log(3.5)) and margin[1] == math.inf
    d = loo_nn_distances(np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 5.0]]))
    assert d.tolist() == pytest.approx([5.0, 1.0, 1.0])


def test_nearest_neighbour_distances_of_a_long_session_are_taken_in_blocks():
    # beyond 2048 points the distance matrix is formed a block of rows at a time (memory);
    # the distances are the brute-force ones, duplicates (distance 0) included
    x = np.random.default_rng(0).normal(size=(2600, 3))
    x[2599] = x[7]
    diff = x[:, None, :] - x[None, :, :]
    brute = np.sqrt((diff * diff).sum(-1))
    np.fill_diagonal(brute, np.inf)
    np.testing.assert_allclose(loo_nn_distances(x), brute.min(1), rtol=0, atol=1e-9)


class _Fixed:
    """A model whose classification is given by hand (posterior per observation's x[0])."""

    def __init__(self, table):
        self.table = table

    def classify(self, x):
        from torchcbl.gmm import Classification

        post = torch.tensor([self.table[int(v)] for v in np.asarray(x)[:, 0]], dtype=torch.float64)
        n = len(post)
        return Classification(post.argmax(1), torch.ones(n), torch.zeros(n), post)


def test_per_boundary_thresholds_by_hand():
    cba = ConfidenceBasedAutonomy(distance_multiplier=1.5, clean_threshold=0.25)
    cba.bind(n_actions=3, n_features=2, config=TeachingConfig(noninteractive=False))
    table = {
        0: [0.8, 0.2, 0.0],  # predicted 0, runner-up 1, margin log 4
        1: [0.6, 0.4, 0.0],  # predicted 0, runner-up 1, margin log 1.5
        2: [0.1, 0.9, 0.0],  # predicted 1, runner-up 0, margin log 9
        3: [0.1, 0.0, 0.9],  # predicted 2, runner-up 0, margin log 9
    }
    x = np.array([[0, 0], [0, 1], [1, 0], [2, 0], [3, 0]], dtype=np.float64)
    # mistakes: point 0 (label 1, predicted 0 over 1) and point 2 (label 1, predicted 0 over 1)
    y = np.array([1, 0, 1, 1, 2])
    cba.observe_refit(_Fixed(table), x, y)
    t = cba.thresholds
    assert t[0, 1] == pytest.approx((math.log(4) + math.log(1.5)) / 2)  # mean of the mistakes
    assert t[1, 0] == 0.25 and t[2, 0] == 0.25  # classified there, never wrong: clean value
    assert t[0, 2] == math.inf and t[1, 2] == math.inf  # never seen: ask
    z = (x - x.mean(0)) / x.std(0)
    assert cba.distance_threshold == pytest.approx(1.5 * loo_nn_distances(z).mean())
    assert not np.isnan(t).any()


def _bound_cba() -> ConfidenceBasedAutonomy:
    cba = ConfidenceBasedAutonomy()  # clean_threshold 0
    cba.bind(n_actions=2, n_features=2, config=TeachingConfig(noninteractive=False))
    return cba


def _classified(model: _Fixed, observation) -> tuple[np.ndarray, object]:
    obs = np.asarray(observation, dtype=np.float64)
    return obs, model.classify(obs[None])


def test_a_confidently_wrong_boundary_is_never_trusted():
    """A demonstration the model gets wrong with posterior 1 against 0 (an infinite margin)
    makes that boundary's threshold +inf: the agent asks at every observation predicted there,
    however large its margin, where a finite mean of the other mistakes (or the clean value 0)
    would trust an infinite margin at once."""
    cba = _bound_cba()
    # by x[0]: certain of 0; certain of 1; 0 over 1 by a finite margin (log 1.5)
    model = _Fixed({0: [1.0, 0.0], 1: [0.0, 1.0], 2: [0.6, 0.4]})
    x = np.array([[0, 0], [0, 1], [1, 0], [1, 1], [2, 0]], dtype=np.float64)
    # (0, 0) is labelled 1 but predicted 0 over 1 with an infinite margin; (2, 0) is the
    # same mistake by a finite margin
    y = np.array([1, 0, 1, 1, 1])
    cba.observe_refit(model, x, y)
    assert cba.thresholds[0, 1] == math.inf
    assert cba.thresholds[1, 0] == 0.0  # predicted 1 over 0, never wrong: the clean value
    # on a stored point (the distance gate passes), certain of 0: it asks; certain of 1: not
    assert cba.decide(*_classified(model, [0.0, 0.0])).ask
    assert not cba.decide(*_classified(model, [1.0, 0.0])).ask


@pytest.mark.parametrize("stored", [1, 2])
def test_a_zero_distance_gate_asks_even_on_a_stored_point(stored):
    """With one demonstration, or two identical ones, the distance gate is 0 (no spread to
    measure), and the comparison is strict: an observation exactly on the stored point
    (distance 0) still asks, though its margin passes."""
    cba = _bound_cba()
    model = _Fixed({0: [0.9, 0.1]})
    x = np.zeros((stored, 2))
    cba.observe_refit(model, x, np.zeros(stored, dtype=int))
    assert cba.distance_threshold == 0.0 and cba.thresholds[0, 1] == 0.0
    obs, c = _classified(model, [0.0, 0.0])
    assert cba.nn_distance(obs) == 0.0
    assert cba.decide(obs, c).ask


def test_demonstration_in_a_stored_state_relabels_it(tmp_path):
    class Discrete(ClusterWorld):  # 4 distinct states only
        def _draw(self):
            self._obs = self.centers[int(self.np_random.integers(4))].astype(np.float32)
            return self._obs.copy()

    env = Discrete([[0, 0], [5, 0], [0, 5], [5, 5]], [0, 1, 2, 0], [1, 1, 1, 1], episode_length=10)
    flips = {"n": 0}

    def fickle(obs, info):  # changes its mind about state (0, 0) after 6 labels
        flips["n"] += 1
        return 1 if flips["n"] > 6 and not obs.any() else env.optimal_action(obs)

    with pytest.warns(UserWarning, match="never correct"):  # demonstrations only, here
        ct = ConfidentTeacher(
            env,
            fickle,
            strategy=ConfidenceBasedAutonomy(),
            config=TeachingConfig(max_new=1, target_accuracy=None),
            model=GaussianMixtureSet(3, 2, max_components=1),
            run_dir=tmp_path / "run",
            progress=False,
        )
    ct.run(max_steps=30)
    ct.close()
    x, y = load_demonstrations(tmp_path / "run")
    assert len(y) == 4 and ct.n_demonstrations == 30  # 30 labels, 4 distinct states
    assert y[np.all(x == 0, axis=1)].tolist() == [1]  # the latest label of (0, 0) won
    assert len(load_labels(tmp_path / "run")[1]) == 30


def test_correction_relabels_the_decision_time_state_and_is_durable(tmp_path):
    env = rare_regions_world(episode_length=10)
    calls = []

    class Corrector:
        def __call__(self, obs, info):
            return env.optimal_action(obs)

        def correct(self, obs, info, action):
            calls.append((obs.copy(), action))
            return (action + 1) % 3 if len(calls) % 7 == 0 else None

    ct = ConfidentTeacher(
        env,
        Corrector(),
        strategy=ConfidenceBasedAutonomy(),
        config=TeachingConfig(max_new=3, noninteractive=False),
        run_dir=tmp_path / "run",
        progress=False,
    )
    ct.run(max_steps=300)
    corrections = ct.corrections
    assert corrections and len(calls) == sum(r.autonomous for r in ct.records)
    by_step = {r.step: r for r in ct.records}
    for corr in corrections:
        r = by_step[corr.step]
        assert r.autonomous and corr.observation == r.observation  # the state at decision time
        assert corr.executed_action == r.executed_action and corr.action != r.executed_action
    assert load_corrections(tmp_path / "run") == corrections  # on disk before close
    n_demo = sum(r.teacher_action is not None for r in ct.records)
    assert ct.n_demonstrations == n_demo + len(corrections)
    ct.close()
    back = ConfidentTeacher.resume(tmp_path / "run", env, Corrector(), progress=False)
    assert back.corrections == corrections and back.n_demonstrations == ct.n_demonstrations
    assert isinstance(back.strategy, ConfidenceBasedAutonomy)
    np.testing.assert_array_equal(back.strategy.thresholds, ct.strategy.thresholds)
    assert back.strategy.distance_threshold == ct.strategy.distance_threshold
    fresh = load_model(tmp_path / "run")
    x = np.random.default_rng(0).normal(size=(50, 2)) * 4
    assert torch.equal(fresh.classify(x).action, ct.model.classify(x).action)
    back.close()


# -- acceptance on the 6-D world -------------------------------------------------------------

STEPS = 2000


def _teach(strategy=None, rule=None, *, corrections=False, seed=0, steps=STEPS):
    env = six_d_world(episode_length=50)
    teacher = correcting(oracle(env)) if corrections else oracle(env)
    wants = bool(getattr(strategy, "wants_corrections", False)) and not corrections
    with pytest.warns(UserWarning, match="never correct") if wants else contextlib.nullcontext():
        ct = ConfidentTeacher(
            env,
            teacher,
            strategy=strategy,
            rule=rule,
            model=GaussianMixtureSet(3, 6, max_components=3, seed=seed),
            config=TeachingConfig(max_new=10, accuracy_window=20, target_accuracy=0.9),
            seed=seed,
            progress=False,
        )
    ct.run(max_steps=steps)
    ct.refit()
    recs = ct.records
    demos = sum(r.teacher_action is not None for r in recs) / len(recs)
    wrong = sum(
        r.autonomous and r.executed_action != env.optimal_action(r.observation) for r in recs
    )
    test_env = six_d_world(episode_length=50)
    got = evaluate_policy(GreedyPolicy(ct.model), test_env, n_episodes=20, seed=10_000 + seed)
    want = evaluate_policy(
        oracle(test_env), test_env, n_episodes=20, seed=10_000 + seed, uses_info=True
    )
    ratio = sum(r.reward for r in got) / sum(r.reward for r in want)
    return {"demos": demos, "return_ratio": ratio, "wrong_autonomous": wrong, "ct": ct}


@pytest.mark.parametrize("seed", [0, 1])
def test_6d_cba_and_chi2_rule_reach_the_teacher_with_few_demonstrations(seed):
    chi2 = _teach(rule=DistanceRule(quantile=0.95), seed=seed)
    cba = _teach(strategy=ConfidenceBasedAutonomy(), corrections=True, seed=seed)
    for name, r in (("chi2", chi2), ("cba", cba)):
        assert r["return_ratio"] >= 0.95, (name, r)
        assert r["demos"] < 0.30, (name, r)
        assert r["ct"].n_demonstrations < 0.30 * STEPS, (name, r)  # corrections counted too
    assert cba["ct"].n_corrections > 0


def test_6d_fixed_two_std_rule_keeps_asking():
    r = _teach(rule=DistanceRule(2.0), steps=1000)
    assert r["demos"] > 0.40, r  # ~0.68: only 32 % of a 6-D Gaussian lies within 2 std


def test_a_run_that_ends_on_a_correction_has_refitted_on_it():
    """With max_new=1 every label is due a refit at once, a correction's included: a
    run(max_steps=...) that ends on the step of a correction leaves the model fitted on
    every label (on_refit's count is the session's), not one short until the next step."""
    env = rare_regions_world(episode_length=10)

    class Corrector:
        def __call__(self, obs, info):
            return env.optimal_action(obs)

        def correct(self, obs, info, action):
            return (action + 1) % 3  # every autonomous action is corrected

    fitted_on = []
    ct = ConfidentTeacher(
        env,
        Corrector(),
        strategy=ConfidenceBasedAutonomy(),
        config=TeachingConfig(max_new=1, noninteractive=False),
        progress=False,
        on_refit=lambda model, n: fitted_on.append(n),
    )
    while ct.n_corrections < 3 and ct.n_steps < 200:
        before = ct.n_corrections
        ct.run(max_steps=ct.n_steps + 1)  # one step; the run ends after it
        if ct.n_corrections > before:
            assert fitted_on[-1] == ct.n_demonstrations, (ct.n_steps, fitted_on[-3:])
    assert ct.n_corrections == 3


@pytest.mark.parametrize("seed", [0, 1])
def test_6d_corrections_mean_fewer_wrong_autonomous_actions(seed):
    with_c = _teach(strategy=ConfidenceBasedAutonomy(), corrections=True, seed=seed)
    without = _teach(strategy=ConfidenceBasedAutonomy(), corrections=False, seed=seed)
    assert with_c["return_ratio"] >= 0.95, with_c
    assert with_c["wrong_autonomous"] < without["wrong_autonomous"], (with_c, without)


def test_a_correction_survives_sigkill_like_a_demonstration(tmp_path):
    import random

    from _toy_envs import check_corrections_kept
    from test_session import _check_nothing_lost, _kill_cycle

    run = tmp_path / "run"
    rng = random.Random(3)
    counts = []
    for i in range(2):
        side = tmp_path / f"side{i}.log"
        _kill_cycle(run, side, rng.uniform(1.0, 1.5), "cba")
        _check_nothing_lost(run, side)
        counts.append(check_corrections_kept(run, side)[0])
    assert counts[-1] > 0  # the session did correct, and those corrections are on disk


def test_cba_refuses_a_single_action_env_at_once():
    from _toy_envs import ClusterWorld

    env = ClusterWorld([[0.0, 0.0]], [0], [1.0], episode_length=5)
    with pytest.raises(ValueError, match="at least 2 actions.*got an env with 1"):
        ConfidentTeacher(
            env,
            correcting(lambda obs, info: 0),
            strategy=ConfidenceBasedAutonomy(),
            config=TeachingConfig(noninteractive=False),
            progress=False,
        )


def test_a_cba_instance_taught_before_decides_a_new_session_as_a_fresh_one():
    """bind() starts CBA afresh, as every other shipped strategy: a reused instance kept the
    thresholds and stored demonstrations of the session it taught before, so a new session
    starting from a fitted model acted on its own at once where a fresh CBA asks (its gates
    come from its own first refit)."""
    import copy

    env = rare_regions_world(episode_length=10)
    cba = ConfidenceBasedAutonomy()
    first = ConfidentTeacher(
        env,
        correcting(oracle(env)),
        strategy=cba,
        config=TeachingConfig(max_new=5, noninteractive=False),
        progress=False,
    )
    first.run(max_steps=300)
    assert cba.thresholds is not None
    fitted = first.model

    def autonomy(strategy):
        env2 = rare_regions_world(episode_length=10)
        ct = ConfidentTeacher(
            env2,
            correcting(oracle(env2)),
            strategy=strategy,
            model=copy.deepcopy(fitted),
            config=TeachingConfig(max_new=50, noninteractive=False),
            seed=3,
            progress=False,
        )
        ct.run(max_steps=20)
        return [r.autonomous for r in ct.records]

    fresh = autonomy(ConfidenceBasedAutonomy())
    assert fresh == [False] * 20  # no refit yet in this session: no gates, so it asks
    assert autonomy(cba) == fresh


def test_a_correcting_teacher_of_the_observation_alone_is_refused_when_wrapped():
    """correcting(teacher) hides the teacher's signature behind its own (observation, info):
    a teacher of the observation alone passed ConfidentTeacher's check and failed at the
    session's first request with Python's "takes 1 positional argument but 2 were given"
    (CBA and HG-DAgger in the benchmark wrap every teacher so). correcting() reads the
    wrapped teacher's signature: a TypeError says how a teacher is called and how to wrap a
    policy; a two-argument teacher, or one with *args, is taken."""
    with pytest.raises(TypeError) as e:
        correcting(lambda obs: 0)
    msg = str(e.value)
    assert "teacher(observation, info)" in msg and "<lambda> takes (obs)" in msg, msg
    assert "correcting(lambda obs, info: policy(obs))" in msg, msg
    with pytest.raises(TypeError, match=r"takes \(obs\)"):
        correcting(torch.no_grad()(lambda obs: 0))
    with pytest.raises(TypeError, match=r"expected a callable teacher.*got None"):
        correcting(None)  # was taken: the wrapper is callable, so only the first request failed
    env = rare_regions_world()
    for teacher in (oracle(env), lambda *args: 0):
        ct = ConfidentTeacher(
            env, correcting(teacher), strategy=ConfidenceBasedAutonomy(), progress=False
        )
        ct.run(max_steps=2)
        assert len(ct.records) == 2
