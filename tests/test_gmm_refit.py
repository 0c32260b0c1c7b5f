"""Incremental refits (GaussianMixtureSet.refit) and the thread policy (issue 17)."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import time

import numpy as np
import pytest
import torch

from torchcbl import _em
from torchcbl import gmm as gmm_mod
from torchcbl.gmm import GaussianMixtureSet


def _stream(n: int = 400, d: int = 3, a: int = 3, seed: int = 0):
    """n demonstrations, each action's observations from 3 Gaussian blobs, shuffled."""
    rng = np.random.default_rng(seed)
    centres = rng.normal(scale=3.0, size=(a, 3, d))
    y = rng.integers(0, a, n)
    comp = rng.integers(0, 3, n)
    x = centres[y, comp] + rng.normal(scale=0.7, size=(n, d))
    return x, y


def _replay(model: GaussianMixtureSet, x, y, counts) -> GaussianMixtureSet:
    for n in counts:
        model.refit(x[:n], y[:n])
    return model


def _assert_same_state(m1: GaussianMixtureSet, m2: GaussianMixtureSet) -> None:
    s1, s2 = m1.state_dict(), m2.state_dict()
    assert s1.keys() == s2.keys()
    for key in s1:
        assert torch.equal(s1[key], s2[key]), key


def test_refit_before_any_fit_is_fit():
    x, y = _stream(120)
    a = GaussianMixtureSet(3, 3, 5, seed=3).refit(x, y)
    b = GaussianMixtureSet(3, 3, 5, seed=3).fit(x, y)
    _assert_same_state(a, b)
    assert a.fit_report_.refit_kind == ("scratch",) * 3


def test_fit_on_a_fitted_model_is_a_fit_from_scratch_bit_for_bit():
    """fit() of a model fitted before gave the state a fresh model's fit gives, except the
    refit statistics: an action without points in the new data kept the old data's
    fingerprint, and every action the old warm refits' statistics (unused, stats_valid_
    False, but a session whose first refit after a fitted start lacked an action was not
    rebuilt from its log bit for bit). They now start from a fresh model's values."""
    x, y = _stream(200)
    m = _replay(GaussianMixtureSet(3, 3, 5, seed=3), x, y, range(20, 201, 5))
    assert bool(m.cand_stats_.any())  # warm refits kept their statistics
    keep = y[:60] != 1  # and the new data lacks action 1
    m.fit(x[:60][keep], y[:60][keep])
    _assert_same_state(m, GaussianMixtureSet(3, 3, 5, seed=3).fit(x[:60][keep], y[:60][keep]))


def test_refit_on_unchanged_data_keeps_every_mixture():
    x, y = _stream(150)
    m = GaussianMixtureSet(3, 3, 5).fit(x, y)
    before = {k: v.clone() for k, v in m.state_dict().items()}
    m.refit(x, y)
    assert m.fit_report_.refit_kind == ("kept",) * 3
    for key, val in m.state_dict().items():
        assert torch.equal(val, before[key]), key


def test_one_new_point_refits_only_its_action_warm():
    x, y = _stream(301)
    y[-1] = 1
    m = GaussianMixtureSet(3, 3, 5).fit(x[:300], y[:300])
    before = {k: v.clone() for k, v in m.state_dict().items()}
    m.refit(x, y)
    assert m.fit_report_.refit_kind == ("kept", "warm", "kept")
    for key in ("weights_", "means_", "covariances_", "cand_weights_", "cand_means_"):
        for a in (0, 2):
            assert torch.equal(getattr(m, key)[a], before[key][a]), (key, a)
        assert not torch.equal(getattr(m, key)[1], before[key][1]), key
    # the priors follow all the data
    counts = np.bincount(y, minlength=3)
    np.testing.assert_allclose(m.log_prior_.numpy(), np.log(counts / len(y)), rtol=1e-12)


def test_warm_start_equals_sklearn_started_from_the_kept_candidate():
    """Oracle: each warm-started candidate takes sklearn's EM step(s) from its previous
    parameters; EM continues across refits, so a refit runs _WARM_ITER - 1 M-steps and keeps
    the parameters its last E-step measured (sklearn with max_iter = _WARM_ITER - 1)."""
    import warnings

    from sklearn.exceptions import ConvergenceWarning
    from sklearn.mixture import GaussianMixture

    x, y = _stream(241, d=2, seed=5)
    y[-1] = 0
    # var_floor=0: the floor is one number for every feature, sklearn's reg_covar
    m = GaussianMixtureSet(3, 2, 4, var_floor=0.0, tol=1e-4, seed=1).fit(x[:240], y[:240])
    kept = (m.cand_weights_[0].clone(), m.cand_means_[0].clone(), m.cand_covariances_[0].clone())
    m.refit(x, y)
    assert m.fit_report_.refit_kind[0] == "warm"
    x0 = x[y == 0]
    reg = float(m.var_floor_[0])
    assert float(m.var_floor_[1]) == reg
    for k in range(1, 5):
        w, mu, cov = kept[0][k - 1, :k], kept[1][k - 1, :k], kept[2][k - 1, :k]
        gm = GaussianMixture(
            k,
            covariance_type="full",
            tol=1e-4,
            max_iter=gmm_mod._WARM_ITER - 1,
            reg_covar=reg,
            weights_init=w.numpy(),
            means_init=mu.numpy(),
            precisions_init=torch.linalg.inv(cov).numpy(),
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            gm.fit(x0)
        assert float(m.fit_report_.log_likelihood[0, k - 1]) == pytest.approx(
            gm.score(x0) * len(x0), rel=1e-9
        )
        np.testing.assert_allclose(m.cand_means_[0, k - 1, :k].numpy(), gm.means_, rtol=1e-9)
        np.testing.assert_allclose(m.cand_weights_[0, k - 1, :k].numpy(), gm.weights_, rtol=1e-9)
        assert int(m.fit_report_.n_iter[0, k - 1]) == gmm_mod._WARM_ITER
        # converged: the kept parameters' mean log-likelihood moved by less than tol in the
        # refit's last EM step (from the previous parameters, on the same data)
        w0 = GaussianMixture(
            k, covariance_type="full", reg_covar=reg, weights_init=w.numpy(),
            means_init=mu.numpy(), precisions_init=torch.linalg.inv(cov).numpy(),
        )  # fmt: skip
        w0._initialize_parameters(x0, np.random.RandomState(0))
        step = gm.score(x0) - w0.score(x0)
        assert bool(m.fit_report_.converged[0, k - 1]) == (abs(step) < 1e-4)


def _sklearn_step(kept, k: int, x0: np.ndarray, reg: float):
    """sklearn's GaussianMixture after one EM step (an E-step and an M-step) from the kept
    candidate with k components, on x0."""
    import warnings

    from sklearn.exceptions import ConvergenceWarning
    from sklearn.mixture import GaussianMixture

    w, mu, cov = kept[0][k - 1, :k], kept[1][k - 1, :k], kept[2][k - 1, :k]
    gm = GaussianMixture(
        k, covariance_type="full", tol=1e-4, max_iter=gmm_mod._WARM_ITER - 1, reg_covar=reg,
        weights_init=w.numpy(), means_init=mu.numpy(),
        precisions_init=torch.linalg.inv(cov).numpy(),
    )  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        return gm.fit(x0)


def _warm_e_step_sizes(monkeypatch) -> list[int]:
    """Points seen by each warm E-step: a refit on kept statistics starts with the new points
    alone, one without them with all the action's points."""
    sizes: list[int] = []
    real = _em.warm_e_step

    def spy(zt, *args):
        sizes.append(int(zt.shape[1]))
        return real(zt, *args)

    monkeypatch.setattr(_em, "warm_e_step", spy)
    return sizes


def _refit_and_check_against_sklearn(m: GaussianMixtureSet, x, y, a: int = 0) -> None:
    kept = (m.cand_weights_[a].clone(), m.cand_means_[a].clone(), m.cand_covariances_[a].clone())
    m.refit(x, y)
    assert m.fit_report_.refit_kind[a] == "warm"
    xa = x[y == a]
    reg = float(m.var_floor_[0])
    for k in range(1, m.max_components + 1):
        gm = _sklearn_step(kept, k, xa, reg)
        assert float(m.fit_report_.log_likelihood[a, k - 1]) == pytest.approx(
            gm.score(xa) * len(xa), rel=1e-9
        )
        np.testing.assert_allclose(m.cand_means_[a, k - 1, :k].numpy(), gm.means_, rtol=1e-9)
        np.testing.assert_allclose(m.cand_weights_[a, k - 1, :k].numpy(), gm.weights_, rtol=1e-9)
        np.testing.assert_allclose(
            m.cand_covariances_[a, k - 1, :k].numpy(), gm.covariances_, rtol=1e-9
        )


def test_warm_refit_on_kept_statistics_equals_sklearn(monkeypatch):
    """Oracle: the refit after a warm one reuses the kept sufficient statistics (its first
    E-step sees only the new points) and still equals sklearn's EM step from the kept
    candidates over ALL the action's points."""
    x, y = _stream(244, d=2, seed=5)
    y[240:] = 0
    m = GaussianMixtureSet(3, 2, 4, var_floor=0.0, tol=1e-4, seed=1).fit(x[:240], y[:240])
    n0 = int((y[:240] == 0).sum())
    sizes = _warm_e_step_sizes(monkeypatch)
    m.refit(x[:241], y[:241])  # after a from-scratch fit: no statistics yet, full E-step
    assert sizes == [n0 + 1, n0 + 1]
    sizes.clear()
    _refit_and_check_against_sklearn(m, x[:242], y[:242])  # one new point
    assert sizes == [1, n0 + 2]
    sizes.clear()
    _refit_and_check_against_sklearn(m, x, y)  # two new points at once
    assert sizes == [2, n0 + 4]


@pytest.mark.parametrize("change", ["edit", "relabel", "remove"])
def test_changed_old_points_are_not_taken_from_the_kept_statistics(monkeypatch, change):
    """An edited, relabelled (into action 0) or removed old point of action 0, with a new
    point appended: the kept statistics no longer describe the old points, so the refit runs
    its first E-step over all of them, and still equals sklearn's step on the new data."""
    x, y = _stream(300, d=2, seed=5)
    m = GaussianMixtureSet(3, 2, 4, var_floor=0.0, tol=1e-4, seed=1).fit(x[:250], y[:250])
    m.refit(x[:251], y[:251])  # a warm refit: statistics kept from here on
    x, y = x[:252].copy(), y[:252].copy()
    y[251] = 0
    first0 = int(np.flatnonzero(y == 0)[3])
    if change == "edit":
        x[first0, 1] += 0.25
    elif change == "relabel":
        y[int(np.flatnonzero(y == 1)[0])] = 0
    else:
        keep = np.arange(len(y)) != first0
        x, y = x[keep], y[keep]
    sizes = _warm_e_step_sizes(monkeypatch)
    _refit_and_check_against_sklearn(m, x, y)
    n0 = int((y == 0).sum())
    assert sizes[:2] == [n0, n0]  # action 0 (a relabelled point also refits action 1, after)


def test_full_refit_rule_fits_from_scratch_after_growth():
    x, y = _stream(300, seed=2)
    m = GaussianMixtureSet(3, 3, 3, refit_growth=0.5).fit(x[:150], y[:150])
    full0 = m.full_fit_points_.clone()
    kinds = []
    for n in range(151, 301):
        m.refit(x[:n], y[:n])
        a = int(y[n - 1])
        kind = m.fit_report_.refit_kind
        assert [kind[b] for b in range(3) if b != a] == ["kept", "kept"]
        kinds.append((a, kind[a], int(m.n_points_[a]), int(full0[a])))
        if kind[a] == "scratch":
            full0[a] = m.n_points_[a]
    for a, kind, n_a, n_full in kinds:
        assert kind == ("scratch" if n_a >= 1.5 * n_full else "warm"), (a, n_a, n_full)
    assert any(k == "scratch" for _, k, _, _ in kinds)
    assert torch.equal(m.full_fit_points_, full0)


def test_scratch_refit_matches_fit_of_that_action():
    x, y = _stream(200, seed=4)
    m = GaussianMixtureSet(3, 3, 5, refit_growth=0.1, seed=2).fit(x[:90], y[:90])
    while True:  # add points until an action is refitted from scratch
        n = int(m.n_points_.sum()) + 1
        m.refit(x[:n], y[:n])
        if "scratch" in m.fit_report_.refit_kind:
            break
    a = m.fit_report_.refit_kind.index("scratch")
    ref = GaussianMixtureSet(3, 3, 5, refit_growth=0.1, seed=2).fit(x[:n], y[:n])
    torch.testing.assert_close(
        m.fit_report_.log_likelihood[a], ref.fit_report_.log_likelihood[a], rtol=1e-9, atol=0
    )
    assert int(m.n_components_[a]) == int(ref.n_components_[a])


def test_same_seed_and_sequence_give_bit_identical_models():
    x, y = _stream(200)
    counts = [*range(1, 30), *range(30, 201, 10)]
    a = _replay(GaussianMixtureSet(3, 3, 6, seed=9), x, y, counts)
    b = _replay(GaussianMixtureSet(3, 3, 6, seed=9), x, y, counts)
    _assert_same_state(a, b)


def test_resume_after_incremental_refits_rebuilds_the_same_model():
    x, y = _stream(200)
    counts = [*range(1, 30), *range(30, 201, 10)]
    live = _replay(GaussianMixtureSet(3, 3, 6, seed=9), x, y, counts[:35])
    buf = io.BytesIO()
    torch.save({"state_dict": live.state_dict()}, buf)  # as the session's checkpoints
    buf.seek(0)
    resumed = GaussianMixtureSet(3, 3, 6, seed=9)
    resumed.load_state_dict(torch.load(buf, weights_only=True)["state_dict"])
    _replay(live, x, y, counts[35:])
    _replay(resumed, x, y, counts[35:])
    assert "warm" in live.fit_report_.refit_kind or "kept" in live.fit_report_.refit_kind
    _assert_same_state(live, resumed)
    obs = x[:50] + 0.05
    assert torch.equal(live.classify(obs).posterior, resumed.classify(obs).posterior)


def test_incremental_model_is_as_good_as_a_full_refit():
    x, y = _stream(600, seed=6)
    # a refit every 8 demonstrations from 200 on: 50 warm starts in a row for some actions
    inc = _replay(GaussianMixtureSet(3, 3, 6, refit_growth=1.0), x, y, range(200, 601, 8))
    assert "warm" in inc.fit_report_.refit_kind
    full = GaussianMixtureSet(3, 3, 6, refit_growth=1.0).fit(x, y)
    mix_i = (inc.log_prob(x) - inc.log_prior_).numpy()
    mix_f = (full.log_prob(x) - full.log_prior_).numpy()
    for a in range(3):
        ll_i, ll_f = mix_i[y == a, a].mean(), mix_f[y == a, a].mean()
        assert ll_i >= ll_f - 0.01 * abs(ll_f), (a, ll_i, ll_f)
    held = x + np.random.default_rng(1).normal(scale=0.2, size=x.shape)
    agree = (inc.classify(held).action == full.classify(held).action).double().mean()
    assert float(agree) >= 0.99


def test_same_counts_but_other_data_is_refitted():
    x, y = _stream(200)
    m = GaussianMixtureSet(3, 3, 5).fit(x, y)
    x2 = x.copy()
    x2[y == 2] += 0.5
    m.refit(x2, y)
    assert m.fit_report_.refit_kind == ("kept", "kept", "warm")


def test_points_at_the_origin_moved_apart_with_the_same_count_and_mean_are_refitted():
    """Their fingerprint is zero, like a state saved before fingerprints were kept: they must
    still be compared, else the mixture of the three points at the origin stays."""
    x1 = np.array([[0.0, 0], [0, 0], [0, 0], [5, 5], [6, 5], [5, 6]])
    x2 = np.array([[3.0, 0], [-3, 0], [0, 0], [5, 5], [6, 5], [5, 6]])
    y = np.array([0, 0, 0, 1, 1, 1])
    m = GaussianMixtureSet(2, 2, max_components=2).fit(x1, y)
    m.refit(x2, y)
    assert m.fit_report_.refit_kind[0] != "kept"
    fresh = GaussianMixtureSet(2, 2, max_components=2).fit(x2, y)
    assert float(m.covariances_[0, 0, 0, 0]) == pytest.approx(6.0, rel=0.01)
    probe = np.array([[3.0, 0.0]])
    assert torch.allclose(m.classify(probe).distance, fresh.classify(probe).distance)


def test_an_action_that_loses_its_data_becomes_empty():
    x, y = _stream(200)
    m = GaussianMixtureSet(3, 3, 5).fit(x, y)
    keep = y != 1
    m.refit(x[keep], y[keep])
    assert m.fit_report_.refit_kind[1] == "empty"
    assert int(m.n_components_[1]) == 0 and not bool(m.component_mask_[1].any())
    assert torch.isinf(m.criterion_[1]).all()
    assert torch.isneginf(m.log_prob(x[:5])[:, 1]).all()
    assert int(m.full_fit_points_[1]) == 0


def test_state_dict_without_the_refit_buffers_loads_and_refits_from_scratch():
    x, y = _stream(200)
    m = GaussianMixtureSet(3, 3, 5).fit(x, y)
    old = {k: v for k, v in m.state_dict().items() if k not in gmm_mod._REFIT_BUFFERS}
    fresh = GaussianMixtureSet(3, 3, 5)
    fresh.load_state_dict(old)  # strict: the missing buffers get their empty defaults
    assert torch.equal(fresh.classify(x[:20]).posterior, m.classify(x[:20]).posterior)
    fresh.refit(x, y)
    assert fresh.fit_report_.refit_kind == ("scratch",) * 3
    _assert_same_state(fresh, m)


def test_refit_rejects_bad_input_and_keeps_its_state():
    x, y = _stream(100)
    m = GaussianMixtureSet(3, 3, 4).fit(x, y)
    before = {k: v.clone() for k, v in m.state_dict().items()}
    with pytest.raises(ValueError, match=r"expected shape \[N, 3\]"):
        m.refit(x[:, :2], y)
    with pytest.raises(ValueError, match=r"labels in \[0, 3\)"):
        m.refit(x, y + 1)
    for key, val in m.state_dict().items():
        assert torch.equal(val, before[key]), key
    with pytest.raises(ValueError, match="refit_growth"):
        GaussianMixtureSet(3, 3, refit_growth=0.0)


# ---------------------------------------------------------------------- thread policy
@pytest.fixture
def two_threads():
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(before)


def _threads_seen_by_em(monkeypatch) -> list[int]:
    """Thread counts seen by each from-scratch EM (run_em) and each warm refit of an action
    (its M-step)."""
    seen: list[int] = []
    real, real_warm = _em.run_em, _em.warm_m_step

    def spy(*args, **kwargs):
        seen.append(torch.get_num_threads())
        return real(*args, **kwargs)

    def spy_warm(*args, **kwargs):
        seen.append(torch.get_num_threads())
        return real_warm(*args, **kwargs)

    monkeypatch.setattr(_em, "run_em", spy)
    monkeypatch.setattr(_em, "warm_m_step", spy_warm)
    return seen


def test_small_fits_run_on_one_thread_and_restore_the_callers_count(monkeypatch, two_threads):
    seen = _threads_seen_by_em(monkeypatch)
    x, y = _stream(100)
    m = GaussianMixtureSet(3, 3, 4)
    m.fit(x, y)
    m.refit(np.concatenate([x, x[:1]]), np.concatenate([y, y[:1]]))
    assert seen == [1, 1]
    assert torch.get_num_threads() == 2


def test_large_fits_use_the_callers_threads(monkeypatch, two_threads):
    seen = _threads_seen_by_em(monkeypatch)
    monkeypatch.setattr(gmm_mod, "SINGLE_THREAD_WORK", 1.0)
    monkeypatch.setattr(gmm_mod, "_spare_core", lambda: True)
    x, y = _stream(100)
    GaussianMixtureSet(3, 3, 4).fit(x, y)
    assert seen == [2]
    assert torch.get_num_threads() == 2


def test_a_busy_machine_gets_one_thread_whatever_the_size(monkeypatch, two_threads):
    """With every usable core taken by another busy process right now, even a large fit runs
    on one thread; the machine's past (a 1-minute load average) plays no part on Linux."""
    seen = _threads_seen_by_em(monkeypatch)
    monkeypatch.setattr(gmm_mod, "SINGLE_THREAD_WORK", 1.0)
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    if not os.path.exists("/proc/loadavg") or cpus > 8:  # the load-average rule instead
        monkeypatch.setattr(gmm_mod, "_running_now", lambda: None)
        monkeypatch.setattr(gmm_mod.os, "getloadavg", lambda: (64.0, 64.0, 64.0))
        busy = []
    else:
        spin = "import time\nt = time.monotonic()\nwhile time.monotonic() - t < 30: pass"
        busy = [subprocess.Popen([sys.executable, "-c", spin]) for _ in range(cpus)]
    try:
        deadline = time.monotonic() + 10  # until the busy processes run
        while busy and gmm_mod._spare_core() and time.monotonic() < deadline:
            time.sleep(0.05)
        if busy and gmm_mod._spare_core():
            pytest.skip("this machine's /proc does not report the busy processes as running")
        x, y = _stream(100)
        GaussianMixtureSet(3, 3, 4).fit(x, y)
    finally:
        for p in busy:
            p.kill()
            p.wait()
    assert seen == [1]
    assert torch.get_num_threads() == 2


def test_thread_count_is_restored_when_a_fit_fails(monkeypatch, two_threads):
    def boom(*args, **kwargs):
        assert torch.get_num_threads() == 1
        raise FloatingPointError("boom")

    monkeypatch.setattr(_em, "run_em", boom)
    x, y = _stream(100)
    with pytest.raises(FloatingPointError, match="boom"):
        GaussianMixtureSet(3, 3, 4).fit(x, y)
    assert torch.get_num_threads() == 2


# ---------------------------------------------------------------------- the teaching loop
def _session(run_dir, **cfg):
    from _toy_envs import oracle, rare_regions_world

    from torchcbl import ConfidentTeacher, TeachingConfig

    env = rare_regions_world()
    config = TeachingConfig(noninteractive=False, refit="incremental", **cfg)
    return ConfidentTeacher(env, oracle(env), config=config, run_dir=run_dir, progress=False)


def test_incremental_session_resumes_to_the_live_model_even_without_its_checkpoint(tmp_path):
    import copy

    from _toy_envs import oracle, rare_regions_world

    from torchcbl import ConfidentTeacher
    from torchcbl.session import CHECKPOINT_DIR, latest_checkpoint, load_model

    run = tmp_path / "run"
    ct = _session(run, max_new=2)
    ct.run(max_demonstrations=30)
    assert "warm" in ct.model.fit_report_.refit_kind  # the loop refits incrementally
    live = copy.deepcopy(ct.model)
    ct.close()
    assert int(live.n_points_.sum()) == 30
    # as if killed between logging the demonstrations and saving the model: the last two
    # checkpoints are missing, resume replays the refits from the one before
    for _ in range(2):
        latest_checkpoint(run)[1].unlink()
    assert latest_checkpoint(run)[0] == 26 and (run / CHECKPOINT_DIR).is_dir()
    _assert_same_state(load_model(run), live)
    env = rare_regions_world()
    back = ConfidentTeacher.resume(run, env, oracle(env), progress=False)
    _assert_same_state(back.model, live)
    assert back.config.refit == "incremental"


def test_incremental_session_from_a_fitted_model_rebuilds_it_from_checkpoint_zero(tmp_path):
    """A session that starts from a fitted model refits it incrementally; with only its
    pre-fit checkpoint (model 0) left, load_model and resume replay refits from that state
    (not a fit from scratch), so they rebuild the live model bit for bit."""
    import copy

    from _toy_envs import oracle, rare_regions_world

    from torchcbl import ConfidentTeacher, TeachingConfig
    from torchcbl.session import CHECKPOINT_DIR, load_model

    env = rare_regions_world()
    x, y = env.sample(60, np.random.default_rng(0))
    n_actions, n_features = int(env.action_space.n), x.shape[1]
    fitted = GaussianMixtureSet(n_actions, n_features, 3, seed=0).fit(x, y)
    run = tmp_path / "run"
    config = TeachingConfig(max_new=6, refit="incremental", noninteractive=False)
    ct = ConfidentTeacher(
        env, oracle(env), model=fitted, config=config, run_dir=run, progress=False
    )
    ct.run(max_demonstrations=12)
    live = copy.deepcopy(ct.model)
    ct.close()
    kept = sorted((run / CHECKPOINT_DIR).glob("model-*.pt"))
    assert kept[0].name == "model-00000000.pt" and len(kept) > 1
    for path in kept[1:]:  # as if killed before any later checkpoint was saved
        path.unlink()
    _assert_same_state(load_model(run), live)
    env2 = rare_regions_world()
    back = ConfidentTeacher.resume(run, env2, oracle(env2), progress=False)
    _assert_same_state(back.model, live)


def test_teaching_config_refit_mode_is_checked():
    from torchcbl import TeachingConfig

    with pytest.raises(ValueError, match="'full' or 'incremental'"):
        TeachingConfig(refit="warm")


def test_warm_refit_is_one_em_step_and_its_report_does_not_cry_wolf():
    x, y = _stream(301, seed=3)
    y[-1] = 2
    m = GaussianMixtureSet(3, 3, 4, tol=1e-12).fit(x[:300], y[:300])
    m.refit(x, y)
    r = m.fit_report_
    assert r.refit_kind == ("kept", "kept", "warm")
    cand = r.candidate_mask[2]
    assert (r.n_iter[2][cand] == gmm_mod._WARM_ITER).all()
    # tol=1e-12: one EM step cannot pass the test, yet no "did not converge" note for warm rows
    assert not r.converged[2][cand].any()
    assert not any("did not converge" in note for note in r.notes)
    # ... while a from-scratch fit that runs out of iterations still says so
    short = GaussianMixtureSet(3, 3, 4, tol=1e-12, max_iter=2).fit(x, y)
    assert any("did not converge" in note for note in short.fit_report_.notes)


def test_fingerprint_depends_on_the_rows_not_on_their_memory():
    """The kept statistics are used only when the fingerprint of the action's first points
    is bit-identical to the stored one, so it must not depend on where the rows lie in memory
    (a live model and a resumed one hold the data at other addresses), and must see an edit
    or a reordering."""
    rng = np.random.default_rng(0)
    for n, d in ((1, 1), (9, 3), (17, 4), (1000, 5)):
        x = rng.normal(size=(n, d)) * 1e3
        ref = gmm_mod._fingerprint(x)
        for off in range(1, 8):  # every 8-byte misalignment within a cache line
            buf = np.empty(n * d + 16)
            view = buf[off : off + n * d].reshape(n, d)
            view[...] = x
            longer = np.concatenate([x, x[:3]])[:n]  # a prefix of a longer array
            assert np.array_equal(gmm_mod._fingerprint(view), ref)
            assert np.array_equal(gmm_mod._fingerprint(longer), ref)
        edited = x.copy()
        edited[n // 2, d - 1] *= 1.0 + 1e-9  # (a change of an ulp or so may round away)
        moved = x[::-1].copy()
        assert not np.array_equal(gmm_mod._fingerprint(edited), ref)
        if n > 1:
            assert not np.array_equal(gmm_mod._fingerprint(moved), ref)


def test_state_dict_without_kept_statistics_refits_with_a_full_first_e_step(monkeypatch):
    """A checkpoint written before the kept statistics existed: its warm refit runs the first
    E-step over all the action's points, and lands where the live model does (to rounding)."""
    x, y = _stream(202, seed=7)
    y[200:] = 1
    live = GaussianMixtureSet(3, 3, 4).fit(x[:200], y[:200])
    live.refit(x[:201], y[:201])
    new = ("cand_stats_", "cand_coef_", "stats_valid_", "ref_center_", "data_print_")
    old = {k: v for k, v in live.state_dict().items() if k not in new}
    resumed = GaussianMixtureSet(3, 3, 4)
    resumed.load_state_dict(old)
    assert not resumed.stats_valid_.any()
    sizes = _warm_e_step_sizes(monkeypatch)
    live.refit(x, y)
    resumed.refit(x, y)
    n1 = int((y == 1).sum())
    assert sizes == [1, n1, n1, n1]  # live: kept statistics; resumed: a full first E-step
    assert resumed.fit_report_.refit_kind == live.fit_report_.refit_kind == ("kept", "warm", "kept")
    for key in ("cand_weights_", "cand_means_", "cand_covariances_", "log_likelihood_"):
        a, b = getattr(live, key), getattr(resumed, key)
        fin = torch.isfinite(a)
        torch.testing.assert_close(b[fin], a[fin], rtol=1e-9, atol=1e-12)


def test_points_edited_with_the_same_count_and_mean_are_refitted():
    """A discrete feature's values edited so that an action's count and mean stay the same
    (0, 0, 2, 2 -> 1, 1, 1, 1): the fingerprint of all its points catches it; the refit is
    not the stale mixture but what a fit of the new points gives."""
    x = np.array([[0.0], [0.0], [2.0], [2.0], [5.0], [5.5], [6.0], [6.5]])
    y = np.array([0, 0, 0, 0, 1, 1, 1, 1])
    m = GaussianMixtureSet(2, 1, 2, seed=0).fit(x, y)
    assert int(m.n_components_[0]) == 2
    x2 = x.copy()
    x2[:4] = 1.0
    m.refit(x2, y)
    assert m.fit_report_.refit_kind[0] != "kept" and m.fit_report_.refit_kind[1] == "kept"
    fresh = GaussianMixtureSet(2, 1, 2, seed=0).fit(x2, y)
    probe = np.array([[1.0]])
    assert int(m.n_components_[0]) == int(fresh.n_components_[0]) == 1
    assert float(m.classify(probe).distance[0]) == pytest.approx(0.0, abs=1e-6)


def test_a_model_converted_to_float32_classifies_but_refuses_to_refit():
    x, y = _stream(120, seed=3)
    m = GaussianMixtureSet(3, 3, 3, seed=0).fit(x, y)
    m.to(torch.float32)
    assert m.classify(x[:5]).action.shape == (5,)
    with pytest.raises(TypeError, match=r"call \.to\(torch\.float64\) first"):
        m.refit(x, y)
    m.to(torch.float64)  # (the float32 round trip lost bits: the next refit steps again)
    m.refit(x, y)
    m.refit(x, y)  # and then, on the same data, keeps every action
    assert m.fit_report_.refit_kind == ("kept", "kept", "kept")


def test_negative_stride_views_are_read_like_their_copies():
    x, y = _stream(300, seed=4)
    rev_x, rev_y = x[::-1], y[::-1]
    a = GaussianMixtureSet(3, 3, 3, seed=0).fit(rev_x, rev_y)
    b = GaussianMixtureSet(3, 3, 3, seed=0).fit(rev_x.copy(), rev_y.copy())
    for name, t in a.state_dict().items():
        assert torch.equal(t, b.state_dict()[name]), name
    assert torch.equal(a.classify(x[:, ::-1][:, ::-1]).action, a.classify(x.copy()).action)
