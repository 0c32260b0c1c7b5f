"""Confidence rules: when the agent acts on its own and when it asks the teacher.

A rule sees a batched :class:`~torchcbl.gmm.Classification` and the observations it was made
on, and answers, per observation, "confident enough to act autonomously?" (the
``conf > autonThresh`` test of Algorithm 1 in Chernova & Veloso, AAMAS 2007). A rule is a tool
that a strategy uses (:class:`torchcbl.strategies.ConfidentExecution` asks when its rule is not
confident). After every refit the strategy calls ``rule.update(model, X, y)`` with the whole
training set, so a rule may adapt its thresholds to the data; fixed rules ignore it. A rule
written before rules saw observations (``is_confident(c)`` only) still works: the strategy
passes the observations only to an ``is_confident`` that takes a second argument. A rule that
keeps state from its updates may have a ``reset()`` method: the strategy calls it when a
session starts (new or resumed), so a rule object reused in another session starts afresh.

Every rule is *never* confident before a model exists (``action == -1``): the agent asks the
teacher on every step until the first fit (Section 4.3).

Rules shipped here:

- :class:`DistanceRule` (default): confident when the observation lies within ``max_std``
  standard deviations (Mahalanobis distance) of the most likely component of the chosen
  mixture; the paper's corridor experiment used 2. ``DistanceRule(quantile=q)`` scales the
  threshold with the dimension: the chi-square quantile with D degrees of freedom.
- :class:`PosteriorRule`: confident when p(chosen action | o) >= ``min_posterior``; catches the
  overlap between actions that the distance rule cannot see.
- :class:`AutoThresholdRule`: per-action distance thresholds set from the data after each refit,
  in the style of Chernova & Veloso (JAIR 2009); see its docstring for the exact rule.

A rule serialises to a small JSON dict (``to_config``) so a run directory can rebuild it on
resume; :func:`rule_from_config` is the inverse.
"""

from __future__ import annotations

import json
import math
import operator
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Protocol, overload, runtime_checkable

import numpy as np
import torch

from torchcbl._text import counted
from torchcbl.gmm import Classification

if TYPE_CHECKING:  # pragma: no cover
    from torchcbl.gmm import GaussianMixtureSet

__all__ = [
    "AutoThresholdRule",
    "ConfidenceRule",
    "DistanceRule",
    "PosteriorRule",
    "chi2_quantile",
    "rule_from_config",
]


@runtime_checkable
class ConfidenceRule(Protocol):
    """Decides, per classified observation, whether the agent may act autonomously."""

    def is_confident(self, c: Classification, observations: Any = None) -> torch.Tensor:
        """Bool tensor [N]: True where the model's action may be executed without asking.
        ``observations`` [N, D] are the classified observations (None when not known)."""
        ...

    def update(self, model: GaussianMixtureSet, observations: Any, actions: Any) -> None:
        """Called after every refit with all demonstrations ([M, D] and [M]); may be a no-op."""
        ...


def _np(t: torch.Tensor | np.ndarray) -> np.ndarray:
    """A CPU numpy view (tiny tensors: numpy ops cost ~1 us, torch ops ~5 us); an array as is."""
    if isinstance(t, np.ndarray):
        return t
    try:
        return t.numpy()
    except (TypeError, RuntimeError):  # on an accelerator, or requires grad
        return t.numpy(force=True)


def _read(c: Any, rule: object, *names: str) -> tuple[Any, ...]:
    """The fields ``names`` of the classification ``c`` given to ``rule.is_confident``; a
    TypeError naming them where ``c`` lacks one. Any object with those fields is read (a
    custom model may answer with a look-alike of :class:`~torchcbl.gmm.Classification`)."""
    try:
        return operator.attrgetter(*names)(c)  # a tuple of the fields, for two or more
    except AttributeError:
        missing = [name for name in names if not hasattr(c, name)]
        if not missing:  # raised inside a property of c's own: its error, as it was
            raise
        raise TypeError(
            f"{rule!r}.is_confident: expected the model's Classification (fields "
            f"{', '.join(names)}) but got {type(c).__name__} {c!r:.60} without "
            f"{', '.join(missing)}; pass the answer of model.classify(observations)"
        ) from None


def _check_positive(name: str, value: float, *, upper: float | None = None) -> float:
    if (
        isinstance(value, (bool, np.bool_))
        or not isinstance(value, (int, float, np.integer, np.floating))
        or not math.isfinite(value)
    ):
        raise ValueError(f"{name}: expected a finite number, got {value!r}")
    if value <= 0 or (upper is not None and value > upper):
        rng = f"in (0, {upper}]" if upper is not None else "> 0"
        raise ValueError(f"{name}: expected a value {rng}, got {value!r}")
    return float(value)


def chi2_quantile(q: float, dof: int) -> float:
    """The ``q`` quantile of the chi-square distribution with ``dof`` degrees of freedom.

    Bisection on the regularised lower incomplete gamma function (``torch.special.gammainc``)
    until the bracket is 1e-13 of its upper end; no SciPy needed. Its precision is
    ``gammainc``'s: against SciPy's ``chi2.ppf``, relative errors of at most 5e-14 up to 10
    degrees of freedom and 2.3e-10 up to 1,000 (the largest at 41 degrees of freedom and
    q = 0.5; measured at q = 0.5 to 0.99). In the tails as well: above q = 0.999 the
    bisection compares the upper tail ``gammaincc`` with 1 - q (``gammainc`` rounds to 1 there),
    and a quantile under 2^-64 of dof + 10 (q = 1e-30 with 1 degree of freedom) is first
    bracketed by steps of 2^-64 (relative errors of at most 2e-11 measured at q = 1e-300 to
    1e-6 and 0.999 to 1 - 1e-15, 1 to 1,000 degrees of freedom).
    """
    if not 0.0 < q < 1.0:
        raise ValueError(f"chi2_quantile: expected q in (0, 1), got {q!r}")
    if isinstance(dof, bool) or not isinstance(dof, (int, np.integer)) or dof < 1:
        raise ValueError(f"chi2_quantile: expected an int dof >= 1, got {dof!r}")
    k = torch.tensor(dof / 2.0, dtype=torch.float64)

    upper, tail = q > _CHI2_UPPER_TAIL, 1.0 - q  # 1 - q is exact for q > 0.5

    def below(x: float) -> bool:
        """True where x lies below the quantile."""
        half = torch.tensor(x / 2.0, dtype=torch.float64)
        if upper:  # gammainc rounds to 1 - a few ulps there: compare the upper tail instead
            return float(torch.special.gammaincc(k, half)) > tail
        return float(torch.special.gammainc(k, half)) < q

    lo, hi = 0.0, float(dof) + 10.0
    while below(hi):
        hi *= 2.0
    while True:  # a tiny quantile: 200 halvings of [0, dof + 10] would not reach it
        smaller = hi * 2.0**-64
        if smaller == 0.0 or below(smaller):
            break
        hi = smaller
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if below(mid):
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-13 * hi:
            break
    return 0.5 * (lo + hi)


_CHI2_UPPER_TAIL = 0.999  # chi2_quantile: above this q, the upper tail is compared with 1 - q


class DistanceRule:
    """The paper's rule: confident when ``distance <= threshold``.

    ``distance`` is the Mahalanobis distance, in standard deviations, of the observation to the
    most likely component of the chosen action's mixture. Before any fit it is +inf, so the
    rule asks.

    A fixed threshold does not scale with the dimension D: a Gaussian's own points lie within
    2 standard deviations of its centre with probability 0.86 in 2-D, 0.59 in 4-D, 0.32 in
    6-D (the squared distance is chi-square with D degrees of freedom). So the threshold may
    be given as a ``quantile`` of that distribution instead: ``DistanceRule(quantile=0.95)``
    is confident inside the region holding 95 % of the component's own points, i.e.
    ``distance <= sqrt(chi2_quantile(0.95, D))`` (3.08 std in 4-D, 3.55 in 6-D). D is taken
    from the observations (or from the model at the first update).

    Args:
        max_std: fixed threshold in standard deviations (> 0). Default (None) 2.0, the
            paper's value.
        quantile: in (0, 1); when given, the threshold is the chi-square quantile above and
            ``max_std`` must not be given.

    Attributes:
        max_std: the fixed threshold in standard deviations, or None when ``quantile`` is
            given (the threshold then depends on D: :meth:`threshold`).
        quantile: the share given, or None for a fixed threshold.
    """

    # max_std or quantile, not both (a ValueError at run time): one overload each
    @overload
    def __init__(self, max_std: float | None = None, *, quantile: None = None) -> None: ...

    @overload
    def __init__(self, max_std: None = None, *, quantile: float) -> None: ...

    def __init__(self, max_std: float | None = None, *, quantile: float | None = None) -> None:
        given = max_std
        fixed = _check_positive("DistanceRule.max_std", 2.0 if max_std is None else max_std)
        self.max_std: float | None = fixed if quantile is None else None
        self.quantile: float | None = None
        self._thresholds: dict[int, float] = {}
        if quantile is not None:
            if given is not None:
                raise ValueError(
                    f"DistanceRule: give max_std ({max_std!r}) or quantile ({quantile!r}), "
                    "not both."
                )
            if (
                isinstance(quantile, (bool, np.bool_))
                or not isinstance(quantile, (int, float, np.integer, np.floating))
                or not 0.0 < float(quantile) < 1.0  # NaN too
            ):
                raise ValueError(
                    "DistanceRule.quantile: expected a share in (0, 1) (e.g. 0.95 for 95%), "
                    f"got {quantile!r}"
                )
            self.quantile = float(quantile)
        self._dof: int | None = None

    @classmethod
    def from_std(cls, max_std: float, reading: str = "literal") -> DistanceRule:
        """The paper's "``max_std`` standard deviations for the most likely Gaussian
        component" as a rule, read ``"literal"`` (a Mahalanobis distance of ``max_std``:
        ``DistanceRule(max_std)``) or as a ``"coverage"``: the share of a Gaussian's points
        within ``max_std`` standard deviations in one dimension (0.9545 for 2), taken as a
        chi-square quantile in the observations' D dimensions
        (``DistanceRule(quantile=erf(max_std / sqrt(2)))``: 2.83 std in 3-D, 3.12 in 4-D).

        Raises:
            ValueError: ``reading`` is neither, or ``max_std`` is not a finite number > 0 (or
                so large that its coverage rounds to 1).
        """
        if reading == "literal":
            return cls(max_std)
        if reading != "coverage":
            raise ValueError(
                f"DistanceRule.from_std: reading must be 'literal' or 'coverage', got {reading!r}"
            )
        _check_positive("DistanceRule.max_std", max_std)
        return cls(quantile=math.erf(float(max_std) / math.sqrt(2.0)))

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Unpickling: a quantile rule pickled before ``max_std`` became None with a quantile
        (c5f2f09) held ``max_std = 2.0`` too; it reads back as None, as documented."""
        self.__dict__.update(state)
        if self.__dict__.get("quantile") is not None:
            self.max_std = None

    def threshold(self, n_features: int | None = None) -> float:
        """The threshold in standard deviations (for D = ``n_features`` with a quantile).

        ``n_features``: the observations' feature count D, an int >= 1 (a fixed threshold
        does not depend on it); None for the D noted by :meth:`update` or read by
        :meth:`is_confident`.

        Raises:
            ValueError: ``n_features`` is not an int >= 1 (a float such as 2.7 is not
                truncated, a bool is no count), or D is not known yet.
        """
        if n_features is not None and (
            isinstance(n_features, (bool, np.bool_))
            or not isinstance(n_features, (int, np.integer))
            or n_features < 1
        ):
            raise ValueError(
                "DistanceRule.threshold: expected n_features as an int >= 1 (the observations' "
                f"feature count D), got {n_features!r}; pass the model's n_features"
            )
        if self.quantile is None:
            return float(self.max_std)  # type: ignore[arg-type]
        d = self._dof if n_features is None else int(n_features)
        if d is None:
            raise ValueError(
                "DistanceRule(quantile=...): the dimension D is not known yet; pass the "
                "observations to is_confident or call update(model, ...) first."
            )
        thr = self._thresholds.get(d)
        if thr is None:
            thr = self._thresholds[d] = math.sqrt(chi2_quantile(self.quantile, d))
        return thr

    def is_confident(self, c: Classification, observations: Any = None) -> torch.Tensor:
        """Bool tensor [N]: True where the model's action may be executed without asking
        (``c``: the model's :class:`Classification` of N observations; ``observations`` [N, D]
        when known, or one observation [D] for N = 1). A quantile rule reads D from the
        observations: a ValueError refuses observations of another shape. ``c`` may be any
        object with ``action`` and ``distance`` (a TypeError names those it lacks)."""
        c_action, c_distance = _read(c, self, "action", "distance")
        action = _np(c_action)
        if self.quantile is None:
            thr = float(self.max_std)  # type: ignore[arg-type]
        else:
            d = None if observations is None else self._features(observations, len(action))
            if d is None and self._dof is None and not (action >= 0).any():
                return torch.zeros(len(action), dtype=torch.bool)  # no model: ask anyway
            thr = self.threshold(d)
        ok = (_np(c_distance) <= thr) & (action >= 0)
        return torch.from_numpy(ok)

    def _features(self, observations: Any, n: int) -> int:
        """D of the ``observations`` given with a classification of ``n`` rows: [n, D], or one
        observation [D] for one row; any other shape is no classified observations (a 1-D
        model's [N] would read as D = N), a ValueError."""
        shape = np.shape(observations)
        if not ((len(shape) == 2 and shape[0] == n) or (len(shape) == 1 and n == 1)):
            raise ValueError(
                f"{self!r}.is_confident: expected the classified observations, shape [{n}, D], "
                f"but got shape {tuple(shape)}; pass the observations given to "
                "model.classify (their D sets the threshold)"
            )
        return int(shape[-1])

    def update(self, model: GaussianMixtureSet, observations: Any, actions: Any) -> None:
        """Called after every refit (``observations`` [M, D], ``actions`` [M]): notes the
        model's feature count D, which a quantile threshold needs."""
        n = getattr(model, "n_features", None)
        if n is not None:
            self._dof = int(n)

    def reset(self) -> None:
        """Forget the dimension noted by :meth:`update` (a session starts)."""
        self._dof = None

    def to_config(self) -> dict[str, Any]:
        if self.quantile is not None:
            return {"type": "DistanceRule", "quantile": self.quantile}
        return {"type": "DistanceRule", "max_std": self.max_std}

    def __repr__(self) -> str:
        if self.quantile is not None:
            return f"DistanceRule(quantile={self.quantile})"
        return f"DistanceRule(max_std={self.max_std})"


class PosteriorRule:
    """Confident when the posterior of the chosen action, p(a | o), is at least ``min_posterior``.

    The posterior compares only the actions the model has data for: while a single action has
    been demonstrated its posterior is 1 everywhere, and with two or more it is near 1 far
    from all of them. So this rule alone may stop asking after the first few labels of a
    session without a non-interactive phase, and it never asks for far-away states;
    :class:`DistanceRule` (the paper's) asks where the data is far.

    Args:
        min_posterior: threshold in (0, 1]. Default 0.9.
    """

    def __init__(self, min_posterior: float = 0.9) -> None:
        self.min_posterior = _check_positive(
            "PosteriorRule.min_posterior", min_posterior, upper=1.0
        )

    def is_confident(self, c: Classification, observations: Any = None) -> torch.Tensor:
        """Bool tensor [N]: True where the model's action may be executed without asking
        (``c``: the model's :class:`Classification` of N observations; ``observations`` [N, D]
        when known). ``c`` may be any object with ``action`` and ``posterior`` (a TypeError
        names those it lacks)."""
        c_action, c_posterior = _read(c, self, "action", "posterior")
        action = _np(c_action)
        post = _np(c_posterior)
        chosen = post[np.arange(len(action)), np.maximum(action, 0)]
        return torch.from_numpy((chosen >= self.min_posterior) & (action >= 0))

    def update(self, model: GaussianMixtureSet, observations: Any, actions: Any) -> None:
        """No state to update (``observations`` [M, D], ``actions`` [M])."""
        return None

    def to_config(self) -> dict[str, Any]:
        return {"type": "PosteriorRule", "min_posterior": self.min_posterior}

    def __repr__(self) -> str:
        return f"PosteriorRule(min_posterior={self.min_posterior})"


def _labels(actions: Any, n: int, n_actions: int) -> torch.Tensor:
    """The teacher's labels as a long tensor [n], checked: one integer in [0, n_actions) per
    observation (a label vector of another length would broadcast against the model's
    answers, or a float label be truncated, and the thresholds come out silently wrong)."""
    if isinstance(actions, torch.Tensor):
        y = actions.detach().cpu().numpy()
    else:
        y = np.asarray(actions)
    if y.dtype.kind not in "iu":  # a TypeError, as GaussianMixtureSet.fit says it
        from torchcbl.gmm import _conversion  # the same advice as fit's

        raise TypeError(
            f"AutoThresholdRule.update: expected actions as integer labels but got dtype "
            f"{y.dtype}; pass the labels the model was fitted on (convert with "
            f"{_conversion(actions, 'actions', 'int')})"
        )
    if y.shape != (n,):
        raise ValueError(
            f"AutoThresholdRule.update: expected actions as integer labels of shape [{n}] "
            f"(one per observation) but got shape {tuple(y.shape)}; pass the labels the model "
            "was fitted on"
        )
    bad = (y < 0) | (y >= n_actions)
    if bad.any():
        raise ValueError(
            f"AutoThresholdRule.update: expected labels in [0, {n_actions}) but got "
            f"{y[bad][0]!r} (row {int(np.flatnonzero(bad)[0])}); pass the labels the model "
            "was fitted on"
        )
    return torch.from_numpy(y.astype(np.int64))


class AutoThresholdRule:
    """Per-action distance thresholds set from the demonstrations after every refit.

    In the style of Chernova & Veloso (JAIR 2009, "Interactive policy learning through
    confidence-based autonomy"), where an action's threshold is the average confidence of the
    points the model misclassifies as that action; it is NOT that paper's rule (capped at
    ``max_std``, it can only ask more than :class:`DistanceRule`): the JAIR 2009 method is
    :class:`torchcbl.strategies.cba.ConfidenceBasedAutonomy`. The exact rule here, on the
    Mahalanobis distance:

    1. After each refit, classify every demonstration with the new model.
    2. For action ``a``, collect the distances of the demonstrations the model assigns to ``a``
       although the teacher labelled them otherwise (its confident mistakes).
    3. If there are any, ``threshold[a] = clip(mean(those distances), min_std, max_std)``;
       otherwise ``threshold[a] = max_std`` (nothing contradicts the paper's default there).
    4. Confident when ``distance < threshold[action]`` (strict: a mistake exactly at the mean
       distance is not trusted). Before the first update every threshold is ``max_std`` and the
       comparison is ``<=``, i.e. the rule behaves as :class:`DistanceRule` (``max_std``).

    The thresholds are a pure function of the model and the demonstrations, so a resumed
    session recomputes them exactly.

    Args:
        max_std: upper bound (and default) of every threshold, in standard deviations.
        min_std: lower bound of every threshold (>= 0); 0 lets an action whose region is full
            of mistakes ask on every step.
    """

    def __init__(self, max_std: float = 2.0, min_std: float = 0.0) -> None:
        self.max_std = _check_positive("AutoThresholdRule.max_std", max_std)
        if (
            isinstance(min_std, (bool, np.bool_))
            or not isinstance(min_std, (int, float, np.integer, np.floating))
            or not 0.0 <= float(min_std) <= self.max_std
        ):
            raise ValueError(
                f"AutoThresholdRule.min_std: expected a value in [0, max_std={self.max_std}], "
                f"got {min_std!r}"
            )
        self.min_std = float(min_std)
        self.thresholds: torch.Tensor | None = None  # [A] float64, None before the first update

    def is_confident(self, c: Classification, observations: Any = None) -> torch.Tensor:
        """Bool tensor [N]: True where the model's action may be executed without asking
        (``c``: the model's :class:`Classification` of N observations; ``observations`` [N, D]
        when known).

        Raises:
            TypeError: ``c`` lacks ``action`` or ``distance`` (any object with both is read).
            ValueError: the thresholds (set by :meth:`update`) are for another number of
                actions than the classification's model has (or a look-alike's action lies
                beyond them).
        """
        c_action, c_distance = _read(c, self, "action", "distance")
        action, distance = c_action.cpu(), c_distance.cpu()  # a CUDA model's answer too
        ok = action >= 0
        if self.thresholds is None:
            return (distance <= self.max_std) & ok
        n = len(self.thresholds)
        posterior = getattr(c, "posterior", None)  # [N, A]; a look-alike may have none
        given = posterior.shape[-1] if getattr(posterior, "ndim", 0) == 2 else None
        # the model's action count is the posterior's width; the library's Classification's
        # action, the posterior's argmax, lies below it, so only a look-alike's (a custom
        # model's own answer type: any action) or one without a posterior has its largest
        # action read (a tensor's max and its int() cost about 3 us, at every step)
        top = -1
        other = given is not None and given != n
        if not other and (given is None or type(c) is not Classification):
            top = int(action.max()) if len(action) else -1
            other = top >= n
        if other:
            has = given if given is not None and given != n else f"action {top}"
            raise ValueError(
                f"AutoThresholdRule.is_confident: its thresholds are for {counted(n, 'action')} "
                f"(set by update) but the classification has {has}; call rule.update(model, "
                "observations, actions) with the model that classified and its "
                "demonstrations, or rule.reset() to start again from max_std"
            )
        thr = self.thresholds.to(distance.dtype)[action.clamp(min=0)]
        return (distance < thr) & ok

    def update(self, model: GaussianMixtureSet, observations: Any, actions: Any) -> None:
        """Recompute the per-action thresholds from the training set (``observations``
        [M, D], ``actions`` [M]) classified by the refitted model.

        Raises:
            TypeError: ``actions`` are not integers (as :meth:`GaussianMixtureSet.fit`).
            ValueError: ``actions`` is not one label per observation, or holds a label
                outside ``[0, n_actions)``.
        """
        c = model.classify(observations)
        action, distance = c.action.cpu(), c.distance.cpu()  # a CUDA model's answer too
        n_actions = c.posterior.shape[1]
        labels = _labels(actions, len(action), n_actions)
        wrong = action != labels
        thr = torch.full((n_actions,), self.max_std, dtype=torch.float64)
        for a in range(n_actions):
            sel = wrong & (action == a) & torch.isfinite(distance)
            if bool(sel.any()):
                mean = float(distance[sel].double().mean())
                thr[a] = min(max(mean, self.min_std), self.max_std)
        self.thresholds = thr

    def reset(self) -> None:
        """Back to the state before the first update: every threshold ``max_std`` (a session
        starts; its thresholds come from its own refits, never another session's)."""
        self.thresholds = None

    def to_config(self) -> dict[str, Any]:
        return {"type": "AutoThresholdRule", "max_std": self.max_std, "min_std": self.min_std}

    def __repr__(self) -> str:
        return f"AutoThresholdRule(max_std={self.max_std}, min_std={self.min_std})"


_RULES = {"DistanceRule": DistanceRule, "PosteriorRule": PosteriorRule}


def _json_form(config: Any, what: str) -> dict[str, Any]:
    """``config`` (a rule's or strategy's ``to_config()``, named ``what``) as a run directory's
    config.json holds it and reads it back: numpy numbers as the Python numbers they hold,
    tuples as lists, so that a resumed session compares like with like. A value JSON cannot
    hold is a TypeError naming ``what``."""

    def plain(value: Any) -> Any:
        if isinstance(value, np.generic):  # np.float32(0.5), np.int64(3), np.True_
            return value.item()
        raise TypeError(f"{type(value).__name__} {value!r:.60} is not JSON")

    if not isinstance(config, Mapping):
        raise TypeError(
            f'{what} returned {config!r:.80}; expected a JSON dict with "type" and the '
            "constructor arguments"
        )
    try:
        return dict(json.loads(json.dumps(dict(config), default=plain)))
    except (TypeError, ValueError) as exc:
        raise TypeError(
            f"{what} returned {dict(config)!r:.120}, which a run directory's config.json cannot "
            f"hold ({exc}); return plain numbers, strings, lists and dicts with string keys "
            "(int(...) or float(...) of a numpy number)."
        ) from None


def _inherited_from(obj: Any, config: Mapping[str, Any]) -> type | None:
    """The class whose ``to_config`` ``obj`` inherits, where the dict it returned (``config``)
    does not name ``obj``'s own class: a subclass that kept a shipped class's ``to_config``,
    whose ``"type"`` would rebuild the parent on resume. None where the method is defined by
    ``obj``'s class (or set on ``obj``), or where its ``"type"`` names ``obj``'s class and
    not the defining one (a ``to_config`` written with ``type(self).__name__``)."""
    cls = type(obj)
    if "to_config" in getattr(obj, "__dict__", {}):
        return None
    owner = next((c for c in cls.__mro__ if "to_config" in vars(c)), None)
    if owner is None or owner is cls:
        return None
    kind = config.get("type")

    def names(c: type) -> tuple[str, ...]:
        return (c.__name__, c.__qualname__, f"{c.__module__}.{c.__qualname__}")

    if kind in names(cls) and kind not in names(owner):
        return None
    return owner


def _class_path(obj: Any) -> str:
    return f"{type(obj).__module__}.{type(obj).__qualname__}"


def rule_to_config(rule: Any) -> dict[str, Any]:
    """JSON dict describing ``rule``, as config.json reads back (numpy numbers as Python
    numbers, tuples as lists); a custom rule without ``to_config`` is named only.

    A subclass that keeps its parent's ``to_config`` (whose ``"type"`` names the parent, not
    it) is stored as custom too, its class named and the parent's dict kept under
    ``"inherited"``: rebuilt from that dict, it would be the parent, with the parent's
    ``is_confident``. Give it a ``to_config`` of its own to say otherwise.

    Raises:
        TypeError: ``to_config()`` returned no dict, or one JSON cannot hold.
    """
    to_config = getattr(rule, "to_config", None)
    if callable(to_config):
        config = _json_form(to_config(), f"{type(rule).__name__}.to_config()")
        if _inherited_from(rule, config) is not None:
            return {"type": _class_path(rule), "custom": True, "inherited": config}
        return config
    return {"type": _class_path(rule), "custom": True}


def rule_from_config(config: dict[str, Any]) -> ConfidenceRule:
    """Rebuild a shipped rule from :meth:`to_config` output.

    Raises:
        ValueError: for a custom rule (pass the rule object yourself) or an unknown type.
    """
    kind = config.get("type")
    params = {k: v for k, v in config.items() if k != "type"}
    if kind == "AutoThresholdRule":
        return AutoThresholdRule(**params)
    if kind in _RULES:
        return _RULES[kind](**params)
    raise ValueError(
        f"cannot rebuild confidence rule {kind!r} from a run directory: it is not one of "
        f"DistanceRule, PosteriorRule, AutoThresholdRule. Pass rule=<your rule> to resume()."
    )


def _check_std_reading(max_std: float, reading: str, readings: tuple[str, ...]) -> None:
    """An experiment config's check of its ``max_std`` and ``threshold_reading`` (``readings``:
    the config's, its default first), made when the config is built, not after a worker's
    teaching: the reading is one of them, and :meth:`DistanceRule.from_std` gives a rule.

    Raises:
        ValueError: naming the field and what was given.
    """
    if reading not in readings:
        raise ValueError(f"threshold_reading: expected one of {readings}, got {reading!r}")
    try:
        DistanceRule.from_std(max_std, reading)
    except ValueError as exc:
        raise ValueError(
            f"max_std = {max_std} gives no usable threshold with threshold_reading="
            f"{reading!r} ({exc})"
        ) from None
