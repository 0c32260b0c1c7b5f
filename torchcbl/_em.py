"""Batched EM for many full-covariance Gaussian mixtures at once, as small pure functions.

Every function works on a flat batch of ``B`` *candidates* (one candidate = one mixture with its
own data and its own component count), padded to ``N`` points and ``K`` components:

- ``x``      [B, N, D] float64 observations (padding rows are zeros),
- ``xx``     [B, N, D*D] the per-point outer products ``x x^T`` (constant over EM iterations),
- ``pmask``  [B, N] float, 1 for a real point and 0 for padding,
- ``cmask``  [B, K] float, 1 for a real component and 0 for padding,
- ``floor``  [D] the variance added to every covariance diagonal (see ``GaussianMixtureSet``).

The maths follows scikit-learn's ``GaussianMixture`` (full covariances) step for step, so that
from the same initial parameters both produce the same iterates: E-step with precision Cholesky
factors, M-step with ``nk + 10 eps``, weights renormalised, convergence when the change of the
mean per-point log-likelihood is below ``tol``.

Padding never reaches ``exp`` with a very negative argument (torch's float64 ``exp`` is several
times slower on underflow): padded components get a large negative finite log weight and all
shifted log-densities are clamped at ``_CLAMP`` before exponentiation, then masked.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import torch
from torch import Tensor

_EPS = float(np.finfo(np.float64).eps)
_CLAMP = -60.0  # e^-60 ~ 1e-26: negligible next to 1, and far from the subnormal range
_PAD_LOG_WEIGHT = -1.0e4


class Params(NamedTuple):
    """Mixture parameters of a batch of candidates.

    weights [B, K], means [B, K, D], covariances [B, K, D, D], prec_chol [B, K, D, D]
    (upper triangular U with U U^T = inverse covariance), log_det [B, K] = log det U.
    Padded components hold weight 0, mean 0 and identity covariance.
    """

    weights: Tensor
    means: Tensor
    covariances: Tensor
    prec_chol: Tensor
    log_det: Tensor


def outer_products(x: Tensor) -> Tensor:
    """[B, N, D] -> [B, N, D*D]: each point's outer product x x^T, flattened."""
    b, n, d = x.shape
    return (x.unsqueeze(-1) * x.unsqueeze(-2)).reshape(b, n, d * d)


def precision_cholesky(covariances: Tensor) -> tuple[Tensor, Tensor]:
    """Upper-triangular precision factors of SPD matrices.

    covariances [..., D, D] -> (prec_chol [..., D, D], log_det [...]) with
    prec_chol = L^{-T} where L L^T = covariance, log_det = sum log diag(prec_chol).
    Raises ``FloatingPointError`` if a matrix is not positive definite.
    """
    chol, info = torch.linalg.cholesky_ex(covariances)
    if bool((info != 0).any()):
        raise FloatingPointError(
            "a covariance matrix is not positive definite even after the variance floor; "
            "increase var_floor"
        )
    eye = torch.eye(covariances.shape[-1], dtype=covariances.dtype, device=covariances.device)
    inv_chol = torch.linalg.solve_triangular(chol, eye.expand_as(chol), upper=False)
    prec_chol = inv_chol.mT
    log_det = -torch.log(torch.diagonal(chol, dim1=-2, dim2=-1)).sum(-1)
    return prec_chol, log_det


def m_step(x: Tensor, xx: Tensor, resp: Tensor, cmask: Tensor, floor: Tensor) -> Params:
    """Maximisation step.

    resp [B, N, K] responsibilities, already zero on padded points and components.
    Returns the new parameters; padded components get weight 0, mean 0, identity covariance.
    """
    b, n, d = x.shape
    k = resp.shape[-1]
    nk = resp.sum(1) + 10.0 * _EPS  # [B, K]
    resp_t = resp.transpose(1, 2)  # [B, K, N]
    means = torch.bmm(resp_t, x) / nk.unsqueeze(-1)  # [B, K, D]
    second = torch.bmm(resp_t, xx).reshape(b, k, d, d) / nk.reshape(b, k, 1, 1)
    cov = second - means.unsqueeze(-1) * means.unsqueeze(-2)
    cov = 0.5 * (cov + cov.mT)
    eye = torch.eye(d, dtype=x.dtype, device=x.device)
    cm = cmask.reshape(b, k, 1, 1)
    cov = cov * cm + eye * (1.0 - cm)  # padded components: identity
    cov = cov + torch.diag_embed(floor).reshape(1, 1, d, d) * cm
    weights = nk * cmask
    weights = weights / weights.sum(1, keepdim=True)
    means = means * cmask.unsqueeze(-1)
    prec_chol, log_det = precision_cholesky(cov)
    return Params(weights, means, cov, prec_chol, log_det)


def log_gaussian(x: Tensor, means: Tensor, prec_chol: Tensor, log_det: Tensor) -> Tensor:
    """log N(x_n; mu_k, S_k) for every point and component.

    x [B, N, D], means [B, K, D], prec_chol [B, K, D, D], log_det [B, K] -> [B, N, K].
    Uses y = x U - mu U with one batched matrix product for all components.
    """
    b, n, d = x.shape
    k = means.shape[1]
    p = prec_chol.permute(0, 2, 1, 3).reshape(b, d, k * d)  # [B, D, K*D]
    y = torch.bmm(x, p)  # [B, N, K*D]
    mu_p = torch.matmul(means.unsqueeze(-2), prec_chol).reshape(b, 1, k * d)
    y = y - mu_p
    maha = (y * y).reshape(b, n, k, d).sum(-1)
    return -0.5 * (d * math.log(2.0 * math.pi) + maha) + log_det.unsqueeze(1)


def e_step(x: Tensor, params: Params, pmask: Tensor, cmask: Tensor) -> tuple[Tensor, Tensor]:
    """Expectation step.

    Returns (loglik [B], resp [B, N, K]): loglik is the total log-likelihood of the real points
    of each candidate; resp is zero on padded points and components.
    """
    log_w = torch.where(cmask > 0, torch.log(params.weights.clamp_min(1e-300)), _PAD_LOG_WEIGHT)
    wlp = log_gaussian(x, params.means, params.prec_chol, params.log_det) + log_w.unsqueeze(1)
    mx = wlp.amax(-1, keepdim=True)
    e = torch.exp((wlp - mx).clamp_min(_CLAMP)) * cmask.unsqueeze(1)
    s = e.sum(-1, keepdim=True)
    resp = e * (pmask.unsqueeze(-1) / s)
    lse = (mx + torch.log(s)).squeeze(-1)
    loglik = (lse * pmask).sum(1)
    return loglik, resp


def _splitmix_uniform(keys: np.ndarray) -> np.ndarray:
    """Deterministic uniforms in [0, 1) from uint64 keys (splitmix64 finaliser)."""
    with np.errstate(over="ignore"):
        z = keys.astype(np.uint64) + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)).astype(np.float64) * (2.0**-53)


def candidate_uniforms(seed: int, action: np.ndarray, n_comp: np.ndarray, k: int) -> np.ndarray:
    """[B, K] uniforms that depend only on (seed, action, component count, draw index).

    So a candidate's initialisation does not depend on which other candidates share its batch:
    fitting all actions at once equals fitting them one at a time.
    """
    with np.errstate(over="ignore"):
        base = (
            np.uint64(seed & 0xFFFFFFFF) * np.uint64(0x100000001B3)
            + action.astype(np.uint64) * np.uint64(0x9E3779B1)
            + n_comp.astype(np.uint64) * np.uint64(0x85EBCA77)
        )
        keys = base[:, None] * np.uint64(1315423911) + np.arange(k, dtype=np.uint64)[None, :]
    return _splitmix_uniform(keys)


def kmeans_init(
    x: Tensor, pmask: Tensor, cmask: Tensor, uniforms: Tensor, n_lloyd: int = 20
) -> Tensor:
    """k-means++ seeding then Lloyd iterations, batched; returns one-hot resp [B, N, K].

    uniforms [B, K] drive the seeding draws (inverse CDF over the D^2 weights), so the result is
    a pure function of the data and the uniforms. Lloyd stops early when no label changes.
    """
    b, n, d = x.shape
    k = cmask.shape[1]
    centers = torch.zeros(b, k, d, dtype=x.dtype, device=x.device)
    d2 = torch.full((b, n), math.inf, dtype=x.dtype, device=x.device)
    rows = torch.arange(b, device=x.device)
    for j in range(k):
        w = pmask if j == 0 else d2 * pmask
        tot = w.sum(1, keepdim=True)
        w = torch.where(tot > 0, w, pmask)  # all remaining distances zero: uniform draw
        cdf = torch.cumsum(w, 1)
        target = uniforms[:, j : j + 1] * cdf[:, -1:]
        idx = torch.searchsorted(cdf, target, right=True).clamp_max(n - 1).squeeze(1)
        c = x[rows, idx]  # [B, D]
        centers[:, j] = c
        d2 = torch.minimum(d2, ((x - c.unsqueeze(1)) ** 2).sum(-1))
    x2 = (x * x).sum(-1, keepdim=True)
    pad = (cmask <= 0).unsqueeze(1)
    labels = None
    for _ in range(max(n_lloyd, 1)):
        dist = x2 - 2.0 * torch.bmm(x, centers.mT) + (centers * centers).sum(-1).unsqueeze(1)
        dist = dist.masked_fill(pad, math.inf)
        new_labels = dist.argmin(-1)
        resp = torch.nn.functional.one_hot(new_labels, k).to(x.dtype) * pmask.unsqueeze(-1)
        if labels is not None and bool((new_labels == labels).all()):
            break
        labels = new_labels
        counts = resp.sum(1)  # [B, K]
        sums = torch.bmm(resp.transpose(1, 2), x)
        centers = torch.where(
            counts.unsqueeze(-1) > 0, sums / counts.clamp_min(1.0).unsqueeze(-1), centers
        )
    return resp


class EMResult(NamedTuple):
    """Output of :func:`run_em` for B candidates (shapes as in :class:`Params`)."""

    params: Params
    loglik: Tensor  # [B] total log-likelihood of the final parameters
    n_iter: Tensor  # [B] long
    converged: Tensor  # [B] bool


def _take(params: Params, idx: Tensor) -> Params:
    return Params(*(t.index_select(0, idx) for t in params))


def run_em(
    x: Tensor,
    pmask: Tensor,
    cmask: Tensor,
    floor: Tensor,
    resp0: Tensor,
    tol: float,
    max_iter: int,
) -> EMResult:
    """EM for B candidates at once, from initial responsibilities resp0 [B, N, K].

    Candidates that converge leave the batch, so late iterations only cost what is still running.
    Mirrors sklearn: each iteration is an E-step (log-likelihood of the current parameters) then
    an M-step; it stops when |mean log-likelihood change| < tol. The returned log-likelihood is
    that of the final parameters (one extra E-step), as sklearn's ``score``.
    """
    b = x.shape[0]
    xx = outer_products(x)
    n_pts = pmask.sum(1)
    params = m_step(x, xx, resp0, cmask, floor)
    return run_em_from_params(x, xx, pmask, cmask, floor, params, n_pts, tol, max_iter, b)


def run_em_from_params(
    x: Tensor,
    xx: Tensor,
    pmask: Tensor,
    cmask: Tensor,
    floor: Tensor,
    params: Params,
    n_pts: Tensor,
    tol: float,
    max_iter: int,
    b: int,
) -> EMResult:
    """EM loop from given initial parameters (see :func:`run_em`)."""
    out = [t.clone() for t in params]
    n_iter = torch.zeros(b, dtype=torch.long, device=x.device)
    converged = torch.zeros(b, dtype=torch.bool, device=x.device)
    active = torch.arange(b, device=x.device)
    prev = torch.full((b,), -math.inf, dtype=x.dtype, device=x.device)
    ax, axx, apm, acm, an = x, xx, pmask, cmask, n_pts
    for it in range(1, max_iter + 1):
        ll, resp = e_step(ax, params, apm, acm)
        params = m_step(ax, axx, resp, acm, floor)
        mean_ll = ll / an
        done = (mean_ll - prev).abs() < tol
        prev = mean_ll
        if it == max_iter or bool(done.any()):
            stop = done | (it == max_iter)
            gone = active[stop]
            n_iter[gone] = it
            converged[gone] = done[stop]
            for o, p in zip(out, params, strict=True):
                o[gone] = p[stop]
            keep = (~stop).nonzero().squeeze(1)
            if keep.numel() == 0:
                break
            active = active[keep]
            params = _take(params, keep)
            ax, axx, apm, acm = (t.index_select(0, keep) for t in (ax, axx, apm, acm))
            an, prev = an[keep], prev[keep]
    final = Params(*out)
    loglik, _ = e_step(x, final, pmask, cmask)
    return EMResult(final, loglik, n_iter, converged)


def n_free_parameters(n_components: Tensor, n_features: int) -> Tensor:
    """Free parameters of a full-covariance mixture: (k-1) + k d + k d (d+1) / 2."""
    d = n_features
    k = n_components.to(torch.float64)
    return (k - 1.0) + k * d + k * d * (d + 1) / 2.0


def information_criterion(
    kind: str, loglik: Tensor, n_components: Tensor, n_points: Tensor, n_features: int
) -> Tensor:
    """Criterion of each mixture (lower is better); all arguments broadcast together.

    ``aic``: 2 p - 2 L (p free parameters, sklearn's ``aic``); ``bic``: p log n - 2 L;
    ``aic_paper``: Eq. 5 of the paper taken literally, 2 k - 2 L.
    """
    if kind == "aic":
        return 2.0 * n_free_parameters(n_components, n_features) - 2.0 * loglik
    if kind == "bic":
        p = n_free_parameters(n_components, n_features)
        return p * torch.log(n_points.to(torch.float64)) - 2.0 * loglik
    if kind == "aic_paper":
        return 2.0 * n_components.to(torch.float64) - 2.0 * loglik
    raise ValueError(f"Expected criterion in ('aic', 'bic', 'aic_paper') but got {kind!r}")
