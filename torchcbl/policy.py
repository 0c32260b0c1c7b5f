"""The learned policy on its own: :class:`GreedyPolicy`, :func:`evaluate_policy` and the checks
every env and teacher answer goes through before the loop or an evaluation uses it."""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal, overload

import gymnasium as gym
import numpy as np
import torch

from torchcbl._signatures import cannot_take as _cannot_take
from torchcbl.errors import EnvError
from torchcbl.gmm import _conversion, _is_real_dtype, _to_numpy
from torchcbl.records import StepRecord, _is_int, jsonable_info

if TYPE_CHECKING:  # pragma: no cover
    from torchcbl.gmm import Classification

__all__ = [
    "ActionAnswer",
    "EpisodeResult",
    "GreedyPolicy",
    "check_env",
    "episode_results",
    "evaluate_policy",
]

#: What a policy or a teacher may answer as its action (:func:`as_action` takes it): an int, a
#: numpy integer, or a 0-d integer array or tensor (e.g. ``logits.argmax()``).
ActionAnswer = int | np.integer[Any] | np.ndarray | torch.Tensor


# What every path says of a GreedyPolicy whose model is not fitted (its one contract, below)
_UNFITTED = (
    "GreedyPolicy: the model is not fitted yet, so it has no action to give. Teach it first "
    "(ConfidentTeacher.run) or load a fitted stage; a learning curve starts at a session's "
    "first fitted stage (model.is_fitted; see torchcbl.load_models)."
)


class GreedyPolicy:
    """A learned policy standing on its own: ``policy(obs [D]) -> int`` (Eq. 7, no asking).

    Holds the model by reference (the live model of a session keeps learning); deep-copy the
    policy or the model to freeze a snapshot. Picklable.

    A model not fitted yet has no action to give: a fresh one, or a session's model before
    its first fit (``load_model(run_dir, n_demonstrations=0)``, stage 0 of
    :func:`~torchcbl.load_models`, for a session without prior demonstrations or a fitted
    starting model). Then calling the policy raises RuntimeError, and so does
    :func:`evaluate_policy` given it, before it resets the env where the model says
    ``is_fitted`` False (a model of one's own without that flag: at the first step, once its
    answer is -1; where a subclass has a ``__call__`` of its own, that is called and
    decides); :meth:`classify` reports the model's
    Classification, action -1, as ``policy.model.classify(batch)`` does for a batch [N, D].
    """

    def __init__(self, model: torch.nn.Module) -> None:
        self.model = model

    def classify(self, observation: Any) -> Classification:
        """The model's Classification of one observation [D] (batched fields of length 1).

        ``observation``: a numpy array, a sequence of numbers or a torch tensor, read as the
        float64 values it holds; a tensor of any real dtype (bfloat16 and float16 too) or
        device, ``requires_grad`` or not, is read without autograd (the model scores without
        it). What :meth:`GaussianMixtureSet.classify <torchcbl.gmm.GaussianMixtureSet.classify>`
        refuses is refused alike: bools, strings and complex numbers are a TypeError naming
        the dtype (never read as 0/1, parsed, or stripped of their imaginary part).
        """
        x = _to_numpy(observation, "GreedyPolicy: observation")  # a tensor without autograd
        if not _is_real_dtype(x.dtype.kind):
            raise TypeError(
                "GreedyPolicy: expected an observation of real numbers (float32/float64 or "
                f"integers) but got dtype {x.dtype}; convert with "
                f"{_conversion(observation, 'observation', 'float')}"
            )
        x = x.astype(np.float64, copy=False)
        n_features = getattr(self.model, "n_features", None)
        if x.ndim != 1 or (isinstance(n_features, int) and x.shape[0] != n_features):
            raise ValueError(
                f"GreedyPolicy: expected one observation of shape ({n_features},), got shape "
                f"{x.shape}; for a batch [N, D] call policy.model.classify(batch)"
            )
        # a copy: a read-only row (a memory-mapped dataset) made torch.as_tensor warn
        return self.model.classify(torch.tensor(x).reshape(1, -1))

    def __call__(self, observation: Any) -> int:
        """The model's action for one observation [D] (Eq. 7; read as :meth:`classify` reads
        it); RuntimeError where the model is not fitted (the class's contract)."""
        action = int(self.classify(observation).action[0])
        if action < 0:
            raise RuntimeError(_UNFITTED)
        return action

    def __repr__(self) -> str:
        return f"GreedyPolicy({type(self.model).__name__})"


# Who last moved each env object (keyed weakly by its unwrapped core, so that a wrapper and the
# env it wraps are one env): a teaching loop notes its own token after each of its resets, and
# evaluate_policy a fresh one as it starts. A loop that finds another token on its env in the
# middle of an episode knows the env moved under it (ConfidentTeacher.step).
_ENV_USERS: weakref.WeakKeyDictionary[Any, object] = weakref.WeakKeyDictionary()


def _note_env_user(env: Any, token: object) -> None:
    """Note ``token`` as the last user of ``env`` (an env that cannot be weakly referenced or
    hashed is not tracked)."""
    try:
        _ENV_USERS[getattr(env, "unwrapped", env)] = token
    except TypeError:
        pass


def _env_user(env: Any, default: object = None) -> object:
    """The token last noted on ``env``; ``default`` for an env no one noted or that is not
    tracked."""
    try:
        return _ENV_USERS.get(getattr(env, "unwrapped", env), default)
    except TypeError:
        return default


def check_env(env: gym.Env) -> tuple[int, int]:
    """(n_features, n_actions) of a supported env, or a clear ValueError (a vector env too:
    one env is taught at a time; a TypeError for an object that is no env at all, such as an
    env id)."""
    if not all(hasattr(env, name) for name in ("reset", "step", "action_space")):
        make = f" Make it first: env = gymnasium.make({env!r})." if isinstance(env, str) else ""
        raise TypeError(
            f"expected a gymnasium.Env, got {type(env).__name__} {env!r:.80}.{make}"
            " An env has reset(), step(action), a Discrete action_space and a 1-D float Box"
            " observation_space."
        )
    # a vector env: gymnasium's, or another library's vector API (num_envs, and no gym.Env;
    # a plain gymnasium.Env may set num_envs = 1, and is one env)
    vector = hasattr(env, "num_envs") and (
        not isinstance(env, gym.Env) or getattr(env, "num_envs", 1) != 1
    )
    if isinstance(env, gym.vector.VectorEnv) or vector:
        spec = getattr(env, "spec", None)
        make = f"gymnasium.make({spec.id!r})" if getattr(spec, "id", None) else "gymnasium.make(id)"
        raise ValueError(
            f"expected one env, got a vector env ({type(env).__name__}, "
            f"num_envs={getattr(env, 'num_envs', '?')}): torchcbl teaches one env at a time "
            f"(one observation, one demonstration). Pass {make} instead."
        )
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
            + _obs_space_hint(obs_space)
        )
    return int(obs_space.shape[0]), int(space.n)


def _obs_space_hint(space: Any) -> str:
    """How to wrap an env whose observation space is not a 1-D float Box into one."""
    flat = "gymnasium.wrappers.FlattenObservation(env)"
    # the cast wrapper of the gymnasium installed: DtypeObservation from 1.0 on, the
    # experimental DtypeObservationV0 before (pyproject allows gymnasium >= 0.29)
    if hasattr(gym.wrappers, "DtypeObservation"):
        cast = "gymnasium.wrappers.DtypeObservation(env, np.float64)"
    else:
        cast = "gymnasium.experimental.wrappers.DtypeObservationV0(env, np.float64)"
    try:
        flat_space = gym.spaces.flatten_space(space)
    except Exception:  # noqa: BLE001 - a space gymnasium cannot flatten (or no space at all)
        return (
            f"Wrap the env so that it observes a 1-D float array (for a Dict, Tuple or "
            f"multi-dimensional Box space: {flat}; for integer observations: {cast})."
        )
    flat_needed = not (isinstance(space, gym.spaces.Box) and len(space.shape) == 1)
    cast_needed = not np.issubdtype(flat_space.dtype, np.floating)
    if flat_needed and cast_needed:
        return f"Flatten it and cast it to float: env = {cast.replace('(env', '(' + flat)}."
    if flat_needed:
        return f"Flatten it: env = {flat}."
    return f"Cast it to float: env = {cast}."


def _check_policy_fits(policy: Any, n_features: int, n_actions: int) -> None:
    """A policy with a model (:class:`GreedyPolicy`) must be the env's size."""
    model = getattr(policy, "model", None)
    for what, want, unit in (
        ("n_features", n_features, "features"),
        ("n_actions", n_actions, "actions"),
    ):
        got = getattr(model, what, None)
        if isinstance(got, (int, np.integer)) and int(got) != want:
            raise ValueError(
                f"evaluate_policy: the policy's model has {what}={int(got)} but the env has "
                f"{want} {unit}: the policy was taught on another env. Evaluate it on the env "
                "it was taught on (a session's config.json names it; `torchcbl evaluate "
                "SESSION_DIR` rebuilds it)."
            )


def as_action(value: Any, n_actions: int) -> int | None:
    """``value`` as an action index in [0, ``n_actions``), or None when it is not one: an int or
    numpy integer, or a 0-d integer array or tensor (e.g. ``logits.argmax()``); a bool, a
    float (even 1.0) or an index out of range is None, for the caller to refuse."""
    if isinstance(value, (np.ndarray, torch.Tensor)) and value.ndim == 0:
        value = value.item()  # e.g. logits.argmax(); a float or bool one is refused below
    if not _is_int(value):
        return None
    value = int(value)
    return value if 0 <= value < n_actions else None


def reset_answer(out: Any) -> tuple[Any, dict]:
    """The (observation, info) of what ``env.reset`` returned, or a clear :class:`EnvError`:
    gymnasium's reset returns the pair, an env written for gym < 0.26 the observation alone
    (which unpacked into two of its own values)."""
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        raise EnvError(
            f"env.reset returned {type(out).__name__} {out!r:.80}; expected the gymnasium pair "
            "(observation, info). An env written for gym < 0.26 returns the observation "
            "alone: return (observation, {}) from its reset."
        )
    raw, info = out
    if info is None:
        return raw, {}
    if not isinstance(info, Mapping):
        raise EnvError(
            f"env.reset returned info {info!r:.80}; expected a dict (the second value of the "
            "pair (observation, info)); return (observation, {}) when there is nothing to say "
            "(an env written for gym < 0.26 returns the observation alone)."
        )
    return raw, dict(info)


def step_outcome(out: Any) -> tuple[float, bool, bool, dict]:
    """The (reward, terminated, truncated, info) of what ``env.step`` returned (its observation
    is checked by :func:`obs_array`), or a clear :class:`EnvError`."""
    try:
        _, r, term, trunc, env_info = out
    except (TypeError, ValueError):
        raise EnvError(
            f"env.step returned {type(out).__name__} {out!r:.80}; expected the gymnasium "
            "5-tuple (observation, reward, terminated, truncated, info)"
        ) from None
    if env_info is None:
        info: dict = {}
    elif isinstance(env_info, Mapping):
        info = dict(env_info)
    else:
        raise EnvError(f"env.step returned info {env_info!r:.80}; expected a dict")
    flags = []
    for name, flag in (("terminated", term), ("truncated", trunc)):
        if not isinstance(flag, (bool, np.bool_, int, np.integer)) or flag not in (0, 1):
            raise EnvError(f"env.step returned {name}={flag!r:.80}; expected a bool")
        flags.append(bool(flag))
    try:
        reward = float(r)
    except (TypeError, ValueError, OverflowError):
        reward = math.nan
    if not math.isfinite(reward):
        raise EnvError(f"env.step returned a non-finite reward {r!r:.80}")
    return reward, flags[0], flags[1], info


def obs_array(obs: Any, n_features: int, where: str) -> np.ndarray:
    """``obs`` as a new float64 array [D] (D = ``n_features``), never a view of the env's
    buffer, or an :class:`~torchcbl.errors.EnvError` naming ``where`` (e.g. ``"env.step"``)
    when it is not numeric, not of shape (D,) or not finite."""
    try:
        x = np.array(obs, dtype=np.float64)  # a copy: an env may reuse its buffer in place
    except (TypeError, ValueError, OverflowError) as exc:
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


@overload
def evaluate_policy(
    policy: Callable[[np.ndarray], ActionAnswer],
    env: gym.Env,
    *,
    n_steps: int | None = None,
    n_episodes: int | None = None,
    seed: int | Sequence[int] | None = None,
    uses_info: Literal[False] = False,
) -> list[StepRecord]: ...


@overload
def evaluate_policy(
    policy: Callable[[np.ndarray, dict[str, Any]], ActionAnswer],
    env: gym.Env,
    *,
    n_steps: int | None = None,
    n_episodes: int | None = None,
    seed: int | Sequence[int] | None = None,
    uses_info: Literal[True],
) -> list[StepRecord]: ...


@overload
def evaluate_policy(
    policy: Callable[[np.ndarray], ActionAnswer]
    | Callable[[np.ndarray, dict[str, Any]], ActionAnswer],
    env: gym.Env,
    *,
    n_steps: int | None = None,
    n_episodes: int | None = None,
    seed: int | Sequence[int] | None = None,
    uses_info: bool,
) -> list[StepRecord]: ...


def evaluate_policy(
    policy: Callable[[np.ndarray], ActionAnswer]
    | Callable[[np.ndarray, dict[str, Any]], ActionAnswer],
    env: gym.Env,
    *,
    n_steps: int | None = None,
    n_episodes: int | None = None,
    seed: int | Sequence[int] | None = None,
    uses_info: bool = False,
) -> list[StepRecord]:
    """Run a policy greedily (never asking) and return one record per step.

    ``policy`` is called as ``policy(observation)``; with ``uses_info=True`` it is called as a
    teacher, ``policy(observation, info)`` with the info (a dict) of the latest reset / step,
    so a scripted expert can be evaluated exactly like a learned policy. ``observation`` is a
    copy of the env's observation [D] as the env returned it; the answer is an action index
    in [0, A) (an int, a numpy integer or a 0-d integer array / tensor), anything else a
    ValueError. A policy whose signature cannot take that call (``policy(obs, info)`` without
    ``uses_info=True``, or the reverse) is a TypeError before the env is reset.

    Episodes that end are reset until ``n_steps`` steps or ``n_episodes`` finished episodes,
    whichever comes first; no reset follows the last episode. ``seed`` seeds the resets:

    - an int >= 0 (or None): the first reset gets it, later ones continue the env's RNG;
    - a sequence of ints >= 0: episode ``i`` is reset with ``seed[i]``, so every episode is
      reproducible on its own (e.g. ``seed=range(100, 110)`` for 10 fixed test episodes).
      ``n_episodes`` then defaults to ``len(seed)`` and may not exceed it.

    Records have ``phase="evaluation"``, ``autonomous=True`` and ``episode`` counting from 0;
    a :class:`GreedyPolicy` (a subclass too, whose own ``__call__`` then gives the action) also
    fills the confidence fields, any other callable leaves them None. A GreedyPolicy whose
    model is not fitted (a session's stage 0: see the class) is a RuntimeError, before the env
    is reset where the model says ``is_fitted`` False (else at the first step).
    :func:`episode_results` turns them into per-episode returns and successes.

    The env is reset first. Evaluating on the env a :class:`~torchcbl.teaching.ConfidentTeacher`
    teaches on, between its steps, moves that env away from the observation the loop holds:
    the loop notices at its next step, leaves the episode it was in unfinished (as a resume
    does) and starts a new one, with a warning. To keep the session's episodes whole, evaluate
    on an env of its own (``gymnasium.make`` it again).

    The env's answers are checked as the teaching loop checks them: a reset that is not the pair
    (observation, info), a step that is not the gymnasium 5-tuple with bool flags, a dict
    info and a finite reward, or an observation that is not D finite numbers, is an
    :class:`~torchcbl.errors.EnvError` saying what came back.
    """
    n_features, n_actions = check_env(env)
    _check_policy_fits(policy, n_features, n_actions)
    seeds: list[int] | None = None
    if seed is not None and not isinstance(seed, (int, np.integer)):
        try:
            seeds = list(seed)  # type: ignore[arg-type]
        except TypeError:
            seeds = None
        if seeds is None or not seeds or not all(_is_int(s) for s in seeds):
            raise ValueError(
                "evaluate_policy: seed must be None, an int, or a non-empty sequence of ints "
                f"(one per episode), got {seed!r}"
            )
        seeds = [int(s) for s in seeds]
        if n_episodes is None:
            n_episodes = len(seeds)
    elif isinstance(seed, (bool, np.bool_)):
        raise ValueError(
            f"evaluate_policy: seed must be None, an int or a list of ints, got {seed!r}"
        )
    negative = [s for s in (seeds if seeds is not None else [seed]) if s is not None and s < 0]
    if negative:  # (gymnasium's reset refuses it with a message of its own)
        where = f"seed={int(seed)}" if seeds is None else f"{negative[0]} in seed={seed!r}"
        raise ValueError(
            f"evaluate_policy: seeds must be ints >= 0 (each seeds an env.reset), got {where}"
        )
    if n_steps is None and n_episodes is None:
        raise ValueError("evaluate_policy: give n_steps and/or n_episodes, or it never ends")
    for name, v in (("n_steps", n_steps), ("n_episodes", n_episodes)):
        if v is not None and (not _is_int(v) or v < 1):
            raise ValueError(f"evaluate_policy: {name} must be an int >= 1, got {v!r}")
    n_steps = None if n_steps is None else int(n_steps)
    n_episodes = None if n_episodes is None else int(n_episodes)
    if seeds is None and seed is not None:
        seed = int(seed)  # gymnasium's reset takes a Python int only, not np.int64(3)
    if seeds is not None and n_episodes is not None and n_episodes > len(seeds):
        raise ValueError(
            f"evaluate_policy: n_episodes={n_episodes} but only {len(seeds)} seeds were given; "
            "give one seed per episode (or leave n_episodes out to run one per seed)"
        )
    # a GreedyPolicy's classification fills the confidence fields; its action is the model's
    # unless a subclass answers in a __call__ of its own (masking, exploration), which is called
    greedy = isinstance(policy, GreedyPolicy)
    own_call = not greedy or type(policy).__call__ is not GreedyPolicy.__call__
    why = _cannot_take(policy, 2 if uses_info else 1) if own_call else None
    call = "(observation, info)" if uses_info else "(observation)"
    if (
        why is not None
        and not (why.missing or why.keyword_only or uses_info)
        and len(why.extra) == 1
        and why.extra[0] in why.positional
    ):
        # one required argument more than the observation: a policy of (observation, info)
        raise TypeError(
            f"evaluate_policy: the policy is called as policy(observation) (uses_info=False), "
            f"but {why.takes}: it needs more arguments. For a policy of the observation and the "
            "info, called policy(observation, info) like a teacher (a scripted expert), pass "
            f"uses_info=True; else {why.advice(call)}"
        )
    if why is not None and why.missing and uses_info:
        also = why.advice(call)
        raise TypeError(
            f"evaluate_policy: with uses_info=True the policy is called as "
            f"policy(observation, info), but {why.takes}. For a policy of the observation alone, "
            f"leave uses_info out (False){f' ({also})' if also else ''}"
        )
    if why is not None:
        fix = why.advice(call) or "it must take the observation"
        raise TypeError(
            f"evaluate_policy: the policy is called as policy{call} (uses_info={uses_info}), "
            f"but {why.takes}; {fix}"
        )
    fitted = getattr(getattr(policy, "model", None), "is_fitted", None)
    if greedy and not own_call and fitted is False:  # (a model that says so)
        raise RuntimeError(f"evaluate_policy: {_UNFITTED}")
    records: list[StepRecord] = []
    _note_env_user(env, object())  # a teaching loop mid-episode on this env starts a new one
    raw, info = reset_answer(env.reset(seed=seeds[0] if seeds is not None else seed))
    obs = obs_array(raw, n_features, "env.reset")
    episode, done_episodes = 0, 0
    while (n_steps is None or len(records) < n_steps) and (
        n_episodes is None or done_episodes < n_episodes
    ):
        confidence = distance = posterior = None
        answer: Any = None
        if greedy:
            c = policy.classify(obs)  # type: ignore[attr-defined]
            answer = int(c.action[0])
            if answer < 0 and not own_call:  # a model that does not say is_fitted
                raise RuntimeError(f"evaluate_policy: {_UNFITTED}")
            confidence, distance = float(c.confidence[0]), float(c.distance[0])
            posterior = tuple(c.posterior[0].tolist())
        if own_call and uses_info:
            answer = policy(np.array(raw, copy=True), dict(info or {}))  # type: ignore[call-arg]
        elif own_call:
            answer = policy(np.array(raw, copy=True))
        action = as_action(answer, n_actions)
        if action is None:
            raise ValueError(
                f"evaluate_policy: the policy answered {answer!r}; expected an int in "
                f"[0, {n_actions})."
            )
        out = env.step(action)
        reward, term, trunc, info = step_outcome(out)
        raw_next = out[0]
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
                terminated=term,
                truncated=trunc,
                info=jsonable_info(info),
            )
        )
        if n_steps is not None and len(records) >= n_steps:
            break  # the last step: no reset and no observation check after it
        if term or trunc:
            done_episodes += 1
            episode += 1
            if n_episodes is not None and done_episodes >= n_episodes:
                break  # no reset after the last episode (for SUMO, a whole new road)
            raw, info = reset_answer(env.reset(seed=None if seeds is None else seeds[episode]))
        else:
            raw = raw_next
        obs = obs_array(raw, n_features, "env.step" if not (term or trunc) else "env.reset")
    return records


@dataclass(frozen=True)
class EpisodeResult:
    """What one episode of a list of :class:`StepRecord` came to (see :func:`episode_results`).

    Attributes:
        episode: the records' episode index.
        steps: steps in the episode.
        episode_return: sum of its rewards (undiscounted; steps whose outcome was never
            observed, reward None, are left out).
        success: the env's ``info["is_success"]`` at the episode's end as a bool; None when the
            env did not say or the episode did not end in the records.
        terminated, truncated: the env's flags at its last step.
        finished: whether the episode ended (terminated or truncated) within the records;
            False for an episode cut by ``n_steps``.
    """

    episode: int
    steps: int
    episode_return: float
    success: bool | None
    terminated: bool
    truncated: bool
    finished: bool


def episode_results(records: Sequence[StepRecord]) -> list[EpisodeResult]:
    """Per-episode returns and successes of the records of :func:`evaluate_policy` (or of a
    teaching session, :func:`torchcbl.load_records`), in episode order.

    An episode is a run of consecutive records with the same ``episode`` index; a record after
    one that ended its episode (terminated or truncated), or whose ``step`` does not follow the
    one before (a list that starts again from step 0), starts a new one. So the records of
    several evaluations may be joined (each numbers its episodes from 0)::

        records = []
        for s in range(10):
            records += evaluate_policy(policy, env, n_episodes=1, seed=s)
        results = episode_results(records)  # 10 episodes

    Example::

        results = episode_results(evaluate_policy(policy, env, seed=range(10)))
        returns = [e.episode_return for e in results]
        success_rate = sum(e.success is True for e in results) / len(results)
    """
    results: list[EpisodeResult] = []
    group: list[StepRecord] = []

    def close() -> None:
        last = group[-1]
        finished = bool(last.terminated or last.truncated)
        flag = last.info.get("is_success") if finished else None
        results.append(
            EpisodeResult(
                episode=last.episode,
                steps=len(group),
                episode_return=math.fsum(r.reward for r in group if r.reward is not None),
                success=None if flag is None else bool(flag),
                terminated=bool(last.terminated),
                truncated=bool(last.truncated),
                finished=finished,
            )
        )

    for r in records:
        if group:
            prev = group[-1]
            if (
                r.episode != prev.episode
                or prev.terminated
                or prev.truncated
                or r.step <= prev.step
            ):
                close()
                group = []
        group.append(r)
    if group:
        close()
    return results
