"""GaussianMixtureSet against scikit-learn's GaussianMixture, plus its contract."""

from __future__ import annotations

import copy
import itertools
import math

import numpy as np
import pytest
import torch
from sklearn.mixture import GaussianMixture

from torchcbl import _em
from torchcbl.gmm import Classification, GaussianMixtureSet


def _blobs(seed: int, n_per: tuple[int, ...], d: int = 3, spread: float = 4.0):
    """Standardised data (every feature variance exactly 1 over all rows), labels."""
    rng = np.random.default_rng(seed)
    xs, ys = [], []
    for a, n in enumerate(n_per):
        centres = rng.normal(scale=spread, size=(3, d))
        comp = rng.integers(0, 3, size=n)
        xs.append(centres[comp] + rng.normal(size=(n, d)) * rng.uniform(0.3, 1.0, size=d))
        ys.append(np.full(n, a))
    x = np.concatenate(xs)
    x = (x - x.mean(0)) / x.std(0)
    return x, np.concatenate(ys)


def _single(model: GaussianMixtureSet, x_a: np.ndarray, action: int, k: int):
    """One candidate alone through the pure EM functions: (centre, x, masks, uniforms)."""
    centre = x_a.mean(0)
    xb = torch.from_numpy(x_a - centre)[None]
    pmask = torch.ones(1, len(x_a), dtype=torch.float64)
    cmask = torch.ones(1, 1, k, dtype=torch.float64)
    u = _em.candidate_uniforms(model.seed, np.array([[action]]), np.array([[k]]), k)
    return centre, xb, pmask, cmask, torch.from_numpy(u)


def _shared_init(model: GaussianMixtureSet, x_a: np.ndarray, action: int, k: int):
    """The initial parameters our fit uses for (action, k), to hand to sklearn."""
    centre, xb, pmask, cmask, u = _single(model, x_a, action, k)
    resp = _em.kmeans_init(xb, pmask, cmask, u)
    p = _em.m_step(_em.quadratic_features(xb), resp, cmask, model.var_floor_)
    prec = torch.linalg.inv(p.covariances[0, 0]).numpy()
    return p.weights[0, 0].numpy(), p.means[0, 0].numpy() + centre, prec


@pytest.fixture(scope="module")
def fitted():
    x, y = _blobs(0, (120, 90, 60))
    model = GaussianMixtureSet(3, 3, max_components=6, seed=3).fit(x, y)
    return model, x, y


def test_each_candidate_matches_sklearn_from_the_same_initialisation(fitted):
    model, x, y = fitted
    floor = model.var_floor_.numpy()
    # features standardised: one scalar floor equals sklearn's reg_covar
    assert np.allclose(floor, floor[0], rtol=1e-12)
    rep = model.fit_report_
    for a in range(3):
        x_a = x[y == a]
        for k in range(1, 7):
            w0, mu0, p0 = _shared_init(model, x_a, a, k)
            gm = GaussianMixture(
                k,
                covariance_type="full",
                tol=model.tol,
                max_iter=model.max_iter,
                reg_covar=float(floor[0]),
                weights_init=w0,
                means_init=mu0,
                precisions_init=p0,
                random_state=0,
            ).fit(x_a)
            ll_sk = gm.score(x_a) * len(x_a)
            ll = float(rep.log_likelihood[a, k - 1])
            assert ll == pytest.approx(ll_sk, rel=1e-3)
            assert float(rep.criterion[a, k - 1]) == pytest.approx(gm.aic(x_a), rel=1e-3)
            # formula identical to sklearn's aic() on the same log-likelihood
            p = (k - 1) + k * 3 + k * 3 * 4 / 2
            assert float(rep.criterion[a, k - 1]) == pytest.approx(2 * p - 2 * ll, rel=1e-12)


def test_aic_bic_methods_equal_sklearn_formulas_on_chosen_mixtures(fitted):
    model, x, y = fitted
    for a in range(3):
        x_a = x[y == a]
        k = int(model.n_components_[a])
        gm = GaussianMixture(k, covariance_type="full")
        gm.weights_ = model.weights_[a, :k].numpy()
        gm.means_ = model.means_[a, :k].numpy()
        gm.covariances_ = model.covariances_[a, :k].numpy()
        gm.precisions_cholesky_ = np.linalg.cholesky(np.linalg.inv(gm.covariances_))
        gm.converged_ = True
        gm.n_features_in_ = 3
        assert float(model.aic()[a]) == pytest.approx(gm.aic(x_a), rel=1e-9)
        assert float(model.bic()[a]) == pytest.approx(gm.bic(x_a), rel=1e-9)
        assert float(model.aic(x, y)[a]) == pytest.approx(gm.aic(x_a), rel=1e-9)
        # and log_prob equals sklearn's score_samples + log prior
        lp = model.log_prob(x_a)[:, a].numpy()
        prior = np.log(len(x_a) / len(x))
        np.testing.assert_allclose(lp, gm.score_samples(x_a) + prior, rtol=1e-9)


def test_choice_is_per_action_argmin_of_criterion(fitted):
    model, _, _ = fitted
    crit = model.criterion_
    assert torch.equal(model.n_components_, crit.argmin(1) + 1)
    assert torch.isinf(crit[~model.fit_report_.candidate_mask]).all()


def test_eq6_joint_minimum_equals_per_action_minimum():
    x, y = _blobs(1, (12, 5, 8), d=2)
    model = GaussianMixtureSet(3, 2, max_components=4, criterion="aic_paper").fit(x, y)
    crit = model.criterion_.numpy()
    share = np.bincount(y) / len(y)
    cands = [range(min(4, int((y == a).sum()))) for a in range(3)]
    best = min(
        itertools.product(*cands),
        key=lambda ks: sum(share[a] * crit[a, k] for a, k in enumerate(ks)),
    )
    assert [k + 1 for k in best] == model.n_components_.tolist()


@pytest.mark.parametrize("criterion", ["aic", "bic", "aic_paper"])
def test_criteria_formulas(criterion):
    x, y = _blobs(2, (40, 30), d=2)
    model = GaussianMixtureSet(2, 2, max_components=3, criterion=criterion).fit(x, y)
    rep = model.fit_report_
    for a in range(2):
        n = int((y == a).sum())
        for k in (1, 2, 3):
            ll = float(rep.log_likelihood[a, k - 1])
            p = (k - 1) + 2 * k + 3 * k
            expect = {"aic": 2 * p - 2 * ll, "bic": p * math.log(n) - 2 * ll}.get(
                criterion, 2 * k - 2 * ll
            )
            assert float(rep.criterion[a, k - 1]) == pytest.approx(expect, rel=1e-12)


def test_batched_fit_equals_fitting_each_candidate_alone():
    x, y = _blobs(4, (80, 50, 30))
    joint = GaussianMixtureSet(3, 3, max_components=5, seed=7).fit(x, y)
    rep = joint.fit_report_
    for a in range(3):
        x_a = x[y == a]
        for k in range(1, 6):
            _, xb, pm, cm, u = _single(joint, x_a, a, k)
            resp0 = _em.kmeans_init(xb, pm, cm, u)
            one = _em.run_em(xb, pm, cm, joint.var_floor_, resp0, joint.tol, joint.max_iter)
            assert float(rep.log_likelihood[a, k - 1]) == pytest.approx(
                float(one.loglik[0, 0]), rel=1e-9
            )
            assert int(rep.n_iter[a, k - 1]) == int(one.n_iter[0, 0])
            if k == int(joint.n_components_[a]):
                torch.testing.assert_close(
                    joint.means_[a, :k] - torch.from_numpy(x_a.mean(0)),
                    one.params.means[0, 0],
                    rtol=1e-7,
                    atol=1e-9,
                )


def test_interleaving_of_rows_does_not_change_the_fit():
    x, y = _blobs(6, (70, 40))
    ref = GaussianMixtureSet(2, 3, max_components=4, seed=2).fit(x, y)
    # interleave the actions' rows, keeping each action's own order
    order = np.argsort(np.r_[np.arange(70) * 2.0, np.arange(40) * 3.0 + 0.5], kind="stable")
    other = GaussianMixtureSet(2, 3, max_components=4, seed=2).fit(x[order], y[order])
    for k, v in ref.state_dict().items():
        torch.testing.assert_close(v, other.state_dict()[k], rtol=1e-9, atol=1e-12), k


def test_state_dict_round_trip_classifies_identically(fitted):
    model, x, _ = fitted
    fresh = GaussianMixtureSet(3, 3, max_components=6, seed=3)
    fresh.load_state_dict(model.state_dict())
    assert fresh.is_fitted
    a, b = model.classify(x), fresh.classify(x)
    for f in Classification._fields:
        assert torch.equal(getattr(a, f), getattr(b, f))
    # loading an unfitted state resets the prediction tables too
    fresh.load_state_dict(GaussianMixtureSet(3, 3, max_components=6).state_dict())
    assert not fresh.is_fitted and (fresh.classify(x[:2]).action == -1).all()


def test_fitted_state_is_made_of_ordinary_tensors(fitted):
    """The EM runs in inference mode; nothing of it may leak into the module or the report
    (an inference tensor refuses in-place updates and autograd outside that mode)."""
    model, x, _ = fitted
    leaked = [name for name, b in model.named_buffers() if b.is_inference()]
    rep = model.fit_report_
    leaked += [f for f, v in vars(rep).items() if isinstance(v, torch.Tensor) and v.is_inference()]
    assert leaked == []
    means = model.means_.clone().requires_grad_(True)
    (means * 2.0).sum().backward()  # usable in a user's own autograd graph
    model.means_.add_(0.0)  # and updatable in place


def test_a_model_built_under_inference_mode_fits_outside_it(fitted):
    """A GaussianMixtureSet constructed inside ``torch.inference_mode()`` (an evaluation
    script's block) holds inference buffers: fit() or refit() outside that block raised
    torch's "Inplace update to inference tensor outside InferenceMode". The fit now replaces
    such buffers, with the same values as a model built normally."""
    model, x, y = fitted
    with torch.inference_mode():
        built = GaussianMixtureSet(3, 3, max_components=6, seed=3)
    built.fit(x, y)
    with torch.inference_mode():
        inside = GaussianMixtureSet(3, 3, max_components=6, seed=3).fit(x[:-20], y[:-20])
    inside.refit(x, y)
    plain = GaussianMixtureSet(3, 3, max_components=6, seed=3).fit(x[:-20], y[:-20]).refit(x, y)
    for got, want in ((built, model), (inside, plain)):
        for (name, b), (_, w) in zip(got.named_buffers(), want.named_buffers(), strict=True):
            assert not b.is_inference() and b.dtype == w.dtype, name
            assert torch.equal(b, w), name
        assert torch.equal(got.classify(x).action, want.classify(x).action)


def test_predictions_are_ordinary_tensors_at_every_batch_size(fitted):
    """Small batches take a numpy path, large ones torch's: either way the caller gets tensors
    it may update in place and use in its own autograd graph."""
    model, x, _ = fitted
    big = np.concatenate([x] * 2)  # 540 rows: the torch path
    for rows in (x[:1], x[:10], big):
        lp, c = model.log_prob(rows), model.classify(rows)
        for t in (lp, *c):
            assert not t.is_inference()
        lp.add_(1.0)
        (c.posterior.clone().requires_grad_(True) * 2.0).sum().backward()


def test_a_fitted_state_loads_only_into_a_model_with_its_settings(fitted):
    """A refit continues from the saved candidates, so a state fitted under one criterion,
    floor, seed... must not load silently into a model that would refit under others."""
    model, x, y = fitted
    for other in (
        dict(seed=4),
        dict(seed=3, criterion="bic"),
        dict(seed=3, var_floor=0.05),
        dict(seed=3, tol=1e-4),
        dict(seed=3, max_iter=50),
        dict(seed=3, refit_growth=0.5),
    ):
        wrong = GaussianMixtureSet(3, 3, max_components=6, **other)
        name = next(k for k in other if k != "seed") if len(other) > 1 else "seed"
        with pytest.raises(ValueError, match=rf"saved by a GaussianMixtureSet with {name}="):
            wrong.load_state_dict(model.state_dict())
        assert not wrong.is_fitted  # refused before anything was loaded
    # a state saved before the settings were kept loads as before
    old = {k: v for k, v in model.state_dict().items() if k != "settings_"}
    fresh = GaussianMixtureSet(3, 3, max_components=6, seed=4)
    fresh.load_state_dict(old)
    assert torch.equal(fresh.classify(x).action, model.classify(x).action)
    assert torch.equal(fresh.settings_, GaussianMixtureSet(3, 3, 6, seed=4).settings_)
    # the settings survive a dtype round trip exactly (on a copy: the fixture is shared)
    cast = copy.deepcopy(model).to(torch.float32).to(torch.float64)
    GaussianMixtureSet(3, 3, max_components=6, seed=3).load_state_dict(cast.state_dict())


def test_a_state_of_other_sizes_is_refused_naming_the_constructor_arguments(fitted):
    """Reloading a saved model into one built with another max_components (or action or
    feature count) raised torch's RuntimeError listing a dozen buffer shapes, naming no
    constructor argument; it is a ValueError saying which sizes differ and what to build."""
    model, _, _ = fitted  # GaussianMixtureSet(3, 3, max_components=6, seed=3)
    for args, differ in (
        ((3, 3), "max_components=10"),
        ((4, 3, 6), "n_actions=4"),
        ((3, 2, 6), "n_features=2"),
    ):
        wrong = GaussianMixtureSet(*args, seed=3)
        with pytest.raises(ValueError) as err:
            wrong.load_state_dict(model.state_dict())
        msg = str(err.value)
        assert "n_actions=3, n_features=3, max_components=6" in msg and differ in msg
        assert "GaussianMixtureSet(3, 3, max_components=6" in msg  # what to build
        assert not wrong.is_fitted
        with pytest.raises(ValueError, match="max_components=6"):  # unfitted states too
            wrong.load_state_dict(GaussianMixtureSet(3, 3, max_components=6).state_dict())


def test_every_bit_of_the_seed_counts():
    x, y = _blobs(1, (60, 60, 60))
    a = GaussianMixtureSet(3, 3, max_components=4, seed=1).fit(x, y)
    b = GaussianMixtureSet(3, 3, max_components=4, seed=2**32 + 1).fit(x, y)
    c = GaussianMixtureSet(3, 3, max_components=4, seed=2**32 + 1).fit(x, y)
    assert not torch.equal(a.means_, b.means_) and torch.equal(b.means_, c.means_)
    for bad in (-1, 2**64, 1.0):
        with pytest.raises(ValueError, match=r"seed to be an int in \[0, 2\*\*64\)"):
            GaussianMixtureSet(3, 3, seed=bad)


def test_to_dtype_and_back(fitted):
    model, x, _ = fitted
    ref = model.classify(x)
    m2 = GaussianMixtureSet(3, 3, max_components=6, seed=3)
    m2.load_state_dict(model.state_dict())
    m2.to(torch.float32)
    assert m2.means_.dtype == torch.float32
    c = m2.classify(x)
    assert (c.action == ref.action).float().mean() > 0.99
    m2.to(torch.float64)
    assert m2.classify(x).action.dtype == torch.long


def test_numpy_and_torch_prediction_paths_agree(fitted):
    model, x, _ = fitted
    big = np.concatenate([x] * 2)  # above the numpy row threshold -> torch path
    assert len(big) > 256
    c_big = model.classify(big)
    lp_big = model.log_prob(torch.from_numpy(big).float())
    for start in range(0, len(big), 100):
        sl = slice(start, start + 100)
        c = model.classify(big[sl])
        torch.testing.assert_close(c.distance, c_big.distance[sl])
        torch.testing.assert_close(c.posterior, c_big.posterior[sl])
        assert torch.equal(c.action, c_big.action[sl])
        torch.testing.assert_close(model.log_prob(big[sl].astype(np.float32)), lp_big[sl])


def test_classification_fields_follow_the_contract(fitted):
    model, x, _ = fitted
    c = model.classify(x)
    lp = model.log_prob(x)
    assert torch.equal(c.action, lp.argmax(1))
    torch.testing.assert_close(c.posterior, torch.softmax(lp, 1))
    torch.testing.assert_close(c.confidence, torch.exp(-0.5 * c.distance**2))
    # distance: to the most likely component of the chosen mixture, brute force
    for i in range(0, len(x), 37):
        a = int(c.action[i])
        k = int(model.n_components_[a])
        best, dist = -math.inf, None
        for j in range(k):
            cov = model.covariances_[a, j].numpy()
            diff = x[i] - model.means_[a, j].numpy()
            m2 = diff @ np.linalg.solve(cov, diff)
            score = math.log(model.weights_[a, j]) - 0.5 * (
                m2 + np.linalg.slogdet(cov)[1] + 3 * math.log(2 * math.pi)
            )
            if score > best:
                best, dist = score, math.sqrt(m2)
        assert float(c.distance[i]) == pytest.approx(dist, rel=1e-9)


def test_before_fit_classify_reports_no_confidence():
    model = GaussianMixtureSet(4, 2)
    c = model.classify(np.zeros((3, 2)))
    assert c.action.tolist() == [-1, -1, -1]
    assert c.confidence.tolist() == [0.0] * 3
    assert torch.isinf(c.distance).all()
    torch.testing.assert_close(c.posterior, torch.full((3, 4), 0.25, dtype=torch.float64))
    with pytest.raises(RuntimeError, match="fit"):
        model.log_prob(np.zeros((1, 2)))


def test_seeded_fit_is_deterministic():
    x, y = _blobs(5, (60, 60))
    a = GaussianMixtureSet(2, 3, 5, seed=11).fit(x, y)
    b = GaussianMixtureSet(2, 3, 5, seed=11).fit(x, y)
    for k, v in a.state_dict().items():
        assert torch.equal(v, b.state_dict()[k]), k


def test_kmeans_on_large_groups_uses_a_stride_and_labels_every_point():
    """Above 1024 points a group seeds and runs Lloyd on an even stride of its points, then
    every point goes to its nearest final centre: three far-apart blobs are found exactly,
    and the result of a group does not depend on the other groups of the batch."""
    rng = np.random.default_rng(5)
    n_big, n_small, d = 3000, 200, 2
    truth = rng.integers(0, 3, size=n_big)
    centres = np.array([[0.0, 0.0], [20.0, 0.0], [0.0, 20.0]])
    big = centres[truth] + rng.normal(size=(n_big, d))
    small = rng.normal(size=(n_small, d))
    x = torch.zeros(2, n_big, d, dtype=torch.float64)
    x[0] = torch.from_numpy(big)
    x[1, :n_small] = torch.from_numpy(small)
    pmask = torch.zeros(2, n_big, dtype=torch.float64)
    pmask[0] = 1.0
    pmask[1, :n_small] = 1.0
    cmask = torch.ones(2, 1, 3, dtype=torch.float64)
    u = torch.from_numpy(_em.candidate_uniforms(0, np.array([[0], [1]]), np.array([[3], [3]]), 3))
    resp = _em.kmeans_init(x, pmask, cmask, u)
    assert resp.shape == (2, n_big, 1, 3)
    torch.testing.assert_close(resp.sum((-1, -2)), pmask)  # one component per real point
    labels = resp[0, :, 0].argmax(-1).numpy()
    # the clustering equals the truth up to a renaming of the components
    pairs = set(zip(labels.tolist(), truth.tolist(), strict=True))
    assert len(pairs) == 3
    alone_big = _em.kmeans_init(x[:1], pmask[:1], cmask[:1], u[:1])
    alone_small = _em.kmeans_init(x[1:, :n_small], pmask[1:, :n_small], cmask[1:], u[1:])
    torch.testing.assert_close(resp[:1], alone_big, rtol=0.0, atol=0.0)
    torch.testing.assert_close(resp[1:, :n_small], alone_small, rtol=0.0, atol=0.0)
    assert n_big > _em._KMEANS_POINTS >= n_small  # both paths are exercised


def test_calling_the_model_like_a_network_says_which_method_to_call():
    """`GaussianMixtureSet(...).fit(X, y)(X[:2])`, as one calls any nn.Module, raised torch's
    `NotImplementedError: Module [GaussianMixtureSet] is missing the required "forward"
    function`, naming none of the methods that answer. It is a TypeError naming them, fitted
    or not, and the model still classifies afterwards."""
    x, y = _blobs(0, (40, 40, 40), d=2)
    for model in (GaussianMixtureSet(3, 2), GaussianMixtureSet(3, 2, max_components=2).fit(x, y)):
        for args in ((x[:2],), (torch.from_numpy(x[:2]),), ()):
            with pytest.raises(TypeError) as info:
                model(*args)
            message = str(info.value)
            assert "\n" not in message
            for name in (".classify(", ".log_prob(", "GreedyPolicy("):
                assert name in message, (name, message)
    assert model.classify(x[:2]).action.tolist() == model.log_prob(x[:2]).argmax(1).tolist()
