"""Confidence rules against hand-built classifications and fitted models."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
import torch

from torchcbl import AutoThresholdRule, DistanceRule, GaussianMixtureSet, PosteriorRule
from torchcbl.confidence import chi2_quantile, rule_from_config, rule_to_config
from torchcbl.gmm import Classification


def cls(action, distance, posterior):
    d = torch.tensor(distance, dtype=torch.float64)
    return Classification(
        torch.tensor(action),
        torch.exp(-0.5 * d**2),
        d,
        torch.tensor(posterior, dtype=torch.float64),
    )


C = cls(
    [-1, 0, 1, 1, 0],
    [math.inf, 1.0, 2.0, 2.0001, 0.1],
    [[0.5, 0.5], [0.95, 0.05], [0.2, 0.8], [0.01, 0.99], [0.9, 0.1]],
)


def test_distance_rule_is_the_papers_two_std():
    assert DistanceRule().is_confident(C).tolist() == [False, True, True, False, True]
    assert DistanceRule(1.0).is_confident(C).tolist() == [False, True, False, False, True]


def test_posterior_rule_and_never_confident_without_a_model():
    assert PosteriorRule(0.9).is_confident(C).tolist() == [False, True, False, True, True]
    # Even a posterior of 1 (one action) is not confident before any fit (action -1).
    one = cls([-1], [math.inf], [[1.0]])
    assert PosteriorRule(0.5).is_confident(one).tolist() == [False]


@pytest.mark.parametrize(
    "make",
    [
        lambda: DistanceRule(0),
        lambda: DistanceRule(float("nan")),
        lambda: PosteriorRule(1.5),
        lambda: AutoThresholdRule(2.0, 3.0),
    ],
)
def test_bad_thresholds_are_clear_errors(make):
    with pytest.raises(ValueError, match="expected"):
        make()


def test_rules_round_trip_through_config():
    for rule in (DistanceRule(1.5), PosteriorRule(0.8), AutoThresholdRule(2.5, 0.5)):
        back = rule_from_config(rule_to_config(rule))
        assert type(back) is type(rule) and rule_to_config(back) == rule_to_config(rule)
    with pytest.raises(ValueError, match="Pass rule="):
        rule_from_config({"type": "my.Rule", "custom": True})


def test_distance_rule_takes_max_std_or_quantile_and_round_trips_either():
    """Both given is refused as the rule is made, and so is a stored dict holding both (a
    damaged config.json), saying which values were given; either one alone (numpy numbers
    too) comes back from its JSON config as it was. Only the type hints' overloads were
    checked before (tests/test_typing.py), not the refusal itself."""
    import json

    both = r"DistanceRule: give max_std \(2\.0\) or quantile \(0\.95\), not both"
    for make in (
        lambda: DistanceRule(2.0, quantile=0.95),
        lambda: rule_from_config({"type": "DistanceRule", "max_std": 2.0, "quantile": 0.95}),
    ):
        with pytest.raises(ValueError, match=both):
            make()
    for rule in (DistanceRule(), DistanceRule(np.float32(2.5)), DistanceRule(quantile=0.9)):
        config = rule_to_config(rule)
        back = rule_from_config(json.loads(json.dumps(config)))
        assert (back.max_std, back.quantile) == (rule.max_std, rule.quantile)
        assert rule_to_config(back) == config and len(config) == 2  # "type" and one of them


def test_a_quantile_distance_rule_says_it_has_no_fixed_max_std():
    """DistanceRule(quantile=...) set max_std = 2.0, the paper's fixed threshold it does not
    use: reading rule.max_std said 2 std where threshold(D) gives the chi-square one (3.08 std
    in 4-D at 0.95). It is None now; every threshold, and the stored configs (as a session's
    config.json holds them) with their round trips, are as before."""
    from torchcbl.strategies import strategy_from_config

    stored = {  # a session's config.json "strategy" entries, as written before and now
        "quantile": {
            "type": "ConfidentExecution",
            "rule": {"type": "DistanceRule", "quantile": 0.95},
            "relabel": False,
        },
        "max_std": {
            "type": "ConfidentExecution",
            "rule": {"type": "DistanceRule", "max_std": 2.0},
            "relabel": False,
        },
    }
    by_quantile = strategy_from_config(stored["quantile"])
    assert by_quantile.rule.max_std is None and by_quantile.rule.quantile == 0.95
    assert by_quantile.rule.threshold(4) == pytest.approx(3.0802, abs=1e-4)
    assert by_quantile.to_config() == stored["quantile"]
    by_std = strategy_from_config(stored["max_std"])
    assert by_std.rule.max_std == 2.0 and by_std.rule.quantile is None
    assert by_std.rule.threshold(4) == 2.0 and by_std.to_config() == stored["max_std"]
    assert DistanceRule().max_std == 2.0 and DistanceRule(quantile=0.9).max_std is None
    rule = DistanceRule(quantile=0.95)
    rule.update(GaussianMixtureSet(2, 4), None, None)  # notes D = 4
    near = cls([0, 1, 1], [2.0, 3.08, 3.09], [[0.9, 0.1], [0.1, 0.9], [0.1, 0.9]])
    assert rule.is_confident(near).tolist() == [True, True, False]
    assert repr(rule) == "DistanceRule(quantile=0.95)"


def test_auto_threshold_rule_follows_the_documented_rule():
    rng = np.random.default_rng(0)
    # Action 0 far away and clean; actions 1 and 2 overlap, so the model makes mistakes there.
    x = np.concatenate([rng.normal([-10, 0], 1, (60, 2)), rng.normal([0, 0], 1, (120, 2))])
    y = np.concatenate([np.zeros(60, int), (x[60:, 0] > 0).astype(int) + 1])
    flip = np.flatnonzero(rng.random(120) < 0.2) + 60
    y[flip] = 3 - y[flip]  # swap 1 <-> 2 on a fifth of the overlapping points
    model = GaussianMixtureSet(3, 2, max_components=2, seed=0).fit(x, y)
    rule = AutoThresholdRule(max_std=2.0)
    c = model.classify(x)
    # Before the first update it is the distance rule.
    assert torch.equal(rule.is_confident(c), DistanceRule(2.0).is_confident(c))
    rule.update(model, x, y)
    for a in range(3):
        wrong = (c.action == a) & (c.action != torch.as_tensor(y))
        want = 2.0 if not wrong.any() else min(2.0, float(c.distance[wrong].mean()))
        assert float(rule.thresholds[a]) == pytest.approx(want)
    assert float(rule.thresholds[0]) == 2.0  # nothing contradicts the clean action
    assert float(rule.thresholds[1:].min()) < 2.0  # the overlapping ones got stricter
    got = rule.is_confident(c)
    assert torch.equal(got, c.distance < rule.thresholds[c.action])


def _one_mistake(at):
    """Two far-apart clean actions and one point labelled 1 at ``at``, inside action 0's
    cluster: the model's only mistake (predicted 0). (model, x, y, index of the mistake)."""
    rng = np.random.default_rng(0)
    x = np.r_[rng.normal([0, 0], 1, (40, 2)), rng.normal([10, 0], 1, (40, 2)), [at]]
    y = np.r_[np.zeros(40, int), np.ones(40, int), [1]]
    model = GaussianMixtureSet(2, 2, max_components=1, seed=0).fit(x, y)
    c = model.classify(x)
    assert torch.nonzero(c.action != torch.as_tensor(y)).flatten().tolist() == [80]
    assert int(c.action[80]) == 0
    return model, x, y, c


def test_auto_threshold_does_not_trust_its_one_mistake_itself():
    """With one misclassified demonstration of action 0, action 0's threshold is that point's
    distance (the mean of one), and the comparison is strict: the rule does not trust the
    very point it got wrong, though it trusts action 0's points nearer the mean."""
    model, x, y, c = _one_mistake([0.3, 0.2])
    rule = AutoThresholdRule(max_std=2.0)
    rule.update(model, x, y)
    mistake = float(c.distance[80])
    assert float(rule.thresholds[0]) == mistake and float(rule.thresholds[1]) == 2.0
    confident = rule.is_confident(c)
    assert not bool(confident[80])
    nearer = torch.nonzero(c.distance[:40] < mistake).flatten()
    assert len(nearer) > 0 and bool(confident[nearer].all())


def test_auto_threshold_never_goes_below_min_std():
    """A mistake close to an action's mean would make its threshold that small distance;
    ``min_std`` is the floor: AutoThresholdRule(max_std=2, min_std=1.5) with one wrong point
    at ~0.5 std gives 1.5, and trusts action 0's points between 0.5 and 1.5 std."""
    model, x, y, c = _one_mistake([0.5, 0.0])
    mistake = float(c.distance[80])
    assert mistake < 1.0
    rule = AutoThresholdRule(max_std=2.0, min_std=1.5)
    rule.update(model, x, y)
    assert rule.thresholds.tolist() == [1.5, 2.0]
    confident = rule.is_confident(c)
    between = torch.nonzero((c.distance[:40] > mistake) & (c.distance[:40] < 1.5)).flatten()
    assert len(between) > 0 and bool(confident[between].all())
    assert bool(confident[80])  # the mistake too: the floor trusts everything within 1.5


def test_a_rule_reused_in_another_session_starts_from_its_own_refits():
    """A ConfidentExecution (and its AutoThresholdRule) taught once and given to a new session
    kept the old session's per-action thresholds: on an env with more actions and a fitted
    model=, the first autonomous decision raised IndexError (2 thresholds, action 2); with as
    many actions it decided on thresholds fitted to other data. bind() now resets the rule."""
    import copy

    from _toy_envs import oracle, overlap_world, rare_regions_world

    from torchcbl import ConfidentTeacher, TeachingConfig
    from torchcbl.strategies import ConfidentExecution

    env = overlap_world(episode_length=10)  # 2 actions
    used = ConfidentExecution(AutoThresholdRule())
    first = ConfidentTeacher(
        env, oracle(env), strategy=used, config=TeachingConfig(max_new=5), progress=False
    )
    first.run(max_steps=200)
    assert used.rule.thresholds is not None and len(used.rule.thresholds) == 2
    world = rare_regions_world(episode_length=10)  # 3 actions
    fitted = GaussianMixtureSet(3, 2).fit(*world.sample(200, np.random.default_rng(0)))

    def decisions(strategy):
        env2 = rare_regions_world(episode_length=10)
        ct = ConfidentTeacher(
            env2,
            oracle(env2),
            strategy=strategy,
            model=copy.deepcopy(fitted),
            config=TeachingConfig(max_new=50, noninteractive=False),
            seed=3,
            progress=False,
        )
        ct.run(max_steps=40)
        return [(r.autonomous, r.executed_action) for r in ct.records]

    fresh = decisions(ConfidentExecution(AutoThresholdRule()))
    assert any(auto for auto, _ in fresh)
    assert decisions(used) == fresh


@pytest.mark.parametrize(
    "bad, error",
    [
        (lambda y: y[:1], ValueError),  # broadcast against the model's answers: wrong thresholds
        (lambda y: y[:50], ValueError),
        (lambda y: y[:, None], ValueError),
        (lambda y: y + 0.5, TypeError),  # truncated to the integer below
        (lambda y: y.astype(float), TypeError),
        (lambda y: y + 3, ValueError),  # no such action
    ],
)
def test_auto_threshold_update_refuses_labels_that_do_not_fit_the_observations(bad, error):
    """AutoThresholdRule.update took any label vector torch could broadcast: one label for
    100 observations set both thresholds from a comparison with that one label (action 1's
    2.0 became 1.09), and float labels were truncated. It now names the expected shape. Float
    labels are a TypeError, as GaussianMixtureSet.fit says them (update said ValueError, so
    code catching the fit's error for the same labels missed the rule's)."""
    rng = np.random.default_rng(0)
    x = np.r_[rng.normal(0, 1, (50, 2)), rng.normal(1.5, 1, (50, 2))]
    y = np.r_[np.zeros(50, int), np.ones(50, int)]
    model = GaussianMixtureSet(2, 2, 2).fit(x, y)
    rule = AutoThresholdRule()
    with pytest.raises(error, match=r"AutoThresholdRule.update: expected"):
        rule.update(model, x, bad(y))
    with pytest.raises(error):  # the fit refuses the same labels the same way
        GaussianMixtureSet(2, 2, 2).fit(x, bad(y))
    assert rule.thresholds is None
    for labels in (y, y.tolist(), torch.from_numpy(y), y.astype(np.uint8)):
        rule.update(model, x, labels)
        assert rule.thresholds is not None


def test_chi2_quantile_is_right_in_both_tails():
    """chi2_quantile(1e-100, 1) returned 3.4e-60 (SciPy: 1.6e-200): its 200 halvings of
    [0, dof + 10] stopped far above a tiny quantile; near q = 1, gammainc rounds to 1 - a few
    ulps, so q = 1 - 1e-15 came out 0.17% low and 1 - 1e-10 2.6e-8 low (before 2026-11-27).
    Now both tails match SciPy, and every q up to 0.999 (the corridor's DistanceRule(quantile=
    0.9545) included) gives the same bits as before."""
    stats = pytest.importorskip("scipy.stats")
    for d in (1, 2, 3, 10, 100, 1000):
        for q in (1e-300, 1e-100, 1e-30, 1e-12, 0.9995, 1 - 1e-6, 1 - 1e-10, 1 - 1e-15):
            want = stats.chi2.ppf(q, d)
            if want > 0:  # 0 where the quantile is below the smallest float
                assert chi2_quantile(q, d) == pytest.approx(want, rel=1e-10, abs=0), (q, d)
    assert chi2_quantile(0.9545, 3) == 8.024894669075394  # the corridor's threshold squared
    assert chi2_quantile(0.95, 4) == 9.487729036781218


def test_a_quantile_rule_pickled_before_max_std_became_none_keeps_its_quantile():
    """Until c5f2f09 a quantile rule also held max_std = 2.0; that commit made threshold()
    and is_confident() read max_std first, so such a rule, unpickled (a notebook's saved
    object, a process pool's argument), went on at 2.0 std instead of its quantile. It also
    went on saying max_std = 2.0 (the attribute the class documents as None with a quantile,
    a mypy-narrowed ``float | None`` a user may branch on) with both set."""
    import pickle

    old = DistanceRule.__new__(DistanceRule)
    old.__dict__.update(max_std=2.0, quantile=0.95, _thresholds={}, _dof=None)
    rule = pickle.loads(pickle.dumps(old))
    assert rule.threshold(4) == pytest.approx(3.0802, abs=1e-4)
    c = Classification(
        action=torch.tensor([0, 0]),
        confidence=torch.tensor([0.04, 0.002], dtype=torch.float64),
        distance=torch.tensor([2.5, 3.5], dtype=torch.float64),
        posterior=torch.tensor([[1.0], [1.0]], dtype=torch.float64),
    )
    assert rule.is_confident(c, np.zeros((2, 4))).tolist() == [True, False]
    assert rule.max_std is None and rule.quantile == 0.95  # as the class documents
    assert repr(rule) == "DistanceRule(quantile=0.95)"


def test_from_std_reads_the_papers_standard_deviations_literally_or_as_a_coverage():
    """DistanceRule.from_std: "2 standard deviations" as a Mahalanobis distance of 2, or as
    the share within 2 std in one dimension (0.9545) taken as a chi-square quantile in D:
    against scipy's chi-square, 2.83 in 3-D and 3.12 in 4-D."""
    from scipy.stats import chi2

    assert DistanceRule.from_std(2.0).threshold(4) == 2.0
    assert DistanceRule.from_std(2.0, "literal").max_std == 2.0
    coverage = DistanceRule.from_std(2.0, "coverage")
    assert coverage.max_std is None and coverage.quantile == pytest.approx(0.954499736)
    for d, expected in ((1, 2.0), (3, 2.83), (4, 3.12)):
        assert coverage.threshold(d) == pytest.approx(math.sqrt(chi2.ppf(0.954499736, d)))
        assert round(coverage.threshold(d), 2) == expected
    with pytest.raises(ValueError, match=r"reading must be 'literal' or 'coverage', got 'lit'"):
        DistanceRule.from_std(2.0, "lit")
    with pytest.raises(ValueError, match=r"DistanceRule.max_std: expected a value > 0, got -1"):
        DistanceRule.from_std(-1, "coverage")


def test_a_quantile_rule_refuses_observations_that_are_not_the_classified_ones():
    """A quantile rule reads D, and so its threshold, from the observations it is given.
    Observations of another shape than the classified ones were read all the same: a 1-D
    model's 40 observations kept as x [40] (classified as x[:, None]) gave D = 40, a
    threshold of 7.5 std instead of 1.96, and 38 of the 40 came out confident instead of 10;
    three observations for five answers gave no error either. Such observations are refused,
    naming the shape expected; one observation [D] for one answer is read as before."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=40)
    model = GaussianMixtureSet(1, 1).fit(x[:, None], np.zeros(40, dtype=np.int64))
    far = np.linspace(-6.0, 6.0, 40)
    c = model.classify(far[:, None])
    rule = DistanceRule(quantile=0.95)
    right = rule.is_confident(c, far[:, None])
    assert 0 < int(right.sum()) < 40  # the far ends ask
    with pytest.raises(
        ValueError,
        match=r"DistanceRule\(quantile=0.95\)\.is_confident: expected the classified "
        r"observations, shape \[40, D\], but got shape \(40,\)",
    ):
        rule.is_confident(c, far)
    with pytest.raises(ValueError, match=r"shape \[5, D\], but got shape \(3, 1\)"):
        rule.is_confident(model.classify(far[:5, None]), far[:3, None])
    one = model.classify(far[:1, None])
    assert (
        rule.is_confident(one, far[:1]).tolist() == rule.is_confident(one, far[:1, None]).tolist()
    )


@pytest.mark.parametrize("bad", [2.7, 2.0, True, "3", 0, -1, np.float64(4.0)])
def test_threshold_refuses_a_feature_count_that_is_not_a_whole_number_of_features(bad):
    """DistanceRule(quantile=...).threshold(2.7) truncated the feature count to 2 and answered
    the 2-D threshold (2.45 std) silently; threshold(True) answered the 1-D one and
    threshold("3") the 3-D one. threshold(0) failed in chi2_quantile ("chi2_quantile: expected
    an int dof >= 1"), naming neither the method called nor its argument. Each is refused
    naming threshold and n_features; a fixed rule, which does not read D, refuses them too."""
    for rule in (DistanceRule(quantile=0.95), DistanceRule(2.0)):
        with pytest.raises(
            ValueError,
            match=rf"DistanceRule.threshold: expected n_features as an int >= 1 .*, got "
            rf"{re.escape(repr(bad))}",
        ):
            rule.threshold(bad)
    rule = DistanceRule(quantile=0.95)
    assert rule.threshold(np.int64(4)) == rule.threshold(4) == pytest.approx(3.0802, abs=1e-4)
    assert DistanceRule(2.0).threshold(4) == DistanceRule(2.0).threshold() == 2.0


def test_auto_threshold_rule_refuses_a_classification_of_another_action_count():
    """An AutoThresholdRule updated on a 3-action model and then given a 4-action model's
    classification raised a bare IndexError ('index 3 is out of bounds for dimension 0 with
    size 3'), and a 2-action model's was judged on the 3-action thresholds, silently. Both
    are a ValueError naming the two counts and what to do; update or reset mends it."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=(60, 2)) + np.repeat(np.arange(3), 20)[:, None] * 3.0
    y3 = np.repeat(np.arange(3), 20)
    for n_actions in (4, 2):
        rule = AutoThresholdRule()
        rule.update(GaussianMixtureSet(3, 2, 2).fit(x, y3), x, y3)
        y = np.repeat(np.arange(n_actions), 60 // n_actions)
        other = GaussianMixtureSet(n_actions, 2, 2).fit(x, y)
        c = other.classify(x)
        with pytest.raises(
            ValueError,
            match=rf"AutoThresholdRule.is_confident: its thresholds are for 3 actions \(set by "
            rf"update\) but the classification has {n_actions}; call rule.update\(model, ",
        ):
            rule.is_confident(c, x)
        fresh = AutoThresholdRule()
        fresh.update(other, x, y)
        rule.update(other, x, y)  # an update with the new model mends it
        assert torch.equal(rule.is_confident(c, x), fresh.is_confident(c, x))
        rule.reset()  # so does a reset (every threshold max_std until the next update)
        assert torch.equal(rule.is_confident(c, x), DistanceRule(2.0).is_confident(c, x))


@pytest.mark.parametrize(
    "rule, fields",
    [
        (DistanceRule(), "action, distance"),
        (DistanceRule(quantile=0.95), "action, distance"),
        (PosteriorRule(), "action, posterior"),
        (AutoThresholdRule(), "action, distance"),
    ],
    ids=repr,
)
def test_a_rule_given_no_classification_says_what_it_expected(rule, fields):
    """rule.is_confident(something that is not a Classification) failed with an
    AttributeError on .distance or .action (e.g. "'numpy.ndarray' object has no attribute
    'distance'"), not saying what a rule reads. It is a TypeError naming the fields expected,
    those missing and what was given. A look-alike with those fields (a custom model's own
    answer type) is read as before: the class is not required."""
    from collections import namedtuple

    for bad, missing in ((np.array([0, 1]), fields), ({"action": 1}, fields)):
        with pytest.raises(
            TypeError,
            match=rf"{re.escape(repr(rule))}\.is_confident: expected the model's Classification "
            rf"\(fields {fields}\) but got {type(bad).__name__} .* without {missing}; ",
        ):
            rule.is_confident(bad, np.zeros((2, 4)))
    Answer = namedtuple("Answer", "action distance posterior")
    alike = Answer(C.action, C.distance, C.posterior)
    assert torch.equal(
        rule.is_confident(alike, np.zeros((5, 4))), rule.is_confident(C, np.zeros((5, 4)))
    )


def test_auto_threshold_rule_refuses_a_look_alike_whose_action_is_beyond_its_posterior():
    """A look-alike classification (a custom model's own answer type) whose posterior is as
    wide as the rule's thresholds but whose action lies beyond them raised a ValueError since
    1c30b8c, then a bare IndexError ('index 2 is out of bounds for dimension 0 with size 2')
    once only the posterior's width was read (38ea69e): only the library's Classification,
    whose action is its posterior's argmax, need not be checked. A look-alike's action is."""
    from collections import namedtuple

    rng = np.random.default_rng(0)
    x = rng.normal(size=(40, 2)) + np.repeat(np.arange(2), 20)[:, None] * 3.0
    y = np.repeat(np.arange(2), 20)
    model = GaussianMixtureSet(2, 2, 2).fit(x, y)
    rule = AutoThresholdRule()
    rule.update(model, x, y)
    c = model.classify(x[:3])
    Answer = namedtuple("Answer", "action distance posterior")
    beyond = Answer(torch.tensor([0, 2, 1]), c.distance, c.posterior)
    with pytest.raises(
        ValueError,
        match=r"AutoThresholdRule.is_confident: its thresholds are for 2 actions \(set by "
        r"update\) but the classification has action 2; call rule.update\(model, ",
    ):
        rule.is_confident(beyond, x[:3])
    alike = Answer(c.action, c.distance, c.posterior)  # in range: read as the library's own
    assert torch.equal(rule.is_confident(alike, x[:3]), rule.is_confident(c, x[:3]))
