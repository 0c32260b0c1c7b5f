"""Small gymnasium worlds with a known optimal policy, for the teaching-loop tests and benches.

:class:`ClusterWorld`: each step the agent sees a point drawn from one of several Gaussian
regions (chosen with given probabilities); the right action is the label of the region whose
centre is nearest (the teacher's policy, optimal by construction: reward 1 when the executed
action equals it, else 0). An episode is ``episode_length`` steps; it ends with
``info["is_success"]`` True when every action in it was right. Regions may overlap (then the
nearest-centre boundary cuts through data of both labels) and may be rare, which is what makes
asking only where unsure pay off.
"""

from __future__ import annotations

import os
import sys
from typing import Any

import gymnasium as gym
import numpy as np


class ClusterWorld(gym.Env):
    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        centers: Any,
        labels: Any,
        probs: Any,
        *,
        spread: float = 1.0,
        episode_length: int = 20,
        n_actions: int | None = None,
    ) -> None:
        self.centers = np.asarray(centers, dtype=np.float64)
        self.labels = np.asarray(labels, dtype=np.int64)
        self.probs = np.asarray(probs, dtype=np.float64)
        self.spread = float(spread)
        self.episode_length = int(episode_length)
        d = self.centers.shape[1]
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(d,), dtype=np.float32)
        self.action_space = gym.spaces.Discrete(
            int(self.labels.max()) + 1 if n_actions is None else n_actions
        )
        self._obs = np.zeros(d, dtype=np.float32)
        self._t = 0
        self._all_right = True

    def optimal_action(self, obs: Any) -> int:
        """The teacher's (optimal) action: label of the nearest region centre."""
        d2 = ((self.centers - np.asarray(obs, dtype=np.float64)) ** 2).sum(1)
        return int(self.labels[int(d2.argmin())])

    def region_of(self, obs: Any) -> int:
        d2 = ((self.centers - np.asarray(obs, dtype=np.float64)) ** 2).sum(1)
        return int(d2.argmin())

    def sample(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """n observations from the world's distribution and their optimal actions."""
        p = self.probs / self.probs.sum()
        regions = rng.choice(len(p), size=n, p=p)
        x = self.centers[regions] + self.spread * rng.standard_normal((n, self.centers.shape[1]))
        x = x.astype(np.float32).astype(np.float64)
        return x, np.asarray([self.optimal_action(o) for o in x])

    def _draw(self) -> np.ndarray:
        p = self.probs / self.probs.sum()
        r = int(self.np_random.choice(len(p), p=p))
        x = self.centers[r] + self.spread * self.np_random.standard_normal(self.centers.shape[1])
        self._obs = x.astype(np.float32)
        return self._obs.copy()

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self._t = 0
        self._all_right = True
        return self._draw(), {}

    def step(self, action: int):
        right = int(action) == self.optimal_action(self._obs)
        self._all_right &= right
        self._t += 1
        truncated = self._t >= self.episode_length
        info: dict[str, Any] = {"optimal": right}
        if truncated:
            info["is_success"] = self._all_right
        return self._draw(), float(right), False, truncated, info


def rare_regions_world(**kw: Any) -> ClusterWorld:
    """2-D, 3 actions: a frequent region (90%) and two rare, well separated ones (5% each)."""
    return ClusterWorld([[0, 0], [8, 0], [0, 8]], [0, 1, 2], [0.9, 0.05, 0.05], **kw)


def novelty_world(**kw: Any) -> ClusterWorld:
    """2-D, 3 actions; region 2 is switched off (probability 0) until a test turns it on."""
    return ClusterWorld([[0, 0], [8, 0], [4, 7]], [0, 1, 2], [0.5, 0.5, 0.0], **kw)


def overlap_world(**kw: Any) -> ClusterWorld:
    """1-D, 2 actions: two overlapping regions at -1 and +1; the optimal action is sign(x)."""
    return ClusterWorld([[-1.0], [1.0]], [0, 1], [0.5, 0.5], **kw)


def four_d_world(**kw: Any) -> ClusterWorld:
    """4-D, 3 actions, 4 well separated regions (action 0 in two of them)."""
    c = np.zeros((4, 4))
    c[1, 0] = c[2, 1] = c[3, 2] = 8.0
    return ClusterWorld(c, [0, 1, 2, 0], [0.4, 0.2, 0.2, 0.2], **kw)


def six_d_world(**kw: Any) -> ClusterWorld:
    """6-D, 3 actions, 5 regions 4 std apart (neighbouring regions of different actions
    overlap: a region's Gaussian puts 2.3 % of its mass across each nearest-centre boundary);
    action 0 in two regions, action 1 in two."""
    c = np.zeros((5, 6))
    c[1, 0] = c[2, 1] = c[3, 2] = 4.0
    c[4, 0] = c[4, 3] = 4.0
    return ClusterWorld(c, [0, 1, 2, 0, 1], [0.3, 0.2, 0.2, 0.15, 0.15], **kw)


def oracle(env: ClusterWorld):
    """The optimal teacher of a ClusterWorld, as ``teacher(obs, info) -> int``."""

    def teacher(obs: np.ndarray, info: dict) -> int:
        return env.optimal_action(obs)

    return teacher


class FaultyWorld(gym.Wrapper):
    """Wraps a world; at global step ``fail_at`` returns NaN (``mode="nan"``) or raises."""

    def __init__(self, env: gym.Env, fail_at: int, mode: str = "nan") -> None:
        super().__init__(env)
        self.fail_at = fail_at
        self.mode = mode
        self.n_steps = 0

    def step(self, action: int):
        self.n_steps += 1
        if self.n_steps == self.fail_at:
            if self.mode == "raise":
                raise OSError("simulator connection lost")
            obs, r, term, trunc, info = self.env.step(action)
            return np.full_like(obs, np.nan), r, term, trunc, info
        return self.env.step(action)


# -- the process the SIGKILL test and bench kill -------------------------------------------------


class _SideLog(gym.Wrapper):
    """Writes ``E <step> <action>`` with os.write before each env.step (survives SIGKILL)."""

    def __init__(self, env: gym.Env, fd: int, base: int) -> None:
        super().__init__(env)
        self.fd, self.base, self.k = fd, base, 0

    def step(self, action: int):
        os.write(self.fd, f"E {self.base + self.k} {int(action)}\n".encode())
        self.k += 1
        return self.env.step(action)


def kill_child_main(run_dir: str, side_log: str, mode: str = "ce") -> None:
    """Create or resume a session in ``run_dir`` and teach until killed.

    Appends to ``side_log``: ``T <step> <label>`` when the teacher answers, ``E <step> <action>``
    when an action is handed to the env, and (``mode="cba"``: Confidence-Based Autonomy with a
    correcting teacher) ``C <step> <action>`` when the teacher corrects step ``<step>``; the
    parent checks every executed demonstration, and every correction followed by a later
    action, is in the log.
    """
    import torch

    from torchcbl import ConfidentTeacher, GaussianMixtureSet, PosteriorRule, TeachingConfig

    torch.set_num_threads(1)

    world = overlap_world(episode_length=25)
    fd = os.open(side_log, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    config = TeachingConfig(max_new=1, accuracy_window=10, target_accuracy=0.8, max_steps=10**9)
    rule = PosteriorRule(0.9)
    kw: dict[str, Any] = {"rule": rule}
    if mode == "cba":
        from torchcbl.strategies.cba import ConfidenceBasedAutonomy

        kw = {"strategy": ConfidenceBasedAutonomy()}
        config = TeachingConfig(max_new=1, noninteractive=False, max_steps=10**9)
    exists = os.path.exists(os.path.join(run_dir, "config.json"))
    model = GaussianMixtureSet(2, 1, max_components=3, seed=0)
    holder: dict[str, Any] = {}

    class Teacher:
        def __call__(self, obs: np.ndarray, info: dict) -> int:
            a = world.optimal_action(obs)
            os.write(fd, f"T {holder['env'].base + holder['env'].k} {a}\n".encode())
            return a

        def correct(self, obs: np.ndarray, info: dict, action: int) -> int | None:
            a = world.optimal_action(obs)
            if a == action:
                return None
            # the step just executed is the env's latest one
            os.write(fd, f"C {holder['env'].base + holder['env'].k - 1} {a}\n".encode())
            return a

    teacher = Teacher() if mode == "cba" else Teacher().__call__

    if exists:
        from torchcbl.session import load_records

        base = len(load_records(run_dir))
        env = _SideLog(world, fd, base)
        holder["env"] = env
        ct = ConfidentTeacher.resume(
            run_dir, env, teacher, model=model, config=config, progress=False, **kw
        )
        assert ct.n_steps == base
    else:
        env = _SideLog(world, fd, 0)
        holder["env"] = env
        ct = ConfidentTeacher(
            env,
            teacher,
            model=model,
            config=config,
            run_dir=run_dir,
            **kw,
            seed=0,
            progress=False,
        )
    sys.stdout.write("ready\n")
    sys.stdout.flush()
    ct.run()


def check_corrections_kept(run_dir: Any, side_log: Any) -> tuple[int, int]:
    """Every correction the teacher gave (``C`` lines) that was followed by a later action
    reaching the env is in the run directory's log, with its action. Returns (corrections in
    the log, corrections the kill caught before anything followed them)."""
    from torchcbl.session import load_corrections

    logged = {c.step: c.action for c in load_corrections(run_dir)}
    given: dict[int, int] = {}
    last_executed = -1
    for line in open(side_log, encoding="utf-8").read().splitlines():
        kind, step, action = line.split()
        if kind == "C":
            given[int(step)] = int(action)
        elif kind == "E":
            last_executed = max(last_executed, int(step))
    unacknowledged = 0
    for step, action in given.items():
        if step < last_executed:
            assert logged.get(step) == action, (
                f"correction of step {step} (action {action}) was followed by step "
                f"{last_executed} but is not in the log ({logged.get(step)})"
            )
        elif step not in logged:
            unacknowledged += 1
    return len(logged), unacknowledged


if __name__ == "__main__":
    kill_child_main(*sys.argv[1:4])
