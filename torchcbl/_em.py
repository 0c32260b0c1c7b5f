"""Batched EM for many full-covariance Gaussian mixtures at once, as small pure functions.

Layout. Data come in ``G`` groups (one group = one action's points), padded to ``N`` points;
each group holds ``C`` candidate *slots* (one slot = one mixture fitted to that group's data),
each padded to ``K`` components:

- ``x``      [G, N, D] float64 observations (padding rows are zeros),
- ``z``      [G, N, Q] their quadratic features (:func:`quadratic_features`),
- ``pmask``  [G, N] float, 1 for a real point and 0 for padding,
- ``cmask``  [G, C, K] float, 1 for a real component of that slot and 0 for padding,
- ``floor``  [D] the variance added to every covariance diagonal.

Grouping by action turns both EM steps into a few large matrix products (:func:`run_em`
packs the running candidates' real components into batch rows, each row holding some of one
action's candidates: ``[M, Q] @ [Q, N]`` per row and its transpose) instead of many tiny ones
per candidate. Every slot must hold at least one real component (pad unused slots with a copy
of a real candidate).

The maths follows scikit-learn's ``GaussianMixture`` (full covariances) step for step, so that
from the same initial parameters both produce the same iterates: M-step with ``nk + 10 eps``
and renormalised weights, convergence when the change of the mean per-point log-likelihood is
below ``tol``.

Padding never reaches ``exp`` with a huge negative argument (torch's float64 ``exp`` is several
times slower on underflow): padded components get a large negative finite log-density and all
shifted log-densities are clamped at ``_CLAMP`` before exponentiation. A padded component so
receives a responsibility of at most e^-60 (~1e-26), which changes nothing measurable.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np
import torch
from torch import Tensor

_EPS = float(np.finfo(np.float64).eps)
_CLAMP = -700.0  # e^-700 ~ 1e-304: still a normal float64 (exp stays fast), ~0 next to 1
_PAD_LOG_WEIGHT = -1.0e4


class Params(NamedTuple):
    """Mixture parameters of every slot, shapes [G, C, K, ...].

    weights [G, C, K], means [G, C, K, D], covariances [G, C, K, D, D], log_det [G, C, K]
    (= -sum log diag chol(S), the log determinant of the precision Cholesky factor) and
    ``coef`` [G, C, K, Q]: the same Gaussians as coefficients over the quadratic features, so
    that ``z @ coef^T`` gives log w_k + log N(x; mu_k, S_k) for every point and component in
    one matrix product. Padded components have zero weight, covariance ``diag(floor)`` and a
    constant, very low log-density in ``coef``.
    """

    weights: Tensor
    means: Tensor
    covariances: Tensor
    log_det: Tensor
    coef: Tensor


@functools.lru_cache(maxsize=64)
def _indices(d: int, device: torch.device) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor, Tensor]:
    """Upper-triangle (i, j), full [D*D] -> packed map, flat positions of the upper triangle,
    quad scale, flat positions of the same entries in the transposed matrix."""
    iu = torch.triu_indices(d, d, device=device)
    i, j = iu[0], iu[1]
    du = i.numel()
    full = torch.zeros(d, d, dtype=torch.long, device=device)
    full[i, j] = torch.arange(du, device=device)
    full[j, i] = torch.arange(du, device=device)
    scale = torch.where(i == j, -0.5, -1.0).to(torch.float64)
    return i, j, full.reshape(-1), i * d + j, scale, j * d + i


def index_sum(
    base: Tensor, dim: int, index: Tensor, source: Tensor, *, copy: bool = False
) -> Tensor:
    """``base.index_add_(dim, index, source)`` (into a copy of ``base`` with ``copy``), summed in
    the same order every run on every device.

    On the CPU this is torch's ``index_add_``, a loop in index order. On CUDA ``index_add_``
    adds with atomics, whose order, and so whose last bits, change from run to run (measured on
    an H200: two fits of the same data and seed differed, and so did two teaching sessions); there
    the sums go through ``index_put_(accumulate=True)``, torch's sort-based kernel, the one its
    deterministic mode uses for ``index_add`` on CUDA.
    """
    out = base.clone() if copy else base
    if out.device.type == "cpu":
        return out.index_add_(dim, index, source)
    out.movedim(dim, 0).index_put_((index,), source.movedim(dim, 0), accumulate=True)
    return out


def quadratic_features(x: Tensor) -> Tensor:
    """[..., D] -> z [..., Q]: (x_i x_j for i <= j, x, 1), Q = D (D + 1) / 2 + D + 1.

    Both EM steps are then single matrix products: the M-step's sufficient statistics are
    resp^T z, and the E-step's weighted log-densities are z coef^T.
    """
    i, j, _, _, _, _ = _indices(x.shape[-1], x.device)
    ones = torch.ones(*x.shape[:-1], 1, dtype=x.dtype, device=x.device)
    return torch.cat([x[..., i] * x[..., j], x, ones], -1)


def _dim_of(q: int) -> int:
    return int(round((math.sqrt(8 * q + 1) - 3) / 2))  # q = d (d + 1) / 2 + d + 1


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
    eye = _eye(covariances.shape[-1], covariances.dtype, covariances.device).expand_as(chol)
    inv_chol = torch.linalg.solve_triangular(chol, eye, upper=False)
    log_det = -torch.log(torch.diagonal(chol, dim1=-2, dim2=-1)).sum(-1)
    return inv_chol.mT, log_det


@functools.lru_cache(maxsize=16)
def _eye(d: int, dtype: torch.dtype, device: torch.device) -> Tensor:
    return torch.eye(d, dtype=dtype, device=device)


def _precision(cov: Tensor) -> tuple[Tensor, Tensor]:
    """Precision matrices and -log det of the Cholesky factors (-1/2 log det) of SPD
    covariances [..., D, D].

    Small batched LAPACK calls cost about a microsecond per matrix whatever they do, so the
    cheapest route is taken. For D <= 4, one LU factorisation gives both the inverse (solved
    against the identity, as ``inv_ex`` does) and the determinant, prod(diag U) with its sign
    flipped once per row swap (a Cholesky factorisation on top would cost as much again); its
    log is summed from log |U_ii|, so no product can overflow. A negative determinant gives
    NaN and a zero one +inf; a matrix with an even number of negative eigenvalues is not
    detected (Cholesky would have failed on it). The covariances here are a weighted scatter
    matrix plus the variance floor (at least 1e-6 of the mean variance), positive definite up
    to rounding far below the floor, so what can go wrong is NaN or infinite input, which
    gives a non-finite log det. For larger D: the Cholesky factor L (NaN when it fails), then
    P = L^-T L^-1 (both faster there than LU or ``cholesky_inverse``). A non-finite value is
    left for the caller's final finiteness check.
    """
    d = cov.shape[-1]
    if d <= 4:
        lu, piv, _ = torch.linalg.lu_factor_ex(cov)
        u = torch.diagonal(lu, dim1=-2, dim2=-1)
        # det = prod(u) * (-1)^swaps: its log from the |u| (no overflow), NaN when it is <= 0
        flips = (u < 0).sum(-1).add_((piv != _pivots(d, piv.dtype, cov.device)).sum(-1))
        log_det = u.abs().log_().sum(-1).mul_(-0.5)
        log_det = log_det.masked_fill_(flips.bitwise_and_(1).bool(), math.nan)
        prec = torch.linalg.lu_solve(lu, piv, _eye(d, cov.dtype, cov.device).expand_as(cov))
        return prec, log_det
    chol, info = torch.linalg.cholesky_ex(cov)
    log_det = -torch.log(torch.diagonal(chol, dim1=-2, dim2=-1)).sum(-1)
    log_det = log_det.masked_fill_(info.bool(), math.nan)  # info != 0
    eye = _eye(d, cov.dtype, cov.device).expand_as(cov)
    inv_chol = torch.linalg.solve_triangular(chol, eye, upper=False)
    return inv_chol.mT @ inv_chol, log_det


@functools.lru_cache(maxsize=16)
def _pivots(d: int, dtype: torch.dtype, device: torch.device) -> Tensor:
    """LAPACK's pivots of an LU factorisation that swaps no rows: 1, ..., d."""
    return torch.arange(1, d + 1, dtype=dtype, device=device)


def m_step(z: Tensor, resp: Tensor, cmask: Tensor, floor: Tensor) -> Params:
    """Maximisation step: z [G, N, Q], resp [G, N, C, K] (zero on padded points) -> Params.

    Same estimates as sklearn's ``_estimate_gaussian_parameters`` (nk + 10 eps, the floor on
    the diagonal, weights renormalised). A covariance that is not positive definite yields NaN,
    which the caller's final finiteness check reports.
    """
    g, n, c, k = resp.shape
    q = z.shape[-1]
    d = _dim_of(q)
    du = q - d - 1
    _, _, full, _, _, _ = _indices(d, z.device)
    # z^T resp keeps the big operand in its natural layout (faster than resp^T z)
    stats = torch.bmm(z.transpose(1, 2), resp.reshape(g, n, c * k)).transpose(1, 2)
    stats = stats.reshape(g, c, k, q)
    nk = stats[..., -1] + 10.0 * _EPS
    stats = stats / nk.unsqueeze(-1)
    means = stats[..., du : du + d]
    cov = stats[..., full].reshape(g, c, k, d, d)
    cov -= means.unsqueeze(-1) * means.unsqueeze(-2)
    cov.diagonal(dim1=-2, dim2=-1).add_(floor)
    weights = nk * cmask
    weights /= weights.sum(-1, keepdim=True)
    return params_of(weights, means, cov, cmask)


def params_of(weights: Tensor, means: Tensor, cov: Tensor, cmask: Tensor) -> Params:
    """Params (with log_det and the quadratic-feature coefficients) of given mixtures:
    weights [G, C, K], means [G, C, K, D], cov [G, C, K, D, D] (floor included), cmask
    [G, C, K]. This is how :func:`m_step` finishes, and how a warm start enters :func:`run_em`.
    """
    g, c, k, d = means.shape
    _, _, _, upper, scale, _ = _indices(d, means.device)
    prec, log_det = _precision(cov)
    lin = (prec * means.unsqueeze(-2)).sum(-1)  # P mu (a batched matmul of 1-column products
    # would cost more than the rest of the M-step's small operations)
    quad = prec.reshape(g, c, k, d * d)[..., upper] * scale.to(means.dtype)
    const = torch.log(weights) + log_det - 0.5 * (lin * means).sum(-1)
    const = torch.where(cmask > 0, const - 0.5 * d * math.log(2.0 * math.pi), _PAD_LOG_WEIGHT)
    coef = torch.cat([quad, lin, const.unsqueeze(-1)], -1)
    return Params(weights, means, cov, log_det, coef)


def total_log_likelihood(zt: Tensor, coef: Tensor, pmask: Tensor) -> Tensor:
    """Each slot's total log-likelihood over the real points of its group (sklearn's ``score``
    times the count): zt [G, Q, N] (features of the points, points last), coef [G, C, K, Q],
    pmask [G, N] -> [G, C]. The log-sum-exp is shifted by each slot's exact maximum.
    """
    g, c, k, q = coef.shape
    n = zt.shape[-1]
    # [C*K, Q] @ [Q, N] (points last): MKL is several times slower on [N, Q] @ [Q, C*K] here
    wlp = torch.bmm(coef.reshape(g, c * k, q), zt).view(g, c, k, n)
    mx = wlp.amax(2, keepdim=True)
    s = wlp.sub_(mx).clamp_min_(_CLAMP).exp_().sum(2)
    lse = mx.squeeze(2) + torch.log(s)  # [G, C, N]
    return (lse * pmask.unsqueeze(1)).sum(-1)


def _splitmix_uniform(keys: np.ndarray) -> np.ndarray:
    """Deterministic uniforms in [0, 1) from uint64 keys (splitmix64 finaliser)."""
    with np.errstate(over="ignore"):
        z = keys.astype(np.uint64) + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)).astype(np.float64) * (2.0**-53)


def candidate_uniforms(
    seed: int, action: np.ndarray, n_comp: np.ndarray, k: int, init: np.ndarray | int = 0
) -> np.ndarray:
    """Uniforms [..., k] that depend only on (seed, action, component count, initialisation,
    draw index).

    ``action``, ``n_comp`` and ``init`` (the initialisation's index, 0 .. n_init - 1; it
    broadcasts) are integer arrays of the same shape. A candidate's initialisation so does not
    depend on which other candidates share its batch: fitting all actions at once equals
    fitting them one at a time. Initialisation 0 adds nothing to the key: its draws are those
    of the code before ``n_init`` existed.
    """
    with np.errstate(over="ignore"):
        base = (
            np.uint64(seed & 0xFFFFFFFF) * np.uint64(0x100000001B3)
            # the seed's high 32 bits (0 below 2**32, which leaves those seeds' draws as they
            # were before the high bits counted)
            + np.uint64((seed >> 32) & 0xFFFFFFFF) * np.uint64(0xC2B2AE3D27D4EB4F)
            + np.asarray(action).astype(np.uint64) * np.uint64(0x9E3779B1)
            + np.asarray(n_comp).astype(np.uint64) * np.uint64(0x85EBCA77)
            + np.asarray(init).astype(np.uint64) * np.uint64(0xD6E8FEB86659FD93)
        )
        keys = base[..., None] * np.uint64(1315423911) + np.arange(k, dtype=np.uint64)
    return _splitmix_uniform(keys)


_KMEANS_POINTS = 1024  # k-means runs on at most this many points per group (an even stride)


def kmeans_init(
    x: Tensor, pmask: Tensor, cmask: Tensor, uniforms: Tensor, n_lloyd: int = 10
) -> Tensor:
    """k-means++ seeding then Lloyd iterations for every slot; returns one-hot resp [G,N,C,K].

    x [G, N, D], pmask [G, N] (each group's real points first, then padding), cmask [G, C, K],
    uniforms [G, C, K] drive the seeding draws (inverse CDF over the D^2 weights), so the
    result is a pure function of the data and the uniforms. Lloyd stops early when no label
    changes anywhere; a point equally near several centres goes to the first.

    A group with more than ``_KMEANS_POINTS`` points seeds and runs Lloyd on an even stride of
    that many of them (points i * n // 1024), and then every point goes to its nearest final
    centre: an initialisation for EM needs no more, and it keeps k-means from costing more
    than the EM itself on large sets. Smaller groups use all their points.
    """
    g, n, d = x.shape
    if n <= _KMEANS_POINTS:
        _, labels = _lloyd(x, pmask, cmask, uniforms, n_lloyd)
    else:
        m = _KMEANS_POINTS
        counts = pmask.sum(1).round().long().unsqueeze(1)  # [G, 1]
        j = torch.arange(m, device=x.device).unsqueeze(0)
        idx = torch.where(counts > m, j * counts // m, torch.minimum(j, (counts - 1).clamp_min(0)))
        sub = torch.gather(x, 1, idx.unsqueeze(-1).expand(g, m, d))
        centers, sub_labels = _lloyd(sub, (j < counts).to(x.dtype), cmask, uniforms, n_lloyd)
        labels = _nearest(_augmented(x), centers, _pad(cmask, x.dtype))
        # a group of at most m points ran on all of them (in order): keep its Lloyd labels,
        # exactly as when it is fitted alone
        whole = (counts <= m).unsqueeze(-1)  # [G, 1, 1]
        labels[..., :m] = torch.where(whole, sub_labels, labels[..., :m])
    c, k = cmask.shape[1:]
    # one-hot by a scatter of each point's mask value (1, or 0 on padding) into zeros: the same
    # values as one_hot(...).to(dtype) * pmask, without its int64 array and range checks
    resp = x.new_zeros(g, n, c, k)
    src = pmask.reshape(g, n, 1, 1).expand(g, n, c, 1)
    return resp.scatter_(3, labels.transpose(1, 2).unsqueeze(-1), src)


def _augmented(x: Tensor) -> Tensor:
    """[G, N, D] -> [x^T; 1] [G, D+1, N]."""
    g, n, _ = x.shape
    return torch.cat([x.transpose(1, 2), x.new_ones(g, 1, n)], 1)


def _pad(cmask: Tensor, dtype: torch.dtype) -> Tensor:
    """[G, C, K] -> [G, C, K, 1]: 0 for a real component, 1e300 (never nearest) for padding."""
    return ((cmask <= 0).to(dtype) * 1e300).unsqueeze(-1)


def _nearest(
    xa: Tensor, centers: Tensor, pad: Tensor, buffers: tuple[Tensor, ...] | None = None
) -> Tensor:
    """Index of the nearest centre of each slot: xa [G, D+1, N] (:func:`_augmented`), centers
    [G, C, K, D], pad [G, C, K, 1] -> labels [G, C, N] long, the first on exact ties.

    |x - c|^2 - |x|^2 = [-2c, |c|^2 + pad] . [x, 1]: one matrix product for all slots, laid out
    [G, C, K, N] (points last) so that the reductions over a slot's centres run along a middle
    axis, vectorised over the points (torch's argmin, and its reductions over a short last axis,
    are several times slower). ``buffers`` (dist, near, near_i) are reused across calls.
    """
    g, c, k, d = centers.shape
    n = xa.shape[-1]
    small = torch.int8 if k <= 127 else torch.int32
    if buffers is None:
        buffers = _nearest_buffers(g, c, k, n, xa.dtype, xa.device)
    dist, near, near_i = buffers
    rev = (k - 1 - torch.arange(k, device=xa.device)).to(small).reshape(1, 1, k, 1)
    cen = torch.cat([centers * -2.0, (centers * centers).sum(-1, keepdim=True) + pad], -1)
    torch.bmm(cen.reshape(g, c * k, d + 1), xa, out=dist)
    dist4 = dist.view(g, c, k, n)
    torch.eq(dist4, dist4.amin(2, keepdim=True), out=near)
    near_i.copy_(near).mul_(rev)
    return (k - 1) - near_i.amax(2).long()


def _nearest_buffers(
    g: int, c: int, k: int, n: int, dtype: torch.dtype, device: torch.device
) -> tuple[Tensor, Tensor, Tensor]:
    small = torch.int8 if k <= 127 else torch.int32
    return (
        torch.empty(g, c * k, n, dtype=dtype, device=device),
        torch.empty(g, c, k, n, dtype=torch.bool, device=device),
        torch.empty(g, c, k, n, dtype=small, device=device),
    )


def _lloyd(
    x: Tensor, pmask: Tensor, cmask: Tensor, uniforms: Tensor, n_lloyd: int
) -> tuple[Tensor, Tensor]:
    """k-means++ seeding and Lloyd on all the given points -> (centers [G, C, K, D], labels
    [G, C, N] of the last assignment)."""
    g, n, d = x.shape
    c, k = cmask.shape[1:]
    dev, dt = x.device, x.dtype
    centers = torch.zeros(g, c, k, d, dtype=dt, device=dev)
    d2 = torch.full((g, c, n), math.inf, dtype=dt, device=dev)
    pm = pmask.unsqueeze(1).expand(g, c, n)
    xt = x.transpose(1, 2).contiguous()  # [G, D, N]
    xt_c = [xt[:, i].unsqueeze(1) for i in range(d)]  # D x [G, 1, N]
    sq_buf = torch.empty(g, c, n, dtype=dt, device=dev)
    dist2 = torch.empty(g, c, n, dtype=dt, device=dev)
    for j in range(k):
        w = pm if j == 0 else d2 * pm
        w = torch.where(w.sum(-1, keepdim=True) > 0, w, pm)  # all distances 0: uniform draw
        cdf = torch.cumsum(w, -1)
        target = uniforms[..., j : j + 1] * cdf[..., -1:]
        idx = torch.searchsorted(cdf, target, right=True).clamp_max(n - 1)  # [G, C, 1]
        cj = torch.gather(
            xt.unsqueeze(1).expand(g, c, d, n), 3, idx.unsqueeze(2).expand(g, c, d, 1)
        )
        centers[:, :, j] = cj.squeeze(-1)
        # squared distances to the new centre, summed over the coordinates in order (a
        # reduction over D would sum in another order: the seeding draws would move); one
        # coordinate at a time into reused buffers ([G, C, D, N] temporaries cost more in
        # page faults than in arithmetic)
        for i in range(d):
            diff = torch.sub(xt_c[i], cj[:, :, i], out=sq_buf)  # [G, C, N]
            if i == 0:
                torch.mul(diff, diff, out=dist2)
            else:
                dist2.add_(diff.mul_(diff))
        torch.minimum(d2, dist2, out=d2)
    xa = _augmented(x)
    pad = _pad(cmask, dt)
    base = (torch.arange(g * c, device=dev) * k).reshape(g, c, 1)  # slot offsets
    # per coordinate, then the count: [x_i; 1] on real points, 0 on padding, once per slot
    weights = (xa * pmask.unsqueeze(1)).unsqueeze(2).expand(g, d + 1, c, n)
    weights = weights.transpose(0, 1).reshape(d + 1, g * c * n)
    acc = torch.empty(d + 1, g * c * k, dtype=dt, device=dev)
    # reused buffers: fresh multi-MB arrays every step would cost a page fault per 4 KiB
    buffers = _nearest_buffers(g, c, k, n, dt, dev)
    labels = None
    for _ in range(max(n_lloyd, 1)):
        new_labels = _nearest(xa, centers, pad, buffers)
        if labels is not None and torch.equal(new_labels, labels):
            break
        labels = new_labels
        flat = (labels + base).view(-1)  # global component id of each (slot, point)
        # sums per (slot, component): one index_sum over the points, in point order
        sums = index_sum(acc.zero_(), 1, flat, weights).T.view(g, c, k, d + 1)
        counts = sums[..., d:]
        centers = torch.where(counts > 0, sums[..., :d] / counts.clamp_min(1.0), centers)
    assert labels is not None
    return centers, labels


class EMResult(NamedTuple):
    """Output of :func:`run_em`: params [G, C, K, ...], loglik [G, C] (total log-likelihood
    of the final parameters), n_iter [G, C] long, converged [G, C] bool."""

    params: Params
    loglik: Tensor
    n_iter: Tensor
    converged: Tensor


_ROW_COST = 4  # per batch row overhead of the packed layout, in components
_REPACK = 0.85  # re-pack once the running components fall to this share of the packed ones
_REPACK_MIN = 16384  # ... and the stopped ones hold at least this many (component, point) pairs


class _Layout(NamedTuple):
    """Packed layout of the running candidates: their real components side by side.

    A batch row holds some running slots of one group; a group's slots may span several rows,
    so that rows hold similar numbers of components (one row per group would pad every row to
    the group with the most left to fit).

    ``gid`` [B, M] numpy: global component id (slot * K0 + j) of each packed component, -1 for
    padding; ``row`` [B, M] numpy: the candidate row (0..R-1) it belongs to, R for padding;
    ``slot`` [B, R] numpy: flat slot id of each candidate row, -1 for padding;
    ``groups`` [B]: the group whose data each batch row holds.
    """

    gid: np.ndarray
    row: np.ndarray
    slot: np.ndarray
    groups: np.ndarray


def _first_fit(items: list[tuple[int, int]], cap: int) -> list[tuple[int, list[int]]]:
    """First-fit decreasing: items (size, slot) sorted by decreasing size -> bins
    (used, slots) of capacity ``cap``."""
    bins: list[tuple[int, list[int]]] = []
    for size, s in items:
        for b, (used, slots) in enumerate(bins):
            if used + size <= cap:
                slots.append(s)
                bins[b] = (used + size, slots)
                break
        else:
            bins.append((size, [s]))
    return bins


def _pack(running: np.ndarray, slot_k: np.ndarray, k0: int) -> _Layout:
    """Layout of the running slots: running [G0, C0] bool, slot_k [G0, C0] component counts.

    Chooses the row capacity among a few values (the largest group's total, and the even
    shares of the total over G, 1.5 G and 2 G rows) by the padded size rows * (capacity +
    _ROW_COST).
    """
    c0 = running.shape[1]
    ks_all = slot_k.tolist()
    groups: list[list[tuple[int, int]]] = []  # per group: (size, flat slot), largest first
    for g, c in zip(*np.nonzero(running), strict=True):
        if not groups or groups[-1][0][1] // c0 != g:
            groups.append([])
        groups[-1].append((ks_all[g][c], int(g) * c0 + int(c)))
    for items in groups:
        items.sort(key=lambda it: -it[0])
    totals = [sum(size for size, _ in items) for items in groups]
    biggest = max(items[0][0] for items in groups)
    n_g, total = len(groups), sum(totals)
    caps = {max(totals)} | {max(biggest, -(-2 * total // b)) for b in (2 * n_g, 3 * n_g, 4 * n_g)}
    best: tuple[int, list[list[int]]] | None = None
    for cap in sorted(caps, reverse=True):
        bins = [b for items in groups for b in _first_fit(items, cap)]
        cost = len(bins) * (max(used for used, _ in bins) + _ROW_COST)
        if best is None or cost < best[0]:
            best = (cost, [sorted(slots) for _, slots in bins])
    assert best is not None
    rows_of = best[1]
    # one flat pass: every (batch row, candidate, component)
    b_n, n_rows = len(rows_of), max(len(r) for r in rows_of)
    flat_slot = np.fromiter((s for r in rows_of for s in r), dtype=np.int64)
    bin_of = np.repeat(np.arange(b_n), [len(r) for r in rows_of])
    cand = np.concatenate([np.arange(len(r)) for r in rows_of])
    ks = slot_k.reshape(-1)[flat_slot]
    used = np.bincount(bin_of, weights=ks, minlength=b_n).astype(np.int64)
    n_comp = int(used.max())
    comp_bin = np.repeat(bin_of, ks)
    start_in_bin = np.repeat(np.cumsum(used) - used, used)
    within_bin = np.arange(comp_bin.size) - start_in_bin
    within_slot = np.arange(ks.sum()) - np.repeat(np.cumsum(ks) - ks, ks)
    gid = np.full((b_n, n_comp), -1, dtype=np.int64)
    row = np.full((b_n, n_comp), n_rows, dtype=np.int64)
    slot = np.full((b_n, n_rows), -1, dtype=np.int64)
    gid[comp_bin, within_bin] = np.repeat(flat_slot * k0, ks) + within_slot
    row[comp_bin, within_bin] = np.repeat(cand, ks)
    slot[bin_of, cand] = flat_slot
    return _Layout(gid, row, slot, np.array([r[0] // c0 for r in rows_of], dtype=np.int64))


class _Batch(NamedTuple):
    """Constants of one packing for the packed E- and M-steps (:func:`_batch`): B batch rows,
    M components and R+1 candidate rows each (the last one padding), N points, Q features.

    Precomputed once per packing, so that an iteration runs as few tensor operations as
    possible (each costs microseconds of dispatch, whatever its size).
    """

    zt: Tensor  # [B, Q+1, N] features, points last; last row: minus the shift (rewritten)
    zt_q: Tensor  # [B, Q, N] view: the features alone
    shift: Tensor  # [B, N] view of zt's last row
    shift3: Tensor  # [B, 1, N] the same
    pm1: Tensor  # [B, 1, N] 1 on real points
    rows: Tensor  # [B*M] long: flat candidate row (b * (R+1) + row) of each component
    row_pad: Tensor  # [B*(R+1)] 1 on padding candidate rows
    pad_rows: Tensor  # [B*(R+1), N] the same per point (keeps their sums non-zero)
    weight_rows: Tensor  # [B*(R+1), N] 1 on real points of real candidate rows, else 0
    row_minf: Tensor  # [B, R+1, 1] 0 on real candidate rows, -inf on padding ones
    valid: Tensor  # [B, M] 1 on real components
    pad_b: Tensor  # [B, M] bool, True on padded components
    ones: Tensor  # [B, M, 1]
    floor_diag: Tensor  # [D, D] diag(variance floor)
    work: Tensor | None  # [B, M, N] reused buffer (receives resp)
    work2: Tensor | None  # [B*M, N] reused buffer


def _batch(
    zt: Tensor,
    pm: Tensor,
    rows: Tensor,
    valid: Tensor,
    row_ok: Tensor,
    floor: Tensor,
    buffers: bool | Tensor = True,
) -> _Batch:
    """zt [B, Q+1, N] (features then a shift row), pm [B, N], rows [B*M], valid [B, M],
    row_ok [B, R+1] (1 on real candidate rows), floor [D] -> _Batch. ``buffers``: True to
    allocate the reused [B, M, N] buffers (fresh multi-MB arrays every iteration would cost a
    page fault per 4 KiB), or a flat tensor of at least 2 B M N elements to carve them from."""
    b, q1, n = zt.shape
    m = valid.shape[1]
    r1 = row_ok.shape[1]
    pad = 1.0 - row_ok
    work = work2 = None
    if isinstance(buffers, Tensor):
        work = buffers[: b * m * n].view(b, m, n)
        work2 = buffers[b * m * n : 2 * b * m * n].view(b * m, n)
    elif buffers:
        work, work2 = zt.new_empty(b, m, n), zt.new_empty(b * m, n)
    return _Batch(
        zt=zt,
        zt_q=zt[:, : q1 - 1],
        shift=zt[:, -1],
        shift3=zt[:, -1:],
        pm1=pm.unsqueeze(1),
        rows=rows,
        row_pad=pad.reshape(-1),
        pad_rows=pad.reshape(-1, 1).expand(b * r1, n).contiguous(),
        weight_rows=(pm.unsqueeze(1) * row_ok.unsqueeze(-1)).reshape(-1, n),
        row_minf=torch.where(row_ok > 0, 0.0, -math.inf).unsqueeze(-1),
        valid=valid,
        pad_b=valid <= 0,
        ones=valid.new_ones(b, m, 1),
        floor_diag=torch.diag(floor),
        work=work,
        work2=work2,
    )


def _m_step_packed(bt: _Batch, resp: Tensor) -> tuple[Params, Tensor]:
    """M-step in the packed layout: resp [B, M, N] -> (Params [B, M, ...], coef [B, M, Q+1]).

    Same estimates as :func:`m_step`. The returned ``coef`` ends with a column of ones, the
    weight of the E-step's shift row; ``Params.coef`` is its first Q columns.
    """
    g, m, _ = resp.shape
    d = bt.floor_diag.shape[0]
    q = d * (d + 3) // 2 + 1
    du = q - d - 1
    _, _, full, upper, scale, lower = _indices(d, resp.device)
    # zt @ resp^T: with the long N axis contiguous in both operands, ~1.7x faster than resp @ z
    stats = torch.bmm(bt.zt_q, resp.transpose(1, 2))  # [B, Q, M]
    nk = stats[:, -1] + 10.0 * _EPS  # [B, M]
    stats = stats / nk.unsqueeze(1)
    means = stats[:, du : du + d].transpose(1, 2)  # [B, M, D] view, M contiguous
    # the covariance entries as whole rows of [B, Q, M] (an index_select along the last axis
    # copies element by element), then viewed [B, M, D, D]: the same values
    cov = stats.index_select(1, full).view(g, d, d, m).permute(0, 3, 1, 2)
    cov.sub_(means.unsqueeze(-1) * means.unsqueeze(-2)).add_(bt.floor_diag)
    wn = nk * bt.valid
    wsum = index_sum(bt.row_pad, 0, bt.rows, wn.view(-1), copy=True)
    weights = wn.div_(wsum.index_select(0, bt.rows).view(g, m))
    prec, log_det = _precision(cov)
    lin = (prec * means.unsqueeze(-2)).sum(-1)  # P mu (a batched matmul of 1-column products
    # would cost more than the rest of the M-step's small operations)
    if prec.mT.is_contiguous():  # LAPACK's column-major inverse: read it without a copy
        quad = prec.mT.reshape(g, m, d * d).index_select(-1, lower).mul_(scale)
    else:
        quad = prec.reshape(g, m, d * d).index_select(-1, upper).mul_(scale)
    const = torch.log(weights).add_(log_det).sub_((lin * means).sum(-1), alpha=0.5)
    const = const.add_(-0.5 * d * math.log(2.0 * math.pi)).masked_fill_(bt.pad_b, _PAD_LOG_WEIGHT)
    coef = torch.cat([quad, lin, const.unsqueeze(-1), bt.ones], -1)
    return Params(weights, means, cov, log_det, coef[..., :q]), coef


def _clamp_exp_(t: Tensor, lo: float, hi: float) -> Tensor:
    """exp(clamp(t, lo, hi)) in place, by torch's kernels: bit-identical on any thread count.
    Measured on an AVX-512 host, with its AVX2 and AVX-512 kernels (numpy 2.4): 1.6x faster
    than numpy's ``exp`` on one thread and 3-4x on two for the E-step's [B, M, N] arrays."""
    return t.clamp_(lo, hi).exp_()


def _e_step_packed(
    bt: _Batch, coef: Tensor, shifted: bool = False
) -> tuple[Tensor, Tensor, Tensor]:
    """E-step in the packed layout: coef [B, M, Q+1] (last column 1) -> (loglik [B, R+1],
    resp [B, M, N], lse [B, R+1, N]); resp is zero on padding rows and padded points and is
    returned in ``bt.work`` when there is one.

    ``bt.zt``'s last row holds minus a log-sum-exp shift per point, so the matrix product
    gives the shifted log-densities directly. With ``shifted`` that row is tried as it is
    (the previous iteration's); the step then rewrites it with this iteration's largest
    candidate log-likelihood per point, for the next.

    Shifts, first that keeps every candidate's shifted sum in [e^-600, e^600] (beyond, the
    e^-700 clamp could matter or exp overflow): the given row; the largest weighted
    log-density per point of any component of the batch row; each candidate's own maximum.
    """
    b, m, _ = coef.shape
    n = bt.zt.shape[-1]
    r1 = bt.row_minf.shape[1]

    def product() -> Tensor:
        return torch.bmm(coef, bt.zt, out=bt.work) if bt.work is not None else coef @ bt.zt

    def sums(e: Tensor) -> tuple[Tensor, Tensor]:
        s = index_sum(bt.pad_rows, 0, bt.rows, e.view(-1, n), copy=True)
        return s, torch.log(s.view(b, r1, n))

    def safe(ls: Tensor) -> bool:
        lo, hi = torch.aminmax(ls)
        return float(lo) > -600.0 and float(hi) < 600.0

    lse = None
    if shifted:
        e = _clamp_exp_(product(), _CLAMP, 700.0)
        s, ls = sums(e)
        if safe(ls):
            lse = ls.sub_(bt.shift3)
    if lse is None:
        bt.shift.zero_()
        w = product()
        mx = w.amax(1, keepdim=True)  # [B, 1, N]
        e = _clamp_exp_(w.sub_(mx), _CLAMP, math.inf)
        s, ls = sums(e)
        if safe(ls):
            lse = ls.add_(mx)
    if lse is None:
        w = product()
        cmx = torch.full((b * r1, n), -math.inf, dtype=w.dtype, device=w.device)
        cmx = cmx.scatter_reduce_(0, bt.rows.unsqueeze(-1).expand(-1, n), w.view(-1, n), "amax")
        cmx = torch.where(bt.row_pad.unsqueeze(-1) > 0, 0.0, cmx)
        e = _clamp_exp_(w.sub_(cmx.index_select(0, bt.rows).view(b, m, n)), _CLAMP, math.inf)
        s, ls = sums(e)
        lse = ls.add_(cmx.view(b, r1, n))
    loglik = (lse * bt.pm1).sum(-1)
    torch.neg(torch.amax(lse + bt.row_minf, 1), out=bt.shift)
    inv = bt.weight_rows / s
    if bt.work2 is not None:
        spread = torch.index_select(inv, 0, bt.rows, out=bt.work2)
    else:
        spread = inv.index_select(0, bt.rows)
    e.mul_(spread.view(b, m, n))
    return loglik, e, lse


def _ix(a: np.ndarray, device: torch.device) -> Tensor:
    return torch.from_numpy(a).to(device)


def run_em(
    x: Tensor,
    pmask: Tensor,
    cmask: Tensor,
    floor: Tensor,
    resp0: Tensor | None,
    tol: float,
    max_iter: int,
    params0: Params | None = None,
) -> EMResult:
    """EM for every slot of every group at once, from initial responsibilities resp0 (one
    M-step makes the first parameters) or, when resp0 is None, from given parameters
    ``params0`` (a warm start, :func:`params_of`).

    Mirrors sklearn: each iteration is an E-step (log-likelihood of the current parameters) then an
    M-step; a slot stops when |mean log-likelihood change| < tol. The iterations run on a packed
    layout (:func:`_pack`): the real components of running slots side by side, with per-candidate
    sums done by index_sum over rows (index_add_ on the CPU). A stopped slot's parameters are saved
    at once; it stays in the batch, unwatched, until the running components fall below ``_REPACK``
    of the packed ones and the stopped ones hold ``_REPACK_MIN`` (component, point) pairs (a
    re-packing costs about as much as an iteration), and then the batch is re-packed without it, so
    late iterations cost only what still runs. The returned log-likelihood is that of the final
    parameters (one extra E-step), as sklearn's ``score``.
    """
    g0, n, _ = x.shape
    c0, k0 = cmask.shape[1:]
    dev, dt = x.device, x.dtype
    z0 = quadratic_features(x)
    zt0 = z0.transpose(1, 2).contiguous()
    if resp0 is not None:
        params0 = m_step(z0, resp0, cmask, floor)
    elif params0 is None:
        raise ValueError("run_em: pass initial responsibilities resp0 or parameters params0")
    out = [t.reshape(g0 * c0 * k0, *t.shape[3:]).clone() for t in params0]
    n_iter = np.zeros(g0 * c0, dtype=np.int64)
    converged = np.zeros(g0 * c0, dtype=bool)
    n_pts = pmask.sum(1).cpu().numpy()  # [G]
    slot_k = cmask.sum(-1).round().long().cpu().numpy()  # [G0, C0]
    running = np.ones((g0, c0), dtype=bool)
    # the convergence bookkeeping runs in numpy: a few [B, R+1] arrays per iteration, where
    # each torch operation would cost more in dispatch than in arithmetic
    prev_all = np.full(g0 * c0 + 1, -math.inf)
    zt0s = torch.cat([zt0, zt0.new_zeros(g0, 1, n)], 1)  # + the E-step's shift row
    q = zt0.shape[1]
    # the current parameters of every running component, with the weight of the shift row,
    # at table[src[global id]]; the last row is padding: no features, a very low constant
    pad_coef = zt0.new_zeros(1, q + 1)
    pad_coef[0, q - 1], pad_coef[0, q] = _PAD_LOG_WEIGHT, 1.0
    table = torch.cat([torch.cat([out[4], out[4].new_ones(g0 * c0 * k0, 1)], 1), pad_coef])
    src = np.arange(g0 * c0 * k0)
    store = None  # memory of the E-step's [B, M, N] buffers, reused by every packing
    saved: list[tuple[Params, np.ndarray, np.ndarray]] = []
    it = 0
    while it < max_iter and running.any():
        lay = _pack(running, slot_k, k0)
        b, mm = lay.gid.shape
        r = lay.slot.shape[1]
        gk = torch.from_numpy(lay.groups).to(dev)
        pm, npts1 = pmask.index_select(0, gk), n_pts[lay.groups][:, None]
        zt = zt0s.index_select(0, gk)
        valid_np = lay.gid >= 0
        valid = torch.from_numpy(valid_np).to(device=dev, dtype=dt)
        rows = torch.from_numpy((np.arange(b)[:, None] * (r + 1) + lay.row).reshape(-1)).to(dev)
        slot_pad = np.concatenate([lay.slot, np.full((b, 1), -1)], 1)  # [B, R+1]
        row_ok_np = slot_pad >= 0
        row_ok = torch.from_numpy(row_ok_np).to(device=dev, dtype=dt)
        if store is None or store.numel() < 2 * b * mm * n:
            store = zt.new_empty(2 * b * mm * n)
        bt = _batch(zt, pm, rows, valid, row_ok, floor, store)
        slot_ix = np.where(row_ok_np, slot_pad, g0 * c0).reshape(-1)
        take = np.where(valid_np, src[lay.gid], table.shape[0] - 1).reshape(-1)
        coef = table.index_select(0, torch.from_numpy(take).to(dev)).view(b, mm, q + 1)
        prev = prev_all[slot_ix].reshape(b, r + 1)
        active = row_ok_np.copy()  # watched rows: running, not yet stopped
        packed = n_active = int(valid_np.sum())
        shifted = False
        while True:
            it += 1
            ll, resp, _ = _e_step_packed(bt, coef, shifted)
            shifted = True
            ll_np = ll.cpu().numpy()
            mean_ll = ll_np / npts1
            done = (np.abs(mean_ll - prev) < tol) & active
            prev = mean_ll
            params, coef = _m_step_packed(bt, resp)
            last = it >= max_iter
            if not (last or done.any()):
                continue
            stop = (done | active) if last else done
            ids_np = slot_pad[stop]
            n_iter[ids_np] = it
            converged[ids_np] = done[stop]
            sel = valid_np & stop[np.arange(b)[:, None], lay.row]
            saved.append((params, np.flatnonzero(sel), lay.gid[sel]))  # copied out at the end
            running[np.unravel_index(ids_np, running.shape)] = False
            active &= ~stop
            n_active -= int(sel.sum())
            if (
                last
                or n_active == 0
                or (n_active <= _REPACK * packed and (packed - n_active) * n >= _REPACK_MIN)
            ):
                break
        # remember where each running component's parameters are, for the next packing
        table = torch.cat([coef.reshape(b * mm, q + 1), pad_coef])
        src[lay.gid[valid_np]] = np.flatnonzero(valid_np)
        prev_all[slot_ix] = prev.reshape(-1)
    # every stopped slot's parameters, as they were when it stopped, in one copy per field
    dst = torch.from_numpy(np.concatenate([d for _, _, d in saved])).to(dev)
    for i, o in enumerate(out):
        src_i = [
            p[i].reshape(-1, *p[i].shape[2:]).index_select(0, _ix(s, dev)) for p, s, _ in saved
        ]
        o.index_copy_(0, dst, torch.cat(src_i))
    final = Params(*(o.reshape(g0, c0, k0, *o.shape[1:]) for o in out))
    loglik = total_log_likelihood(zt0, final.coef, pmask)
    return EMResult(
        final,
        loglik,
        torch.from_numpy(n_iter).reshape(g0, c0).to(dev),
        torch.from_numpy(converged).reshape(g0, c0).to(dev),
    )


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


# ---------------------------------------------------------------------- warm refits
# A warm refit (``GaussianMixtureSet.refit``) continues each candidate's EM by one step, for
# one action's C candidates at once (candidate c has c + 1 components). It runs on the
# candidates' real components side by side, R = C (C + 1) / 2 rows, with no packing or
# batch bookkeeping: a handful of tensor operations per step.


@functools.lru_cache(maxsize=64)
def warm_rows(n_cand: int, device: torch.device) -> tuple[Tensor, Tensor, Tensor]:
    """Rows of the real components of candidates 1..n_cand: (cand [R] long, comp [R] long,
    indicator [C, R] float64 with 1 where row r belongs to candidate c)."""
    cand = np.repeat(np.arange(n_cand), np.arange(1, n_cand + 1))
    comp = np.concatenate([np.arange(c + 1) for c in range(n_cand)])
    ind = (cand[None, :] == np.arange(n_cand)[:, None]).astype(np.float64)
    return (
        torch.from_numpy(cand).to(device),
        torch.from_numpy(comp).to(device),
        torch.from_numpy(ind).to(device),
    )


def quadratic_features_t(xt: Tensor) -> Tensor:
    """[D, N] (points last) -> zt [Q, N]: :func:`quadratic_features` transposed."""
    i, j, _, _, _, _ = _indices(xt.shape[0], xt.device)
    return torch.cat([xt[i] * xt[j], xt, xt.new_ones(1, xt.shape[1])], 0)


def warm_e_step(zt: Tensor, coef: Tensor, cand: Tensor, ind: Tensor) -> tuple[Tensor, Tensor]:
    """E-step of C candidates over one action's points, with their sufficient statistics.

    zt [Q, N] quadratic features (points last), coef [R, Q] the real components' weighted
    log-density coefficients (:class:`Params` ``coef``), cand [R] and ind [C, R] from
    :func:`warm_rows` -> (loglik [C] total log-likelihood of each candidate, stats [R, Q]
    = sum over the points of resp * z, the M-step's sufficient statistics).

    Each point's log-sum-exp is shifted by its largest component log-density over all
    candidates; where a candidate's shifted sum falls below e^-600 (its best component far
    below another candidate's: the e^-700 clamp could matter), every candidate is shifted
    by its own maximum instead.
    """
    w = coef @ zt  # [R, N]
    mx = w.amax(0)  # [N]
    e = (w - mx).clamp_min_(_CLAMP).exp_()
    s = ind @ e  # [C, N]
    lo = float(s.amin())
    if lo > math.exp(-600.0):
        lse = torch.log(s).add_(mx)
    else:  # per-candidate shifts (rare)
        c, r = ind.shape
        wp = torch.full((c, r, w.shape[1]), -math.inf, dtype=w.dtype, device=w.device)
        wp[cand, torch.arange(r, device=w.device)] = w
        cmx = wp.amax(1)  # [C, N]
        e = (w - cmx.index_select(0, cand)).clamp_min_(_CLAMP).exp_()
        s = ind @ e
        lse = torch.log(s).add_(cmx)
    e.mul_(torch.reciprocal(s).index_select(0, cand))  # responsibilities [R, N]
    stats = (zt @ e.T).T  # zt @ resp^T: the long N axis contiguous in both operands
    return lse.sum(1), stats


def warm_m_step(stats: Tensor, cand: Tensor, n_cand: int, floor: Tensor) -> tuple[Tensor, ...]:
    """M-step from sufficient statistics stats [R, Q] (:func:`warm_e_step`) -> weights [R],
    means [R, D], covariances [R, D, D] (floor on the diagonal); the same estimates as
    :func:`m_step` (nk + 10 eps, weights renormalised per candidate)."""
    q = stats.shape[-1]
    d = _dim_of(q)
    du = q - d - 1
    _, _, full, _, _, _ = _indices(d, stats.device)
    nk = stats[:, -1] + 10.0 * _EPS
    st = stats / nk.unsqueeze(-1)
    means = st[:, du : du + d]
    cov = st.index_select(-1, full).view(-1, d, d)
    cov.sub_(means.unsqueeze(-1) * means.unsqueeze(-2)).add_(torch.diag(floor))
    tot = index_sum(torch.zeros(n_cand, dtype=stats.dtype, device=stats.device), 0, cand, nk)
    return nk / tot.index_select(0, cand), means, cov


def warm_coef(weights: Tensor, means: Tensor, cov: Tensor) -> Tensor:
    """coef [R, Q] of real components: weights [R], means [R, D], cov [R, D, D]."""
    r, d = means.shape
    _, _, _, upper, scale, _ = _indices(d, means.device)
    prec, log_det = _precision(cov)
    lin = (prec * means.unsqueeze(-2)).sum(-1)
    quad = prec.reshape(r, d * d)[:, upper] * scale
    const = torch.log(weights) + log_det - 0.5 * (lin * means).sum(-1) - 0.5 * d * _LOG_2PI
    return torch.cat([quad, lin, const.unsqueeze(-1)], -1)


_LOG_2PI = math.log(2.0 * math.pi)
