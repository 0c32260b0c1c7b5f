"""Confidence-Based Autonomy (Chernova & Veloso, JAIR 2009) on a Gaussian mixture set.

The agent acts on its own only where two gates both pass:

1. **Classification confidence at its decision boundary.** For an observation o the model
   chooses a* = argmax_a p(a | o); the runner-up r = the second most probable action names the
   decision boundary (a*, r). The confidence is the log-posterior margin
   ``log p(a* | o) - log p(r | o)`` (>= 0; +inf when p(r | o) underflows to 0). The agent may
   act only if the margin EXCEEDS ``T[a*, r]``, a threshold kept per (predicted action,
   boundary) pair.
2. **Nearest-neighbour distance to the stored demonstrations.** On features standardised by
   the training set's mean and standard deviation, the Euclidean distance from o to its
   nearest stored demonstration must be BELOW ``distance_multiplier`` (1.5, as in the authors'
   reference implementation) times the mean leave-one-out nearest-neighbour distance of the
   stored demonstrations.

Thresholds are recomputed after every refit (resubstitution): every stored demonstration is
classified by the new model; ``T[a, b]`` is the mean margin of the demonstrations predicted
``a`` with runner-up ``b`` whose label is not ``a`` (the points misclassified at that
boundary). A pair at which demonstrations were classified but none misclassified gets
``clean_threshold`` (default 0: any positive margin is enough there; the reference
implementation computes 0/0 = NaN there and so asks forever); a pair no demonstration was
classified at keeps +inf, so the agent asks there (and its answer makes the pair known).

Learning: a demonstration for an observation already stored (bit-for-bit equal) relabels it
instead of adding a point (``relabel = True``); after each autonomous step the teacher may
correct the action just taken (``wants_corrections = True``, see :mod:`torchcbl.strategies`):
the correction relabels the observation at decision time, not the current one.

Like the shipped confident execution, the strategy honours the TeachingConfig's
non-interactive phase and bursts; JAIR 2009's CBA has no non-interactive phase, so set
``noninteractive=False`` to run it as published (every step asks until a model exists).
The state (thresholds, the stored set for the distance gate) is a pure function of the model
and training set at the last refit, so a resumed session recomputes it exactly.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from torchcbl.confidence import _np
from torchcbl.strategies._phased import _Phased, _plain

if TYPE_CHECKING:  # pragma: no cover
    from torchcbl.gmm import Classification

__all__ = ["ConfidenceBasedAutonomy", "loo_nn_distances", "posterior_margin"]

_STD_FLOOR = 1e-9


def posterior_margin(posterior: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(chosen [N], runner-up [N], margin [N]) of posteriors [N, A] (A >= 2).

    margin = log p(chosen) - log p(runner-up) >= 0, +inf when the runner-up's posterior is 0.
    """
    post = np.asarray(posterior, dtype=np.float64)
    if post.ndim != 2 or post.shape[1] < 2:
        raise ValueError(
            f"posterior_margin: expected posteriors [N, A] with A >= 2 actions, got shape "
            f"{post.shape}"
        )
    order = np.argsort(-post, axis=1, kind="stable")
    chosen, runner = order[:, 0], order[:, 1]
    rows = np.arange(len(post))
    with np.errstate(divide="ignore"):
        margin = np.log(post[rows, chosen]) - np.log(post[rows, runner])
    margin = np.where(np.isnan(margin), 0.0, margin)  # both 0: no information either way
    return chosen, runner, margin


_NN_BLOCK = 2048  # rows of the distance matrix at a time beyond this many points


def loo_nn_distances(x: np.ndarray) -> np.ndarray:
    """Leave-one-out nearest-neighbour Euclidean distance of each row of x [M, D] (M >= 2).

    Up to ``_NN_BLOCK`` points the [M, M] squared distances are formed at once; beyond, in
    blocks of that many rows, so that memory stays O(M) per row block (a one-shot matrix at
    10,000 demonstrations would take 0.8 GB, several times over for its temporaries).
    """
    sq = (x * x).sum(1)
    m = len(x)
    if m <= _NN_BLOCK:
        d2 = sq[:, None] + sq[None, :] - 2.0 * (x @ x.T)
        np.fill_diagonal(d2, np.inf)
        return np.sqrt(np.maximum(d2.min(1), 0.0))
    out = np.empty(m)
    for i in range(0, m, _NN_BLOCK):
        rows = slice(i, min(i + _NN_BLOCK, m))
        d2 = sq[rows, None] + sq[None, :] - 2.0 * (x[rows] @ x.T)
        k = np.arange(d2.shape[0])
        d2[k, i + k] = np.inf
        out[rows] = d2.min(1)
    return np.sqrt(np.maximum(out, 0.0))


class ConfidenceBasedAutonomy(_Phased):
    """Confidence-Based Autonomy (JAIR 2009): per-boundary thresholds and a nearest-neighbour
    distance gate; relabels stored states; learns from corrections (see the module docstring).

    Args:
        distance_multiplier: the distance gate is this multiple (> 0) of the mean leave-one-out
            nearest-neighbour distance of the stored demonstrations, on standardised features.
            Default 1.5 (the authors' reference implementation).
        clean_threshold: the margin threshold (>= 0, log-posterior units) of a (predicted
            action, runner-up) pair at which no stored demonstration is misclassified.
            Default 0.0.

    Attributes (after the first refit):
        thresholds: [A, A] float64, ``thresholds[a, b]`` for prediction a, runner-up b;
            +inf where no demonstration was classified.
        distance_threshold: the distance gate in standardised units (0 with < 2 points: ask).

    Hooks (what each does here; the call order is :mod:`torchcbl.strategies`'):

    - ``bind``: a ValueError with fewer than 2 actions; starts the phase schedule afresh from
      the TeachingConfig, as :class:`~torchcbl.strategies.ConfidentExecution`'s, and drops
      the gates (``thresholds`` None, ``distance_threshold`` 0: it asks until its first
      refit).
    - ``episode_start``: cuts a burst short.
    - ``decide``: asks in the non-interactive phase and during a burst; else asks where no
      model exists or either gate fails (the margin does not exceed ``thresholds[a*, r]``, or
      :meth:`nn_distance` is not below ``distance_threshold``), and that request starts a
      burst of ``burst`` teacher moves. A RuntimeError before ``bind``.
    - ``actor``: the teacher on asked steps, the model otherwise.
    - ``observe_label``: a demonstration adds whether the model predicted it to the accuracy
      window of the non-interactive phase; a correction adds nothing there.
    - ``observe_step``: counts a live burst down (cut at an episode's end) and ends the
      non-interactive phase once the window is full and its accuracy reaches
      ``target_accuracy``, as confident execution's.
    - ``observe_refit``: recomputes ``thresholds`` [A, A] (log-posterior margins) and
      ``distance_threshold`` (standardised units) from the whole training set
      (``observations`` [M, D], ``actions`` [M]) classified by the refitted model; a
      RuntimeError before ``bind``.
    """

    relabel = True
    wants_corrections = True

    _INIT_SETS = ("distance_multiplier", "clean_threshold")

    def __init__(self, distance_multiplier: float = 1.5, clean_threshold: float = 0.0) -> None:
        super().__init__()
        distance_multiplier, clean_threshold = _plain(distance_multiplier), _plain(clean_threshold)
        for name, v, ok, want in (
            ("distance_multiplier", distance_multiplier, lambda v: v > 0, "> 0"),
            ("clean_threshold", clean_threshold, lambda v: v >= 0, ">= 0"),
        ):
            if (
                isinstance(v, bool)
                or not isinstance(v, (int, float))
                or not math.isfinite(v)
                or not ok(v)
            ):
                raise ValueError(
                    f"ConfidenceBasedAutonomy.{name}: expected a finite number {want}, got {v!r}"
                )
        self.distance_multiplier = float(distance_multiplier)
        self.clean_threshold = float(clean_threshold)
        self.thresholds: np.ndarray | None = None
        self.distance_threshold = 0.0
        self._stored: np.ndarray | None = None  # standardised training set [M, D]
        self._stored_sq: np.ndarray | None = None  # its squared norms [M]
        self._mean: np.ndarray | None = None
        self._scale: np.ndarray | None = None

    def bind(self, *, n_actions: int, n_features: int, config: Any) -> None:
        """Starts the phase schedule afresh from ``config`` (a TeachingConfig) and drops the
        gates (``thresholds`` None: it asks until its first refit).

        Raises:
            ValueError: fewer than 2 actions.
        """
        if int(n_actions) < 2:
            raise ValueError(
                "ConfidenceBasedAutonomy needs at least 2 actions (its confidence is the margin "
                f"between the chosen action and the runner-up), got an env with {n_actions}; "
                "use ConfidentExecution for a single action."
            )
        super().bind(n_actions=n_actions, n_features=n_features, config=config)
        # a session (new or resumed) starts with no gates: they come from its own first refit,
        # never from another session this instance taught
        self.thresholds = None
        self.distance_threshold = 0.0
        self._stored = self._stored_sq = self._mean = self._scale = None

    # -- the two gates -----------------------------------------------------------------------

    def nn_distance(self, observation: np.ndarray) -> float:
        """Standardised distance from ``observation`` [D] to its nearest stored demonstration
        (+inf before the first refit)."""
        if self._stored is None:
            return math.inf
        z = (np.asarray(observation, dtype=np.float64) - self._mean) / self._scale
        d2 = float((self._stored_sq - 2.0 * (self._stored @ z)).min()) + float(z @ z)
        return math.sqrt(max(d2, 0.0))

    def _confident(self, observation: np.ndarray, c: Classification) -> bool:
        if self.thresholds is None:
            return False
        chosen = int(_np(c.action)[0])
        post = _np(c.posterior)[0].copy()
        p_chosen = float(post[chosen])
        post[chosen] = -1.0
        runner = int(post.argmax())
        p_runner = float(post[runner])
        if p_runner >= p_chosen:  # a tie: no margin
            return False
        margin = math.inf if p_runner <= 0.0 else math.log(p_chosen) - math.log(p_runner)
        if not margin > self.thresholds[chosen, runner]:
            return False
        return self.nn_distance(observation) < self.distance_threshold

    # -- learning ------------------------------------------------------------------------------

    def _track_refit(self, model: Any, observations: np.ndarray, actions: np.ndarray) -> None:
        """After every refit: the per-(action, runner-up) margin thresholds and the distance
        gate from the training set (``observations`` [M, D], ``actions`` [M]) classified by the
        refitted model."""
        self._require_bound("observe_refit")  # the thresholds are [n_actions, n_actions]
        x = np.asarray(observations, dtype=np.float64)
        y = np.asarray(actions, dtype=np.int64)
        c = model.classify(x)
        chosen, runner, margin = posterior_margin(_np(c.posterior))
        a = self.n_actions
        wrong = chosen != y
        total = np.zeros((a, a))
        count = np.zeros((a, a))
        seen = np.zeros((a, a), dtype=bool)
        seen[chosen, runner] = True
        finite = wrong & np.isfinite(margin)
        np.add.at(total, (chosen[finite], runner[finite]), margin[finite])
        np.add.at(count, (chosen[finite], runner[finite]), 1.0)
        thr = np.full((a, a), np.inf)
        thr[seen] = self.clean_threshold
        has = count > 0
        thr[has] = total[has] / count[has]
        # a pair with any misclassified point of infinite margin: never trust it
        inf_wrong = wrong & ~np.isfinite(margin)
        thr[chosen[inf_wrong], runner[inf_wrong]] = np.inf
        self.thresholds = thr
        self._mean = x.mean(0)
        scale = x.std(0)
        self._scale = np.where(scale > _STD_FLOOR, scale, 1.0)
        self._stored = (x - self._mean) / self._scale
        self._stored_sq = (self._stored * self._stored).sum(1)
        if len(x) >= 2:
            self.distance_threshold = self.distance_multiplier * float(
                loo_nn_distances(self._stored).mean()
            )
        else:
            self.distance_threshold = 0.0

    def to_config(self) -> dict[str, Any]:
        return {
            "type": "ConfidenceBasedAutonomy",
            "distance_multiplier": self.distance_multiplier,
            "clean_threshold": self.clean_threshold,
            "relabel": True,
        }

    def __repr__(self) -> str:
        return (
            f"ConfidenceBasedAutonomy(distance_multiplier={self.distance_multiplier}, "
            f"clean_threshold={self.clean_threshold})"
        )
