"""Batched EM for many full-covariance Gaussian mixtures at once, as small pure functions.

Layout. Data come in ``G`` groups (one group = one action's points), padded to ``N`` points;
each group holds ``C`` candidate *slots* (one slot = one mixture fitted to that group's data),
each padded to ``K`` components:

- ``x``      [G, N, D] float64 observations (padding rows are zeros),
- ``z``      [G, N, Q] their quadratic features (:func:`quadratic_features`),
- ``pmask``  [G, N] float, 1 for a real point and 0 for padding,
- ``cmask``  [G, C, K] float, 1 for a real component of that slot and 0 for padding,
- ``floor``  [D] the variance added to every covariance diagonal.

Grouping by action turns both EM steps into one large matrix product per action
(``[N, Q] @ [Q, C*K]`` and its transpose) instead of many tiny ones per candidate. Every slot
must hold at least one real component (pad unused slots with a copy of a real candidate).

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
_CLAMP = -60.0  # e^-60 ~ 1e-26: negligible next to 1, and far from the subnormal range
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
def _indices(d: int, device: torch.device) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """Upper-triangle (i, j), full [D*D] -> packed map, packed upper positions, quad scale."""
    iu = torch.triu_indices(d, d, device=device)
    i, j = iu[0], iu[1]
    du = i.numel()
    full = torch.zeros(d, d, dtype=torch.long, device=device)
    full[i, j] = torch.arange(du, device=device)
    full[j, i] = torch.arange(du, device=device)
    scale = torch.where(i == j, -0.5, -1.0).to(torch.float64)
    return i, j, full.reshape(-1), i * d + j, scale


def quadratic_features(x: Tensor) -> Tensor:
    """[..., D] -> z [..., Q]: (x_i x_j for i <= j, x, 1), Q = D (D + 1) / 2 + D + 1.

    Both EM steps are then single matrix products: the M-step's sufficient statistics are
    resp^T z, and the E-step's weighted log-densities are z coef^T.
    """
    i, j, _, _, _ = _indices(x.shape[-1], x.device)
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
    eye = torch.eye(covariances.shape[-1], dtype=covariances.dtype, device=covariances.device)
    inv_chol = torch.linalg.solve_triangular(chol, eye.expand_as(chol), upper=False)
    log_det = -torch.log(torch.diagonal(chol, dim1=-2, dim2=-1)).sum(-1)
    return inv_chol.mT, log_det


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
    _, _, full, upper, scale = _indices(d, z.device)
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
    chol, _ = torch.linalg.cholesky_ex(cov)
    prec = torch.cholesky_inverse(chol)
    log_det = -torch.log(torch.diagonal(chol, dim1=-2, dim2=-1)).sum(-1)
    lin = (prec @ means.unsqueeze(-1)).squeeze(-1)
    quad = prec.reshape(g, c, k, d * d)[..., upper] * scale.to(z.dtype)
    const = torch.log(weights) + log_det - 0.5 * (lin * means).sum(-1)
    const = torch.where(cmask > 0, const - 0.5 * d * math.log(2.0 * math.pi), _PAD_LOG_WEIGHT)
    coef = torch.cat([quad, lin, const.unsqueeze(-1)], -1)
    return Params(weights, means, cov, log_det, coef)


def e_step(
    z: Tensor, coef: Tensor, pmask: Tensor, shift: Tensor | None = None
) -> tuple[Tensor, Tensor, Tensor]:
    """Expectation step: z [G, N, Q], coef [G, C, K, Q], pmask [G, N].

    Returns (loglik [G, C], resp [G, N, C, K], lse [G, N, C]): loglik is each slot's total
    log-likelihood over the real points of its group, lse the per-point log-likelihood; resp is
    zero on padded points. ``shift`` [G, N, C] (the previous iteration's lse) replaces the
    per-point maximum as the log-sum-exp shift, saving a pass over the largest array; if the
    shifted sums leave a safe range (some component 40 nats below, or 550 above, the shift)
    the step is recomputed with the exact maximum, so the result never depends on it.
    """
    g, c, k, q = coef.shape
    n = z.shape[1]
    wlp = torch.bmm(z, coef.reshape(g, c * k, q).transpose(1, 2)).reshape(g, n, c, k)
    if shift is not None:
        e = wlp.sub_(shift.unsqueeze(-1)).clamp_(_CLAMP, 600.0).exp_()
        s = e.sum(-1, keepdim=True)
        ls = torch.log(s)
        lo, hi = torch.aminmax(ls)
        if float(lo) > -40.0 and float(hi) < 550.0:
            lse = ls.squeeze(-1) + shift
            loglik = (lse * pmask.unsqueeze(-1)).sum(1)
            return loglik, e.mul_(pmask.reshape(g, n, 1, 1) / s), lse
        wlp = torch.bmm(z, coef.reshape(g, c * k, q).transpose(1, 2)).reshape(g, n, c, k)
    mx = wlp.amax(-1, keepdim=True)
    e = wlp.sub_(mx).clamp_min_(_CLAMP).exp_()
    s = e.sum(-1, keepdim=True)
    lse = (mx + torch.log(s)).squeeze(-1)
    loglik = (lse * pmask.unsqueeze(-1)).sum(1)
    return loglik, e.mul_(pmask.reshape(g, n, 1, 1) / s), lse


def log_gaussian(x: Tensor, means: Tensor, prec_chol: Tensor, log_det: Tensor) -> Tensor:
    """log N(x_n; mu_k, S_k), direct form: x [N, D], means [K, D], prec_chol [K, D, D],
    log_det [K] -> [N, K]."""
    d = x.shape[-1]
    y = torch.einsum("nd,kde->nke", x, prec_chol) - torch.einsum("kd,kde->ke", means, prec_chol)
    return -0.5 * (d * math.log(2.0 * math.pi) + (y * y).sum(-1)) + log_det


def _splitmix_uniform(keys: np.ndarray) -> np.ndarray:
    """Deterministic uniforms in [0, 1) from uint64 keys (splitmix64 finaliser)."""
    with np.errstate(over="ignore"):
        z = keys.astype(np.uint64) + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)).astype(np.float64) * (2.0**-53)


def candidate_uniforms(seed: int, action: np.ndarray, n_comp: np.ndarray, k: int) -> np.ndarray:
    """Uniforms [..., k] that depend only on (seed, action, component count, draw index).

    ``action`` and ``n_comp`` are integer arrays of the same shape. A candidate's
    initialisation so does not depend on which other candidates share its batch: fitting all
    actions at once equals fitting them one at a time.
    """
    with np.errstate(over="ignore"):
        base = (
            np.uint64(seed & 0xFFFFFFFF) * np.uint64(0x100000001B3)
            + np.asarray(action).astype(np.uint64) * np.uint64(0x9E3779B1)
            + np.asarray(n_comp).astype(np.uint64) * np.uint64(0x85EBCA77)
        )
        keys = base[..., None] * np.uint64(1315423911) + np.arange(k, dtype=np.uint64)
    return _splitmix_uniform(keys)


def kmeans_init(
    x: Tensor, pmask: Tensor, cmask: Tensor, uniforms: Tensor, n_lloyd: int = 10
) -> Tensor:
    """k-means++ seeding then Lloyd iterations for every slot; returns one-hot resp [G,N,C,K].

    x [G, N, D], pmask [G, N], cmask [G, C, K], uniforms [G, C, K] drive the seeding draws
    (inverse CDF over the D^2 weights), so the result is a pure function of the data and the
    uniforms. Lloyd stops early when no label changes anywhere.
    """
    g, n, d = x.shape
    c, k = cmask.shape[1:]
    centers = torch.zeros(g, c, k, d, dtype=x.dtype, device=x.device)
    d2 = torch.full((g, c, n), math.inf, dtype=x.dtype, device=x.device)
    pm = pmask.unsqueeze(1).expand(g, c, n)
    flat_x = x.unsqueeze(1).expand(g, c, n, d)
    for j in range(k):
        w = pm if j == 0 else d2 * pm
        w = torch.where(w.sum(-1, keepdim=True) > 0, w, pm)  # all distances 0: uniform draw
        cdf = torch.cumsum(w, -1)
        target = uniforms[..., j : j + 1] * cdf[..., -1:]
        idx = torch.searchsorted(cdf, target, right=True).clamp_max(n - 1)  # [G, C, 1]
        cj = torch.gather(flat_x, 2, idx.unsqueeze(-1).expand(g, c, 1, d))  # [G, C, 1, D]
        centers[:, :, j] = cj.squeeze(2)
        d2 = torch.minimum(d2, ((x.unsqueeze(1) - cj) ** 2).sum(-1))
    pad = torch.where(cmask > 0, 0.0, math.inf).to(x.dtype)  # [G, C, K]
    base = (torch.arange(g * c, device=x.device) * k).reshape(g, 1, c)  # slot offsets
    xw = (x * pmask.unsqueeze(-1)).unsqueeze(2).expand(g, n, c, d).reshape(-1, d)
    pw = pmask.unsqueeze(-1).expand(g, n, c).reshape(-1)
    labels = None
    for _ in range(max(n_lloyd, 1)):
        c2 = ((centers * centers).sum(-1) + pad).reshape(g, 1, c * k)
        # x @ (-2 c)^T + |c|^2 (bmm then add: baddbmm would first copy the broadcast |c|^2)
        dist = torch.bmm(x, centers.reshape(g, c * k, d).transpose(1, 2) * -2.0).add_(c2)
        new_labels = dist.reshape(g, n, c, k).argmin(-1)  # [G, N, C]
        if labels is not None and torch.equal(new_labels, labels):
            break
        labels = new_labels
        flat = (labels + base).reshape(-1)
        counts = torch.zeros(g * c * k, dtype=x.dtype, device=x.device).index_add_(0, flat, pw)
        sums = torch.zeros(g * c * k, d, dtype=x.dtype, device=x.device).index_add_(0, flat, xw)
        counts = counts.reshape(g, c, k, 1)
        centers = torch.where(counts > 0, sums.reshape(g, c, k, d) / counts.clamp_min(1.0), centers)
    resp = torch.nn.functional.one_hot(labels, k).to(x.dtype)
    return resp.mul_(pmask.reshape(g, n, 1, 1))


class EMResult(NamedTuple):
    """Output of :func:`run_em`: params [G, C, K, ...], loglik [G, C] (total log-likelihood
    of the final parameters), n_iter [G, C] long, converged [G, C] bool."""

    params: Params
    loglik: Tensor
    n_iter: Tensor
    converged: Tensor


class _Layout(NamedTuple):
    """Packed layout of the running candidates: components of every running slot side by side.

    ``gid`` [G, M] numpy: global component id (slot * K0 + j) of each packed component, -1 for
    padding; ``row`` [G, M] numpy: the candidate row (0..R-1) it belongs to, R for padding;
    ``slot`` [G, R] numpy: flat slot id of each candidate row, -1 for padding;
    ``groups``: the original group of each row of the batch.
    """

    gid: np.ndarray
    row: np.ndarray
    slot: np.ndarray
    groups: np.ndarray


def _pack(running: np.ndarray, slot_k: np.ndarray, k0: int) -> _Layout:
    """Layout of the running slots: running [G0, C0] bool, slot_k [G0, C0] component counts."""
    groups = np.flatnonzero(running.any(1))
    n_rows = int(running[groups].sum(1).max())
    n_comp = int((running * slot_k)[groups].sum(1).max())
    g = groups.size
    gid = np.full((g, n_comp), -1, dtype=np.int64)
    row = np.full((g, n_comp), n_rows, dtype=np.int64)
    slot = np.full((g, n_rows), -1, dtype=np.int64)
    c0 = running.shape[1]
    for i, g0 in enumerate(groups):
        cs = np.flatnonzero(running[g0])
        ks = slot_k[g0, cs]
        slot[i, : cs.size] = g0 * c0 + cs
        m = int(ks.sum())
        row[i, :m] = np.repeat(np.arange(cs.size), ks)
        within = np.arange(m) - np.repeat(np.cumsum(ks) - ks, ks)
        gid[i, :m] = np.repeat((g0 * c0 + cs) * k0, ks) + within
    return _Layout(gid, row, slot, groups)


def _m_step_packed(
    zt: Tensor, resp: Tensor, rows: Tensor, valid: Tensor, row_pad: Tensor, floor: Tensor
) -> tuple[Params, Tensor]:
    """M-step in the packed layout: zt [G, Q, N] (contiguous), resp [G, M, N] -> (Params
    [G, M, ...], coef [G, M, Q]).

    ``rows`` [G*M] flat candidate-row index (g * (R+1) + row), ``valid`` [G, M] 1 for a real
    component, ``row_pad`` [G*(R+1)] 1 for a padding row (keeps its weight sum non-zero).
    """
    g, m, _ = resp.shape
    q = zt.shape[1]
    d = _dim_of(q)
    du = q - d - 1
    _, _, full, upper, scale = _indices(d, zt.device)
    # zt @ resp^T: with the long N axis contiguous in both operands, ~1.7x faster than resp @ z
    stats = torch.bmm(zt, resp.transpose(1, 2)).transpose(1, 2)  # [G, M, Q]
    nk = stats[..., -1] + 10.0 * _EPS
    stats = stats / nk.unsqueeze(-1)
    means = stats[..., du : du + d]
    cov = stats[..., full].reshape(g, m, d, d)
    cov -= means.unsqueeze(-1) * means.unsqueeze(-2)
    cov.diagonal(dim1=-2, dim2=-1).add_(floor)
    wn = (nk * valid).reshape(-1)
    wsum = row_pad.clone().index_add_(0, rows, wn)
    weights = (wn / wsum.index_select(0, rows)).reshape(g, m)
    chol, _ = torch.linalg.cholesky_ex(cov)
    prec = torch.cholesky_inverse(chol)
    log_det = -torch.log(torch.diagonal(chol, dim1=-2, dim2=-1)).sum(-1)
    lin = (prec @ means.unsqueeze(-1)).squeeze(-1)
    quad = prec.reshape(g, m, d * d)[..., upper] * scale.to(zt.dtype)
    const = torch.log(weights) + log_det - 0.5 * (lin * means).sum(-1)
    const = torch.where(valid > 0, const - 0.5 * d * math.log(2.0 * math.pi), _PAD_LOG_WEIGHT)
    coef = torch.cat([quad, lin, const.unsqueeze(-1)], -1)
    return Params(weights, means, cov, log_det, coef), coef


def _shifted_sums(
    wlp: Tensor, shift: Tensor, rows: Tensor, row_pad: Tensor, r1: int, *, lowest: float
) -> tuple[Tensor, Tensor, Tensor] | None:
    """exp(wlp - shift) [G, M, N] (in place on wlp), its per-candidate sums s [G*R1, N] and
    log(s), or None when the shift was too far off: some candidate's log-sum below ``lowest``
    (the clamp at _CLAMP would then cost precision) or near overflow."""
    n = wlp.shape[-1]
    e = wlp.sub_(shift).clamp_(_CLAMP, 600.0).exp_()
    s = torch.zeros(wlp.shape[0] * r1, n, dtype=e.dtype, device=e.device)
    s = s.index_add_(0, rows, e.reshape(-1, n)).add_(row_pad.unsqueeze(-1))
    ls = torch.log(s)
    lo, hi = torch.aminmax(ls)
    return (e, s, ls) if float(lo) > lowest and float(hi) < 550.0 else None


def _e_step_packed(
    zt: Tensor,
    coef: Tensor,
    pm: Tensor,
    rows: Tensor,
    row_pad: Tensor,
    row_ok: Tensor,
    shift: Tensor | None,
    shared: bool = False,
) -> tuple[Tensor, Tensor, Tensor, bool]:
    """E-step in the packed layout: zt [G, Q, N], coef [G, M, Q], pm [G, N].

    Returns (loglik [G, R+1], resp [G, M, N], lse [G, R+1, N], shared_ok); rows as in
    _m_step_packed, row_pad [G*(R+1)] 1 on padding rows, row_ok [G, R+1] 1 on real rows.
    The log-sum-exp shift, first choice that keeps every candidate's sums in a safe range:
    with ``shared``, one shift per point for all candidates of a group (the largest previous
    lse; safe when no candidate's sum falls below e^-20 of it, so the e^-60 clamp changes
    nothing above 1e-16 relative: saves expanding a shift per component); then ``shift``
    (the previous lse, per candidate); then the exact per-candidate maximum. ``shared_ok``
    is False when the shared shift was tried and rejected.
    """
    g, m, _ = coef.shape
    n = zt.shape[-1]
    r1 = row_ok.shape[1]
    wlp = torch.bmm(coef, zt)  # [G, M, N]
    lse = None
    shared_ok = True
    if shift is not None and shared:
        gs = shift.masked_fill(row_ok.unsqueeze(-1) == 0, -math.inf).amax(1, keepdim=True)
        tried = _shifted_sums(wlp, gs, rows, row_pad, r1, lowest=-20.0)
        if tried is not None:
            e, s, ls = tried
            lse = ls.reshape(g, r1, n) + gs
        else:
            shared_ok = False
            wlp = torch.bmm(coef, zt)
    if shift is not None and lse is None:
        sh = shift.reshape(-1, n).index_select(0, rows).reshape(g, m, n)
        tried = _shifted_sums(wlp, sh, rows, row_pad, r1, lowest=-40.0)
        if tried is not None:
            e, s, ls = tried
            lse = ls.reshape(g, r1, n) + shift
        else:
            wlp = torch.bmm(coef, zt)
    if lse is None:
        mx = torch.full((g * r1, n), -math.inf, dtype=wlp.dtype, device=wlp.device)
        mx = mx.scatter_reduce_(0, rows.unsqueeze(-1).expand(-1, n), wlp.reshape(-1, n), "amax")
        mx = torch.where(row_pad.unsqueeze(-1) > 0, 0.0, mx)
        e = wlp.sub_(mx.index_select(0, rows).reshape(g, m, n)).clamp_min_(_CLAMP).exp_()
        s = torch.zeros(g * r1, n, dtype=e.dtype, device=e.device)
        s = s.index_add_(0, rows, e.reshape(-1, n)).add_(row_pad.unsqueeze(-1))
        lse = (torch.log(s) + mx).reshape(g, r1, n)
    loglik = (lse * pm.unsqueeze(1)).sum(-1)
    inv = (pm.unsqueeze(1) * row_ok.unsqueeze(-1)).reshape(-1, n) / s
    e.mul_(inv.index_select(0, rows).reshape(g, m, n))
    return loglik, e, lse, shared_ok


def run_em(
    x: Tensor,
    pmask: Tensor,
    cmask: Tensor,
    floor: Tensor,
    resp0: Tensor,
    tol: float,
    max_iter: int,
) -> EMResult:
    """EM for every slot of every group at once, from initial responsibilities resp0.

    Mirrors sklearn: each iteration is an E-step (log-likelihood of the current parameters)
    then an M-step; a slot stops when |mean log-likelihood change| < tol. The iterations run
    on a packed layout: the real components of every running slot of a group side by side
    (no padding to the largest component count), with per-candidate sums done by index_add
    over rows. Stopped slots leave the batch (the layout is re-packed only when some slot
    stops), so late iterations cost only what still runs. The returned log-likelihood is that
    of the final parameters (one extra E-step), as sklearn's ``score``.
    """
    g0, n, _ = x.shape
    c0, k0 = cmask.shape[1:]
    dev = x.device
    z0 = quadratic_features(x)
    params0 = m_step(z0, resp0, cmask, floor)
    out = [t.reshape(g0 * c0 * k0, *t.shape[3:]).clone() for t in params0]
    n_iter = torch.zeros(g0 * c0, dtype=torch.long, device=dev)
    converged = torch.zeros(g0 * c0, dtype=torch.bool, device=dev)
    n_pts = pmask.sum(1)  # [G]
    slot_k = cmask.sum(-1).round().long().cpu().numpy()  # [G0, C0]
    running = np.ones((g0, c0), dtype=bool)
    prev_all = torch.full((g0 * c0 + 1,), -math.inf, dtype=x.dtype, device=dev)
    lse_all = None  # [G0*C0 + 1, N] last lse of every slot (by flat slot id)
    flat_coef = out[4]  # where the current parameters are: flat_coef[src_gid[global id]]
    src_gid = None
    shared = True  # try the shared shift until it is once rejected
    it = 0
    while it < max_iter and running.any():
        lay = _pack(running, slot_k, k0)
        g, mm = lay.gid.shape
        r = lay.slot.shape[1]
        gk = torch.from_numpy(lay.groups).to(dev)
        z, pm, npts = z0.index_select(0, gk), pmask.index_select(0, gk), n_pts.index_select(0, gk)
        zt = z.transpose(1, 2).contiguous()
        valid_np = lay.gid >= 0
        valid = torch.from_numpy(valid_np.astype(np.float64)).to(device=dev, dtype=x.dtype)
        rows = torch.from_numpy((np.arange(g)[:, None] * (r + 1) + lay.row).reshape(-1)).to(dev)
        slot_pad = np.concatenate([lay.slot, np.full((g, 1), -1)], 1)  # [G, R+1]
        row_ok_np = slot_pad >= 0
        row_ok = torch.from_numpy(row_ok_np.astype(np.float64)).to(device=dev, dtype=x.dtype)
        row_pad = (1.0 - row_ok).reshape(-1)
        slot_ix = torch.from_numpy(np.where(row_ok_np, slot_pad, g0 * c0).reshape(-1)).to(dev)
        # current parameters of the packed components (padding: copy of a real one, masked)
        first = np.where(valid_np, lay.gid, lay.gid[:, :1])
        take = torch.from_numpy(first.reshape(-1)).to(dev)
        if src_gid is not None:
            take = src_gid.index_select(0, take)
        coef = flat_coef.index_select(0, take).reshape(g, mm, -1)
        coef = torch.where(valid.unsqueeze(-1) > 0, coef, coef[..., :1] * 0.0)
        coef[..., -1] = torch.where(valid > 0, coef[..., -1], _PAD_LOG_WEIGHT)
        prev = prev_all.index_select(0, slot_ix).reshape(g, r + 1)
        shift = None
        if lse_all is not None:
            shift = lse_all.index_select(0, slot_ix).reshape(g, r + 1, n)
        while True:
            it += 1
            ll, resp, shift, shared = _e_step_packed(
                zt, coef, pm, rows, row_pad, row_ok, shift, shared
            )
            params, coef = _m_step_packed(zt, resp, rows, valid, row_pad, floor)
            mean_ll = ll / npts.unsqueeze(-1)
            done = ((mean_ll - prev).abs() < tol) & (row_ok > 0)
            prev = mean_ll
            if it < max_iter and not bool(done.any()):
                continue
            break
        stop = done.cpu().numpy() | ((it == max_iter) & row_ok_np)
        ids_np = slot_pad[stop]
        ids = torch.from_numpy(ids_np).to(dev)
        n_iter[ids] = it
        converged[ids] = torch.from_numpy(done.cpu().numpy()[stop]).to(dev)
        sel = valid_np & stop[np.arange(g)[:, None], lay.row]
        pos = torch.from_numpy(np.flatnonzero(sel)).to(dev)
        dst = torch.from_numpy(lay.gid[sel]).to(dev)
        for o, p in zip(out, params, strict=True):
            o.index_copy_(0, dst, p.reshape(g * mm, *p.shape[2:]).index_select(0, pos))
        running[np.unravel_index(ids_np, running.shape)] = False
        # remember where each running component's parameters are, for the next packing
        flat_coef = coef.reshape(g * mm, -1)
        src = np.zeros(g0 * c0 * k0, dtype=np.int64)
        src[lay.gid[valid_np]] = np.flatnonzero(valid_np)
        src_gid = torch.from_numpy(src).to(dev)
        prev_all = prev_all.index_copy(0, slot_ix, prev.reshape(-1))
        if lse_all is None:
            lse_all = torch.zeros(g0 * c0 + 1, n, dtype=x.dtype, device=dev)
        lse_all = lse_all.index_copy(0, slot_ix, shift.reshape(-1, n))
    final = Params(*(o.reshape(g0, c0, k0, *o.shape[1:]) for o in out))
    loglik, _, _ = e_step(z0, final.coef, pmask)
    return EMResult(final, loglik, n_iter.reshape(g0, c0), converged.reshape(g0, c0))


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
