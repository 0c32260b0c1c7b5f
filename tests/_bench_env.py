"""A registered toy env and its teacher factory for the benchmark tests (found by import path,
also in worker processes: gymnasium id ``_bench_env:BenchCluster-v0``)."""

from __future__ import annotations

from typing import Any

from _toy_envs import oracle, rare_regions_world
from gymnasium.envs.registration import register, registry

ENV_ID = "BenchCluster-v0"


def make_world(episode_length: int = 10, spread: float = 1.0) -> Any:
    return rare_regions_world(episode_length=episode_length, spread=spread)


def teacher(env: Any) -> Any:
    return oracle(env.unwrapped)


if ENV_ID not in registry:
    register(id=ENV_ID, entry_point="_bench_env:make_world")


def endless_world(spread: float = 2.0) -> Any:
    """The toy env with episodes that never end (no TimeLimit either: registered without
    max_episode_steps), as a user's env that stops only where its task is done can be."""
    return rare_regions_world(episode_length=10**12, spread=spread)


if "BenchEndless-v0" not in registry:
    register(id="BenchEndless-v0", entry_point="_bench_env:endless_world")


def toy_spec(**kw: Any) -> Any:
    """The benchmark tests' EnvSpec of this env (cheap cells: 60 steps, budgets 5, 10, 20);
    ``kw`` overrides its fields."""
    from torchcbl.benchmark import EnvSpec

    return EnvSpec(
        **{
            "name": "toy",
            "env_id": "_bench_env:BenchCluster-v0",
            "teacher": "_bench_env:teacher",
            "budgets": (5, 10, 20),
            "max_steps": 60,
            "env_kwargs": {"spread": 2.0},
            "eval_seeds": (100, 101),
            "eval_episodes": 3,
            "teaching": {"max_new": 5},
            "model": {"max_components": 2},
            **kw,
        }
    )


def policy_as_teacher(env: Any) -> Any:
    """A factory that returns a policy of the observation alone, not a teacher (a user's slip)."""
    return lambda obs: 0


def pole_teacher(env: Any) -> Any:
    """CartPole's textbook controller: push toward the side the pole leans to."""
    return lambda obs, info: int(obs[2] + 0.5 * obs[3] > 0)


def glitchy_teacher(env: Any, seed: int) -> Any:
    """The oracle, except that on seed 1 it raises at its third call (a teacher's bug that
    shows on one cell of a sweep only)."""
    inner, calls = oracle(env.unwrapped), [0]

    def teach(obs: Any, info: dict) -> int:
        calls[0] += 1
        if seed == 1 and calls[0] == 3:
            raise ValueError("sensor glitch")
        return inner(obs, info)

    return teach


def steps_over_budget(records: Any) -> float:
    """A cost-like score, higher when better and below 0 for every policy (the teacher too):
    minus the number of evaluation steps."""
    return -float(len(records))


def sloppy_teacher(env: Any) -> Any:
    """The oracle, answering at random on a share of the steps drawn from numpy's and Python's
    global RNGs (as a quick teacher of one's own often does)."""
    import random

    import numpy as np

    inner = oracle(env.unwrapped)

    def teach(obs: Any, info: dict) -> int:
        if np.random.random() < 0.3:  # noqa: NPY002
            return random.randrange(env.action_space.n)
        return inner(obs, info)

    return teach


# what each call of drawing_teacher drew from numpy's global RNG, in call order
GLOBAL_DRAWS: list[tuple[float, ...]] = []


def drawing_teacher(env: Any) -> Any:
    """The oracle, from a factory that draws three numbers from numpy's global RNG as it is
    called (as a teacher of one's own may, to perturb itself) and keeps them in GLOBAL_DRAWS."""
    import numpy as np

    GLOBAL_DRAWS.append(tuple(float(v) for v in np.random.random(3)))  # noqa: NPY002
    return oracle(env.unwrapped)


def mean_finished_length(records: Any) -> float:
    """The mean length of the evaluation's finished episodes: NaN (numpy's mean of nothing)
    when none finished."""
    import warnings

    import numpy as np

    lengths, n = [], 0
    for r in records:
        n += 1
        if r.terminated or r.truncated:
            lengths.append(n)
            n = 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return float(np.mean(lengths))


def no_score(records: Any) -> None:
    """A score that forgot its return statement."""


def dying_teacher(env: Any, seed: int) -> Any:
    """The oracle, except that on seed 1 its process is killed at its third call (a worker
    taken by the kernel's out-of-memory killer)."""
    import os
    import signal

    inner, calls = oracle(env.unwrapped), [0]

    def teach(obs: Any, info: dict) -> int:
        calls[0] += 1
        if seed == 1 and calls[0] == 3:
            os.kill(os.getpid(), signal.SIGKILL)
        return inner(obs, info)

    return teach


def failing_sweep(out: str) -> None:
    """A sweep whose one cell fails (glitchy_teacher on seed 1), to run in a process of one's
    own."""
    from torchcbl import benchmark as bm

    env = bm.EnvSpec(
        name="toy",
        env_id="_bench_env:BenchCluster-v0",
        teacher="_bench_env:glitchy_teacher",
        budgets=(5,),
        max_steps=10,
        eval_episodes=1,
    )
    bm.run_benchmark([bm.StrategySpec("bc")], [env], [1], out, workers=1, plots=False)


def bare_teacher(obs: Any, info: dict) -> int:
    """A teacher itself, not a factory that returns one (what --teacher must name)."""
    return 0


class StrategyWithParams:
    """A strategy of one's own whose constructor needs a parameter (the command gives none)."""

    def __new__(cls, horizon: int) -> Any:
        from torchcbl.strategies.dagger import DAgger

        return DAgger(iteration_steps=horizon)


class StrategyThatFails:
    """A strategy class whose constructor fails for a reason of its own (no parameter missing)."""

    def __init__(self) -> None:
        raise RuntimeError("needs a licence file")


def noisy_teacher(env: Any, seed: int) -> Any:
    """The oracle, answering at random on 20 % of its calls, drawn from its own generator
    seeded by the cell's seed (a stochastic teacher, as the driving domain's person is)."""
    import numpy as np

    inner, rng = oracle(env.unwrapped), np.random.default_rng(seed)

    def teach(obs: Any, info: dict) -> int:
        wanted = inner(obs, info)
        return int(rng.integers(0, 2)) if rng.random() < 0.2 else wanted

    return teach


def teacher_failing_while_told(env: Any) -> Any:
    """The oracle, except that it raises at its third call while the environment variable
    BENCH_TEACHER_FAILS is set: a cell that stops part-way in one run (as a Ctrl-C or a crash
    stops it) and goes through when run again."""
    import os

    inner, calls = oracle(env.unwrapped), [0]

    def teach(obs: Any, info: dict) -> int:
        calls[0] += 1
        if os.environ.get("BENCH_TEACHER_FAILS") and calls[0] == 3:
            raise RuntimeError("stopped part-way")
        return inner(obs, info)

    return teach


def teacher_killed_while_told(env: Any) -> Any:
    """The oracle, except that its process is killed (SIGKILL) at its third call while the
    environment variable BENCH_TEACHER_KILLED is set: a cell killed mid-way in one run (the
    out-of-memory killer) that goes through when run again."""
    import os
    import signal

    inner, calls = oracle(env.unwrapped), [0]

    def teach(obs: Any, info: dict) -> int:
        calls[0] += 1
        if os.environ.get("BENCH_TEACHER_KILLED") and calls[0] == 3:
            os.kill(os.getpid(), signal.SIGKILL)
        return inner(obs, info)

    return teach


def teacher_once_stdout_has_no_reader(env: Any) -> Any:
    """The oracle, made once nothing reads this process's standard output any more (its
    pipe's reader has gone, as ``| head -2`` goes once it has its lines), or after 30 s."""
    import select
    import sys
    import time

    poller = select.poll()
    poller.register(sys.stdout.fileno(), select.POLLOUT)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        if any(ev & select.POLLERR for _, ev in poller.poll(0)):
            break
        time.sleep(0.02)
    return oracle(env.unwrapped)


def teacher_of_a_cleaned_out(env: Any, out: str) -> Any:
    """The oracle, made after ``out/cells`` and ``out`` are removed where they are empty, as a
    second sweep into the same new OUT removes them when its first cell fails before this
    sweep's first cell is written."""
    import os

    for folder in (os.path.join(out, "cells"), out):
        try:
            os.rmdir(folder)
        except OSError:  # not there, or not empty (a cell is written): left as it is
            pass
    return oracle(env.unwrapped)


def teacher_ctrl_c_on_seed_1(env: Any, seed: int) -> Any:
    """The oracle, except that on seed 1 its first call raises KeyboardInterrupt: a Ctrl-C
    while the second cell of an in-process sweep (workers=1) teaches."""
    inner = oracle(env.unwrapped)

    def teach(obs: Any, info: dict) -> int:
        if seed == 1:
            raise KeyboardInterrupt
        return inner(obs, info)

    return teach
