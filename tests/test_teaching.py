"""The confident-execution loop (Algorithm 1) on small worlds with a known optimal policy."""

from __future__ import annotations

import copy
import pickle
import re

import gymnasium as gym
import numpy as np
import pytest
import torch
from _toy_envs import (
    ClusterWorld,
    novelty_world,
    oracle,
    overlap_world,
    rare_regions_world,
)

from torchcbl import (
    ConfidentTeacher,
    GaussianMixtureSet,
    PosteriorRule,
    TeachingConfig,
    evaluate_policy,
    load_records,
)
from torchcbl.teaching import GreedyPolicy


def make(env, **cfg):
    kw = {k: cfg.pop(k) for k in ("rule", "model", "seed", "on_refit", "on_step") if k in cfg}
    return ConfidentTeacher(env, oracle(env), config=TeachingConfig(**cfg), progress=False, **kw)


def test_before_any_model_every_step_asks():
    ct = make(rare_regions_world(), noninteractive=False, max_new=4)
    ct.run(max_steps=4)
    assert [r.teacher_action is not None for r in ct.records] == [True] * 4
    assert [r.model_action for r in ct.records] == [-1] * 4
    assert all(r.distance == float("inf") and r.confidence == 0.0 for r in ct.records)
    assert all(r.phase == "confident" for r in ct.records)
    assert ct.model.is_fitted  # refitted after the 4th demonstration


def test_a_teacher_of_the_observation_alone_is_refused_before_anything_runs(tmp_path):
    """The loop calls teacher(observation, info). A policy-style teacher of the observation
    alone was taken, and the session stopped at its first request with a TeacherError around
    Python's "takes 1 positional argument but 2 were given", its run directory already
    written. Its signature is read first: a TypeError says how a teacher is called, what
    this one takes and how to wrap it, and no run directory is made. A teacher with an
    optional info, or *args, or a keyword-only parameter of its own with a default, is
    taken."""
    env = rare_regions_world()
    with pytest.raises(TypeError) as e:
        ConfidentTeacher(env, lambda obs: 0, run_dir=tmp_path / "s", progress=False)
    msg = str(e.value)
    assert "teacher(observation, info)" in msg and "<lambda> takes (obs)" in msg, msg
    assert "lambda obs, info:" in msg, msg
    assert not (tmp_path / "s").exists()
    for teacher in (lambda obs, info=None: 0, lambda *args: 0, lambda obs, info, *, k=0: k):
        ct = ConfidentTeacher(env, teacher, progress=False)
        ct.run(max_steps=2)
        assert [r.teacher_action for r in ct.records] == [0, 0]


def test_a_teacher_that_wraps_a_policy_with_functools_wraps_is_taken():
    """The signature check read through ``functools.wraps``: an adapter
    ``@wraps(policy) def teacher(obs, info): return policy(obs)``, the wrapping the refusal
    itself advises, was refused as "policy takes (obs)" (the wrapped function's signature, not
    the one called), and so was a session resumed with it. The adapter's own signature counts."""
    import functools

    env = rare_regions_world()

    def policy(obs):
        return 0

    @functools.wraps(policy)
    def teacher(obs, info):
        return policy(obs)

    ct = ConfidentTeacher(env, teacher, progress=False)
    ct.run(max_steps=2)
    assert [r.teacher_action for r in ct.records] == [0, 0]

    # and the reverse: a one-argument wrapper of a teacher is still refused by what it takes
    @functools.wraps(teacher)
    def alone(obs):
        return 0

    with pytest.raises(TypeError, match=r"takes \(obs\)"):
        ConfidentTeacher(env, alone, progress=False)
    # a generic (*args, **kwargs) wrapper is read through to what it calls: torch.no_grad()
    # around a teacher of the observation alone is refused up front, not at the first request
    no_grad_alone = torch.no_grad()(policy)
    with pytest.raises(TypeError, match=r"takes \(obs\)"):
        ConfidentTeacher(env, no_grad_alone, progress=False)
    ct = ConfidentTeacher(env, torch.no_grad()(teacher), progress=False)
    ct.run(max_steps=1)


def test_a_teacher_whose_wrapped_chain_never_ends_is_read_in_bounded_time():
    """The signature check reads a generic (*args, **kwargs) wrapper through its __wrapped__,
    one at a time. A proxy whose __getattr__ makes (and keeps) a new proxy for any name has a
    chain without end: it was walked until memory ran out. At most 100 hops are read, and a
    chain of wrappers that says nothing more is taken, as a wrapper of unknown signature is."""
    made = []

    class Proxy:
        def __call__(self, *args, **kwargs):
            return 0

        def __getattr__(self, name):
            if len(made) > 10_000:
                raise RuntimeError("the __wrapped__ chain was walked without end")
            made.append(Proxy())
            return made[-1]

    ct = ConfidentTeacher(rare_regions_world(), Proxy(), progress=False)
    ct.run(max_steps=2)
    assert [r.teacher_action for r in ct.records] == [0, 0]
    assert len(made) <= 1_000  # 100 a check at most (the teacher is checked more than once)


def test_a_method_under_a_generic_wrapper_is_read_as_it_is_called():
    """A teacher method under a generic (*args, **kwargs) wrapper, ``@torch.no_grad() def
    act(self, obs, info)`` given as ``agent.act`` (a common PyTorch pattern), was refused as
    "act takes (self, obs, info)": the walk read the bound method's __wrapped__, the plain
    function, with its ``self``. It is read bound, as it is called; a method of the
    observation alone is still refused."""

    class Agent:
        @torch.no_grad()
        def act(self, obs, info):
            return 0

        @torch.no_grad()
        def act_alone(self, obs):
            return 0

    env = rare_regions_world()
    agent = Agent()
    ct = ConfidentTeacher(env, agent.act, progress=False)
    ct.run(max_steps=2)
    assert [r.teacher_action for r in ct.records] == [0, 0]
    with pytest.raises(TypeError, match=r"takes \(obs\)"):
        ConfidentTeacher(env, agent.act_alone, progress=False)


def test_windowed_accuracy_and_phase_switch_as_specified():
    ct = make(rare_regions_world(), accuracy_window=10, target_accuracy=0.9, max_new=1)
    ct.run(max_steps=80)
    recs = ct.records
    window: list[bool] = []
    switch = None
    for i, r in enumerate(recs):
        if r.phase == "noninteractive":
            window = (window + [r.model_action == r.teacher_action])[-10:]
            assert r.windowed_accuracy == pytest.approx(sum(window) / len(window))
            if len(window) == 10 and sum(window) >= 9:
                switch = i + 1
                break
    assert switch is not None and switch >= 10
    assert all(r.phase == "noninteractive" for r in recs[:switch])
    assert all(r.phase == "confident" for r in recs[switch:])
    # Every prediction is scored BEFORE the point is learned: the first step had no model.
    assert recs[0].model_action == -1 and recs[0].windowed_accuracy == 0.0


def test_target_none_never_switches_and_noninteractive_false_skips():
    ct = make(rare_regions_world(), target_accuracy=None)
    ct.run(max_steps=60)
    assert all(r.phase == "noninteractive" and r.is_demonstration for r in ct.records)
    ct2 = make(rare_regions_world(), noninteractive=False)
    ct2.run(max_steps=60)
    assert all(r.phase == "confident" for r in ct2.records)
    assert any(r.autonomous for r in ct2.records)


def test_refit_after_every_max_new_demonstrations():
    seen: list[int] = []
    ct = make(
        rare_regions_world(), max_new=5, target_accuracy=None, on_refit=lambda m, n: seen.append(n)
    )
    ct.run(max_demonstrations=23)
    assert seen == [5, 10, 15, 20]
    assert int(ct.model.n_points_.sum()) == 20


def test_autonomy_grows_and_requests_fall():
    ct = make(rare_regions_world(), noninteractive=False, accuracy_window=50)
    ct.run(max_steps=600)
    asked = np.array([r.is_demonstration for r in ct.records])
    assert asked[:100].sum() > 3 * asked[-200:].sum()
    # Not zero: the 2-std rule leaves a share of any fitted cluster's own points outside
    # (exp(-2) = 13.5% for a 2-D Gaussian); seen 4-5% here, depending on the EM tolerance.
    assert asked[-200:].mean() < 0.08
    assert ct.records[100].autonomy_rate < ct.records[-1].autonomy_rate
    assert ct.autonomy_rate >= 0.9


def test_asks_where_unsure_and_not_elsewhere():
    env = novelty_world()
    ct = make(env, noninteractive=False)
    ct.run(max_steps=300)
    env.probs = np.array([0.4, 0.4, 0.2])  # a region never seen before appears
    ct.run(max_steps=500)
    new = ct.records[300:]
    region = np.array([env.region_of(r.observation) for r in new])
    asked = np.array([r.is_demonstration for r in new])
    assert (region == 2).sum() > 20
    # The familiar regions are (almost) never asked about, the novel one is.
    assert asked[region != 2].mean() < 0.03
    assert asked[region == 2][:3].all()
    assert (region[asked] == 2).mean() > 0.8


def test_posterior_rule_asks_near_the_overlap():
    env = overlap_world()
    # A non-interactive start: with one action seen, its posterior is 1 everywhere.
    ct = make(env, rule=PosteriorRule(0.9))
    ct.run(max_steps=500)
    assert ct.records[200].phase == "confident"
    late = ct.records[200:]
    x = np.abs([r.observation[0] for r in late])
    asked = np.array([r.is_demonstration for r in late])
    assert 0 < asked.sum() < len(late)
    assert x[asked].mean() < 0.5 * x[~asked].mean()


def test_burst_gives_consecutive_teacher_moves():
    ct = make(rare_regions_world(episode_length=1000), noninteractive=False, burst=3)
    ct.run(max_steps=200)
    asked = [r.is_demonstration for r in ct.records]
    runs, n = [], 0  # lengths of the maximal runs of consecutive teacher moves
    for a in [*asked, False]:
        if a:
            n += 1
        elif n:
            runs.append(n)
            n = 0
    if asked[-1]:
        runs.pop()  # the last run may be cut by max_steps
    # every request brings exactly 3 teacher moves: runs are whole bursts, neither longer
    # nor shorter, and some bursts stand alone (the agent was confident right after)
    assert runs and all(r % 3 == 0 for r in runs), runs
    assert 3 in runs


def test_stop_criteria():
    ct = make(rare_regions_world(), noninteractive=False, autonomous_steps_to_stop=30)
    ct.run()
    tail = ct.records[-30:]
    assert all(r.autonomous for r in tail)
    assert not ct.records[-31].autonomous  # stopped exactly when the streak reached 30
    n = ct.n_steps
    ct.run(max_demonstrations=ct.n_demonstrations + 2)
    assert ct.n_demonstrations == ct.records[-1].n_demonstrations
    assert ct.n_steps > n and ct.records[-1].is_demonstration

    ct = make(rare_regions_world(episode_length=10), noninteractive=False)
    ct.run(autonomous_episodes_to_stop=3)
    last = ct.records[-30:]
    assert all(r.autonomous for r in last) and last[-1].truncated
    assert [r.info.get("is_success") for r in last if r.truncated] == [True] * 3

    with pytest.raises(ValueError, match="never end"):
        make(rare_regions_world()).run()
    with pytest.raises(ValueError, match="unknown stop criteria"):
        make(rare_regions_world()).run(max_step=3)


def test_run_continues_and_snapshots_at_stages():
    ct = make(rare_regions_world(), noninteractive=False)
    snaps = {}
    for k in (10, 20):
        ct.run(max_demonstrations=k)
        assert ct.n_demonstrations == k
        snaps[k] = copy.deepcopy(ct.model)
    assert int(snaps[10].n_points_.sum()) == 10 and int(snaps[20].n_points_.sum()) == 20
    steps = [r.step for r in ct.records]
    assert steps == list(range(len(steps)))


def test_same_seed_identical_step_log_and_other_seed_differs():
    def log(seed):
        env = rare_regions_world()
        ct = make(env, noninteractive=False, seed=seed)
        ct.run(max_steps=150)
        return ct.records

    a, b, c = log(3), log(3), log(4)
    assert a == b
    assert a != c


def test_policy_stands_alone_and_evaluates():
    env = rare_regions_world(episode_length=10)
    with pytest.raises(RuntimeError, match="not fitted"):
        GreedyPolicy(GaussianMixtureSet(3, 2))(np.zeros(2))
    ct = make(env, noninteractive=False)
    ct.run(max_steps=300)
    policy = pickle.loads(pickle.dumps(ct.policy))
    obs = np.array([8.0, 0.3])
    assert policy(obs) == 1 == ct.policy(obs)
    recs = evaluate_policy(policy, rare_regions_world(episode_length=10), n_episodes=3, seed=5)
    assert len(recs) == 30 and {r.episode for r in recs} == {0, 1, 2}
    assert all(r.phase == "evaluation" and r.autonomous for r in recs)
    assert np.mean([r.reward for r in recs]) > 0.95
    plain = evaluate_policy(lambda o: 0, rare_regions_world(), n_steps=7, seed=5)
    assert len(plain) == 7 and plain[0].confidence is None
    again = evaluate_policy(policy, rare_regions_world(episode_length=10), n_episodes=3, seed=5)
    assert again == recs


class _NoFlag(torch.nn.Module):
    """A model of one's own that does not say is_fitted (an unfitted GaussianMixtureSet's
    classification behind it)."""

    def __init__(self):
        super().__init__()
        self.inner = GaussianMixtureSet(3, 2)

    def classify(self, x):
        return self.inner.classify(x)


def test_an_unfitted_greedy_policy_has_no_action_on_every_path():
    """GreedyPolicy's one contract for a model not fitted yet (a session's stage 0, before its
    first fit): no action. Called directly it raised RuntimeError, but evaluate_policy, which
    reads the action from classify, reset the env, stepped nowhere and raised a ValueError
    saying the policy answered -1. Now it raises the same RuntimeError, before the reset;
    classify (one observation, or the model's for a batch) reports action -1."""
    resets = []

    class Counted(gym.Wrapper):
        def reset(self, **kwargs):
            resets.append(kwargs)
            return super().reset(**kwargs)

    env = Counted(rare_regions_world(episode_length=10))
    policy = GreedyPolicy(GaussianMixtureSet(3, 2))
    with pytest.raises(RuntimeError, match="not fitted") as direct:
        policy(np.zeros(2))
    with pytest.raises(RuntimeError, match="not fitted") as evaluated:
        evaluate_policy(policy, env, n_steps=5, seed=0)
    assert resets == []  # refused before the env moved
    assert str(evaluated.value) == f"evaluate_policy: {direct.value}"
    assert policy.classify(np.zeros(2)).action.tolist() == [-1]
    assert policy.model.classify(np.zeros((4, 2))).action.tolist() == [-1] * 4

    with pytest.raises(RuntimeError, match="not fitted"):
        evaluate_policy(GreedyPolicy(_NoFlag()), env, n_steps=5, seed=0)


def test_a_greedy_policy_with_a_call_of_its_own_evaluates_with_an_unfitted_model():
    """As documented (GreedyPolicy, evaluate_policy): where a subclass has a ``__call__`` of
    its own, that is called and decides, also while the model is not fitted (one that falls
    back on a default action, say), for a model that says is_fitted and one that does not;
    the confidence fields are filled from the unfitted model's classification."""

    class Fallback(GreedyPolicy):
        def __call__(self, observation):
            action = int(self.classify(observation).action[0])
            return 0 if action < 0 else action

    for model in (GaussianMixtureSet(3, 2), _NoFlag()):
        policy = Fallback(model)
        records = evaluate_policy(policy, rare_regions_world(episode_length=5), n_steps=5, seed=0)
        assert [r.executed_action for r in records] == [0] * 5
        assert all(r.confidence is not None and r.posterior is not None for r in records)


class _ActedOn(gym.Wrapper):
    """Notes, for every env.step, the observation the env was in when the action ran."""

    def __init__(self, env):
        super().__init__(env)
        self.acted_on: list[tuple[float, ...]] = []

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self.now = tuple(np.asarray(obs, dtype=np.float64).tolist())
        return obs, info

    def step(self, action):
        self.acted_on.append(self.now)
        out = self.env.step(action)
        self.now = tuple(np.asarray(out[0], dtype=np.float64).tolist())
        return out


def test_evaluating_on_the_teaching_env_mid_episode_starts_a_new_episode(tmp_path):
    """evaluate_policy on the env a session teaches on, with the session in the middle of an
    episode, moves the env under the loop: its next step must not decide, label and record on
    the observation it held from before, which the env no longer shows."""
    env = _ActedOn(rare_regions_world(episode_length=10))
    ct = ConfidentTeacher(
        env, oracle(env.unwrapped), config=TeachingConfig(), run_dir=tmp_path / "s",
        progress=False,
    )  # fmt: skip
    ct.run(max_steps=15)  # stops in the middle of episode 1
    evaluate_policy(ct.policy, env, n_steps=3, seed=7)
    with pytest.warns(UserWarning, match="left unfinished") as caught:
        ct.run(max_steps=20)
    assert caught[0].filename == __file__  # the caller's run() line, not the loop's
    recs = ct.records
    # every step's record holds the observation its action ran in
    teaching = env.acted_on[:15] + env.acted_on[18:]
    assert [r.observation for r in recs] == teaching
    assert [r.episode for r in recs[14:17]] == [1, 2, 2]  # episode 1 left unfinished
    assert not (recs[14].terminated or recs[14].truncated)
    ct.close()
    again = ConfidentTeacher.resume(tmp_path / "s", env, oracle(env.unwrapped), progress=False)
    assert again.records == recs and again.n_episodes == ct.n_episodes == 1
    again.close()
    # an evaluation on an env of its own leaves the session's episode whole
    other = make(rare_regions_world(episode_length=10))
    other.run(max_steps=15)
    evaluate_policy(other.policy, rare_regions_world(episode_length=10), n_steps=3, seed=7)
    other.run(max_steps=20)
    assert [r.episode for r in other.records[14:17]] == [1, 1, 1]


def _demos_to_reach(env_fn, seed, eval_x, eval_y, **cfg):
    """Demonstrations when the model first matches the teacher on the evaluation set."""
    reached: list[int] = []

    def on_refit(model, n):
        if not reached:
            acc = (model.classify(eval_x).action.numpy() == eval_y).mean()
            if acc >= 0.995:
                reached.append(n)

    env = env_fn()
    ct = ConfidentTeacher(
        env,
        oracle(env),
        model=GaussianMixtureSet(3, 2, max_components=4, seed=seed),
        config=TeachingConfig(**cfg),
        seed=seed,
        progress=False,
        on_refit=on_refit,
    )
    while not reached and ct.n_steps < 3000:
        ct.run(max_steps=ct.n_steps + 50)
    assert reached, "never reached the teacher's performance"
    return reached[0]


def test_confident_execution_needs_at_most_half_the_demonstrations():
    """Acceptance (1): the teacher's performance (accuracy 1 by construction, reached = >= 99.5%
    on 2000 held-out points) with <= half the demonstrations of non-interactive teaching."""
    env = rare_regions_world()
    eval_x, eval_y = env.sample(2000, np.random.default_rng(123))
    ratios = []
    for seed in (0, 1, 2):
        passive = _demos_to_reach(
            rare_regions_world, seed, eval_x, eval_y, target_accuracy=None, max_new=4
        )
        active = _demos_to_reach(
            rare_regions_world, seed, eval_x, eval_y, noninteractive=False, max_new=4
        )
        ratios.append(active / passive)
        assert active <= passive / 2, (seed, active, passive)
    print("confident / non-interactive demonstrations:", ratios)


def test_bad_config_is_a_clear_error():
    with pytest.raises(ValueError, match="max_new"):
        TeachingConfig(max_new=0)
    with pytest.raises(ValueError, match="target_accuracy"):
        TeachingConfig(target_accuracy=1.5)
    with pytest.raises(TypeError, match="unexpected keyword"):
        TeachingConfig(max_neww=2)
    env = ClusterWorld([[0.0]], [0], [1.0])
    import gymnasium as gym

    env.action_space = gym.spaces.Box(0, 1, (1,))
    with pytest.raises(ValueError, match="Discrete action space"):
        ConfidentTeacher(env, lambda o, i: 0)
    with pytest.raises(ValueError, match="n_features"):
        ConfidentTeacher(rare_regions_world(), lambda o, i: 0, model=GaussianMixtureSet(3, 5))
    torch.manual_seed(0)


@pytest.mark.parametrize("env", ["torchcbl/Corridor-v0", None])
def test_an_env_id_or_no_env_in_place_of_an_env_says_to_make_one(env, tmp_path):
    """ConfidentTeacher("CartPole-v1", ...) said "expected an env with a Discrete action space
    starting at 0, got None": the action space of an object that is no env at all."""
    session, world = tmp_path / "session", rare_regions_world()
    ConfidentTeacher(world, oracle(world), run_dir=session, progress=False).run(max_steps=3).close()
    for call in (
        lambda: ConfidentTeacher(env, oracle(world), run_dir=tmp_path / "new"),
        lambda: ConfidentTeacher.resume(session, env, oracle(world)),
        lambda: evaluate_policy(lambda o: 0, env, n_steps=1),
    ):
        with pytest.raises(TypeError) as err:
            call()
        message = str(err.value)
        assert message.startswith(f"expected a gymnasium.Env, got {type(env).__name__} {env!r}")
        if isinstance(env, str):
            assert f"gymnasium.make({env!r})" in message
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize("field", ["max_new", "accuracy_window", "burst"])
@pytest.mark.parametrize("value", [0, 2.5, None])
def test_a_learning_setting_that_must_be_an_int_says_so_not_that_none_would_do(field, value):
    """TeachingConfig(max_new=0) said "expected None or an int >= 1": a user who then gave
    None was refused again, as these three settings take no None."""
    with pytest.raises(ValueError) as err:
        TeachingConfig(**{field: value})
    assert str(err.value) == f"TeachingConfig.{field}: expected an int >= 1, got {value!r}"
    with pytest.raises(ValueError, match=r"max_steps: expected None or an int >= 0, got -1"):
        TeachingConfig(max_steps=-1)  # a stop field does take None (no such stop)


def test_a_negative_seed_is_refused_before_a_run_directory_is_written(tmp_path):
    # numpy and gymnasium refuse negative seeds at the first reset: a session that wrote its
    # run directory first could then neither run nor resume
    with pytest.raises(ValueError, match="seed: expected an int >= 0, got -1"):
        ConfidentTeacher(rare_regions_world(), lambda o, i: 0, seed=-1, run_dir=tmp_path / "r")
    assert not (tmp_path / "r").exists()


def test_a_model_converted_to_float32_is_refused_before_a_run_directory_is_written(tmp_path):
    # a GaussianMixtureSet fits only in float64: such a session failed at its first refit
    # after a demonstration had been logged (before 2026-11-27: at the second)
    env = rare_regions_world()
    model = GaussianMixtureSet(env.action_space.n, env.observation_space.shape[0]).float()
    with pytest.raises(TypeError, match=r"model: .*torch.float32.*model.to\(torch.float64\)"):
        ConfidentTeacher(env, oracle(env), model=model, run_dir=tmp_path / "r", progress=False)
    assert not (tmp_path / "r").exists()
    ct = ConfidentTeacher(env, oracle(env), model=model.double(), progress=False)
    ct.run(max_steps=5)
    assert ct.model.is_fitted


def test_numpy_scalars_in_the_config_are_stored_as_python_numbers(tmp_path):
    import json

    cfg = TeachingConfig(max_new=np.int64(5), target_accuracy=np.float32(0.5), burst=np.int32(2))
    assert (type(cfg.max_new), type(cfg.target_accuracy), type(cfg.burst)) == (int, float, int)
    ct = ConfidentTeacher(rare_regions_world(), lambda o, i: 0, config=cfg, run_dir=tmp_path)
    ct.close()
    stored = json.loads((tmp_path / "config.json").read_text())["teaching"]
    assert stored["max_new"] == 5 and stored["burst"] == 2
    with pytest.raises(ValueError, match="max_new"):
        TeachingConfig(max_new=np.int64(0))


def test_numpy_bools_in_the_config_are_taken_as_bools(tmp_path):
    """A sweep built with numpy (a grid array, a DataFrame row) gives np.bool_ flags: the config
    took numpy ints and floats as Python numbers but refused np.False_ for noninteractive, and
    run(time_limit_is_success=np.True_) alike."""
    import json

    flags = np.array([False, True])
    cfg = TeachingConfig(noninteractive=flags[0], time_limit_is_success=flags[1], max_steps=3)
    assert (cfg.noninteractive, cfg.time_limit_is_success) == (False, True)
    assert type(cfg.noninteractive) is bool and type(cfg.time_limit_is_success) is bool
    ct = ConfidentTeacher(rare_regions_world(), lambda o, i: 0, config=cfg, run_dir=tmp_path)
    ct.run(time_limit_is_success=flags[0])
    ct.close()
    stored = json.loads((tmp_path / "config.json").read_text())["teaching"]
    assert stored["noninteractive"] is False and ct.records[0].phase == "confident"
    with pytest.raises(ValueError, match="max_new"):
        TeachingConfig(max_new=np.True_)  # a bool is no count, numpy's or Python's


def test_refit_brings_a_snapshot_up_to_date_and_stop_reason_names_the_stop():
    ct = make(rare_regions_world(), noninteractive=False, max_new=5)
    ct.run(max_demonstrations=7)
    assert ct.stop_reason == "max_demonstrations"
    assert ct.n_demonstrations == 7
    fitted_on = []
    ct.on_refit = lambda model, n: fitted_on.append(n)
    assert ct.refit() is True  # 2 demonstrations arrived since the refit at 5
    assert fitted_on == [7]
    assert ct.refit() is False  # nothing new: no work
    x = np.stack([np.asarray(r.observation) for r in ct.records if r.teacher_action is not None])
    y = np.array([r.teacher_action for r in ct.records if r.teacher_action is not None])
    fresh = copy.deepcopy(ct.model).fit(x, y)
    probe = torch.linspace(-3, 3, 50, dtype=torch.float64)[:, None].repeat(1, x.shape[1])
    assert torch.equal(ct.model.classify(probe).action, fresh.classify(probe).action)
    ct.run(max_steps=ct.n_steps + 3)
    assert ct.stop_reason == "max_steps"


def test_evaluate_policy_passes_info_to_a_teacher_style_policy():
    env = rare_regions_world()
    seen = []

    def expert(obs, info):
        seen.append(dict(info))
        return oracle(env)(obs, info)

    recs = evaluate_policy(expert, env, n_steps=5, seed=0, uses_info=True)
    assert len(recs) == 5 and len(seen) == 5
    assert all(r.executed_action == oracle(env)(np.asarray(r.observation), {}) for r in recs)
    with pytest.raises(TypeError):
        evaluate_policy(expert, env, n_steps=1, seed=0)  # a 2-argument policy needs uses_info


def test_the_teacher_judges_an_autonomous_step_on_what_the_agent_saw():
    """An env that reuses its observation buffer (mutated in place by step) must not show the
    correcting teacher the next state: the correction is a label for the decision's state."""
    import gymnasium as gym

    from torchcbl.strategies.hg_dagger import HGDAgger

    class InPlace(gym.Env):
        observation_space = gym.spaces.Box(-10, 10, (2,), np.float64)
        action_space = gym.spaces.Discrete(2)

        def __init__(self):
            self.buf = np.zeros(2)

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            self.t = 0
            self.buf[:] = self.np_random.uniform(-1, 1, 2)
            return self.buf, {}

        def step(self, a):
            self.t += 1
            self.buf[:] = self.np_random.uniform(-1, 1, 2)
            return self.buf, 0.0, False, self.t >= 20, {}

    class Teacher:
        def __init__(self):
            self.seen = []

        def __call__(self, obs, info):
            return int(obs[0] > 0)

        def correct(self, obs, info, action):
            self.seen.append(tuple(obs.tolist()))
            return 1 - action  # always disagrees

    t = Teacher()
    ct = ConfidentTeacher(
        InPlace(),
        t,
        strategy=HGDAgger(warmup=5),
        config=TeachingConfig(max_steps=30),
        progress=False,
    )
    ct.run()
    assert ct.corrections and len(t.seen) == len(ct.corrections)
    assert [c.observation for c in ct.corrections] == t.seen


def test_a_failed_first_reset_keeps_its_seed_for_the_retry():
    """The same seed gives the same session even when the env's first reset fails and run()
    is called again."""
    import gymnasium as gym

    from torchcbl.errors import EnvError

    class FlakyReset(gym.Wrapper):
        def __init__(self, env):
            super().__init__(env)
            self.calls = 0

        def reset(self, **kw):
            self.calls += 1
            if self.calls == 1:
                raise ConnectionError("simulator not ready")
            return self.env.reset(**kw)

    def first_observations(flaky: bool):
        env = rare_regions_world()
        ct = ConfidentTeacher(
            FlakyReset(env) if flaky else env,
            oracle(env),
            config=TeachingConfig(max_steps=3),
            seed=7,
            progress=False,
        )
        if flaky:
            with pytest.raises(EnvError, match="simulator not ready"):
                ct.run()
        ct.run()
        return [r.observation for r in ct.records]

    assert first_observations(True) == first_observations(False)


@pytest.mark.parametrize(
    ("answer", "says"),
    [
        (("decision", "non-interactive"), r"decided with phase 'non-interactive'; expected"),
        (("decision", "evaluation"), r"decided with phase 'evaluation'; expected"),
        ((True, "confident"), r"decide\(\) returned \(True, 'confident'\); expected a .*Decision"),
        (None, r"decide\(\) returned None; expected a .*Decision"),
    ],
    ids=["phase-non-interactive", "phase-evaluation", "tuple", "none"],
)
def test_a_decide_that_is_no_decision_of_a_known_phase_is_refused_before_the_teacher_is_asked(
    tmp_path, answer, says
):
    """A strategy of one's own whose decide() names a phase the loop does not know, returns a
    plain tuple, or nothing (a subclass of the Strategy protocol that left decide() out), is
    refused with what a Decision is, before the teacher is asked or anything is recorded."""
    from torchcbl.strategies import Decision
    from torchcbl.strategies.bc import BehaviourCloning

    if isinstance(answer, tuple) and answer[0] == "decision":
        answer = Decision(True, answer[1])

    class Mine(BehaviourCloning):
        def decide(self, obs, c):
            return answer

    env = rare_regions_world()
    asked = []

    def teacher(obs, info):
        asked.append(1)
        return oracle(env)(obs, info)

    ct = ConfidentTeacher(env, teacher, strategy=Mine(), run_dir=tmp_path / "r", progress=False)
    with pytest.raises(RuntimeError, match=says):
        ct.run(max_steps=3)
    ct.close()
    # nothing recorded: the session, failed at its first step, was removed again
    assert asked == [] and not (tmp_path / "r" / "config.json").exists()


def test_a_decide_not_to_ask_in_the_noninteractive_phase_is_refused_as_the_strategys(tmp_path):
    """The "noninteractive" phase is for steps on which the teacher is asked by design (a
    StepRecord holds a label on every one). A strategy of one's own that decided not to ask
    in it, once a model existed, failed in the record's own check: a ValueError telling to
    pass a label "if you built this record yourself" and that "from the teaching loop this
    points at a bug or a corrupted log". It is refused as the strategy's, as the other
    checks of a decision are, before anything of the step is recorded; the steps before it
    are kept."""
    from torchcbl.strategies import Decision
    from torchcbl.strategies.bc import BehaviourCloning

    class Mine(BehaviourCloning):
        def bind(self, **kw):
            super().bind(**kw)
            self.decided = 0

        def decide(self, obs, c):
            self.decided += 1
            return Decision(self.decided <= 5, "noninteractive")

        def actor(self, decision, model_action, teacher_action):
            return "teacher" if decision.ask else "agent"

    env = rare_regions_world()
    run = tmp_path / "r"
    ct = ConfidentTeacher(
        env, oracle(env), strategy=Mine(), config=TeachingConfig(max_new=2), run_dir=run,
        progress=False,
    )  # fmt: skip
    with ct, pytest.raises(RuntimeError) as caught:
        ct.run(max_steps=10)
    text = str(caught.value)
    assert (
        text.startswith("strategy ") and "decided not to ask in the 'noninteractive' phase" in text
    )
    assert "decide with phase 'confident'" in text and "Nothing was recorded" in text, text
    assert ct.n_steps == 5 and len(load_records(run)) == 5


class _Observing(gym.Env):
    """An env observing ``space`` (sampled), with 2 actions, 5 steps an episode."""

    def __init__(self, space):
        self.observation_space = space
        self.action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.observation_space.seed(seed)
        self.t = 0
        return self.observation_space.sample(), {}

    def step(self, action):
        self.t += 1
        return self.observation_space.sample(), 0.0, False, self.t >= 5, {}


# the cast wrapper of the installed gymnasium: wrappers.DtypeObservation from 1.0 on, the
# experimental DtypeObservationV0 in 0.29 (which pyproject.toml admits)
_CAST = (
    "gymnasium.wrappers.DtypeObservation"
    if int(gym.__version__.split(".")[0]) >= 1
    else "gymnasium.experimental.wrappers.DtypeObservationV0"
)


@pytest.mark.parametrize(
    ("space", "wrap"),
    [
        (gym.spaces.Box(0, 4, (2,), np.int64), f"{_CAST}(env, np.float64)"),
        (
            gym.spaces.Box(0.0, 1.0, (1, 3), np.float32),
            "gymnasium.wrappers.FlattenObservation(env)",
        ),
        (
            gym.spaces.Dict(
                {"pos": gym.spaces.Box(0, 4, (2,), np.int64), "goal": gym.spaces.Discrete(3)}
            ),
            f"{_CAST}(gymnasium.wrappers.FlattenObservation(env), np.float64)",
        ),
    ],
    ids=["int-box", "row-box", "dict-with-ints"],
)
def test_an_observation_space_that_is_no_1d_float_box_is_refused_with_the_wrapper_that_fits(
    space, wrap
):
    """An integer grid position, a [1, D] row or a Dict with integer parts: the refusal names
    the gymnasium wrapper(s) that make the env one the loop takes, and that wrapping works.
    (It said 'Flatten the observation (FlattenObservation) and cast to float' for all, and an
    integer Box stays integer when flattened.)"""
    env = _Observing(space)
    with pytest.raises(ValueError, match=re.escape(f"env = {wrap}.")) as info:
        ConfidentTeacher(env, lambda obs, i: 0, progress=False)
    advice = str(info.value).split("env = ")[1].rstrip(".")
    wrapped = eval(advice, {"gymnasium": gym, "np": np, "env": env})
    ct = ConfidentTeacher(wrapped, lambda obs, i: int(obs[0] > 1), progress=False)
    ct.run(max_steps=12)
    assert ct.n_steps == 12 and ct.n_episodes == 2


def test_the_cast_advice_names_the_wrapper_of_an_older_gymnasium(monkeypatch):
    """gymnasium before 1.0 (pyproject allows 0.29) has no wrappers.DtypeObservation, only the
    experimental DtypeObservationV0: the refusal names the one the installed gymnasium has.
    (With gymnasium 0.29 itself there is nothing to remove.)"""
    monkeypatch.delattr(gym.wrappers, "DtypeObservation", raising=False)
    env = _Observing(gym.spaces.Box(0, 4, (2,), np.int64))
    want = "env = gymnasium.experimental.wrappers.DtypeObservationV0(env, np.float64)."
    with pytest.raises(ValueError, match=re.escape(want)):
        ConfidentTeacher(env, lambda obs, i: 0, progress=False)


def test_commit_every_is_checked(tmp_path):
    env = rare_regions_world()
    for bad in (0, "32", 2.0, True):
        with pytest.raises(ValueError, match="commit_every: expected an int >= 1"):
            ConfidentTeacher(env, oracle(env), run_dir=tmp_path / "r", commit_every=bad)
        assert not (tmp_path / "r" / "config.json").exists()


@pytest.mark.parametrize(
    ("answer", "says"),
    [
        (lambda obs, info: obs, r"returned ndarray .*gym < 0\.26 returns the observation alone"),
        (lambda obs, info: (obs, "ready"), r"returned info 'ready'; expected a dict"),
    ],
    ids=["observation-alone", "info-not-a-dict"],
)
def test_a_reset_answer_that_is_not_the_gymnasium_pair_is_named_as_such(answer, says):
    """An env written for gym < 0.26 returns the observation alone from reset; with a 2-D
    observation it unpacked into two floats and the loop and evaluate_policy said "expected an
    observation of shape (2,), got ()", and a non-dict info gave a bare ValueError from dict()."""
    import gymnasium as gym

    from torchcbl.errors import EnvError

    class OldReset(gym.Wrapper):
        def reset(self, **kw):
            return answer(*self.env.reset(**kw))

    env = OldReset(rare_regions_world())
    ct = ConfidentTeacher(env, oracle(env.env), config=TeachingConfig(max_steps=3), progress=False)
    with pytest.raises(EnvError, match=says):
        ct.run()
    assert ct.n_steps == 0
    with pytest.raises(EnvError, match=says):
        evaluate_policy(lambda obs: 0, env, n_steps=3)


def test_a_reset_answer_given_as_a_list_pair_is_taken():
    """The pair check of reset (c2b367f) took only a tuple, so an env whose reset returns
    ``[obs, info]`` (accepted before it, as step's five values still are in a list) was refused
    as a gym < 0.26 env. A list of two is the pair too, in the loop and in evaluate_policy."""
    import gymnasium as gym

    class ListReset(gym.Wrapper):
        def reset(self, **kw):
            return list(self.env.reset(**kw))

    env = ListReset(rare_regions_world())
    ct = ConfidentTeacher(env, oracle(env.env), config=TeachingConfig(max_steps=5), progress=False)
    ct.run()
    assert ct.n_steps == 5
    assert len(evaluate_policy(lambda obs: 0, env, n_steps=5)) == 5


@pytest.mark.filterwarnings("ignore:HumanTiming. the info given to the teacher has no 't'")
@pytest.mark.parametrize("answer", [1.7, np.float64(2.0), "2", True, None])
def test_human_timing_refuses_a_wrapped_answer_that_is_no_action_index(answer):
    """HumanTiming passed the wrapped teacher's answer through int(): 1.7 became a
    demonstration of action 1, "2" of action 2 and True of action 1, where the loop refuses
    each from a bare teacher; None gave int()'s own message."""
    from torchcbl import TeacherError
    from torchcbl.teachers import HumanTiming, HumanTimingConfig

    cfg = HumanTimingConfig(delay_probs=(1.0,), miss_prob=0.0, double_prob=0.0)
    env = rare_regions_world(episode_length=5)
    ct = ConfidentTeacher(
        env,
        HumanTiming(lambda obs, info: answer, cfg),
        config=TeachingConfig(max_steps=3),
        progress=False,
    )
    with pytest.raises(
        TeacherError, match="HumanTiming: the wrapped teacher .*expected an int action"
    ):
        ct.run()
    assert ct.n_steps == 0 and ct.n_demonstrations == 0


def test_human_timing_takes_numpy_and_0d_integer_answers():
    from torchcbl.teachers import HumanTiming, HumanTimingConfig

    cfg = HumanTimingConfig(delay_probs=(1.0,), miss_prob=0.0, double_prob=0.0)
    for answer in (np.int64(2), np.array(2), torch.tensor(2)):
        assert HumanTiming(lambda obs, info, a=answer: a, cfg)(np.zeros(2), {"t": 0}) == 2


@pytest.mark.filterwarnings("ignore:HumanTiming. the info given to the teacher has no .t.")
def test_human_timing_refuses_a_teacher_of_the_observation_alone_up_front():
    """HumanTiming wrapped any callable: a teacher of the observation alone (``lambda obs:``,
    or one under torch.no_grad()) was taken, and the session failed only at its first
    request, with Python's bare TypeError. It is refused where it is wrapped, saying what it
    takes and what to do; a two-argument teacher (through a generic wrapper too) is taken."""
    from torchcbl.teachers import HumanTiming

    def policy(obs):
        return 0

    for alone in (policy, torch.no_grad()(policy)):
        with pytest.raises(TypeError, match=r"HumanTiming: .*called as teacher\(observation, "):
            HumanTiming(alone)
        with pytest.raises(TypeError, match=r"policy.*takes \(obs\).*lambda obs, info: "):
            HumanTiming(alone)
    env = rare_regions_world(episode_length=5)
    best = oracle(env)
    for teacher in (best, torch.no_grad()(best), lambda obs, info, extra=0: best(obs, info)):
        ct = ConfidentTeacher(
            env, HumanTiming(teacher), config=TeachingConfig(max_steps=3), progress=False
        )
        ct.run()
        assert ct.n_steps == 3


def test_an_empty_run_dir_is_refused_not_taken_as_the_working_directory(tmp_path, monkeypatch):
    """Path("") is ".": run_dir="" (say os.environ.get("RUN_DIR", "") meant as "none") wrote a
    session's files among whatever the working directory held."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.txt").write_text("mine")
    env = rare_regions_world()
    with pytest.raises(ValueError, match=r"run_dir: expected a directory path or None, got ''"):
        ConfidentTeacher(env, oracle(env), run_dir="", progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_a_pytorch_module_of_the_observation_alone_is_refused_as_a_teacher():
    """``ConfidentTeacher(env, Net())`` with ``Net.forward(self, x)`` was taken: an nn.Module's
    ``__call__`` shows ``(*args, **kwargs)``, so the check passed it, and the session stopped at
    its first request with a TeacherError around "forward() takes 2 positional arguments but
    3 were given". The module's forward is read: it is refused when the teacher is made (and
    by correcting()), saying how to wrap a network; a module whose forward takes the info is
    taken."""
    from torchcbl.strategies import correcting

    class Net(torch.nn.Module):
        def forward(self, x):
            return x

    class InfoNet(torch.nn.Module):
        def forward(self, obs, info):
            return torch.tensor(0)

    env = rare_regions_world()
    for net in (Net(), torch.nn.Sequential(torch.nn.Linear(1, 2))):
        with pytest.raises(TypeError) as e:
            ConfidentTeacher(env, net, progress=False)
        msg = str(e.value)
        assert "teacher(observation, info)" in msg and ".forward takes (" in msg, msg
        assert "lambda obs, info: int(net(torch.as_tensor(obs" in msg, msg
        with pytest.raises(TypeError, match=r"correcting: .*\.forward takes \("):
            correcting(net)
    # a network under a generic wrapper (torch.no_grad()) is named by its class too, not as
    # "function.forward" (the wrapper's type)
    with pytest.raises(TypeError, match=r"\bNet\.forward takes \(x\)"):
        ConfidentTeacher(env, torch.no_grad()(Net()), progress=False)
    ct = ConfidentTeacher(env, InfoNet(), progress=False)
    ct.run(max_steps=2)
    assert [r.teacher_action for r in ct.records] == [0, 0]


def test_the_teacher_signature_error_names_what_is_wrong_with_the_signature():
    """``def three(obs, info, k)`` was told "give it an info parameter", though it has one: the
    extra required argument is the problem. ``lambda obs, *, info: 0`` was shown as taking
    "(obs)": its keyword-only info was left out of what it takes, and it is passed by
    position. And ``def t(obs, info, *, k)`` was taken and failed at the first request."""
    env = rare_regions_world()

    def three(obs, info, k):
        return 0

    def keyword_k(obs, info, *, k):
        return 0

    with pytest.raises(TypeError) as e:
        ConfidentTeacher(env, three, progress=False)
    msg = str(e.value)
    assert "three takes (obs, info, k)" in msg and "give it an info parameter" not in msg, msg
    assert "exactly (observation, info)" in msg and "give k a default" in msg, msg
    assert "functools.partial" in msg, msg

    with pytest.raises(TypeError) as e:
        ConfidentTeacher(env, lambda obs, *, info: 0, progress=False)
    msg = str(e.value)
    assert "<lambda> takes (obs, *, info)" in msg and "positionally" in msg, msg
    assert "give it an info parameter" not in msg, msg

    with pytest.raises(TypeError) as e:
        ConfidentTeacher(env, keyword_k, progress=False)
    msg = str(e.value)
    assert "keyword_k takes (obs, info, *, k)" in msg and "give k a default" in msg, msg


def test_a_vector_env_is_refused_saying_torchcbl_teaches_one_env(tmp_path):
    """``gymnasium.make_vec("CartPole-v1", num_envs=2)`` was refused as "got MultiDiscrete([2
    2]). Wrap the env so its actions are 0..n-1": no wrapping makes a vector env one env.
    Everywhere an env is checked, the message says to make one env instead."""
    vec = gym.make_vec("CartPole-v1", num_envs=2)
    session, world = tmp_path / "session", rare_regions_world()
    ConfidentTeacher(world, oracle(world), run_dir=session, progress=False).run(max_steps=3).close()
    try:
        for call in (
            lambda: ConfidentTeacher(vec, lambda o, i: 0, run_dir=tmp_path / "new"),
            lambda: ConfidentTeacher.resume(session, vec, oracle(world)),
            lambda: evaluate_policy(lambda o: 0, vec, n_steps=1),
        ):
            with pytest.raises(ValueError) as err:
                call()
            message = str(err.value)
            assert "vector env" in message and "num_envs=2" in message, message
            assert "one env at a time" in message, message
            assert "gymnasium.make('CartPole-v1')" in message, message
            assert "Wrap the env" not in message, message
    finally:
        vec.close()
    assert not (tmp_path / "new").exists()
    # a plain env that sets num_envs = 1 (some libraries' single envs do) is one env
    single = rare_regions_world()
    single.num_envs = 1
    evaluate_policy(lambda o: 0, single, n_steps=2)
    # another library's vector env of one env (no gymnasium.Env; e.g. a DummyVecEnv of one)

    class OneEnvVec:
        num_envs = 1
        action_space = single.action_space
        observation_space = single.observation_space

        def reset(self):
            return np.zeros((1, 2))

        def step(self, actions):
            raise AssertionError("never stepped")

    with pytest.raises(ValueError, match="vector env .*num_envs=1.*one env at a time"):
        evaluate_policy(lambda o: 0, OneEnvVec(), n_steps=1)
