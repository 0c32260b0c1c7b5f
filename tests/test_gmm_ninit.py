"""GaussianMixtureSet(n_init=...): several k-means++ initialisations per candidate, the one of
highest log-likelihood kept (as scikit-learn's GaussianMixture(n_init=...))."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch
from sklearn.mixture import GaussianMixture

from torchcbl import _em
from torchcbl.gmm import GaussianMixtureSet


def _four_clusters(seed: int = 0) -> np.ndarray:
    """One wide cluster and three tight ones, standardised: a k-means++ start with two centres
    in the wide cluster ends EM in a poor local optimum at k = 4 (k = 2, 3 alike)."""
    rng = np.random.default_rng(seed)
    centres = np.array([[0.0, 0.0], [8.0, 0.0], [0.0, 8.0], [8.0, 8.0]])
    parts = [
        c + rng.normal(size=(n, 2)) * s
        for c, n, s in zip(centres, (150, 30, 30, 30), (1.5, 0.5, 0.5, 0.5), strict=True)
    ]
    x = np.concatenate(parts)
    return (x - x.mean(0)) / x.std(0)


def _blobs(seed: int, n_per: tuple[int, ...], d: int = 3) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    xs, ys = [], []
    for a, n in enumerate(n_per):
        centres = rng.normal(scale=4.0, size=(3, d))
        xs.append(centres[rng.integers(0, 3, size=n)] + rng.normal(size=(n, d)))
        ys.append(np.full(n, a))
    x, y = np.concatenate(xs), np.concatenate(ys)
    order = rng.permutation(len(y))  # the actions interleaved, as a stream of labels
    return ((x - x.mean(0)) / x.std(0))[order], y[order]


def _same_state(a: GaussianMixtureSet, b: GaussianMixtureSet) -> bool:
    sa, sb = a.state_dict(), b.state_dict()
    return sa.keys() == sb.keys() and all(
        sa[k].dtype == sb[k].dtype and torch.equal(sa[k], sb[k]) for k in sa
    )


def _one_init(model: GaussianMixtureSet, x_a: np.ndarray, action: int, k: int, init: int):
    """Total log-likelihood of candidate (action, k) fitted alone from initialisation ``init``
    through the pure EM functions, as fit() centres and seeds it."""
    xb = torch.from_numpy(x_a - x_a.mean(0))[None]
    pmask = torch.ones(1, len(x_a), dtype=torch.float64)
    cmask = torch.ones(1, 1, k, dtype=torch.float64)
    u = _em.candidate_uniforms(model.seed, np.array([[action]]), np.array([[k]]), k, init)
    resp = _em.kmeans_init(xb, pmask, cmask, torch.from_numpy(u))
    res = _em.run_em(xb, pmask, cmask, model.var_floor_, resp, model.tol, model.max_iter)
    return float(res.loglik[0, 0])


def test_n_init_1_is_the_fit_without_it_bit_for_bit():
    """n_init=1 (the default) fits exactly as a model built without the argument, fits and
    refits alike: its first initialisation is the one there was before n_init."""
    x, y = _blobs(1, (80, 50, 30))
    for kwargs in (dict(seed=0), dict(seed=5, criterion="bic"), dict(seed=2**40 + 3)):
        a = GaussianMixtureSet(3, 3, 5, **kwargs).fit(x, y)
        b = GaussianMixtureSet(3, 3, 5, n_init=1, **kwargs).fit(x, y)
        assert _same_state(a, b)
        for n in (100, 130, 160):
            a.refit(x[:n], y[:n])
            b.refit(x[:n], y[:n])
            assert _same_state(a, b)


@pytest.mark.parametrize("bad", [0, -1, 2.0, True, "3", None])
def test_n_init_must_be_an_int_of_at_least_one(bad):
    with pytest.raises(ValueError, match=rf"Expected n_init to be an int >= 1 but got {bad!r}"):
        GaussianMixtureSet(2, 2, n_init=bad)
    assert GaussianMixtureSet(2, 2, n_init=np.int64(3)).n_init == 3


@pytest.mark.parametrize("big", [4 * 10**18, 2**63, 2**70, np.uint64(2**63)])
def test_n_init_beyond_what_a_state_holds_is_refused_saying_so(big):
    """A model keeps n_init in its state (with the criterion, in one int64 code): an n_init
    too large for it failed in the constructor with torch's bare "Overflow when unpacking
    long long". It is refused in the constructor's words, naming the largest n_init, which
    the state holds whatever the criterion."""
    top = (2**63 - 3) // 3 + 1
    with pytest.raises(ValueError, match=rf"Expected n_init to be an int in \[1, {top}\]"):
        GaussianMixtureSet(2, 2, n_init=big, criterion="aic_paper")
    assert GaussianMixtureSet(2, 2, n_init=top, criterion="aic_paper").n_init == top


@pytest.mark.parametrize("big", [10**12, 3 * 10**18])
def test_a_fit_whose_starts_no_memory_holds_is_refused_up_front(big):
    """A fit runs all n_init starts of every candidate in one batch, so its memory grows with
    n_init: an n_init no machine's memory holds died in numpy's allocation ("array is too
    big", or MemoryError "Unable to allocate 43.7 TiB"). It is refused before anything is
    allocated, naming the memory, what the starts need at least, and how many starts would
    fill it; the model keeps its state (here: unfitted)."""
    x, y = _blobs(0, (10, 10), d=2)
    model = GaussianMixtureSet(2, 2, 3, n_init=big)
    with pytest.raises(
        ValueError,
        match=rf"Expected an n_init whose starts fit in the memory of cpu \(.* GiB\) but "
        rf"got {big}: .* at least .* GiB \(even \d+ starts would fill the memory\); pass a "
        "much smaller n_init",
    ):
        model.fit(x, y)
    assert not model.is_fitted


def test_each_candidate_keeps_its_best_initialisation():
    """Oracle: every candidate fitted alone from each of its n_init starts (the pure EM
    functions); the kept one is the best of them, and on these data the first start (the
    n_init=1 fit) is far from the best for several k."""
    x = _four_clusters()
    y = np.zeros(len(x), dtype=np.int64)
    n_init = 4
    one = GaussianMixtureSet(1, 2, 6, seed=0).fit(x, y)
    many = GaussianMixtureSet(1, 2, 6, seed=0, n_init=n_init).fit(x, y)
    worse = 0
    for k in range(1, 7):
        singles = [_one_init(many, x, 0, k, i) for i in range(n_init)]
        kept = float(many.fit_report_.log_likelihood[0, k - 1])
        # the same EM in a larger batch: equal up to the last bits of the sums
        assert kept == pytest.approx(max(singles), rel=1e-9, abs=1e-9)
        assert kept >= max(singles) - 1e-9 * abs(kept)
        first = float(one.fit_report_.log_likelihood[0, k - 1])
        assert first == pytest.approx(singles[0], rel=1e-9, abs=1e-9)
        worse += max(singles) > singles[0] + 1.0
    assert worse >= 2
    # and the criterion chooses among the kept candidates: here the four clusters
    assert one.n_components_.tolist() == [5] and many.n_components_.tolist() == [4]


def test_more_initialisations_never_fit_worse():
    """The first n starts of n_init=m (m > n) are those of n_init=n, so every candidate's
    log-likelihood can only rise with n_init, up to the last bits of a larger batch."""
    x, y = _blobs(3, (120, 70, 40))
    fits = [GaussianMixtureSet(3, 3, 6, seed=4, n_init=n).fit(x, y) for n in (1, 2, 5)]
    lls = [f.fit_report_.log_likelihood for f in fits]
    mask = fits[0].fit_report_.candidate_mask
    for low, high in zip(lls, lls[1:], strict=False):
        assert bool((high[mask] >= low[mask] - 1e-9 * low[mask].abs()).all())
    assert bool((lls[2][mask] > lls[0][mask] + 1e-3).any())  # the data do give it a chance


def test_the_better_optimum_is_the_one_scikit_learn_finds_with_n_init():
    """On data where the first k-means++ start ends in a poor local optimum (k = 2, 3, 4),
    n_init=10 finds the optimum scikit-learn's GaussianMixture(n_init=10) finds (same floor as
    reg_covar: the features are standardised), and n_init=1 does not."""
    x = _four_clusters()
    y = np.zeros(len(x), dtype=np.int64)
    one = GaussianMixtureSet(1, 2, 6, seed=0).fit(x, y)
    ten = GaussianMixtureSet(1, 2, 6, seed=0, n_init=10).fit(x, y)
    floor = ten.var_floor_.numpy()
    assert np.allclose(floor, floor[0], rtol=1e-12)
    for k in (2, 3, 4):
        gm = GaussianMixture(
            k, covariance_type="full", tol=ten.tol, max_iter=ten.max_iter,
            reg_covar=float(floor[0]), n_init=10, init_params="k-means++", random_state=0,
        ).fit(x)  # fmt: skip
        ll_sk = gm.score(x) * len(x)
        ll_ten = float(ten.fit_report_.log_likelihood[0, k - 1])
        ll_one = float(one.fit_report_.log_likelihood[0, k - 1])
        assert ll_ten == pytest.approx(ll_sk, abs=0.1)
        assert ll_one < ll_sk - 5.0


def test_a_state_loads_only_into_a_model_of_its_n_init():
    """A from-scratch refit of a loaded state fits with the model's n_init, so a state fitted
    with n_init=3 is refused by a model of another n_init, naming it, and loads into a fresh
    n_init=3 model (the buffers' shapes do not depend on n_init)."""
    x, y = _blobs(2, (60, 40))
    three = GaussianMixtureSet(2, 3, 4, seed=1, n_init=3).fit(x, y)
    plain = GaussianMixtureSet(2, 3, 4, seed=1)
    with pytest.raises(ValueError, match=r"with n_init=3, this one has n_init=1"):
        plain.load_state_dict(three.state_dict())
    assert not plain.is_fitted
    with pytest.raises(ValueError, match=r"with n_init=1, this one has n_init=3"):
        GaussianMixtureSet(2, 3, 4, seed=1, n_init=3).load_state_dict(
            GaussianMixtureSet(2, 3, 4, seed=1).fit(x, y).state_dict()
        )
    with pytest.raises(ValueError, match=r"with criterion='aic', n_init=3, this one has "):
        GaussianMixtureSet(2, 3, 4, seed=1, criterion="bic").load_state_dict(three.state_dict())
    back = GaussianMixtureSet(2, 3, 4, seed=1, n_init=3)
    back.load_state_dict(three.state_dict())
    assert _same_state(back, three)
    shapes = {k: v.shape for k, v in plain.state_dict().items()}
    assert shapes == {k: v.shape for k, v in three.state_dict().items()}
    # refits of the loaded state and of the live one are the same
    three.refit(x[:90], y[:90])
    back.refit(x[:90], y[:90])
    assert _same_state(back, three)


def test_n_init_counts_in_from_scratch_refits_only():
    """refit() fits an action from scratch (k-means++, n_init starts) as fit() does; a warm
    refit continues each kept candidate by one EM step, whatever n_init."""
    x, y = _blobs(5, (200, 150))
    n0 = 120
    three = GaussianMixtureSet(2, 3, 5, seed=2, n_init=3).fit(x[:n0], y[:n0])
    one = copy.deepcopy(three)
    one.n_init = 1  # the same kept candidates, refitted with one start
    for n in (130, 140):  # below refit_growth: warm refits
        three.refit(x[:n], y[:n])
        one.refit(x[:n], y[:n])
        assert three.fit_report_.refit_kind == ("warm", "warm")
        assert all(torch.equal(one.state_dict()[k], v) for k, v in three.state_dict().items())
    three.refit(x, y)  # grown past refit_growth: from scratch, three starts
    one.refit(x, y)
    assert three.fit_report_.refit_kind == ("scratch", "scratch")
    ref = GaussianMixtureSet(2, 3, 5, seed=2, n_init=3).fit(x, y)
    assert torch.equal(three.fit_report_.log_likelihood, ref.fit_report_.log_likelihood)
    assert not torch.equal(one.fit_report_.log_likelihood, ref.fit_report_.log_likelihood)


def test_ties_keep_the_first_initialisation_and_a_failed_one_is_never_kept():
    """The choice among a candidate's starts, on a made-up EM result (exact ties and a failed
    start cannot be set up through a fit: tied starts end in the same mixture): the highest
    final log-likelihood, the first start on ties, a non-finite one only when all are."""
    from torchcbl.gmm import _best_init

    # 1 group, 3 starts x 2 candidates; slot i * 2 + c
    loglik = torch.tensor([[-5.0, -7.0, -5.0, float("nan"), -6.0, -9.0]], dtype=torch.float64)
    g, s, k, d = 1, 6, 2, 1
    marker = torch.arange(s, dtype=torch.float64).reshape(1, s, 1)  # which slot was taken
    params = _em.Params(
        weights=marker.expand(g, s, k).clone(),
        means=marker.reshape(1, s, 1, 1).expand(g, s, k, d).clone(),
        covariances=torch.ones(g, s, k, d, d, dtype=torch.float64),
        log_det=torch.zeros(g, s, k, dtype=torch.float64),
        coef=torch.zeros(g, s, k, 3, dtype=torch.float64),
    )
    res = _em.EMResult(
        params, loglik, torch.arange(s).reshape(1, s), torch.ones(1, s, dtype=torch.bool)
    )
    best = _best_init(res, 3)
    # candidate 0: starts 0 and 1 tie at -5 -> start 0 (slot 0); candidate 1: -7, NaN, -9 ->
    # start 0 (slot 1), the NaN never
    assert best.loglik.tolist() == [[-5.0, -7.0]]
    assert best.n_iter.tolist() == [[0, 1]] and best.params.weights[0, :, 0].tolist() == [0.0, 1.0]
    all_bad = res._replace(loglik=torch.full((1, s), float("nan"), dtype=torch.float64))
    assert _best_init(all_bad, 3).n_iter.tolist() == [[0, 1]]  # reported as a failure later


@pytest.mark.parametrize("n_init", [1, 2])
def test_a_fit_whose_candidates_no_memory_holds_even_once_is_refused_naming_the_cap(n_init):
    """A cap of 1,000 components on 100,000 points of one action is an EM of 1,000 candidates
    over every point at once (at least 3 TB): with n_init=1 it was not checked and died in
    torch's allocator ("DefaultCPUAllocator: can't allocate memory", naming no argument, or
    the OS killed the process), and with n_init=2 it was refused saying "even 0 starts would
    fill the memory; pass a much smaller n_init", which no n_init mends. Either is refused
    before anything is allocated, naming the cap and the points; the model keeps its state."""
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(100_000, 1)), np.zeros(100_000, dtype=np.int64)
    model = GaussianMixtureSet(1, 1, 1000, n_init=n_init)
    with pytest.raises(
        ValueError,
        match=r"Expected a max_components whose candidates fit in the memory of cpu "
        r"\(.* GiB\) but got 1000: this fit's batched EM runs 1000 candidate\(s\) for 1 "
        r"action\(s\) of up to 100000 points at once, at least .* GiB for one start; pass a "
        r"smaller max_components \(or fit fewer points\)",
    ):
        model.fit(x, y)
    assert not model.is_fitted
