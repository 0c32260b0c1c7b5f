"""The packed E-step against a direct log-sum-exp per candidate, whichever shift it uses."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchcbl import _em


def _packed_problem(seed: int = 0):
    gen = torch.Generator().manual_seed(seed)
    g, n, d = 2, 50, 3
    ks = [1, 3, 2]  # candidate component counts, the same in both groups
    r = len(ks)
    x = torch.randn(g, n, d, generator=gen, dtype=torch.float64)
    zt = _em.quadratic_features(x).transpose(1, 2)
    zt = torch.cat([zt, torch.zeros(g, 1, n, dtype=torch.float64)], 1)  # + the shift row
    # random SPD Gaussians through the M-step of random responsibilities
    m = sum(ks) + 1  # one padded component at the end of each batch row
    row = np.r_[np.repeat(np.arange(r), ks), r]
    rows = torch.from_numpy((np.arange(g)[:, None] * (r + 1) + row[None]).reshape(-1))
    valid = torch.ones(g, m, dtype=torch.float64)
    valid[:, -1] = 0.0
    row_ok = torch.ones(g, r + 1, dtype=torch.float64)
    row_ok[:, r] = 0.0
    resp = torch.rand(g, m, n, generator=gen, dtype=torch.float64) * valid.unsqueeze(-1)
    floor = torch.full((d,), 1e-2, dtype=torch.float64)
    pm = torch.ones(g, n, dtype=torch.float64)
    pm[1, -7:] = 0.0  # padded points in the second group

    def batch(buffers: bool) -> _em._Batch:
        return _em._batch(zt.clone(), pm, rows, valid, row_ok, floor, buffers)

    _, coef = _em._m_step_packed(batch(False), resp)
    return batch, coef, pm, rows, ks


def _direct(zt, coef, pm, ks):  # zt [G, Q+1, N], coef [G, M, Q+1]
    """Per candidate: log-sum-exp over its components with torch.logsumexp, and resp."""
    w = torch.bmm(coef[..., :-1], zt[:, :-1])  # [G, M, N], without the shift row
    lls, resps, start = [], [], 0
    for k in ks:
        part = w[:, start : start + k]
        lse = torch.logsumexp(part, 1)  # [G, N]
        lls.append((lse * pm).sum(-1))
        resps.append(torch.exp(part - lse.unsqueeze(1)) * pm.unsqueeze(1))
        start += k
    return torch.stack(lls, 1), torch.cat(resps, 1)


@pytest.mark.parametrize("shift", [None, 0.0, 30.0, -30.0, 650.0, -650.0])
@pytest.mark.parametrize("offset", [0.0, -650.0, -2000.0])
def test_packed_e_step_equals_a_direct_log_sum_exp(offset, shift):
    """Whatever shift row it is given (None: none), the E-step gives the direct result.

    ``offset`` scales one candidate's weights by e^offset: beyond -600 nats the shared shift of
    the batch row is refused and each candidate's own maximum is used instead; a given shift
    600 nats off is refused too.
    """
    batch, coef, pm, rows, ks = _packed_problem()
    coef[:, 1:4, -2] += offset  # the constant term of candidate 1 (components 1..3)
    ll_ref, resp_ref = _direct(batch(False).zt, coef, pm, ks)
    for buffers in [False, True]:
        bt = batch(buffers)
        if shift is not None:  # the previous iteration's shift row, moved by ``shift`` nats
            _em._e_step_packed(bt, coef)
            bt.shift.sub_(shift)
        ll, resp, lse = _em._e_step_packed(bt, coef, shifted=shift is not None)
        torch.testing.assert_close(ll[:, :3], ll_ref, rtol=1e-12, atol=1e-9)
        torch.testing.assert_close(resp[:, :-1], resp_ref, rtol=1e-10, atol=1e-14)
        assert bool((resp[:, -1] == 0).all())  # the padded component gets nothing
        torch.testing.assert_close(  # the shift row left for the next step: the best lse
            -bt.zt[:, -1], lse[:, :3].amax(1), rtol=0.0, atol=0.0
        )
    n = resp.shape[-1]
    # responsibilities of each candidate sum to one on real points, zero on padding
    sums = torch.zeros(2 * 4, n, dtype=torch.float64)
    sums.index_add_(0, rows, resp.reshape(-1, n))
    sums = sums.reshape(2, 4, -1)[:, :3]
    torch.testing.assert_close(sums, pm.unsqueeze(1).expand_as(sums), rtol=1e-12, atol=1e-12)


def test_pack_balances_rows_and_keeps_every_component_once():
    running = np.ones((4, 10), dtype=bool)
    running[1:, 5:] = False  # one group with much more left to fit than the others
    slot_k = np.tile(np.arange(1, 11), (4, 1))
    lay = _em._pack(running, slot_k, 10)
    gids = lay.gid[lay.gid >= 0]
    expect = [
        s * 10 + j
        for g in range(4)
        for c in range(10)
        if running[g, c]
        for s in [g * 10 + c]
        for j in range(c + 1)
    ]
    assert sorted(gids.tolist()) == sorted(expect)
    for b in range(lay.gid.shape[0]):  # a row's components belong to its group's slots
        real = lay.gid[b] >= 0
        assert set((lay.gid[b, real] // 10 // 10).tolist()) == {int(lay.groups[b])}
        slots = lay.slot[b][lay.row[b, real]]
        assert bool((slots == lay.gid[b, real] // 10).all())
    # group 0 (55 components) is split; one row per group would pad every row to 55
    assert lay.gid.shape[1] < 55
    assert lay.gid.size < 4 * 55


@pytest.mark.parametrize("d", [3, 6])  # precision by LU inverse (D <= 4) or triangular inverse
def test_packed_m_step_equals_the_padded_m_step(d):
    """Same responsibilities -> same mixtures in the packed and the padded layouts."""
    gen = torch.Generator().manual_seed(3)
    g, n, ks = 2, 40, [1, 3, 2]
    x = torch.randn(g, n, d, generator=gen, dtype=torch.float64)
    z = _em.quadratic_features(x)
    floor = torch.full((d,), 1e-3, dtype=torch.float64)
    c, k = len(ks), max(ks)
    cmask = (torch.arange(k) < torch.tensor(ks).unsqueeze(-1)).to(torch.float64).expand(g, c, k)
    resp_pad = torch.rand(g, n, c, k, generator=gen, dtype=torch.float64) * cmask.unsqueeze(1)
    ref = _em.m_step(z, resp_pad, cmask.contiguous(), floor)
    # packed: the real components of each group side by side, then one padded component
    real = cmask[0].reshape(-1) > 0
    m = int(real.sum()) + 1
    resp = torch.zeros(g, m, n, dtype=torch.float64)
    resp[:, :-1] = resp_pad.reshape(g, n, c * k)[:, :, real].transpose(1, 2)
    row = np.r_[np.repeat(np.arange(c), ks), c]
    rows = torch.from_numpy((np.arange(g)[:, None] * (c + 1) + row[None]).reshape(-1))
    valid = torch.ones(g, m, dtype=torch.float64)
    valid[:, -1] = 0.0
    row_ok = torch.ones(g, c + 1, dtype=torch.float64)
    row_ok[:, c] = 0.0
    zt = torch.cat([z.transpose(1, 2), torch.zeros(g, 1, n, dtype=torch.float64)], 1)
    bt = _em._batch(zt, torch.ones(g, n, dtype=torch.float64), rows, valid, row_ok, floor)
    got, coef = _em._m_step_packed(bt, resp)
    for name in ("weights", "means", "covariances", "log_det", "coef"):
        want = getattr(ref, name).reshape(g, c * k, *getattr(ref, name).shape[3:])[:, real]
        torch.testing.assert_close(getattr(got, name)[:, :-1], want, rtol=1e-10, atol=1e-12)
    assert bool((coef[..., -1] == 1).all())  # the weight of the E-step's shift row
    assert float(got.weights[:, -1].abs().max()) == 0.0  # the padded component weighs nothing


@pytest.mark.parametrize("d", [1, 2, 3, 4, 6])  # LU route (D <= 4) and Cholesky route
def test_precision_and_log_det_against_numpy(d):
    """The precision matrices and -1/2 log det of SPD covariances (rows swapped or not by
    LU's pivoting) equal numpy's inverse and slogdet; a matrix with a negative determinant
    gives NaN, not a finite log-likelihood."""
    rng = np.random.default_rng(d)
    a = rng.normal(size=(50, d, d + 2))
    cov = a @ a.transpose(0, 2, 1) / (d + 2) + 0.05 * np.eye(d)
    cov[0] = np.diag(np.arange(1.0, d + 1))  # diagonal
    v = np.r_[0.1, np.ones(d - 1)]
    cov[1] = np.outer(v, v) + 0.01 * np.eye(d)  # a small first variance: LU swaps rows
    if d > 1:
        _, piv = torch.linalg.lu_factor(torch.from_numpy(cov[1]))
        assert bool((piv != torch.arange(1, d + 1, dtype=piv.dtype)).any())
    prec, log_det = _em._precision(torch.from_numpy(cov))
    np.testing.assert_allclose(prec.numpy(), np.linalg.inv(cov), rtol=1e-9, atol=1e-12)
    sign, logdet = np.linalg.slogdet(cov)
    assert (sign > 0).all()
    np.testing.assert_allclose(log_det.numpy(), -0.5 * logdet, rtol=1e-12, atol=1e-12)
    bad = cov[:3].copy()
    bad[0, 0, 0] = -1.0  # one negative pivot: determinant < 0 (d = 1) or indefinite
    bad[1, 0, 0] = np.nan
    _, ld_bad = _em._precision(torch.from_numpy(bad))
    assert bool(torch.isnan(ld_bad[1]))
    if np.linalg.det(bad[0]) < 0:
        assert bool(torch.isnan(ld_bad[0]))
    assert bool(torch.isfinite(ld_bad[2]))
