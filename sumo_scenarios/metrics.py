"""Metrics of the paper's Section 5.2.1 and plot helpers for Figures 6, 8, 9 and 10.

All functions take plain sequences or arrays, so they work on step records from any loop:
``contacts`` [T] bool, ``lanes`` [T] int (0 right shoulder .. 4 left shoulder), ``correct`` [T]
bool (model prediction == teacher action), ``distances`` [T] float (Mahalanobis distance of the
best classification, standard deviations).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from sumo_scenarios.scenarios import LANE_NAMES, N_LANES, _as_int

__all__ = [
    "collision_rate",
    "lane_distribution",
    "plot_accuracy",
    "plot_confidence_trace",
    "plot_lane_bars",
    "total_variation",
    "windowed_accuracy",
]


def collision_rate(contacts: Sequence[bool] | np.ndarray) -> float:
    """Share of timesteps in contact with another car, in [0, 1]."""
    c = _flags("contacts", contacts)
    if c.size == 0:
        raise ValueError("collision_rate needs at least one timestep")
    return float(c.mean())


def _flags(name: str, values: Sequence[bool] | np.ndarray) -> np.ndarray:
    """``values`` as float64 0 / 1 [T]; a NaN or None (which made a NaN count as a contact, or
    every later accuracy window NaN) or any other number is refused."""
    try:
        v = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be True / False per timestep, got {values!r:.60}") from None
    if v.ndim != 1 or not np.all((v == 0.0) | (v == 1.0)):
        raise ValueError(f"{name} must be True / False per timestep (1-D), got {values!r:.60}")
    return v


def lane_distribution(lanes: Sequence[int] | np.ndarray) -> np.ndarray:
    """Share of timesteps in each lane: float64 [5] summing to 1 (index = SUMO lane)."""
    raw = np.asarray(lanes)
    if raw.ndim != 1 or raw.size == 0:
        raise ValueError(f"lane_distribution needs a 1-D sequence of lanes, got shape {raw.shape}")
    with np.errstate(invalid="ignore"):
        whole = raw.dtype.kind in "iub" or (
            raw.dtype.kind == "f" and bool(np.all(raw == np.round(raw)))
        )
    if not whole:  # 2.7 was truncated to lane 2 (NaN to a cast error)
        raise ValueError(f"lanes must be whole lane indices, got {raw[:5].tolist()!r}")
    lane = raw.astype(np.int64)
    if lane.min() < 0 or lane.max() >= N_LANES:
        raise ValueError(f"lanes must lie in [0, {N_LANES - 1}]")
    return np.bincount(lane, minlength=N_LANES) / lane.size


def total_variation(p: Sequence[float] | np.ndarray, q: Sequence[float] | np.ndarray) -> float:
    """Total-variation distance 0.5 * sum |p - q| between two distributions, in [0, 1].

    ``p`` and ``q`` are shares (e.g. :func:`lane_distribution`'s): 1-D, finite, >= 0, each
    summing to 1; counts, percentages or a NaN are refused (they gave a distance above 1, or
    NaN, without a word)."""
    a, b = _distribution("p", p), _distribution("q", q)
    if a.shape != b.shape:
        raise ValueError(f"shapes differ: {a.shape} vs {b.shape}")
    return float(0.5 * np.abs(a - b).sum())


def _distribution(name: str, values: Sequence[float] | np.ndarray) -> np.ndarray:
    """``values`` as float64 [K], refused unless they are shares summing to 1."""
    try:
        v = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a sequence of shares, got {values!r:.60}") from None
    if v.ndim != 1 or v.size == 0 or not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ValueError(f"{name} must be a 1-D sequence of finite shares >= 0, got {values!r:.60}")
    if abs(v.sum() - 1.0) > 1e-6:
        raise ValueError(
            f"{name} must sum to 1 (shares, as lane_distribution gives), sums to {v.sum():g}: "
            "divide counts by their total, percentages by 100"
        )
    return v


def windowed_accuracy(correct: Sequence[bool] | np.ndarray, window: int = 150) -> np.ndarray:
    """Prediction accuracy over the last ``window`` steps (fewer at the start): float64 [T]."""
    if _as_int(window) is None or window < 1:
        raise ValueError(f"window must be an int >= 1, got {window!r}")
    c = _flags("correct", correct)
    cs = np.concatenate([[0.0], np.cumsum(c)])
    idx = np.arange(1, c.size + 1)
    lo = np.maximum(idx - window, 0)
    return (cs[idx] - cs[lo]) / (idx - lo)


def plot_accuracy(
    ax: Any,
    accuracy: Sequence[float] | np.ndarray,
    *,
    target: float | None = 0.8,
    label: str | None = None,
    marks: Sequence[int] = (),
) -> None:
    """Figures 6 and 9: windowed prediction accuracy against demonstration count."""
    acc = np.asarray(accuracy, dtype=np.float64)
    ax.plot(np.arange(1, acc.size + 1), 100 * acc, label=label)
    if target is not None:
        ax.axhline(100 * target, color="grey", ls="--", lw=0.8)
    for m in marks:
        ax.axvline(m, color="grey", ls=":", lw=0.8)
    ax.set_xlabel("demonstrations")
    ax.set_ylabel("prediction accuracy (%)")
    ax.set_ylim(0, 100)


def plot_lane_bars(
    ax: Any,
    labels: Sequence[str],
    distributions: Sequence[Sequence[float]],
    collision_rates: Sequence[float],
) -> None:
    """Figure 8: one stacked bar of lane shares per policy, collision % written beside it.

    ``distributions`` [P, 5] (lane shares per policy, as :func:`lane_distribution` gives) and
    ``collision_rates`` [P] (shares, not percent) go with the P ``labels``."""
    dist = np.asarray(distributions, dtype=np.float64)
    if dist.shape != (len(labels), N_LANES) or len(collision_rates) != len(labels):
        # one distribution too few was drawn for every label (broadcast), 3 lanes an IndexError
        raise ValueError(
            f"plot_lane_bars needs one distribution over the {N_LANES} lanes and one collision "
            f"rate per label: {len(labels)} labels, distributions of shape {dist.shape}, "
            f"{len(collision_rates)} collision rates"
        )
    y = np.arange(len(labels))[::-1]
    colors = ["#8c564b", "#ff7f0e", "#2ca02c", "#1f77b4", "#9467bd"]
    left = np.zeros(len(labels))
    for k in range(N_LANES):
        ax.barh(y, 100 * dist[:, k], left=left, color=colors[k], label=LANE_NAMES[k])
        left += 100 * dist[:, k]
    for yi, c in zip(y, collision_rates, strict=True):
        ax.text(102, yi, f"{100 * c:.1f}%", va="center", fontsize=8)
    ax.set_yticks(y)
    ax.set_yticklabels(labels, fontsize=8)
    ax.set_xlim(0, 115)
    ax.set_xlabel("time in lane (%)   |   collisions")
    ax.legend(fontsize=7, ncol=5, loc="upper center", bbox_to_anchor=(0.5, -0.18))


def plot_confidence_trace(
    ax: Any,
    distances: Sequence[float] | np.ndarray,
    contacts: Sequence[bool] | np.ndarray,
    *,
    threshold: float | None = 2.0,
    start: int = 0,
) -> None:
    """Figure 10: Mahalanobis distance of the best classification per timestep, contacts as
    squares (a larger distance = less confident); ``start`` is the first timestep's index."""
    d = np.asarray(distances, dtype=np.float64)
    c = _flags("contacts", contacts).astype(bool)  # a NaN was drawn as a contact
    if d.ndim != 1 or d.shape != c.shape:
        raise ValueError(
            f"distances and contacts need one entry per timestep each, got {d.shape} and {c.shape}"
        )
    t = start + np.arange(d.size)
    ax.plot(t, d, lw=0.8)
    ax.plot(t[c], d[c], "s", ms=4, mfc="none", color="red", label="contact")
    if threshold is not None:
        ax.axhline(threshold, color="grey", ls="--", lw=0.8)
    ax.set_xlabel("timestep")
    ax.set_ylabel("distance (std)")
    ax.legend(fontsize=7)
