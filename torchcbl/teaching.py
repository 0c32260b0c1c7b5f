"""ConfidentTeacher: confident execution (Chernova & Veloso, AAMAS 2007, Algorithm 1).

The pieces are separate and swappable, as in imitation's DAgger: the *rule* that decides when
to ask (:mod:`torchcbl.confidence`), the *teacher* (any callable ``teacher(obs, info) -> int``),
the *learner* (a :class:`~torchcbl.gmm.GaussianMixtureSet`) and the *collector* (this loop,
writing every step to a :class:`~torchcbl.records.StepRecord` and, with ``run_dir``, to a
durable session directory laid out as documented in :mod:`torchcbl.session`).

One step of the loop:

1. Classify the current observation with the current model (action, confidence, distance,
   posterior; before any fit: action -1, distance +inf).
2. Non-interactive phase, or inside a teacher burst: ask the teacher. Confident execution: ask
   the teacher only when the rule is not confident; a request starts a burst of
   ``config.burst`` teacher moves (the paper's driving teacher gave 10). A burst ends early at
   the end of an episode.
3. A teacher answer is a demonstration: the model's prediction is scored against it (windowed
   prediction accuracy), it is committed to the log, and the model is refitted when
   ``config.max_new`` demonstrations have accumulated since the last fit. Then the teacher's
   action is executed. Otherwise the model's action is executed.
4. The step is recorded; an episode that ends is reset and teaching goes on. Only the first
   reset of a new session is seeded (with ``seed``); later resets continue the env's RNG. The
   first reset after :meth:`ConfidentTeacher.resume` is seeded from (seed, episode index).

The non-interactive phase ends after the step at which the accuracy window is full
(``accuracy_window`` demonstrations) and its accuracy is >= ``target_accuracy``; never when the
target is None; it is skipped when ``noninteractive=False``.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import os
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from torchcbl.confidence import DistanceRule, _np, rule_from_config, rule_to_config
from torchcbl.records import StepRecord, jsonable_info
from torchcbl.session import (
    FORMAT,
    IncompatibleRunDirError,
    SessionStore,
    build_model,
    fitted_count,
    latest_checkpoint,
    load_config,
    load_policy,
    replay_refits,
)

__all__ = [
    "ConfidentTeacher",
    "EnvError",
    "GreedyPolicy",
    "TeacherError",
    "TeachingConfig",
    "evaluate_policy",
    "load_policy",
]

Teacher = Callable[[np.ndarray, dict], int]
STOP_FIELDS = (
    "autonomous_steps_to_stop",
    "autonomous_episodes_to_stop",
    "max_demonstrations",
    "max_steps",
)
_MODEL_ARG_NAMES = (
    "n_actions",
    "n_features",
    "max_components",
    "criterion",
    "var_floor",
    "tol",
    "max_iter",
    "seed",
    "refit_growth",
)


class TeacherError(RuntimeError):
    """The teacher raised or gave an invalid action; nothing was recorded for that step."""


class TeachingInterrupted(Exception):
    """The teacher asked to stop teaching (a person pressed 'q' or Ctrl-C, input closed).

    A teacher raises it from inside its call; the loop lets it through unwrapped, after
    committing what was recorded: every demonstration before the interrupted decision is kept,
    the decision being asked about is not answered, and the session can be resumed.
    """


class EnvError(RuntimeError):
    """The environment raised or returned a non-finite / malformed observation or reward."""


def _opt_int(name: str, value: Any, *, minimum: int) -> None:
    if value is None:
        return
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(
            f"TeachingConfig.{name}: expected None or an int >= {minimum}, got {value!r}"
        )


@dataclass(frozen=True)
class TeachingConfig:
    """How the loop teaches and when it stops. Defaults follow the paper's corridor setup.

    Attributes:
        max_new: refit after this many new demonstrations (>= 1).
        refit: "full" (default) fits the model from scratch at every refit, so it is a function
            of the demonstrations alone; "incremental" uses ``GaussianMixtureSet.refit``: only
            the actions whose data changed are refitted, each candidate warm-started from its
            previous parameters, with a periodic from-scratch fit (1/7.5 to 1/9.5 of the
            refit time of a 10,000-demonstration session with max_new = 1, the same quality:
            bench/bench_refit.py). The model then depends on the refit history as well.
        accuracy_window: number of most recent demonstrations the prediction accuracy is taken
            over (20 corridor, 150 driving); also the window of ``autonomy_rate``.
        target_accuracy: windowed accuracy in (0, 1] that ends the non-interactive phase;
            None = never switch.
        noninteractive: False starts directly in confident execution.
        burst: teacher moves per request in confident execution (10 in the driving domain).
        autonomous_steps_to_stop: stop after this many consecutive autonomous steps.
        autonomous_episodes_to_stop: stop after this many consecutive episodes that ended with
            no request and with ``info.get("is_success", True)`` truthy.
        max_demonstrations: stop when the session holds this many demonstrations.
        max_steps: stop when the session holds this many steps.

    The four stop fields count over the whole session for the two budgets and within one
    ``run`` call for the two streaks; ``run(**overrides)`` may change them per call.
    """

    max_new: int = 1
    refit: str = "full"
    accuracy_window: int = 20
    target_accuracy: float | None = 0.9
    noninteractive: bool = True
    burst: int = 1
    autonomous_steps_to_stop: int | None = None
    autonomous_episodes_to_stop: int | None = None
    max_demonstrations: int | None = None
    max_steps: int | None = None

    def __post_init__(self) -> None:
        _opt_int("max_new", self.max_new, minimum=1)
        if self.refit not in ("full", "incremental"):
            raise ValueError(
                f"TeachingConfig.refit: expected 'full' or 'incremental', got {self.refit!r}"
            )
        _opt_int("accuracy_window", self.accuracy_window, minimum=1)
        _opt_int("burst", self.burst, minimum=1)
        for name in ("max_new", "accuracy_window", "burst"):
            if getattr(self, name) is None:
                raise ValueError(f"TeachingConfig.{name}: expected an int >= 1, got None")
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

    def learning_fields(self) -> dict[str, Any]:
        """The fields a resumed session must share with its run directory (not the stops)."""
        return {
            f.name: getattr(self, f.name)
            for f in dataclasses.fields(self)
            if f.name not in STOP_FIELDS
        }


class GreedyPolicy:
    """A learned policy standing on its own: ``policy(obs [D]) -> int`` (Eq. 7, no asking).

    Holds the model by reference (the live model of a session keeps learning); deep-copy the
    policy or the model to freeze a snapshot. Picklable.
    """

    def __init__(self, model: torch.nn.Module) -> None:
        self.model = model

    def classify(self, observation: Any) -> Any:
        """The model's Classification of one observation [D] (batched fields of length 1)."""
        x = torch.as_tensor(np.asarray(observation, dtype=np.float64)).reshape(1, -1)
        return self.model.classify(x)

    def __call__(self, observation: Any) -> int:
        action = int(self.classify(observation).action[0])
        if action < 0:
            raise RuntimeError(
                "GreedyPolicy: the model is not fitted yet, so it has no action to give. "
                "Teach it first (ConfidentTeacher.run) or load a fitted checkpoint."
            )
        return action

    def __repr__(self) -> str:
        return f"GreedyPolicy({type(self.model).__name__})"


def _check_env(env: gym.Env) -> tuple[int, int]:
    """(n_features, n_actions) of a supported env, or a clear ValueError."""
    space = getattr(env, "action_space", None)
    if not isinstance(space, gym.spaces.Discrete) or int(space.start) != 0:
        raise ValueError(
            f"expected an env with a Discrete action space starting at 0, got {space!r}. "
            "Wrap the env so its actions are 0..n-1."
        )
    obs_space = getattr(env, "observation_space", None)
    if (
        not isinstance(obs_space, gym.spaces.Box)
        or len(obs_space.shape) != 1
        or not np.issubdtype(obs_space.dtype, np.floating)
    ):
        raise ValueError(
            f"expected an env with a 1-D float Box observation space, got {obs_space!r}. "
            "Flatten the observation (gymnasium.wrappers.FlattenObservation) and cast to float."
        )
    return int(obs_space.shape[0]), int(space.n)


def _as_action(value: Any, n_actions: int) -> int | None:
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        return None
    value = int(value)
    return value if 0 <= value < n_actions else None


def _model_args(model: torch.nn.Module) -> dict[str, Any]:
    args = getattr(model, "init_args", None)
    if isinstance(args, dict):
        return dict(args)
    missing = [n for n in _MODEL_ARG_NAMES if not hasattr(model, n)]
    if missing:
        raise ValueError(
            f"cannot record the constructor arguments of {type(model).__name__}: attributes "
            f"{missing} are missing. Pass a torchcbl.GaussianMixtureSet as model."
        )
    return {n: getattr(model, n) for n in _MODEL_ARG_NAMES}


def _is_fitted(model: Any) -> bool:
    return bool(getattr(model, "is_fitted", False))


def _seed_for(seed: int, episode: int) -> int:
    return int(np.random.SeedSequence([seed, episode]).generate_state(1)[0])


def _obs_array(obs: Any, n_features: int, where: str) -> np.ndarray:
    try:
        x = np.array(obs, dtype=np.float64)  # a copy: an env may reuse its buffer in place
    except (TypeError, ValueError) as exc:
        raise EnvError(f"{where}: observation is not numeric ({exc}).") from exc
    if x.shape != (n_features,):
        raise EnvError(
            f"{where}: expected an observation of shape ({n_features},), got {x.shape}. "
            "Check the env's observation_space."
        )
    if not np.isfinite(x).all():
        raise EnvError(
            f"{where}: the observation has non-finite values {x.tolist()}. Fix the env (or wrap "
            "it to clip / replace them); nothing non-finite is ever learned from."
        )
    return x


class ConfidentTeacher:
    """Teach a discrete-action policy, asking the teacher only where the model is unsure.

    Args:
        env: a ``gymnasium.Env`` with a ``Discrete`` action space (from 0) and a 1-D float
            ``Box`` observation space of size D.
        teacher: ``teacher(observation [D] ndarray, info dict) -> int`` in ``[0, n_actions)``.
            It gets a copy of the env's observation and the info of the latest reset / step.
        model: the learner; default ``GaussianMixtureSet(n_actions, D, seed=seed)``. Its
            ``fit`` must be deterministic given the data (resume relies on it).
        rule: the confidence rule; default ``DistanceRule(2.0)`` (the paper's).
        config: a :class:`TeachingConfig`.
        run_dir: if given, a new session directory (see :mod:`torchcbl.session`); it must not
            already hold a session (continue one with :meth:`resume`).
        seed: seeds the first ``env.reset`` (and the default model).
        progress: show a tqdm bar with the live counters while :meth:`run` runs.
        on_step: called with each :class:`StepRecord` after it is recorded.
        on_refit: called as ``on_refit(model, n_demonstrations)`` after each refit.
        commit_every: autonomous steps batched per commit at most (demonstrations are always
            committed before their action runs).

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
        rule: Any = None,
        config: TeachingConfig | None = None,
        run_dir: str | os.PathLike[str] | None = None,
        seed: int = 0,
        progress: bool = True,
        on_step: Callable[[StepRecord], None] | None = None,
        on_refit: Callable[[torch.nn.Module, int], None] | None = None,
        commit_every: int = 32,
    ) -> None:
        self._setup(env, teacher, model, rule, config, seed, progress, on_step, on_refit)
        self._env_config = self._describe_env()
        self._store: SessionStore | None = None
        self.run_dir = None if run_dir is None else Path(run_dir)
        if self.run_dir is not None:
            session_config = {
                "format": FORMAT,
                "teaching": dataclasses.asdict(self.config),
                "model": {"class": type(self.model).__name__, "args": _model_args(self.model)},
                "rule": rule_to_config(self.rule),
                "env": self._env_config,
                "seed": self.seed,
            }
            self._store = SessionStore.create(self.run_dir, session_config)
            self._store.commit_every = commit_every
            if _is_fitted(self.model):  # a session may start from a fitted model
                self._store.save_checkpoint(self.model, 0)
        self._next_reset_seed: int | None = self.seed

    def _setup(self, env, teacher, model, rule, config, seed, progress, on_step, on_refit):
        self.n_features, self.n_actions = _check_env(env)
        if not callable(teacher):
            raise TypeError(
                f"teacher: expected a callable teacher(observation, info) -> int, got {teacher!r}"
            )
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise TypeError(f"seed: expected an int, got {seed!r}")
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
        self.model = model
        self.rule = DistanceRule() if rule is None else rule
        if not (
            callable(getattr(self.rule, "is_confident", None))
            and callable(getattr(self.rule, "update", None))
        ):
            raise TypeError(
                f"rule: expected a ConfidenceRule (is_confident and update), got {self.rule!r}"
            )
        self.progress = bool(progress)
        self.on_step = on_step
        self.on_refit = on_refit
        self.records: list[StepRecord] = []
        w = self.config.accuracy_window
        self._acc_window: deque[bool] = deque(maxlen=w)
        self._auto_window: deque[bool] = deque(maxlen=w)
        self._demo_x: list[np.ndarray] = []
        self._demo_y: list[int] = []
        self._new_since_refit = 0
        self._phase = "noninteractive" if self.config.noninteractive else "confident"
        self._burst_left = 0
        self._needs_reset = True
        self._next_episode = 0
        self._episode = 0
        self._episode_had_demo = False
        self._auto_steps_streak = 0
        self._auto_episodes_streak = 0
        #: why the last :meth:`run` returned: "max_demonstrations", "max_steps",
        #: "autonomous_steps", "autonomous_episodes", or None before any run.
        self.stop_reason: str | None = None
        self._obs: np.ndarray | None = None
        self._raw_obs: Any = None
        self._info: dict = {}

    def _describe_env(self) -> dict[str, Any]:
        spec = getattr(self.env, "spec", None)
        return {
            "id": getattr(spec, "id", None),
            "n_features": self.n_features,
            "n_actions": self.n_actions,
            "observation_space": repr(self.env.observation_space),
        }

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
        config: TeachingConfig | None = None,
        progress: bool = True,
        on_step: Callable[[StepRecord], None] | None = None,
        on_refit: Callable[[torch.nn.Module, int], None] | None = None,
        commit_every: int = 32,
    ) -> ConfidentTeacher:
        """Continue a session from its run directory, killed or cleanly stopped.

        The counters (steps, episodes, demonstrations, accuracy and autonomy windows, phase)
        are rebuilt from the log; the model is the checkpoint matching the logged
        demonstrations, or is refitted on them deterministically if that checkpoint is missing.
        A demonstration logged but never executed (the process died in between) is kept.
        The env is reset into a new episode (seeded from the session seed and episode index).

        Args:
            config: optional; its stop fields may differ from the stored ones, the learning
                fields may not. ``model`` / ``rule``: optional; must match the stored ones
                (a custom rule that cannot be rebuilt must be passed).

        Raises:
            IncompatibleRunDirError: the directory is not a session, or it was written for a
                different env, model, rule or learning configuration.
        """
        stored = load_config(run_dir)
        problems: list[str] = []
        n_features, n_actions = _check_env(env)
        senv = stored["env"]
        if (senv["n_features"], senv["n_actions"]) != (n_features, n_actions):
            problems.append(
                f"env: the session has {senv['n_features']} features and {senv['n_actions']} "
                f"actions, the given env {n_features} and {n_actions}"
            )
        spec_id = getattr(getattr(env, "spec", None), "id", None)
        if senv.get("id") and spec_id and senv["id"] != spec_id:
            problems.append(f"env id: the session used {senv['id']!r}, got {spec_id!r}")
        try:
            stored_config = TeachingConfig(**stored["teaching"])
        except TypeError as exc:
            raise IncompatibleRunDirError(f"{run_dir}: unreadable TeachingConfig: {exc}") from exc
        if config is None:
            config = stored_config
        elif config.learning_fields() != stored_config.learning_fields():
            diff = {
                k: (v, config.learning_fields()[k])
                for k, v in stored_config.learning_fields().items()
                if config.learning_fields()[k] != v
            }
            problems.append(f"config (stored, given): {diff}; only the stop fields may change")
        if model is None:
            if not problems:
                model = build_model(stored)
        else:
            try:
                args = _model_args(model)
            except ValueError as exc:
                args = {"error": str(exc)}
            if args != stored["model"]["args"]:
                problems.append(f"model args: stored {stored['model']['args']}, given {args}")
        if rule is None:
            try:
                rule = rule_from_config(stored["rule"])
            except (ValueError, TypeError) as exc:
                problems.append(str(exc))
        elif not rule_to_config(rule).get("custom") and rule_to_config(rule) != stored["rule"]:
            problems.append(f"rule: stored {stored['rule']}, given {rule_to_config(rule)}")
        if problems:
            raise IncompatibleRunDirError(
                f"cannot resume the session in {run_dir}: "
                + "; ".join(problems)
                + ". Resume with matching arguments, or start a new session in another run_dir."
            )
        self = cls.__new__(cls)
        self._setup(env, teacher, model, rule, config, stored["seed"], progress, on_step, on_refit)
        self._env_config = self._describe_env()
        self.run_dir = Path(run_dir)
        self._store = SessionStore(self.run_dir, commit_every=commit_every)
        self._store.finalize_pending()
        self._restore(self._store.records())
        return self

    def _restore(self, records: list[StepRecord]) -> None:
        self.records = records
        for r in records:
            if r.teacher_action is not None:
                self._demo_x.append(r.observation_array)
                self._demo_y.append(r.teacher_action)
                self._acc_window.append(r.model_action == r.teacher_action)
            if r.phase == "confident":
                self._auto_window.append(r.autonomous)
        n = len(self._demo_y)
        k = fitted_count(self.run_dir, n, self.config.max_new)
        assert self._store is not None
        ckpt = latest_checkpoint(self.run_dir, at_most=k)
        if ckpt is not None and ckpt[0] == k:
            self.model.load_state_dict(torch.load(ckpt[1], weights_only=True)["state_dict"])
        elif k > 0 and self.config.refit == "incremental":
            x, y = np.stack(self._demo_x), np.asarray(self._demo_y)
            replay_refits(self.model, self.run_dir, x, y, k, self.config.max_new)
            self._store.save_checkpoint(self.model, k)
        elif k > 0:
            self.model.fit(np.stack(self._demo_x[:k]), np.asarray(self._demo_y[:k]))
            self._store.save_checkpoint(self.model, k)
        if k > 0:
            self.rule.update(self.model, np.stack(self._demo_x[:k]), np.asarray(self._demo_y[:k]))
        self._new_since_refit = n - k
        if any(r.phase == "confident" for r in records) or self._target_reached():
            self._phase = "confident"
        self._next_episode = records[-1].episode + 1 if records else 0
        self._next_reset_seed = _seed_for(self.seed, self._next_episode)

    # -- counters ---------------------------------------------------------------------------

    @property
    def n_demonstrations(self) -> int:
        """Demonstrations (steps with a teacher label) in the session."""
        return len(self._demo_y)

    @property
    def n_steps(self) -> int:
        """Steps in the session."""
        return len(self.records)

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
        """``"noninteractive"`` or ``"confident"``: the phase of the next step."""
        return self._phase

    @property
    def policy(self) -> GreedyPolicy:
        """The learned policy as a callable obs -> action (live; deep-copy to freeze)."""
        return GreedyPolicy(self.model)

    def _target_reached(self) -> bool:
        t = self.config.target_accuracy
        w = self._acc_window
        return t is not None and len(w) == w.maxlen and sum(w) / len(w) >= t

    # -- the loop ---------------------------------------------------------------------------

    def _reset(self) -> None:
        seed, self._next_reset_seed = self._next_reset_seed, None
        try:
            raw, info = self.env.reset(seed=seed)
        except Exception as exc:
            raise EnvError(f"env.reset raised {type(exc).__name__}: {exc}") from exc
        self._obs = _obs_array(raw, self.n_features, "env.reset")
        self._raw_obs, self._info = raw, dict(info or {})
        self._episode = self._next_episode
        self._next_episode += 1
        self._needs_reset = False
        self._episode_had_demo = False
        self._burst_left = 0

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
        action = _as_action(answer, self.n_actions)
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
        """
        if self._new_since_refit == 0 or not self._demo_y:
            return False
        self._refit()
        return True

    def snapshot(self) -> torch.nn.Module:
        """A copy of the model fitted on every demonstration so far, leaving the session as it
        is (its model and refit schedule untouched): for evaluating a learning stage."""
        model = copy.deepcopy(self.model)
        if self._new_since_refit and self._demo_y:
            fit = model.refit if self.config.refit == "incremental" else model.fit
            fit(np.stack(self._demo_x), np.asarray(self._demo_y, dtype=np.int64))
        return model

    @property
    def autonomous_episodes_streak(self) -> int:
        """Consecutive episodes, in the current :meth:`run`, with no request and success."""
        return self._auto_episodes_streak

    @property
    def autonomous_steps_streak(self) -> int:
        """Consecutive autonomous steps in the current :meth:`run`."""
        return self._auto_steps_streak

    def _refit(self) -> None:
        x = np.stack(self._demo_x)
        y = np.asarray(self._demo_y, dtype=np.int64)
        (self.model.refit if self.config.refit == "incremental" else self.model.fit)(x, y)
        self.rule.update(self.model, x, y)
        self._new_since_refit = 0
        if self._store is not None:
            self._store.save_checkpoint(self.model, len(y))
        if self.on_refit is not None:
            self.on_refit(self.model, len(y))

    def step(self) -> StepRecord:
        """Take one decision (Algorithm 1) and return its record.

        Autonomous steps reach disk in batches; call :meth:`flush` (or let :meth:`run` do it)
        to commit them.
        """
        if self._needs_reset:
            self._reset()
        obs, info = self._obs, self._info
        assert obs is not None
        c = self.model.classify(obs[None])
        model_action = int(_np(c.action)[0])
        confidence = float(_np(c.confidence)[0])
        distance = float(_np(c.distance)[0])
        posterior = tuple(_np(c.posterior)[0].tolist())
        phase = self._phase
        if phase == "noninteractive" or self._burst_left > 0:
            ask, burst_left = True, self._burst_left
        else:
            ask = not bool(self.rule.is_confident(c)[0])
            burst_left = self.config.burst if ask else 0
        teacher_action = self._ask(info) if ask else None
        # From here on the step happens: update the counters, then log.
        step = len(self.records)
        if ask:
            self._burst_left = max(burst_left - 1, 0) if phase == "confident" else 0
            self._acc_window.append(model_action == teacher_action)
            self._demo_x.append(obs)
            self._demo_y.append(teacher_action)  # type: ignore[arg-type]
            self._episode_had_demo = True
        if phase == "confident":
            self._auto_window.append(not ask)
        executed = teacher_action if ask else model_action
        record = StepRecord(
            step=step,
            episode=self._episode,
            observation=tuple(obs.tolist()),
            model_action=model_action,
            confidence=confidence,
            distance=distance,
            posterior=posterior,
            teacher_action=teacher_action,
            executed_action=executed,  # type: ignore[arg-type]
            phase=phase,  # type: ignore[arg-type]
            autonomous=not ask,
            reward=None,
            terminated=False,
            truncated=False,
            info={},
            n_demonstrations=len(self._demo_y),
            autonomy_rate=self.autonomy_rate,
            windowed_accuracy=self.windowed_accuracy,
        )
        if ask:
            if self._store is not None:
                self._store.commit_demonstration(record)  # durable before the action runs
            self._new_since_refit += 1
        try:
            record = self._execute(record)
        finally:
            # Refit once the step is complete (Algorithm 1 executes the teacher's action either
            # way), so a fit that fails leaves a whole step behind, not half of one.
            if ask and self._new_since_refit >= self.config.max_new:
                self._refit()
        if ask:
            self._auto_steps_streak = 0
        else:
            self._auto_steps_streak += 1
        if phase == "noninteractive" and self._target_reached():
            self._phase = "confident"
        if record.terminated or record.truncated:
            clean = (
                not self._episode_had_demo
                and phase == "confident"
                and bool(self._info.get("is_success", True))
            )
            self._auto_episodes_streak = self._auto_episodes_streak + 1 if clean else 0
        if self.on_step is not None:
            self.on_step(record)
        return record

    def _execute(self, record: StepRecord) -> StepRecord:
        error: str | None = None
        cause: BaseException | None = None
        reward: float | None = None
        terminated = truncated = False
        info: dict = {}
        try:
            raw, r, term, trunc, env_info = self.env.step(record.executed_action)
        except Exception as exc:
            error, cause = f"env.step raised {type(exc).__name__}: {exc}", exc
        else:
            info = dict(env_info or {})
            terminated, truncated = bool(term), bool(trunc)
            try:
                reward = float(r)
            except (TypeError, ValueError):
                reward = math.nan
            if not math.isfinite(reward):
                error, reward = f"env.step returned a non-finite reward {r!r}", None
            else:
                try:
                    self._obs = _obs_array(raw, self.n_features, "env.step")
                    self._raw_obs, self._info = raw, info
                except EnvError as exc:
                    error, cause = str(exc), exc
        if error is not None:
            truncated = True
            info = {"torchcbl_error": error}
        final = record.with_outcome(
            reward, terminated, truncated, jsonable_info(info) if error is None else info
        )
        self.records.append(final)
        if self._store is not None:
            if final.teacher_action is not None:
                self._store.finish(final)
            else:
                self._store.append(final)
        if terminated or truncated:
            self._needs_reset = True
            self._burst_left = 0
        if error is not None:
            if self._store is not None:
                self._store.commit()
            raise EnvError(
                f"{error} (step {final.step}, action {final.executed_action}). The step is "
                "logged with the episode cut (truncated); call run() again to continue from a "
                "fresh episode, or resume the run directory."
            ) from cause
        return final

    def run(self, **stop_overrides: int | None) -> ConfidentTeacher:
        """Teach until a stop criterion holds; may be called again to continue.

        Args:
            **stop_overrides: any of ``autonomous_steps_to_stop``,
                ``autonomous_episodes_to_stop``, ``max_demonstrations``, ``max_steps``, for
                this call only (e.g. ``run(max_demonstrations=50)`` then
                ``copy.deepcopy(teacher.model)`` to snapshot the model at a stage).

        Raises:
            ValueError: unknown override, or no stop criterion at all (it would never end).
        """
        unknown = sorted(set(stop_overrides) - set(STOP_FIELDS))
        if unknown:
            raise ValueError(f"run(): unknown stop criteria {unknown}; expected {STOP_FIELDS}")
        cfg = dataclasses.replace(self.config, **stop_overrides)
        if all(getattr(cfg, name) is None for name in STOP_FIELDS):
            raise ValueError(
                "run(): no stop criterion is set, so it would never end. Set one of "
                f"{STOP_FIELDS} in TeachingConfig or as run(...) arguments."
            )
        self._auto_steps_streak = 0
        self._auto_episodes_streak = 0
        self.stop_reason = None
        from tqdm.auto import tqdm

        total = None if cfg.max_steps is None else max(cfg.max_steps - self.n_steps, 0)
        bar = tqdm(total=total, disable=not self.progress, unit="step", desc="teaching")
        try:
            while True:
                if cfg.max_demonstrations is not None and (
                    self.n_demonstrations >= cfg.max_demonstrations
                ):
                    self.stop_reason = "max_demonstrations"
                    break
                if cfg.max_steps is not None and self.n_steps >= cfg.max_steps:
                    self.stop_reason = "max_steps"
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
        finally:
            self.flush()
            if self.progress:
                bar.set_postfix_str(self._postfix())
            bar.close()
        return self

    def _postfix(self) -> str:
        def pct(v: float | None) -> str:
            return "-" if v is None else f"{100 * v:.0f}%"

        return (
            f"{self._phase} demos={self.n_demonstrations} "
            f"autonomy={pct(self.autonomy_rate)} acc={pct(self.windowed_accuracy)}"
        )

    def flush(self) -> None:
        """Commit any batched autonomous steps to the run directory (no-op without one)."""
        if self._store is not None:
            self._store.commit()

    def close(self) -> None:
        """Commit and close the step log. The session can be resumed from its directory."""
        if self._store is not None:
            self._store.close()
            self._store = None

    def __enter__(self) -> ConfidentTeacher:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return (
            f"ConfidentTeacher(steps={self.n_steps}, demonstrations={self.n_demonstrations}, "
            f"phase={self._phase!r}, run_dir={str(self.run_dir) if self.run_dir else None!r})"
        )


def evaluate_policy(
    policy: Callable[[np.ndarray], int],
    env: gym.Env,
    *,
    n_steps: int | None = None,
    n_episodes: int | None = None,
    seed: int | None = None,
    uses_info: bool = False,
) -> list[StepRecord]:
    """Run a policy greedily (never asking) and return one record per step.

    ``policy`` is called as ``policy(observation)``; with ``uses_info=True`` it is called as a
    teacher, ``policy(observation, info)`` with the info of the latest reset / step, so a
    scripted expert can be evaluated exactly like a learned policy.

    Episodes that end are reset (the first reset with ``seed``, later ones continuing the env's
    RNG) until ``n_steps`` steps or ``n_episodes`` finished episodes, whichever comes first.
    Records have ``phase="evaluation"``, ``autonomous=True``; a :class:`GreedyPolicy` also fills
    the confidence fields, any other callable leaves them None.
    """
    n_features, n_actions = _check_env(env)
    if n_steps is None and n_episodes is None:
        raise ValueError("evaluate_policy: give n_steps and/or n_episodes, or it never ends")
    for name, v in (("n_steps", n_steps), ("n_episodes", n_episodes)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
            raise ValueError(f"evaluate_policy: {name} must be an int >= 1, got {v!r}")
    records: list[StepRecord] = []
    raw, info = env.reset(seed=seed)
    obs = _obs_array(raw, n_features, "env.reset")
    episode, done_episodes = 0, 0
    while (n_steps is None or len(records) < n_steps) and (
        n_episodes is None or done_episodes < n_episodes
    ):
        confidence = distance = posterior = None
        if isinstance(policy, GreedyPolicy):
            c = policy.classify(obs)
            answer: Any = int(c.action[0])
            confidence, distance = float(c.confidence[0]), float(c.distance[0])
            posterior = tuple(c.posterior[0].tolist())
        elif uses_info:
            answer = policy(np.array(raw, copy=True), dict(info or {}))
        else:
            answer = policy(np.array(raw, copy=True))
        action = _as_action(answer, n_actions)
        if action is None:
            raise ValueError(
                f"evaluate_policy: the policy answered {answer!r}; expected an int in "
                f"[0, {n_actions}) (an unfitted GreedyPolicy answers -1)."
            )
        raw_next, r, term, trunc, info = env.step(action)
        try:
            reward = float(r)
        except (TypeError, ValueError):
            reward = math.nan
        if not math.isfinite(reward):
            raise EnvError(f"env.step returned a reward that is not a finite number: {r!r}")
        records.append(
            StepRecord(
                step=len(records),
                episode=episode,
                observation=tuple(obs.tolist()),
                model_action=action,
                confidence=confidence,
                distance=distance,
                posterior=posterior,
                teacher_action=None,
                executed_action=action,
                phase="evaluation",
                autonomous=True,
                reward=reward,
                terminated=bool(term),
                truncated=bool(trunc),
                info=jsonable_info(info),
            )
        )
        if term or trunc:
            done_episodes += 1
            episode += 1
            if n_episodes is not None and done_episodes >= n_episodes:
                break  # no reset after the last episode (for SUMO, a whole new road)
            raw, info = env.reset()
        else:
            raw = raw_next
        obs = _obs_array(raw, n_features, "env.step" if not (term or trunc) else "env.reset")
    return records
