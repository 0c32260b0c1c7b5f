"""Record types of a teaching session: frozen dataclasses validated on creation.

A :class:`StepRecord` is one decision of the loop, whatever the strategy: what the agent saw,
what the model proposed and how sure it was, what the teacher said (if asked), what was
executed and who chose it (``actor``), and what the environment answered. The teacher's label
is stored apart from the executed action, so a demonstration is simply a step with a teacher
label, and a strategy may execute the agent's action on a labelled step (DAgger).

A :class:`CorrectionRecord` is a label that arrives after its step was executed (the teacher
overriding an autonomous action, Confidence-Based Autonomy's corrective demonstration): it
refers to that earlier step's observation, the state at decision time.

Records are built by the loop, :func:`torchcbl.policy.evaluate_policy` and the session store,
or by a loop of one's own (which may pass numpy / gymnasium values: they are stored as the
plain Python values the loop stores); a record that breaks an invariant raises
:class:`ValueError` at creation, so nothing inconsistent can reach the step log.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

_isfinite = math.isfinite

__all__ = [
    "ACTORS",
    "PHASES",
    "Actor",
    "CorrectionRecord",
    "Phase",
    "StepRecord",
    "jsonable_info",
    "training_set",
]

Phase = Literal["noninteractive", "confident", "evaluation"]
PHASES: tuple[str, ...] = ("noninteractive", "confident", "evaluation")
Actor = Literal["teacher", "agent"]
ACTORS: tuple[str, ...] = ("teacher", "agent")

_MAX_INFO_ARRAY = 64  # numpy arrays in info with at most this many elements are kept as lists


def _is_int(x: Any) -> bool:
    return isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_))


def _jsonable(value: Any) -> tuple[bool, Any]:
    """(keep, converted) for one info value; floats must be finite so the JSON stays standard."""
    if value is None or isinstance(value, (bool, str)):
        return True, value
    if isinstance(value, np.bool_):
        return True, bool(value)
    if _is_int(value):
        return True, int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return (True, v) if math.isfinite(v) else (False, None)
    if isinstance(value, np.ndarray):
        if value.size > _MAX_INFO_ARRAY:
            return False, None
        return _jsonable(value.tolist())
    if isinstance(value, (list, tuple)):
        out = []
        for item in value:
            keep, conv = _jsonable(item)
            if not keep:
                return False, None
            out.append(conv)
        return True, out
    if isinstance(value, Mapping):
        return True, jsonable_info(value)
    return False, None


def jsonable_info(info: Mapping[str, Any] | None) -> dict[str, Any]:
    """The JSON-able subset of an env's ``info`` dict.

    Kept: None, bool, int, str, finite floats, numpy scalars, small numpy arrays (at most 64
    elements, as lists), and lists / tuples / dicts made of those. Dropped: everything else
    (objects, large arrays, non-finite floats), so a step log always holds standard JSON.
    Keys are converted to ``str``.
    """
    if not info:
        return {}
    out: dict[str, Any] = {}
    for key, value in info.items():
        keep, conv = _jsonable(value)
        if keep:
            out[str(key)] = conv
    return out


@dataclass(frozen=True)
class StepRecord:
    """One step of a teaching session (or of a greedy evaluation).

    Attributes:
        step: index of the step in the session, from 0; consecutive across ``run`` calls and
            resumes.
        episode: index of the episode the step belongs to, from 0.
        observation: the observation the decision was made on, shape [D], finite floats.
        model_action: the model's classification (Eq. 7); -1 when there was no fitted model.
        confidence: ``exp(-distance**2 / 2)`` in [0, 1]; None when the policy gave no
            classification (a plain callable in :func:`~torchcbl.policy.evaluate_policy`).
        distance: Mahalanobis distance, in standard deviations, of the observation to the most
            likely component of the chosen mixture; ``inf`` before any model; None as above.
        posterior: p(a | o) for every action, shape [A]; None as above.
        teacher_action: the teacher's label, or None when the teacher was not asked.
        executed_action: the action sent to the environment.
        phase: ``"noninteractive"`` (the teacher is asked by design, e.g. the paper's first
            phase), ``"confident"`` (the strategy decides per step whether to ask) or
            ``"evaluation"``.
        autonomous: True when the teacher was not asked (no label) and the model's action ran.
        reward: the env's reward; None when the outcome was never observed (the env raised, or
            the process stopped after the demonstration was committed and before or while its
            action ran).
        terminated, truncated: the env's flags. A step whose outcome was lost is ``truncated``.
        info: JSON-able subset of the env's ``info`` after the step (see :func:`jsonable_info`);
            the loop adds ``"torchcbl_error"`` / ``"torchcbl_interrupted"`` keys when it had to
            cut an episode.
        n_demonstrations: labels in the session once this step's own label (if any) is
            counted: demonstrations plus corrections of earlier steps.
        autonomy_rate: share of autonomous steps among the last ``accuracy_window``
            confident-execution steps, this one included; None before confident execution.
        windowed_accuracy: share of the last ``accuracy_window`` demonstrations the model
            predicted correctly before learning them; None before any demonstration.
        actor: who chose ``executed_action``: ``"teacher"`` (it equals the label) or
            ``"agent"`` (it equals ``model_action``). Default (None at creation): ``"teacher"``
            when labelled, else ``"agent"`` (Algorithm 1's rule).

    Built by a loop of one's own, a record takes numpy values too and stores them as the plain
    values the teaching loop passes (so its log is the same): numpy integers in the int fields;
    numpy floats and ints (no bools) in the float fields; ``np.bool_`` in the bool fields; a
    1-D array or a list of numbers as ``observation`` / ``posterior`` (a tuple of floats).
    """

    step: int
    episode: int
    observation: tuple[float, ...]
    model_action: int
    confidence: float | None
    distance: float | None
    posterior: tuple[float, ...] | None
    teacher_action: int | None
    executed_action: int
    phase: Phase
    autonomous: bool
    reward: float | None
    terminated: bool
    truncated: bool
    info: dict[str, Any] = field(default_factory=dict)
    n_demonstrations: int = 0
    autonomy_rate: float | None = None
    windowed_accuracy: float | None = None
    actor: Actor | None = None

    def __post_init__(self) -> None:
        if self.actor is None:
            object.__setattr__(self, "actor", "agent" if self.teacher_action is None else "teacher")
        self._validate_decision()
        self._validate_outcome()
        _plain_ints(self, _STEP_INTS)

    def _plain_floats(self, names: tuple[str, ...]) -> None:
        for name in names:
            v = getattr(self, name)
            if v is not None and type(v) is not float:
                object.__setattr__(self, name, _as_float(v))

    def _bad(self, what: str, expected: str, got: Any) -> ValueError:
        return ValueError(
            f"StepRecord.{what}: expected {expected}, got {got!r} (step {self.step!r}); if you "
            f"built this record yourself, pass {expected}; from the teaching loop this points "
            "at a bug or a corrupted log."
        )

    def _validate_decision(self) -> None:
        bad = self._bad
        for name in ("step", "episode", "n_demonstrations"):
            v = getattr(self, name)
            if not _is_int(v) or v < 0:
                raise bad(name, "an int >= 0", v)
        obs = self.observation
        if type(obs) is not tuple or not all(type(x) is float for x in obs):
            obs = _float_tuple(obs)  # an array or list from a loop of one's own
            object.__setattr__(self, "observation", obs)
        if type(obs) is not tuple or not obs:
            raise bad("observation", "a non-empty tuple of floats", obs)
        for x in obs:
            if type(x) is not float or not _isfinite(x):
                raise bad("observation", "finite floats only", obs)
        if not _is_int(self.model_action) or self.model_action < -1:
            raise bad("model_action", "an int >= -1 (-1: no model)", self.model_action)
        self._plain_floats(_DECISION_FLOATS)
        conf, dist = self.confidence, self.distance
        if conf is not None and not (type(conf) is float and 0.0 <= conf <= 1.0):
            raise bad("confidence", "a float in [0, 1] or None", conf)
        if dist is not None and not (type(dist) is float and dist >= 0.0):  # rejects NaN too
            raise bad("distance", "a float >= 0 (inf allowed) or None", dist)
        post = self.posterior
        if post is not None and (
            type(post) is not tuple or not all(type(p) is float for p in post)
        ):
            post = _float_tuple(post)
            object.__setattr__(self, "posterior", post)
        if post is not None:
            if type(post) is not tuple:
                raise bad("posterior", "a tuple of floats in [0, 1] or None", post)
            for p in post:
                if type(p) is not float or not (0.0 <= p <= 1.0):
                    raise bad("posterior", "a tuple of floats in [0, 1] or None", post)
        if self.teacher_action is not None and (
            not _is_int(self.teacher_action) or self.teacher_action < 0
        ):
            raise bad("teacher_action", "an int >= 0 or None", self.teacher_action)
        if not _is_int(self.executed_action) or self.executed_action < 0:
            raise bad("executed_action", "an int >= 0", self.executed_action)
        if self.phase not in PHASES:
            raise bad("phase", f"one of {PHASES}", self.phase)
        if isinstance(self.autonomous, np.bool_):
            object.__setattr__(self, "autonomous", bool(self.autonomous))
        if type(self.autonomous) is not bool:
            raise bad("autonomous", "a bool", self.autonomous)
        if self.actor not in ACTORS:
            raise bad("actor", f"one of {ACTORS}", self.actor)
        if self.autonomous != (self.teacher_action is None):
            raise bad(
                "autonomous",
                "True exactly when the step has no teacher label",
                (self.teacher_action, self.autonomous),
            )
        if self.actor == "teacher":
            if self.teacher_action is None or self.executed_action != self.teacher_action:
                raise bad(
                    "actor",
                    "'teacher' only on a labelled step that executed the label",
                    (self.teacher_action, self.executed_action),
                )
        elif self.executed_action != self.model_action:
            raise bad(
                "actor",
                "'agent' only when the model's action was executed",
                (self.model_action, self.executed_action),
            )
        if self.phase == "noninteractive" and self.teacher_action is None:
            raise bad("teacher_action", "a label on every non-interactive step", None)
        for name in ("autonomy_rate", "windowed_accuracy"):
            v = getattr(self, name)
            if v is not None and not (type(v) is float and 0.0 <= v <= 1.0):
                raise bad(name, "a float in [0, 1] or None", v)

    def _validate_outcome(self) -> None:
        bad = self._bad
        if self.reward is not None and type(self.reward) is not float:
            object.__setattr__(self, "reward", _as_float(self.reward))
        for name in ("terminated", "truncated"):
            if isinstance(getattr(self, name), np.bool_):
                object.__setattr__(self, name, bool(getattr(self, name)))
        if self.reward is not None and not (type(self.reward) is float and _isfinite(self.reward)):
            raise bad("reward", "a finite float or None", self.reward)
        if type(self.terminated) is not bool:
            raise bad("terminated", "a bool", self.terminated)
        if type(self.truncated) is not bool:
            raise bad("truncated", "a bool", self.truncated)
        if type(self.info) is not dict:
            raise bad("info", "a dict", self.info)
        info = self.info
        if info and not all(  # plain values (most infos) need no encoding to be known good
            type(k) is str and type(v) in _PLAIN for k, v in info.items()
        ):
            try:
                json.dumps(info)
            except (TypeError, ValueError) as exc:  # here, not later in to_dict or the log
                raise bad("info", f"a dict JSON can hold ({exc})", info) from None

    def with_outcome(
        self, reward: float | None, terminated: bool, truncated: bool, info: dict[str, Any]
    ) -> StepRecord:
        """A copy with the env's answer filled in (only the new fields are re-validated)."""
        new = object.__new__(StepRecord)
        object.__setattr__(new, "__dict__", {**self.__dict__})
        for name, value in (
            ("reward", reward),
            ("terminated", terminated),
            ("truncated", truncated),
            ("info", info),
        ):
            object.__setattr__(new, name, value)
        new._validate_outcome()
        return new

    @property
    def is_demonstration(self) -> bool:
        """True when the step carries a teacher label (a training point)."""
        return self.teacher_action is not None

    @property
    def observation_array(self) -> np.ndarray:
        """The observation as a float64 array, shape [D]."""
        return np.asarray(self.observation, dtype=np.float64)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able dict (``distance`` inf is written as the string ``"inf"``)."""
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        d["observation"] = list(self.observation)
        d["posterior"] = None if self.posterior is None else list(self.posterior)
        if d["distance"] is not None and math.isinf(d["distance"]):
            d["distance"] = "inf"
        json.dumps(d)  # fail here, not in a consumer, if something slipped through
        return d


_PLAIN = (str, int, float, bool, type(None))
_STEP_INTS = (
    "step",
    "episode",
    "n_demonstrations",
    "model_action",
    "teacher_action",
    "executed_action",
)


_DECISION_FLOATS = ("confidence", "distance", "autonomy_rate", "windowed_accuracy")


def _as_float(v: Any) -> Any:
    """A numpy float or an int (no bool) as the plain float it holds; anything else as is,
    for the validation to refuse."""
    if isinstance(v, (float, np.floating)) or _is_int(v):
        try:
            return float(v)
        except OverflowError:
            return v
    return v


def _float_tuple(v: Any) -> Any:
    """A 1-D numeric array, or a list / tuple of numbers, as a tuple with plain floats where
    :func:`_as_float` makes them; anything else as is, for the validation to refuse."""
    if isinstance(v, np.ndarray):
        if v.ndim != 1 or v.dtype.kind not in "iuf":
            return v
        v = v.tolist()
    if isinstance(v, (list, tuple)):
        return tuple(_as_float(x) for x in v)
    return v


def _plain_ints(record: Any, names: tuple[str, ...]) -> None:
    """Store a validated numpy integer field as a Python int, so that the record goes through
    JSON (:meth:`StepRecord.to_dict`) and into the step log as one the loop builds."""
    for name in names:
        v = getattr(record, name)
        if v is not None and type(v) is not int:
            object.__setattr__(record, name, int(v))


@dataclass(frozen=True)
class CorrectionRecord:
    """A label for an earlier step: the teacher overrode an action the agent took on its own.

    Attributes:
        step: the step whose decision it corrects; its observation is the one relabelled.
        episode: that step's episode.
        observation: that step's observation (the state at decision time), shape [D].
        executed_action: the action the agent executed there.
        action: the teacher's corrected action for ``observation``.

    Built by a loop of one's own, a correction takes numpy values as :class:`StepRecord` does
    and stores the plain values the teaching loop passes: numpy integers (no bools) in the int
    fields; a 1-D array or a list / tuple of numbers (numpy floats too) as ``observation`` (a
    tuple of floats).
    """

    step: int
    episode: int
    observation: tuple[float, ...]
    executed_action: int
    action: int

    def __post_init__(self) -> None:
        def bad(name: str, expected: str, got: Any) -> ValueError:
            return ValueError(
                f"CorrectionRecord.{name}: expected {expected}, got {got!r} (step "
                f"{self.step!r}); if you built this record yourself, pass {expected}; from the "
                "teaching loop this points at a bug or a corrupted log."
            )

        for name in ("step", "episode", "executed_action", "action"):
            v = getattr(self, name)
            if not _is_int(v) or v < 0:
                raise bad(name, "an int >= 0", v)
        obs = self.observation
        if type(obs) is not tuple or not all(type(x) is float for x in obs):
            obs = _float_tuple(obs)  # an array or list from a loop of one's own
            object.__setattr__(self, "observation", obs)
        if (
            type(obs) is not tuple
            or not obs
            or not all(type(x) is float and _isfinite(x) for x in obs)
        ):
            raise bad("observation", "a non-empty tuple of finite floats", obs)
        if self.action == self.executed_action:
            raise bad(
                "action", f"another action than the executed {self.executed_action}", self.action
            )
        _plain_ints(self, ("step", "episode", "executed_action", "action"))

    @property
    def observation_array(self) -> np.ndarray:
        """The observation as a float64 array, shape [D]."""
        return np.asarray(self.observation, dtype=np.float64)


def training_set(
    xs: list[np.ndarray], ys: list[int], *, relabel: bool
) -> tuple[np.ndarray, np.ndarray]:
    """The training set a sequence of labels gives: observations [M, D] and actions [M].

    Without ``relabel`` every label is a point (the paper's confident execution). With it, a
    label for an observation already in the set (bit-for-bit equal) replaces that point's
    label (Confidence-Based Autonomy: "a demonstration in a stored state relabels it"), so M
    can be smaller than the number of labels.
    """
    if not ys:
        return np.zeros((0, 0), dtype=np.float64), np.zeros(0, dtype=np.int64)
    if not relabel:
        return np.stack(xs), np.asarray(ys, dtype=np.int64)
    ts = TrainingSet(relabel=True)
    for x, y in zip(xs, ys, strict=True):
        ts.add(x, y)
    return ts.arrays()


class TrainingSet:
    """The loop's growing training set (see :func:`training_set`); O(1) per label."""

    def __init__(self, *, relabel: bool) -> None:
        self.relabel = relabel
        self.x: list[np.ndarray] = []
        self.y: list[int] = []
        self._index: dict[bytes, int] = {}

    def add(self, x: np.ndarray, y: int) -> bool:
        """Add one label; returns False when it relabelled a stored point instead."""
        if self.relabel:
            key = np.ascontiguousarray(x, dtype=np.float64).tobytes()
            at = self._index.get(key)
            if at is not None:
                self.y[at] = int(y)
                return False
            self._index[key] = len(self.y)
        self.x.append(x)
        self.y.append(int(y))
        return True

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(observations [M, D] float64, actions [M] int64)."""
        if not self.y:
            return np.zeros((0, 0), dtype=np.float64), np.zeros(0, dtype=np.int64)
        return np.stack(self.x), np.asarray(self.y, dtype=np.int64)

    def __len__(self) -> int:
        return len(self.y)
