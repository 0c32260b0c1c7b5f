"""Time GaussianMixtureSet's full candidate sweep against scikit-learn's sequential sweep.

Cases (the acceptance of issue 2):
  a: 3 actions x 330 points x 4-D, k <= 15      target ours/sklearn <= 1/20
  b: 3 actions x 3000 points x 4-D, k <= 15     target <= 1/10
  c: 10 actions x 1000 points x 8-D, k <= 10    target <= 1/10
  refit: a full refit (``fit``) of 999 points (3 actions x 333, 4-D), k <= 15, the library's
         defaults: target < 0.1 s (median)
Both sides do a whole model selection: fit every candidate and measure its log-likelihood on
the action's points for the criterion (ours in the fit's final E-step, sklearn by ``score``,
about 2% of its sweep; the ``threadpool_limits`` scope is entered once per sweep, ~0.1%).
sklearn: GaussianMixture per action per k, full covariances, same tol / max_iter / reg_covar
(= our variance floor: features are standardised so the floor is one number), n_init=1,
k-means initialisation, pinned to one thread with threadpoolctl (its fastest setting here:
it is 30-50% slower on two). Ours runs as a user gets it, on torch's default thread count
(``--threads`` to change); the "1 thr" columns time ours on one thread as well, for a
per-core comparison. Ours and sklearn are timed in alternation (best of each), so that a
slow spell of the machine hits both. Each timed fit of ours follows an untimed one with the
same thread count: the first fit after sklearn's 1.5-4 s sweep (or a thread switch) pays
5-10% more for page faults and cold caches, which sklearn's sweep of many fits amortises.

Log-likelihood agreement, per action at our chosen k. The acceptance check is "same-init
|dLL|": sklearn started from OUR initial parameters (weights, means, precisions of our k-means
start, exactly as ``fit`` computes them) against our fit, largest relative difference. The two
k-means initialisations differ (ours: one-draw k-means++ seeding + <= 10 Lloyd steps, a pure
function of the seed; sklearn: greedy k-means++ + Lloyd to convergence), so from their own
starts either side can land in the better local optimum: "own-init dLL" shows the largest
shortfall of ours (+) or excess (-) against sklearn's own kmeans start, for information only
(sklearn's own result at the same k moves by several % between its random_states).

Usage: python bench/bench_gmm.py [--repeats 5] [--sk-repeats 3] [--threads N] [--cases a,b,c]
The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import json
import os
import statistics
import time

import numpy as np
import torch
from _parser import Parser
from threadpoolctl import threadpool_limits

from torchcbl import _em
from torchcbl.gmm import GaussianMixtureSet

CASES = {
    "a": (3, 330, 4, 15, 1 / 20),
    "b": (3, 3000, 4, 15, 1 / 10),
    "c": (10, 1000, 8, 10, 1 / 10),
}
TOL, MAX_ITER = 1e-4, 200


def make_data(n_actions: int, n_per: int, d: int, seed: int = 0):
    """Each action: a mixture of 3-5 Gaussians; features standardised over all rows."""
    rng = np.random.default_rng(seed)
    xs = []
    for _ in range(n_actions):
        m = int(rng.integers(3, 6))
        centres = rng.normal(scale=3.0, size=(m, d))
        scales = rng.uniform(0.3, 1.0, size=(m, d))
        comp = rng.integers(0, m, size=n_per)
        xs.append(centres[comp] + rng.normal(size=(n_per, d)) * scales[comp])
    x = np.concatenate(xs)
    x = (x - x.mean(0)) / x.std(0)
    return x, np.repeat(np.arange(n_actions), n_per)


def make_model(a, d, k, *, library_defaults=False):
    if library_defaults:  # what a user of the teaching loop gets
        return GaussianMixtureSet(a, d, k, seed=0)
    return GaussianMixtureSet(a, d, k, tol=TOL, max_iter=MAX_ITER, seed=0)


def time_fit(model, x, y, threads):
    """Seconds of one fit on ``threads`` torch threads (restored afterwards)."""
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        t0 = time.perf_counter()
        model.fit(x, y)
        return time.perf_counter() - t0
    finally:
        torch.set_num_threads(before)


def sweep_sklearn(x, y, a, k, reg):
    """sklearn's sequential sweep on one thread -> (seconds, total log-likelihood per (a, k))."""
    from sklearn.mixture import GaussianMixture

    ll = {}
    t0 = time.perf_counter()
    with threadpool_limits(1):
        for act in range(a):
            xa = x[y == act]
            for kk in range(1, min(k, len(xa)) + 1):
                gm = GaussianMixture(
                    kk,
                    covariance_type="full",
                    tol=TOL,
                    max_iter=MAX_ITER,
                    n_init=1,
                    init_params="kmeans",
                    reg_covar=reg,
                    random_state=0,
                ).fit(xa)
                ll[act, kk] = gm.score(xa) * len(xa)
    return time.perf_counter() - t0, ll


def sklearn_from_our_init(model, x, y, act, k, reg):
    """Total log-likelihood of sklearn's EM started from our initial parameters for (act, k)."""
    from sklearn.mixture import GaussianMixture

    xa = x[y == act]
    centre = xa.mean(0)
    xb = torch.from_numpy(xa - centre)[None]
    pmask = torch.ones(1, len(xa), dtype=torch.float64)
    cmask = torch.ones(1, 1, k, dtype=torch.float64)
    u = _em.candidate_uniforms(model.seed, np.array([[act]]), np.array([[k]]), k)
    resp = _em.kmeans_init(xb, pmask, cmask, torch.from_numpy(u))
    p = _em.m_step(_em.quadratic_features(xb), resp, cmask, model.var_floor_)
    with threadpool_limits(1):
        gm = GaussianMixture(
            k,
            covariance_type="full",
            tol=TOL,
            max_iter=MAX_ITER,
            reg_covar=reg,
            weights_init=p.weights[0, 0].numpy(),
            means_init=p.means[0, 0].numpy() + centre,
            precisions_init=torch.linalg.inv(p.covariances[0, 0]).numpy(),
        ).fit(xa)
    return gm.score(xa) * len(xa)


def main() -> None:
    ap = Parser(__doc__)
    ap.add_argument(
        "--repeats",
        type=int,
        default=5,
        help="timed sweeps of ours per case, and full refits (default %(default)s)",
    )
    ap.add_argument(
        "--sk-repeats",
        type=int,
        default=3,
        help="timed sweeps of scikit-learn's per case (default %(default)s)",
    )
    ap.add_argument(
        "--threads",
        type=int,
        default=torch.get_num_threads(),
        help="torch threads for ours (default: torch's default, here %(default)s)",
    )
    ap.add_argument(
        "--cases", default="a,b,c", help="comma-separated, of a, b, c (default %(default)s)"
    )
    args = ap.parse_args()
    for flag, v in (("--repeats", args.repeats), ("--sk-repeats", args.sk_repeats)):
        if v < 1:
            ap.error(f"{flag}: expected an int >= 1, got {v}")
    if args.threads < 1:
        ap.error(f"--threads: expected an int >= 1, got {args.threads}")
    unknown = sorted(set(args.cases.split(",")) - set(CASES))
    if unknown:
        ap.error(f"--cases: unknown {unknown}; expected some of {sorted(CASES)}")
    threads = args.threads
    results: dict[str, dict] = {"torch_threads": threads, "sklearn_threads": 1}
    print(
        f"ours: torch threads={threads} (torch's default here: {torch.get_num_threads()}); "
        f"sklearn threads=1; cpus={os.cpu_count()}"
    )
    hdr = (
        f"{'case':<6}{'shape':>18}{'ours best':>11}{'ours med':>10}{'sklearn':>9}"
        f"{'ratio':>8}{'target':>8}{'1 thr':>9}{'ratio':>8}{'same-init |dLL|':>17}"
        f"{'own-init dLL':>14}  ok"
    )
    print(hdr)
    print("-" * len(hdr))
    for name in args.cases.split(","):
        a, n, d, k, target = CASES[name]
        x, y = make_data(a, n, d)
        model = make_model(a, d, k)
        time_fit(model, x, y, threads)  # warm-up
        reg = float(model.var_floor_[0])
        ours, ours1, sk = [], [], []
        ll_sk: dict = {}
        for rep in range(max(args.repeats, args.sk_repeats)):
            if rep < args.sk_repeats:
                t_sk, ll_sk = sweep_sklearn(x, y, a, k, reg)
                sk.append(t_sk)
            if rep < args.repeats:  # each timed fit follows an untimed one (see the docstring)
                for times, n_threads in ((ours, threads), (ours1, 1)):
                    time_fit(model, x, y, n_threads)
                    times.append(time_fit(model, x, y, n_threads))
        rel, rel_same = [], []
        for act in range(a):
            kk = int(model.n_components_[act])
            mine = float(model.fit_report_.log_likelihood[act, kk - 1])
            ref = ll_sk[act, kk]
            rel.append((ref - mine) / abs(ref))
            same = sklearn_from_our_init(model, x, y, act, kk, reg)
            rel_same.append((same - mine) / abs(same))
        best, med, skb, best1 = min(ours), statistics.median(ours), min(sk), min(ours1)
        ratio, ratio1 = best / skb, best1 / skb
        worst = max(abs(r) for r in rel_same)
        lower = max(rel, key=abs)
        ok = ratio <= target and worst <= 0.01
        print(
            f"{name:<6}{f'{a}x{n}x{d} k<={k}':>18}{best * 1e3:>9.1f}ms{med * 1e3:>8.1f}ms"
            f"{skb:>8.2f}s{f'1/{1 / ratio:.1f}':>8}{f'1/{1 / target:.0f}':>8}"
            f"{best1 * 1e3:>7.1f}ms{f'1/{1 / ratio1:.1f}':>8}{worst:>16.2%}{lower:>+13.2%}"
            f"  {'yes' if ok else 'NO'}"
        )
        results[name] = {
            "ours_best_s": best,
            "ours_median_s": med,
            "ours_one_thread_best_s": best1,
            "sklearn_s": skb,
            "ratio": ratio,
            "speedup": 1 / ratio,
            "ratio_one_thread": ratio1,
            "target_ratio": target,
            "chosen_k": model.n_components_.tolist(),
            "rel_loglik_diff_same_init": rel_same,
            "rel_loglik_diff_own_init": rel,
            "ok": ok,
        }
    x, y = make_data(3, 333, 4, seed=1)
    model = make_model(3, 4, 15, library_defaults=True)
    time_fit(model, x, y, threads)
    rt, rt1 = [], []
    for _ in range(args.repeats):
        rt.append(time_fit(model, x, y, threads))
        rt1.append(time_fit(model, x, y, 1))
    print(
        f"full refit (fit) of 999 points, 3x333x4 k<=15 (library defaults, tol=1e-3): "
        f"best {min(rt) * 1e3:.1f} ms, "
        f"median {statistics.median(rt) * 1e3:.1f} ms; one thread: best {min(rt1) * 1e3:.1f} "
        f"ms, median {statistics.median(rt1) * 1e3:.1f} ms (target < 100 ms)"
    )
    results["refit_1000"] = {  # the key kept for continuity: 3 x 333 = 999 points
        "n_points": 999,
        "best_s": min(rt),
        "median_s": statistics.median(rt),
        "one_thread_best_s": min(rt1),
        "one_thread_median_s": statistics.median(rt1),
        "target_s": 0.1,
        "ok": statistics.median(rt) < 0.1,
    }
    one = x[:1].copy()
    per_call = []
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(2000):
            model.classify(one)
        per_call.append((time.perf_counter() - t0) / 2000)
    print(
        f"classify one observation (3 actions, 4-D, k<=15): best {min(per_call) * 1e6:.1f} us, "
        f"median {statistics.median(per_call) * 1e6:.1f} us"
    )
    results["classify_one_us"] = {
        "best": min(per_call) * 1e6,
        "median": statistics.median(per_call) * 1e6,
    }
    print(json.dumps(results))


if __name__ == "__main__":
    main()
