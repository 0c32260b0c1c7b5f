"""The paper's phase schedule shared by the shipped strategies, and the Decision type (private
module: import from :mod:`torchcbl.strategies`)."""

from __future__ import annotations

import inspect
from collections import deque
from typing import TYPE_CHECKING, Any, Literal, NamedTuple, get_args

import numpy as np

from torchcbl.confidence import _np

if TYPE_CHECKING:  # pragma: no cover
    from torchcbl.gmm import Classification
    from torchcbl.records import StepRecord

LabelKind = Literal["demonstration", "correction"]
_LABEL_KINDS: tuple[str, ...] = get_args(LabelKind)


class Decision(NamedTuple):
    """A strategy's answer for one step.

    Attributes:
        ask: ask the teacher for a label at this step.
        phase: ``"noninteractive"`` or ``"confident"``, recorded on the step.
        state: anything the strategy wants back in ``observe_step`` (the loop never reads it).
    """

    ask: bool
    phase: Literal["noninteractive", "confident"]
    state: Any = None


def _plain(value: Any) -> Any:
    """A numpy integer or float as the Python number it holds (np.int64(50), np.float32(0.5):
    accepted wherever an int or float is, and stored JSON-serialisable); anything else as is."""
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    return value


def _rule_takes_observations(rule: Any) -> bool:
    try:
        params = list(inspect.signature(rule.is_confident).parameters.values())
    except (TypeError, ValueError):
        return False
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    return len(positional) >= 2 or any(p.kind == p.VAR_POSITIONAL for p in params)


class _StrategyDefaults:
    """The protocol's defaults, for a strategy to override what it needs: remembers the
    problem's size in ``bind``, executes the teacher's action exactly on asked steps
    (``actor``), and ignores episode starts, labels, refits and finished steps.

    It also holds the two protections every shipped strategy shares against a subclass that
    skips ``super()``:

    - :meth:`_refuse_uninitialised`: a subclass ``__init__`` that skips ``super().__init__()``
      is refused (TypeError, naming it) when given to a session or bound, not steps later.
    - The shipped state lives in the private ``_track_label`` / ``_track_step`` /
      ``_track_refit``, which the public hooks call. ConfidentTeacher calls the hooks through
      ``_loop_label`` / ``_loop_step`` / ``_loop_refit``: where an override of a hook never
      reached the base hook (it once silently froze the schedule, DAgger's beta, the novelty
      window, CBA's thresholds), the loop keeps the state itself after the hook returns (or
      raises: the label or step is logged, and a resume counts it), with the loop's arguments;
      where it did, ``super()`` kept it, with the arguments the override gave it, at the moment
      the override chose.
    """

    relabel = False
    wants_corrections = False

    # what each shipped class's own __init__ sets (in its class body), checked by
    # _refuse_uninitialised: a subclass __init__ skipping super().__init__() lacks them
    _INIT_SETS: tuple[str, ...] = ()
    # None: no loop's call of that hook is under way; False / True: under way, and whether
    # the base hook ran in it
    _label_kept: bool | None = None
    _step_kept: bool | None = None
    _refit_kept: bool | None = None

    def _refuse_uninitialised(self) -> None:
        """TypeError where a shipped class's ``__init__`` was skipped (a subclass's
        ``__init__`` without ``super().__init__(...)``), which would otherwise fail steps later
        on an attribute the user never heard of."""
        for klass in type(self).__mro__:
            missing = [n for n in vars(klass).get("_INIT_SETS", ()) if not hasattr(self, n)]
            if missing:
                break
        else:
            return
        init = type(self).__init__
        owner = getattr(init, "__qualname__", "").rpartition(".")[0].rpartition(".")[2]
        try:
            args = ", ".join(
                p.name for p in list(inspect.signature(klass.__init__).parameters.values())[1:]
            )
        except (TypeError, ValueError):  # pragma: no cover - a shipped __init__ has one
            args = "..."
        if not owner or owner == klass.__name__:  # made without any __init__ (__new__)
            said = f"{klass.__name__}.__init__ was not run on this {type(self).__name__}"
            fix = f"Make it by calling {type(self).__name__}(...)."
        else:
            said = f"{owner}.__init__ did not call super().__init__(...)"
            fix = (
                f"Call super().__init__({args}) in {owner}.__init__ (with {klass.__name__}'s "
                "arguments), before setting attributes of its own."
            )
        raise TypeError(
            f"{said}: {klass.__name__}.__init__ sets up the strategy's state, which it lacks "
            f"({', '.join(missing)}), so it would fail steps into the session. {fix}"
        )

    def bind(self, *, n_actions: int, n_features: int, config: Any) -> None:
        """Once per session, before any other call (see the protocol): notes ``n_actions`` and
        ``n_features``. What a shipped strategy starts afresh here is under "Hooks" in its
        class docstring."""
        self._refuse_uninitialised()
        self.n_actions, self.n_features = int(n_actions), int(n_features)

    def episode_start(self) -> None:
        """After each ``env.reset``: nothing here (a shipped strategy's class docstring says
        under "Hooks" what it does)."""
        return None

    def actor(
        self, decision: Decision, model_action: int, teacher_action: int | None
    ) -> Literal["teacher", "agent"]:
        """``"teacher"`` on an asked step, ``"agent"`` otherwise."""
        return "teacher" if decision.ask else "agent"

    def _through_loop(self, hook: str, *args: Any, **kwargs: Any) -> None:
        """The loop's call of the public ``observe_<hook>``, then ``_track_<hook>`` with the
        loop's arguments where the hook did not reach the base one (also where it raised)."""
        flag = f"_{hook}_kept"
        setattr(self, flag, False)
        try:
            getattr(self, f"observe_{hook}")(*args, **kwargs)
        finally:
            kept = getattr(self, flag)
            setattr(self, flag, None)
            if not kept:
                getattr(self, f"_track_{hook}")(*args, **kwargs)

    def _reached(self, hook: str) -> None:
        """The base hook ran: a loop's call under way need not keep the state itself."""
        flag = f"_{hook}_kept"
        if getattr(self, flag) is False:
            setattr(self, flag, True)

    def _loop_label(
        self, observation: np.ndarray, action: int, *, model_action: int, kind: LabelKind
    ) -> None:
        """The loop's call of ``observe_label`` (see the class docstring)."""
        self._through_loop("label", observation, action, model_action=model_action, kind=kind)

    def _loop_step(self, record: StepRecord, decision: Decision | None) -> None:
        """The loop's call of ``observe_step`` (see the class docstring)."""
        self._through_loop("step", record, decision)

    def _loop_refit(self, model: Any, observations: np.ndarray, actions: np.ndarray) -> None:
        """The loop's call of ``observe_refit`` (see the class docstring)."""
        self._through_loop("refit", model, observations, actions)

    def _track_label(
        self, observation: np.ndarray, action: int, *, model_action: int, kind: LabelKind
    ) -> None:
        return None

    def _check_decide(self, observation: Any, c: Any) -> None:
        """ValueError unless ``observation`` is [D] (the bound ``n_features``) and ``c`` is the
        classification of one observation (batch 1): a [1, D] row failed inside numpy (CBA)
        or was taken (confident execution), and a second row of ``c`` was ignored. Runs every
        step, so it only reads shapes. Unbound (a baseline decides without ``bind``), any [D]."""
        shape = np.shape(observation)
        d = getattr(self, "n_features", None)
        if (shape != (d,)) if d is not None else len(shape) != 1:
            raise ValueError(
                f"{type(self).__name__}.decide: expected one observation of shape "
                f"({'D' if d is None else d},), got shape {tuple(shape)}; pass obs [D] (a row "
                "x[i], not x[i:i+1]) with c = model.classify(obs[None])."
            )
        n = np.shape(c.action)[:1]
        if n != (1,):
            raise ValueError(
                f"{type(self).__name__}.decide: expected c of batch 1 (the classification of "
                f"this one observation, model.classify(obs[None])), got a batch of "
                f"{n[0] if n else 0}; classify the observation alone."
            )

    def _check_label(self, action: Any, kind: Any) -> None:
        """ValueError for a ``kind`` that is no :data:`LabelKind` (a typo would silently leave
        the label uncounted) and, where bound (``n_actions`` known), an action outside
        [0, n_actions)."""
        name = type(self).__name__
        if kind not in _LABEL_KINDS:
            raise ValueError(
                f"{name}.observe_label: kind: expected one of {_LABEL_KINDS}, got {kind!r}; pass "
                "'demonstration' for a label asked for at its step, 'correction' for one that "
                "overrides an action already executed."
            )
        n = getattr(self, "n_actions", None)
        if n is None:
            return
        ok = isinstance(action, (int, np.integer)) and not isinstance(action, (bool, np.bool_))
        if not ok or not 0 <= action < n:
            raise ValueError(
                f"{name}.observe_label: action: expected an int in [0, {n}) (the n_actions "
                f"given to bind), got {action!r}; pass the teacher's action index."
            )

    def _track_step(self, record: StepRecord, decision: Decision | None) -> None:
        return None

    def _track_refit(self, model: Any, observations: np.ndarray, actions: np.ndarray) -> None:
        return None

    def observe_label(
        self, observation: np.ndarray, action: int, *, model_action: int, kind: LabelKind
    ) -> None:
        """Every label (see the protocol); keeps the shipped strategy's state (what that is,
        per strategy: "Hooks" in its class docstring). An override under ConfidentTeacher
        need not call ``super()``: where it does not, the loop keeps the state after it
        returns, with the loop's arguments; where it does, with the arguments it gives (a
        loop of one's own that calls the hooks needs the ``super()`` call).

        Raises:
            ValueError: ``kind`` is not ``"demonstration"`` or ``"correction"``, or, once
                bound, ``action`` is not an int in [0, n_actions).
        """
        self._check_label(action, kind)
        self._reached("label")  # first: where the update raises, the loop does not run it again
        self._track_label(observation, action, model_action=model_action, kind=kind)

    def observe_refit(self, model: Any, observations: np.ndarray, actions: np.ndarray) -> None:
        """After every refit, with the training set (``observations`` [M, D], ``actions``
        [M]); keeps the shipped strategy's state (per strategy: "Hooks" in its class
        docstring), under ConfidentTeacher also where an override does not call ``super()``,
        as :meth:`observe_label`."""
        self._reached("refit")  # first: where the update raises, the loop does not run it again
        self._track_refit(model, observations, actions)

    def observe_step(self, record: StepRecord, decision: Decision | None) -> None:
        """After every step (see the protocol); keeps the shipped strategy's state (per
        strategy: "Hooks" in its class docstring), under ConfidentTeacher also where an
        override does not call ``super()``, as :meth:`observe_label`."""
        self._reached("step")  # first: where the update raises, the loop does not run it again
        self._track_step(record, decision)


# the TeachingConfig fields the phase schedule reads in bind()
_SCHEDULE = ("noninteractive", "target_accuracy", "accuracy_window", "burst")


class _Phased(_StrategyDefaults):
    """The paper's schedule, shared by the shipped strategies: a non-interactive phase (the
    teacher acts every step) that ends once the windowed prediction accuracy reaches
    ``config.target_accuracy`` over ``config.accuracy_window`` demonstrations (never when
    it is None; skipped when ``config.noninteractive`` is False), then per-step decisions in
    which each request starts a burst of ``config.burst`` teacher moves (cut at the end of
    an episode). Subclasses say when they are confident (:meth:`_confident`)."""

    # what each shipped class's own __init__ sets (in its class body), checked by
    # _refuse_uninitialised: a subclass __init__ skipping super().__init__() lacks them
    _INIT_SETS = ("_phase", "_burst_left", "_window")
    _bound = False

    def __init__(self) -> None:
        self._phase: Literal["noninteractive", "confident"] = "noninteractive"
        self._burst_left = 0
        self._burst = 1
        self._target: float | None = None
        self._window: deque[bool] = deque(maxlen=1)
        self._bound = False

    @property
    def phase(self) -> str:
        """The phase of the next step."""
        return self._phase

    def bind(self, *, n_actions: int, n_features: int, config: Any) -> None:
        """Starts the schedule afresh from ``config`` (a TeachingConfig: its
        ``noninteractive``, ``target_accuracy``, ``accuracy_window`` and ``burst``); see
        "Hooks" in the class docstring.

        Raises:
            TypeError: ``config`` lacks those fields (None, a dict), or ``__init__`` was
                skipped.
        """
        self._refuse_uninitialised()
        missing = [n for n in _SCHEDULE if not hasattr(config, n)]
        if missing:  # a loop of one's own may pass None or a dict
            raise TypeError(
                f"{type(self).__name__}.bind: expected a TeachingConfig as config (its "
                f"{', '.join(_SCHEDULE)} set the phases), got {config!r:.80}, which lacks "
                f"{', '.join(missing)}; pass "
                "torchcbl.TeachingConfig() for the paper's schedule, or "
                "TeachingConfig(noninteractive=False) to decide from the first step."
            )
        self.n_actions, self.n_features = int(n_actions), int(n_features)
        self._phase = "noninteractive" if config.noninteractive else "confident"
        self._burst = int(config.burst)
        self._target = config.target_accuracy
        self._window = deque(maxlen=int(config.accuracy_window))
        self._bound = True

    def episode_start(self) -> None:
        """After each ``env.reset``: cuts a burst short."""
        self._burst_left = 0

    def _confident(self, observation: np.ndarray, c: Classification) -> bool:
        raise NotImplementedError

    def _require_bound(self, where: str) -> None:
        """RuntimeError naming ``where`` (the public method called) unless :meth:`bind` ran:
        unbound, the phase would never leave the non-interactive one, and CBA's refit lacks
        the number of actions. A strategy never initialised is told that first."""
        if self._bound:
            return
        self._refuse_uninitialised()
        raise RuntimeError(
            f"{type(self).__name__}.{where}: the strategy was not bound; call "
            "bind(n_actions=A, n_features=D, config=TeachingConfig(...)) once before it "
            "(ConfidentTeacher does; a loop of one's own must)."
        )

    def decide(self, observation: np.ndarray, c: Classification) -> Decision:
        """Pure: asks in the non-interactive phase and during a burst, else where no model
        exists or the strategy is not confident (a request starts a burst); see "Hooks" in
        the class docstring. ``observation`` [D], ``c`` its classification (batch of 1).

        Raises:
            RuntimeError: :meth:`bind` was not called.
            ValueError: ``observation`` is not of shape (n_features,), or ``c`` is not of
                batch 1.
        """
        self._require_bound("decide")
        self._check_decide(observation, c)
        if self._phase == "noninteractive" or self._burst_left > 0:
            return Decision(True, self._phase, self._burst_left)
        ask = int(_np(c.action)[0]) < 0 or not self._confident(observation, c)
        return Decision(ask, self._phase, self._burst if ask else 0)

    # The schedule's bookkeeping (the accuracy window, the phase, the burst) lives in
    # _track_label / _track_step, kept by the loop as _StrategyDefaults says.

    def _track_label(
        self, observation: np.ndarray, action: int, *, model_action: int, kind: LabelKind
    ) -> None:
        if kind == "demonstration":
            self._window.append(model_action == action)

    def _target_reached(self) -> bool:
        w, t = self._window, self._target
        return t is not None and len(w) == w.maxlen and sum(w) / len(w) >= t

    def _track_step(self, record: StepRecord, decision: Decision | None) -> None:
        if decision is None:  # replayed on resume; a resumed session starts a new episode
            if record.phase == "confident":
                self._phase = "confident"
        elif decision.ask:
            left = decision.state if isinstance(decision.state, int) else 0
            self._burst_left = max(left - 1, 0) if decision.phase == "confident" else 0
        if record.terminated or record.truncated:
            self._burst_left = 0
        if self._phase == "noninteractive" and self._target_reached():
            self._phase = "confident"
