"""Strategies: who asks and who acts, one small object per method.

The teaching loop (:class:`torchcbl.teaching.ConfidentTeacher`) asks two questions at every
step and leaves both to a *strategy*: do we ask the teacher for a label, and whose action is
executed? It tells the strategy of every label, every refit and every finished step, so the
strategy can keep whatever state it needs (a phase, a burst, thresholds, a beta schedule).
The loop owns everything else: the env, the teacher, the model and its refit schedule
(``TeachingConfig.max_new``), the training set, the records and the run directory.

The protocol (:class:`Strategy`), in the order the loop calls it::

    strategy.bind(n_actions=A, n_features=D, config=teaching_config)   # once per session
                                             # (new or resumed), before anything
    # on resume only: the log is replayed into the strategy, then one refit
    for record in log:                       # in step order
        if record.teacher_action is not None:
            strategy.observe_label(obs, label, model_action=..., kind="demonstration")
        for a correction of that step:
            strategy.observe_label(obs, label, model_action=..., kind="correction")
        strategy.observe_step(record, None)  # None: replayed, not live
    strategy.observe_refit(model, X, y)      # when the resumed model stands on labels (not
                                             # before the first refit, as in the live run)
    # every step
    strategy.episode_start()                 # after each env.reset
    d = strategy.decide(obs [D], c)          # c: the model's Classification, batch of 1
    if d.ask: label = teacher(obs, info)     # TeacherError / TeachingInterrupted: nothing
                                             # of this step happened, decide() is re-asked
    actor = strategy.actor(d, model_action, label)   # "teacher" or "agent"
    if d.ask: strategy.observe_label(obs, label, model_action=..., kind="demonstration")
    ... the label is on disk, THEN the action runs, then a refit when due:
    strategy.observe_refit(model, X, y)      # X [M, D], y [M]: the whole training set
    strategy.observe_step(record, d)         # the finished StepRecord (outcome included)
    if strategy.wants_corrections and not d.ask and the teacher corrects:  # autonomous steps
        strategy.observe_label(obs_then, label, model_action=..., kind="correction")
        (and a refit when due, with observe_refit)

Rules a strategy must keep:

- :meth:`Strategy.decide` is pure (it changes no state): the teacher may fail after it, and
  the loop then asks again. Put state changes in ``observe_step`` (it gets the decision back,
  with the strategy's own ``Decision.state``) and ``observe_label``.
- Ask whenever ``c.action[0] < 0`` (no model yet): ``actor`` "agent" needs a model action.
- ``actor`` returns ``"teacher"`` only for a step with a label; ``"agent"`` executes the
  model's action (DAgger may do so on a labelled step: a label is recorded either way).
- Resume must land in the same state as the live run: derive state from what
  ``observe_label`` / ``observe_step`` / ``observe_refit`` tell you, or from a seeded RNG that
  you advance in ``observe_step``; never from wall-clock time. Reset that state in ``bind``:
  a resume may be handed the live run's object, and replays the whole log into it.
- ``to_config()`` returns a JSON dict with ``"type"`` (the class name), every constructor
  argument and ``"relabel"``; the run directory stores it and :func:`strategy_from_config`
  rebuilds the strategy on resume (register a new class in ``STRATEGIES`` under that type,
  ``STRATEGIES["MyStrategy"] = MyStrategy``, in the process that resumes; it is called with
  the dict's other keys as keyword arguments). The ``"type"`` must name the strategy's own
  class: a session refuses to start with a class whose ``"type"`` names a ``STRATEGIES``
  entry that rebuilds another class (a class of one's own called ``DAgger``). Classes are
  compared by module and qualified name, so an object made before its module was reloaded
  (``importlib.reload``, IPython's autoreload) passes. A subclass
  of that class passes: one that keeps its parent's ``to_config`` (whose ``"type"`` names the
  parent) is stored as custom, its class named and the parent's dict kept under
  ``"inherited"``, as its rebuilt parent would go on teaching with the parent's behaviour:
  pass it again to ``resume``, or give it a ``to_config`` and a ``"type"`` of its own and
  register it. So is a confidence rule's subclass that keeps its parent's ``to_config``
  (pass ``rule=`` again). ``"relabel"`` must be the strategy's ``relabel``
  attribute (it may be left out when that is False): the session's readers relabel as the
  stored dict says, so a session refuses to start with a dict that misstates it (a
  TypeError, nothing written); a session stored before that check resumes with a warning
  naming both values. A strategy without
  ``to_config`` (or whose ``to_config`` returns None, as a subclass of :class:`Strategy` that
  does not define one) is stored as custom and must be passed again to ``resume``. A resume
  compares a custom dict by the last part of its class name (a class moved to another module
  still resumes), its relabel flag and, since 2026-11-27, the dicts it holds of a parent's
  ``to_config`` and of the rule (a custom rule by its class name too): a confidence rule of
  one's own without ``to_config`` that was renamed since the session was stored, which
  resumed before, is refused.

Subclassing a shipped strategy (:class:`ConfidentExecution`,
:class:`~torchcbl.strategies.cba.ConfidenceBasedAutonomy` and the baselines below): their
state (the phase schedule's accuracy window, phase and bursts; DAgger's step count, which
sets its beta and coins; HG-DAgger's label count and takeover; the novelty gate's window and
rescoring; confident execution's rule update and CBA's thresholds at each refit) is kept by
:class:`~torchcbl.teaching.ConfidentTeacher` where an override of ``observe_label``,
``observe_step`` or ``observe_refit`` never reaches the base hook (after it returns or
raises, with the loop's arguments), so an override adds behaviour and need not call
``super()``; where it calls ``super()``, the state is kept there, with the arguments it gives
(nothing is counted twice). To replace a refit's update (CBA's ``thresholds``), call
``super().observe_refit(...)`` first and set your own after it: without the call, the loop's
update after the hook overwrites yours. A loop of one's own that calls the public hooks gets
the state kept by theirs, and there an override must call ``super()``. An ``__init__`` or
``bind`` of one's own calls ``super()``; an ``__init__`` that does not call
``super().__init__(...)`` is a TypeError when the strategy is given to ConfidentTeacher or
``resume`` (or bound), naming it. To change when a strategy asks, override ``decide``.

Two attributes complete the protocol:

- ``relabel`` (bool): a label for an observation already in the training set (bit-for-bit
  equal) replaces that point's label instead of adding a point (CBA).
- ``wants_corrections`` (bool): after each autonomous step, the loop offers the teacher to
  correct it (see "Corrections" below).

The ``Decision.phase`` is recorded on the step (``StepRecord.phase``): ``"noninteractive"``
for steps on which the teacher is asked by design (a decision not to ask in it is a
RuntimeError, before anything of the step is recorded), ``"confident"`` for steps on which the
strategy decided. Only confident-phase steps count towards ``autonomy_rate`` and the
autonomous-episode stop.

Corrections (Confidence-Based Autonomy, Chernova & Veloso, JAIR 2009). A teacher may offer
the optional method ``teacher.correct(observation, info, action) -> int | None``: it is called
after an autonomous step with the observation and info the agent decided on and the action it
executed; it returns the action it should have taken, or None (or the same action) to let it
stand. A correction is a label for that earlier observation: it is journalled before the next
decision (durable like a demonstration), added to the training set and counted towards the
refit schedule. A scripted teacher corrects by comparing with its own choice (see
:func:`correcting`).

Shipped strategies:

- :class:`ConfidentExecution` (default): the paper's Algorithm 1 with its non-interactive
  phase and teacher bursts; asks when its confidence rule is not confident.
- :class:`~torchcbl.strategies.cba.ConfidenceBasedAutonomy`: JAIR 2009's per-boundary
  thresholds, nearest-neighbour distance gate, relabelling and corrections.

Baselines (for :mod:`torchcbl.benchmark`), one file each: :mod:`~torchcbl.strategies.bc`
(behaviour cloning), :mod:`~torchcbl.strategies.dagger` (DAgger, beta schedule),
:mod:`~torchcbl.strategies.hg_dagger` (teacher-gated HG-DAgger, through corrections),
:mod:`~torchcbl.strategies.novelty` (ThriftyDAgger-style novelty quantile gate).
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Literal, Protocol, runtime_checkable

import numpy as np

from torchcbl._signatures import refuse_unless_a_teacher
from torchcbl.confidence import (
    DistanceRule,
    _class_path,
    _inherited_from,
    _json_form,
    rule_from_config,
    rule_to_config,
)
from torchcbl.strategies._phased import Decision, LabelKind, _Phased, _rule_takes_observations

if TYPE_CHECKING:  # pragma: no cover
    from torchcbl.gmm import Classification
    from torchcbl.records import StepRecord

    # loaded by __getattr__ at run time, which a type checker cannot see through (without
    # this the name was Any to a user's mypy or pyright); "X as X" marks it re-exported
    from torchcbl.strategies.cba import ConfidenceBasedAutonomy as ConfidenceBasedAutonomy

__all__ = [
    "ConfidenceBasedAutonomy",
    "ConfidentExecution",
    "Decision",
    "STRATEGIES",
    "Strategy",
    "correcting",
    "strategy_from_config",
    "strategy_to_config",
]


@runtime_checkable
class Strategy(Protocol):
    """Decides, per step, whether to ask the teacher and whose action runs (see the module
    docstring for the call order and the rules)."""

    relabel: bool
    wants_corrections: bool

    def bind(self, *, n_actions: int, n_features: int, config: Any) -> None:
        """Called once per session (new or resumed) before any other method; ``config`` is the
        TeachingConfig. Start the strategy's state afresh here, not in ``__init__``: the same
        object may be passed to another session or to ``resume``, which replays the log into
        it."""
        ...

    def episode_start(self) -> None:
        """Called after each ``env.reset``."""
        ...

    def decide(self, observation: np.ndarray, c: Classification) -> Decision:
        """Pure: whether to ask at this observation [D] given its classification (batch 1)."""
        ...

    def actor(
        self, decision: Decision, model_action: int, teacher_action: int | None
    ) -> Literal["teacher", "agent"]:
        """Whose action is executed at this step."""
        ...

    def observe_label(
        self, observation: np.ndarray, action: int, *, model_action: int, kind: LabelKind
    ) -> None:
        """Every label, in arrival order. ``kind`` is ``"demonstration"`` (asked for at this
        step) or ``"correction"`` (for an earlier autonomous step's observation);
        ``model_action`` is the model's prediction at the labelled step (-1 without a model)."""
        ...

    def observe_refit(self, model: Any, observations: np.ndarray, actions: np.ndarray) -> None:
        """After every refit, with the whole training set ([M, D], [M])."""
        ...

    def observe_step(self, record: StepRecord, decision: Decision | None) -> None:
        """After every step's outcome; ``decision`` None when replayed from the log."""
        ...

    def to_config(self) -> dict[str, Any]:
        """JSON description (``"type"``, constructor arguments, ``"relabel"``)."""
        ...


class ConfidentExecution(_Phased):
    """Confident execution (Chernova & Veloso, AAMAS 2007, Algorithm 1): the default.

    Non-interactive phase and bursts as in the module docstring (their settings are the
    TeachingConfig's ``noninteractive``, ``target_accuracy``, ``accuracy_window``, ``burst``),
    then: ask when ``rule`` is not confident, execute the teacher's label when asked, the
    model's action otherwise. Learns from labels only; no relabelling, no corrections.

    Args:
        rule: a :class:`~torchcbl.confidence.ConfidenceRule`; default ``DistanceRule(2.0)``
            (the paper's). A rule whose ``is_confident`` takes a second positional argument
            gets the observations [N, D] too (a nearest-neighbour or density gate needs them).

    Hooks (what each does here; the call order is the module docstring's):

    - ``bind``: starts afresh from the TeachingConfig: phase ``"noninteractive"`` (
      ``"confident"`` with ``noninteractive=False``), an empty accuracy window of the last
      ``accuracy_window`` demonstrations, no burst; calls the rule's ``reset()`` where it has
      one.
    - ``episode_start``: cuts a burst short.
    - ``decide``: asks in the non-interactive phase and during a burst; else asks where no
      model exists (``c.action[0] < 0``) or the rule is not confident, and that request
      starts a burst of ``burst`` teacher moves (``Decision.state``: the burst's moves left).
      A RuntimeError before ``bind``.
    - ``actor``: the teacher on asked steps, the model otherwise.
    - ``observe_label``: a demonstration adds whether the model predicted it
      (``model_action == action``) to the accuracy window; a correction adds nothing.
    - ``observe_step``: counts a live burst down (cut at an episode's end); ends the
      non-interactive phase once the window is full and its accuracy reaches
      ``target_accuracy``; a replayed step (``decision`` None) recorded ``"confident"`` sets
      that phase.
    - ``observe_refit``: the rule's ``update(model, observations [M, D], actions [M])`` with
      the whole training set (an :class:`~torchcbl.confidence.AutoThresholdRule` sets its
      thresholds there, a quantile ``DistanceRule`` notes D).
    """

    _INIT_SETS = ("rule", "_with_obs")

    def __init__(self, rule: Any = None) -> None:
        super().__init__()
        self.rule = DistanceRule() if rule is None else rule
        if isinstance(self.rule, type):  # its methods are there, unbound: they would lack self
            raise TypeError(
                f"rule: expected a ConfidenceRule object, got the class {self.rule.__name__}; "
                f"pass an instance, e.g. {self.rule.__name__}()."
            )
        if not (
            callable(getattr(self.rule, "is_confident", None))
            and callable(getattr(self.rule, "update", None))
        ):
            raise TypeError(
                f"rule: expected a ConfidenceRule (is_confident and update), got {self.rule!r}"
            )
        self._with_obs = _rule_takes_observations(self.rule)

    def bind(self, *, n_actions: int, n_features: int, config: Any) -> None:
        """Starts the phase schedule afresh from ``config`` (a TeachingConfig) and calls the
        rule's ``reset()`` where it has one."""
        super().bind(n_actions=n_actions, n_features=n_features, config=config)
        reset = getattr(self.rule, "reset", None)
        if callable(reset):  # a rule reused from another session starts afresh
            reset()

    def _confident(self, observation: np.ndarray, c: Classification) -> bool:
        if self._with_obs:
            answer = self.rule.is_confident(c, observation[None])
        else:
            answer = self.rule.is_confident(c)
        try:
            return bool(answer[0])
        except (TypeError, IndexError, KeyError):  # a bool, a 0-d tensor or array: no rows
            raise TypeError(
                f"rule {self.rule!r}: is_confident() returned {answer!r:.80}; expected one bool "
                "per classified observation, a bool tensor [N] (the loop classifies one "
                "observation at a time: N = 1), e.g. `return c.distance <= 2.0`. Nothing was "
                "recorded for this step."
            ) from None

    def _track_refit(self, model: Any, observations: np.ndarray, actions: np.ndarray) -> None:
        """After every refit: the rule's ``update`` with the training set (``observations``
        [M, D], ``actions`` [M])."""
        self.rule.update(model, observations, actions)

    def to_config(self) -> dict[str, Any]:
        rule = rule_to_config(self.rule)
        out: dict[str, Any] = {"type": "ConfidentExecution", "rule": rule, "relabel": False}
        if rule.get("custom"):
            out["custom"] = True
        return out

    def __repr__(self) -> str:
        return f"ConfidentExecution(rule={self.rule!r})"


def __getattr__(name: str) -> Any:
    if name == "ConfidenceBasedAutonomy":  # lazily: cba imports this package's base class
        from torchcbl.strategies.cba import ConfidenceBasedAutonomy

        return ConfidenceBasedAutonomy
    raise AttributeError(f"module 'torchcbl.strategies' has no attribute {name!r}")


def strategy_to_config(strategy: Any, *, check_relabel: bool = True) -> dict[str, Any]:
    """JSON dict describing ``strategy``, as config.json reads back (numpy numbers as Python
    numbers, tuples as lists); one without ``to_config``, or whose ``to_config`` returns None
    (a subclass of :class:`Strategy` inherits the protocol's empty one), is named only
    (custom). A subclass that keeps its parent's ``to_config`` (whose ``"type"`` names the
    parent, not it) is custom too, its class named and the parent's dict kept under
    ``"inherited"``: rebuilt from that dict, a resume would go on with the parent.

    ``check_relabel=False`` skips the checks of ``"type"`` and ``"relabel"`` below: a resume
    compares the dict with a stored one, and a session stored before the checks may fail them.

    Raises:
        TypeError: ``to_config()`` returned something other than a dict or None, a dict
            JSON cannot hold, one whose ``"type"`` is not a string, or one whose
            ``"relabel"`` (false when absent) is not the
            strategy's ``relabel`` (a session's readers, ``load_demonstrations`` and
            ``load_model``, relabel as the stored dict says).
    """
    to_config = getattr(strategy, "to_config", None)
    config = to_config() if callable(to_config) else None
    if config is not None:
        name = type(strategy).__name__
        if not isinstance(config, Mapping):
            raise TypeError(
                f"{name}.to_config() returned {config!r:.80}; expected a "
                'JSON dict with "type" and the constructor arguments (see torchcbl.strategies), '
                "or None to store the strategy as custom (then pass it again to resume())."
            )
        if check_relabel and "type" in config and not isinstance(config["type"], str):
            raise TypeError(
                f'{name}.to_config() gives "type": {config["type"]!r:.80}; expected a string, '
                "the name the strategy is rebuilt and compared by on resume (e.g. "
                f'"type": {name!r}).'
            )
        relabel = bool(getattr(strategy, "relabel", False))
        if check_relabel and bool(config.get("relabel", False)) != relabel:
            given = repr(config["relabel"]) if "relabel" in config else "nothing"
            raise TypeError(
                f'{name}.to_config() gives "relabel": {given}, but {name}.relabel is '
                f"{relabel}; the session's readers relabel as the stored dict says, so it "
                f'would read another training set than the one taught: return "relabel": '
                f"{relabel} in to_config()."
            )
        config = _json_form(config, f"{name}.to_config()")
        if _inherited_from(strategy, config) is None:
            return config
    out = {
        "type": _class_path(strategy),
        "custom": True,
        "relabel": bool(getattr(strategy, "relabel", False)),
    }
    if config is not None:  # a subclass that keeps its parent's to_config: the parent's dict
        out["inherited"] = config
    return out


def _build_ce(params: dict[str, Any]) -> Any:
    rule = params.get("rule")
    if set(params) != {"rule"} or not isinstance(rule, Mapping):
        raise ValueError(
            f"cannot rebuild ConfidentExecution from {params!r:.200}: expected exactly "
            '"rule", a dict as rule_to_config() writes it (config.json was changed or '
            "damaged). Pass strategy=ConfidentExecution(<your rule>) to resume()."
        )
    return ConfidentExecution(rule_from_config(dict(rule)))


def _build_cba(params: dict[str, Any]) -> Any:
    from torchcbl.strategies.cba import ConfidenceBasedAutonomy

    return ConfidenceBasedAutonomy(**params)


def _lazy(module: str, name: str) -> Callable[[dict[str, Any]], Any]:
    def build(params: dict[str, Any]) -> Any:
        import importlib

        return getattr(importlib.import_module(module), name)(**params)

    build._builds = (module, name)  # type: ignore[attr-defined]
    return build


# the class each shipped builder function builds, as (module, name): checked without importing
_build_ce._builds = (__name__, "ConfidentExecution")  # type: ignore[attr-defined]
_build_cba._builds = ("torchcbl.strategies.cba", "ConfidenceBasedAutonomy")  # type: ignore[attr-defined]

#: name -> the strategy's class, called with the ``to_config`` dict's keys (without "type" and
#: "relabel") as keyword arguments; or a function, called with that dict (the shipped ones).
STRATEGIES: dict[str, Callable[..., Any]] = {
    "ConfidentExecution": _build_ce,
    "ConfidenceBasedAutonomy": _build_cba,
    # the baselines (issue 14), one file each
    "BehaviourCloning": _lazy("torchcbl.strategies.bc", "BehaviourCloning"),
    "DAgger": _lazy("torchcbl.strategies.dagger", "DAgger"),
    "HGDAgger": _lazy("torchcbl.strategies.hg_dagger", "HGDAgger"),
    "NoveltyGated": _lazy("torchcbl.strategies.novelty", "NoveltyGated"),
}


def _names(cls: type) -> tuple[str, str]:
    return cls.__module__, cls.__qualname__


def _check_rebuilt_as_itself(strategy: Any, config: Mapping[str, Any]) -> None:
    """Refuse, when a session starts, a strategy whose stored ``to_config`` ``"type"`` names a
    :data:`STRATEGIES` entry that would rebuild it (on a resume without ``strategy=``) as a
    class it is not an instance of: a user's class called ``DAgger`` describing itself as
    ``"DAgger"`` would resume as the shipped DAgger, with no word.

    An instance of the entry's class passes, and so does an instance of a subclass of it
    (``class Mine(DAgger)`` with a ``to_config`` of its own that names the parent: it resumes
    as its parent, as its ``to_config`` says; one that keeps the parent's ``to_config`` is
    stored as custom by :func:`strategy_to_config`, and does not reach this check); many such
    subclasses only add to the parent (a hook, a log), and refusing them would break them.
    A function a user registered under a name is not checked (what it
    builds is the user's choice), nor is a name not in STRATEGIES (its resume asks for
    ``strategy=``), nor a custom config (never rebuilt).

    Raises:
        TypeError: the entry builds another class; the message says what to rename.
    """
    if config.get("custom"):
        return
    kind = config.get("type")
    entry = STRATEGIES.get(str(kind))
    builds = entry if isinstance(entry, type) else getattr(entry, "_builds", None)
    if builds is None:
        return
    if isinstance(builds, tuple):  # a shipped builder: a module not imported yet holds no
        module, name = builds  # class the strategy could be an instance of
        builds = getattr(sys.modules.get(module), name, None)
        where = f"{module}.{name}"
    else:
        where = f"{builds.__module__}.{builds.__qualname__}"
    cls = type(strategy)
    if isinstance(builds, type) and (
        isinstance(strategy, builds)
        # or the class was reloaded since the instance was made (importlib.reload,
        # IPython's autoreload): the same module and qualified name is the same strategy
        or any(_names(c) == _names(builds) for c in cls.__mro__)
    ):
        return
    own = f"{cls.__module__}.{cls.__qualname__}"
    raise TypeError(
        f'{cls.__name__}.to_config() gives "type": {kind!r}, under which '
        f"torchcbl.strategies.STRATEGIES rebuilds {where}, and {own} is neither that class "
        "nor a subclass of it: a resume without strategy= would go on with another strategy. "
        f'Return a "type" of its own in to_config(), e.g. "type": {own!r}, and register it '
        f"where the session resumes (torchcbl.strategies.STRATEGIES[{own!r}] = "
        f"{cls.__qualname__}); or register {cls.__qualname__} under {kind!r} in STRATEGIES "
        "before the session starts."
    )


def strategy_from_config(config: dict[str, Any]) -> Any:
    """Rebuild a shipped (or registered) strategy from its ``to_config`` dict.

    Raises:
        ValueError: a custom strategy or rule (pass it to ``resume`` yourself), or an unknown
            type.
        TypeError: the rebuild raised one (the message names the call made: the class with
            the dict's keys as keyword arguments, or the function registered, with the dict),
            e.g. the class does not take the dict's keys as keyword arguments.
    """
    kind = config.get("type")
    if config.get("custom"):
        what = "rule" if kind == "ConfidentExecution" else "strategy"
        described = config.get("rule", config) if what == "rule" else config
        inherited = described.get("inherited") if isinstance(described, Mapping) else None
        if isinstance(inherited, Mapping):  # a subclass that keeps its parent's to_config
            own = str(described.get("type")).rpartition(".")[2]
            # a rule of one's own is never rebuilt (rule_from_config knows the shipped ones)
            other = (
                f"; or give {own} a to_config() of its own and register it in "
                "torchcbl.strategies.STRATEGIES, for the sessions it starts"
                if what == "strategy"
                else ""
            )
            raise ValueError(
                f"cannot rebuild the {what} {described.get('type')!r} from a run directory: "
                f"it keeps the to_config() of {inherited.get('type')!r}, whose dict would "
                f"rebuild that class, not {own}. Pass {what}={own}(...) to resume(), made as "
                f"the session made it{other}."
            )
        raise ValueError(
            f"cannot rebuild the custom {what} {config.get('rule', config)!r} from a run "
            f"directory. Pass {what}=<your {what}> to resume()."
        )
    build = STRATEGIES.get(str(kind))
    if build is None:
        raise ValueError(
            f"cannot rebuild strategy {kind!r} from a run directory: it is not one of "
            f"{sorted(STRATEGIES)}. Pass strategy=<your strategy> to resume(), or register "
            f"its class first: torchcbl.strategies.STRATEGIES[{kind!r}] = <your class>."
        )
    params = {k: v for k, v in config.items() if k not in ("type", "relabel")}
    try:
        if isinstance(build, type):  # a class registered as the module docstring says
            return build(**params)
        return build(params)
    except TypeError as exc:
        raise TypeError(_rebuild_failed(str(kind), build, params, exc)) from exc


def _rebuild_failed(
    kind: str, build: Callable[..., Any], params: dict[str, Any], exc: Exception
) -> str:
    """The message for a TypeError from ``STRATEGIES[kind]`` called with ``params``: the call
    made, and the advice on the keys only where the keys do not fit the constructor (not where
    the constructor refused a value, nor for a registered function, whose keys are its own)."""
    import inspect

    cls = build if isinstance(build, type) else None
    builds = getattr(build, "_builds", None)
    if cls is None and isinstance(builds, tuple):  # a shipped builder: imported by the call
        cls = getattr(sys.modules.get(builds[0]), builds[1], None)
    shown = f"{params!r:.200}"
    if build is _build_ce:
        call, cls = f"ConfidentExecution(rule_from_config({params.get('rule')!r:.200}))", None
    elif isinstance(cls, type):
        call = f"{cls.__name__}(**{shown})"
    else:
        name = getattr(build, "__name__", type(build).__name__)
        call = f"STRATEGIES[{kind!r}]({shown}) (the function {name}, given the dict)"
    keys_fit = True
    if isinstance(cls, type):
        try:
            inspect.signature(cls).bind(**params)
        except TypeError:
            keys_fit = False
        except ValueError:  # no signature to check against
            pass
    if not keys_fit:
        return (
            f"cannot rebuild strategy {kind!r} from a run directory as {call}: {exc}; the keys "
            'of its to_config() (other than "type" and "relabel") must be its constructor\'s '
            "keyword arguments. Pass strategy=<your strategy> to resume()."
        )
    return (
        f"cannot rebuild strategy {kind!r} from a run directory: {call} raised TypeError: "
        f"{exc}. Pass strategy=<your strategy> to resume()."
    )


class _Correcting:
    """A scripted teacher that also corrects (see :func:`correcting`); a module-level class, so
    that it pickles whenever the teacher it wraps does (a process pool's arguments)."""

    def __init__(self, inner: Callable[[np.ndarray, dict], int]) -> None:
        if not callable(inner):  # this wrapper is: the loop's check would pass it
            raise TypeError(
                f"correcting: expected a callable teacher(observation, info) -> action, got "
                f"{inner!r}"
            )
        # else it passed the loop's check (this wrapper's signature) and failed at the first
        # request
        refuse_unless_a_teacher(inner, "correcting", "correcting(lambda obs, info: policy(obs))")
        self.inner = inner

    def __call__(self, observation: np.ndarray, info: dict) -> int:
        return self.inner(observation, info)

    def correct(self, observation: np.ndarray, info: dict, action: int) -> int | None:
        inner_correct = getattr(self.inner, "correct", None)
        if callable(inner_correct):  # a teacher that corrects in its own way (HumanTiming)
            return inner_correct(observation, info, action)
        own = int(self.inner(observation, info))
        return None if own == int(action) else own

    def __repr__(self) -> str:
        return f"correcting({self.inner!r})"


def correcting(teacher: Callable[[np.ndarray, dict], int]) -> Any:
    """Wrap a scripted teacher so it also corrects: ``correct(obs, info, action)`` answers its
    own choice when that differs from ``action``, else None (a teacher with a ``correct`` of
    its own, such as :class:`~torchcbl.teachers.HumanTiming`, is asked through it). The
    wrapper pickles whenever ``teacher`` does. A teacher whose signature cannot take
    ``(observation, info)`` is a TypeError here."""
    return _Correcting(teacher)
