"""GaussianMixtureSet: bad input is refused clearly; degenerate data fits without NaN."""

from __future__ import annotations

import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from torchcbl import AutoThresholdRule
from torchcbl.gmm import Classification, GaussianMixtureSet

ROOT = Path(__file__).resolve().parents[1]


def _data(seed: int = 0, n: int = 60, d: int = 3, a: int = 3):
    rng = np.random.default_rng(seed)
    y = np.arange(n) % a
    x = rng.normal(size=(n, d)) + y[:, None] * 3.0
    return x, y


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_actions": 0}, "n_actions"),
        ({"n_features": -1}, "n_features"),
        ({"max_components": 0}, "max_components"),
        ({"max_iter": 0}, "max_iter"),
        ({"criterion": "aicc"}, "criterion"),
        ({"var_floor": -1.0}, "var_floor"),
        ({"var_floor": math.nan}, "var_floor"),
        ({"tol": 0.0}, "tol"),
        # a bool was taken as the number it equals: var_floor=True fitted with a floor of 1.0
        ({"var_floor": True}, "var_floor"),
        ({"var_floor": False}, "var_floor"),
        ({"tol": True}, "tol"),
        ({"seed": 1.5}, "seed"),
    ],
)
def test_constructor_rejects_bad_arguments(kwargs, match):
    args = {"n_actions": 2, "n_features": 2} | kwargs
    with pytest.raises(ValueError, match=match):
        GaussianMixtureSet(**args)


@pytest.mark.parametrize(("n_features", "cap"), [(4, 10**6), (1, 10**9), (200, 10**5), (10**5, 10)])
def test_sizes_whose_model_no_memory_holds_are_refused_naming_them(n_features, cap):
    """The model keeps every candidate's parameters in buffers of n_actions x max_components^2
    rows (``cand_covariances_`` [A, K, K, D, D], ...), allocated by the constructor: a cap of
    a million components in 4-D (a petabyte), or 100,000 features, died in torch's allocator
    ("DefaultCPUAllocator: can't allocate memory", naming no argument), or got the process
    killed where the OS overcommits. They are refused before anything is allocated, naming
    the sizes, the memory and what the buffers need at least; sizes that fit build as before."""
    with pytest.raises(
        ValueError,
        match=rf"Expected sizes whose model fits in the memory of the host \(.* GiB\) but got "
        rf"n_actions=3, n_features={n_features}, max_components={cap}: .* at least .* GiB; "
        "pass a smaller max_components .* or fewer features",
    ):
        GaussianMixtureSet(3, n_features, cap)
    assert GaussianMixtureSet(3, min(n_features, 50), 20).max_components == 20


def _fitted():
    x, y = _data()
    return GaussianMixtureSet(3, 3, 4).fit(x, y), x, y


@pytest.mark.parametrize(
    ("obs", "exc", "match"),
    [
        (np.zeros(3), ValueError, r"expected shape \[N, 3\].*got shape \(3,\).*obs\[None, :\]"),
        (np.zeros((2, 4)), ValueError, r"n_features=3.*got shape \(2, 4\)"),
        (np.zeros((0, 3)), ValueError, "N >= 1"),
        (np.zeros((2, 3), dtype=complex), TypeError, "complex"),
        (np.array([["a", "b", "c"]]), TypeError, "real numbers"),
        (np.zeros((2, 3), dtype=bool), TypeError, "bool"),
    ],
)
def test_bad_observations_are_refused_everywhere(obs, exc, match):
    model, _, _ = _fitted()
    for call in (model.classify, model.log_prob):
        with pytest.raises(exc, match=match):
            call(obs)
    with pytest.raises(exc, match=match):
        model.fit(obs, np.zeros(len(obs) if obs.ndim else 1, dtype=int))


def test_a_one_dimensional_array_gets_the_reshape_that_fits_it():
    """A 1-D array was always told "pass one observation as obs[None, :]": with one feature,
    100 values (100 observations, as scikit-learn users pass them) were sent to obs[None, :],
    whose shape (1, 100) is refused again. Now the hint depends on the case, and an array
    that fits neither gets none."""
    rng = np.random.default_rng(0)
    x1 = rng.normal(size=100)
    y = (x1 > 0).astype(int)
    one = GaussianMixtureSet(2, 1, 3)
    for call in (lambda: one.fit(x1, y), lambda: one.classify(x1)):
        with pytest.raises(ValueError, match=r"got shape \(100,\); .*x\.reshape\(-1, 1\)"):
            call()
    fitted = one.fit(x1.reshape(-1, 1), y)  # the hint's shape works
    assert fitted.log_prob(x1.reshape(-1, 1)).shape == (100, 2)
    three, _, _ = _fitted()
    with pytest.raises(ValueError, match=r"got shape \(7,\)$"):
        three.classify(np.zeros(7))


def test_nan_and_inf_rows_are_named():
    model, x, y = _fitted()
    bad = x.copy()
    bad[4, 1] = np.nan
    bad[9, 0] = np.inf
    with pytest.raises(ValueError, match=r"rows \[4, 9\] contain NaN or inf"):
        model.fit(bad, y)
    with pytest.raises(ValueError, match=r"rows \[4, 9\]"):
        model.classify(torch.from_numpy(bad))


@pytest.mark.parametrize(
    ("actions", "exc", "match"),
    [
        (
            lambda y: np.where(np.arange(len(y)) == 5, 3, y),
            ValueError,
            r"values \[3\] at rows \[5\]",
        ),
        (lambda y: np.where(np.arange(len(y)) == 2, -1, y), ValueError, r"\[0, 3\).*\[-1\]"),
        (lambda y: y.astype(float), TypeError, "integer labels"),
        (lambda y: y[:-1], ValueError, r"expected shape \[60\]"),
        (lambda y: y[:, None], ValueError, r"expected shape \[60\]"),
    ],
)
def test_bad_actions_are_refused(actions, exc, match):
    x, y = _data()
    with pytest.raises(exc, match=match):
        GaussianMixtureSet(3, 3, 4).fit(x, actions(y))


def test_failed_fit_leaves_the_previous_model_untouched():
    model, x, y = _fitted()
    before = {k: v.clone() for k, v in model.state_dict().items()}
    report = model.fit_report_
    bad = x.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError):
        model.fit(bad, y)
    with pytest.raises(ValueError):
        model.fit(x, y + 5)
    for k, v in model.state_dict().items():
        assert torch.equal(v, before[k]), k
    assert model.fit_report_ is report


def test_fit_report_counts_one_point_and_one_candidate_in_the_singular():
    """FitReport's text said "1 points", "of 1 candidates" and "1 candidate(s) did not
    converge"; it counts as the other messages do (torchcbl._text.counted)."""
    rng = np.random.default_rng(0)
    x = np.r_[rng.normal(size=(1, 2)), rng.normal(size=(30, 2)) + 5]
    y = np.r_[0, np.ones(30, dtype=np.int64)]
    text = str(GaussianMixtureSet(2, 2, 2, max_iter=2).fit(x, y).fit_report_)
    assert "action 0: 1 point, chose k=1 of 1 candidate (1 converged, scratch)" in text, text
    assert "action 1: 30 points, chose k=1 of 2 candidates (1 converged, scratch)" in text, text
    assert "note: 1 candidate did not converge in max_iter=2: (action 1, k=2)" in text, text
    text = str(GaussianMixtureSet(2, 2, 2, max_iter=1).fit(x, y).fit_report_)
    assert "note: 3 candidates did not converge in max_iter=1" in text, text


def test_action_without_data_is_never_predicted_and_reported():
    x, y = _data(a=2)  # labels 0, 1 only, model has 3 actions
    model = GaussianMixtureSet(3, 3, 4).fit(x, y)
    assert model.n_components_[2] == 0
    assert model.fit_report_.empty_actions == (2,)
    assert any("action 2 has no data" in n for n in model.fit_report_.notes)
    assert "action 2: no data" in str(model.fit_report_)
    probe = np.random.default_rng(1).normal(scale=10, size=(50, 3))
    lp = model.log_prob(probe)
    assert torch.isneginf(lp[:, 2]).all() and torch.isfinite(lp[:, :2]).all()
    c = model.classify(probe)
    assert (c.action != 2).all() and (c.posterior[:, 2] == 0).all()
    assert float(model.aic()[2]) == 0.0
    # held-out points of the action without data: likelihood 0, so +inf, never NaN
    for crit in (model.aic(probe, np.arange(50) % 3), model.bic(probe, np.arange(50) % 3)):
        assert torch.isfinite(crit[:2]).all() and torch.isposinf(crit[2])


def test_low_precision_tensors_are_read_as_the_numbers_they_hold():
    x, y = _data(a=2)
    model = GaussianMixtureSet(2, 3, 3).fit(x, y)
    for dtype in (torch.bfloat16, torch.float16):
        t = torch.as_tensor(x[:20]).to(dtype)
        want = model.classify(t.to(torch.float64))
        got = model.classify(t)
        assert torch.equal(got.action, want.action) and torch.equal(got.distance, want.distance)


def test_degenerate_actions_fit_without_nan():
    rng = np.random.default_rng(3)
    x0 = rng.normal(size=(30, 3))
    x0[:, 2] = rng.integers(0, 5, size=30)  # a discrete feature (lane index)
    x1 = np.tile([[1.0, 2.0, 3.0]], (7, 1))  # all-identical points
    x2 = np.array([[5.0, -1.0, 2.0]])  # a single point
    x = np.concatenate([x0, x1, x2])
    y = np.r_[np.zeros(30, int), np.ones(7, int), [2]]
    model = GaussianMixtureSet(3, 3, 6).fit(x, y)
    for t in model.state_dict().values():
        if t.is_floating_point():
            assert not torch.isnan(t).any()
    assert model.n_components_.tolist()[1:] == [1, 1]
    c = model.classify(x)
    assert torch.isfinite(c.distance).all() and not torch.isnan(c.posterior).any()
    # the identical points and the single point are classified as their own action
    assert (c.action[30:] == torch.tensor([1] * 7 + [2])).all()
    # floor: var_floor * feature variance + 1e-6 * mean variance, on the diagonal
    var = x.var(0)
    np.testing.assert_allclose(model.var_floor_.numpy(), 1e-3 * var + 1e-6 * var.mean())
    np.testing.assert_allclose(model.covariances_[2, 0].numpy(), np.diag(model.var_floor_))


def test_all_data_identical_everywhere():
    x = np.ones((5, 2))
    model = GaussianMixtureSet(2, 2, 3).fit(x, np.array([0, 0, 0, 1, 1]))
    c = model.classify(x)
    assert torch.isfinite(c.distance).all() and (c.distance == 0).all()
    torch.testing.assert_close(c.posterior[0], torch.tensor([0.6, 0.4], dtype=torch.float64))


def test_float32_and_int_inputs_and_torch_labels():
    x, y = _data()
    ref = GaussianMixtureSet(3, 3, 4).fit(x.astype(np.float32).astype(np.float64), y)
    m = GaussianMixtureSet(3, 3, 4).fit(torch.from_numpy(x.astype(np.float32)), torch.from_numpy(y))
    for k, v in ref.state_dict().items():
        assert torch.equal(v, m.state_dict()[k]), k
    c = m.classify(np.round(x).astype(np.int32))
    assert c.action.dtype == torch.long and c.distance.dtype == torch.float64


def test_read_only_arrays_are_read_without_a_warning():
    """A read-only array (np.load(..., mmap_mode="r"), np.broadcast_to, a JAX or
    copy-on-write pandas array) went to torch.from_numpy as it was: fit, refit and the
    classify/log_prob of a batch of more than 256 rows warned "The given NumPy array is not
    writable ... writing to this tensor will result in undefined behavior" (an error under
    -W error). The data are read, never written: they are now copied first when read-only."""
    x, y = _data(n=300)
    x.setflags(write=False)
    y.setflags(write=False)
    warn_always = torch.is_warn_always_enabled()
    torch.set_warn_always(True)  # torch warns once per process otherwise
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            model = GaussianMixtureSet(3, 3, 4).fit(x, y)
            model.refit(x, y)
            c = model.classify(x)
            lp = model.log_prob(x)
            aic = model.aic(x, y)
    finally:
        torch.set_warn_always(warn_always)
    ref = GaussianMixtureSet(3, 3, 4).fit(x.copy(), y.copy())
    for k, v in ref.state_dict().items():
        assert torch.equal(v, model.state_dict()[k]), k
    assert all(torch.equal(a, b) for a, b in zip(c, ref.classify(x.copy()), strict=True))
    assert torch.equal(lp, ref.log_prob(x.copy())) and torch.equal(aic, ref.aic(x.copy(), y))


def test_a_policy_reads_a_read_only_observation_without_a_warning():
    """GreedyPolicy handed a read-only observation (a row of an np.load(mmap_mode="r")
    dataset, an env's frozen buffer) to torch.as_tensor as it was: "The given NumPy array is
    not writable" at every call (an error under -W error)."""
    from torchcbl import GreedyPolicy

    x, y = _data(n=60)
    policy = GreedyPolicy(GaussianMixtureSet(3, 3, 2).fit(x, y))
    row = x[7].copy()
    row.setflags(write=False)
    warn_always = torch.is_warn_always_enabled()
    torch.set_warn_always(True)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            action = policy(row)
    finally:
        torch.set_warn_always(warn_always)
    assert action == policy(x[7].copy())


def test_a_policy_reads_a_tensor_observation_as_the_numbers_it_holds():
    """GreedyPolicy read every observation with np.asarray, so a tensor from a network in the
    loop failed with torch's own words: requires_grad=True "Can't call numpy() on Tensor that
    requires grad", bfloat16 "Got unsupported ScalarType BFloat16" (the model's classify
    takes both). It now reads it as the model does: its values as float64, without autograd."""
    from torchcbl import GreedyPolicy

    x, y = _data(n=60)
    policy = GreedyPolicy(GaussianMixtureSet(3, 3, 2).fit(x, y))
    for i in (0, 7, 31):
        for t in (
            torch.tensor(x[i], requires_grad=True),
            torch.tensor(x[i], dtype=torch.float32, requires_grad=True),
            torch.tensor(x[i], dtype=torch.bfloat16),
            torch.tensor(x[i], dtype=torch.bfloat16, requires_grad=True),
            torch.tensor(x[i], dtype=torch.float16),
        ):
            values = t.detach().double().numpy()  # the numbers the tensor holds
            got, want = policy.classify(t), policy.classify(values)
            assert all(torch.equal(a, b) for a, b in zip(got, want, strict=True)), t.dtype
            assert policy(t) == policy(values) and not got.confidence.requires_grad
            assert t.grad is None
        assert policy(torch.tensor(x[i], requires_grad=True)) == policy(x[i])
    with pytest.raises(ValueError, match=r"GreedyPolicy: expected one observation of shape"):
        policy(torch.zeros(1, 3, requires_grad=True))  # a batch is still refused as before


@pytest.mark.parametrize(
    "obs",
    [
        [True, False, True],
        np.array([True, False, True]),
        torch.tensor([True, False, True]),
        ["1", "2", "3"],
        np.array(["1", "2", "3"]),
        np.array([1 + 1j, 2, 3]),
        torch.tensor([1 + 1j, 2, 3]),
        [1 + 0j, 2, 3],
    ],
    ids=["bools", "bool array", "bool tensor", "strings", "str array", "complex array",
         "complex tensor", "complex list"],
)  # fmt: skip
def test_a_policy_refuses_the_observations_classify_refuses(obs):
    """GreedyPolicy read every observation as float64: bools as 0/1, strings ("1") as the
    numbers they spell, and complex arrays and tensors without their imaginary part (numpy's
    ComplexWarning, torch's UserWarning), answering an action where model.classify refuses
    the same observation as a batch; a list of Python complex numbers failed with float()'s
    own words. It refuses them as classify does: a TypeError naming the dtype and the
    conversion, and no warning."""
    from torchcbl import GreedyPolicy

    x, y = _data(n=60)
    model = GaussianMixtureSet(3, 3, 2).fit(x, y)
    policy = GreedyPolicy(model)
    batch = obs[None] if isinstance(obs, (np.ndarray, torch.Tensor)) else [obs]
    with pytest.raises(TypeError, match=r"observations: expected real numbers .* but got dtype"):
        model.classify(batch)
    for call in (policy, policy.classify):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with pytest.raises(
                TypeError,
                match=r"GreedyPolicy: expected an observation of real numbers \(float32/float64 "
                r"or integers\) but got dtype \S+; convert with ",
            ):
                call(obs)
    for fine in ([1, 2, 3], np.array([1, 2, 3], dtype=np.uint8), torch.tensor([1, 2, 3])):
        assert policy(fine) == policy(np.array([1.0, 2.0, 3.0]))


def test_single_observation_path_matches_batch_path():
    model, x, _ = _fitted()
    probe = np.random.default_rng(5).normal(scale=4, size=(40, 3)) + 3
    batch = model.classify(probe)
    for i in range(len(probe)):
        one = model.classify(probe[i : i + 1])
        assert isinstance(one, Classification) and one.action.shape == (1,)
        assert int(one.action[0]) == int(batch.action[i])
        for f in ("confidence", "distance", "posterior"):
            torch.testing.assert_close(getattr(one, f)[0], getattr(batch, f)[i])


def test_single_observation_path_weighs_unbalanced_priors_like_the_batch_path():
    """With unbalanced classes (priors 0.8 / 0.15 / 0.05) over overlapping clusters, the
    one-row path (the teaching loop's) gives the batch path's action, posterior, confidence
    and distance row for row: the prior Pr(G_a) of Eq. 7 counts on both."""
    rng = np.random.default_rng(11)
    y = np.repeat([0, 1, 2], [160, 30, 10])
    x = rng.normal(size=(len(y), 2)) + y[:, None] * 0.8  # overlapping: the prior can decide
    model = GaussianMixtureSet(3, 2, 2, seed=0).fit(x, y)
    probe = rng.normal(scale=1.5, size=(30, 2)) + 0.8
    batch = model.classify(probe)
    uniform = torch.softmax(model.log_prob(probe) - model.log_prior_, dim=1)
    assert not torch.allclose(uniform, batch.posterior)  # the prior moves these posteriors
    for i in range(len(probe)):
        one = model.classify(probe[i : i + 1])
        assert int(one.action[0]) == int(batch.action[i]), i
        for f in ("confidence", "distance", "posterior"):
            torch.testing.assert_close(getattr(one, f)[0], getattr(batch, f)[i])


def test_aic_requires_both_or_neither_and_a_fit():
    with pytest.raises(RuntimeError, match="fit"):
        GaussianMixtureSet(2, 2).aic()
    model, x, _ = _fitted()
    with pytest.raises(ValueError, match="both"):
        model.aic(x)


def _nearest_real_component(model: GaussianMixtureSet, x: np.ndarray) -> tuple[int, float]:
    """(action, Mahalanobis distance) of the nearest real component, computed directly on
    x / s (s = max |x|) and scaled back, so that no square overflows."""
    s = max(float(np.abs(x).max()), 1.0)
    best = (math.inf, -1)
    for a in range(model.n_actions):
        for k in range(int(model.n_components_[a])):
            u = model.precisions_cholesky_[a, k].numpy()
            d = s * float(np.linalg.norm((x / s - model.means_[a, k].numpy() / s) @ u))
            best = min(best, (d, a))
    return best[1], best[0]


@pytest.mark.parametrize(
    ("d", "value"),
    [
        (2, 1e153),  # the real components' squares overflow, the padding's do not
        (10, 1e148),  # no square overflows, but every real score is below the padding's
    ],
)
def test_very_far_rows_are_never_decided_by_the_padding_components(d, value):
    """Slots beyond an action's component count hold a padding component (mean 0, unit
    covariance, log weight -1e300). Far enough away the real components scored below it (or
    overflowed to -inf while it did not), and every path (one row, a batch, the torch path
    beyond 256 rows) answered the padding's distance, posterior 1/2 each and its log-density
    (before 2026-11-27)."""
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 0.02, (200, d))
    y = np.arange(200) % 2
    x[y == 1] += 0.3
    model = GaussianMixtureSet(2, d, 3, seed=0).fit(x, y)
    assert (model.n_components_ < 3).all()  # padding slots exist
    q = np.full((1, d), value)
    want_a, want_d = _nearest_real_component(model, q[0])
    for rows in (q, np.repeat(q, 3, axis=0), np.repeat(q, 300, axis=0)):
        c = model.classify(rows)
        assert c.action.tolist() == [want_a] * len(rows)
        assert c.distance.tolist() == pytest.approx([want_d] * len(rows), rel=1e-9)
        assert c.posterior[:, want_a].tolist() == [1.0] * len(rows)
        lp = model.log_prob(rows)
        # the real mixtures' log-density: far below the padding's -1e300 - |x|^2 / 2
        assert bool((lp[:, want_a] >= lp[:, 1 - want_a]).all())
        assert not bool((lp > -1.001e300).any()) and not torch.isnan(lp).any()


def test_a_model_converted_from_float64_refuses_its_first_fit_too():
    """fit/refit need the float64 state; an unfitted model converted to float32 was fitted
    once (into float32 buffers) and refused every later fit, e.g. at the teaching loop's
    second refit (before 2026-11-27)."""
    x, y = _data()
    for dtype in (torch.float32, torch.float16):
        model = GaussianMixtureSet(3, 3, 4).to(dtype)
        for call in (model.fit, model.refit):
            with pytest.raises(TypeError, match=r"float64 state.*\.to\(torch\.float64\)"):
                call(x, y)
        assert not model.is_fitted
        model.to(torch.float64).fit(x, y).fit(x, y)  # and back: fits as usual


def test_numpy_float_settings_are_the_python_numbers_they_hold():
    """var_floor=np.float32(0.01) was refused as 'Expected var_floor to be a finite float >= 0
    but got np.float32(0.01)' (tol and refit_growth alike; the int arguments took numpy ints)
    before 2026-11-27."""
    model = GaussianMixtureSet(
        2, 2, np.int64(3), var_floor=np.float32(0.01), tol=np.float64(1e-4),
        refit_growth=np.int32(1), seed=np.uint32(5),
    )  # fmt: skip
    assert type(model.var_floor) is float and model.var_floor == float(np.float32(0.01))
    assert type(model.refit_growth) is float and model.refit_growth == 1.0
    x, y = _data(a=2, d=2)
    fresh = GaussianMixtureSet(2, 2, 3, var_floor=float(np.float32(0.01)), tol=1e-4,
                               refit_growth=1.0, seed=5)  # fmt: skip
    fresh.load_state_dict(model.fit(x, y).state_dict())  # the same settings
    with pytest.raises(ValueError, match="var_floor"):
        GaussianMixtureSet(2, 2, var_floor=np.bool_(True))


def test_parameters_a_dtype_cannot_hold_are_refused_not_answered_with_nan():
    """A fitted model converted to float16 (or a state_dict holding NaN) classified every
    observation with distance NaN, log_prob NaN and an arbitrary action, without a word: a
    mean beyond float16's 65504 or a standard deviation below ~1.5e-5 overflows to inf there
    (before 2026-11-27). Now such a model refuses to predict, naming the buffers and what to
    do; a float16 model whose parameters fit still classifies."""
    rng = np.random.default_rng(0)
    y = np.arange(60) % 3
    offset = rng.normal(size=(60, 2)) + 1e5 + y[:, None]  # means beyond 65504
    tiny = (rng.normal(size=(60, 2)) + y[:, None]) * 1e-5  # precisions beyond 65504
    for x, bad in ((offset, "means_"), (tiny, "precisions_cholesky_")):
        model = GaussianMixtureSet(3, 2, 3).fit(x, y)
        half = GaussianMixtureSet(3, 2, 3).to(torch.float16)
        half.load_state_dict(model.state_dict())
        for rows in (x[:1], x[:5], np.tile(x, (5, 1))):  # the N = 1, numpy and torch paths
            for call in (half.classify, half.log_prob):
                with pytest.raises(RuntimeError, match=rf"non-finite.*{bad}.*float16.*float64"):
                    call(rows)
        with pytest.raises(RuntimeError, match="non-finite"):
            half.aic(x, y)
        back = half.to(torch.float64)  # converting back cannot restore them
        with pytest.raises(RuntimeError, match=rf"{bad}.*round trip through float16"):
            back.classify(x)
    x, y = _data()
    model = GaussianMixtureSet(3, 3, 4).fit(x, y)
    state = {k: v.clone() for k, v in model.state_dict().items()}
    state["weights_"][0, 0] = math.nan
    damaged = GaussianMixtureSet(3, 3, 4)
    damaged.load_state_dict(state)
    with pytest.raises(RuntimeError, match=r"weights_: .*NaN or inf"):
        damaged.classify(x)
    half = GaussianMixtureSet(3, 3, 4).to(torch.float16)
    half.load_state_dict(model.state_dict())
    c = half.classify(x)
    assert bool(torch.isfinite(c.distance).all()) and (c.action == model.classify(x).action).all()


_PEAK_SCRIPT = """
import resource, sys
import numpy as np
from torchcbl.gmm import GaussianMixtureSet
rng = np.random.default_rng(0)
y = np.arange(400) % 4
x = rng.normal(size=(400, 3)) * (1 + np.arange(400) % 7)[:, None] + y[:, None] * 3
model = GaussianMixtureSet(4, 3, 20, var_floor=0.0).fit(x, y)
assert min(model.n_components_.tolist()) >= 15, model.n_components_
q = rng.normal(size=(300_000, 3)) * 5
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
c = model.classify(q)
lp = model.log_prob(q)
print((resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="ru_maxrss in KiB: Linux")
def test_a_large_batch_is_scored_in_bounded_memory():
    """classify/log_prob of N observations held an [N, A*K*D] float64 array and its square
    at once: 300,000 points (7 MB) of a 4-action, 3-D model with k <= 20 raised the process's
    peak memory by 1.3 GB, a 1000 x 1000 decision map by ~5 GB (before 2026-11-27). Now a large
    batch is scored in blocks of rows (peak ~0.35 GB here, whatever N), with the same answers."""
    out = subprocess.run(
        [sys.executable, "-c", _PEAK_SCRIPT], capture_output=True, text=True, check=True, cwd=ROOT
    )
    assert float(out.stdout.split()[-1]) < 700.0  # MiB
    rng = np.random.default_rng(1)
    y = np.arange(400) % 4
    x = rng.normal(size=(400, 3)) + y[:, None] * 3
    model = GaussianMixtureSet(4, 3, 20).fit(x, y)
    q = rng.normal(size=(150_000, 3)) * 4
    q[-1] = 1e200  # a far row in the last block: scored exactly there
    big, lp = model.classify(q), model.log_prob(q)
    assert big.action.shape == (150_000,) and lp.shape == (150_000, 4)
    for start in range(0, len(q), 30_000):  # the same rows in smaller batches
        sl = slice(start, start + 30_000)
        c = model.classify(q[sl])
        assert torch.equal(c.action, big.action[sl])
        torch.testing.assert_close(c.distance, big.distance[sl], rtol=1e-12, atol=0)
        torch.testing.assert_close(c.posterior, big.posterior[sl], rtol=1e-12, atol=1e-300)
        torch.testing.assert_close(model.log_prob(q[sl]), lp[sl], rtol=1e-12, atol=0)


@pytest.mark.parametrize(
    ("wrap", "fix"),
    [
        (lambda a: a, ".astype(int)"),
        (torch.from_numpy, ".long()"),
        (lambda a: a.tolist(), "numpy.asarray(actions, dtype=int)"),
    ],
)
def test_labels_of_the_wrong_dtype_get_the_conversion_their_container_has(wrap, fix):
    """Float labels were told "convert with .astype(int)" whatever held them: a torch tensor
    has no .astype (an AttributeError for whoever followed the advice), nor has a list."""
    x, y = _data()
    model = GaussianMixtureSet(3, 3, 4)
    with pytest.raises(TypeError, match="integer labels") as err:
        model.fit(x, wrap(y.astype(np.float32)))
    assert str(err.value).endswith(f"convert with {fix}")
    model.fit(x, y)
    with pytest.raises(TypeError, match="integer labels") as err:
        AutoThresholdRule().update(model, x, wrap(y.astype(np.float32)))
    assert f"convert with {fix}" in str(err.value)


@pytest.mark.parametrize(
    ("wrap", "fix"),
    [
        (lambda a: a, ".astype(float)"),
        (torch.from_numpy, ".double()"),
        (lambda a: a.tolist(), "numpy.asarray(observations, dtype=float)"),
    ],
)
def test_observations_of_the_wrong_dtype_get_the_conversion_their_container_has(wrap, fix):
    x, y = _data()
    with pytest.raises(TypeError, match="real numbers") as err:
        GaussianMixtureSet(3, 3, 4).fit(wrap(x.astype(np.complex64)), y)
    assert str(err.value).endswith(f"convert with {fix}")
