"""Time GaussianMixtureSet on a CUDA device beside the same model on the CPU, and compare them.

For each case of ``bench_gmm.py`` (a: 3 x 330 x 4-D, k <= 15; b: 3 x 3000 x 4-D, k <= 15; c:
10 x 1000 x 8-D, k <= 10) both sides fit the whole candidate sweep from the same seed; then both
classify one large batch of rows (``--rows``, default 1,000,000). Reported per case: the best of
``--repeats`` fits on each side and their ratio, whether the two chose the same component
counts, the largest relative difference of the chosen candidates' log-likelihoods, and the share
of rows both classify alike. The CPU side runs on torch's default thread count. The GPU is
synchronised before each clock is read. There is no target: the GMM set is built for the
teaching loop's small fits on a CPU, and this script says what a GPU changes.

Usage: python bench/bench_gmm_device.py [--repeats 3] [--rows 1000000] [--cases a,b,c]
Needs a CUDA device (exits 2 with one line without one). The last line printed is one JSON
object with every figure.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
import torch
from _parser import Parser
from bench_gmm import make_data  # the same cases' data (bench/ is on sys.path when run)

from torchcbl.gmm import GaussianMixtureSet

CASES = {"a": (3, 330, 4, 15), "b": (3, 3000, 4, 15), "c": (10, 1000, 8, 10)}


def _timed(fn, device: str) -> float:
    if device == "cuda":
        torch.cuda.synchronize()
    t0 = time.perf_counter()
    fn()
    if device == "cuda":
        torch.cuda.synchronize()
    return time.perf_counter() - t0


def _side(
    dev: str, spec: tuple[int, int, int], x: np.ndarray, y: np.ndarray, q: np.ndarray, repeats: int
) -> tuple[GaussianMixtureSet, float, float, object]:
    """Fit and classify on ``dev``: (model, best fit seconds, best classify seconds, result)."""
    n_act, d, k = spec
    m = GaussianMixtureSet(n_act, d, k, tol=1e-4, max_iter=200, seed=0).to(dev)
    m.fit(x, y)  # warm-up (CUDA context, kernels, allocator)
    fit_s = min(_timed(lambda: m.fit(x, y), dev) for _ in range(repeats))
    m.classify(q[:1000])
    box: list = []
    cls_s = min(_timed(lambda: box.append(m.classify(q)), dev) for _ in range(repeats))
    return m, fit_s, cls_s, box[-1]


def main(argv: list[str] | None = None) -> int:
    p = Parser(__doc__)
    p.add_argument(
        "--repeats", type=int, default=3, help="timed fits and classifications per side (default 3)"
    )
    p.add_argument(
        "--rows", type=int, default=1_000_000, help="rows classified per case (default 1000000)"
    )
    p.add_argument("--cases", default="a,b,c", help="comma-separated, of a, b, c (default a,b,c)")
    a = p.parse_args(argv)
    cases = a.cases.split(",")
    for flag, v in (("--repeats", a.repeats), ("--rows", a.rows)):
        if v < 1:
            p.error(f"{flag}: expected an int >= 1, got {v}")
    if not set(cases) <= set(CASES):
        p.error(f"--cases: expected some of {sorted(CASES)}, got {a.cases!r}")
    if not torch.cuda.is_available():
        print(
            "error: no CUDA device visible to torch; run this on a machine with a GPU",
            file=sys.stderr,
        )
        return 2
    out: dict = {"device": torch.cuda.get_device_name(0), "torch": torch.__version__, "cases": {}}
    print(f"{out['device']}, torch {torch.__version__}, CPU threads {torch.get_num_threads()}")
    print(
        f"{'case':5} {'cpu fit s':>10} {'gpu fit s':>10} {'gpu/cpu':>8} {'same k':>7} "
        f"{'max dLL':>9} {'cpu cls s':>10} {'gpu cls s':>10} {'agree':>7}"
    )
    q_rng = np.random.default_rng(1)
    for name in cases:
        n_act, n_per, d, k = CASES[name]
        x, y = make_data(n_act, n_per, d)
        q = q_rng.normal(scale=1.5, size=(a.rows, d))
        c, fit_c, cls_c, res_c = _side("cpu", (n_act, d, k), x, y, q, a.repeats)
        g, fit_g, cls_g, res_g = _side("cuda", (n_act, d, k), x, y, q, a.repeats)
        same_k = g.n_components_.cpu().tolist() == c.n_components_.tolist()
        rows = torch.arange(n_act)
        ll_c = c.fit_report_.log_likelihood[rows, c.n_components_ - 1]
        ll_g = g.fit_report_.log_likelihood.cpu()[rows, g.n_components_.cpu() - 1]
        dll = float(((ll_g - ll_c).abs() / ll_c.abs()).max())
        agree = float((res_g.action.cpu() == res_c.action).double().mean())
        out["cases"][name] = {
            "cpu_fit_s": fit_c,
            "gpu_fit_s": fit_g,
            "gpu_over_cpu_fit": fit_g / fit_c,
            "same_components": same_k,
            "max_rel_dll": dll,
            "rows": a.rows,
            "cpu_classify_s": cls_c,
            "gpu_classify_s": cls_g,
            "classify_agreement": agree,
        }
        print(
            f"{name:5} {fit_c:10.3f} {fit_g:10.3f} {fit_g / fit_c:8.2f} {str(same_k):>7} "
            f"{dll:9.1e} {cls_c:10.3f} {cls_g:10.3f} {agree:7.4f}"
        )
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
