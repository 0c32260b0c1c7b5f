"""The set of Gaussian mixtures of the paper's Section 4.1: one full-covariance mixture per action.

``GaussianMixtureSet`` fits every candidate component count of every action in ONE batched EM
(see :mod:`torchcbl._em`), keeps per action the count with the lowest information criterion, and
classifies observations with Eq. 7, reporting for each the Mahalanobis distance (in standard
deviations) to the most likely component of the chosen mixture, which the paper's confidence
rule thresholds.

Variance floor
--------------
Every covariance matrix gets ``floor_j`` added to its diagonal entry ``j`` (as scikit-learn's
``reg_covar``, but per feature and scaled to the data)::

    floor_j = var_floor * Var_j + 1e-6 * mean_i(Var_i)      (1e-6 if every Var_i is 0)

where ``Var_j`` is the (biased) variance of feature ``j`` over ALL training observations, all
actions together. So a discrete feature that is constant inside a component (the lane index), an
action with a single point or with identical points, all fit without a singular matrix: such a
component's spread along feature ``j`` is ``sqrt(floor_j)``, i.e. about 3% of that feature's
overall standard deviation with the default ``var_floor = 1e-3``, as long as the features'
scales are not far apart. The second term is shared: a feature whose variance is below
``1e-3 * mean_i(Var_i)`` (a standard deviation some 30 times below the others' for a few
features) gets a floor larger than its own share, up to wider than the feature itself (a
spread of about 7 for a feature of standard deviation 1e-4 beside one of 1e4). Put features
on comparable scales (metres with metres, or standardised) before fitting. The floor is stored
in the ``var_floor_`` buffer.

Selection of the component count
--------------------------------
Eq. 6 sums each mixture's criterion weighted by Pr(G_a) > 0; each term depends only on its own
mixture's count, so the joint minimum over all count combinations is reached by minimising each
action separately, which is what ``fit`` does. ``criterion="aic"`` (default) is the standard AIC
with free parameters p = (k-1) + k d + k d (d+1) / 2 (equal to scikit-learn's ``aic``);
``"bic"`` is p log n - 2 L; ``"aic_paper"`` is Eq. 5 taken literally, 2 k - 2 L.

The floor decides how far the AIC can go: a component on a handful of points (or on a point
mass, such as a range reading clipped at the sensor's maximum) gains more likelihood from a
floor-sized spread than the AIC charges for its parameters. With the default floor, points
drawn from ONE standard 2-D Gaussian got 5-7 components at n = 10 and 1-10 at n = 50 (five
seeds each, cap 10; scikit-learn with the same ``reg_covar`` behaves alike), and such narrow
components make new points look far. Both experiments therefore raise the floor, by the
smallest value at which no mixture sits at its component cap on their demonstrations (corridor
0.01, driving 0.03; ``docs/data/*_var_floor_2026-11-26.md``); ``criterion="bic"`` penalises
more with small n.

Incremental refits
------------------
:meth:`GaussianMixtureSet.refit` refits only the actions whose data changed, each candidate
warm-started from its own kept parameters and sufficient statistics (one EM step per refit),
and fits an action from scratch again once its data grew by ``refit_growth`` since its last
from-scratch fit (see docs/architecture.md).

Threads
-------
Fits and classification run on one torch thread in a scope that restores the caller's count;
only work of at least :data:`SINGLE_THREAD_WORK` gets the caller's threads (an EM: its largest
action's points x candidate components x quadratic features; classifying a batch of more than 256
rows: rows x actions x components x D**2), and only while the machine has a spare core. The
global setting is never changed behind the caller's back.
Such an EM's last bits can depend on the count it got, and so on the machine's load at that
moment: a matrix product over many points may split its sums between threads (one action of
20,000 points, 4-D, k <= 8 fitted on one and on two threads differed in the 14th digit). On
one torch thread (``torch.set_num_threads(1)``, as the experiments' workers run) every fit and
refit is reproducible bit for bit.
"""

from __future__ import annotations

import contextlib
import math
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, Literal, NamedTuple, NoReturn, overload

import numpy as np
import torch
from torch import Tensor, nn

from torchcbl import _em
from torchcbl._text import counted

__all__ = ["SINGLE_THREAD_WORK", "Classification", "FitReport", "GaussianMixtureSet"]

Criterion = Literal["aic", "bic", "aic_paper"]
_CRITERIA = ("aic", "bic", "aic_paper")
# the constructor's settings that decide what fit() and refit() choose, kept in the
# ``settings_`` buffer (in this order) so that a state_dict cannot load into a model that
# would refit differently
_SETTINGS = ("criterion", "var_floor", "tol", "max_iter", "seed", "refit_growth", "n_init")
# the largest n_init a state holds: its code, criterion index + 3 (n_init - 1), is an int64
_N_INIT_MAX = (2**63 - len(_CRITERIA)) // len(_CRITERIA) + 1


def _float_bits(x: float) -> int:
    """A float's IEEE-754 bits as an int64: exact, and untouched by a module's ``.to(dtype)``."""
    return struct.unpack("<q", struct.pack("<d", float(x)))[0]


def _bits_float(b: int) -> float:
    return struct.unpack("<d", struct.pack("<q", int(b)))[0]


def _settings_codes(model: GaussianMixtureSet) -> list[int]:
    seed = model.seed
    return [
        # the criterion and n_init share the first code: a state of n_init=1 holds the code it
        # held before n_init existed (and one of n_init > 1 reads as an unknown criterion to
        # the code before it, which refuses to load it)
        _CRITERIA.index(model.criterion) + len(_CRITERIA) * (model.n_init - 1),
        _float_bits(model.var_floor),
        _float_bits(model.tol),
        model.max_iter,
        seed - 2**64 if seed >= 2**63 else seed,  # the uint64 seed's bits as an int64
        _float_bits(model.refit_growth),
    ]


def _settings_values(codes: list[int]) -> dict[str, Any]:
    """The settings that :func:`_settings_codes` encoded, by name."""
    crit, floor, tol, max_iter, seed, growth = codes
    return {
        "criterion": _CRITERIA[crit % len(_CRITERIA)] if crit >= 0 else f"<code {crit}>",
        "n_init": crit // len(_CRITERIA) + 1 if crit >= 0 else f"<code {crit}>",
        "var_floor": _bits_float(floor),
        "tol": _bits_float(tol),
        "max_iter": max_iter,
        "seed": seed + 2**64 if seed < 0 else seed,
        "refit_growth": _bits_float(growth),
    }


def _device_memory(dev: torch.device) -> int | None:
    """Bytes of memory of ``dev`` (the host's physical memory for the CPU, the GPU's own for
    CUDA), None where it cannot be read."""
    try:
        if dev.type == "cuda":
            return int(torch.cuda.get_device_properties(dev).total_memory)
        if dev.type == "cpu":
            return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError, RuntimeError):  # no sysconf (Windows), ...
        pass
    return None


# the batched EM holds at once (at least) the responsibilities [G, N, C, K] and the candidates'
# parameters [G, C, K, Q + D^2] in float64, and as much again in their temporaries: this many
# times their bytes is a lower bound of its peak memory (peaks measured on the CPU: 3.4 to 7.5
# times). The memory check (naming n_init, or max_components where one start is too many)
# refuses only what this lower bound says no memory of the device holds; it is no estimate
# of the peak, and a fit it lets through may still run out. Not 4: a
# peak of 3.4 times was measured, and at 4 a 16 GiB machine would refuse 20,000 points of 8
# features in 4 actions, cap 40, n_init 5, once 17,000 of them are one action's (16.3 GiB at
# 4, 8.2 at 2)
_EM_MEMORY_FACTOR = 2


_ABS_FLOOR = 1e-6
_NUMPY_MAX_ROWS = 256  # below this many rows (CPU), classify/log_prob run in numpy: less overhead
# larger batches are scored in blocks of rows whose [rows, A*K*D] scores hold at most this many
# float64 values (128 MiB): memory stays bounded whatever N (a decision map of 10^6 points)
_BLOCK_VALUES = 1 << 24
_LOG_2PI = math.log(2.0 * math.pi)
_VERY_NEGATIVE = -1.0e300  # log weight of padded components in the prediction tables


class Classification(NamedTuple):
    """Result of :meth:`GaussianMixtureSet.classify` for N observations.

    action [N] long: argmax_a p_a(o) Pr(G_a) (Eq. 7); -1 before any fit.
    confidence [N] float64 in [0, 1]: exp(-distance^2 / 2); 0 before any fit.
    distance [N] float64: Mahalanobis distance, in standard deviations, of o to the most likely
        component (largest w_c N(o; mu_c, S_c)) of the chosen action's mixture; +inf before fit.
    posterior [N, A] float64: p(a | o); uniform before any fit.
    """

    action: Tensor
    confidence: Tensor
    distance: Tensor
    posterior: Tensor


@dataclass(frozen=True, eq=False)
class FitReport:
    """What happened in one :meth:`GaussianMixtureSet.fit`.

    Tables are [A, max_components]; column j is the candidate with j + 1 components.
    Entries that are not candidates (j + 1 > points of the action) hold -inf log-likelihood,
    +inf criterion, converged False and 0 iterations; ``candidate_mask`` marks the real ones.
    ``log_likelihood`` is the total (summed over the action's points) natural-log likelihood.
    ``refit_kind`` says per action what this fit did: "scratch" (k-means++ start), "warm"
    (every candidate started from its previous parameters, :meth:`GaussianMixtureSet.refit`),
    "kept" (data unchanged, mixture kept; its table rows are those of its last fit) or "empty".
    A warm candidate takes one EM step per refit (EM continues across refits): its
    ``converged`` says whether that step moved its mean per-point log-likelihood by less than
    ``tol``, its ``n_iter`` counts the E-steps (2, the first one often over the new points
    only, see :meth:`GaussianMixtureSet.refit`), and the "did not converge" note lists only
    candidates fitted from scratch.
    """

    criterion_name: str
    n_points: tuple[int, ...]
    n_components: tuple[int, ...]
    empty_actions: tuple[int, ...]
    candidate_mask: Tensor
    log_likelihood: Tensor
    criterion: Tensor
    converged: Tensor
    n_iter: Tensor
    notes: tuple[str, ...]
    refit_kind: tuple[str, ...] = ()

    @property
    def all_converged(self) -> bool:
        """True if every candidate of every action converged within max_iter."""
        return bool(self.converged[self.candidate_mask].all())

    def __str__(self) -> str:
        lines = [f"FitReport (criterion={self.criterion_name})"]
        for a, (n, k) in enumerate(zip(self.n_points, self.n_components, strict=True)):
            if n == 0:
                lines.append(f"  action {a}: no data, never predicted")
                continue
            m = self.candidate_mask[a]
            conv = int(self.converged[a][m].sum())
            how = f", {self.refit_kind[a]}" if self.refit_kind else ""
            lines.append(
                f"  action {a}: {counted(n, 'point')}, chose k={k} of "
                f"{counted(int(m.sum()), 'candidate')} "
                f"({conv} converged{how}), log-likelihood "
                f"{float(self.log_likelihood[a, k - 1]):.4g}"
            )
        lines.extend(f"  note: {s}" for s in self.notes)
        return "\n".join(lines)


_FAR = 1e150  # |(x - mu)^T U| per coordinate beyond which squares may overflow: _classify_far
# A component score (log w + log N) at or below this is no real component's: the padding
# components score _VERY_NEGATIVE - maha / 2 at most. A row whose best real score is this low
# (or overflows) would be decided by the padding (at the origin, unit covariance), so it goes
# to the exact path, _far_scores.
_FAR_SCORE = 0.5 * _VERY_NEGATIVE


def _merge_rows(far: np.ndarray, c_far: Any, classify: Any, x: np.ndarray) -> Any:
    """One Classification from the far rows' and the other rows' (classified by ``classify``)."""
    near = ~far
    if not near.any():
        return c_far
    c_near = classify(x[near])
    fields = []
    for f_far, f_near in zip(c_far, c_near, strict=True):
        out = torch.empty((x.shape[0], *f_far.shape[1:]), dtype=f_near.dtype)
        out[torch.from_numpy(far)] = f_far.to(f_near.dtype)
        out[torch.from_numpy(near)] = f_near
        fields.append(out)
    return type(c_far)(*fields)


def _is_real_dtype(kind: str) -> bool:
    return kind in "fiu"


_NUMPY_FLOATS = (torch.float16, torch.float32, torch.float64)


def _to_numpy(value: Any, name: str) -> np.ndarray:
    if isinstance(value, np.ndarray):
        # a view with negative strides (x[::-1]) cannot become a torch tensor; a matrix or a
        # masked array is read as the plain array it holds
        return np.ascontiguousarray(np.asarray(value))
    if isinstance(value, Tensor):
        value = value.detach().cpu()
        if value.dtype.is_floating_point and value.dtype not in _NUMPY_FLOATS:
            value = value.to(torch.float64)  # bfloat16, float8: numpy has no such dtype
        return value.numpy()
    try:
        return np.asarray(value)
    except Exception as exc:  # noqa: BLE001 - re-raised with a clear message
        raise TypeError(
            f"{name}: expected a numpy array, a torch tensor or a nested sequence of numbers "
            f"with rows of equal length, but numpy could not read the {type(value).__name__} "
            f"given ({exc})"
        ) from exc


def _conversion(value: Any, name: str, to: str) -> str:
    """How to convert ``value`` (what the caller passed as ``name``) to ``to`` ("int" or
    "float") in its own kind of container."""
    if isinstance(value, Tensor):
        return ".long()" if to == "int" else ".double()"
    if isinstance(value, np.ndarray):
        return f".astype({to})"
    return f"numpy.asarray({name}, dtype={to})"


def _rows_preview(rows: np.ndarray) -> str:
    shown = ", ".join(str(int(r)) for r in rows[:10])
    more = f" (showing the first 10 of {rows.size})" if rows.size > 10 else ""
    return f"[{shown}]{more}"


# the refit statistics of the incremental EM, in the order of _fit's stats tables
_STATS_BUFFERS = ("cand_stats_", "cand_coef_", "stats_valid_", "ref_center_", "data_print_")

_REFIT_BUFFERS = (
    "converged_",
    "n_iter_",
    "data_mean_",
    "cand_weights_",
    "cand_means_",
    "cand_covariances_",
    "full_fit_points_",
    *_STATS_BUFFERS,
)


_PRINT_WEIGHTS = np.ones(0)


def _fingerprint(xa: np.ndarray) -> np.ndarray:
    """[n, D] -> [D]: the sum of the rows weighted by a fixed pseudo-random weight in [1, 2)
    per row position. Bit-identical for the same rows; an edited, removed or moved row
    changes it, except for a coincidence or an edit below the sum's rounding (an ulp or so
    of one value, which moves the statistics by as little). numpy sums over the leading axis
    one row after the other, whatever the array's memory alignment."""
    global _PRINT_WEIGHTS
    n = xa.shape[0]
    if _PRINT_WEIGHTS.size < n:
        size = max(1024, 1 << (n - 1).bit_length())
        _PRINT_WEIGHTS = 1.0 + _em._splitmix_uniform(np.arange(size, dtype=np.uint64))
    return (xa * _PRINT_WEIGHTS[:n, None]).sum(0)


def _initial_buffer(model: GaussianMixtureSet, name: str) -> Tensor:
    """The value a buffer of :data:`_REFIT_BUFFERS` has before any fit."""
    buf = getattr(model, name)
    if name == "cand_covariances_":
        return torch.eye(model.n_features, dtype=buf.dtype).expand(buf.shape).clone()
    return torch.zeros(buf.shape, dtype=buf.dtype)


# Thread policy (see docs/architecture.md, "Threads"). Everything in fit/refit/classify runs on
# one torch thread, in a scope that restores the caller's count, except the EM of a problem of
# at least this much work per iteration (points x candidate components x quadratic features),
# which gets the caller's threads when the machine has a core to spare (no other process's
# thread running on it now, see _spare_core). Measured with bench/bench_refit.py --sections
# threads.
SINGLE_THREAD_WORK = 1.0e6

# A warm-started candidate takes one EM step per refit, reported as this many E-steps: the
# one of its kept parameters (often over the new points alone, added to the kept statistics)
# and the one that measures the parameters of the M-step between them.
_WARM_ITER = 2


def _usable_cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not on Linux
        return os.cpu_count() or 1


def _running_now() -> tuple[int, int] | None:
    """(threads running or runnable on the system now, this process's own among them, the
    calling thread included) from /proc (Linux), or None where /proc does not say. The own
    count is only read when the system count alone cannot settle :func:`_spare_core`."""
    try:
        with open("/proc/loadavg", "rb") as f:
            running = int(f.read().split()[3].split(b"/")[0])
        if running < _usable_cpus():
            return running, 1
        own = 0
        for tid in os.listdir("/proc/self/task"):
            try:
                with open(f"/proc/self/task/{tid}/stat", "rb") as f:
                    stat = f.read()
                end = stat.rindex(b")")  # the name may hold ")": the state follows the last
            except (OSError, ValueError):  # the thread has just ended
                continue
            own += stat[end + 2 : end + 3] == b"R"
    except (OSError, ValueError, IndexError):
        return None
    return running, max(own, 1)


def _spare_core() -> bool:
    """True when another thread of ours would find a core that no other process is using.

    Where /proc says (Linux), what runs now counts, not what ran over the last minute: the
    1-minute load average lags a competing process by a minute, and counts this process's own
    threads, so that a process that had fitted on two threads for a minute would throttle
    itself. Elsewhere the 1-minute load average (below the usable CPUs minus 0.5); with
    neither (Windows), the size rule alone.
    """
    now = _running_now()
    if now is not None:
        running, own = now
        # a core beyond the one ours runs on is free. One sample of one instant; /proc/loadavg
        # counts the whole machine, so in a container limited to some of its CPUs a busy host
        # means one thread (as the load average did), and a CPU quota is not seen at all
        return running - own + 1 < _usable_cpus()
    try:
        load = os.getloadavg()[0]
    except (AttributeError, OSError):  # no load average (Windows): trust the size rule
        return True
    return load < _usable_cpus() - 0.5


def _em_threads(work: float, caller: int) -> int:
    """Threads for an EM of ``work`` (see SINGLE_THREAD_WORK): 1 or the caller's count."""
    if caller <= 1 or work < SINGLE_THREAD_WORK or not _spare_core():
        return 1
    return caller


@contextlib.contextmanager
def _threads(n: int) -> Iterator[None]:
    """Run the block on ``n`` torch threads, then restore the count the caller had.

    torch's thread count is process-wide: another Python thread running torch operations at
    the same time sees ``n`` for that while.
    """
    before = torch.get_num_threads()
    if n == before:
        yield
        return
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _best_init(res: _em.EMResult, n_init: int) -> _em.EMResult:
    """An EM result over [G, n_init * C] slots (initialisation i of candidate c in slot
    i * C + c) -> the [G, C] result of each candidate's initialisation with the highest final
    log-likelihood (the first on ties; a non-finite one only when all are)."""
    g, slots = res.loglik.shape
    c = slots // n_init
    ll = res.loglik.view(g, n_init, c)
    best = torch.where(torch.isfinite(ll), ll, -math.inf).argmax(1)  # [G, C], first maximum
    slot = best * c + torch.arange(c, device=best.device)  # [G, C]
    rows = torch.arange(g, device=best.device).unsqueeze(1)
    return _em.EMResult(
        _em.Params(*(t[rows, slot] for t in res.params)),
        res.loglik[rows, slot],
        res.n_iter[rows, slot],
        res.converged[rows, slot],
    )


class GaussianMixtureSet(nn.Module):
    """One full-covariance Gaussian mixture per action, fitted by batched EM (Section 4.1).

    Args:
        n_actions: number of discrete actions A (labels 0..A-1).
        n_features: observation dimension D.
        max_components: largest component count tried per action; the candidates of an action
            with n_a points are k = 1..min(max_components, n_a), all fitted at once (a fit's
            memory grows with their count squared times n_a: see ``n_init``). The model keeps
            every candidate's parameters (the ``cand_*_`` buffers, A x max_components^2 rows):
            sizes whose buffers exceed the host's memory are a ValueError.
        criterion: "aic" (free-parameter AIC, default), "bic", or "aic_paper" (Eq. 5 literally).
        var_floor: relative variance floor, see the module docstring (>= 0).
        tol: EM stops when the mean per-point log-likelihood changes less than this (nats).
            Default 1e-3, scikit-learn's default; it keeps a refit of 999 points (3 actions,
            4-D, k <= 15) under 0.1 s. Use 1e-4 or less for tighter fits.
        max_iter: EM iteration cap per candidate.
        seed: seeds the k-means++ initialisation, an int in [0, 2**64); the same seed and data
            give the same model.
        refit_growth: :meth:`refit` fits an action from scratch once its point count reached
            ``1 + refit_growth`` times its count at its last from-scratch fit (> 0; default
            0.25: about 3 from-scratch fits per doubling of the data, log 2 / log 1.25, whose
            total cost is about 5 times one fit at the final size).
        n_init: k-means++ initialisations per candidate (an int >= 1; default 1, as
            scikit-learn's ``n_init``): every candidate fitted from scratch (by :meth:`fit`, and
            by :meth:`refit` for an action it fits from scratch) runs EM from ``n_init``
            initialisations, all in the same batched EM, and keeps the one whose final
            parameters have the highest total log-likelihood (the first on ties); the
            criterion then chooses among the kept candidates. Initialisation 0 is the one of
            ``n_init=1``; the others are drawn from ``seed`` too, each its own. A warm refit
            continues the kept candidate alone (one EM step), whatever ``n_init``. The cost
            of a from-scratch fit grows about n_init times; the buffers do not change. At
            most 3074457345618258602, the most the model's state holds. A fit holds all
            its starts in memory at once (measured on the CPU: 27 to 60 bytes x n_init x
            actions x candidates^2 x (the most points of one action + D^2 + D (D + 3) / 2
            + 1)). A ValueError refuses up front only a fit whose lower bound of memory
            (16 bytes x the same) exceeds the device's whole memory (the host's physical
            memory for the CPU): it names ``n_init``, or ``max_components`` where even one
            start does not fit (whatever ``n_init``); a fit that passes may still run out
            of memory.

    Fitted buffers (fixed shapes, so ``state_dict`` loads into a fresh instance built with the
    same arguments, and only into one: a state of other sizes, ``n_actions``, ``n_features``
    or ``max_components``, is a ValueError that names them, and see ``settings_``):
    ``weights_`` [A, K], ``means_``
    [A, K, D], ``covariances_`` [A, K, D, D], ``precisions_cholesky_`` [A, K, D, D],
    ``component_mask_`` [A, K] bool, ``log_prior_`` [A]
    (log share of points, -inf for an action without data), ``n_points_`` [A],
    ``n_components_`` [A] long, ``criterion_`` [A, K] (+inf where k is not a candidate),
    ``log_likelihood_`` [A, K] (-inf where k is not a candidate), ``converged_`` [A, K] bool,
    ``n_iter_`` [A, K] long, ``var_floor_`` [D]. For :meth:`refit`, every candidate's
    parameters (slot c = the candidate with c + 1 components, uncentred; zero weights beyond
    it): ``cand_weights_`` [A, K, K], ``cand_means_`` [A, K, K, D], ``cand_covariances_``
    [A, K, K, D, D]; ``data_mean_`` [A, D] (each action's mean, to detect changed data) and
    ``full_fit_points_`` [A] long (count at the last from-scratch fit, 0 = none). After a
    warm refit of an action, its candidates' sufficient statistics over its points
    ``cand_stats_`` [A, K, K, Q] (Q = D (D + 3) / 2 + 1: sums of resp * (x x^T upper
    triangle, x, 1), x centred at ``ref_center_`` [A, D]) with the coefficients they were
    measured with ``cand_coef_`` [A, K, K, Q], ``stats_valid_`` [A] bool, and a fingerprint
    of the points ``data_print_`` [A, D]: the next warm refit adds the new points' share to
    them instead of an E-step over all the points.
    ``settings_`` [6] long holds the arguments that decide what a fit or refit chooses
    (criterion and n_init in one code, criterion index + 3 (n_init - 1), then var_floor,
    tol, max_iter, seed, refit_growth; floats by their IEEE bits): loading a state saved
    with other values is a ValueError that names them.
    ``fit_report_`` (a :class:`FitReport`) is a plain attribute, not part of the state_dict.

    Prediction: :meth:`classify` (the action of Eq. 7 with its confidence, distance and
    posterior) and :meth:`log_prob` (log p_a(o) + log Pr(G_a), [N, A]); for a callable
    obs -> action, :class:`torchcbl.GreedyPolicy` (``GreedyPolicy(model)``). The model is not
    called like a network: ``model(x)`` raises a TypeError naming these (see :meth:`forward`).
    """

    # The buffers registered in __init__, typed for a type checker (nn.Module's __getattr__
    # says Tensor | Module); shapes in the class docstring.
    weights_: Tensor
    means_: Tensor
    covariances_: Tensor
    precisions_cholesky_: Tensor
    log_det_: Tensor
    component_mask_: Tensor
    log_prior_: Tensor
    n_points_: Tensor
    n_components_: Tensor
    criterion_: Tensor
    log_likelihood_: Tensor
    converged_: Tensor
    n_iter_: Tensor
    var_floor_: Tensor
    data_mean_: Tensor
    cand_weights_: Tensor
    cand_means_: Tensor
    cand_covariances_: Tensor
    full_fit_points_: Tensor
    cand_stats_: Tensor
    cand_coef_: Tensor
    stats_valid_: Tensor
    ref_center_: Tensor
    data_print_: Tensor
    fitted_: Tensor
    settings_: Tensor

    def __init__(
        self,
        n_actions: int,
        n_features: int,
        max_components: int = 10,
        *,
        criterion: Criterion = "aic",
        var_floor: float = 1e-3,
        tol: float = 1e-3,
        max_iter: int = 200,
        seed: int = 0,
        refit_growth: float = 0.25,
        n_init: int = 1,
    ) -> None:
        """An unfitted set of ``n_actions`` mixtures over ``n_features`` features (the
        arguments: see the class docstring); :meth:`fit` fits it. Raises ValueError for an
        argument out of its range, or sizes whose buffers exceed the host's memory."""
        super().__init__()
        for name, val in (
            ("n_actions", n_actions),
            ("n_features", n_features),
            ("max_components", max_components),
            ("max_iter", max_iter),
            ("n_init", n_init),
        ):
            if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < 1:
                raise ValueError(f"Expected {name} to be an int >= 1 but got {val!r}")
        if n_init > _N_INIT_MAX:
            raise ValueError(
                f"Expected n_init to be an int in [1, {_N_INIT_MAX}] (the most a model's state "
                f"holds) but got {n_init!r}; pass a smaller n_init"
            )
        # numpy numbers (np.float32(0.01) from a sweep) are the Python numbers they hold
        var_floor, tol, refit_growth = (
            float(v) if isinstance(v, (np.floating, np.integer)) and not isinstance(v, np.bool_)
            else v
            for v in (var_floor, tol, refit_growth)
        )  # fmt: skip
        if criterion not in _CRITERIA:
            raise ValueError(f"Expected criterion in {_CRITERIA} but got {criterion!r}")

        def real(v: Any) -> bool:  # a bool is no number of these (True would be 1.0)
            return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

        if not real(var_floor) or var_floor < 0:
            raise ValueError(f"Expected var_floor to be a finite float >= 0 but got {var_floor!r}")
        if not real(tol) or tol <= 0:
            raise ValueError(f"Expected tol to be a finite float > 0 but got {tol!r}")
        if (
            isinstance(seed, bool)
            or not isinstance(seed, (int, np.integer))
            or not 0 <= seed < 2**64
        ):
            raise ValueError(f"Expected seed to be an int in [0, 2**64) but got {seed!r}")
        if (
            isinstance(refit_growth, bool)
            or not isinstance(refit_growth, (int, float))
            or not math.isfinite(refit_growth)
            or refit_growth <= 0
        ):
            raise ValueError(
                f"Expected refit_growth to be a finite float > 0 but got {refit_growth!r}"
            )
        self.n_actions = int(n_actions)
        self.n_features = int(n_features)
        self.max_components = int(max_components)
        self.criterion: Criterion = criterion
        self.var_floor = float(var_floor)
        self.tol = float(tol)
        self.max_iter = int(max_iter)
        self.seed = int(seed)
        self.refit_growth = float(refit_growth)
        self.n_init = int(n_init)
        a, k, d = self.n_actions, self.max_components, self.n_features
        # every candidate's parameters and statistics (cand_*_: [A, K, K, ...] float64) are
        # buffers: refused before anything is allocated where no memory of the host holds them
        q = d * (d + 3) // 2 + 1
        need, memory = 8 * a * k * k * (1 + d + d * d + 2 * q), _device_memory(torch.device("cpu"))
        if memory is not None and need > memory:
            raise ValueError(
                f"Expected sizes whose model fits in the memory of the host "
                f"({memory / 2**30:.3g} GiB) but got n_actions={a}, n_features={d}, "
                f"max_components={k}: the model keeps every candidate's parameters, "
                "n_actions x max_components^2 x (n_features^2 + ...) float64 values, at least "
                f"{need / 2**30:.3g} GiB; pass a smaller max_components (the memory grows with "
                "its square) or fewer features"
            )
        f64 = torch.float64
        eye = torch.eye(d, dtype=f64).expand(a, k, d, d).clone()
        self.register_buffer("weights_", torch.zeros(a, k, dtype=f64))
        self.register_buffer("means_", torch.zeros(a, k, d, dtype=f64))
        self.register_buffer("covariances_", eye.clone())
        self.register_buffer("precisions_cholesky_", eye)
        self.register_buffer("log_det_", torch.zeros(a, k, dtype=f64))
        self.register_buffer("component_mask_", torch.zeros(a, k, dtype=torch.bool))
        self.register_buffer("log_prior_", torch.full((a,), -math.inf, dtype=f64))
        self.register_buffer("n_points_", torch.zeros(a, dtype=torch.long))
        self.register_buffer("n_components_", torch.zeros(a, dtype=torch.long))
        self.register_buffer("criterion_", torch.full((a, k), math.inf, dtype=f64))
        self.register_buffer("log_likelihood_", torch.full((a, k), -math.inf, dtype=f64))
        self.register_buffer("converged_", torch.zeros(a, k, dtype=torch.bool))
        self.register_buffer("n_iter_", torch.zeros(a, k, dtype=torch.long))
        self.register_buffer("var_floor_", torch.zeros(d, dtype=f64))
        self.register_buffer("data_mean_", torch.zeros(a, d, dtype=f64))
        self.register_buffer("cand_weights_", torch.zeros(a, k, k, dtype=f64))
        self.register_buffer("cand_means_", torch.zeros(a, k, k, d, dtype=f64))
        self.register_buffer(
            "cand_covariances_", torch.eye(d, dtype=f64).expand(a, k, k, d, d).clone()
        )
        self.register_buffer("full_fit_points_", torch.zeros(a, dtype=torch.long))
        q = d * (d + 3) // 2 + 1
        self.register_buffer("cand_stats_", torch.zeros(a, k, k, q, dtype=f64))
        self.register_buffer("cand_coef_", torch.zeros(a, k, k, q, dtype=f64))
        self.register_buffer("stats_valid_", torch.zeros(a, dtype=torch.bool))
        self.register_buffer("ref_center_", torch.zeros(a, d, dtype=f64))
        self.register_buffer("data_print_", torch.zeros(a, d, dtype=f64))
        self.register_buffer("fitted_", torch.zeros((), dtype=torch.bool))
        self.register_buffer("settings_", torch.tensor(_settings_codes(self), dtype=torch.long))
        self.fit_report_: FitReport | None = None
        self._cache: dict[str, Any] | None = None

    def extra_repr(self) -> str:
        return (
            f"n_actions={self.n_actions}, n_features={self.n_features}, "
            f"max_components={self.max_components}, criterion={self.criterion!r}, "
            f"var_floor={self.var_floor}, tol={self.tol}, max_iter={self.max_iter}, "
            f"seed={self.seed}, refit_growth={self.refit_growth}, n_init={self.n_init}"
        )

    # ------------------------------------------------------------------ state and caches
    @property
    def is_fitted(self) -> bool:
        """True once :meth:`fit` succeeded (or a fitted state_dict was loaded)."""
        return bool(self.fitted_)

    def _apply(self, fn: Any, recurse: bool = True) -> GaussianMixtureSet:  # type: ignore[override]
        self._cache = None
        return super()._apply(fn, recurse)

    def _load_from_state_dict(
        self, state_dict: dict[str, Any], prefix: str, *args: Any, **kwargs: Any
    ) -> None:
        # the sizes first: torch's own refusal lists a dozen buffer shapes and names neither
        # the constructor argument that differs nor what to do
        weights, means = state_dict.get(prefix + "weights_"), state_dict.get(prefix + "means_")
        if isinstance(weights, Tensor) and isinstance(means, Tensor) and means.dim() == 3:
            a, k, d = means.shape
            given = {"n_actions": a, "n_features": d, "max_components": k}
            own = {n: getattr(self, n) for n in given}
            if given != own or tuple(weights.shape) != (a, k):
                raise ValueError(
                    "load_state_dict: the state was saved by a GaussianMixtureSet("
                    + ", ".join(f"{n}={v}" for n, v in given.items())
                    + "), this one has "
                    + ", ".join(f"{n}={v}" for n, v in own.items())
                    + f"; build the model with those sizes, GaussianMixtureSet({a}, {d}, "
                    f"max_components={k}, ...), and load the state into it."
                )
        key = prefix + "settings_"
        saved, fitted = state_dict.get(key), state_dict.get(prefix + "fitted_")
        if isinstance(fitted, Tensor) and bool(fitted) and saved is not None:
            # a fitted state: its candidates were chosen under the saved settings, and a
            # refit continues from them (an unfitted state carries nothing to continue)
            if isinstance(saved, Tensor) and saved.shape == self.settings_.shape:
                given = _settings_values(saved.cpu().tolist())
                own = {n: getattr(self, n) for n in _SETTINGS}
                differ = [n for n in _SETTINGS if given[n] != own[n]]
                if differ:
                    raise ValueError(
                        "load_state_dict: the state was saved by a GaussianMixtureSet with "
                        + ", ".join(f"{n}={given[n]!r}" for n in differ)
                        + ", this one has "
                        + ", ".join(f"{n}={own[n]!r}" for n in differ)
                        + "; its refits would choose other models. Build the model with the "
                        "saved settings and load the state into it."
                    )
        if prefix + "fitted_" in state_dict:
            # the settings stay this instance's own (they are its attributes); a state saved
            # before the settings were kept has nothing to check them against
            state_dict[key] = self.settings_.clone()
        self._cache = None
        self.fit_report_ = None
        # a state_dict saved before refit() existed lacks the candidates: load it with the
        # empty defaults, so that the next refit() fits every action from scratch
        for name in _REFIT_BUFFERS:
            if prefix + name not in state_dict and prefix + "fitted_" in state_dict:
                state_dict[prefix + name] = _initial_buffer(self, name)
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    def _tables(self) -> dict[str, Any]:
        """Prediction tables derived from the buffers, computed once per fit/load/.to()."""
        if self._cache is not None:
            return self._cache
        self._check_finite_state()
        a, k, d = self.n_actions, self.max_components, self.n_features
        dev = self.means_.device
        f64 = torch.float64
        prec = self.precisions_cholesky_.to(f64)
        means = self.means_.to(f64)
        mask = self.component_mask_
        # y = x @ pcat - mu_p gives, per component, (x - mu)^T U: one matrix product for all.
        pcat = prec.permute(2, 0, 1, 3).reshape(d, a * k * d).contiguous()
        mu_p = torch.matmul(means.unsqueeze(-2), prec).reshape(a * k * d)
        logw = torch.log(self.weights_.to(f64).clamp_min(1e-300))
        const = torch.where(mask, logw + self.log_det_.to(f64) - 0.5 * d * _LOG_2PI, _VERY_NEGATIVE)
        log_prior = self.log_prior_.to(f64)
        cache: dict[str, Any] = {
            "pcat": pcat,
            "mu_p": mu_p,
            "const": const,
            "log_prior": log_prior,
            "cpu": dev.type == "cpu",
        }
        # numpy copies on every device: small batches on the CPU are scored in numpy, and a
        # row too far for the batched path is scored exactly in numpy on any device
        # (_classify_far), a CUDA model's included
        cache["np"] = tuple(t.detach().cpu().numpy().copy() for t in (pcat, mu_p, const, log_prior))
        cache["prior_np"] = np.exp(cache["np"][3])
        cache["has_data_np"] = np.isfinite(cache["np"][3])  # [A]: actions with a mixture
        cache["has_data"] = torch.from_numpy(cache["has_data_np"]).to(dev)
        self._cache = cache
        return cache

    def _check_finite_state(self) -> None:
        """Refuse to predict from parameters that are not finite (NaN answers otherwise).

        A model converted to float16 cannot hold a mean beyond +-65504 or a precision above
        it (a standard deviation below about 1.5e-5): those become inf, and every distance
        and log-probability NaN. A state_dict holding NaN or inf is refused the same way.
        """
        bad = [
            name
            for name in ("weights_", "means_", "precisions_cholesky_", "log_det_")
            if not bool(torch.isfinite(getattr(self, name)).all())
        ]
        prior = self.log_prior_
        if bool((torch.isnan(prior) | (prior == math.inf)).any()):
            bad.append("log_prior_")
        if not bad:
            return
        dtype = self.means_.dtype
        if dtype != torch.float64:
            why = (
                f"the model was converted to {dtype}, whose range cannot hold them (float16: "
                "a mean beyond +-65504 or a standard deviation below about 1.5e-5); converting "
                "it back does not restore them: load the float64 state_dict of the fitted "
                "model (or refit) and keep it in float64 or float32"
            )
        else:
            why = (
                "its state holds NaN or inf (a damaged state_dict, or a round trip through "
                "float16): load the float64 state_dict of the fitted model, or refit"
            )
        raise RuntimeError(
            "GaussianMixtureSet: cannot classify or score observations with non-finite "
            f"parameters in {', '.join(bad)}: {why}"
        )

    # ------------------------------------------------------------------ input checks
    def _check_observations(self, observations: Any, name: str = "observations") -> np.ndarray:
        """Validate [N, D] real, finite observations; returns a writable float64 numpy array."""
        x = _to_numpy(observations, name)
        if not _is_real_dtype(x.dtype.kind):
            raise TypeError(
                f"{name}: expected real numbers (float32/float64 or integers) but got dtype "
                f"{x.dtype}; convert with {_conversion(observations, name, 'float')}"
            )
        if x.ndim != 2 or x.shape[1] != self.n_features:
            if x.ndim == 1 and self.n_features == 1:
                hint = "; pass N observations of the one feature as x.reshape(-1, 1)"
            elif x.ndim == 1 and x.shape[0] == self.n_features:
                hint = "; pass one observation as obs[None, :]"
            else:
                hint = ""
            raise ValueError(
                f"{name}: expected shape [N, {self.n_features}] (N >= 1 rows of "
                f"n_features={self.n_features} as given to the constructor) but got shape "
                f"{tuple(x.shape)}{hint}"
            )
        if x.shape[0] == 0:
            raise ValueError(
                f"{name}: expected N >= 1 rows but got an empty array of shape {tuple(x.shape)}"
            )
        if x.dtype != np.float64 or not x.flags.writeable:
            # a read-only array (np.load(mmap_mode="r"), np.broadcast_to) is copied too: fit
            # and large batches hand it to torch.from_numpy, which warns on it (nothing here
            # writes to it)
            x = x.astype(np.float64)
        if not np.isfinite(x).all():
            bad = np.flatnonzero(~np.isfinite(x).all(1))
            raise ValueError(
                f"{name}: expected finite values but rows {_rows_preview(bad)} contain NaN or "
                "inf; remove or impute those rows"
            )
        return x

    def _check_actions(self, actions: Any, n: int) -> np.ndarray:
        y = _to_numpy(actions, "actions")
        if y.dtype.kind not in "iu":
            raise TypeError(
                f"actions: expected integer labels in [0, {self.n_actions}) but got dtype "
                f"{y.dtype}; convert with {_conversion(actions, 'actions', 'int')}"
            )
        if y.ndim != 1 or y.shape[0] != n:
            raise ValueError(
                f"actions: expected shape [{n}] (one label per observation) but got shape "
                f"{tuple(y.shape)}"
            )
        bad = np.flatnonzero((y < 0) | (y >= self.n_actions))
        if bad.size:
            vals = ", ".join(str(int(v)) for v in np.unique(y[bad])[:10])
            raise ValueError(
                f"actions: expected labels in [0, {self.n_actions}) (n_actions="
                f"{self.n_actions}) but got values [{vals}] at rows {_rows_preview(bad)}"
            )
        return y.astype(np.int64)

    # ------------------------------------------------------------------ fitting
    def fit(self, observations: Any, actions: Any) -> GaussianMixtureSet:
        """Fit one mixture per action from scratch, choosing each count by the criterion.

        Every candidate of every action starts from its k-means++ initialisation (from
        ``n_init`` of them, keeping the best, see the constructor). Nothing of an earlier fit
        stays: a fitted model's fit gives the state a fresh model's gives, bit for bit.

        Args:
            observations: [N, D] real array (numpy or torch, float32/float64), N >= 1.
            actions: [N] integer labels in [0, n_actions).

        Returns self. On any error the previously fitted state is left untouched.
        """
        return self._fit_checked(observations, actions, incremental=False)

    def refit(self, observations: Any, actions: Any) -> GaussianMixtureSet:
        """Refit on the full data set, refitting only the actions whose data changed.

        The incremental refit of the teaching loop: after new demonstrations, pass ALL the data
        (old and new). An action whose points are unchanged (same count and bit-identical mean)
        keeps its mixture; every other action is refitted, each of its candidate component
        counts warm-started from that candidate's own previous parameters (all candidates are
        kept, not only the chosen one), and the criterion chooses among the candidates again.
        The priors Pr(G_a) always follow all the data; the variance floor is recomputed from
        all the data and applied to the actions refitted now (a kept action keeps the floor of
        its last fit: with many points the floor moves little between refits).

        A warm candidate takes one EM step (EM continues across refits): an E-step of its
        kept parameters, an M-step, and the E-step of the new parameters, whose sufficient
        statistics are kept. When the action's first points are those of its last refit
        (appended points only: checked by count and a fingerprint of those points, so an
        edited, relabelled or removed old point is caught), the first E-step runs over the new
        points alone and adds their share to the kept statistics (Neal and Hinton's
        incremental EM); otherwise it runs over all the points. Same result either way, up to
        rounding. An action whose points changed with the same count and mean (an edit that
        keeps both) is caught by the fingerprint of all its points and refitted too.
        ``refit`` updates a model along a stream of demonstrations (appended, now and then
        edited or relabelled): one warm EM step is an update, not a fit of other data, so for
        a different data set call :meth:`fit`.

        Full-refit rule: an action is fitted from scratch (k-means++, as :meth:`fit`) instead
        when it was never fitted from scratch, when it gains a candidate (it had fewer than
        ``max_components`` points), or when its point count reached ``1 + refit_growth``
        times its count at its last from-scratch fit. Warm starts so cannot keep an action in a
        poor optimum for good, and as from-scratch fits come at geometrically growing sizes
        their total cost stays a constant multiple of one fit at the final size.

        Before any fit, ``refit`` is ``fit``. The result is a pure function of the state and
        the data: the same seed and data sequence give the same model, bit for bit, and a
        model loaded from this one's ``state_dict`` refits exactly as this one does (on one
        torch thread; an EM large enough to take the caller's threads may differ in its last
        bits with the count it got, see the module's "Threads").

        Args:
            observations: [N, D] real array, N >= 1, every demonstration so far.
            actions: [N] integer labels in [0, n_actions).

        Returns self. On any error the previously fitted state is left untouched.
        """
        return self._fit_checked(observations, actions, incremental=True)

    def _fit_checked(
        self, observations: Any, actions: Any, *, incremental: bool
    ) -> GaussianMixtureSet:
        """Check the inputs, then fit single-threaded (the EM may take the caller's threads
        back, see the thread policy)."""
        if self.means_.dtype != torch.float64:
            # the refit bookkeeping compares float64 state bit for bit: a float32 copy would
            # look changed at every refit (and float16 overflows covariances). Refused before
            # the first fit too: that fit would succeed and every later one fail
            raise TypeError(
                f"fit/refit need the model's float64 state, but it was converted to "
                f"{self.means_.dtype} (a converted model still classifies, computing in "
                "float64 from its converted state); call .to(torch.float64) first"
            )
        x_np = self._check_observations(observations)
        y_np = self._check_actions(actions, x_np.shape[0])
        if not torch.is_inference_mode_enabled():
            for name, buf in self._buffers.items():
                if buf is not None and buf.is_inference():
                    # built under torch.inference_mode(): such a buffer cannot be written in
                    # place outside it, so it becomes an ordinary copy (same values)
                    self._buffers[name] = buf.clone()
        caller = torch.get_num_threads()
        with _threads(1):
            return self._fit(x_np, y_np, incremental=incremental, caller_threads=caller)

    def _fit(
        self, x_np: np.ndarray, y_np: np.ndarray, *, incremental: bool, caller_threads: int = 1
    ) -> GaussianMixtureSet:
        dev = self.means_.device
        f64 = torch.float64
        a_n, kmax, d = self.n_actions, self.max_components, self.n_features
        x = torch.from_numpy(x_np).to(dev)
        y = torch.from_numpy(y_np).to(dev)
        n_total = x.shape[0]

        var = x.var(0, unbiased=False)
        mean_var = float(var.mean())
        floor = self.var_floor * var + (_ABS_FLOOR * mean_var if mean_var > 0 else _ABS_FLOOR)

        counts = torch.bincount(y, minlength=a_n)  # [A]
        counts_np = counts.cpu().numpy()
        centers = _em.index_sum(torch.zeros(a_n, d, dtype=f64, device=dev), 0, y, x)
        centers = centers / counts.clamp_min(1).unsqueeze(1).to(f64)
        k_per_action = np.minimum(counts_np, kmax)  # 0 for an empty action

        # which actions to fit, and how
        has_data = counts_np > 0
        if incremental and self.is_fitted:
            old_n = self.n_points_.cpu().numpy()
            full_n = self.full_fit_points_.cpu().numpy()
            same_mean = (centers == self.data_mean_.to(f64)).all(1).cpu().numpy()
            changed = (counts_np != old_n) | ~same_mean
            prints = self.data_print_.cpu().numpy()
            # a state saved before the fingerprint was kept at every fit holds zeros there: not
            # compared, unless the mean is zero too (points whose print is truly zero, e.g. all
            # at the origin, must be compared: a refit is the safe side of the doubt)
            known = prints.any(1) | ~self.data_mean_.cpu().numpy().any(1)
            for a in np.flatnonzero(has_data & ~changed & known):
                # same count and mean: the same points? (an edit can keep both)
                changed[a] = not np.array_equal(_fingerprint(x_np[y_np == a]), prints[a])
            warm_ok = (
                (full_n > 0)
                & (k_per_action <= np.minimum(old_n, kmax))
                & (counts_np < (1.0 + self.refit_growth) * full_n)
            )
            scratch_np = changed & has_data & ~warm_ok
            warm_np = changed & has_data & warm_ok
        else:
            changed = np.ones(a_n, dtype=bool)
            scratch_np = has_data.copy()
            warm_np = np.zeros(a_n, dtype=bool)
        groups_np = np.flatnonzero(scratch_np | warm_np)  # one EM group per refitted action
        groups = torch.from_numpy(groups_np).to(dev)

        # start from the current tables; the refitted (or emptied) actions' rows are replaced
        crit_tab = self.criterion_.to(f64).clone()
        ll_tab = self.log_likelihood_.to(f64).clone()
        conv_tab = self.converged_.clone()
        iter_tab = self.n_iter_.clone()
        weights = self.weights_.to(f64).clone()
        means = self.means_.to(f64).clone()
        covs = self.covariances_.to(f64).clone()
        precs = self.precisions_cholesky_.to(f64).clone()
        log_det = self.log_det_.to(f64).clone()
        n_comp = self.n_components_.clone()
        c_w = self.cand_weights_.to(f64).clone()
        c_mu = self.cand_means_.to(f64).clone()
        c_cov = self.cand_covariances_.to(f64).clone()
        full_n_new = self.full_fit_points_.clone()
        stats_tab = (
            self.cand_stats_.to(f64).clone(),
            self.cand_coef_.to(f64).clone(),
            self.stats_valid_.clone(),
            self.ref_center_.to(f64).clone(),
            self.data_print_.to(f64).clone(),
        )
        eye = torch.eye(d, dtype=f64, device=dev)
        reset = torch.from_numpy(changed & ~(scratch_np | warm_np)).to(dev)  # emptied actions
        if incremental and self.is_fitted and bool(reset.any()):
            crit_tab[reset] = math.inf
            ll_tab[reset] = -math.inf
            conv_tab[reset] = False
            iter_tab[reset] = 0
            n_comp[reset] = 0
            full_n_new[reset] = 0
        elif not (incremental and self.is_fitted):
            crit_tab.fill_(math.inf)
            ll_tab.fill_(-math.inf)
            conv_tab.fill_(False)
            iter_tab.fill_(0)
            n_comp.zero_()
            full_n_new.zero_()
            # a fit from scratch is a function of the data alone: no refit statistics or
            # fingerprint of earlier data stays (an action without points here kept its old
            # fingerprint), so it is the state a fresh model's fit has, bit for bit
            for table, name in zip(stats_tab, _STATS_BUFFERS, strict=True):
                table.copy_(_initial_buffer(self, name))

        if groups_np.size:
            scratch_groups = np.flatnonzero(scratch_np)
            if scratch_groups.size:
                self._fit_groups(
                    x, y, counts, centers, floor, scratch_groups, k_per_action, crit_tab,
                    ll_tab, conv_tab, iter_tab, n_comp, (c_w, c_mu, c_cov), caller_threads,
                )  # fmt: skip
                stats_tab[2][torch.from_numpy(scratch_groups).to(dev)] = False
                for a in scratch_groups:  # what the next refit compares the points with
                    stats_tab[4][a] = torch.from_numpy(_fingerprint(x_np[y_np == a])).to(dev)
            for a in np.flatnonzero(warm_np):
                self._warm_action(
                    int(a), x_np[y_np == a], centers[a], floor, crit_tab, ll_tab, conv_tab,
                    iter_tab, n_comp, (c_w, c_mu, c_cov), stats_tab, caller_threads,
                )  # fmt: skip
            g_t = groups
            full_n_new[torch.from_numpy(np.flatnonzero(scratch_np)).to(dev)] = counts[
                torch.from_numpy(np.flatnonzero(scratch_np)).to(dev)
            ]
            # the chosen candidate of every refitted action
            chosen = (n_comp[g_t] - 1).clamp_min(0)
            w_ch = c_w[g_t, chosen]
            mu_ch = c_mu[g_t, chosen]
            cov_ch = c_cov[g_t, chosen]
            m_ch = torch.arange(kmax, device=dev) < n_comp[g_t].unsqueeze(1)
            cov_ch = torch.where(m_ch[..., None, None], cov_ch, eye)
            prec_ch, log_det_ch = _em.precision_cholesky(cov_ch)
            weights[g_t] = w_ch * m_ch
            means[g_t] = mu_ch * m_ch.unsqueeze(-1)
            covs[g_t] = cov_ch
            precs[g_t] = torch.where(m_ch[..., None, None], prec_ch, eye)
            log_det[g_t] = log_det_ch * m_ch
        if bool(reset.any()):
            stats_tab[2][reset] = False
            weights[reset] = 0.0
            means[reset] = 0.0
            covs[reset] = eye
            precs[reset] = eye
            log_det[reset] = 0.0
            c_w[reset] = 0.0
            c_mu[reset] = 0.0
            c_cov[reset] = eye
        comp_mask = torch.arange(kmax, device=dev) < n_comp.unsqueeze(1)
        log_prior = torch.where(
            counts > 0, torch.log(counts.to(f64) / n_total), torch.tensor(-math.inf, dtype=f64)
        )
        cand_mask = torch.isfinite(crit_tab)

        kinds = tuple(
            "empty" if not has_data[a] else
            "scratch" if scratch_np[a] else "warm" if warm_np[a] else "kept"
            for a in range(a_n)
        )  # fmt: skip
        empty = tuple(int(i) for i in np.flatnonzero(counts_np == 0))
        notes = [f"action {i} has no data: it is never predicted (log prob -inf)" for i in empty]
        scratch_rows = torch.from_numpy(scratch_np).to(dev).unsqueeze(1)
        not_conv = (cand_mask & ~conv_tab & scratch_rows).nonzero().cpu().numpy()
        if len(not_conv):
            pairs = ", ".join(f"(action {i}, k={j + 1})" for i, j in not_conv[:10])
            notes.append(
                f"{counted(len(not_conv), 'candidate')} did not converge in "
                f"max_iter={self.max_iter}: "
                f"{pairs}"
            )
        report = FitReport(
            criterion_name=self.criterion,
            n_points=tuple(int(c) for c in counts_np),
            n_components=tuple(n_comp.tolist()),
            empty_actions=empty,
            candidate_mask=cand_mask.cpu(),
            log_likelihood=ll_tab.cpu(),
            criterion=crit_tab.cpu(),
            converged=conv_tab.cpu(),
            n_iter=iter_tab.cpu(),
            notes=tuple(notes),
            refit_kind=kinds,
        )

        # Everything succeeded: commit the new state at once.
        with torch.no_grad():
            for name, val in (
                ("weights_", weights),
                ("means_", means),
                ("covariances_", covs),
                ("precisions_cholesky_", precs),
                ("log_det_", log_det),
                ("component_mask_", comp_mask),
                ("log_prior_", log_prior),
                ("n_points_", counts),
                ("n_components_", n_comp),
                ("criterion_", crit_tab),
                ("log_likelihood_", ll_tab),
                ("converged_", conv_tab),
                ("n_iter_", iter_tab),
                ("var_floor_", floor),
                ("data_mean_", centers),
                ("cand_weights_", c_w),
                ("cand_means_", c_mu),
                ("cand_covariances_", c_cov),
                ("full_fit_points_", full_n_new),
                ("cand_stats_", stats_tab[0]),
                ("cand_coef_", stats_tab[1]),
                ("stats_valid_", stats_tab[2]),
                ("ref_center_", stats_tab[3]),
                ("data_print_", stats_tab[4]),
                ("fitted_", torch.ones((), dtype=torch.bool)),
            ):
                getattr(self, name).copy_(val)  # copy_ converts dtype and device
        self.fit_report_ = report
        self._cache = None
        return self

    def _fit_groups(
        self,
        x: Tensor,
        y: Tensor,
        counts: Tensor,
        centers: Tensor,
        floor: Tensor,
        groups_np: np.ndarray,
        k_per_action: np.ndarray,
        crit_tab: Tensor,
        ll_tab: Tensor,
        conv_tab: Tensor,
        iter_tab: Tensor,
        n_comp: Tensor,
        cand: tuple[Tensor, Tensor, Tensor],
        caller_threads: int = 1,
    ) -> None:
        """One batched EM over the given actions, each candidate from its ``n_init`` k-means++
        starts (one slot each: slot i * k_pad + c holds initialisation i of the candidate with
        c + 1 components), the start with the highest final log-likelihood kept; writes their
        rows of the tables, n_comp and the kept candidates ``cand`` in place."""
        dev = x.device
        f64 = torch.float64
        d = self.n_features
        c_w, c_mu, c_cov = cand
        groups = torch.from_numpy(groups_np).to(dev)
        g_n = groups_np.size
        counts_g = counts[groups]
        n_max = int(counts_g.max())
        # the groups' points, centred per action (a better conditioned M-step), in data order
        if g_n == 1:  # one action (a refit's usual case): the same values as the general path
            a0 = int(groups_np[0])
            xg = (x[y == a0] - centers[a0]).unsqueeze(0)
        else:
            sel = torch.isin(y, groups)
            xs, ys = x[sel], y[sel]
            gpos = torch.full((self.n_actions,), -1, dtype=torch.long, device=dev)
            gpos[groups] = torch.arange(g_n, device=dev)
            yg = gpos[ys]
            order = torch.argsort(yg, stable=True)
            ygs = yg[order]
            starts = torch.cumsum(counts_g, 0) - counts_g
            pos = torch.arange(ys.numel(), device=dev) - starts[ygs]
            xg = torch.zeros(g_n, n_max, d, dtype=f64, device=dev)
            xg[ygs, pos] = xs[order] - centers[groups][ygs]

        k_pad = int(k_per_action[groups_np].max())
        # slot c of a group holds the candidate with c + 1 components; slots beyond the
        # action's count hold a duplicate of its k = 1 candidate (computed, then ignored)
        slot_k_np = np.arange(1, k_pad + 1)[None, :].repeat(g_n, 0)
        real_np = slot_k_np <= k_per_action[groups_np][:, None]
        slot_k_np = np.where(real_np, slot_k_np, 1)
        # n_init > 1: the same slots again for every further initialisation, side by side
        n_init = self.n_init
        # refused before anything is allocated where no memory of the device holds the EM:
        # one start of every candidate (the cap's fault, not n_init's), or all n_init of them
        q = d * (d + 3) // 2 + 1
        per_init = _EM_MEMORY_FACTOR * 8 * g_n * k_pad * k_pad * (n_max + q + d * d)
        memory = _device_memory(dev)
        if memory is not None and n_init * per_init > memory:
            if per_init > memory:
                raise ValueError(
                    f"Expected a max_components whose candidates fit in the memory of "
                    f"{dev.type} ({memory / 2**30:.3g} GiB) but got {self.max_components}: "
                    f"this fit's batched EM runs {k_pad} candidate(s) for {g_n} action(s) of "
                    f"up to {n_max} points at once, at least {per_init / 2**30:.3g} GiB for "
                    "one start; pass a smaller max_components (or fit fewer points)"
                )
            raise ValueError(
                f"Expected an n_init whose starts fit in the memory of {dev.type} "
                f"({memory / 2**30:.3g} GiB) but got {n_init}: this fit's batched EM runs "
                f"all its starts of {k_pad} candidate(s) for {g_n} action(s) of up to "
                f"{n_max} points at once, at least {n_init * per_init / 2**30:.3g} GiB "
                f"(even {memory // per_init} starts would fill the memory); pass a much "
                "smaller n_init"
            )
        slot_k_np = np.tile(slot_k_np, (1, n_init))  # [G, n_init * k_pad]
        init_np = np.repeat(np.arange(n_init), k_pad)[None, :].repeat(g_n, 0)
        slot_k = torch.from_numpy(slot_k_np).to(dev)
        pmask = (torch.arange(n_max, device=dev) < counts_g.unsqueeze(1)).to(f64)
        cmask = (torch.arange(k_pad, device=dev) < slot_k.unsqueeze(-1)).to(f64)
        # inference mode (no view or version tracking): ~10% off the EM's many small operations;
        # everything below reads its results through functional ops, so the fitted buffers
        # are ordinary tensors
        work = float(n_max) * float(slot_k_np.sum()) * (d * (d + 3) // 2 + 1)
        with _threads(_em_threads(work, caller_threads)), torch.inference_mode():
            uniforms = torch.from_numpy(
                _em.candidate_uniforms(
                    self.seed,
                    groups_np[:, None].repeat(n_init * k_pad, 1),
                    slot_k_np,
                    k_pad,
                    init_np,
                )
            ).to(dev)
            resp0 = _em.kmeans_init(xg, pmask, cmask, uniforms)
            res = _em.run_em(xg, pmask, cmask, floor, resp0, self.tol, self.max_iter)
            if n_init > 1:
                res = _best_init(res, n_init)
        real = torch.from_numpy(real_np).to(dev)
        g_idx, c_idx = real.nonzero(as_tuple=True)
        cand_action = groups[g_idx]
        cand_k = c_idx + 1
        loglik = res.loglik[g_idx, c_idx]
        self._put_candidates(
            (crit_tab, ll_tab, conv_tab, iter_tab), groups, (cand_action, c_idx), loglik,
            cand_k, counts[cand_action], res.converged[g_idx, c_idx], res.n_iter[g_idx, c_idx],
        )  # fmt: skip
        # Per-action choice (Eq. 6 = sum of independent terms -> per-action argmin).
        n_comp[groups] = crit_tab[groups].argmin(1) + 1  # first minimum: smallest k on ties
        # keep every candidate (uncentred); non-candidate slots hold an empty mixture
        p = res.params
        eye = torch.eye(d, dtype=f64, device=dev)
        kmax = self.max_components
        rm = real.unsqueeze(-1)  # [G, C, 1]
        w_new = torch.zeros(g_n, kmax, kmax, dtype=f64, device=dev)
        mu_new = torch.zeros(g_n, kmax, kmax, d, dtype=f64, device=dev)
        cov_new = eye.expand(g_n, kmax, kmax, d, d).clone()
        w_new[:, :k_pad, :k_pad] = p.weights * rm
        mu_new[:, :k_pad, :k_pad] = (p.means + centers[groups][:, None, None]) * rm[..., None]
        cov_new[:, :k_pad, :k_pad] = torch.where(rm[..., None, None], p.covariances, eye)
        c_w.index_copy_(0, groups, w_new)
        c_mu.index_copy_(0, groups, mu_new)
        c_cov.index_copy_(0, groups, cov_new)

    def _put_candidates(
        self,
        tables: tuple[Tensor, Tensor, Tensor, Tensor],
        rows: Any,
        index: tuple[Any, Any],
        loglik: Tensor,
        ks: Tensor,
        n_points: Tensor,
        converged: Any,
        n_iter: Any,
    ) -> Tensor:
        """Score the fitted candidates (total log-likelihood ``loglik``, component counts
        ``ks``, points ``n_points``) by the criterion and write them into the tables (criterion,
        log-likelihood, converged, iterations) at ``index``, after clearing the refitted action
        ``rows``. Returns the criterion; raises FloatingPointError on a non-finite one."""
        d = self.n_features
        crit = _em.information_criterion(self.criterion, loglik, ks, n_points, d)
        if not bool(torch.isfinite(crit).all()):
            raise FloatingPointError(
                "EM produced a non-finite log-likelihood; the data may be badly scaled "
                "(try standardising the features or a larger var_floor)"
            )
        crit_tab, ll_tab, conv_tab, iter_tab = tables
        crit_tab[rows] = math.inf
        ll_tab[rows] = -math.inf
        conv_tab[rows] = False
        iter_tab[rows] = 0
        crit_tab[index] = crit
        ll_tab[index] = loglik
        conv_tab[index] = converged
        iter_tab[index] = n_iter
        return crit

    def _warm_action(
        self,
        a: int,
        xa: np.ndarray,
        center: Tensor,
        floor: Tensor,
        crit_tab: Tensor,
        ll_tab: Tensor,
        conv_tab: Tensor,
        iter_tab: Tensor,
        n_comp: Tensor,
        cand: tuple[Tensor, Tensor, Tensor],
        stats_tab: tuple[Tensor, Tensor, Tensor, Tensor, Tensor],
        caller_threads: int = 1,
    ) -> None:
        """One EM step for every candidate of action ``a`` (points xa [n, D], data order),
        each from its kept parameters; writes the action's rows of the tables in place.

        The first E-step (the kept parameters on the current points) is skipped when the
        kept sufficient statistics still describe the action's first ``n_old`` points (same
        count at least, and the same fingerprint of those points, so an edited or relabelled
        old point is caught): the new points' share is added to them (Neal and Hinton's
        incremental EM). Otherwise that E-step runs over all the points.
        """
        dev = center.device
        d, kmax = self.n_features, self.max_components
        c_w, c_mu, c_cov = cand
        st_buf, coef_buf, valid_buf, ref_buf, print_buf = stats_tab
        n = xa.shape[0]
        n_old = int(self.n_points_[a])
        c_n = min(n, kmax)
        cand_t, comp_t, ind = _em.warm_rows(c_n, dev)
        flat = cand_t * kmax + comp_t  # rows in the [K * K] candidate slots of an action
        f64 = torch.float64

        def rows(table: Tensor) -> Tensor:  # the action's real components [R, ...]
            return table[a].reshape(kmax * kmax, *table.shape[3:]).index_select(0, flat)

        def put(table: Tensor, value: Tensor, empty: Tensor | float) -> None:  # in place
            slots = table[a].view(kmax * kmax, *table.shape[3:])
            if isinstance(empty, Tensor):
                slots.copy_(empty)
            else:
                slots.fill_(empty)
            slots.index_copy_(0, flat, value)

        fast = (
            bool(self.stats_valid_[a])
            and n > n_old
            and np.array_equal(_fingerprint(xa[:n_old]), self.data_print_[a].cpu().numpy())
        )
        ref = self.ref_center_[a].to(f64) if fast else center
        xt = (torch.from_numpy(xa).to(dev) - ref).T.contiguous()  # [D, n]
        work = float(n) * float(c_n * (c_n + 1) // 2) * (d * (d + 3) // 2 + 1)
        with _threads(_em_threads(work, caller_threads)), torch.inference_mode():
            zt = _em.quadratic_features_t(xt)
            if fast:  # the kept statistics plus the new points' share
                coef0 = rows(self.cand_coef_.to(f64))
                ll_add, st_add = _em.warm_e_step(zt[:, n_old:], coef0, cand_t, ind)
                stats = rows(self.cand_stats_.to(f64)) + st_add
                ll0 = self.log_likelihood_[a, :c_n].to(f64) + ll_add
            else:
                coef0 = _em.warm_coef(rows(c_w), rows(c_mu) - ref, rows(c_cov))
                ll0, stats = _em.warm_e_step(zt, coef0, cand_t, ind)
            w1, mu1, cov1 = _em.warm_m_step(stats, cand_t, c_n, floor)
            coef1 = _em.warm_coef(w1, mu1, cov1)
            ll1, stats1 = _em.warm_e_step(zt, coef1, cand_t, ind)
        crit = self._put_candidates(
            (crit_tab, ll_tab, conv_tab, iter_tab), a, (a, slice(0, c_n)), ll1,
            torch.arange(1, c_n + 1, device=dev), torch.tensor(n, device=dev),
            (ll1 - ll0).abs() / n < self.tol, _WARM_ITER,
        )  # fmt: skip
        n_comp[a] = int(crit.argmin()) + 1  # first minimum: smallest k on ties
        put(c_w, w1, 0.0)
        put(c_mu, mu1 + ref, 0.0)
        put(c_cov, cov1, torch.eye(d, dtype=f64, device=dev))
        put(st_buf, stats1, 0.0)
        put(coef_buf, coef1, 0.0)
        valid_buf[a] = True
        ref_buf[a] = ref
        print_buf[a] = torch.from_numpy(_fingerprint(xa)).to(dev)

    # ------------------------------------------------------------------ prediction
    def _component_scores_np(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pcat, mu_p, const, _ = self._tables()["np"]
        n = x.shape[0]
        y = x @ pcat
        y -= mu_p
        with np.errstate(over="ignore"):  # a far row: its squares are inf, its density 0
            y *= y
            maha = y.reshape(n, self.n_actions, self.max_components, self.n_features).sum(-1)
        return const - 0.5 * maha, maha

    def _component_scores_torch(self, x: Tensor) -> tuple[Tensor, Tensor]:
        t = self._tables()
        n = x.shape[0]
        y = x @ t["pcat"] - t["mu_p"]
        maha = (y * y).reshape(n, self.n_actions, self.max_components, self.n_features).sum(-1)
        return t["const"] - 0.5 * maha, maha

    def _prepare(self, observations: Any) -> tuple[np.ndarray | Tensor, bool]:
        x = self._check_observations(observations)
        if x.shape[0] <= _NUMPY_MAX_ROWS and self._tables()["cpu"]:
            return x, True
        return torch.from_numpy(x).to(self.means_.device), False

    def log_prob(self, observations: Any) -> Tensor:
        """log p_a(o) + log Pr(G_a) for every observation and action (Eq. 7's terms).

        observations [N, D] -> Tensor [N, A] float64 (natural log). -inf for an action without
        data. Raises RuntimeError before any fit, and when the model's parameters are not
        finite (converted to float16, which cannot hold them, or loaded from a damaged state).
        """
        if not self.is_fitted:
            raise RuntimeError("log_prob() needs a fitted model: call fit() first")
        x, use_np = self._prepare(observations)
        tables = self._tables()
        has_data = tables["has_data_np"]
        if use_np:
            lp, _ = self._component_scores_np(x)  # type: ignore[arg-type]
            mx = lp.max(-1, keepdims=True)
            # a row where an action's real components all score that low (or overflow) is
            # scored exactly apart: the padding components would decide it
            far = ~(mx[..., 0] > _FAR_SCORE)[:, has_data].all(1)
            mx = np.where(np.isfinite(mx), mx, 0.0)
            with np.errstate(divide="ignore"):
                mix = mx[..., 0] + np.log(np.exp(lp - mx).sum(-1)) + tables["np"][3]
            if far.any():
                mix[far] = self._far_scores(x[far])[0]  # type: ignore[index]
            return torch.from_numpy(mix)
        # no_grad, not inference_mode: the caller gets ordinary tensors it may modify in place
        # or use with autograd, whatever the batch size
        with self._predict_threads(x.shape[0]), torch.no_grad():
            return torch.cat([self._log_prob_torch(b) for b in self._blocks(x)])  # type: ignore[arg-type]

    def _blocks(self, x: Tensor) -> list[Tensor]:
        """x [N, D] as consecutive blocks of rows of at most ``_BLOCK_VALUES`` scores each."""
        rows = max(1, _BLOCK_VALUES // (self.n_actions * self.max_components * self.n_features))
        return list(torch.split(x, rows)) if x.shape[0] > rows else [x]

    def _log_prob_torch(self, x: Tensor) -> Tensor:
        tables = self._tables()
        lp, _ = self._component_scores_torch(x)
        out = torch.logsumexp(lp, -1) + tables["log_prior"]
        low = ~(lp.amax(-1) > _FAR_SCORE)[:, tables["has_data"]]
        far = low.any(1)
        if bool(far.any()):
            value = self._far_scores(x[far].cpu().numpy())[0]
            out[far] = torch.from_numpy(value).to(out.device, out.dtype)
        return out

    def classify(self, observations: Any) -> Classification:
        """Classify observations [N, D] by Eq. 7 and report how sure the model is.

        Returns a :class:`Classification` with fields of length N. Before any fit: action -1,
        confidence 0, distance +inf, posterior uniform 1/A. Raises RuntimeError when the
        fitted parameters are not finite (see :meth:`log_prob`). A large batch is scored in
        blocks of rows (at most 2**24 component coordinates, A * K * D per row, at a time), so
        its memory stays bounded whatever N; :meth:`log_prob` alike.
        """
        if not self.is_fitted:
            x = self._check_observations(observations)
            n = x.shape[0]
            return Classification(
                torch.full((n,), -1, dtype=torch.long),
                torch.zeros(n, dtype=torch.float64),
                torch.full((n,), math.inf, dtype=torch.float64),
                torch.full((n, self.n_actions), 1.0 / self.n_actions, dtype=torch.float64),
            )
        x, use_np = self._prepare(observations)
        if use_np:
            if x.shape[0] == 1:
                return self._classify_one(x)  # type: ignore[arg-type]
            return self._classify_np(x)  # type: ignore[arg-type]
        with self._predict_threads(x.shape[0]), torch.no_grad():  # ordinary tensors out
            blocks = [self._classify_torch(b) for b in self._blocks(x)]  # type: ignore[arg-type]
        if len(blocks) == 1:
            return blocks[0]
        return Classification(*(torch.cat(field) for field in zip(*blocks, strict=True)))

    def forward(self, *args: Any, **kwargs: Any) -> NoReturn:
        """Refused: ``model(x)`` raises a TypeError that names the methods to call.

        A mixture set has no one output a call could mean: the paper's decision is an action
        with a confidence (:meth:`classify`, a :class:`Classification`, not a tensor), the
        per-action scores [N, A] are :meth:`log_prob` (without the confidence, and scored
        without autograd), and a policy obs [D] -> int is ``torchcbl.GreedyPolicy(model)``.
        """
        raise TypeError(
            f"{type(self).__name__} is not called like a network (it has no forward): call "
            "model.classify(observations [N, D]) for the actions of Eq. 7 with their "
            "confidence, distance and posterior, model.log_prob(observations) for the "
            "per-action log-likelihoods [N, A], or torchcbl.GreedyPolicy(model) for a "
            "callable obs [D] -> action"
        )

    def _predict_threads(self, n: int) -> contextlib.AbstractContextManager[None]:
        """The thread policy for scoring n rows: [N, D] @ [D, A*K*D] is the work."""
        work = float(n) * self.n_actions * self.max_components * self.n_features**2
        return _threads(_em_threads(work, torch.get_num_threads()))

    def _classify_one(self, x: np.ndarray) -> Classification:
        """The N = 1 case of :meth:`_classify_np`, with few array ops (the teaching loop's path).

        Shifts by the single largest component score: an action more than ~700 nats below the
        best then gets posterior 0, which is its float64 value anyway.
        """
        pcat, mu_p, const, _ = self._tables()["np"]
        prior = self._tables()["prior_np"]
        y = x @ pcat
        y -= mu_p
        if not abs(y).max() < _FAR:  # squares would overflow (or x is beyond float64 range)
            return self._classify_far(x)
        y *= y
        maha = y.reshape(self.n_actions, self.max_components, self.n_features).sum(-1)
        lp = const - 0.5 * maha  # [A, K]
        top = lp.max()
        if not top > _FAR_SCORE:  # no real component scores above the padding's range
            return self._classify_far(x)
        e = np.exp(lp - top)
        p = e.sum(1) * prior
        a = int(p.argmax())
        d2 = float(maha[a, int(lp[a].argmax())])
        return Classification(
            torch.from_numpy(np.array([a])),
            torch.from_numpy(np.array([math.exp(-0.5 * d2)])),
            torch.from_numpy(np.array([math.sqrt(d2)])),
            torch.from_numpy((p / p.sum())[None]),
        )

    def _classify_np(self, x: np.ndarray) -> Classification:
        pcat, mu_p, const, _ = self._tables()["np"]
        n = x.shape[0]
        y = x @ pcat
        y -= mu_p
        far = ~(abs(y).max(1) < _FAR)
        if far.any():  # squares would overflow: those rows exactly, apart
            return _merge_rows(far, self._classify_far(x[far]), self._classify_np, x)
        y *= y
        maha = y.reshape(n, self.n_actions, self.max_components, self.n_features).sum(-1)
        lp = const - 0.5 * maha
        far = ~(lp.reshape(n, -1).max(1) > _FAR_SCORE)
        if far.any():  # no real component scores above the padding's range: exactly apart
            return _merge_rows(far, self._classify_far(x[far]), self._classify_np, x)
        mx = lp.max(-1, keepdims=True)
        logp = mx[..., 0] + np.log(np.exp(lp - mx).sum(-1)) + self._tables()["np"][3]
        action = logp.argmax(1)
        m = logp.max(1, keepdims=True)
        post = np.exp(logp - m)
        post /= post.sum(1, keepdims=True)
        rows = np.arange(n)
        lp_a = lp[rows, action]
        comp = lp_a.argmax(1)
        d2 = maha[rows, action, comp]
        dist = np.sqrt(d2)
        return Classification(
            torch.from_numpy(action),
            torch.from_numpy(np.exp(-0.5 * d2)),
            torch.from_numpy(dist),
            torch.from_numpy(post),
        )

    def _classify_torch(self, x: Tensor) -> Classification:
        lp, maha = self._component_scores_torch(x)
        logp = torch.logsumexp(lp, -1) + self._tables()["log_prior"]
        action = logp.argmax(1)
        post = torch.softmax(logp, 1)
        rows = torch.arange(x.shape[0], device=x.device)
        comp = lp[rows, action].argmax(1)
        d2 = maha[rows, action, comp]
        out = Classification(action.clone(), torch.exp(-0.5 * d2), torch.sqrt(d2), post.clone())
        far = ~(torch.isfinite(post).all(1) & torch.isfinite(d2))
        far |= ~(lp.reshape(x.shape[0], -1).amax(1) > _FAR_SCORE)  # decided by the padding
        if bool(far.any()):  # rows whose squared distances overflow: redo them exactly
            rows_far = far.cpu().numpy()
            c = self._classify_far(x[far].cpu().numpy())
            dev = x.device
            for field, value in zip(out, c, strict=True):
                field[torch.from_numpy(rows_far).to(dev)] = value.to(dev, field.dtype)
        return out

    def _classify_far(self, x: np.ndarray) -> Classification:
        """Classify rows whose squared Mahalanobis distances overflow float64 (an observation
        very far from some component, e.g. 1e155 in one feature), with finite results.

        Coordinates are divided by s = max(1, max |x_d|) first, so the distances (not their
        squares) are computed without overflow; a component's log-likelihood is exact where it
        is representable and -inf beyond. When every component's is -inf, the nearest
        component (smallest Mahalanobis distance) decides: its action wins with posterior 1,
        and the confidence is exp(-d^2/2) = 0. The distance is clipped to the largest float.
        """
        n, a, k = x.shape[0], self.n_actions, self.max_components
        logp, lp, ms, dist = self._far_scores(x)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            best = logp.max(1, keepdims=True)
            exact = np.isfinite(best[:, 0])
            post = np.where(exact[:, None], np.exp(logp - np.where(exact[:, None], best, 0)), 0.0)
            action = np.where(exact, logp.argmax(1), ms.reshape(n, a * k).argmin(1) // k)
            rows = np.arange(n)
            post[rows[~exact], action[~exact]] = 1.0
            post /= post.sum(1, keepdims=True)
            comp = np.where(exact, lp[rows, action].argmax(1), ms[rows, action].argmin(1))
            dd = dist[rows, action, comp]
            conf = np.exp(-0.5 * dd * dd)
        return Classification(
            torch.from_numpy(action),
            torch.from_numpy(conf),
            torch.from_numpy(dd),
            torch.from_numpy(post),
        )

    def _far_scores(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(log p_a(o) + log Pr(G_a) [N, A], component scores [N, A, K], maha / s^2 [N, A, K],
        distances [N, A, K]) of the real components alone (the padding scores -inf), computed
        on x / s (s = max(1, max |x_d|)) so that no square overflows: exact where
        representable, -inf beyond (a distance: clipped to the largest float)."""
        pcat, mu_p, const, log_prior = self._tables()["np"]
        n, a, k, d = x.shape[0], self.n_actions, self.max_components, self.n_features
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            scale = np.maximum(abs(x).max(1), 1.0)[:, None]
            y = (x / scale) @ pcat - mu_p / scale
            valid = const > _FAR_SCORE  # [A, K]: components that exist
            ms = np.where(valid, (y * y).reshape(n, a, k, d).sum(-1), np.inf)  # maha / s^2
            dist = np.minimum(scale[:, :, None] * np.sqrt(ms), np.finfo(np.float64).max)
            lp = np.where(valid, const - 0.5 * (scale[:, :, None] ** 2 * ms), -np.inf)
            mx = lp.max(-1, keepdims=True)
            mx0 = np.where(np.isfinite(mx), mx, 0.0)
            logp = mx0[..., 0] + np.log(np.exp(lp - mx0).sum(-1)) + log_prior  # [N, A]
        return logp, lp, ms, dist

    # ------------------------------------------------------------------ criteria
    def _criterion_of_chosen(
        self, kind: str, observations: Any | None, actions: Any | None
    ) -> Tensor:
        if not self.is_fitted:
            raise RuntimeError(f"{kind}() needs a fitted model: call fit() first")
        k = self.n_components_.cpu()
        if observations is None and actions is None:
            idx = (k - 1).clamp_min(0)
            ll = self.log_likelihood_.cpu().to(torch.float64).gather(1, idx[:, None])[:, 0]
            n = self.n_points_.cpu()
        elif observations is None or actions is None:
            raise ValueError("pass both observations and actions, or neither")
        else:
            x = self._check_observations(observations)
            y = self._check_actions(actions, x.shape[0])
            mix = self.log_prob(x).cpu() - self.log_prior_.cpu().to(torch.float64)
            yt = torch.from_numpy(y)
            n = torch.bincount(yt, minlength=self.n_actions)
            ll = torch.zeros(self.n_actions, dtype=torch.float64).index_add_(
                0, yt, mix[torch.arange(len(y)), yt]
            )
        out = _em.information_criterion(kind, ll, k, n.clamp_min(1), self.n_features)
        out = torch.where(n > 0, out, torch.zeros((), dtype=torch.float64))
        # an action without training data has no mixture: its points have likelihood 0
        unfitted = (self.n_points_.cpu() == 0) & (n > 0)
        return out.masked_fill(unfitted, math.inf)

    # both observations and actions, or neither (a ValueError at run time)
    @overload
    def aic(self) -> Tensor: ...

    @overload
    def aic(self, observations: Any, actions: Any) -> Tensor: ...

    def aic(self, observations: Any | None = None, actions: Any | None = None) -> Tensor:
        """Free-parameter AIC [A] of each chosen mixture (2 p - 2 L, as sklearn's ``aic``).

        On the training data by default, or on the given (observations [N, D], actions [N]),
        each mixture scored on its own action's points. 0 for an action without points;
        +inf for an action given points but fitted on none (no mixture: likelihood 0).
        """
        return self._criterion_of_chosen("aic", observations, actions)

    @overload
    def bic(self) -> Tensor: ...

    @overload
    def bic(self, observations: Any, actions: Any) -> Tensor: ...

    def bic(self, observations: Any | None = None, actions: Any | None = None) -> Tensor:
        """BIC [A] of each chosen mixture (p log n - 2 L, as sklearn's ``bic``); see aic()."""
        return self._criterion_of_chosen("bic", observations, actions)
