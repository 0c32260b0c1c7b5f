"""Property tests (hypothesis) for GaussianMixtureSet's invariants on arbitrary small data."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from torchcbl.gmm import GaussianMixtureSet


@st.composite
def datasets(draw):
    a = draw(st.integers(1, 4))
    d = draw(st.integers(1, 4))
    kmax = draw(st.integers(1, 5))
    counts = draw(st.lists(st.integers(0, 25), min_size=a, max_size=a))
    if sum(counts) == 0:
        counts[0] = 1
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    discrete = draw(st.booleans())
    scale = draw(st.sampled_from([1e-3, 1.0, 1e3]))
    xs = []
    for n in counts:
        x = rng.normal(loc=rng.normal(scale=3, size=d), size=(n, d)) * scale
        if discrete:
            x[:, -1] = rng.integers(0, 3, size=n)  # a lane-index-like feature
        xs.append(x)
    y = np.repeat(np.arange(a), counts)
    criterion = draw(st.sampled_from(["aic", "bic", "aic_paper"]))
    return a, d, kmax, np.concatenate(xs), y, criterion, seed


@settings(max_examples=40, deadline=None)
@given(datasets())
def test_fit_invariants(case):
    a, d, kmax, x, y, criterion, seed = case
    model = GaussianMixtureSet(a, d, kmax, criterion=criterion, seed=seed).fit(x, y)
    counts = np.bincount(y, minlength=a)
    k = model.n_components_
    assert k.shape == (a,)
    assert k.tolist() == [
        0 if n == 0 else int(model.criterion_[i].argmin()) + 1 for i, n in enumerate(counts)
    ]
    assert all(kk <= min(kmax, n) for kk, n in zip(k.tolist(), counts, strict=True))
    mask = model.component_mask_
    assert torch.equal(mask.sum(1), k)
    # weights of each fitted mixture sum to 1, padding is 0
    w = model.weights_
    assert (w[~mask] == 0).all()
    for i in range(a):
        if counts[i]:
            assert float(w[i].sum()) == pytest.approx(1.0, rel=1e-9)
    # covariances symmetric positive definite
    cov = model.covariances_[mask]
    torch.testing.assert_close(cov, cov.mT)
    assert (torch.linalg.eigvalsh(cov) > 0).all()
    # criterion table: finite exactly on the candidates
    cand = model.fit_report_.candidate_mask
    assert torch.isfinite(model.criterion_[cand]).all()
    assert torch.isinf(model.criterion_[~cand]).all()
    assert torch.equal(cand.sum(1), torch.from_numpy(np.minimum(counts, kmax)))
    # prediction: shapes, posteriors sum to 1, confidence in [0, 1], consistent with log_prob
    probe = np.concatenate([x[:7], x[:3] + 1.0])
    c = model.classify(probe)
    n = len(probe)
    assert c.action.shape == (n,) and c.posterior.shape == (n, a)
    torch.testing.assert_close(c.posterior.sum(1), torch.ones(n, dtype=torch.float64))
    assert ((c.confidence >= 0) & (c.confidence <= 1)).all()
    assert torch.isfinite(c.distance).all() and (c.distance >= 0).all()
    lp = model.log_prob(probe)
    assert lp.shape == (n, a) and not torch.isnan(lp).any()
    assert torch.equal(c.action, lp.argmax(1))
    assert all(counts[i] > 0 for i in c.action.tolist())


@settings(max_examples=15, deadline=None)
@given(datasets())
def test_state_dict_round_trip_property(case):
    a, d, kmax, x, y, criterion, seed = case
    model = GaussianMixtureSet(a, d, kmax, criterion=criterion, seed=seed).fit(x, y)
    fresh = GaussianMixtureSet(a, d, kmax, criterion=criterion, seed=seed)
    fresh.load_state_dict(model.state_dict())
    for big in (False, True):
        probe = np.concatenate([x] * (300 // len(x) + 1)) if big else x[:5]
        c1, c2 = model.classify(probe), fresh.classify(probe)
        for f1, f2 in zip(c1, c2, strict=True):
            assert torch.equal(f1, f2)
