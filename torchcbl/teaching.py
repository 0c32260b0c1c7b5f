"""The teaching loop: ConfidentTeacher (Chernova & Veloso, AAMAS 2007, Algorithm 1, and its
successors through a pluggable strategy).

The pieces are separate and swappable, as in imitation's DAgger: the *strategy* that decides
whether to ask and whose action runs (:mod:`torchcbl.strategies`; the default,
:class:`~torchcbl.strategies.ConfidentExecution`, is Algorithm 1 with a confidence rule from
:mod:`torchcbl.confidence`), the *teacher* (any callable ``teacher(obs, info) -> int``, with an
optional ``correct`` method), the *learner* (a :class:`~torchcbl.gmm.GaussianMixtureSet`) and
the *collector* (this loop, writing every step to a :class:`~torchcbl.records.StepRecord`
and, with ``run_dir``, to a durable session directory, :mod:`torchcbl.session`).

One step of the loop:

1. Classify the current observation with the current model (action, confidence, distance,
   posterior; before any fit: action -1, distance +inf).
2. The strategy decides whether to ask the teacher (default: always in the non-interactive
   phase and inside a teacher burst, else when the rule is not confident).
3. A teacher answer is a label: the model's prediction is scored against it (windowed
   prediction accuracy), it is committed to the log, and the model is refitted when
   ``config.max_new`` labels have accumulated since the last fit. The strategy says whose
   action is executed (default: the teacher's when asked, else the model's).
4. The step is recorded; with a strategy that wants corrections and a teacher that has
   ``correct``, the teacher may then relabel the observation the agent just acted on
   autonomously (a :class:`~torchcbl.records.CorrectionRecord`, durable before the next
   decision). An episode that ends is reset and teaching goes on. Only the first reset of a
   new session is seeded (with ``seed``); later resets continue the env's RNG. The first reset
   after :meth:`ConfidentTeacher.resume` is seeded from (seed, episode index); with ``seed``
   itself where the session logged no step yet, so that it starts as the new session did. An
   env that :func:`~torchcbl.policy.evaluate_policy` or another loop reset or stepped since
   this loop's last step no longer shows the observation the loop holds: the loop leaves its
   episode unfinished (as a resume does) and starts a new one, with a warning. (Stepping the
   env by hand between the loop's steps cannot be noticed: don't.)

The non-interactive phase ends after the step at which the accuracy window is full
(``accuracy_window`` demonstrations) and its accuracy is >= ``target_accuracy``; never when the
target is None; it is skipped when ``noninteractive=False``.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import hashlib
import json
import math
import os
import sys
import warnings
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import gymnasium as gym
import numpy as np
import torch

from torchcbl._checkpoints import DEFAULT_KEEP_CHECKPOINTS, is_keep_count
from torchcbl._signatures import refuse_unless_a_teacher
from torchcbl._text import counted
from torchcbl.confidence import _np, rule_to_config
from torchcbl.errors import (
    CorruptSessionError,
    EnvError,
    IncompatibleRunDirError,
    SessionWriteError,
    TeacherError,
    TeachingInterrupted,
)
from torchcbl.policy import (
    ActionAnswer,
    GreedyPolicy,
    _env_user,
    _note_env_user,
    as_action,
    check_env,
    evaluate_policy,
    obs_array,
    reset_answer,
    step_outcome,
)
from torchcbl.records import CorrectionRecord, StepRecord, TrainingSet, _is_int, jsonable_info
from torchcbl.session import (
    _MODEL_ARG_NAMES,
    _STOP_SETTINGS,
    FORMAT,
    PRIOR_FORMAT,
    PRIOR_NAME,
    STOP_FIELDS,
    Demonstrations,
    LabelDigest,
    SessionStore,
    _check_new_session_path,
    _check_restorable,
    _env_objects,
    _InterruptHold,
    _judged,
    _last_run_streaks,
    _last_writer_reading,
    _model_args,
    _names_a_session_format,
    _pair_digest,
    _read_prior,
    _streak_met,
    _warn_unrecorded_args,
    build_model,
    kept_checkpoints,
    label_sequence,
    latest_checkpoint,
    load_config,
    load_policy,
    observation_space_text,
    prior_bytes,
    restore_model,
    resume_problems,
    stored_strategy,
)
from torchcbl.strategies import (
    ConfidentExecution,
    Decision,
    _check_rebuilt_as_itself,
    strategy_from_config,
    strategy_to_config,
)
from torchcbl.strategies._phased import _StrategyDefaults

__all__ = [
    "ConfidentTeacher",
    "EnvError",
    "GreedyPolicy",
    "TeacherError",
    "TeachingConfig",
    "TeachingInterrupted",
    "evaluate_policy",
    "load_policy",
]

# an int action, or what as_action takes for one (a numpy integer, a 0-d array or tensor)
Teacher = Callable[[np.ndarray, dict[str, Any]], ActionAnswer]
# STOP_FIELDS, the stop criteria, and _STOP_SETTINGS, those plus the settings that only say
# when to stop (a resumed session and a run() call may change these; every other field is part
# of what the session learned with), are torchcbl.session's: describe() reads them too.
_NO_STOP = (
    "no stop criterion is set, so it would never end. TeachingConfig has no default stop (the "
    "paper ties it to its domains: the corridor stops after 10 consecutive autonomous circuits "
    "that succeed, autonomous_episodes_to_stop=10; the driving run after 650 demonstrations, "
    "max_demonstrations=650). Set at least one of {fields} in TeachingConfig or as run(...) "
    "arguments."
)


def _opt_int(name: str, value: Any, *, minimum: int, optional: bool = True) -> None:
    if value is None and optional:
        return
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        expected = f"None or an int >= {minimum}" if optional else f"an int >= {minimum}"
        raise ValueError(f"TeachingConfig.{name}: expected {expected}, got {value!r}")


@dataclass(frozen=True)
class TeachingConfig:
    """How the loop teaches and when it stops.

    The learning settings default to the paper's corridor setup. When to stop has no default
    (the paper ties it to its domains): give at least one stop criterion, here or to
    :meth:`ConfidentTeacher.run`, or ``run()`` refuses to start.

    Attributes:
        max_new: refit after this many new labels (>= 1): demonstrations, and corrections
            with a strategy that takes them. With ``refit="full"`` every refit fits on all the
            labels so far, so with ``max_new=1`` a session of N labels costs about N**2 / 2
            point-fits in all: it grows quadratically. The refit comes once ``max_new`` new
            labels have accumulated (``>=``), as Section 4.2's prose has it, "relearning the
            mixture parameters after maxNew new datapoints are obtained"; Algorithm 1 writes
            "if numNewDatapoints > maxNew", which would refit only at ``max_new + 1``. The
            paper names maxNew without a value: the default 1, a refit after each label, is
            its tightest reading (fine for the corridor's ~50); for long sessions (hundreds
            or thousands of labels) raise it, e.g. 10 for the driving domain's 650, which
            divides the total cost by about 10, or use ``refit="incremental"``. Requests are
            still decided with the latest fitted model.
        refit: "full" (default) fits the model from scratch at every refit, so it is a function
            of the labels alone; "incremental" uses ``GaussianMixtureSet.refit``: only the
            actions whose data changed are refitted, each candidate warm-started from its
            previous parameters, with a periodic from-scratch fit (about 1/11 to 1/16 of the
            refit time of a 10,000-demonstration session with max_new = 1 on an idle machine,
            the same quality: bench/bench_refit.py, README's speed table). The model then
            depends on the refit history as well.
        accuracy_window: number of most recent demonstrations the prediction accuracy is taken
            over (20 corridor, 150 driving); also the window of ``autonomy_rate``.
        target_accuracy: windowed accuracy in (0, 1] that ends the non-interactive phase;
            None = never switch.
        noninteractive: False starts directly in confident execution.
        burst: teacher moves per request in confident execution (10 in the driving domain).
        autonomous_steps_to_stop: stop after this many consecutive autonomous steps.
        autonomous_episodes_to_stop: stop after this many consecutive successful episodes of
            confident execution with no request. Success is never assumed: an episode succeeds
            when the env says so at its end (``info["is_success"]`` truthy), or, if the env
            does not say (no ``"is_success"`` key, or None), when it was cut by the time limit
            (``truncated``) and ``time_limit_is_success`` is True. An episode the env does not
            judge counts as a failure otherwise (a warning says so once). An env whose
            episodes end (``terminated``) on reaching their goal (gymnasium's MountainCar,
            Acrobot) says so with a wrapper setting ``info["is_success"] = terminated`` at
            each episode's end (the README's ``GoalIsSuccess``), which evaluations read too.
        max_demonstrations: stop when the session holds this many demonstrations (its own
            labels, as :attr:`ConfidentTeacher.n_demonstrations`: prior demonstrations do not
            count).
        max_steps: stop when the session holds this many steps.
        max_episodes: stop when the session holds this many finished episodes (ended by the
            env, terminated or truncated).
        time_limit_is_success: for envs that never set ``info["is_success"]`` and whose goal
            is to last until the time limit (CartPole, "drive 1000 steps" tasks): an episode
            that reaches its time limit (truncated, not terminated) counts as a success for
            ``autonomous_episodes_to_stop``, a terminated one as a failure. Not for an env
            whose episodes end (terminated) at their goal (above). Default False.

    The stop fields count over the whole session for the three budgets and within one
    ``run`` call for the two streaks; ``run(**overrides)`` may change them (and
    ``time_limit_is_success``) per call, and a resumed session may use other values. A
    resumed session that had met a streak of its config before it was stopped takes no step
    (see :meth:`ConfidentTeacher.run`).
    """

    max_new: int = 1
    refit: Literal["full", "incremental"] = "full"
    accuracy_window: int = 20
    target_accuracy: float | None = 0.9
    noninteractive: bool = True
    burst: int = 1
    autonomous_steps_to_stop: int | None = None
    autonomous_episodes_to_stop: int | None = None
    max_demonstrations: int | None = None
    max_steps: int | None = None
    max_episodes: int | None = None
    time_limit_is_success: bool = False

    def __post_init__(self) -> None:
        # numpy scalars (np.int64(10), np.float32(0.9), np.True_) are taken as the Python
        # numbers and bools they hold, so that the config stays JSON-serialisable in a run
        # directory (a bool stays refused where a number is expected)
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.bool_):
                object.__setattr__(self, f.name, bool(v))
            elif isinstance(v, np.integer):
                object.__setattr__(self, f.name, int(v))
            elif isinstance(v, np.floating):
                object.__setattr__(self, f.name, float(v))
        _opt_int("max_new", self.max_new, minimum=1, optional=False)
        if self.refit not in ("full", "incremental"):
            raise ValueError(
                f"TeachingConfig.refit: expected 'full' or 'incremental', got {self.refit!r}"
            )
        _opt_int("accuracy_window", self.accuracy_window, minimum=1, optional=False)
        _opt_int("burst", self.burst, minimum=1, optional=False)
        if self.target_accuracy is not None and (
            isinstance(self.target_accuracy, bool)
            or not isinstance(self.target_accuracy, (int, float))
            or not 0.0 < self.target_accuracy <= 1.0
        ):
            raise ValueError(
                "TeachingConfig.target_accuracy: expected None or a number in (0, 1], "
                f"got {self.target_accuracy!r}"
            )
        if not isinstance(self.noninteractive, bool):
            raise ValueError(
                f"TeachingConfig.noninteractive: expected a bool, got {self.noninteractive!r}"
            )
        for name in STOP_FIELDS:
            _opt_int(name, getattr(self, name), minimum=1 if "autonomous" in name else 0)
        if not isinstance(self.time_limit_is_success, bool):
            raise ValueError(
                "TeachingConfig.time_limit_is_success: expected a bool, got "
                f"{self.time_limit_is_success!r}"
            )

    def learning_fields(self) -> dict[str, Any]:
        """The fields a resumed session must share with its run directory (not the stops)."""
        return {
            f.name: getattr(self, f.name)
            for f in dataclasses.fields(self)
            if f.name not in _STOP_SETTINGS
        }


# every method the loop calls on a strategy (torchcbl.strategies' protocol)
_STRATEGY_METHODS = (
    "bind",
    "episode_start",
    "decide",
    "actor",
    "observe_label",
    "observe_refit",
    "observe_step",
)


def _warn_misstated_relabel(stored: dict[str, Any], strategy: Any) -> None:
    """Warn where a resumed session's stored ``"relabel"`` is not the strategy's (a session
    made before ``strategy_to_config`` refused that): the loop relabels as the strategy says,
    the session's readers as the stored dict says."""
    relabel = bool(getattr(strategy, "relabel", False))
    if bool(stored.get("relabel", False)) != relabel:
        warnings.warn(
            f'this session\'s config.json stores "relabel": {bool(stored.get("relabel"))} '
            f"for its strategy, but {type(strategy).__name__}.relabel is {relabel}: the loop "
            "relabels as the strategy says, while load_demonstrations and load_model read "
            "this session as the stored value says (another training set). To read it as "
            "taught, start a new session with a to_config() that states relabel truly.",
            UserWarning,
            stacklevel=3,
        )


def _tell_label(strategy: Any, *args: Any, **kwargs: Any) -> None:
    """``strategy.observe_label``; a shipped strategy's state is kept by the loop where an
    override never reaches the base hook (also where it raised), so that a subclass overriding
    the hook without ``super()`` still leaves the non-interactive phase (or DAgger's warmup,
    ...)."""
    if isinstance(strategy, _StrategyDefaults):
        strategy._loop_label(*args, **kwargs)
    else:
        strategy.observe_label(*args, **kwargs)


def _tell_step(strategy: Any, record: StepRecord, decision: Decision | None) -> None:
    """``strategy.observe_step``, with a shipped strategy's state kept as above."""
    if isinstance(strategy, _StrategyDefaults):
        strategy._loop_step(record, decision)
    else:
        strategy.observe_step(record, decision)


def _tell_refit(strategy: Any, model: Any, x: np.ndarray, y: np.ndarray) -> None:
    """``strategy.observe_refit``, with a shipped strategy's state (a rule's update, CBA's
    thresholds, the novelty scores) kept as above."""
    if isinstance(strategy, _StrategyDefaults):
        strategy._loop_refit(model, x, y)
    else:
        strategy.observe_refit(model, x, y)


def _pick_strategy(rule: Any, strategy: Any) -> Any:
    if rule is not None and strategy is not None:
        raise ValueError(
            "give either rule= (confident execution with that rule) or strategy=, not both; "
            "for confident execution with a rule, pass strategy=ConfidentExecution(rule)."
        )
    if strategy is None:
        return ConfidentExecution(rule)
    if isinstance(strategy, type):  # its methods are there, unbound: bind() would lack self
        raise TypeError(
            f"strategy: expected a strategy object, got the class {strategy.__name__}; pass an "
            f"instance, e.g. strategy={strategy.__name__}()."
        )
    for name in _STRATEGY_METHODS:
        if not callable(getattr(strategy, name, None)):
            raise TypeError(
                f"strategy: expected a torchcbl.strategies.Strategy (methods "
                f"{', '.join(_STRATEGY_METHODS)}), got {strategy!r} without {name}(); see "
                "the protocol in torchcbl.strategies (an episode_start that does nothing is "
                "`def episode_start(self): pass`)."
            )
    if isinstance(
        strategy, _StrategyDefaults
    ):  # a subclass whose __init__ skipped super().__init__()
        strategy._refuse_uninitialised()
    return strategy


def _is_fitted(model: Any) -> bool:
    return bool(getattr(model, "is_fitted", False))


def _model_device(model: Any) -> str:
    """The device of the model's first buffer or parameter ("cpu" without one)."""
    for tensor in (*getattr(model, "buffers", tuple)(), *getattr(model, "parameters", tuple)()):
        return str(tensor.device)
    return "cpu"


def _seed_for(seed: int, episode: int) -> int:
    return int(np.random.SeedSequence([seed, episode]).generate_state(1)[0])


def _make_kwargs(env: gym.Env) -> Mapping[str, Any]:
    """What ``gymnasium.make`` was given for ``env``, as given (its spec's kwargs, objects
    whole); empty for an env not made by ``gymnasium.make``."""
    return getattr(getattr(env, "spec", None), "kwargs", None) or {}


def _env_kwargs(env: gym.Env) -> dict[str, Any]:
    """What ``gymnasium.make`` was given for ``env`` (its spec's kwargs): a path
    (``os.PathLike``, a ``pathlib.Path`` say) as the str it names, a value JSON cannot hold as
    ``{"repr": ...}``; empty for an env not made by ``gymnasium.make``."""
    kwargs = _make_kwargs(env)

    def kept(v: Any) -> Any:
        if isinstance(v, os.PathLike) and isinstance(os.fspath(v), str):
            return os.fspath(v)  # make() reads the str as it read the path
        return v if _jsonable(v) else {"repr": repr(v)[:200]}

    return {str(k): kept(v) for k, v in kwargs.items()}


def _call_env_hook(unwrapped: Any, name: str, cannot: str) -> Any:
    """``unwrapped.<name>()`` (an env's describe hook), its exception an :class:`EnvError`
    saying ``cannot`` and that nothing was changed (the exception is the cause)."""
    try:
        return getattr(unwrapped, name)()
    except Exception as exc:
        raise EnvError(
            f"{type(unwrapped).__name__}.{name}() raised {type(exc).__name__}: {exc} "
            f"({cannot}; nothing was changed)"
        ) from exc


def _env_inputs(env: gym.Env) -> dict[str, Any] | None:
    """What the unwrapped env's ``describe_inputs()`` says identifies what it reads beyond its
    ``gymnasium.make`` arguments (a map file's digest, say), or None for an env without one.

    Raises:
        TypeError: ``describe_inputs()`` gave something other than a dict of str keys and
            plain JSON values (str, int, float, bool, None).
        EnvError: ``describe_inputs()`` raised (its exception is the cause).
    """
    unwrapped = getattr(env, "unwrapped", env)
    if not callable(getattr(unwrapped, "describe_inputs", None)):
        return None
    inputs = _call_env_hook(
        unwrapped, "describe_inputs", "what the env reads, e.g. a file, cannot be described now"
    )

    def plain(v: Any) -> bool:  # what JSON keeps and gives back equal (no NaN: NaN != NaN)
        if isinstance(v, float):
            return math.isfinite(v)
        return v is None or type(v) in (str, int, bool)

    if not (
        isinstance(inputs, dict) and all(isinstance(k, str) and plain(v) for k, v in inputs.items())
    ):
        raise TypeError(
            f"{type(unwrapped).__name__}.describe_inputs() must return a dict of str keys and "
            f"plain JSON values (str, int, a finite float, bool or None), got {inputs!r}; "
            "return e.g. {'my_file_sha256': hashlib.sha256(data).hexdigest()}"
        )
    return {k: float(v) if isinstance(v, float) else v for k, v in inputs.items()}


def _env_versions(env: gym.Env) -> dict[str, str] | None:
    """What the unwrapped env's ``describe_versions()`` says it runs on (a simulator and its
    bindings, each by name: ``{"sumo": "1.28.0"}``), or None for an env without one.

    Raises:
        TypeError: ``describe_versions()`` gave something other than a dict of str keys and
            str values.
        EnvError: ``describe_versions()`` raised (its exception is the cause).
    """
    unwrapped = getattr(env, "unwrapped", env)
    if not callable(getattr(unwrapped, "describe_versions", None)):
        return None
    versions = _call_env_hook(
        unwrapped, "describe_versions", "what the env runs on cannot be told now"
    )
    if not (
        isinstance(versions, dict)
        and all(type(k) is str and type(v) is str for k, v in versions.items())
    ):
        raise TypeError(
            f"{type(unwrapped).__name__}.describe_versions() must return a dict of str keys "
            f"and str values (what the env runs on, each with its version), got {versions!r}; "
            "return e.g. {'mysim': importlib.metadata.version('mysim')}"
        )
    return dict(versions)


def _warn_changed_versions(
    run_dir: Path, previous: Any, versions: dict[str, str] | None, first_step: int
) -> None:
    """Warn where the env of a resume runs on other versions (``versions``) than the session's
    last writer recorded (``previous``, its ``env_versions``) on a key both give; silent where
    either recorded none (a writer of an env without the hook, or of an older torchcbl)."""
    if not isinstance(previous, dict) or versions is None:
        return
    differ = [k for k in versions if k in previous and previous[k] != versions[k]]
    if not differ:
        return
    old = ", ".join(f"{k} {previous[k]}" for k in differ)
    new = ", ".join(f"{k} {versions[k]}" for k in differ)
    warnings.warn(
        f"the session in {run_dir} was last taught under {old} and is resumed under {new}: "
        f"steps from {first_step} on are taught under another simulator, so the env may "
        f"behave differently (torchcbl show lists what each writer ran on); resume under "
        f"{old} to continue as taught",
        UserWarning,
        stacklevel=3,
    )


def _episode_cap(env: gym.Env) -> int | None:
    """The step cap in force on ``env``: the smallest of its ``TimeLimit`` wrappers' (an outer
    ``TimeLimit(gymnasium.make(id), n)`` reports ``n`` in its spec whatever the inner cap) and
    of the env's own, an int ``max_episode_steps`` attribute of the unwrapped env (e.g.
    ``CorridorEnv``'s, resolved from its map when not given: a version whose default differs
    then gives another cap); without a wrapper, its spec's ``max_episode_steps`` (None: no
    cap)."""
    caps = []
    layer: Any = env
    while isinstance(layer, gym.Wrapper):
        if isinstance(layer, gym.wrappers.TimeLimit):
            caps.append(int(layer._max_episode_steps))
        layer = layer.env
    own = getattr(getattr(env, "unwrapped", layer), "max_episode_steps", None)
    if _is_int(own) and own >= 1:
        caps.append(int(own))
    if caps:
        return min(caps)
    return getattr(getattr(env, "spec", None), "max_episode_steps", None)


def _resumed_cap(stored_env: Mapping[str, Any], env: gym.Env) -> int | None:
    """The cap of ``env`` to compare with a session's: the one in force, or the outermost
    ``TimeLimit``'s as the spec reports it where the session stored that (sessions of an env
    with a gymnasium id written before the cap in force was kept), so that the env the
    session was made with resumes. An env without a spec has no such legacy: a session of one
    kept its cap in force from the first (2026-11-27)."""
    cap = _episode_cap(env)
    spec = getattr(env, "spec", None)
    if spec is None or not stored_env.get("id"):
        return cap
    legacy = spec.max_episode_steps
    return legacy if stored_env.get("max_episode_steps") == legacy else cap


def _env_class(env: gym.Env) -> str:
    """The unwrapped env's class as a session keeps it, ``module.qualname``."""
    cls = type(getattr(env, "unwrapped", env))
    return f"{cls.__module__}.{cls.__qualname__}"


def _as_interrupted(record: StepRecord) -> StepRecord:
    """A demonstration whose outcome never came, as the log keeps it (and a resume reads it):
    no reward, its episode cut."""
    return record.with_outcome(None, False, True, {"torchcbl_interrupted": True})


def _prior_source_entry(source: Path, n_steps: int, run_dir: Path) -> dict[str, Any]:
    """config.json's ``prior.source``: the session the prior was read from, by its absolute
    path and by its path relative to the new session's directory (found there where both
    moved together), and the steps its log held then."""
    entry: dict[str, Any] = {"session": str(source)}
    with contextlib.suppress(ValueError):  # (another drive than run_dir's: no relative path)
        entry["relative"] = os.path.relpath(source, os.path.abspath(run_dir))
    entry["n_steps"] = n_steps
    return entry


def _check_prior(value: Any, n_features: int, n_actions: int) -> tuple[np.ndarray, np.ndarray]:
    """``prior_demonstrations`` as (observations [N, D] float64, actions [N] int64), read-only
    copies; a ValueError / TypeError saying what was expected, what was given and what to do."""
    name = "prior_demonstrations"
    want = f"a pair (observations [N, {n_features}], actions [N]) with N >= 1"
    if isinstance(value, (str, os.PathLike)):
        path = os.fspath(value)
        if os.path.isdir(path):  # numpy cannot load it: a session's is read by the store
            # a session's as the store tells one (a user's own config.json is none)
            if _names_a_session_format(Path(path) / "config.json") or os.path.isfile(
                os.path.join(path, "steps.sqlite")
            ):
                raise TypeError(
                    f"{name}: expected {want}, got the session directory {path!r}; pass its "
                    "demonstrations (its training set, its own prior included): "
                    f"prior_demonstrations=torchcbl.session.load_demonstrations({path!r})."
                )
            raise TypeError(
                f"{name}: expected {want}, got the directory {path!r}, which holds no teaching "
                "session (no torchcbl session's config.json); pass a session's demonstrations with "
                "prior_demonstrations=torchcbl.session.load_demonstrations(session_dir), or "
                "a .npz file's with d = numpy.load(path); "
                "prior_demonstrations=(d['observations'], d['actions'])."
            )
        raise TypeError(
            f"{name}: expected {want}, got the path {path!r}; load it first, e.g. "
            "d = numpy.load(path); prior_demonstrations=(d['observations'], d['actions'])."
        )
    if isinstance(value, Mapping) or not isinstance(value, (tuple, list)) or len(value) != 2:
        got = type(value).__name__
        if isinstance(value, Mapping):  # a dict, or numpy.load's NpzFile
            keys = list(value.keys())
            got += f" with keys {keys!r:.200}"
        elif hasattr(value, "shape"):
            got += f" of shape {tuple(value.shape)}"
        elif isinstance(value, (tuple, list)):
            got += f" of {len(value)} items"
        else:
            got += f" {value!r:.80}"
        fix = "e.g. prior_demonstrations=torchcbl.session.load_demonstrations(earlier_run_dir)"
        if isinstance(value, Mapping) and {"observations", "actions"} <= set(keys):
            fix = (
                "pass its two arrays: prior_demonstrations=(d['observations'], d['actions']), "
                f"d being this {type(value).__name__}"
            )
        raise TypeError(f"{name}: expected {want}, got {' '.join(got.split())}; {fix}.")
    x, y = (np.asarray(v) for v in value)
    if x.dtype.kind not in "iuf" or x.ndim != 2 or x.shape[1] != n_features:
        raise ValueError(
            f"{name}: expected observations as a real-number array of shape [N, {n_features}] "
            f"(the env's {counted(n_features, 'feature')}), got {x.dtype} {x.shape}"
            + ("; one feature per row: observations.reshape(-1, 1)" if x.ndim == 1 else "")
            + "."
        )
    if x.shape[0] < 1:
        raise ValueError(
            f"{name}: expected at least one demonstration, got 0; leave it out (None) to start "
            "without prior demonstrations."
        )
    bad = ~np.isfinite(x.astype(np.float64)).all(axis=1)
    if bad.any():
        raise ValueError(
            f"{name}: observations must be finite; row {int(bad.argmax())} is "
            f"{x[int(bad.argmax())].tolist()} ({int(bad.sum())} rows with NaN or inf in all); "
            "drop or repair those rows."
        )
    if y.dtype.kind not in "iu" or y.shape != (x.shape[0],):
        raise ValueError(
            f"{name}: expected actions as an int array of shape [{x.shape[0]}] (one per "
            f"observation), got {y.dtype} {y.shape}"
            + (
                "; whole numbers stored as floats: actions.astype(numpy.int64)"
                if y.dtype.kind == "f"
                else ""
            )
            + "."
        )
    out = (y < 0) | (y >= n_actions)
    if out.any():
        raise ValueError(
            f"{name}: actions must be in [0, {n_actions}) (the env's Discrete({n_actions})); "
            f"action {int(y[int(out.argmax())])} at row {int(out.argmax())} ({int(out.sum())} "
            "out of range in all)."
        )
    x = np.array(x, dtype=np.float64, order="C")
    y = np.array(y, dtype=np.int64)
    x.flags.writeable = False
    y.flags.writeable = False
    return x, y


def _check_commit_every(commit_every: Any) -> None:
    if not _is_int(commit_every) or commit_every < 1:
        raise ValueError(f"commit_every: expected an int >= 1, got {commit_every!r}")


def _check_keep_checkpoints(keep: Any, *, resume: bool = False) -> None:
    if keep is not None and not is_keep_count(keep):
        raise ValueError(
            "keep_checkpoints: expected None (keep every checkpoint)"
            + (', "as_before" (as the session\'s last writer),' if resume else "")
            + f" or an int >= 1 (the newest checkpoints kept), got {keep!r}"
        )


class ConfidentTeacher:
    """Teach a discrete-action policy, asking the teacher only where the model is unsure.

    Args:
        env: a ``gymnasium.Env`` with a ``Discrete`` action space (from 0) and a 1-D float
            ``Box`` observation space of size D. An env that reads more than its
            ``gymnasium.make`` arguments (a file whose contents may change) may define
            ``describe_inputs() -> dict`` on its unwrapped class: str keys and plain JSON
            values that identify those inputs (e.g. a file's SHA-256). The session keeps it in
            its ``config.json`` and :meth:`resume` refuses an env whose description differs
            (``CorridorEnv`` describes its map so, ``DrivingEnv`` its traffic and SUMO files).
            An env that runs on a simulator may define ``describe_versions() -> dict[str,
            str]`` on its unwrapped class: the versions of what it runs on, each by name
            (``DrivingEnv``'s ``{"sumo": "1.28.0"}``, ``CorridorEnv``'s pymunk). Each writer
            of the session records them in ``writers.jsonl`` (``torchcbl show`` lists them),
            and :meth:`resume` warns where they differ from the last writer's.
        teacher: ``teacher(observation [D] ndarray, info dict) -> int`` in ``[0, n_actions)``
            (or a numpy integer, or a 0-d integer array or tensor). It gets a copy of the env's
            observation and the info of the latest reset / step. Optionally it has
            ``correct(observation, info, action) -> int | None``, offered after each autonomous
            step by strategies that take corrections (see :mod:`torchcbl.strategies`).
        model: the learner; default ``GaussianMixtureSet(n_actions, D, seed=seed)``. Its
            ``fit`` must be deterministic given the data (resume relies on it). A fitted model
            starts the session from it (kept as checkpoint 0), until the first refit. A
            session records the model's class by name and its constructor arguments:
            GaussianMixtureSet's, read from its attributes, or, for a subclass that sets one,
            the dict ``model.init_args`` (all of its constructor arguments, its own included;
            without it a subclass's own arguments are not recorded, and a warning says so).
        prior_demonstrations: labels the session starts from, e.g. logged data, an earlier
            session's (``torchcbl.session.load_demonstrations(run_dir)``) or a BC data set:
            ``(observations [N, D], actions [N])``, N >= 1, finite, actions in
            ``[0, n_actions)``. The model is fitted on them before the first decision, and
            every refit fits them first, then the session's own labels, in that fixed order;
            the strategy's ``observe_refit`` sees them. They are the teacher's labels of no
            step of this session: :attr:`n_demonstrations`, ``max_demonstrations``, the log's
            counts and the checkpoints' numbers count the session's own labels only
            (:attr:`n_prior` and :attr:`prior_demonstrations` say what the prior holds). The
            session keeps them in its directory (``prior.npz``, its SHA-256 in config.json),
            so :meth:`resume` and ``load_model`` use them without being given them again, and
            refuse a session whose file is missing or changed. Given as
            ``load_demonstrations`` returns them (a :class:`~torchcbl.session.Demonstrations`,
            its arrays unchanged since), the session also records the session they were read
            from and its step count then (:func:`~torchcbl.session.prior_source`), so that the
            road they were taught on counts as taught where a driving policy is evaluated;
            arrays of one's own (changed ones too) record no origin, and such an evaluation
            cannot say it is held out (``held_out``: None).
            Not with a fitted ``model`` (the first refit would replace it by a fit on the
            prior anyway): pass an unfitted one, or the prior alone.
        rule: the confidence rule of the default strategy; default ``DistanceRule(2.0)``
            (the paper's). Shorthand for ``strategy=ConfidentExecution(rule)``.
        strategy: who asks and who acts (:mod:`torchcbl.strategies`); default
            ``ConfidentExecution(rule)``. Give ``rule`` or ``strategy``, not both.
        config: a :class:`TeachingConfig`.
        run_dir: if given, a new session directory (see :mod:`torchcbl.session`): a folder
            that does not exist yet, or an empty one (or one holding only what torchcbl leaves
            where a session could not start, such as its ``writer.lock``). A folder holding a
            session (continue it with :meth:`resume`), what another session left, or files of
            one's own is refused with :class:`IncompatibleRunDirError`, and nothing is written
            (checked before the model is fitted on ``prior_demonstrations``).
        seed: seeds the first ``env.reset`` (and the default model).
        progress: show a tqdm bar with the live counters while :meth:`run` runs.
        on_step: called with each :class:`StepRecord` after it is recorded.
        on_refit: called as ``on_refit(model, n_labels)`` after each refit (not for the fit
            on ``prior_demonstrations`` before the first step).
        commit_every: journal lines (steps, demonstrations' outcomes, corrections) per SQLite
            commit, an int >= 1; every line is durable in the session's journal as it is
            written, and a demonstration's before its action runs.
        keep_checkpoints: how many of the newest checkpoints (``checkpoints/model-<n>.pt``,
            one written per refit) the session keeps as it writes each (an int >= 1; checkpoint
            0 is always kept, and so is that of a refit by hand, :meth:`refit`, which moves
            the schedule the older stages are rebuilt on); None keeps every one. A
            checkpoint is the refit it saves, so resume and ``load_model`` load it instead of
            refitting; ``load_model(run_dir, n_demonstrations=k)`` rebuilds the model at a
            stage whose checkpoint is gone from the log, the same model, at the cost of the
            refits it saved: one fit with
            ``refit="full"``, every refit since the last kept checkpoint before ``k`` with
            ``"incremental"`` (3 s at 2,000 labels, 5 features, measured 2026-11-27). For a
            learning curve over many stages, ``torchcbl.load_models(run_dir, stages)``
            rebuilds them in one pass, the incremental refits replayed once for all of them
            (at most one per label), not once per stage; or score the stages as the session
            runs, ``on_refit``. Each checkpoint is the model's whole state, its candidate
            sizes' statistics included: 0.14 MB for the default model on 4 features and 3
            actions, 2 MB with ``max_components=40`` (the driving domain's), so a session
            refitting after every label writes 70 MB, or 1 GB, per 500 labels when all are
            kept.

    Errors: a teacher that raises or answers outside the action space gives
    :class:`TeacherError`; an env that raises or returns a non-finite observation or reward
    gives :class:`EnvError`. Either way the log stays consistent and the session can go on
    (call :meth:`run` again: after an env error the episode is cut and the env reset) or be
    resumed from its directory.
    """

    def __init__(
        self,
        env: gym.Env,
        teacher: Teacher,
        *,
        model: torch.nn.Module | None = None,
        prior_demonstrations: Any = None,
        rule: Any = None,
        strategy: Any = None,
        config: TeachingConfig | None = None,
        run_dir: str | os.PathLike[str] | None = None,
        seed: int = 0,
        progress: bool = True,
        on_step: Callable[[StepRecord], None] | None = None,
        on_refit: Callable[[Any, int], None] | None = None,
        commit_every: int = 32,
        keep_checkpoints: int | None = DEFAULT_KEEP_CHECKPOINTS,
    ) -> None:
        if isinstance(run_dir, str) and not run_dir.strip():
            # Path("") is the working directory: the session would be written among its files
            raise ValueError(
                f"run_dir: expected a directory path or None, got {run_dir!r}; pass None to "
                "teach without a session directory, or '.' to write the session into the "
                f"working directory ({Path.cwd()})."
            )
        strategy = _pick_strategy(rule, strategy)
        if prior_demonstrations is not None and _is_fitted(model):
            raise ValueError(
                "give prior_demonstrations= or a fitted model=, not both: the session fits its "
                "model on the prior demonstrations before its first step (and on them and its "
                "own labels at every refit), so the fitted model would never be used. Pass an "
                "unfitted model (e.g. GaussianMixtureSet(...) with the arguments you want), or "
                "the fitted model alone."
            )
        self._setup(env, teacher, model, strategy, config, seed, progress, on_step, on_refit)
        if run_dir is not None:  # refused before the fit on a prior (seconds to minutes), not
            _check_new_session_path(Path(run_dir))  # after it; reads only, create checks again
            _check_commit_every(commit_every)
            _check_keep_checkpoints(keep_checkpoints)
        starts_fitted = _is_fitted(self.model)
        prior = None
        if prior_demonstrations is not None:
            self._set_prior(*_check_prior(prior_demonstrations, self.n_features, self.n_actions))
            prior = prior_bytes(*self._prior)
            x, y = self._train.arrays()
            self.model.fit(x, y)  # before the first decision, as a resume rebuilds it
            _tell_refit(self.strategy, self.model, x, y)
        self._env_config = self._describe_env()
        # what the env runs on, for writers.jsonl (a bad hook refused before anything is written)
        self._env_versions = _env_versions(self.env)
        self._store: SessionStore | None = None
        self.run_dir = None if run_dir is None else Path(run_dir)
        if self.run_dir is not None:
            stored_strategy_config = strategy_to_config(self.strategy)
            # only here, as a session starts: a stored session of such a strategy (from before
            # this check) still resumes with strategy= passed
            _check_rebuilt_as_itself(self.strategy, stored_strategy_config)
            _warn_unrecorded_args(self.model)
            session_config = {
                "format": FORMAT if prior is None else PRIOR_FORMAT,
                "teaching": dataclasses.asdict(self.config),
                "model": {"class": type(self.model).__name__, "args": _model_args(self.model)},
                "rule": None if self.rule is None else rule_to_config(self.rule),
                "strategy": stored_strategy_config,
                "env": self._env_config,
                "seed": self.seed,
                "starts_fitted": starts_fitted,  # then checkpoint 0 alone holds it
            }
            if prior is not None:
                session_config["prior"] = {
                    "file": PRIOR_NAME,
                    "sha256": hashlib.sha256(prior).hexdigest(),
                    "n_demonstrations": self.n_prior,
                }
                read = prior_demonstrations
                if (
                    isinstance(read, Demonstrations)
                    and read.source is not None
                    and read.n_steps is not None
                    and read.digest == _pair_digest(*self._prior)
                ):  # where they were read, unchanged since (prior_source checks it is still so)
                    session_config["prior"]["source"] = _prior_source_entry(
                        read.source, read.n_steps, self.run_dir
                    )
            # a session may start from a fitted model: its checkpoint 0, written with the
            # session (a resume can only load it, no label refits it); one with prior
            # demonstrations has its model fitted on them as checkpoint 0, and them in prior.npz
            self._new_session = (session_config, prior, commit_every, keep_checkpoints)
            self._create_session()
        self._next_reset_seed: int | None = self.seed

    def _create_session(self) -> None:
        """Write the new session this teacher was made with into :attr:`run_dir` (at its
        creation, or again after :meth:`_discard_unstarted` removed it)."""
        assert self.run_dir is not None and self._new_session is not None
        session_config, prior, commit_every, keep_checkpoints = self._new_session
        store = SessionStore.create(
            self.run_dir,
            session_config,
            initial_model=self.model if _is_fitted(self.model) else None,
            initial_digest=None if prior is None else self._digest.hexdigest(),
            prior=prior,
        )
        store.commit_every = commit_every
        store.keep_checkpoints = keep_checkpoints
        try:
            store.note_writer(0, _model_device(self.model), env_versions=self._env_versions)
        except BaseException as exc:
            # nothing is recorded yet: no half session (the directory is left without one,
            # checkpoint 0 of a fitted starting model included)
            store.discard_new()
            if isinstance(exc, SessionWriteError):
                exc.add_note(
                    f"torchcbl: nothing was recorded, and {self.run_dir} was left without "
                    "a session; free space (or fix the permissions) and create the teacher "
                    "again."
                )
            raise
        self._store = store
        self._unstarted = self._discarded = False

    def _discard_unstarted(self, exc: BaseException) -> None:
        """After ``exc`` (an error of the env, the teacher, the strategy or the model; not
        the user's stop nor a failing disk) ended the first step of the session this
        teacher made, with nothing recorded (no step, outcome or correction was written):
        remove that session again, so that a rerun of the same code with the cause fixed
        may start it in the same run_dir. A session that was resumed, or has any line in its
        log, is never removed; only the files its creation wrote are (see
        :meth:`SessionStore.discard_new`), under its lock."""
        store = self._store
        if (
            store is None
            or self._new_session is None
            or store.logged
            or self.records
            or self.corrections
            # the user's stop (Ctrl-C, 'q': the session resumes as it would have gone on)
            # and a failing disk (the removal could fail halfway) keep the session
            or not isinstance(exc, Exception)
            or isinstance(exc, (TeachingInterrupted, SessionWriteError))
        ):
            return
        self._store = None
        self._unstarted = self._discarded = True  # the next step() writes it again
        try:
            store.discard_new()
        except Exception:  # noqa: BLE001 - the error on its way out says more
            return
        exc.add_note(
            f"torchcbl: nothing was recorded, so {self.run_dir} was left without a session: "
            "fix the cause and run the same code again (or call run() again on this teacher)."
        )

    def _set_prior(self, x: np.ndarray, y: np.ndarray) -> None:
        """Take the prior demonstrations (read-only arrays) as the first labels of the
        training set and of the label digest the checkpoints carry."""
        self._prior = (x, y)
        for row, action in zip(x, y.tolist(), strict=True):
            self._train.add(row, action)
            self._digest.update(row, action)

    def _setup(self, env, teacher, model, strategy, config, seed, progress, on_step, on_refit):
        self.n_features, self.n_actions = check_env(env)
        if not callable(teacher):
            raise TypeError(
                f"teacher: expected a callable teacher(observation, info) -> int, got {teacher!r}"
            )
        refuse_unless_a_teacher(teacher, "teacher")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise TypeError(f"seed: expected an int, got {seed!r}")
        if seed < 0:  # checked before a run directory is written: a session must resume
            raise ValueError(f"seed: expected an int >= 0, got {seed} (numpy and gymnasium seeds)")
        self.env = env
        self.teacher = teacher
        self.seed = int(seed)
        self.config = TeachingConfig() if config is None else config
        if not isinstance(self.config, TeachingConfig):
            raise TypeError(f"config: expected a TeachingConfig, got {type(config).__name__}")
        if model is None:
            from torchcbl.gmm import GaussianMixtureSet

            model = GaussianMixtureSet(self.n_actions, self.n_features, seed=self.seed)
        for attr, want in (("n_actions", self.n_actions), ("n_features", self.n_features)):
            got = getattr(model, attr, want)
            if got != want:
                raise ValueError(
                    f"model.{attr} is {got} but the env has {want}; build the model with "
                    f"{attr}={want}."
                )
        means = getattr(model, "means_", None)
        if isinstance(means, torch.Tensor) and means.dtype != torch.float64:
            # refused here, before a session exists: its first refit would raise (a
            # GaussianMixtureSet fits only in float64)
            raise TypeError(
                f"model: its state was converted to {means.dtype}, but teaching refits it, and "
                "a GaussianMixtureSet fits only in float64; pass model.to(torch.float64) (a "
                "copy converted to another dtype may classify, e.g. GreedyPolicy(copy))."
            )
        self.model = model
        self.strategy = strategy
        strategy.bind(n_actions=self.n_actions, n_features=self.n_features, config=self.config)
        self._relabel = bool(getattr(strategy, "relabel", False))
        wants = bool(getattr(strategy, "wants_corrections", False))
        self._corrects = wants and callable(getattr(teacher, "correct", None))
        if wants and not self._corrects:
            warnings.warn(
                f"{type(strategy).__name__} learns from corrections of its autonomous steps, "
                f"but the teacher ({type(teacher).__name__}) has no correct(observation, info, "
                "action) method, so it will never correct one; a scripted teacher corrects by "
                "comparing with its own choice once wrapped: "
                "torchcbl.strategies.correcting(teacher).",
                stacklevel=3,
            )
        self.progress = bool(progress)
        self.on_step = on_step
        self.on_refit = on_refit
        self.records: list[StepRecord] = []
        w = self.config.accuracy_window
        self._acc_window: deque[bool] = deque(maxlen=w)
        self._auto_window: deque[bool] = deque(maxlen=w)
        self._labels = 0  # labels (demonstrations + corrections) so far
        self._train = TrainingSet(relabel=self._relabel)
        self._digest = LabelDigest()  # of every label so far, stored with each checkpoint
        self._prior: tuple[np.ndarray, np.ndarray] | None = None  # see _set_prior
        self.corrections: list[CorrectionRecord] = []
        self._new_since_refit = 0
        self._needs_reset = True
        self._next_episode = 0
        self._episode = 0
        self._episode_had_demo = False
        self._auto_steps_streak = 0
        self._auto_episodes_streak = 0
        self._n_episodes = 0  # finished episodes in the session
        # (session config.json, prior bytes, commit_every) of a session this teacher made,
        # None for a resumed one (see _discard_unstarted); _unstarted: removed, to be made again
        self._new_session: tuple[dict[str, Any], bytes | None, int] | None = None
        self._unstarted = False
        self._discarded = False  # it was removed (and stays so once closed)
        self._run_config: TeachingConfig | None = None  # the config of the running run()
        # a resumed session's (first step of its last run(), steps logged): the log's steps
        # of the run it was stopped in, whose streaks say whether it had met its stop
        self._resumed_at: tuple[int, int] | None = None
        # the stop settings of the running run() while it has not yet recorded where it
        # began (runs.jsonl, before its first step); None once it has, or outside run()
        self._run_unnoted: dict[str, Any] | None = None
        self._warned_unjudged = False
        #: why the last :meth:`run` returned: "max_demonstrations", "max_steps",
        #: "max_episodes", "autonomous_steps", "autonomous_episodes", or None before any run.
        #: After :meth:`resume`: the stop of its config the session had already met, as its
        #: log shows (a budget, or a streak its last run()'s steps end on), else None.
        self.stop_reason: str | None = None
        self._obs: np.ndarray | None = None
        self._env_token = object()  # noted on the env at each reset (torchcbl.policy)
        self._raw_obs: Any = None
        self._info: dict = {}

    def _describe_env(self) -> dict[str, Any]:
        spec = getattr(self.env, "spec", None)
        described = {
            "id": getattr(spec, "id", None),
            "class": _env_class(self.env),  # compared on resume, by its name
            "n_features": self.n_features,
            "n_actions": self.n_actions,
            "observation_space": observation_space_text(self.env.observation_space),
        }
        kwargs = _env_kwargs(self.env)
        if kwargs:
            described["kwargs"] = kwargs
        # beside the text of each argument that is a frozen dataclass, a form it can be made
        # again from (torchcbl.session.env_make_argument), for a domain's evaluate and replay
        objects = _env_objects(_make_kwargs(self.env))
        if objects:
            described["kwargs_objects"] = objects
        # the cap in force (TimeLimit or the env's own; None: none), compared on resume, also
        # for an env made directly (kept only for an env with a gymnasium id before 2026-11-27)
        described["max_episode_steps"] = _episode_cap(self.env)
        inputs = _env_inputs(self.env)
        if inputs is not None:  # what the env reads beyond its arguments, compared on resume
            described["inputs"] = inputs
        return described

    # -- resume -----------------------------------------------------------------------------

    @classmethod
    def resume(
        cls,
        run_dir: str | os.PathLike[str],
        env: gym.Env,
        teacher: Teacher,
        *,
        model: torch.nn.Module | None = None,
        rule: Any = None,
        strategy: Any = None,
        config: TeachingConfig | None = None,
        progress: bool = True,
        on_step: Callable[[StepRecord], None] | None = None,
        on_refit: Callable[[Any, int], None] | None = None,
        commit_every: int = 32,
        keep_checkpoints: int | None | Literal["as_before"] = "as_before",
    ) -> ConfidentTeacher:
        """Continue a session from its run directory, killed or cleanly stopped.

        The counters (steps, episodes, demonstrations, accuracy and autonomy windows, phase)
        are rebuilt from the log; the model is the checkpoint matching the logged
        demonstrations, or is refitted on them deterministically if that checkpoint is missing.
        A demonstration logged but never executed (the process died in between) is kept.
        The env is reset into a new episode (seeded from the session seed and episode index; a
        session that logged no step yet, e.g. stopped at its first request, is reset with the
        session seed, as the new session was, and so goes on as it would have). Every refusal
        below comes before the session is opened for writing: a refused resume touches no file.
        :attr:`stop_reason` says the stop of ``config`` the session had already met (a budget,
        or a streak its last run()'s steps end on; None: none), where :meth:`run` takes no
        step; the streaks of a session stopped before they held count from zero.

        Once the session is open, resume changes files in its ``checkpoints/``
        (:func:`torchcbl.session.restore_model`, the module's notes on damaged files): a
        checkpoint it cannot use is renamed ``<name>.stale`` (not fitted on the log's labels,
        or named for more labels than the log holds) or ``<name>.damaged`` (one whose name
        records no refit: a folder, a dangling link, checkpoint 0 where the session did not
        start from a fitted model; with full refits, also one whose refit lies on the regular
        schedule); a damaged checkpoint whose name records a refit, or
        one of another model's state at the count the model stands on, stays under its
        name, its bytes kept as ``<name>.damaged``, and the rebuilt model is written over it;
        with full refits the checkpoint of the labels the model stands on is written where
        it is missing. No checkpoint's bytes are lost: a file is never
        written over before they are kept.

        Args:
            config: optional; its stop fields may differ from the stored ones, the learning
                fields may not. ``model`` / ``rule`` / ``strategy``: optional; must match the
                stored ones (a model: its class, by name, and its recorded arguments, its
                ``init_args`` where it has one, see ``model`` above; a custom rule or
                strategy that cannot be rebuilt must be passed).
            commit_every: as for the constructor, for this writer.
            keep_checkpoints: as for the constructor, for this writer; by default
                ("as_before") what the session's last writer kept (``writers.jsonl`` records
                it; every checkpoint for a session of a torchcbl from before 2026-11-27, which
                kept every one). Given a number, the checkpoints earlier writers left beyond
                it go as this writer writes its first.

        Raises:
            TypeError: ``env`` is not an env (an env id: make it first with
                ``gymnasium.make``), or its ``describe_inputs()`` or ``describe_versions()``
                gives what the constructor refuses (:class:`EnvError` where one raises).
            IncompatibleRunDirError: the directory is not a session, or it was written for a
                different env, model, rule or learning configuration. Of the env its class,
                observation space and step cap are compared, and where both were made by
                ``gymnasium.make`` its id and arguments (one given as a frozen dataclass field
                by field, where both the session and ``env`` keep it whole), whether the
                session's env or the given one was made by ``gymnasium.make`` or directly (a
                session whose env was made with arguments refuses an env made directly).
            CorruptSessionError: a file of the session is damaged, its log lacks steps, or its
                ``-wal`` or journal is missing while ``writer.lock`` says it held steps the log
                lacks (nothing is changed; the message says how to recover).
            SessionLockedError: another writer has the directory open.

        Warns:
            UserWarning: the log holds fewer steps than ``writer.lock`` says were committed,
                its ``-wal`` there (a copy taken while the writer ran, or a power cut): the
                session goes on from what the files hold. Or the stored strategy's
                ``"relabel"`` is not the strategy's (a session stored before a new session
                refused that): the loop relabels as the strategy says, the readers as stored.
                Or the env's ``describe_versions()`` differs from what the session's last
                writer recorded on a key both give (another simulator release, say): the
                steps from here on are taught under it, and the env may behave otherwise.
                Not a refusal: a patch release usually changes nothing. Silent where either
                recorded none. Or a checkpoint resume rebuilt could not be written (a full
                disk; the message says what resume and ``load_model`` give meanwhile: a
                damaged file kept in place still records its refit), or the rebuilt model was
                written but its folder could not be flushed; or a damaged checkpoint's bytes
                could not be kept as ``.damaged``, so the rebuilt model was not written over
                it; or a file could not be renamed ``.stale`` / ``.damaged`` and stays as it
                is, never written over. Each names the file and what to do (free space, or
                move the file out of ``checkpoints/``); the session goes on.
        """
        stored = load_config(run_dir)
        n_features, n_actions = check_env(env)
        try:
            stored_config = TeachingConfig(**stored["teaching"])
        except TypeError as exc:  # a field this version does not know (a newer torchcbl's)
            raise IncompatibleRunDirError(f"{run_dir}: unreadable TeachingConfig: {exc}") from exc
        except ValueError as exc:  # a value no TeachingConfig takes: edited or damaged
            raise CorruptSessionError(
                f"{Path(run_dir) / 'config.json'}: its 'teaching' entry is no valid "
                f"TeachingConfig ({exc}). The file was edited or damaged; restore it from a "
                "backup or a copy of the run directory, or put the value the session was "
                "started with back. Nothing was changed."
            ) from exc
        config = stored_config if config is None else config
        model_args = None
        if model is not None:
            try:
                model_args = _model_args(model)
            except ValueError as exc:
                model_args = {"error": str(exc)}
        # the strategy given (a rule: confident execution with it), None to rebuild the stored
        given = None if rule is None and strategy is None else _pick_strategy(rule, strategy)
        problems = resume_problems(
            stored,
            n_features=n_features,
            n_actions=n_actions,
            env_id=getattr(getattr(env, "spec", None), "id", None),
            env_kwargs=_env_kwargs(env),
            env_max_episode_steps=_resumed_cap(stored.get("env") or {}, env),
            env_inputs=_env_inputs(env),
            env_class=_env_class(env),
            env_observation_space=env.observation_space,
            env_make_kwargs=_make_kwargs(env),
            learning=(stored_config.learning_fields(), config.learning_fields()),
            model_args=model_args,
            model_class=None if model is None else type(model).__name__,
            model_type=None if model is None else type(model),
            strategy=(
                None
                if given is None
                # unchecked: a session stored before the "relabel" check may misstate it
                else strategy_to_config(given, check_relabel=False)
            ),
        )
        if given is None:
            try:
                strategy = strategy_from_config(stored_strategy(stored))
            except (ValueError, TypeError) as exc:
                problems.append(str(exc))
        else:
            strategy = given
        if problems:
            raise IncompatibleRunDirError(
                f"cannot resume the session in {run_dir}: "
                + "; ".join(problems).rstrip(".")
                + ". Resume with matching arguments, or start a new session in another run_dir."
            )
        if given is not None:  # (a refused resume has said enough)
            _warn_misstated_relabel(stored_strategy(stored), given)
        prior = _read_prior(run_dir, stored)  # a missing or changed prior.npz: refused here
        # a checkpoints/ that cannot be listed: refused here too, before the session is
        # opened for writing (restore_model lists it after; nothing is noted or touched)
        latest_checkpoint(run_dir)
        if model is None:
            model = build_model(stored)
        self = cls.__new__(cls)
        self._setup(
            env, teacher, model, strategy, config, stored["seed"], progress, on_step, on_refit
        )
        if prior is not None:
            for a in prior:
                a.flags.writeable = False
            self._set_prior(*prior)
        self._env_config = self._describe_env()
        self._env_versions = _env_versions(env)  # refused here, before the session is opened
        self.run_dir = Path(run_dir)
        self._starts_fitted = stored.get("starts_fitted") is True
        _check_commit_every(commit_every)
        if isinstance(keep_checkpoints, str) and keep_checkpoints == "as_before":
            keep_checkpoints = kept_checkpoints(run_dir)
        _check_keep_checkpoints(keep_checkpoints, resume=True)

        def check(records: list[StepRecord], corrections: list[CorrectionRecord]) -> None:
            # a model restore_model would refuse to rebuild (a lost starting model) is refused
            # before the session is opened for writing: a refused resume touches no file
            xs, ys = label_sequence(records, corrections)
            _check_restorable(
                run_dir,
                self.model,
                xs,
                ys,
                max_new=self.config.max_new,
                incremental=self.config.refit == "incremental",
                starts_fitted=self._starts_fitted,
                prior=self._prior,
            )

        self._store, records, corrections = SessionStore.open_for_resume(
            self.run_dir, commit_every=commit_every, check=check if self._starts_fitted else None
        )
        self._store.keep_checkpoints = keep_checkpoints  # before note_writer records it
        try:
            # under the lock, before this writer's own line: the last writer's versions, and
            # where the run() that wrote the log's last step began
            versions, run_start = _last_writer_reading(self.run_dir, len(records))
            _warn_changed_versions(self.run_dir, versions, self._env_versions, len(records))
            last_run = (run_start, len(records))
            self._store.note_writer(
                len(records), _model_device(self.model), env_versions=self._env_versions
            )
            self._restore(records, corrections)
        except BaseException:
            self.close()
            raise
        self._resumed_at = last_run
        self.stop_reason = self._budget_met(self.config) or self._streak_met(self.config)
        return self

    def _restore(self, records: list[StepRecord], corrections: list[CorrectionRecord]) -> None:
        """Replay the log into the counters, the training set and the strategy (see
        :mod:`torchcbl.strategies` for the order), then restore the model."""
        self.records = records
        self._n_episodes = sum(1 for r in records if r.terminated or r.truncated)
        self.corrections = list(corrections)
        by_step = {c.step: c for c in corrections}
        strategy = self.strategy
        for r in records:
            if r.teacher_action is not None:
                self._acc_window.append(r.model_action == r.teacher_action)
                _tell_label(
                    strategy,
                    r.observation_array,
                    r.teacher_action,
                    model_action=r.model_action,
                    kind="demonstration",
                )
            corr = by_step.get(r.step)
            if corr is not None:
                _tell_label(
                    strategy,
                    corr.observation_array,
                    corr.action,
                    model_action=r.model_action,
                    kind="correction",
                )
            if r.phase == "confident":
                self._auto_window.append(r.autonomous)
            _tell_step(strategy, r, None)
        xs, ys = label_sequence(records, corrections)
        for x, y in zip(xs, ys, strict=True):
            self._train.add(x, y)
            self._digest.update(x, y)
        self._labels = len(ys)
        assert self.run_dir is not None
        from torchcbl.gmm import GaussianMixtureSet

        if _is_fitted(self.model) and isinstance(self.model, GaussianMixtureSet):
            # the model the session had is rebuilt from its directory (its checkpoint, else
            # a refit on its labels), never taken from the caller's fitted one: at 0 labels
            # without checkpoint 0 that one would decide where the session had no model
            # (strict=False: a subclass's state of its own is its own, loaded from the
            # checkpoint with the rest). The library's arguments are read from the model's
            # attributes, not its recorded arguments: a subclass's init_args may hold
            # arguments of its own, which GaussianMixtureSet does not take
            fresh = GaussianMixtureSet(**{n: getattr(self.model, n) for n in _MODEL_ARG_NAMES})
            self.model.load_state_dict(fresh.state_dict(), strict=False)
        k = restore_model(
            self.run_dir,
            self.model,
            xs,
            ys,
            max_new=self.config.max_new,
            relabel=self._relabel,
            store=self._store,
            incremental=self.config.refit == "incremental",
            starts_fitted=self._starts_fitted,
            prior=self._prior,
        )
        if k > 0 or self._prior is not None:
            if k == len(ys):
                x, y = self._train.arrays()
            else:
                from torchcbl.records import training_set

                px, py = ([], []) if self._prior is None else self._prior
                x, y = training_set(
                    [*px, *xs[:k]], [*np.asarray(py).tolist(), *ys[:k]], relabel=self._relabel
                )
            _tell_refit(strategy, self.model, x, y)
        self._new_since_refit = len(ys) - k
        self._next_episode = records[-1].episode + 1 if records else 0
        # nothing logged: the session's first reset (seeded with the seed itself) is still to
        # come, and the resumed session starts as the uninterrupted one did
        self._next_reset_seed = _seed_for(self.seed, self._next_episode) if records else self.seed

    # -- counters ---------------------------------------------------------------------------

    @property
    def n_demonstrations(self) -> int:
        """Labels in the session: demonstrations (steps with a teacher label) plus
        corrections. Refits and checkpoints count these; prior demonstrations do not count
        (:attr:`n_prior`)."""
        return self._labels

    @property
    def n_prior(self) -> int:
        """Prior demonstrations the session started from (0 without); they are in every fit
        but not in :attr:`n_demonstrations`."""
        return 0 if self._prior is None else len(self._prior[1])

    @property
    def prior_demonstrations(self) -> tuple[np.ndarray, np.ndarray]:
        """The prior demonstrations, ``(observations [N, D] float64, actions [N] int64)``,
        read-only ([0, D] and [0] without)."""
        if self._prior is None:
            x = np.zeros((0, self.n_features), dtype=np.float64)
            y = np.zeros(0, dtype=np.int64)
            x.flags.writeable = y.flags.writeable = False
            return x, y
        return self._prior

    @property
    def n_corrections(self) -> int:
        """Corrections (labels for earlier, autonomous steps) in the session."""
        return len(self.corrections)

    @property
    def rule(self) -> Any:
        """The confidence rule of the strategy (None for a strategy without one)."""
        return getattr(self.strategy, "rule", None)

    @property
    def n_steps(self) -> int:
        """Steps in the session (all :meth:`run` calls and resumes together; a step is one
        action sent to the env, asked or autonomous)."""
        return len(self.records)

    @property
    def n_episodes(self) -> int:
        """Finished episodes in the session: those the env ended (terminated or truncated),
        resumes included; the episode under way is not counted. This is what
        ``max_episodes`` bounds, and ``describe(run_dir).n_episodes_ended``;
        ``describe(run_dir).n_episodes`` counts the episodes with a logged step, the one
        under way included (one more while an episode is under way)."""
        return self._n_episodes

    @property
    def windowed_accuracy(self) -> float | None:
        """Share of the last ``accuracy_window`` demonstrations predicted right before learning."""
        w = self._acc_window
        return sum(w) / len(w) if w else None

    @property
    def autonomy_rate(self) -> float | None:
        """Share of autonomous steps among the last ``accuracy_window`` confident steps."""
        w = self._auto_window
        return sum(w) / len(w) if w else None

    @property
    def phase(self) -> str:
        """``"noninteractive"`` or ``"confident"``: the phase of the next step (the
        strategy's; ``"confident"`` for a strategy without phases)."""
        return str(getattr(self.strategy, "phase", "confident"))

    @property
    def policy(self) -> GreedyPolicy:
        """The learned policy as a callable obs -> action (live; deep-copy to freeze)."""
        return GreedyPolicy(self.model)

    # -- the loop ---------------------------------------------------------------------------

    def _reset(self) -> None:
        try:
            out = self.env.reset(seed=self._next_reset_seed)
        except Exception as exc:  # the seed stays for the retry: the same seed, the same run
            raise EnvError(f"env.reset raised {type(exc).__name__}: {exc}") from exc
        self._next_reset_seed = None
        _note_env_user(self.env, self._env_token)
        raw, info = reset_answer(out)
        self._obs = obs_array(raw, self.n_features, "env.reset")
        self._raw_obs, self._info = raw, info
        self._episode = self._next_episode
        self._next_episode += 1
        self._needs_reset = False
        self._episode_had_demo = False
        self.strategy.episode_start()

    def _ask(self, info: dict) -> int:
        obs = np.array(self._raw_obs, copy=True)
        step = len(self.records)
        try:
            answer = self.teacher(obs, info)
        except TeachingInterrupted:
            raise
        except Exception as exc:
            raise TeacherError(
                f"the teacher raised {type(exc).__name__}: {exc} (step {step}). Nothing was "
                "recorded for this step; fix the teacher and call run() again, or resume."
            ) from exc
        action = as_action(answer, self.n_actions)
        if action is None:
            raise TeacherError(
                f"the teacher answered {answer!r} at step {step}; expected an int action in "
                f"[0, {self.n_actions}). Nothing was recorded for this step; fix the teacher "
                "and call run() again, or resume."
            )
        return action

    def refit(self) -> bool:
        """Refit now on every recorded demonstration if any arrived since the last refit.

        The refit schedule then counts ``max_new`` from here. To evaluate a stage without
        changing the session, use :meth:`snapshot` instead. Returns whether a refit happened.
        In a session on disk its checkpoint (kept whatever ``keep_checkpoints`` says) is the
        only record of where the schedule moved, which resume and ``load_model`` read from
        its name (even damaged: a resume then writes the rebuilt model in its place).

        Raises:
            SessionWriteError: its checkpoint could not be written (a full disk); the refit
                is done in memory, and the message says what resume and ``load_model`` give
                for the stages up to the loop's next refit until the checkpoint is written:
                the teacher writes it with its next checkpoint and at :meth:`close` (a
                warning where that fails too; then, or where the process ends without
                :meth:`close`, those stages stay so for good).
        """
        if self._new_since_refit == 0 or not len(self._train):
            return False
        self._refit(by_hand=True)
        return True

    def snapshot(self) -> Any:
        """A copy of the model fitted on every demonstration so far, leaving the session as it
        is (its model and refit schedule untouched): for evaluating a learning stage. Of the
        model's own class (a :class:`~torchcbl.gmm.GaussianMixtureSet` unless ``model=`` gave
        another), as :attr:`model` is."""
        model = copy.deepcopy(self.model)
        if self._new_since_refit and len(self._train):
            fit = model.refit if self.config.refit == "incremental" else model.fit
            fit(*self._train.arrays())
        return model

    @property
    def autonomous_episodes_streak(self) -> int:
        """Consecutive episodes, in the current :meth:`run`, with no request and success."""
        return self._auto_episodes_streak

    @property
    def autonomous_steps_streak(self) -> int:
        """Consecutive autonomous steps in the current :meth:`run`."""
        return self._auto_steps_streak

    def _refit(self, by_hand: bool = False) -> None:
        x, y = self._train.arrays()
        (self.model.refit if self.config.refit == "incremental" else self.model.fit)(x, y)
        _tell_refit(self.strategy, self.model, x, y)
        self._new_since_refit = 0
        if self._store is not None:
            self._store.save_checkpoint(
                self.model, self._labels, self._digest.hexdigest(), by_hand=by_hand
            )
        if self.on_refit is not None:
            self.on_refit(self.model, self._labels)

    def step(self) -> StepRecord:
        """Take one decision (the strategy's; Algorithm 1 by default) and return its record.

        Autonomous steps reach disk in batches; call :meth:`flush` (or let :meth:`run` do it)
        to commit them. Demonstrations and corrections reach disk before the loop goes on.
        """
        if self._unstarted:
            self._create_session()
        try:
            return self._step()
        except BaseException as exc:
            if not self.records:
                self._discard_unstarted(exc)
            raise

    def _step(self) -> StepRecord:
        if self._store is None and self.run_dir is not None:
            if self._discarded:
                raise IncompatibleRunDirError(
                    f"this ConfidentTeacher was closed after its first step failed, with "
                    f"nothing recorded and no session left in {self.run_dir}; create the "
                    "teacher again to start the session."
                )
            raise IncompatibleRunDirError(
                f"this ConfidentTeacher was closed, so {self.run_dir} no longer records its "
                "steps; continue the session with ConfidentTeacher.resume(run_dir, env, teacher)."
            )
        if self._run_unnoted is not None and self._store is not None:
            # where this run() begins, before its first step (a resume counts the streak the
            # log ends on from there): a step of this run() is never logged without it
            self._store.note_run(len(self.records), self._run_unnoted)
            self._run_unnoted = None
        if self._new_since_refit >= self.config.max_new:
            # a refit owed since the last step (it raised, or was interrupted): done first, on
            # the labels it was due on, as load_model and a resume rebuild it
            self._refit()
        if not self._needs_reset and _env_user(self.env, self._env_token) is not self._env_token:
            self._cut_moved_episode()
        if self._needs_reset:
            self._reset()
        obs, info, raw = self._obs, self._info, self._raw_obs
        if self._corrects:  # the teacher judges the step on what the agent saw, even where
            # the env reuses its observation buffer in place
            raw, info = np.array(raw, copy=True), dict(info)
        assert obs is not None
        c = self.model.classify(obs[None])
        model_action = int(_np(c.action)[0])
        confidence = float(_np(c.confidence)[0])
        distance = float(_np(c.distance)[0])
        posterior = tuple(_np(c.posterior)[0].tolist())
        decision: Decision = self.strategy.decide(obs, c)
        if not (hasattr(decision, "ask") and hasattr(decision, "phase")):
            raise RuntimeError(
                f"strategy {self.strategy!r}: decide() returned {decision!r:.80}; expected a "
                "torchcbl.strategies.Decision(ask, phase, state=None), e.g. "
                "Decision(True, 'confident') (see torchcbl.strategies). Nothing was recorded "
                "for this step."
            )
        ask, phase = bool(decision.ask), decision.phase
        if phase not in ("noninteractive", "confident"):  # before the teacher is asked
            raise RuntimeError(
                f"strategy {self.strategy!r} decided with phase {phase!r}; expected "
                "'noninteractive' or 'confident' (see torchcbl.strategies). Nothing was "
                "recorded for this step."
            )
        if not ask and phase == "noninteractive":  # a StepRecord holds a label on each one
            raise RuntimeError(
                f"strategy {self.strategy!r} decided not to ask in the 'noninteractive' phase, "
                "which is for steps on which the teacher is asked by design; ask there, or "
                "decide with phase 'confident' for a step the agent takes on its own (see "
                "torchcbl.strategies). Nothing was recorded for this step."
            )
        if not ask and model_action < 0:
            raise RuntimeError(
                f"strategy {self.strategy!r} decided not to ask before any model exists; a "
                "strategy must ask while c.action is -1 (see torchcbl.strategies)."
            )
        teacher_action = self._ask(info) if ask else None
        actor = self.strategy.actor(decision, model_action, teacher_action)
        if not (
            (actor == "teacher" and teacher_action is not None)
            or (actor == "agent" and model_action >= 0)
        ):
            raise RuntimeError(
                f"strategy {self.strategy!r}: actor() returned {actor!r} with the teacher's label "
                f"{teacher_action!r} and the model's action {model_action}; expected 'teacher' "
                "on a labelled step or 'agent' once a model exists (see torchcbl.strategies)"
            )
        # From here on the step happens. The windows and the label count the record reports
        # are advanced first and undone if the step cannot be logged (memory never runs ahead
        # of disk); the training set and the strategy learn the label once it is durable.
        step = len(self.records)
        acc, auto = self._acc_window, self._auto_window
        acc_out = acc[0] if ask and len(acc) == acc.maxlen else None
        auto_out = auto[0] if phase == "confident" and len(auto) == auto.maxlen else None

        def undo() -> None:
            if ask:
                acc.pop()
                if acc_out is not None:
                    acc.appendleft(acc_out)
                self._labels -= 1
            if phase == "confident":
                auto.pop()
                if auto_out is not None:
                    auto.appendleft(auto_out)

        # A Ctrl-C waits while the windows advance and the demonstration's line is written:
        # once it is, the step is kept (and logged as interrupted below), never undone while it
        # stays on disk (an autonomous step writes nothing here: no hold, it costs ~10 us)
        hold = _InterruptHold(active=ask and self._store is not None)
        advanced = False
        try:
            if ask:
                acc.append(model_action == teacher_action)
                self._labels += 1
            if phase == "confident":
                auto.append(not ask)
            advanced = True
            record = self._record(
                step,
                obs,
                model_action,
                confidence,
                distance,
                posterior,
                teacher_action,
                actor,
                phase,
                ask,
            )
            if ask and self._store is not None:
                self._store.commit_demonstration(record)  # durable before the action runs
        except BaseException:
            if advanced:
                undo()
            hold.release()  # the error raised says more than a Ctrl-C that came with it
            raise
        try:  # a Ctrl-C as the hold ends lands here too: the demonstration is durable
            stopped: BaseException | None = hold.release()
        except BaseException as exc:
            stopped = exc
        if stopped is not None and not ask:  # nothing was written: the step never happened
            undo()
            raise stopped
        if ask:
            # The demonstration is durable: from here on it is kept, whatever is raised (a
            # strategy's error, a Ctrl-C): it joins the training data and, if the strategy
            # raised, the step is logged as interrupted without running the action.
            added = digested = False
            try:
                self._train.add(obs, teacher_action)  # type: ignore[arg-type]
                added = True
                self._digest.update(obs, teacher_action)  # type: ignore[arg-type]
                digested = True
                _tell_label(
                    self.strategy,
                    obs,
                    teacher_action,  # type: ignore[arg-type]
                    model_action=model_action,
                    kind="demonstration",
                )
            except BaseException as exc:
                if not added:
                    self._train.add(obs, teacher_action)  # type: ignore[arg-type]
                if not digested:
                    self._digest.update(obs, teacher_action)  # type: ignore[arg-type]
                if stopped is None:
                    stopped = exc
            self._episode_had_demo = True
            self._new_since_refit += 1
        if stopped is not None:
            self._execute(record, interrupted=stopped)  # logs the step, raises ``stopped``
        try:
            record = self._execute(record)
        except BaseException:
            if len(self.records) == step:  # raised before the record reached memory
                self._needs_reset = True  # the env may have moved: a fresh episode next
                if not ask:  # an autonomous step: on disk neither
                    undo()
                else:  # the demonstration is durable: kept, as a resume reads it
                    self._keep_interrupted(record)
            raise
        finally:
            # Refit once the step is complete (Algorithm 1 executes the teacher's action either
            # way), so a fit that fails leaves a whole step behind, not half of one; the
            # strategy sees the logged step even then (a resume replays it)
            try:
                if ask and self._new_since_refit >= self.config.max_new:
                    self._refit()
            finally:
                if len(self.records) > step:  # executed (also when the env failed afterwards)
                    _tell_step(self.strategy, self.records[step], decision)
        if ask:
            self._auto_steps_streak = 0
        else:
            self._auto_steps_streak += 1
            if self._corrects and self._offer_correction(record, raw, info):
                self._auto_steps_streak = 0
                self._episode_had_demo = True
        if record.terminated or record.truncated:
            clean = (
                not self._episode_had_demo
                and phase == "confident"
                and self._episode_succeeded(record, self._info)
            )
            self._auto_episodes_streak = self._auto_episodes_streak + 1 if clean else 0
        if self.on_step is not None:
            self.on_step(record)
        return record

    def _cut_moved_episode(self) -> None:
        """The env was reset or stepped by someone else (evaluate_policy, another loop) since
        this loop's last step: the observation it holds is no longer the env's, so the episode
        is left unfinished, as a resume leaves one, and the next step starts a new one."""
        self._needs_reset = True
        last = self.records[-1].step if self.records else None
        warnings.warn(
            f"ConfidentTeacher: its env was used by something else (evaluate_policy, or another "
            f"ConfidentTeacher) since its last step ({last}) in episode {self._episode}, so the "
            "env no longer shows the observation the loop holds; that episode is left unfinished "
            "(as a resume leaves one) and teaching goes on from a fresh episode. Evaluate on an "
            "env of its own (gymnasium.make it again) to keep the session's episodes whole.",
            stacklevel=_caller_level(),
        )

    def _keep_interrupted(self, record: StepRecord) -> None:
        """Add a durable demonstration whose step failed before it reached memory as a resume
        would read it (interrupted, episode cut), and log that outcome if the log takes it."""
        final = _as_interrupted(record)
        hold = _InterruptHold()
        try:
            self.records.append(final)
            self._n_episodes += 1
            if self._store is not None:
                try:
                    self._store.finish(final)
                except SessionWriteError:
                    pass  # left pending on disk: a resume marks it interrupted alike
        finally:
            hold.release()  # the exception on its way out says enough

    def _episode_succeeded(self, record: StepRecord, info: dict) -> bool:
        """Success is never assumed: the env's ``info["is_success"]`` decides; without it, a
        time-limit end counts only with ``time_limit_is_success`` (see TeachingConfig)."""
        cfg = self._run_config or self.config
        judged = _judged(record, info, cfg.time_limit_is_success)
        if judged or info.get("is_success") is not None:  # the env said, or the time limit
            return judged
        if cfg.autonomous_episodes_to_stop is not None and not self._warned_unjudged:
            self._warned_unjudged = True
            warnings.warn(_unjudged_text(record, cfg), stacklevel=_caller_level())
        return False

    def _record(
        self,
        step,
        obs,
        model_action,
        confidence,
        distance,
        posterior,
        teacher_action,
        actor,
        phase,
        ask,
    ) -> StepRecord:
        executed = teacher_action if actor == "teacher" else model_action
        return StepRecord(
            step=step,
            episode=self._episode,
            observation=tuple(obs.tolist()),
            model_action=model_action,
            confidence=confidence,
            distance=distance,
            posterior=posterior,
            teacher_action=teacher_action,
            executed_action=executed,  # type: ignore[arg-type]
            phase=phase,
            autonomous=not ask,
            reward=None,
            terminated=False,
            truncated=False,
            info={},
            n_demonstrations=self._labels,
            autonomy_rate=self.autonomy_rate,
            windowed_accuracy=self.windowed_accuracy,
            actor=actor,
        )

    def _offer_correction(self, record: StepRecord, raw: Any, info: dict) -> bool:
        """Let the teacher correct the autonomous step just taken; True if it did."""
        try:
            answer = self.teacher.correct(  # type: ignore[attr-defined]
                np.array(raw, copy=True), dict(info), record.executed_action
            )
        except TeachingInterrupted:
            raise
        except Exception as exc:
            raise TeacherError(
                f"the teacher's correct() raised {type(exc).__name__}: {exc} (step "
                f"{record.step}). The step is recorded, no correction was; fix the teacher "
                "and call run() again, or resume."
            ) from exc
        if answer is None:
            return False
        action = as_action(answer, self.n_actions)
        if action is None:
            raise TeacherError(
                f"the teacher's correct() answered {answer!r} at step {record.step}; expected "
                f"None or an int action in [0, {self.n_actions}). The step is recorded, no "
                "correction was; fix the teacher and call run() again, or resume."
            )
        if action == record.executed_action:
            return False
        correction = CorrectionRecord(
            step=record.step,
            episode=record.episode,
            observation=record.observation,
            executed_action=record.executed_action,
            action=action,
        )
        x = record.observation_array
        hold = _InterruptHold()  # a Ctrl-C waits until memory holds what disk holds
        try:
            if self._store is not None:
                self._store.correct(correction)  # durable before the next decision
            self.corrections.append(correction)
            self._labels += 1
            self._train.add(x, action)
            self._digest.update(x, action)
            self._new_since_refit += 1
        except BaseException:
            hold.release()
            raise
        try:  # the strategy and the refit schedule learn the label as a resume replays it;
            late = hold.release()  # a Ctrl-C held back (or landing now) stops the run after
        except BaseException as exc:
            late = exc
        _tell_label(self.strategy, x, action, model_action=record.model_action, kind="correction")
        if self._new_since_refit >= self.config.max_new:
            self._refit()
        if late is not None:
            raise late
        return True

    def _execute(
        self, record: StepRecord, *, interrupted: BaseException | None = None
    ) -> StepRecord:
        """Run the record's action, log the step with its outcome and return it.

        Whatever happens in the env, the step is appended to :attr:`records` and logged
        (an env error or a Ctrl-C cuts the episode). If the log write fails, memory follows
        disk: a demonstration (already durable) is kept as interrupted, an autonomous step is
        dropped; either way the episode is cut and :class:`SessionWriteError` raised.
        ``interrupted``: an exception raised before the action ran; the action is not run, the
        step is logged as interrupted and the exception re-raised.
        """
        error: str | None = None
        cause: BaseException | None = None
        interrupt: BaseException | None = interrupted
        reward: float | None = None
        terminated = truncated = False
        info: dict = {}
        try:
            if interrupted is not None:
                raise interrupted
            out = self.env.step(record.executed_action)
        except Exception as exc:
            if interrupted is not None:
                interrupt = interrupted
            else:
                error, cause = f"env.step raised {type(exc).__name__}: {exc}", exc
        except BaseException as exc:  # KeyboardInterrupt (Ctrl-C), SystemExit: log, re-raise
            interrupt = exc
        else:
            # whatever reading the env's answer raises, the step is still logged below
            try:
                reward, terminated, truncated, info = step_outcome(out)
                self._obs = obs_array(out[0], self.n_features, "env.step")
                self._raw_obs, self._info = out[0], info
            except EnvError as exc:
                error, cause = str(exc), exc
            except Exception as exc:
                error = f"env.step's answer could not be read ({type(exc).__name__}: {exc})"
                cause = exc
            except BaseException as exc:  # a Ctrl-C while reading it
                interrupt = exc
        if interrupt is not None:
            reward, terminated, truncated = None, False, True
            info = {"torchcbl_interrupted": True}
        elif error is not None:
            truncated = True
            info = {"torchcbl_error": error}
        else:
            info = jsonable_info(info)
        final = record.with_outcome(reward, terminated, truncated, info)
        # a Ctrl-C waits until the record is in memory and its line on disk, or neither
        hold = _InterruptHold(active=self._store is not None)
        try:
            self.records.append(final)
            # the session's episode count follows the log: here, where a record is added,
            # replaced or dropped (as a resume counts: every terminated or truncated record)
            ended = terminated or truncated
            if ended:
                self._needs_reset = True
                self._n_episodes += 1
            if self._store is not None:
                try:
                    if final.teacher_action is not None:
                        self._store.finish(final)
                    else:
                        self._store.append(final)
                except BaseException as exc:  # the line was not written (SessionStore._write)
                    self._needs_reset = True
                    if final.teacher_action is not None:  # durable as pending: interrupted
                        self.records[-1] = _as_interrupted(record)
                        self._n_episodes += not ended  # it now ends its episode
                    else:
                        self.records.pop()
                        self._n_episodes -= ended
                    if interrupt is None or not isinstance(exc, SessionWriteError):
                        raise
                    interrupt.add_note(f"torchcbl: {exc}")
        finally:
            late = hold.release()
        if late is not None and interrupt is None and error is None:
            raise late  # the step is whole in memory and on disk; run() goes on from it
        if interrupt is not None:
            where = f" in {self.run_dir}" if self.run_dir is not None else ""
            interrupt.add_note(
                f"torchcbl: step {final.step} was logged as interrupted (episode cut){where}; "
                "call run() again to go on from a fresh episode, or resume the directory."
            )
            raise interrupt
        if error is not None:
            raise EnvError(
                f"{error} (step {final.step}, action {final.executed_action}). The step is "
                "logged with the episode cut (truncated); call run() again to continue from a "
                "fresh episode, or resume the run directory."
            ) from cause
        return final

    def run(self, **stop_overrides: int | bool | None) -> ConfidentTeacher:
        """Teach until a stop criterion holds; may be called again to continue.

        The budgets (``max_steps``, ``max_demonstrations``, ``max_episodes``) count over the
        whole session, so ``run(max_steps=ct.n_steps + 500)`` teaches 500 more steps; the
        streaks start from zero in each call. ``stop_reason`` then says which criterion held.
        A resumed session that had met a streak in the run it was stopped in (its log, from
        the step its last ``run()`` began at, which each call records in ``runs.jsonl`` before
        its first step, ends on that many autonomous steps, or successful episodes with no
        request) is done: its first ``run()`` takes no step, as for a budget reached; a longer
        streak is one it has not met, and goes on until it holds, counted from zero. Met is
        judged by this call's stop, not the one the last run() was given (a last run() that
        stopped on 20 in a row has met a stop of 3). A session stopped before its streak held
        (Ctrl-C, a kill), or taught in several run() calls none of which met it, counts it
        from zero on resume.

        Args:
            **stop_overrides: any of ``autonomous_steps_to_stop``,
                ``autonomous_episodes_to_stop``, ``max_demonstrations``, ``max_steps``,
                ``max_episodes`` and ``time_limit_is_success``, for this call only (e.g.
                ``run(max_demonstrations=50)`` then :meth:`snapshot` to keep the model of a
                stage).

        Raises:
            ValueError: unknown override, or no stop criterion at all (it would never end).

        Warns:
            UserWarning: the call took no step because a budget was already reached when it
                began (e.g. ``run(max_steps=100)`` on a session of 150 steps, or ``run()`` on
                a resumed session that had finished): the warning names the budget, the
                session's count and how to ask for more. Or a resumed session had met its
                streak (above): the warning names it, the streak its log ends on and how to
                ask for a longer one.
        """
        unknown = sorted(set(stop_overrides) - set(_STOP_SETTINGS))
        if unknown:
            raise ValueError(
                f"run(): unknown stop criteria {unknown}; expected some of {_STOP_SETTINGS}"
            )
        cfg = dataclasses.replace(self.config, **stop_overrides)
        if all(getattr(cfg, name) is None for name in STOP_FIELDS):
            raise ValueError("run(): " + _NO_STOP.format(fields=STOP_FIELDS))
        self._run_config = cfg
        self._run_unnoted = {name: getattr(cfg, name) for name in _STOP_SETTINGS}
        self._auto_steps_streak = 0
        self._auto_episodes_streak = 0
        self.stop_reason = None
        from torchcbl._progress import progress_bar

        total = None if cfg.max_steps is None else max(cfg.max_steps - self.n_steps, 0)
        bar = progress_bar(total=total, desc="teaching", unit="step", show=bool(self.progress))
        first_step = self.n_steps
        # a resumed session whose last run had met a streak of cfg's is done, as one whose
        # budget is reached: no step (a raised streak is not met: it goes on until it holds)
        already = self._streak_met(cfg)
        try:
            while True:
                reached = self._budget_met(cfg) or already
                if reached is not None:
                    self.stop_reason = reached
                    break
                self.step()
                if self.progress:
                    bar.update(1)
                    if self.n_steps % 16 == 0:
                        bar.set_postfix_str(self._postfix(), refresh=False)
                if (
                    cfg.autonomous_steps_to_stop is not None
                    and self._auto_steps_streak >= cfg.autonomous_steps_to_stop
                ):
                    self.stop_reason = "autonomous_steps"
                    break
                if (
                    cfg.autonomous_episodes_to_stop is not None
                    and self._auto_episodes_streak >= cfg.autonomous_episodes_to_stop
                ):
                    self.stop_reason = "autonomous_episodes"
                    break
        except BaseException as exc:
            try:
                self.flush()
            except SessionWriteError as flush_error:
                exc.add_note(f"torchcbl: also, {flush_error}")
            raise
        else:
            self.flush()
            if self.n_steps == first_step and self.stop_reason in _BUDGET_COUNTS:
                self._warn_budget_reached(cfg)
            elif self.n_steps == first_step and self.stop_reason in _STREAK_COUNTS:
                self._warn_streak_met(cfg)
        finally:
            self._run_config = self._run_unnoted = None
            if self.progress:
                bar.set_postfix_str(self._postfix())
            bar.close()
        return self

    def _budget_met(self, cfg: TeachingConfig) -> str | None:
        """The budget of ``cfg`` the session has reached (as :attr:`stop_reason` names it),
        in the order run() checks them; None: none."""
        if cfg.max_demonstrations is not None and self.n_demonstrations >= cfg.max_demonstrations:
            return "max_demonstrations"
        if cfg.max_steps is not None and self.n_steps >= cfg.max_steps:
            return "max_steps"
        if cfg.max_episodes is not None and self._n_episodes >= cfg.max_episodes:
            return "max_episodes"
        return None

    def _last_run_streaks(self, cfg: TeachingConfig) -> tuple[int, int]:
        """The streaks (autonomous steps, successful autonomous episodes) a resumed session's
        log ends on, counted as run() counts them over the steps of its last run() (where
        ``runs.jsonl`` says it began; in an older session, its last writer's first step: a
        run() ends with its writer; one that raised ends its streaks too), success judged as
        ``cfg`` says."""
        assert self._resumed_at is not None
        start, end = self._resumed_at
        return _last_run_streaks(
            self.records[start:end],  # resume refuses a log with a gap: record i is step i
            {c.step for c in self.corrections},
            start,
            time_limit_is_success=cfg.time_limit_is_success,
        )

    def _streak_met(self, cfg: TeachingConfig) -> str | None:
        """The streak of ``cfg`` (as :attr:`stop_reason` names it) a resumed session that has
        taken no step yet had met in the run it was stopped in; None: none (a streak counts
        within one run(), so a run() after a step of this writer counts its own)."""
        if self._resumed_at is None or self.n_steps != self._resumed_at[1]:
            return None
        return _streak_met(
            self._last_run_streaks(cfg),
            cfg.autonomous_steps_to_stop,
            cfg.autonomous_episodes_to_stop,
        )

    def _warn_streak_met(self, cfg: TeachingConfig) -> None:
        """Say that :meth:`run` took no step because the resumed session had met its streak
        (the :attr:`stop_reason`) before it was resumed, and how to teach on."""
        reason = self.stop_reason
        assert reason is not None
        name, noun, more = _STREAK_COUNTS[reason]
        have = self._last_run_streaks(cfg)[reason == "autonomous_episodes"]
        warnings.warn(
            f"run() took no step: {name}={getattr(cfg, name)} was already met (this resumed "
            f"session's log ends on {have} {noun} in a row, of the run it was stopped in: its "
            f"teaching is done). A streak counts within one run() call: to teach on, ask for "
            f"a longer one, counted from here, e.g. run({name}={have + more}).",
            stacklevel=3,
        )

    def _warn_budget_reached(self, cfg: TeachingConfig) -> None:
        """Say that :meth:`run` took no step because a budget of the whole session (the
        :attr:`stop_reason`) was reached before it began, and how to ask for more."""
        name = self.stop_reason
        assert name is not None
        attr, noun = _BUDGET_COUNTS[name]
        have = getattr(self, attr)
        warnings.warn(
            f"run() took no step: {name}={getattr(cfg, name)} was already reached (the session "
            f"holds {have} {noun}; budgets count over the whole session, resumes included). "
            f"To go on, raise it for this call, e.g. run({name}=ct.{attr} + 100), here "
            f"run({name}={have + 100}).",
            stacklevel=3,
        )

    def _postfix(self) -> str:
        def pct(v: float | None) -> str:
            return "-" if v is None else f"{100 * v:.0f}%"

        return (
            f"{self.phase} demos={self.n_demonstrations} "
            f"autonomy={pct(self.autonomy_rate)} acc={pct(self.windowed_accuracy)}"
        )

    def flush(self) -> None:
        """Commit any batched autonomous steps to the run directory (no-op without one)."""
        if self._store is not None:
            self._store.commit()

    def close(self) -> None:
        """Commit and close the step log. The session can be resumed from its directory.

        A refit by hand's checkpoint that a write failed to save (:meth:`refit`) is written
        first; where that fails again, a warning says what is lost."""
        self._unstarted = False  # a session removed after its first step failed stays so
        if self._store is not None:
            store, self._store = self._store, None
            store.close()  # releases the lock even when the final commit fails

    def __enter__(self) -> ConfidentTeacher:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return (
            f"ConfidentTeacher(steps={self.n_steps}, demonstrations={self.n_demonstrations}, "
            f"phase={self.phase!r}, run_dir={str(self.run_dir) if self.run_dir else None!r})"
        )


def _caller_level() -> int:
    """The ``stacklevel`` that makes a warning raised by the function calling this one point
    at the first frame outside this module: the user's ``run()`` or ``step()`` line."""
    frame, level = sys._getframe(1), 1
    while frame.f_back is not None and frame.f_code.co_filename == __file__:
        frame, level = frame.f_back, level + 1
    return level


#: How an env whose episodes end at their goal says so, for the warning of an episode the
#: env does not judge.
_WRAP_GOAL = (
    "wrap the env to set info['is_success'] = terminated at each episode's end (the README's "
    "GoalIsSuccess, under 'Success is never assumed')"
)


def _unjudged_text(record: StepRecord, cfg: TeachingConfig) -> str:
    """The warning for the episode ``record`` ends, which the env does not judge (no
    ``info["is_success"]``) and ``cfg.time_limit_is_success`` does not count: it names both
    kinds of env, a goal reached by termination and a time limit to survive."""
    how = "(terminated)" if record.terminated else "at its time limit (truncated)"
    if cfg.time_limit_is_success:  # so it ended terminated, and that counts as a failure
        return (
            f"episode {record.episode} ended {how} without info['is_success']: with "
            "time_limit_is_success=True it counts as a failure (only an episode cut by its "
            "time limit succeeds, as for CartPole). If this env's episodes end (terminated) on "
            "reaching their goal (MountainCar, Acrobot), that is the wrong way round: leave "
            f"time_limit_is_success False and {_WRAP_GOAL}."
        )
    return (
        f"episode {record.episode} ended {how} without info['is_success'], so it does not "
        "count towards autonomous_episodes_to_stop (success is never assumed). Say what "
        "success is for this env: where an episode ends (terminated) on reaching its goal "
        f"(MountainCar, Acrobot), {_WRAP_GOAL}; where the goal is to last until the time "
        "limit (CartPole), set TeachingConfig(time_limit_is_success=True)."
    )


#: The streaks run() stops at, by stop_reason: the stop field, what it counts, and how many
#: more the warning of a run() that took no step suggests.
_STREAK_COUNTS = {
    "autonomous_steps": ("autonomous_steps_to_stop", "autonomous steps", 100),
    "autonomous_episodes": (
        "autonomous_episodes_to_stop",
        "successful episodes with no request",
        10,
    ),
}

#: The budgets run() stops at, by stop_reason: the counter (attribute) each one bounds and
#: what it counts, for the warning of a run() that took no step.
_BUDGET_COUNTS = {
    "max_steps": ("n_steps", "steps"),
    "max_demonstrations": ("n_demonstrations", "labels"),
    "max_episodes": ("n_episodes", "finished episodes"),
}


def _jsonable(value: Any) -> bool:
    try:
        json.dumps(value, allow_nan=False)
    except (TypeError, ValueError):
        return False
    return True
