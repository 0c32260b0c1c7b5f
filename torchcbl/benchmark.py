"""A benchmark of interactive imitation strategies: strategies x environments x seeds.

Every *cell* (one strategy, one environment, one seed) teaches a fresh
:class:`~torchcbl.gmm.GaussianMixtureSet` with :class:`~torchcbl.teaching.ConfidentTeacher`
and the strategy, with the same teacher, refit schedule and label budgets for every strategy.
At each label budget it snapshots the model (fitted on every label so far) and, after teaching,
evaluates each snapshot greedily on held-out seeds of the evaluation env. A cell records:

- the learning curve: ``[{"labels", "steps", "performance"}]``, one point per budget reached;
- teacher attention: labels (demonstrations + corrections), requests (steps the teacher was
  asked), monitored steps (requests, plus the autonomous steps a gating teacher had to watch:
  those of a strategy that wants corrections), context switches (changes of who acted between
  consecutive steps), corrections;
- wrong autonomous actions: steps on which the learner's action ran (autonomous steps, and
  DAgger's labelled steps executed by the learner) and differs from the teacher's choice in that
  state (asked of a second, separate teacher instance, so the teacher itself is not disturbed);
- the teacher's own performance on the same evaluation seeds (``teacher_performance``) and
  how many of its evaluation episodes ended (``teacher_episodes_ended``, over those seeds),
  wall and CPU time.

The core never imports a domain: an environment is a gymnasium id (``"module:Id"`` makes
gymnasium import the registering module first) and a teacher is an import path
``"module:factory"``, called as ``factory(env=env, seed=seed, **teacher_kwargs)`` (each of
``env`` and ``seed`` only if the factory takes it). The domains ship their presets
(``corridor.benchmark``, ``sumo_scenarios.benchmark``).

Cells are cached in ``OUT/cells/<hash>.json``, the hash being the first 20 hex digits of the
SHA-256 of the cell's canonical
JSON configuration: a rerun skips finished cells, and a killed sweep resumes where it stopped
(each cell is written atomically as it finishes). Cells run on a local process pool (one
simulation per process: libsumo allows one per process) or on Ray (``use_ray=True``, with
``ray_address`` for a cluster); every cell is deterministic, so both give the same figures.

Sessions (``keep_sessions=True``, ``torchcbl benchmark --keep-sessions``): each computed
cell's teaching is also written as a session directory (:mod:`torchcbl.session`)::

    OUT/sessions/<hash>/            the cell's session (same hash as its cells/<hash>.json):
                                    config.json (the teaching env's id and make() arguments,
                                    strategy, TeachingConfig, the cell's seed), steps.sqlite
                                    (every step, with the teacher's label where it gave one;
                                    corrections), checkpoints/ (the model at its newest
                                    refits: 3 by default, ``keep_checkpoints=``, None for
                                    every one; ``--keep-checkpoints N|all``)
    OUT/sessions/<hash>.stale-N     a session a killed or failed cell left; set aside, not
                                    removed, when the cell is computed again

read with :func:`~torchcbl.session.load_records`, :func:`~torchcbl.session.load_labels`,
:func:`~torchcbl.session.load_demonstrations` and :func:`~torchcbl.session.load_model`
(``load_model(path, n_demonstrations=labels)`` is the model as the loop had it, its last
refit; a curve point's snapshot is fitted on every label so far: the same model where
``labels`` is a refit point). The session holds the teaching only: the evaluations, the
auditor's answers and the attention figures stay in the cell's JSON. Keeping sessions is not
part of a cell's configuration (the figures and the hash are the same either way); a cached
cell keeps the session it has and is not computed again for one. With Ray, each session is
written by the worker that runs its cell, at the absolute path of ``OUT/sessions`` on that
worker's machine: on a cluster without a shared file system, the sessions stay on the nodes.

Results: ``OUT/results.json`` with, per (strategy, environment), ``labels_to_95pct`` (labels
at which the performance first reaches 95 % of the teacher's; mean, sd, n; runs that never
reach it are censored at their last label count and marked), performance at each budget
(each seed's model of at most that many labels; ``n_reached``: the seeds that held them),
``final_performance``, attention and times; ``paired``: each strategy against
:data:`REFERENCE_STRATEGY` (confident execution) seed by seed, at each budget the per-seed
difference's mean, sd, n and 95 % t interval (:func:`summarize`); ``OUT/learning_curves.png``
(performance vs labels, one panel per environment, a line per strategy with a band of +-1 sd
over seeds).
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import inspect
import json
import math
import os
import sys
import time
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from torchcbl._checkpoints import DEFAULT_KEEP_CHECKPOINTS, is_keep_count
from torchcbl._durable import write_durably
from torchcbl._text import one_line
from torchcbl.evaluation import (
    figure_style,
    mean_sd,
    paired_interval,
    run_versions,
    save_whole,
    worker_pool,
)
from torchcbl.records import _is_int

__all__ = [
    "CELL_FORMAT",
    "CellError",
    "EnvSpec",
    "STRATEGY_PATHS",
    "REFERENCE_STRATEGY",
    "StrategySpec",
    "cell_configs",
    "cell_key",
    "no_penalty_share",
    "run_benchmark",
    "run_cell",
    "success_rate",
    "summarize",
]

CELL_FORMAT = 5
"""Bumped when a cell's computation changes, so old cached cells are not reused (2: a strategy
that takes a ``seed``, DAgger's coins, is seeded by the cell's seed unless its params give one;
in format 1 every cell drew DAgger's coins from seed 0. 4: a timed human teacher,
:class:`~torchcbl.teachers.HumanTiming`, the driving default, corrects with a key press (or,
where it wants the default action and the learner did another, with the default at once), never
with a press still pending or lost, and presses nothing where the learner does what it wants; in
format 2 a pending or lost press counted as a correction to the default action, and format 3,
a day's intermediate, still drew presses, and so doubled ones, where the learner agreed. 5: a
cell's attention holds ``wrong_autonomous_rate`` and ``auditor_disagreement``)."""

#: short strategy names -> import path of the class.
STRATEGY_PATHS: dict[str, str] = {
    "bc": "torchcbl.strategies.bc:BehaviourCloning",
    "dagger": "torchcbl.strategies.dagger:DAgger",
    "hg_dagger": "torchcbl.strategies.hg_dagger:HGDAgger",
    "novelty": "torchcbl.strategies.novelty:NoveltyGated",
    "confident": "torchcbl.strategies:ConfidentExecution",
    "cba": "torchcbl.strategies.cba:ConfidenceBasedAutonomy",
}


#: the strategy every other is paired with, seed by seed, in ``results.json``'s ``paired``: the
#: paper's confident execution (a :class:`StrategySpec` of this name, whatever its label).
REFERENCE_STRATEGY = "confident"


def _import(path: str) -> Any:
    """The object at ``"package.module:attr"`` (``attr`` may be dotted)."""
    if not isinstance(path, str) or ":" not in path:
        raise ValueError(f"expected an import path 'package.module:name', got {path!r}")
    module, _, attr = path.partition(":")
    obj: Any = importlib.import_module(module)
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise ImportError(
                f"cannot import {path!r}: {module!r} has no attribute {attr!r}; expected an "
                "import path 'package.module:name' of an existing object"
            ) from None
    return obj


def _check_imports(strategies: Sequence[StrategySpec], envs: Sequence[EnvSpec]) -> None:
    """Resolve every import path of a benchmark (strategies, teachers, scores, gymnasium
    registration modules) before anything runs: a misspelt name fails at once, with an
    ImportError that names it, not in a worker after other cells have run. Each strategy is
    made once from its params too, so a misspelt or refused parameter, or a class that lacks
    a method the loop calls, is a ValueError naming the strategy now, not after every cell of
    the strategies before it."""
    from torchcbl.teaching import TeachingConfig, _pick_strategy

    for s in strategies:
        _import(STRATEGY_PATHS.get(s.name, s.name))
        try:
            strategy = s.build(seed=0)
        except Exception as exc:  # the class's own refusal of its arguments, whatever it is
            text = one_line(exc)
            raise ValueError(
                f"StrategySpec {s.title!r}: cannot make {s.name} with params "
                f"{dict(s.params)}: {type(exc).__name__}: {text}; fix its params (the keyword "
                "arguments of its constructor)"
            ) from exc
        try:  # the loop's own check, as the cell would make it
            _pick_strategy(None, strategy)
        except TypeError as exc:
            raise ValueError(f"StrategySpec {s.title!r}: {exc}") from None

    for s in strategies:
        for e in envs:
            if s.teaching:
                try:
                    TeachingConfig(**{**dict(e.teaching), **dict(s.teaching)})
                except (TypeError, ValueError) as exc:
                    raise ValueError(
                        f"StrategySpec {s.title!r}: its teaching {dict(s.teaching)} over EnvSpec "
                        f"{e.name!r}'s {dict(e.teaching)}: {exc}"
                    ) from None
    for e in envs:
        factory = _import(e.teacher)
        try:
            params = inspect.signature(factory).parameters
        except (TypeError, ValueError):  # no signature to read: the cell will tell
            params = None
        if params is not None:
            given = {k: None for k in ("env", "seed") if k in params}
            taken = sorted(set(given) & set(e.teacher_kwargs))
            try:
                if taken:
                    raise TypeError(f"{taken} come from the cell; leave them out")
                inspect.signature(factory).bind_partial(**given, **dict(e.teacher_kwargs))
            except TypeError as exc:
                raise ValueError(
                    f"EnvSpec {e.name!r}: teacher_kwargs {dict(e.teacher_kwargs)} do not fit "
                    f"{e.teacher}{inspect.signature(factory)}: {exc} (it is called as "
                    "factory(env=..., seed=..., **teacher_kwargs), each of env and seed only if "
                    "it takes it)"
                ) from None
            try:  # every argument the call does not give has a default
                inspect.signature(factory).bind(**given, **dict(e.teacher_kwargs))
            except TypeError as exc:
                names = ", ".join(params)
                raise ValueError(
                    f"EnvSpec {e.name!r}: teacher {e.teacher!r} must name a factory that "
                    "returns the teacher, called as factory(env=..., seed=..., "
                    "**teacher_kwargs) (env and seed only if it takes them), but "
                    f"{e.teacher}({names}) needs arguments that call does not give ({exc}); "
                    "give them in teacher_kwargs or, if it is the teacher itself, name a "
                    "factory that returns it (e.g. def make_teacher(env): return my_teacher)"
                ) from None
        _import(e.score)
        module, _, env_id = e.env_id.rpartition(":")  # as gymnasium.make reads "module:Id"
        if module:
            importlib.import_module(module)
        try:
            gym.spec(env_id)
        except gym.error.Error as exc:  # a misspelt or unregistered id
            raise ValueError(
                f"EnvSpec {e.name!r}: env_id {e.env_id!r}: {exc}; expected a registered "
                "gymnasium id ('module:Id' imports the module that registers it first)"
            ) from None


def _check_teaching(teaching: Mapping[str, Any], where: str) -> None:
    """``teaching`` as TeachingConfig learning fields, or a ValueError naming ``where``: an
    unknown key is named with the fields there are (not Python's "unexpected keyword")."""
    import dataclasses

    from torchcbl.teaching import _STOP_SETTINGS, TeachingConfig

    names = {f.name for f in dataclasses.fields(TeachingConfig)}
    unknown = [k for k in teaching if k not in names]
    if unknown:
        learning = sorted(names - set(_STOP_SETTINGS))
        raise ValueError(
            f"{where}: unknown field{'s' if len(unknown) > 1 else ''} "
            f"{', '.join(map(repr, unknown))}; expected TeachingConfig's learning fields "
            f"{learning}"
        )
    stops = [k for k in _STOP_SETTINGS if k in teaching]
    if stops:  # a cell stops at each budget and at max_steps, and nowhere else
        raise ValueError(
            f"{where}: {stops} say when to stop, which a cell decides (each of budgets, then "
            "max_steps); give TeachingConfig's learning fields only"
        )
    try:  # a refused value now, not in the first cell
        TeachingConfig(**teaching)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def _json_plain(value: Any, where: str) -> Any:
    """``value`` with numpy scalars as the Python numbers they hold (np.int64(10) -> 10), or a
    ValueError naming ``where`` for anything that is not a JSON value: a cell's configuration is
    hashed into its cache key and written with the cell, so a parameter must be one (before,
    a numpy int got a key of its own and then failed the cell's write after it had run)."""
    if isinstance(value, np.generic):
        value = value.item()
    if value is None or isinstance(value, (str, bool, int, float)):
        return value
    if isinstance(value, Mapping):
        return {k: _json_plain(v, f"{where}[{k!r}]") for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        items = [_json_plain(v, f"{where}[{i}]") for i, v in enumerate(value)]
        return items if isinstance(value, list) else tuple(items)
    raise ValueError(
        f"{where} = {value!r} is not a JSON value (a cell's configuration is stored as JSON "
        "and hashed into its cache key); give numbers, strings, bools, None, lists or dicts"
    )


@dataclass(frozen=True)
class StrategySpec:
    """A strategy by name and constructor arguments.

    Attributes:
        name: a key of :data:`STRATEGY_PATHS` or an import path ``"module:Class"``.
        params: keyword arguments of the class, JSON values (numpy scalars are taken as the
            numbers they hold; they are part of the cells' cache key). For ``"confident"``, the
            :class:`~torchcbl.confidence.DistanceRule`'s (``max_std``, default 2, or
            ``quantile``): ``ConfidentExecution(DistanceRule(**params))``.
        label: the name in tables and plots (default: ``name``).
        teaching: :class:`~torchcbl.teaching.TeachingConfig` learning fields that this
            strategy's cells take over the env's ``teaching`` (JSON values, part of the cells'
            key), e.g. ``{"noninteractive": False}`` for CBA as JAIR 2009 publishes it,
            without confident execution's non-interactive phase.
    """

    name: str
    params: Mapping[str, Any] = field(default_factory=dict)
    label: str | None = None
    teaching: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or (
            self.name not in STRATEGY_PATHS and ":" not in self.name
        ):
            raise ValueError(
                f"StrategySpec: name must be one of {sorted(STRATEGY_PATHS)} or an import path "
                f"'module:Class', got {self.name!r}"
            )
        if not isinstance(self.params, Mapping):
            raise ValueError(f"StrategySpec {self.name!r}: params must be a mapping")
        if self.label is not None and not isinstance(self.label, str):
            raise ValueError(f"StrategySpec {self.name!r}: label must be a str or None")
        object.__setattr__(
            self, "params", _json_plain(self.params, f"StrategySpec {self.name!r}: params")
        )
        if not isinstance(self.teaching, Mapping):
            raise ValueError(
                f"StrategySpec {self.name!r}: teaching must be a mapping of TeachingConfig "
                f"fields, got {self.teaching!r}"
            )
        teaching = _json_plain(self.teaching, f"StrategySpec {self.name!r}: teaching")
        _check_teaching(teaching, f"StrategySpec {self.name!r}: teaching")
        object.__setattr__(self, "teaching", teaching)

    @property
    def title(self) -> str:
        """The name shown in tables and plots."""
        return self.label or self.name

    def build(self, seed: int | None = None) -> Any:
        """A fresh strategy object; ``seed`` (a cell's seed) seeds a strategy whose constructor
        takes one (DAgger's coins) unless ``params`` give it, so that the seeds of a sweep are
        independent repeats."""
        path = STRATEGY_PATHS.get(self.name, self.name)
        params = dict(self.params)
        if self.name == "confident":
            from torchcbl.confidence import DistanceRule
            from torchcbl.strategies import ConfidentExecution

            return ConfidentExecution(DistanceRule(**params))
        cls = _import(path)
        if seed is not None and "seed" not in params:
            try:
                takes_seed = "seed" in inspect.signature(cls).parameters
            except (TypeError, ValueError):  # no signature to read
                takes_seed = False
            if takes_seed:
                params["seed"] = int(seed)
        return cls(**params)

    def to_dict(self) -> dict[str, Any]:
        out = {"name": self.name, "params": dict(self.params), "label": self.title}
        if self.teaching:  # (absent when empty: the cells of a spec without it keep their key)
            out["teaching"] = dict(self.teaching)
        return out


@dataclass(frozen=True)
class EnvSpec:
    """An environment with its teacher, score and budgets.

    Attributes:
        name: the name in tables and plots.
        env_id: gymnasium id; ``"module:Id"`` imports ``module`` (which registers it) first.
        teacher: import path of ``factory(env=..., seed=..., **teacher_kwargs) -> teacher``.
        budgets: label budgets at which the model is snapshotted (increasing).
        max_steps: cap on teaching steps per cell (a strategy that stops asking ends here); at
            least the last budget (a step brings one label at most).
        env_kwargs: ``gymnasium.make`` keyword arguments of the teaching env.
        eval_env_kwargs: overrides of ``env_kwargs`` for the evaluation env.
        teacher_kwargs: extra keyword arguments of the teacher factory.
        score: import path of ``score(records) -> float`` (finite, higher is better) over
            the evaluation records of one seed; default :func:`success_rate`.
        eval_seeds: held-out reset seeds of the evaluation env (one evaluation each).
        eval_episodes: episodes per evaluation (or None).
        eval_steps: steps per evaluation (or None; at least one of the two). Without it, on
            an env with no step cap (no TimeLimit: registered without
            ``max_episode_steps``; no ``max_episode_steps`` attribute of its own, as the
            corridor's), an evaluation of ``eval_episodes`` episodes gets at most 10,000 steps
            per episode (``max_steps`` where more) in all: if its episodes have not all ended
            by then, the cell stops with an error saying to give ``eval_steps`` (an episode
            that never ends would run for ever); where they end sooner, it is evaluated as
            without the cap.
        teaching: :class:`~torchcbl.teaching.TeachingConfig` fields, learning ones only (a
            stop criterion such as ``max_episodes`` is refused: a cell stops at its budgets
            and ``max_steps``).
        model: :class:`~torchcbl.gmm.GaussianMixtureSet` keyword arguments (not n_actions,
            n_features, seed).

    The five mappings hold JSON values (numpy scalars are taken as the numbers they hold): the
    spec is a cell's configuration, hashed into its cache key.
    """

    name: str
    env_id: str
    teacher: str
    budgets: tuple[int, ...]
    max_steps: int
    env_kwargs: Mapping[str, Any] = field(default_factory=dict)
    eval_env_kwargs: Mapping[str, Any] = field(default_factory=dict)
    teacher_kwargs: Mapping[str, Any] = field(default_factory=dict)
    score: str = "torchcbl.benchmark:success_rate"
    eval_seeds: tuple[int, ...] = (1_000_000,)
    eval_episodes: int | None = None
    eval_steps: int | None = None
    teaching: Mapping[str, Any] = field(default_factory=dict)
    model: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        try:
            b = [] if isinstance(self.budgets, (str, bytes)) else list(self.budgets)
        except TypeError:  # not a sequence
            b = []
        if not b or any(not _is_int(x) or x < 1 for x in b) or b != sorted(set(b)):
            raise ValueError(
                f"EnvSpec {self.name!r}: budgets must be increasing ints >= 1, got {self.budgets!r}"
            )
        if not _is_int(self.max_steps) or self.max_steps < 1:
            raise ValueError(
                f"EnvSpec {self.name!r}: max_steps must be an int >= 1, got {self.max_steps!r}"
            )
        above = [int(x) for x in b if x > self.max_steps]
        if above:  # a step brings one label at most (a request's, or a correction's)
            raise ValueError(
                f"EnvSpec {self.name!r}: budgets {above} are above max_steps {self.max_steps}; "
                "a cell takes at most one label per step, so no strategy could reach them and "
                "their performance_at_budget would be read at fewer labels; raise max_steps "
                "or drop those budgets"
            )
        if self.eval_episodes is None and self.eval_steps is None:
            raise ValueError(f"EnvSpec {self.name!r}: give eval_episodes and/or eval_steps")
        for name in ("eval_episodes", "eval_steps"):
            v = getattr(self, name)
            if v is not None and (not _is_int(v) or v < 1):
                raise ValueError(
                    f"EnvSpec {self.name!r}: {name} must be None or an int >= 1, got {v!r}"
                )
        if not isinstance(self.name, str):
            raise ValueError(f"EnvSpec: name must be a str, got {self.name!r}")
        try:
            seeds = [] if isinstance(self.eval_seeds, (str, bytes)) else list(self.eval_seeds)
        except TypeError:  # not a sequence
            seeds = []
        if not seeds or any(not _is_int(s) or s < 0 for s in seeds):
            raise ValueError(
                f"EnvSpec {self.name!r}: eval_seeds must be a non-empty tuple of ints >= 0, "
                f"got {self.eval_seeds!r}"
            )
        # stored as plain ints: the spec's JSON (the cache key of its cells) is the same for
        # numpy ints as for the ints they hold
        plain = object.__setattr__
        plain(self, "budgets", tuple(int(x) for x in b))
        plain(self, "eval_seeds", tuple(int(x) for x in seeds))
        plain(self, "max_steps", int(self.max_steps))
        for name in ("eval_episodes", "eval_steps"):
            if getattr(self, name) is not None:
                plain(self, name, int(getattr(self, name)))
        for name in ("env_kwargs", "eval_env_kwargs", "teacher_kwargs", "teaching", "model"):
            value = getattr(self, name)
            if not isinstance(value, Mapping):
                raise ValueError(f"EnvSpec {self.name!r}: {name} must be a mapping, got {value!r}")
            plain(self, name, _json_plain(value, f"EnvSpec {self.name!r}: {name}"))
        # what every worker would fail on at its first cell, checked now
        from torchcbl.gmm import GaussianMixtureSet

        _check_teaching(self.teaching, f"EnvSpec {self.name!r}: teaching")
        taken = {"n_actions", "n_features", "seed"} & set(self.model)
        if taken:
            raise ValueError(
                f"EnvSpec {self.name!r}: model: {sorted(taken)} come from the env and the cell's "
                "seed; leave them out"
            )
        try:
            inspect.signature(GaussianMixtureSet).bind(2, 2, **dict(self.model))
        except TypeError as exc:
            raise ValueError(
                f"EnvSpec {self.name!r}: model: {exc} (GaussianMixtureSet's keyword arguments)"
            ) from None
        if ":" not in self.score:
            raise ValueError(
                f"EnvSpec {self.name!r}: score must be an import path 'module:function', "
                f"got {self.score!r}"
            )
        if ":" not in self.teacher:
            raise ValueError(
                f"EnvSpec {self.name!r}: teacher must be an import path 'module:factory', "
                f"got {self.teacher!r}"
            )

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        for k in ("env_kwargs", "eval_env_kwargs", "teacher_kwargs", "teaching", "model"):
            d[k] = dict(d[k])
        d["budgets"] = list(self.budgets)
        d["eval_seeds"] = list(self.eval_seeds)
        return d


# -- scores -----------------------------------------------------------------------------------


def success_rate(records: Sequence[Any]) -> float:
    """Share of the finished episodes that ended with ``info["is_success"]`` truthy (an
    evaluation cut before any episode ended scores 0)."""
    ends = [r for r in records if r.terminated or r.truncated]
    if not ends:
        return 0.0
    return sum(1 for r in ends if r.info.get("is_success")) / len(ends)


def no_penalty_share(records: Sequence[Any]) -> float:
    """Share of the steps with a reward >= 0 (the driving domain: 1 - collision rate)."""
    if not records:
        raise ValueError("no_penalty_share: no evaluation steps")
    return sum(1 for r in records if (r.reward or 0.0) >= 0) / len(records)


# the range of the shipped scores (shares): plot_curves clips their +-1 sd band to it; a score
# of one's own, whose range is not known, has its band drawn unclipped
_SCORE_RANGES: dict[str, tuple[float, float]] = {
    "torchcbl.benchmark:success_rate": (0.0, 1.0),
    "torchcbl.benchmark:no_penalty_share": (0.0, 1.0),
}


# -- one cell ---------------------------------------------------------------------------------


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)


def cell_key(config: Mapping[str, Any]) -> str:
    """The cache key of a cell: the first 20 hex digits of SHA-256 of its canonical JSON."""
    return hashlib.sha256(_canonical(config).encode()).hexdigest()[:20]


def cell_configs(
    strategies: Sequence[StrategySpec], envs: Sequence[EnvSpec], seeds: Sequence[int]
) -> list[dict[str, Any]]:
    """One JSON configuration per (env, strategy, seed), in that nesting order."""
    return [
        {"format": CELL_FORMAT, "env": e.to_dict(), "strategy": s.to_dict(), "seed": int(seed)}
        for e in envs
        for s in strategies
        for seed in seeds
    ]


def _make_teacher(path: str, env: Any, seed: int, kwargs: Mapping[str, Any]) -> Any:
    factory = _import(path)
    try:
        params = inspect.signature(factory).parameters
    except (TypeError, ValueError):
        params = {}
    extra: dict[str, Any] = {}
    if "env" in params:
        extra["env"] = env
    if "seed" in params:
        extra["seed"] = seed
    return factory(**extra, **kwargs)


class _Audited(gym.Wrapper):
    """Env wrapper that asks a separate teacher instance, before every step, what it would do
    there (to count wrong autonomous actions without disturbing the real teacher)."""

    def __init__(self, env: gym.Env, auditor: Callable[[np.ndarray, dict], int]) -> None:
        super().__init__(env)
        self.auditor = auditor
        self.expected: list[int] = []
        self._last: tuple[Any, dict] = (None, {})

    def reset(self, **kwargs: Any) -> Any:
        obs, info = self.env.reset(**kwargs)
        self._last = (obs, dict(info or {}))
        return obs, info

    def step(self, action: Any) -> Any:
        obs, info = self._last
        self.expected.append(int(self.auditor(np.array(obs, copy=True), dict(info))))
        out = self.env.step(action)
        self._last = (out[0], dict(out[4] or {}))
        return out


# where nothing bounds an evaluation episode (no eval_steps, no TimeLimit, no cap of the env's
# own), it gets this many steps (or max_steps, where more) before the cell stops with an error
_EVAL_GUARD_STEPS = 10_000


def _evaluate(
    policy: Any,
    spec: EnvSpec,
    env: Any,
    score: Callable,
    uses_info: bool,
    what: str,
    guard: int | None = None,
) -> tuple[float, int]:
    """The mean of ``score`` over the evaluations of ``policy`` on ``spec.eval_seeds``, and
    the number of their episodes that ended (over all the seeds); a score
    that is not a finite number (NaN from a mean over no finished episode, None) is a
    ValueError naming the score, the seed and ``what`` was evaluated: it would be a NaN in
    every figure of the table (and results.json), not an error.

    ``guard`` (where nothing else bounds an evaluation: no ``eval_steps``, no TimeLimit) is
    its step cap; an evaluation that reaches it before its ``eval_episodes`` episodes ended is
    a ValueError saying what to give, not a loop that runs as long as an episode does (for
    ever, where none ends). Where they all end within it, the records are those without it."""
    from torchcbl.policy import evaluate_policy

    values, ended_total = [], 0
    for s in spec.eval_seeds:
        records = evaluate_policy(
            policy,
            env,
            n_steps=spec.eval_steps if guard is None else guard,
            n_episodes=spec.eval_episodes,
            seed=int(s),
            uses_info=uses_info,
        )
        ended = sum(1 for r in records if r.terminated or r.truncated)
        ended_total += ended
        if guard is not None:
            if ended < int(spec.eval_episodes or 0):
                raise ValueError(
                    f"EnvSpec {spec.name!r}: the evaluation of {what} on evaluation seed {s} "
                    f"ran {len(records)} steps in all and {ended} of its "
                    f"{spec.eval_episodes} episodes ended; {spec.env_id} has no step cap (no "
                    "TimeLimit: registered without max_episode_steps; no max_episode_steps "
                    "of its own) and eval_steps is None, so an evaluation gets at most "
                    f"{guard // int(spec.eval_episodes or 1)} steps per episode in all (an "
                    "episode that never ends would run for ever): give eval_steps (the steps "
                    "of one evaluation; torchcbl benchmark --eval-steps N), or register the env "
                    "with max_episode_steps (or give it in env_kwargs)"
                )
        value = score(records)
        try:
            number = float(value)
        except (TypeError, ValueError):
            number = float("nan")
        if isinstance(value, (bool, np.bool_)) or not np.isfinite(number):
            ends = sum(1 for r in records if r.terminated or r.truncated)
            raise ValueError(
                f"EnvSpec {spec.name!r}: score {spec.score} returned {value!r} for {what} on "
                f"evaluation seed {s} ({len(records)} steps, {ends} finished episodes); "
                "expected a finite number, higher is better, for every evaluation (give "
                "eval_steps long enough for an episode to end, or a score defined without one)"
            )
        values.append(number)
    return float(np.mean(values)), ended_total


def run_cell(
    config: Mapping[str, Any],
    *,
    run_dir: str | os.PathLike[str] | None = None,
    keep_checkpoints: int | None = DEFAULT_KEEP_CHECKPOINTS,
) -> dict[str, Any]:
    """Run one cell (see the module docstring) and return its JSON result.

    Deterministic given ``config`` (one torch thread, seeded model, env and strategy, and the
    global numpy, ``random`` and torch CPU RNGs seeded from the cell's seed, for a teacher, env
    or strategy of one's own that draws from them), apart from the ``wall_s`` / ``cpu_s``
    timings. The caller's torch thread count and global torch (CPU and CUDA), numpy and
    ``random`` RNGs are as they were when it returns (``run_benchmark(workers=1)`` runs cells
    in-process).

    Args:
        config: one of :func:`cell_configs`' configurations.
        run_dir: if given, the cell's teaching is also written there as a session directory
            (:mod:`torchcbl.session`; ``ConfidentTeacher(run_dir=...)``: a new directory, or
            one holding no session), closed when the cell returns or raises; the result is
            the same with or without it (its timings apart).
        keep_checkpoints: with ``run_dir``, the checkpoints its session keeps
            (``ConfidentTeacher(keep_checkpoints=)``: the newest that many and checkpoint 0,
            3 by default; None: every one); the result is the same whatever it is.
    """
    import random

    import torch

    threads = torch.get_num_threads()
    np_state, py_state = np.random.get_state(), random.getstate()  # noqa: NPY002
    try:
        with torch.random.fork_rng(devices=[]):
            return _run_cell(config, run_dir, keep_checkpoints)
    finally:
        torch.set_num_threads(threads)
        np.random.set_state(np_state)  # noqa: NPY002
        random.setstate(py_state)


def _run_cell(
    config: Mapping[str, Any],
    run_dir: str | os.PathLike[str] | None = None,
    keep_checkpoints: int | None = DEFAULT_KEEP_CHECKPOINTS,
) -> dict[str, Any]:
    import random

    import torch

    from torchcbl._signatures import refuse_unless_a_teacher
    from torchcbl.gmm import GaussianMixtureSet
    from torchcbl.policy import GreedyPolicy, check_env
    from torchcbl.strategies import correcting
    from torchcbl.teaching import ConfidentTeacher, TeachingConfig, _episode_cap

    torch.set_num_threads(1)
    spec = EnvSpec(
        **{
            **config["env"],
            "budgets": tuple(config["env"]["budgets"]),
            "eval_seeds": tuple(config["env"]["eval_seeds"]),
        }
    )
    sspec = StrategySpec(**config["strategy"])
    seed = int(config["seed"])
    # the CPU generator only (run_cell gives it back): torch.manual_seed would also reseed the
    # caller's CUDA generators (now, or as CUDA starts), which no cell uses and none restores
    torch.random.default_generator.manual_seed(seed)
    # the global RNGs a teacher, env or strategy of one's own may draw from (the shipped ones
    # do not): otherwise a cell's figures depend on what ran before it in the process
    np.random.seed([seed & 0xFFFFFFFF, seed >> 32])  # noqa: NPY002
    random.seed(seed)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    score = _import(spec.score)

    env = gym.make(spec.env_id, **dict(spec.env_kwargs))
    snapshots: list[tuple[int, int, Any]] = []
    loop = None
    try:
        try:  # what the loop takes (not an AttributeError on a Box action space's .n)
            n_features, n_actions = check_env(env)
        except ValueError as exc:
            raise ValueError(f"EnvSpec {spec.name!r} ({spec.env_id}): {exc}") from None
        teacher = _make_teacher(spec.teacher, env, seed, spec.teacher_kwargs)
        auditor = _make_teacher(spec.teacher, env, seed, spec.teacher_kwargs)
        strategy = sspec.build(seed)
        wants_corrections = bool(getattr(strategy, "wants_corrections", False))
        if callable(teacher):  # here, not in correcting(): the factory is the user's to fix
            refuse_unless_a_teacher(teacher, f"teacher (from the factory {spec.teacher!r})")
        if wants_corrections and not callable(getattr(teacher, "correct", None)):
            teacher = correcting(teacher)
        audited = _Audited(env, auditor)
        model = GaussianMixtureSet(n_actions, n_features, seed=seed, **dict(spec.model))
        tc = TeachingConfig(**{**dict(spec.teaching), **dict(sspec.teaching)})
        loop = ConfidentTeacher(
            audited,
            teacher,
            model=model,
            strategy=strategy,
            config=tc,
            seed=seed,
            progress=False,
            run_dir=run_dir,
            keep_checkpoints=keep_checkpoints,
        )
        for budget in spec.budgets:
            if loop.n_demonstrations < budget:  # (a step with a correction may pass one)
                loop.run(max_demonstrations=budget, max_steps=spec.max_steps)
            if not snapshots or snapshots[-1][0] != loop.n_demonstrations:
                snapshots.append((loop.n_demonstrations, loop.n_steps, loop.snapshot()))
            if loop.n_steps >= spec.max_steps:
                break
        records = loop.records
        expected = audited.expected
    finally:
        try:
            if loop is not None:  # its session, if kept, committed and closed
                loop.close()
        finally:
            env.close()
    teach_wall = time.perf_counter() - wall0

    steps = len(records)
    autonomous = [r for r in records if r.teacher_action is None]
    # the learner's own actions that ran: autonomous steps, and DAgger's labelled agent steps
    agent = [r for r in records if r.actor == "agent"]
    wrong = sum(1 for r in agent if r.executed_action != expected[r.step])
    # the auditor is another instance of the teacher, asked at every step: where the real
    # teacher answered, how often it answers otherwise (a stochastic teacher, such as the
    # driving domain's, disagrees with itself): the floor under the wrong-action rate
    asked = [r for r in records if r.teacher_action is not None]
    disagree = sum(1 for r in asked if r.teacher_action != expected[r.step])
    actors = [r.actor for r in records]
    switches = sum(1 for a, b in zip(actors, actors[1:], strict=False) if a != b)
    requests = steps - len(autonomous)
    attention = {
        "labels": loop.n_demonstrations,
        "requests": requests,
        "corrections": loop.n_corrections,
        "monitored_steps": steps if wants_corrections else requests,
        "context_switches": switches,
        "teacher_actions": sum(1 for a in actors if a == "teacher"),
        "steps": steps,
        "autonomous_steps": len(autonomous),
        "agent_actions": len(agent),
        "wrong_autonomous_actions": wrong,
        "wrong_autonomous_rate": wrong / len(agent) if agent else None,
        "auditor_disagreement": disagree / len(asked) if asked else None,
    }

    eval_env = gym.make(spec.env_id, **{**dict(spec.env_kwargs), **dict(spec.eval_env_kwargs)})
    try:
        # an evaluation always ends: at eval_steps, at a cap of the env's own (a TimeLimit,
        # an env that bounds its episodes itself, as the corridor does), else within
        # _EVAL_GUARD_STEPS steps per episode (max_steps where more) or with an error
        guard = None
        if spec.eval_steps is None and _episode_cap(eval_env) is None:
            per_episode = max(spec.max_steps, _EVAL_GUARD_STEPS)
            guard = int(spec.eval_episodes or 1) * per_episode
        eval_teacher = _make_teacher(spec.teacher, eval_env, seed, spec.teacher_kwargs)
        teacher_perf, teacher_ended = _evaluate(
            eval_teacher, spec, eval_env, score, True, "the teacher", guard
        )
        curve = [
            {
                "labels": labels,
                "steps": n_steps,
                "performance": _evaluate(
                    GreedyPolicy(m),
                    spec,
                    eval_env,
                    score,
                    False,
                    f"the model of {labels} labels",
                    guard,
                )[0],
            }
            for labels, n_steps, m in snapshots
        ]
    finally:
        eval_env.close()
    return {
        "key": cell_key(config),
        "config": dict(config),
        "env": spec.name,
        "strategy": sspec.title,
        "seed": seed,
        "curve": curve,
        "teacher_performance": teacher_perf,
        # (a score of finished episodes, such as success_rate, has none to score where none
        # ended: the command says so; absent from the cells of earlier versions)
        "teacher_episodes_ended": teacher_ended,
        "attention": attention,
        "teach_wall_s": teach_wall,
        "wall_s": time.perf_counter() - wall0,
        "cpu_s": time.process_time() - cpu0,
    }


def _run_cell_in_worker(
    config: Mapping[str, Any],
    run_dir: str | None = None,
    keep_checkpoints: int | None = DEFAULT_KEEP_CHECKPOINTS,
) -> dict[str, Any]:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    if run_dir is not None:  # (on a Ray node of its own, what the sweep's host could not see)
        _set_aside(Path(run_dir))
    return run_cell(config, run_dir=run_dir, keep_checkpoints=keep_checkpoints)


# -- the sweep --------------------------------------------------------------------------------


def _cell_path(out: Path, key: str) -> Path:
    return out / "cells" / f"{key}.json"


def _session_path(out: Path, key: str) -> Path:
    return out / "sessions" / key


def _set_aside(path: Path) -> Path | None:
    """Rename what is at ``path`` (a session a killed or failed cell left) to the first free
    ``<name>.stale-N`` beside it, N = 1, 2, ...; return that new path, None if nothing was
    there."""
    if not os.path.lexists(path):
        return None
    n = 1
    while os.path.lexists(path.with_name(f"{path.name}.stale-{n}")):
        n += 1
    return path.rename(path.with_name(f"{path.name}.stale-{n}"))


def _write_atomic(path: Path, text: str) -> None:
    # its folder made again if need be: another sweep into the same new OUT (the cell cache is
    # shared) that stopped before any cell finished removes OUT/cells and OUT, still empty
    path.parent.mkdir(parents=True, exist_ok=True)
    write_durably(path, text.encode("utf-8"), path.with_name(f".{path.name}.{os.getpid()}.tmp"))


def _load_cell(path: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None  # unreadable: recompute
    return data if isinstance(data, dict) and "curve" in data else None


class CellError(RuntimeError):
    """A cell of a sweep failed: the message names the cell (env, strategy, seed and key) and
    the cause (also ``__cause__``), and says what is kept; ``config`` is the cell's
    configuration. The cells finished before it are kept, so running the same sweep again
    computes only the rest."""

    def __init__(
        self, config: Mapping[str, Any], cause: BaseException, out: Path, kept: int
    ) -> None:
        """``kept``: how many of the sweep's cells are finished and kept in ``out/cells`` (this
        call's and cached ones)."""
        self.config = dict(config)
        self.key = cell_key(config)
        text = one_line(cause)
        if kept == 0:
            held = (
                "no cell of this sweep has finished (none is kept); fix the cause and run it again"
            )
        else:
            cells = f"the {kept} finished cell{' is' if kept == 1 else 's are'}"
            held = (
                f"{cells} kept in {out / 'cells'}; fix the cause and run the same sweep again to "
                "compute the rest"
            )
        super().__init__(
            f"cell {self.key} (env {config['env']['name']!r}, strategy "
            f"{config['strategy']['label']!r}, seed {config['seed']}) failed: "
            f"{type(cause).__name__}: {text} -- {held}"
        )

    def __reduce__(self) -> tuple[Any, ...]:
        # pickled as its message and config (a sweep run inside a worker process of one's
        # own sends it back to the parent); the cause itself may not pickle
        return (_rebuild_cell_error, (str(self), self.config))


def _rebuild_cell_error(message: str, config: dict[str, Any]) -> CellError:
    exc = CellError.__new__(CellError)
    RuntimeError.__init__(exc, message)
    exc.config, exc.key = config, cell_key(config)
    return exc


def _check_ray_address(address: str, timeout: float = 10.0) -> None:
    """A RuntimeError unless something answers at the Ray cluster address ``address``
    (``host:port``, or ``"auto"``: the cluster ``RAY_ADDRESS`` or the last ``ray start`` on
    this machine names; ``"local"`` and ``ray://`` addresses are left to Ray). Ray itself,
    given a host and port where nothing listens (a typo, or the file a stopped cluster left
    behind for ``"auto"``), retries its connection for about a quarter of an hour (20 tries of
    some 40 s), printing warnings, before it fails."""
    import socket

    if "://" in address or address == "local":
        return
    try:  # where ray.init connects: localhost and 127.0.0.1 become this node's IP
        from ray._private.services import canonicalize_bootstrap_address

        target = canonicalize_bootstrap_address(address) or address
    except ConnectionError:  # "auto": no RAY_ADDRESS, no cluster file, no GCS process
        raise RuntimeError(
            "Ray at auto: no running Ray cluster found on this machine (RAY_ADDRESS is unset "
            "and no `ray start` left its address); start one with `ray start --head`, give "
            "its address as host:port, or use --ray for a Ray of this command's own"
        ) from None
    except Exception:  # a Ray without it, or an address it refuses (ray.init will say)
        target = address
    host, _, port = target.rpartition(":")
    if not host or not port.isdigit():
        return  # not host:port: ray.init says what it expected
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as exc:
        raise RuntimeError(
            f"Ray at {address}: nothing answers at {target} "
            f"({' '.join(str(exc).split()) or type(exc).__name__}); expected the address of a "
            "running Ray cluster's head node (host:port, the GCS port that `ray start --head` "
            "prints, 6379 by default): start Ray there first, or fix the address"
        ) from None


def _stop_ray_tasks(ray: Any, refs: list[Any], timeout: float = 10.0) -> None:
    """Cancel the Ray tasks ``refs`` (killing the workers of those that run, as the process
    pool terminates its workers) and wait up to ``timeout`` seconds for them to end. On a
    Ray this sweep did not start (``ray.shutdown`` leaves its workers running), a cell's
    task would otherwise go on writing its session, which a rerun sets aside as
    ``<key>.stale-N`` while it is still written."""
    for ref in refs:
        try:
            ray.cancel(ref, force=True)
        except Exception:  # finished meanwhile, or Ray is going away: nothing to stop
            pass
    try:
        ray.wait(refs, num_returns=len(refs), timeout=timeout, fetch_local=False)
    except Exception:
        pass


def _execute(
    todo: list[dict[str, Any]],
    *,
    workers: int,
    use_ray: bool,
    ray_address: str | None,
    done: Callable[[dict[str, Any]], None],
    out: Path,
    sessions: Path | None = None,
    cached: int = 0,
    keep_checkpoints: int | None = DEFAULT_KEEP_CHECKPOINTS,
) -> None:
    """Run the cells of ``todo`` and hand each result to ``done`` as it comes; the first cell
    that raises stops the sweep with a :class:`CellError` naming it (any other cell that
    finished meanwhile is handed to ``done`` first) and saying how many cells are kept (the
    ``cached`` ones and those handed to ``done``), and stops the other cells (on Ray, their
    tasks are cancelled, also on a Ray this sweep did not start). With ``sessions`` (an
    absolute path), each cell writes its teaching session to ``sessions/<key>``, keeping
    ``keep_checkpoints`` checkpoints (see :func:`run_cell`)."""
    if not todo:
        return
    kept = [cached]  # the cells in out/cells: the cached ones, then each one done keeps

    def keep(cell: dict[str, Any]) -> None:
        done(cell)
        kept[0] += 1

    def run_dir(config: Mapping[str, Any]) -> str | None:
        return None if sessions is None else str(sessions / cell_key(config))

    if use_ray:
        try:
            import ray
        except ImportError as exc:
            raise RuntimeError(
                "Ray is not installed; install it into this environment with `pip install "
                "ray` (from a checkout, `pip install -e '.[ray]'`), or run without --ray."
            ) from exc
        started = not ray.is_initialized()
        if started:
            ray.init(
                address=ray_address,
                num_cpus=None if ray_address else workers,
                include_dashboard=False,
                log_to_driver=False,
                runtime_env={"env_vars": {"PYTHONPATH": os.environ.get("PYTHONPATH", "")}},
            )
        configs: dict[Any, dict[str, Any]] = {}
        pending: list[Any] = []  # the tasks not handed to done (nor raised) yet
        try:
            # One cell per task and CPU; a cell closes its envs, so a worker process may run
            # cells one after another (libsumo: one live simulation per process).
            remote = ray.remote(num_cpus=1)(_run_cell_in_worker)
            for c in todo:
                ref = remote.remote(c, run_dir(c), keep_checkpoints)
                configs[ref] = c
                pending.append(ref)
            while pending:
                ready, pending = ray.wait(pending, num_returns=1)
                try:
                    cell = ray.get(ready[0])
                except Exception as exc:  # a RayTaskError: the cell's own exception is its cause
                    cause = getattr(exc, "cause", None)
                    cause = cause if isinstance(cause, BaseException) else exc
                    raise CellError(configs[ready[0]], cause, out, kept[0]) from cause
                keep(cell)
        finally:
            if pending:  # the sweep stopped (a CellError, a Ctrl-C): stop the other cells
                _stop_ray_tasks(ray, pending)
            if started:
                ray.shutdown()
        return
    if workers <= 1:
        for c in todo:  # in this process: its environment variables are left alone
            try:
                cell = run_cell(c, run_dir=run_dir(c), keep_checkpoints=keep_checkpoints)
            except Exception as exc:
                raise CellError(c, exc, out, kept[0]) from exc
            keep(cell)
        return
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    # spawn: a fresh interpreter (no forked torch or libsumo state); workers are reused, as
    # every cell closes its envs before it returns.
    died = (  # what worker_pool adds to how a worker died mid-cell
        f"the cells finished before are kept in {out / 'cells'}: run the same sweep again to "
        "compute the rest (with fewer workers if memory ran out)"
    )
    with worker_pool(
        min(workers, len(todo)), ctx, running="one of the unfinished cells", after=died
    ) as pool:  # a Ctrl-C stops the workers
        futures = {
            pool.submit(_run_cell_in_worker, c, run_dir(c), keep_checkpoints): c for c in todo
        }
        pending = set(futures)
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            failed = [f for f in finished if f.exception() is not None]
            for f in finished:  # the cells that finished with a failed one are kept too
                if f.exception() is None:
                    keep(f.result())
            if failed:
                exc = failed[0].exception()
                if isinstance(exc, BrokenProcessPool):  # every unfinished cell gets it: the
                    # dead worker's cell is not known, so naming one would blame the wrong one
                    raise exc  # worker_pool says how the worker died
                raise CellError(futures[failed[0]], exc, out, kept[0]) from exc


def run_benchmark(
    strategies: Sequence[StrategySpec],
    envs: Sequence[EnvSpec],
    seeds: Sequence[int],
    out_dir: str | os.PathLike[str],
    *,
    workers: int | None = None,
    use_ray: bool = False,
    ray_address: str | None = None,
    plots: bool = True,
    on_cell: Callable[[dict[str, Any], bool], None] | None = None,
    keep_sessions: bool = False,
    keep_checkpoints: int | None = DEFAULT_KEEP_CHECKPOINTS,
) -> dict[str, Any]:
    """Run (or resume) a sweep and write ``results.json`` and the plots into ``out_dir``.

    Args:
        strategies, envs, seeds: the grid; every strategy meets every env with every seed.
        out_dir: the benchmark directory; finished cells are cached in ``out_dir/cells``, so
            calling again with the same grid computes only the missing cells.
        workers: processes of the local pool (default: ``os.cpu_count()``); 1 runs in-process.
            The pool spawns fresh interpreters, which import the caller's main module: from a
            script, call ``run_benchmark`` under ``if __name__ == "__main__":``.
        use_ray: run the cells as Ray tasks (``ray_address`` None: a local Ray with
            ``workers`` CPUs; else ``ray.init(address=ray_address)``, e.g. ``"auto"``; a
            ``host:port`` where nothing answers within 10 s is a RuntimeError).
        plots: write ``learning_curves.png``. The ``results.json`` and plot an earlier sweep
            left in ``out_dir`` are removed first, so what is there is this sweep's or
            nothing (a sweep that stops early writes neither).
        on_cell: called as ``on_cell(cell_result, cached)`` for every cell, cached or new.
        keep_sessions: also keep each computed cell's teaching session, a session directory
            (:mod:`torchcbl.session`) in ``out_dir/sessions/<key>`` (see the module
            docstring). Not part of a cell's configuration: the figures and keys are the same
            either way, and a cached cell is not computed again for its session (a warning
            names the cached cells that have none).
        keep_checkpoints: with ``keep_sessions``, the checkpoints each session keeps, as
            ``ConfidentTeacher(keep_checkpoints=)``: the newest that many (an int >= 1) and
            checkpoint 0, 3 by default; None keeps every one (an earlier stage's model is
            rebuilt from the log by ``load_model(path, n_demonstrations=k)`` either way). Not
            part of a cell's configuration either: the figures and keys are the same whatever
            it is, and a cached cell keeps the session it has. Without ``keep_sessions`` it is
            checked, and unused.

    Returns:
        The results dict that was written to ``results.json``.

    Raises:
        CellError: a cell raised; it names the cell and has the cell's exception as its
            ``__cause__``. The sweep stops there; the cells finished before it are kept.
        RuntimeError: a worker process of the local pool could not start (a script without
            the guard above), or died while it ran a cell.
    """
    if isinstance(seeds, (str, bytes)) or not isinstance(seeds, Iterable):
        raise ValueError(f"run_benchmark: seeds must be a sequence of ints >= 0, got {seeds!r}")
    seeds = list(seeds)  # a numpy array too (its truth value is ambiguous)
    bad = [s for s in seeds if not _is_int(s) or not 0 <= s < 2**64]
    if bad:
        raise ValueError(
            f"run_benchmark: seeds must be ints in [0, 2**64) (each seeds a cell's model, env "
            f"and teacher), got {bad!r}"
        )
    if not strategies or not envs or not seeds:
        raise ValueError("run_benchmark: need at least one strategy, one env and one seed")
    titles = [s.title for s in strategies]
    if len(set(titles)) != len(titles):
        raise ValueError(
            f"run_benchmark: strategy labels must be distinct (tables group cells by label), got "
            f"{titles}; give each StrategySpec its own label= (e.g. StrategySpec('cba', "
            "teaching={'noninteractive': False}, label='cba-jair') beside StrategySpec('cba'))"
        )
    names = [e.name for e in envs]
    if len(set(names)) != len(names):
        raise ValueError(
            f"run_benchmark: env names must be distinct (tables group cells by name), got "
            f"{names}; give each EnvSpec its own name="
        )
    if len({int(s) for s in seeds}) != len(seeds):
        raise ValueError(
            f"run_benchmark: seeds must be distinct (a repeated seed repeats the same cells and "
            f"counts them twice), got {list(seeds)}"
        )
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int) or workers < 1
    ):
        raise ValueError(f"workers must be None (os.cpu_count()) or an int >= 1, got {workers!r}")
    if keep_checkpoints is not None and not is_keep_count(keep_checkpoints):
        raise ValueError(
            "run_benchmark: keep_checkpoints: expected None (keep every checkpoint) or an int "
            f">= 1 (the newest checkpoints each kept session keeps), got {keep_checkpoints!r}"
        )
    _check_imports(strategies, envs)
    if use_ray and ray_address is not None:  # before the output directory is touched
        ray = sys.modules.get("ray")  # (a Ray already started is used as it is)
        if ray is None or not ray.is_initialized():
            _check_ray_address(ray_address)
    out = Path(out_dir)
    if (out / "cells").is_dir():
        # An earlier sweep's results and plot would read as this one's if it stops early (a
        # failed cell, Ctrl-C) or draws no plot; its cells stay, so running it again rewrites
        # them at once. (Files of that name in a directory no sweep wrote are not a sweep's.)
        for name in ("results.json", "learning_curves.png"):
            (out / name).unlink(missing_ok=True)
    # the folders this sweep makes (cells/, OUT and any missing above it), nearest first: one
    # that stops before any cell is written leaves none of them behind empty
    made = [p for p in (out / "cells", out, *out.parents) if not p.exists()]
    (out / "cells").mkdir(parents=True, exist_ok=True)
    configs = cell_configs(strategies, envs, seeds)
    results: dict[str, dict[str, Any]] = {}
    todo = []
    for c in configs:
        key = cell_key(c)
        cached = _load_cell(_cell_path(out, key))
        if cached is not None:
            results[key] = cached
            if on_cell is not None:
                on_cell(cached, True)
        else:
            todo.append(c)
    for c in todo:  # what is there is a killed or failed run's, never this cell's session
        _set_aside(_session_path(out, cell_key(c)))
    if keep_sessions:
        bare = [k for k in results if not _session_path(out, k).is_dir()]
        if bare:
            warnings.warn(
                f"run_benchmark: keep_sessions: {len(bare)} of the {len(results)} cached cells "
                f"have no session in {out / 'sessions'} (they were computed without "
                f"keep_sessions), e.g. {bare[0]}; a cached cell is not computed again: delete "
                "its cells/<key>.json to compute it again with its session",
                stacklevel=2,
            )
    wall0 = time.perf_counter()

    def done(cell: dict[str, Any]) -> None:
        _write_atomic(_cell_path(out, cell["key"]), json.dumps(cell, indent=1))
        results[cell["key"]] = cell
        if on_cell is not None:
            on_cell(cell, False)

    n_workers = max(1, int(workers or os.cpu_count() or 1))
    try:
        _execute(
            todo,
            workers=n_workers,
            use_ray=use_ray,
            ray_address=ray_address,
            done=done,
            out=out,
            # absolute: a worker (a Ray one) may run in another directory
            sessions=(out / "sessions").resolve() if keep_sessions else None,
            cached=len(results),
            keep_checkpoints=keep_checkpoints,
        )
    except BaseException:
        for folder in made:  # those left empty (no cell, no session written into them)
            try:
                folder.rmdir()
            except OSError:
                break
        raise
    cells = [results[cell_key(c)] for c in configs]
    summary = summarize(cells, envs=[e.name for e in envs], strategies=titles)
    summary["sweep"] = {
        "cells": len(configs),
        "computed": len(todo),
        "cached": len(configs) - len(todo),
        "seeds": [int(s) for s in seeds],
        # (the cells of workers=1 ran in this process: _execute)
        "engine": (
            ("ray" if use_ray else "process_pool" if n_workers > 1 else "in_process")
            if todo
            else "cache"
        ),
        "workers": n_workers,
        "wall_s_this_call": time.perf_counter() - wall0,
        "cell_cpu_s_total": float(sum(c["cpu_s"] for c in cells)),
        "cell_wall_s_total": float(sum(c["wall_s"] for c in cells)),
    }
    summary["envs"] = {e.name: e.to_dict() for e in envs}
    summary["strategies"] = {s.title: s.to_dict() for s in strategies}
    summary["versions"] = run_versions()
    summary["cells"] = {c["key"]: f"cells/{c['key']}.json" for c in cells}
    _write_atomic(out / "results.json", json.dumps(summary, indent=1))
    if plots:
        plot_curves(cells, out / "learning_curves.png", envs=[e.name for e in envs])
    return summary


# -- aggregation ------------------------------------------------------------------------------


def _labels_to(cell: Mapping[str, Any], fraction: float) -> tuple[int | None, bool]:
    """Labels at which the cell first reaches ``fraction`` x the teacher's performance, and
    whether that is censored (never reached: the last label count, a lower bound). None when
    the teacher's performance is not positive: a share of it is no target (e.g. a score that
    the env never feeds, such as ``success_rate`` on an env without ``info["is_success"]``)."""
    if not float(cell["teacher_performance"]) > 0:
        return None, False
    target = fraction * float(cell["teacher_performance"])
    for p in cell["curve"]:
        if p["performance"] >= target - 1e-12:
            return int(p["labels"]), False
    last = cell["curve"][-1]["labels"] if cell["curve"] else 0
    return int(last), True


def _perf_at(cell: Mapping[str, Any], budget: int) -> float | None:
    """Performance of the model fitted on at most ``budget`` labels (the last snapshot at or
    below it), None if the cell had no snapshot that small."""
    best = None
    for p in cell["curve"]:
        if p["labels"] <= budget:
            best = p["performance"]
    return best


def summarize(
    cells: Iterable[Mapping[str, Any]],
    *,
    envs: Sequence[str],
    strategies: Sequence[str],
    reference: str | None = None,
) -> dict[str, Any]:
    """The results from cell results: ``table`` (per env, per strategy, the figures over
    seeds) and ``paired`` (each strategy against the reference, seed by seed).

    Args:
        cells: cell results (:func:`run_cell`'s).
        envs, strategies: the env names and strategy titles (labels) to summarize, in order.
        reference: the strategy title every other is paired with; None: the first of
            ``strategies`` whose cells are a :data:`REFERENCE_STRATEGY` spec's (confident
            execution, whatever its label), and no pairs where there is none.

    ``paired`` is ``{"reference": title or None, "table": {env: {strategy: {budget: {mean,
    sd, n, ci95}}}}}``: at each budget, over the seeds where both the strategy and the
    reference have a figure (each seed's model of at most that many labels), the differences
    strategy − reference of the same seed's two figures (every strategy runs on the same
    seeds: the same env, evaluation and teacher seeds), their mean, sample sd and a 95 % t
    interval (:func:`~torchcbl.evaluation.paired_interval`; sd and ci95 None where n < 2). A
    budget where no seed has both figures is left out.

    Raises:
        ValueError: ``reference`` is not one of ``strategies``.
    """
    cells = list(cells)
    if reference is not None and reference not in strategies:
        raise ValueError(
            f"summarize: reference must be one of the strategies {list(strategies)}, got "
            f"{reference!r}"
        )
    table: dict[str, dict[str, Any]] = {}
    for env in envs:
        table[env] = {}
        for strat in strategies:
            mine = sorted(
                (c for c in cells if c["env"] == env and c["strategy"] == strat),
                key=lambda c: c["seed"],
            )
            if not mine:
                continue
            hits = [_labels_to(c, 0.95) for c in mine]
            budgets = mine[0]["config"]["env"]["budgets"]
            # every key any seed's cell has (a cell of an older format lacks the newer ones)
            keys = dict.fromkeys(k for c in mine for k in c["attention"])
            att = {k: mean_sd(c["attention"].get(k) for c in mine) for k in keys}
            teacher = [float(c["teacher_performance"]) for c in mine]
            table[env][strat] = {
                "labels_to_95pct": {
                    **mean_sd(v for v, _ in hits),
                    "n_censored": sum(1 for _, cen in hits if cen),
                    "lower_bound": any(cen for _, cen in hits),
                    "per_seed": [
                        {"seed": c["seed"], "labels": v, "censored": cen}
                        for c, (v, cen) in zip(mine, hits, strict=True)
                    ],
                },
                "final_performance": mean_sd(
                    c["curve"][-1]["performance"] if c["curve"] else None for c in mine
                ),
                "final_labels": mean_sd(
                    c["curve"][-1]["labels"] if c["curve"] else None for c in mine
                ),
                # each seed's model of at most b labels; n_reached: the seeds that held b (the
                # others, stopped or capped below it, count with their last model)
                "performance_at_budget": {
                    str(b): {
                        **mean_sd(_perf_at(c, b) for c in mine),
                        "n_reached": sum(
                            1 for c in mine if c["curve"] and c["curve"][-1]["labels"] >= b
                        ),
                    }
                    for b in budgets
                },
                "teacher_performance": mean_sd(teacher),
                "attention": att,
                "wall_s": mean_sd(c["wall_s"] for c in mine),
                "cpu_s": mean_sd(c["cpu_s"] for c in mine),
            }
    if reference is None:
        reference = _reference(cells, strategies)
    return {
        "table": table,
        "paired": {
            "reference": reference,
            "table": {} if reference is None else _paired(cells, envs, strategies, reference),
        },
    }


def _reference(cells: Sequence[Mapping[str, Any]], strategies: Sequence[str]) -> str | None:
    """The first of ``strategies`` whose cells are a :data:`REFERENCE_STRATEGY` spec's."""
    for strat in strategies:
        for c in cells:
            spec = c.get("config", {}).get("strategy", {})
            if c["strategy"] == strat and spec.get("name") == REFERENCE_STRATEGY:
                return strat
    return None


def _paired(
    cells: Sequence[Mapping[str, Any]],
    envs: Sequence[str],
    strategies: Sequence[str],
    reference: str,
) -> dict[str, dict[str, dict[str, dict[str, Any]]]]:
    """``summarize``'s ``paired["table"]``: per env, per other strategy, per budget, the
    per-seed differences strategy − reference."""
    out: dict[str, dict[str, dict[str, dict[str, Any]]]] = {}
    for env in envs:
        ref = {c["seed"]: c for c in cells if c["env"] == env and c["strategy"] == reference}
        if not ref:
            continue
        budgets = next(iter(ref.values()))["config"]["env"]["budgets"]
        rows: dict[str, dict[str, dict[str, Any]]] = {}
        for strat in strategies:
            if strat == reference:
                continue
            mine = {c["seed"]: c for c in cells if c["env"] == env and c["strategy"] == strat}
            at_budget = {}
            for b in budgets:
                diffs = []
                for seed in sorted(mine.keys() & ref.keys()):
                    a, r = _perf_at(mine[seed], b), _perf_at(ref[seed], b)
                    if a is not None and r is not None:
                        diffs.append(float(a) - float(r))
                if diffs:
                    at_budget[str(b)] = paired_interval(diffs)
            if at_budget:
                rows[strat] = at_budget
        if rows:
            out[env] = rows
    return out


def format_table(summary: Mapping[str, Any]) -> str:
    """A Markdown table of the results (one row per environment and strategy). The column of
    performance at a budget shows each row's 2nd budget, or its only one (its header says which;
    each cell names its budget, ``@ 20``, and where some seeds stopped below it, how many
    reached it: ``(0/3 reached)``, the others' figure is their last model's)."""
    counts = {
        len(r["performance_at_budget"]) for s in summary["table"].values() for r in s.values()
    }
    at_header = (
        "perf. at its only budget"
        if counts and max(counts) == 1
        else "perf. at 2nd budget (or the only one)"
        if counts and min(counts) == 1
        else "perf. at 2nd budget"
    )
    rows = [
        f"| env | strategy | labels to 95 % (censored) | {at_header} | final perf. "
        "(labels) | teacher perf. | requests | monitored | context switches | "
        "wrong auto. actions (rate) | auditor ≠ teacher | wall s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]

    def ms(d: Mapping[str, Any], fmt: str | None = None) -> str:
        """``mean ± sd``; without ``fmt``, a count's: whole or >= 10, no decimals; else two
        significant digits, the sd to as many decimals (a mean of 0.5 is not "0")."""
        if d.get("mean") is None:
            return "-"
        if fmt is None:
            mean = float(d["mean"])
            whole = abs(mean - round(mean)) < 1e-9 or abs(mean) >= 10
            fmt = "{:.0f}" if whole else f"{{:.{max(1, 1 - math.floor(math.log10(abs(mean))))}f}}"
        if d.get("sd") is None:
            return f"{fmt.format(d['mean'])} (n = 1)"
        return f"{fmt.format(d['mean'])} ± {fmt.format(d['sd'])}"

    def rate(d: Mapping[str, Any] | None) -> str:  # a share, mean over the seeds that have one
        return "-" if not d or d.get("mean") is None else f"{d['mean']:.2f}"

    for env, strategies in summary["table"].items():
        for strat, r in strategies.items():
            lt = r["labels_to_95pct"]
            a = r["attention"]
            cens = f" ({lt['n_censored']}/{lt['n']})" if lt["n_censored"] else ""
            prefix = "≥ " if lt["lower_bound"] else ""
            budgets = list(r["performance_at_budget"])
            second = budgets[min(1, len(budgets) - 1)]
            pab = r["performance_at_budget"][second]
            at = f"{ms(pab, '{:.2f}')} @ {second}"
            if pab.get("n_reached") is not None and pab["n"] and pab["n_reached"] < pab["n"]:
                at += f" ({pab['n_reached']}/{pab['n']} reached)"  # the others stopped below
            rows.append(
                f"| {env} | {strat} | {prefix}{ms(lt)}{cens} | {at} | "
                f"{ms(r['final_performance'], '{:.2f}')} ({ms(r['final_labels'])}) | "
                f"{ms(r['teacher_performance'], '{:.2f}')} | {ms(a['requests'])} | "
                f"{ms(a['monitored_steps'])} | {ms(a['context_switches'])} | "
                f"{ms(a['wrong_autonomous_actions'])} ({rate(a.get('wrong_autonomous_rate'))}) | "
                f"{rate(a.get('auditor_disagreement'))} | {ms(r['wall_s'], '{:.0f}')} |"
            )
    return "\n".join(rows)


def format_paired(summary: Mapping[str, Any]) -> str:
    """The paired comparison of ``summary["paired"]`` (:func:`summarize`): a Markdown table,
    one row per env, strategy and budget, of the per-seed difference strategy − reference
    (mean ± sd, n, 95 % t interval), under a line that says what it is; or one line saying why
    there is none."""
    paired = summary.get("paired") or {}
    reference = paired.get("reference")
    if reference is None:
        return (
            f"No paired comparison: no strategy named {REFERENCE_STRATEGY} in this sweep (each "
            f"strategy is paired seed by seed with {REFERENCE_STRATEGY}, the paper's method)."
        )
    if not paired.get("table"):
        return f"No paired comparison: no other strategy has a figure beside {reference}'s."
    rows = [
        f"Paired by seed with {reference} (every strategy ran on the same seeds): at each "
        f"budget, the difference strategy − {reference} of a seed's two performances (each the "
        "model of the last snapshot at or below the budget), mean ± sd over the n seeds where "
        "both have one, and its 95 % t interval (none where n < 2); an interval that excludes "
        f"0 says the strategy is ahead of (above 0) or behind (below 0) {reference} there.",
        "",
        f"| env | strategy − {reference} | labels | difference (mean ± sd) | n | 95 % interval |",
        "|---|---|---|---|---|---|",
    ]
    for env, strategies in paired["table"].items():
        for strat, budgets in strategies.items():
            for b, d in budgets.items():
                if d["sd"] is None:
                    diff, ci = f"{d['mean']:+.2f} (n = 1)", "none (n < 2)"
                else:
                    lo, hi = d["ci95"]
                    diff, ci = f"{d['mean']:+.2f} ± {d['sd']:.2f}", f"[{lo:+.2f}, {hi:+.2f}]"
                rows.append(f"| {env} | {strat} | {b} | {diff} | {d['n']} | {ci} |")
    return "\n".join(rows)


@figure_style()
def plot_curves(
    cells: Sequence[Mapping[str, Any]], path: str | os.PathLike[str], *, envs: Sequence[str]
) -> Path:
    """Performance vs labels: one panel per env, a line per strategy (mean over seeds, each
    seed's curve held constant after its last point) with a +-1 sd band, clipped to [0, 1]
    for the shipped scores (:func:`success_rate`, :func:`no_penalty_share`: shares). Each
    panel's title says how many seeds and the band, its y axis names the score.

    Drawn on a bare :class:`matplotlib.figure.Figure` with an Agg canvas, never through pyplot:
    the caller's backend (a notebook's inline plots) and open figures are left as they were.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5.5 * len(envs), 4))
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(envs), squeeze=False)
    for ax, env in zip(axes[0], envs, strict=True):
        mine = [c for c in cells if c["env"] == env]
        strategies = list(dict.fromkeys(c["strategy"] for c in mine))
        for strat in strategies:
            runs = [c for c in mine if c["strategy"] == strat and c["curve"]]
            if not runs:
                continue
            grid = sorted({int(p["labels"]) for c in runs for p in c["curve"]})
            ys = np.array([[_perf_at(c, b) for b in grid] for c in runs], dtype=float)
            with warnings.catch_warnings():  # one run at a budget: no spread (NaN, not drawn)
                warnings.simplefilter("ignore", RuntimeWarning)
                # ddof=1: the sd of the tables (mean_sd), not the narrower population sd
                m, s = np.nanmean(ys, axis=0), np.nanstd(ys, axis=0, ddof=1)
            (line,) = ax.plot(grid, m, marker=".", label=strat)
            # a share's band stops at 0 and 1 (mean + sd of 1.0 and 0.6 is 1.08); the mean line
            # and every number of the results are as computed
            scores = {c.get("config", {}).get("env", {}).get("score") for c in runs}
            one = scores.pop() if len(scores) == 1 else None
            lo, hi = _SCORE_RANGES.get(one, (-np.inf, np.inf))
            ax.fill_between(
                grid,
                np.clip(m - s, lo, hi),
                np.clip(m + s, lo, hi),
                alpha=0.15,
                color=line.get_color(),
            )
        teacher = [float(c["teacher_performance"]) for c in mine]
        if teacher:
            t = float(np.mean(teacher))
            ax.axhline(t, color="k", lw=0.8, ls="--", label="teacher")
            if t > 0:  # no target for a teacher at or below 0: 0.95 x -100 is above it
                ax.axhline(0.95 * t, color="k", lw=0.6, ls=":", label="95 % of teacher")
        # what the line and band are, and which score: a reader of the PNG alone sees them
        # (one cell per strategy and seed: a strategy's cells are the seeds)
        n = max((sum(1 for c in mine if c["strategy"] == s) for s in strategies), default=0)
        ax.set_title(
            f"{env}: mean over {n} seeds, band ±1 sd" if n > 1 else f"{env}: 1 seed (no band)"
        )
        scores = {c.get("config", {}).get("env", {}).get("score") for c in mine}
        score = scores.pop() if len(scores) == 1 else None
        ax.set_xlabel("teacher labels")
        ax.set_ylabel(
            f"{score.rpartition(':')[2] if isinstance(score, str) else 'performance'} "
            "(greedy, held-out eval seeds)"
        )
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return save_whole(path, fig.savefig, dpi=110)  # whole or not at all, as results.json
