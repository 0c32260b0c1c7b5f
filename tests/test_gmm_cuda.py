"""The GMM set on a CUDA device agrees with the same model on the CPU.

Skipped where torch sees no CUDA device (this project's CI machines); run on a machine with a GPU
(``pytest tests/test_gmm_cuda.py``). The oracle is the CPU fit of the same data and seed: both
work in float64, so they differ only in the order of floating-point sums (GPU reductions), which
moves the last bits, not the chosen model.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchcbl.gmm import GaussianMixtureSet

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")


def _data(seed: int = 0, n_per: int = 400, d: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Three actions, each a mixture of three well-separated Gaussians (standardised)."""
    rng = np.random.default_rng(seed)
    xs = []
    for _ in range(3):
        centres = rng.normal(scale=4.0, size=(3, d))
        comp = rng.integers(0, 3, size=n_per)
        xs.append(centres[comp] + rng.normal(scale=0.5, size=(n_per, d)))
    x = np.concatenate(xs)
    x = (x - x.mean(0)) / x.std(0)
    return x, np.repeat(np.arange(3), n_per)


def _fit(device: str, x: np.ndarray, y: np.ndarray) -> GaussianMixtureSet:
    return GaussianMixtureSet(3, x.shape[1], 8, tol=1e-6, max_iter=300, seed=3).to(device).fit(x, y)


def test_fit_on_cuda_selects_the_cpu_model_and_stays_on_the_device() -> None:
    x, y = _data()
    cpu, gpu = _fit("cpu", x, y), _fit("cuda", x, y)
    assert gpu.means_.device.type == "cuda"
    assert gpu.n_components_.cpu().tolist() == cpu.n_components_.tolist()
    ll_cpu = cpu.fit_report_.log_likelihood
    ll_gpu = gpu.fit_report_.log_likelihood.cpu()
    real = cpu.fit_report_.candidate_mask
    # every candidate's total log-likelihood, not only the chosen ones
    np.testing.assert_allclose(ll_gpu[real].numpy(), ll_cpu[real].numpy(), rtol=1e-6)
    np.testing.assert_allclose(gpu.means_.cpu().numpy(), cpu.means_.numpy(), atol=1e-6)


def test_classify_on_cuda_matches_cpu_for_small_and_large_batches() -> None:
    x, y = _data()
    cpu, gpu = _fit("cpu", x, y), _fit("cuda", x, y)
    rng = np.random.default_rng(1)
    for n in (5, 5000):  # below and above the numpy path's row limit
        q = rng.normal(scale=1.5, size=(n, x.shape[1]))
        c, g = cpu.classify(q), gpu.classify(q)
        assert torch.equal(g.action.cpu(), c.action)
        np.testing.assert_allclose(g.distance.cpu().numpy(), c.distance.numpy(), rtol=1e-6)
        np.testing.assert_allclose(g.posterior.cpu().numpy(), c.posterior.numpy(), atol=1e-9)


def test_a_cuda_state_dict_loads_into_a_fresh_cpu_model() -> None:
    x, y = _data()
    gpu = _fit("cuda", x, y)
    fresh = GaussianMixtureSet(3, x.shape[1], 8, tol=1e-6, max_iter=300, seed=3)
    fresh.load_state_dict({k: v.cpu() for k, v in gpu.state_dict().items()})
    q = np.random.default_rng(2).normal(size=(300, x.shape[1]))
    g, f = gpu.classify(q), fresh.classify(q)
    assert torch.equal(g.action.cpu(), f.action)
    np.testing.assert_allclose(g.distance.cpu().numpy(), f.distance.numpy(), rtol=1e-12)


def test_incremental_refit_on_cuda_tracks_the_cpu_refit() -> None:
    x, y = _data(n_per=300)
    x2, y2 = _data(seed=5, n_per=60)
    xa, ya = np.concatenate([x, x2]), np.concatenate([y, y2])
    cpu, gpu = _fit("cpu", x, y), _fit("cuda", x, y)
    cpu.refit(xa, ya)
    gpu.refit(xa, ya)
    assert gpu.n_components_.cpu().tolist() == cpu.n_components_.tolist()
    np.testing.assert_allclose(gpu.means_.cpu().numpy(), cpu.means_.numpy(), atol=1e-6)


def test_every_confidence_rule_judges_a_cuda_models_answer_as_the_cpu_models() -> None:
    """The rules keep their thresholds on the CPU; a CUDA model's classification must not trip
    a device mismatch in any of them (AutoThresholdRule indexed CPU thresholds with CUDA
    actions before 2026-11-26)."""
    from torchcbl.confidence import AutoThresholdRule, DistanceRule, PosteriorRule

    x, y = _data()
    cpu, gpu = _fit("cpu", x, y), _fit("cuda", x, y)
    for make in (DistanceRule, PosteriorRule, AutoThresholdRule):
        rule_cpu, rule_gpu = make(), make()
        if isinstance(rule_cpu, AutoThresholdRule):
            rule_cpu.update(cpu, x, y)
            rule_gpu.update(gpu, x, y)
            assert torch.allclose(rule_cpu.thresholds, rule_gpu.thresholds)
        a = rule_cpu.is_confident(cpu.classify(x), x)
        b = rule_gpu.is_confident(gpu.classify(x), x)
        assert (a.cpu() == b.cpu()).float().mean() > 0.999, make.__name__


def test_a_far_observation_classifies_on_cuda_as_on_the_cpu() -> None:
    """A row whose squared distances overflow is scored exactly in numpy (_classify_far); a
    CUDA model had no numpy tables for it and raised KeyError 'np' (before 2026-11-27)."""
    x, y = _data()
    cpu, gpu = _fit("cpu", x, y), _fit("cuda", x, y)
    q = np.zeros((3, x.shape[1]))
    q[0, 0] = 1e155
    for rows in (q[:1], q, np.repeat(q, 100, axis=0)):  # one row, a batch, the torch path
        c, g = cpu.classify(rows), gpu.classify(rows)
        assert torch.equal(g.action.cpu(), c.action)
        np.testing.assert_allclose(g.distance.cpu().numpy(), c.distance.numpy(), rtol=1e-6)
        assert torch.isfinite(g.posterior).all()
        lc, lg = cpu.log_prob(rows), gpu.log_prob(rows)
        assert torch.equal(torch.isinf(lg.cpu()), torch.isinf(lc))


def test_a_cuda_fit_and_refit_repeat_bit_for_bit() -> None:
    """Same data and seed on the same GPU: the same model to the last bit (the README's
    determinism note), for a fit large enough to spread its sums over many blocks."""
    x, y = _data(n_per=3000, d=6)
    more, more_y = _data(seed=7, n_per=200, d=6)
    models = []
    for _ in range(2):
        m = _fit("cuda", x, y)
        one = {k: v.clone() for k, v in m.state_dict().items()}
        m.refit(np.concatenate([x, more]), np.concatenate([y, more_y]))
        models.append((one, m.state_dict(), m.classify(more)))
    (fit_a, refit_a, cls_a), (fit_b, refit_b, cls_b) = models
    for a, b in ((fit_a, fit_b), (refit_a, refit_b)):
        assert a.keys() == b.keys()
        for key in a:
            assert torch.equal(a[key], b[key]), key
    assert torch.equal(cls_a.distance, cls_b.distance)
    assert torch.equal(cls_a.posterior, cls_b.posterior)


def _fit_n_init(device: str, x: np.ndarray, y: np.ndarray, n_init: int) -> GaussianMixtureSet:
    model = GaussianMixtureSet(3, x.shape[1], 8, tol=1e-6, max_iter=300, seed=3, n_init=n_init)
    return model.to(device).fit(x, y)


def test_an_n_init_fit_on_cuda_keeps_the_cpu_models_starts() -> None:
    """n_init > 1 batches every start of every candidate side by side (_best_init picks the
    best per candidate): on CUDA the same start must win as on the CPU, so the chosen model
    and each candidate's log-likelihood agree, and the state holds the same settings code."""
    x, y = _data(n_per=500)
    cpu, gpu = _fit_n_init("cpu", x, y, 4), _fit_n_init("cuda", x, y, 4)
    assert gpu.means_.device.type == "cuda"
    assert gpu.n_components_.cpu().tolist() == cpu.n_components_.tolist()
    real = cpu.fit_report_.candidate_mask
    np.testing.assert_allclose(
        gpu.fit_report_.log_likelihood.cpu()[real].numpy(),
        cpu.fit_report_.log_likelihood[real].numpy(),
        rtol=1e-6,
    )
    np.testing.assert_allclose(gpu.means_.cpu().numpy(), cpu.means_.numpy(), atol=1e-6)
    for key, value in cpu.state_dict().items():
        if value.dtype == torch.int64:
            assert torch.equal(gpu.state_dict()[key].cpu(), value), key
    q = np.random.default_rng(4).normal(scale=1.5, size=(2000, x.shape[1]))
    assert torch.equal(gpu.classify(q).action.cpu(), cpu.classify(q).action)


def test_an_n_init_cuda_fit_repeats_bit_for_bit() -> None:
    x, y = _data(n_per=2000, d=5)
    a, b = (_fit_n_init("cuda", x, y, 3).state_dict() for _ in range(2))
    assert a.keys() == b.keys()
    for key in a:
        assert torch.equal(a[key], b[key]), key


def test_an_n_init_no_gpu_memory_holds_is_refused_naming_the_gpu() -> None:
    """The up-front n_init check reads the GPU's own memory for a CUDA model (the host's for the
    CPU); the model stays unfitted and on the GPU."""
    x, y = _data(n_per=50)
    total = torch.cuda.get_device_properties(0).total_memory
    model = GaussianMixtureSet(3, x.shape[1], 8, seed=3, n_init=10**12).to("cuda")
    with pytest.raises(
        ValueError,
        match=rf"Expected an n_init whose starts fit in the memory of cuda "
        rf"\({total / 2**30:.3g} GiB\) but got {10**12}",
    ):
        model.fit(x, y)
    assert not model.is_fitted
    assert model.means_.device.type == "cuda"
