"""Incremental refits against full refits, and the thread policy (issue 17).

Sections (``--sections``, default all):
  long:    a long teaching session's refits: 10,000 demonstrations, 4-D, 3 actions, k <= 10,
           a refit after every demonstration (max_new = 1). ``GaussianMixtureSet.refit``
           (incremental) runs at every step; the full refit (``fit`` on all data, today's loop)
           is timed at every ``--full-every``-th step, right after the incremental refit of the
           same step (alternation: a slow spell of the machine hits both), and its total is
           the sum of those times times ``--full-every``, the last one standing also for the
           steps after it when ``--n`` is no multiple (1 = every step, exact but ~10 min).
           Targets: total incremental <= 1/10 of total full; the final incremental model's
           mean log-likelihood per point, per action, within 1 % of (or better than) a full
           fit's on the same data; >= 99 % agreement of the picked actions on 5,000 held-out
           observations. Two streams: "iid" (shuffled) and "drift" (the observations sweep
           along feature 0, so new regions, hence new components, appear late).
  single:  one refit after one new demonstration at 1,000 demonstrations (3 actions x 4-D,
           k <= 15, library defaults), median of 200 (target <= 5 ms); a full fit beside it.
  snippet: the README's corridor snippet (teach to 10 autonomous episodes) in a fresh process
           on torch's default threads, alone and with one competing busy process of our own
           (target: busy <= 1.3x alone), with the library's thread policy and, for reference,
           with the policy switched off (the library's thread scope replaced by a no-op:
           torch's threads everywhere, as before issue 17).
  threads: full fits of growing size on 1 thread and on torch's default count, alone and
           beside a busy process, in alternation: where the threshold of the thread policy
           (``torchcbl.gmm.SINGLE_THREAD_WORK``) comes from.

Usage: python bench/bench_refit.py [--sections long,single,snippet,threads] [--full-every 50]
The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import contextlib
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator

import numpy as np
import torch
from _parser import Parser

from torchcbl import gmm as gmm_mod
from torchcbl.gmm import GaussianMixtureSet

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def stream(n: int, d: int, a: int, kind: str, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n demonstrations (observation, action) plus the order they arrive in.

    Each action's observations: a mixture of 6 Gaussians in d dimensions. "iid": shuffled;
    "drift": sorted by feature 0 plus noise (the session explores new regions over time).
    """
    if kind not in ("iid", "drift"):
        raise ValueError(f"stream kind: expected 'iid' or 'drift', got {kind!r}")
    rng = np.random.default_rng(seed)
    xs, ys = [], []
    for act in range(a):
        centres = rng.normal(scale=3.0, size=(6, d))
        scales = rng.uniform(0.3, 1.0, size=(6, d))
        comp = rng.integers(0, 6, size=n)
        xs.append(centres[comp] + rng.normal(size=(n, d)) * scales[comp])
        ys.append(np.full(n, act))
    x, y = np.concatenate(xs), np.concatenate(ys)
    x = (x - x.mean(0)) / x.std(0)
    pick = rng.permutation(len(y))[:n]
    x, y = x[pick], y[pick]
    if kind == "drift":
        order = np.argsort(x[:, 0] + rng.normal(scale=0.5, size=n), kind="stable")
        x, y = x[order], y[order]
    return x, y


def held_out(x: np.ndarray, n: int, seed: int = 1) -> np.ndarray:
    """Observations near the training ones (a point plus noise), for the agreement check."""
    rng = np.random.default_rng(seed)
    return x[rng.integers(0, len(x), n)] + rng.normal(scale=0.1, size=(n, x.shape[1]))


def mean_ll_per_action(model: GaussianMixtureSet, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Mean log-likelihood per point of each action's mixture on that action's points [A]."""
    mix = (model.log_prob(x) - model.log_prior_).numpy()
    # an action without points (a tiny --n) has no mean: NaN here, null in the JSON
    return np.array(
        [mix[y == a, a].mean() if (y == a).any() else np.nan for a in range(model.n_actions)]
    )


def long_session(kind: str, n: int, full_every: int) -> dict:
    d, a, k = 4, 3, 10
    x, y = stream(n, d, a, kind)
    inc = GaussianMixtureSet(a, d, k, seed=0)
    full = GaussianMixtureSet(a, d, k, seed=0)
    t_inc = t_full_sampled = c_inc = c_full_sampled = t_scratch = c_scratch = 0.0
    t_last = c_last = 0.0  # the last timed full refit: it stands for the steps after it too
    n_sampled = 0
    kinds = {"scratch": 0, "warm": 0}
    t_start = time.perf_counter()
    for i in range(1, n + 1):
        t0, c0 = time.perf_counter(), time.process_time()
        inc.refit(x[:i], y[:i])
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        t_inc += dt
        c_inc += dc
        if "scratch" in inc.fit_report_.refit_kind:  # the refits with a from-scratch fit
            t_scratch += dt
            c_scratch += dc
        for kk in inc.fit_report_.refit_kind:
            if kk in kinds:
                kinds[kk] += 1
        if i % full_every == 0:
            t0, c0 = time.perf_counter(), time.process_time()
            full.fit(x[:i], y[:i])
            t_last, c_last = time.perf_counter() - t0, time.process_time() - c0
            t_full_sampled += t_last
            c_full_sampled += c_last
            n_sampled += 1
        if i % 2000 == 0:
            print(
                f"  [{kind}] {i} demonstrations, {time.perf_counter() - t_start:.0f} s", flush=True
            )
    if n % full_every:
        full.fit(x, y)
    # each timed full refit stands for the --full-every steps up to it, the last one also
    # for the steps after it (n not a multiple of --full-every)
    tail = n % full_every
    t_full = t_full_sampled * full_every + t_last * tail
    c_full = c_full_sampled * full_every + c_last * tail
    ll_inc = mean_ll_per_action(inc, x, y)
    ll_full = mean_ll_per_action(full, x, y)
    xh = held_out(x, 5000)
    agree = float((inc.classify(xh).action == full.classify(xh).action).double().mean())
    # relative shortfall of incremental against full (negative: incremental is better)
    rel = (ll_full - ll_inc) / np.abs(ll_full)
    return {
        "stream": kind,
        "n": n,
        "incremental_total_s": t_inc,
        "full_total_s_estimated": t_full,
        "full_timed_refits": n_sampled,
        "ratio": t_inc / t_full,
        "incremental_cpu_s": c_inc,
        "full_cpu_s_estimated": c_full,
        "ratio_cpu": c_inc / c_full,
        "from_scratch_action_fits": kinds["scratch"],
        "scratch_refits_share_of_incremental": t_scratch / t_inc,
        "scratch_refits_share_of_incremental_cpu": c_scratch / c_inc,
        "warm_action_fits": kinds["warm"],
        "mean_ll_incremental": [v if np.isfinite(v) else None for v in ll_inc.tolist()],
        "mean_ll_full": [v if np.isfinite(v) else None for v in ll_full.tolist()],
        "ll_shortfall_rel_max": float(np.nanmax(rel)) if np.isfinite(rel).any() else None,
        "k_incremental": [int(v) for v in inc.n_components_],
        "k_full": [int(v) for v in full.n_components_],
        "agreement_heldout": agree,
    }


def single_refit(repeats: int = 200) -> dict:
    sys.path.insert(0, os.path.join(ROOT, "bench"))
    from bench_gmm import make_data

    x, y = make_data(3, 400, 4, seed=0)  # 1,200 demonstrations
    perm = np.random.default_rng(0).permutation(len(y))
    x, y = x[perm], y[perm]
    m = GaussianMixtureSet(3, 4, 15, seed=0).fit(x[:1000], y[:1000])
    ts, tf, cs, cf = [], [], [], []
    for i in range(repeats):
        n = 1001 + i  # one new demonstration each time, from 1,000 to 1,200
        t0, c0 = time.perf_counter(), time.process_time()
        m.refit(x[:n], y[:n])
        ts.append(time.perf_counter() - t0)
        cs.append(time.process_time() - c0)
        if i % 20 == 0:
            f = GaussianMixtureSet(3, 4, 15, seed=0)
            t0, c0 = time.perf_counter(), time.process_time()
            f.fit(x[:n], y[:n])
            tf.append(time.perf_counter() - t0)
            cf.append(time.process_time() - c0)
    return {
        "refit_median_ms": 1e3 * statistics.median(ts),
        "refit_cpu_median_ms": 1e3 * statistics.median(cs),
        "full_fit_cpu_median_ms": 1e3 * statistics.median(cf),
        "refit_p10_ms": 1e3 * float(np.percentile(ts, 10)),
        "refit_p90_ms": 1e3 * float(np.percentile(ts, 90)),
        "full_fit_median_ms": 1e3 * statistics.median(tf),
    }


SNIPPET = r"""
import os, sys, time, tempfile
import torchcbl.gmm as g
if os.environ.get("POLICY_OFF") == "1":  # torch's threads everywhere, as before issue 17
    import contextlib
    g._threads = lambda n: contextlib.nullcontext()
import gymnasium as gym
import corridor
from corridor.expert import CorridorExpert
from torchcbl import ConfidentTeacher, TeachingConfig
t0 = time.perf_counter()
env = gym.make("torchcbl/Corridor-v0")
teacher = CorridorExpert(env.unwrapped.world.map)
config = TeachingConfig(autonomous_episodes_to_stop=10)
with tempfile.TemporaryDirectory() as d:
    ct = ConfidentTeacher(env, teacher, config=config, run_dir=d + "/s")
    ct.run()
print(time.perf_counter() - t0, ct.n_demonstrations)
"""


@contextlib.contextmanager
def busy_process() -> Iterator[None]:
    """One competing CPU-bound process of our own, ended (by its pid) on exit."""
    p = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    time.sleep(0.5)
    try:
        yield
    finally:
        p.kill()
        p.wait()


def run_snippet(policy_off: bool) -> float:
    env = dict(os.environ, PYTHONPATH=ROOT, POLICY_OFF="1" if policy_off else "0")
    out = subprocess.run(
        [sys.executable, "-c", SNIPPET], env=env, capture_output=True, text=True, check=True
    )
    return float(out.stdout.split()[0])


def snippet(repeats: int) -> dict:
    res: dict = {}
    for off in (False, True):
        alone, busy = [], []
        for _ in range(repeats):  # alternation: alone, busy, alone, busy, ...
            alone.append(run_snippet(off))
            with busy_process():
                busy.append(run_snippet(off))
        key = "policy_off" if off else "policy_on"
        res[key] = {
            "alone_s": alone,
            "busy_s": busy,
            "ratio_of_medians": statistics.median(busy) / statistics.median(alone),
        }
    return res


def threads_sweep(repeats: int) -> dict:
    sys.path.insert(0, os.path.join(ROOT, "bench"))
    from bench_gmm import make_data

    default = torch.get_num_threads()
    saved = gmm_mod.SINGLE_THREAD_WORK
    gmm_mod.SINGLE_THREAD_WORK = 0.0  # the policy off: the thread count set here applies
    spare = gmm_mod._spare_core
    gmm_mod._spare_core = lambda: True
    rows = []
    try:
        for a, n, d, k in ((3, 50, 3, 10), (3, 150, 4, 10), (3, 330, 4, 15), (3, 1000, 4, 15),
                           (3, 3000, 4, 15), (10, 1000, 8, 10)):  # fmt: skip
            x, y = make_data(a, n, d, seed=0)
            m = GaussianMixtureSet(a, d, k, seed=0)
            work = float(n) * a * (k * (k + 1) // 2) * (d * (d + 3) // 2 + 1)
            row = {"case": f"{a}x{n}x{d}-D k<={k}", "work": work}
            for load in ("alone", "busy"):
                ctx = busy_process() if load == "busy" else contextlib.nullcontext()
                t = {1: [], default: []}
                with ctx:
                    for _ in range(repeats):
                        for th in (1, default):
                            torch.set_num_threads(th)
                            m.fit(x, y)  # untimed warm-up on this thread count
                            t0 = time.perf_counter()
                            m.fit(x, y)
                            t[th].append(time.perf_counter() - t0)
                row[load] = {
                    "one_thread_ms": 1e3 * min(t[1]),
                    "default_threads_ms": 1e3 * min(t[default]),
                    "gain_of_threads": min(t[1]) / min(t[default]),
                }
            rows.append(row)
            al, bu = row["alone"], row["busy"]
            print(
                f"  {row['case']:<20} work {work:9.3g}  alone: 1 thr "
                f"{al['one_thread_ms']:7.1f} ms, {default} thr {al['default_threads_ms']:7.1f} ms"
                f" | busy: 1 thr {bu['one_thread_ms']:7.1f} ms, {default} thr "
                f"{bu['default_threads_ms']:7.1f} ms",
                flush=True,
            )
    finally:
        torch.set_num_threads(default)
        gmm_mod.SINGLE_THREAD_WORK = saved
        gmm_mod._spare_core = spare
    return {"default_threads": default, "rows": rows}


def main() -> None:
    ap = Parser(__doc__)
    ap.add_argument(
        "--sections",
        default="long,single,snippet,threads",
        help="comma-separated, of long, single, snippet, threads (default all)",
    )
    ap.add_argument(
        "--n", type=int, default=10_000, help="long: demonstrations per stream (default 10000)"
    )
    ap.add_argument(
        "--full-every",
        type=int,
        default=50,
        help="long: time the full refit at every N-th step (default %(default)s)",
    )
    ap.add_argument(
        "--streams", default="iid,drift", help="long: comma-separated, of iid, drift (default both)"
    )
    ap.add_argument(
        "--snippet-repeats",
        type=int,
        default=3,
        help="snippet: runs alone and busy, each (default %(default)s)",
    )
    ap.add_argument(
        "--thread-repeats",
        type=int,
        default=3,
        help="threads: timed fits per size and setting (default %(default)s)",
    )
    ns = ap.parse_args()
    sections = ns.sections.split(",")
    known = {"long", "single", "snippet", "threads"}
    if not set(sections) <= known:
        ap.error(f"--sections: expected some of {sorted(known)}, got {ns.sections!r}")
    if not set(ns.streams.split(",")) <= {"iid", "drift"}:
        ap.error(f"--streams: expected some of ['drift', 'iid'], got {ns.streams!r}")
    for flag, v in (
        ("--n", ns.n),
        ("--full-every", ns.full_every),
        ("--snippet-repeats", ns.snippet_repeats),
        ("--thread-repeats", ns.thread_repeats),
    ):
        if v < 1:
            ap.error(f"{flag}: expected an int >= 1, got {v}")
    if ns.n < ns.full_every:
        ap.error(
            f"--n ({ns.n}) must be at least --full-every ({ns.full_every}): the full refit "
            "is timed every --full-every demonstrations"
        )
    out: dict = {"load_average_at_start": os.getloadavg(), "cpus": os.cpu_count()}
    print(f"load average at start: {out['load_average_at_start']}, {out['cpus']} CPUs")
    if "single" in sections:
        r = single_refit()
        out["single"] = r
        print(
            f"single refit at 1000 demonstrations (3 x 4-D, k<=15): median "
            f"{r['refit_median_ms']:.2f} ms (p10 {r['refit_p10_ms']:.2f}, p90 "
            f"{r['refit_p90_ms']:.2f}; CPU {r['refit_cpu_median_ms']:.2f}); full fit median "
            f"{r['full_fit_median_ms']:.1f} ms (CPU {r['full_fit_cpu_median_ms']:.1f})"
        )
    if "long" in sections:
        out["long"] = []
        print(f"long session: {ns.n} demonstrations, 4-D, 3 actions, k<=10, max_new=1")
        head = f"{'stream':<7}{'incremental s':>14}{'full s (est.)':>15}{'ratio':>9}"
        print(
            head + f"{'CPU ratio':>10}{'LL shortfall':>14}{'agreement':>11}{'scratch fits':>14}"
            f"{'their share':>13}"
        )
        for kind in ns.streams.split(","):
            r = long_session(kind, ns.n, ns.full_every)
            out["long"].append(r)
            short = r["ll_shortfall_rel_max"]
            print(
                f"{kind:<7}{r['incremental_total_s']:>14.1f}{r['full_total_s_estimated']:>15.1f}"
                f"{'1/' + format(1 / r['ratio'], '.1f'):>9}"
                f"{'1/' + format(1 / r['ratio_cpu'], '.1f'):>10}"
                f"{'-' if short is None else format(short, '.2e'):>14}"
                f"{r['agreement_heldout']:>11.4f}{r['from_scratch_action_fits']:>14}"
                f"{r['scratch_refits_share_of_incremental']:>13.1%}",
                flush=True,
            )
    if "threads" in sections:
        print("thread sweep (best of repeats, policy off):")
        out["threads"] = threads_sweep(ns.thread_repeats)
    if "snippet" in sections:
        r = snippet(ns.snippet_repeats)
        out["snippet"] = r
        for key, v in r.items():
            print(
                f"corridor snippet, {key}: alone {min(v['alone_s']):.2f}-{max(v['alone_s']):.2f} s,"
                f" beside a busy process {min(v['busy_s']):.2f}-{max(v['busy_s']):.2f} s, "
                f"ratio of medians {v['ratio_of_medians']:.2f}"
            )
    out["load_average_at_end"] = os.getloadavg()
    print(json.dumps(out))


if __name__ == "__main__":
    main()
