"""The packed E-step gives the same result whichever log-sum-exp shift it ends up using."""

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
    zt = _em.quadratic_features(x).transpose(1, 2).contiguous()
    # random SPD Gaussians through the M-step of random responsibilities
    m = sum(ks)
    row = np.repeat(np.arange(r), ks)
    rows = torch.from_numpy((np.arange(g)[:, None] * (r + 1) + row[None]).reshape(-1))
    valid = torch.ones(g, m, dtype=torch.float64)
    row_ok = torch.ones(g, r + 1, dtype=torch.float64)
    row_ok[:, r] = 0.0
    row_pad = (1.0 - row_ok).reshape(-1)
    resp = torch.rand(g, m, n, generator=gen, dtype=torch.float64)
    floor = torch.full((d,), 1e-2, dtype=torch.float64)
    _, coef = _em._m_step_packed(zt, resp, rows, valid, row_pad, floor)
    pm = torch.ones(g, n, dtype=torch.float64)
    pm[1, -7:] = 0.0  # padded points in the second group
    return zt, coef, pm, rows, row_pad, row_ok


@pytest.mark.parametrize("offset", [0.0, 0.5, 30.0, -30.0])
@pytest.mark.parametrize("shared", [False, True])
def test_packed_e_step_does_not_depend_on_the_shift(offset, shared):
    zt, coef, pm, rows, row_pad, row_ok = _packed_problem()
    ll0, resp0, lse0, _ = _em._e_step_packed(zt, coef, pm, rows, row_pad, row_ok, None)
    shift = lse0.clone()
    shift[:, 1] += offset  # one candidate's previous lse far off: forces the fallbacks
    ll, resp, lse, shared_ok = _em._e_step_packed(
        zt, coef, pm, rows, row_pad, row_ok, shift, shared
    )
    real = row_ok > 0
    torch.testing.assert_close(ll[real], ll0[real], rtol=1e-12, atol=1e-10)
    torch.testing.assert_close(resp, resp0, rtol=1e-10, atol=1e-14)
    torch.testing.assert_close(lse[real], lse0[real], rtol=1e-12, atol=1e-10)
    if shared and offset >= 30.0:  # the others then sum to ~e^-30 of the shared shift
        assert not shared_ok
    # responsibilities of each candidate sum to one on real points, zero on padding
    sums = torch.zeros(2 * 4, zt.shape[-1], dtype=torch.float64)
    sums.index_add_(0, rows, resp.reshape(-1, zt.shape[-1]))
    sums = sums.reshape(2, 4, -1)[:, :3]
    torch.testing.assert_close(sums, pm.unsqueeze(1).expand_as(sums), rtol=1e-12, atol=1e-12)
