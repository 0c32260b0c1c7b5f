"""Smoke test of the Section 5.2 experiment: a tiny run writes every acceptance figure."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import os
import signal
from pathlib import Path

import numpy as np
import pytest
from _driving_tiny import tiny_config
from _processes import exists, kill_left

from sumo_scenarios.experiment import (
    DrivingExperimentConfig,
    evaluate_saved_policy,
    format_summary,
    plot_results,
    run_experiment,
    session_eval_segment,
)


def _clip_script(session, capsys) -> dict:
    """scripts/driving_components_at_clip.py on ``session`` (caps 3) -> its JSON line."""
    path = Path(__file__).resolve().parents[1] / "scripts" / "driving_components_at_clip.py"
    spec = importlib.util.spec_from_file_location("driving_components_at_clip", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    capsys.readouterr()
    assert mod.main([str(session), "--caps", "3"]) == 0
    return json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def stages_of(results: dict) -> list[dict]:
    return list(results["per_seed"][0]["stages"].values())


def test_tiny_run_writes_every_acceptance_figure_and_the_plots(tmp_path, capsys):
    cfg = tiny_config()
    res = run_experiment(cfg, tmp_path, workers=1, progress=False)
    on_disk = json.loads((tmp_path / "results.json").read_text())
    assert on_disk["acceptance"] == res["acceptance"]
    s = on_disk["summary"]
    for key in (
        "straight.collision_pct.mean",
        "expert.collision_pct.mean",
        "noninteractive_demos.mean",
        "arm_a.collision_pct.mean",
        "arm_a.tv_to_expert.mean",
        "arm_a.demonstrations.mean",
        "arm_b.collision_pct.mean",
        "arm_b.demonstrations.mean",
        "arm_a_minus_b_collision_pct.mean",
        "components_total.mean",
        "autonomy_confident_phase.mean",
    ):
        node = s
        for part in key.split("."):
            node = node[part]
        assert isinstance(node, float | int), key
    assert len(s["expert"]["lanes"]) == 5 and sum(s["expert"]["lanes"]) == pytest.approx(1.0)
    assert s["n"] == 1
    # Figure 10's number is the paper's policy's (end of the non-interactive phase): recount it
    # by hand from that policy's stored trace
    tr = on_disk["per_seed"][0]["fig10"]
    assert s["fig10_stage"] == tr["label"] == "a_end_noninteractive"
    dist, contact = tr["distance"], tr["contact"]
    onsets = [t for t in range(len(contact)) if contact[t] and (t == 0 or not contact[t - 1])]

    def low(t):
        return any(d > cfg.max_std for d in dist[max(0, t - 4) : t + 1])

    assert s["fig10_collision_onsets"] == len(onsets)
    if onsets:
        share = sum(low(t) for t in onsets) / len(onsets)
        assert s["fig10_collisions_after_low_confidence"] == pytest.approx(share)
    else:
        assert s["fig10_collisions_after_low_confidence"] is None
    assert s["fig10_base_rate"] == pytest.approx(sum(map(low, range(len(dist)))) / len(dist))
    every = s["fig10_all_snapshots"]
    assert every["runs"] == sum("demonstrations" in e for e in stages_of(on_disk))
    assert every["onsets"] >= s["fig10_collision_onsets"]
    # one seed: no spread is made up, and "beats" needs an interval
    assert s["arm_a"]["collision_pct"]["sd"] is None
    assert on_disk["acceptance"]["arm_a_beats_arm_b"] is False
    stages = on_disk["stages"]
    labels = list(stages)
    assert labels[0] == "straight" and labels[-1] == "expert"
    assert labels[-5:-1] == ["a_plus10", "a_plus20", "b_60", "b_80"]
    assert all(stages[k]["name"] and "_" not in stages[k]["name"] for k in labels)
    for label, entry in stages.items():
        assert 0.0 <= entry["collision_pct"]["mean"] <= 100.0, label
        assert sum(entry["lanes"]) == pytest.approx(1.0)
    assert stages["straight"]["lanes"][2] == 1.0 and stages["expert"]["tv_to_expert"]["mean"] == 0
    n_ni = on_disk["per_seed"][0]["noninteractive_demos"]
    assert s["arm_a"]["demonstrations"]["mean"] == n_ni + 20
    assert s["arm_b"]["demonstrations"]["mean"] == 80
    ni = on_disk["per_seed"][0]["ni_stages"]
    assert ni == list(range(20, n_ni, 20))  # Figure 8's first section: every 20 demos here
    for entry in on_disk["per_seed"][0]["stages"].values():  # snapshots hold every demo
        if "demonstrations" in entry:
            assert entry["fitted_on"] == entry["demonstrations"]
    d = s["arm_a_minus_b_collision_pct"]
    assert d["mean"] == pytest.approx(
        s["arm_a"]["collision_pct"]["mean"] - s["arm_b"]["collision_pct"]["mean"]
    )
    for name in (
        "fig8_lanes_collisions.png",
        "fig6_accuracy.png",
        "fig7_middle_lane_demos.png",
        "fig9_accuracy.png",
        "fig10_confidence.png",
        "seed_0/episodes.json",
    ):
        assert (tmp_path / name).stat().st_size > 1000, name
    # every teaching session is kept, and evaluate works on it
    for arm in ("arm_a", "arm_b"):
        report = evaluate_saved_policy(tmp_path / "seed_0" / "sessions" / arm, n_steps=20)
        assert report["steps"] == 20
    for bad in (0, 2.5, "10"):  # named as given, not as the env's max_episode_steps
        with pytest.raises(ValueError, match=f"^n_steps must be an int >= 1, got {bad!r}"):
            evaluate_saved_policy(tmp_path / "seed_0" / "sessions" / "arm_a", n_steps=bad)
    assert on_disk["domain"] == "driving"
    # the clip analysis of docs/reproduction.md runs on a kept session: its counts are the session's
    clip = _clip_script(tmp_path / "seed_0" / "sessions" / "arm_a", capsys)
    assert clip["demonstrations"] == s["arm_a"]["demonstrations"]["mean"]
    assert sum(clip["per_action"]) == clip["demonstrations"]
    assert all(0.0 <= v <= 1.0 for v in clip["share_at_clip_per_lane"])
    assert max(clip["caps"]["3"]["components"]) <= 3
    assert clip["caps"]["3"]["floor_sized_on_clip"] <= clip["caps"]["3"]["floor_sized"]
    (tmp_path / "fig8_lanes_collisions.png").unlink()
    written = plot_results(on_disk, tmp_path)
    assert tmp_path / "fig8_lanes_collisions.png" in written
    # results.json alone redraws them into a directory of one's own, made for them
    apart = plot_results(on_disk, tmp_path / "redrawn" / "variant")
    assert [p.name for p in apart] == [p.name for p in written] and len(apart) == 5
    assert all(p.parent == tmp_path / "redrawn" / "variant" and p.is_file() for p in apart)
    text = format_summary(on_disk)
    lines = [ln for ln in text.splitlines() if ln.startswith("|")]
    assert lines[1] == "|---|---|---|---|" and all(ln.endswith("|") for ln in lines)
    assert "+-" not in text and "± 0.0" not in text  # one seed: no made-up spread
    # the rows name this run's target, window and arm (b) size, not the paper's 80 %, 150, 1000
    assert "| Fig 6 | non-interactive demos to 80% over 20 | 500 |" in text
    assert "| Fig 8 | arm (b) 80 demos, collisions % | 4.0 |" in text
    assert "| Fig 8 | arm (b) 80 demos, lane TV to the teacher |" in text
    assert "over 150" not in text and "arm (b) 1000" not in text
    with pytest.raises(ValueError, match="teacher"):
        DrivingExperimentConfig(teacher="robot")


@pytest.mark.parametrize(
    "bad",
    [
        {"target_accuracy": 80},
        {"train_episode_steps": 0},
        {"criterion": "BIC"},
        {"max_std": -2.0},
        {"accuracy_window": 0},
        {"arm_b_stages": (600, 600, 700)},
        {"var_floor": -0.01},
        {"var_floor": float("nan")},
        {"stage_every": 0},  # was a ZeroDivisionError
        {"seeds": (0, 0)},  # two workers into one seed_0
        {"seeds": (-1,)},
        {"eval_steps": float("nan")},
        {"burst": 1.5},
        {"arm_b_stages": (0, 10)},
        {"eval_segment": 1.5},
        {"target_accuracy": True},
        {"max_std": "2"},  # was Python's 'must be real number, not str'
        {"max_std": True},  # was taken as a threshold of 1
        {"max_std": None},
        {"gmm_tol": "1e-4"},
        {"gmm_tol": None},
        {"max_confident_steps": 0},
        # the window never fills: no seed could reach the target (ran, all "not reached")
        {"max_noninteractive": 100, "accuracy_window": 150},
    ],
)
def test_experiment_config_refuses_what_every_worker_would_fail_on(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        DrivingExperimentConfig(**bad)


@pytest.mark.parametrize(
    "bad, says",
    [
        ({"confident_demos": 150, "stage_every": 40}, "stage_every, got 150 and 40"),
        ({"arm_b_stages": (700, 600)}, r"strictly increasing, got \(700, 600\)"),
        ({"eval_segment": 3, "extra_eval_segments": (3,)}, r"eval_segment 3 and .* \(3,\)"),
    ],
)
def test_config_refusals_name_the_values_given(bad, says):
    with pytest.raises(ValueError, match=says):
        DrivingExperimentConfig(**bad)


def test_paired_interval_matches_the_t_distribution():
    from sumo_scenarios.experiment import paired_interval

    d = paired_interval([1.0, 2.0, 3.0, 4.0])
    # mean 2.5, sd 1.291, t(0.975, 3) = 3.182: half-width 3.182 * 1.291 / 2 = 2.054
    assert d["mean"] == 2.5 and d["ci95"] == pytest.approx([0.4457, 4.5543], abs=1e-3)
    one = paired_interval([-0.7])
    assert one["mean"] == -0.7 and one["sd"] is None and one["ci95"] is None


def test_a_saved_teaching_session_is_evaluated_on_the_held_out_road(tmp_path):
    from sumo_scenarios.env import DrivingEnv
    from sumo_scenarios.expert import ScriptedExpert
    from torchcbl import ConfidentTeacher, TeachingConfig

    env = DrivingEnv(scenario="train", max_episode_steps=200)
    try:
        ct = ConfidentTeacher(
            env,
            ScriptedExpert(seed=0),
            config=TeachingConfig(accuracy_window=50, target_accuracy=None, max_new=20),
            run_dir=tmp_path / "session",
            progress=False,
        )
        ct.run(max_demonstrations=120)
        ct.close()
    finally:
        env.close()
    report = evaluate_saved_policy(tmp_path / "session", n_steps=150, seed=0)
    assert report["steps"] == 150 and report["eval_segment"] == 0
    assert sum(report["lanes"]) == pytest.approx(1.0)
    # the expert's habits were learned: it keeps off the right lane and right shoulder
    assert report["lanes"][0] + report["lanes"][1] < 0.2
    assert 0.0 <= report["collision_pct"] < 10.0


def _taught(run_dir: Path, **make_kwargs) -> None:
    """A short session of the scripted expert on ``gymnasium.make``'s driving env."""
    import gymnasium as gym

    import sumo_scenarios
    from sumo_scenarios.expert import ScriptedExpert
    from torchcbl import ConfidentTeacher, TeachingConfig

    env = gym.make(sumo_scenarios.ENV_ID, max_episode_steps=100, **make_kwargs)
    try:
        ct = ConfidentTeacher(
            env,
            ScriptedExpert(seed=0),
            config=TeachingConfig(accuracy_window=20, target_accuracy=None, max_new=20),
            run_dir=run_dir,
            progress=False,
        )
        ct.run(max_demonstrations=60)
        ct.close()
    finally:
        env.close()


def _driven(session: Path, n_steps: int, **config) -> dict:
    """The oracle: the session's policy on the eval road, in an env made here by hand."""
    from sumo_scenarios.env import DrivingConfig, DrivingEnv
    from torchcbl import evaluate_policy, load_policy

    env = DrivingEnv(DrivingConfig(**{"scenario": "eval", "max_episode_steps": n_steps, **config}))
    try:
        recs = evaluate_policy(load_policy(session), env, n_steps=n_steps, seed=0)
    finally:
        env.close()
    return {
        "collision_pct": 100 * float(np.mean([r.info["contact"] for r in recs])),
        "lanes": [int(r.info["lane"]) for r in recs],
    }


def test_a_session_is_evaluated_with_the_step_length_and_start_lane_it_was_taught_with(tmp_path):
    """A session of an env made with other SUMO settings or another start lane was evaluated on
    the defaults (0.25 s steps, the middle lane) without a word: a policy taught at 0.1 s steps
    got a collision rate of another driving task. The start lane (kept) is driven; the SUMO
    settings (kept only as text) are asked for, or taken as given."""
    from sumo_scenarios.sim import SimConfig
    from torchcbl.cli import main

    n = 60
    _taught(tmp_path / "lane", start_lane=4)
    report = evaluate_saved_policy(tmp_path / "lane", n_steps=n)
    want = _driven(tmp_path / "lane", n, start_lane=4)
    assert want["lanes"] != _driven(tmp_path / "lane", n)["lanes"]  # the start lane matters
    assert report["lanes"] == [want["lanes"].count(k) / n for k in range(5)]
    assert report["collision_pct"] == want["collision_pct"]
    assert report["start_lane"] == 4 and report["sim"]["step_length_s"] == 0.25

    fast = SimConfig(step_length_s=0.1)
    _taught(tmp_path / "fast", sim=fast)
    report = evaluate_saved_policy(tmp_path / "fast", n_steps=n)  # the session keeps its sim
    want = _driven(tmp_path / "fast", n, sim=fast)
    assert report["lanes"] == [want["lanes"].count(k) / n for k in range(5)]
    assert report["collision_pct"] == want["collision_pct"]
    assert report["sim"]["step_length_s"] == 0.1 and report["start_lane"] == 2
    assert evaluate_saved_policy(tmp_path / "fast", n_steps=n, sim=fast) == report
    _forget_objects(tmp_path / "fast")  # as a session written before kept them: text only
    with pytest.raises(ValueError, match=r"SUMO settings as an object.*step_length_s=0\.1"):
        evaluate_saved_policy(tmp_path / "fast", n_steps=n)
    assert main(["evaluate", str(tmp_path / "fast"), "--steps", "10"]) == 2  # one line
    assert evaluate_saved_policy(tmp_path / "fast", n_steps=n, sim=fast) == report
    with pytest.raises(ValueError, match="sim must be a SimConfig"):
        evaluate_saved_policy(tmp_path / "fast", n_steps=n, sim={"step_length_s": 0.1})


def test_a_session_of_an_env_given_its_settings_as_dicts_is_evaluated_and_replayed(tmp_path):
    """An env made again from its spec as JSON (gymnasium's ``EnvSpec.from_json``, e.g.
    Minari's ``recover_environment``) is given its ``SimConfig``, ``TrafficScenario`` and
    ``DrivingConfig`` as dicts of their fields, and a session keeps those dicts: evaluate and
    replay drive it on the settings they hold, as they do a session given the objects."""
    from sumo_scenarios.replay import session_episodes
    from sumo_scenarios.sim import SimConfig

    n = 60
    fast = SimConfig(step_length_s=0.1)
    sim = dataclasses.asdict(fast)
    _taught(tmp_path / "sim", sim=sim, start_lane=4)
    report = evaluate_saved_policy(tmp_path / "sim", n_steps=n)
    want = _driven(tmp_path / "sim", n, sim=fast, start_lane=4)
    assert report["lanes"] == [want["lanes"].count(k) / n for k in range(5)]
    assert report["collision_pct"] == want["collision_pct"]
    assert report["sim"] == sim and report["start_lane"] == 4
    assert session_episodes(tmp_path / "sim", check=True)[0].sim == fast

    config = {"scenario": "train", "max_episode_steps": 100, "start_lane": 4, "sim": sim}
    _taught(tmp_path / "config", config=config)
    assert evaluate_saved_policy(tmp_path / "config", n_steps=n) == report
    assert session_episodes(tmp_path / "config", check=True)[0].start_lane == 4


def _forget_objects(session: Path) -> None:
    """Make ``session`` as a session written before the make arguments' objects were kept
    rebuildably: its config keeps them only as text."""
    config = json.loads((session / "config.json").read_text())
    del config["env"]["kwargs_objects"]
    (session / "config.json").write_text(json.dumps(config))


def _short(run_dir: Path, **make_kwargs) -> None:
    """A session of a dozen steps (two refits) on ``gymnasium.make``'s driving env."""
    import gymnasium as gym

    import sumo_scenarios
    from sumo_scenarios.teacher import make_teacher
    from torchcbl import ConfidentTeacher, TeachingConfig

    env = gym.make(sumo_scenarios.ENV_ID, max_episode_steps=10, **make_kwargs)
    with ConfidentTeacher(
        env, make_teacher(0), config=TeachingConfig(max_new=5), run_dir=run_dir, progress=False
    ) as ct:
        ct.run(max_steps=12)
    env.close()


def test_a_session_is_evaluated_on_the_held_out_twin_of_the_traffic_it_was_taught_on(
    tmp_path, capsys
):
    """A session taught on other traffic (a TrafficScenario of the user's, or the shipped
    "light" by name) was evaluated on the shipped held-out "eval" traffic without a word, and
    the JSON did not say which; then on its very traffic, segment 0: the road its first
    episode drove. It is now driven on its traffic's held-out twin (the same traffic, the next
    base seed), named in the JSON (the shipped "train" traffic's twin is "eval", as before); a
    session that kept its traffic only as text (written before) is refused in one line unless
    ``scenario=`` says which to drive."""
    import dataclasses

    from sumo_scenarios.scenarios import EVAL, LIGHT, TrafficScenario, held_out_twin
    from torchcbl.cli import main

    def named(scenario):  # as the report's JSON holds it
        return json.loads(json.dumps(dataclasses.asdict(scenario)))

    n = 20
    mine = TrafficScenario(name="mine", seed=7, mean_spacing_m=(80, 60, 200))
    twin = dataclasses.replace(mine, name="mine-held-out", seed=8)
    _short(tmp_path / "mine", scenario=mine)
    report = evaluate_saved_policy(tmp_path / "mine", n_steps=n)
    assert report["scenario"] == named(twin) and report["held_out"] is True
    want = _driven(tmp_path / "mine", n, scenario=twin)
    assert report["lanes"] == [want["lanes"].count(k) / n for k in range(5)]
    assert report["collision_pct"] == want["collision_pct"]
    assert main(["evaluate", str(tmp_path / "mine"), "--steps", str(n)]) == 0
    assert json.loads(capsys.readouterr().out) == report
    _short(tmp_path / "light", scenario="light")
    light = dataclasses.replace(LIGHT, name="light-held-out", seed=4)
    assert evaluate_saved_policy(tmp_path / "light", n_steps=n)["scenario"] == named(light)
    _short(tmp_path / "train")  # the default traffic: its held-out twin, as before
    assert evaluate_saved_policy(tmp_path / "train", n_steps=n)["scenario"] == named(EVAL)
    # told which traffic to drive, it drives that
    other = evaluate_saved_policy(tmp_path / "mine", n_steps=n, scenario="eval")
    assert other["scenario"] == named(EVAL)
    with pytest.raises(
        ValueError, match="scenario must be a shipped scenario's name, the path of a JSON"
    ):
        evaluate_saved_policy(tmp_path / "mine", n_steps=n, scenario=7)
    _forget_objects(tmp_path / "mine")
    with pytest.raises(ValueError, match=r"traffic as an object.*\(TrafficScenario\(name="):
        evaluate_saved_policy(tmp_path / "mine", n_steps=n)
    assert main(["evaluate", str(tmp_path / "mine"), "--steps", str(n)]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert (
        evaluate_saved_policy(tmp_path / "mine", n_steps=n, scenario=held_out_twin(mine)) == report
    )


def test_a_session_taught_on_a_traffic_scenario_refuses_another_on_resume(tmp_path):
    """A TrafficScenario given to gymnasium.make was kept only as its repr, which resume did
    not compare: a session resumed on other traffic without a word. The session keeps it
    whole (env.kwargs_objects), and a resume on another is refused in one line naming the
    argument, the field and both values, touching no file; the same traffic resumes, under
    another name too (a scenario's name changes nothing the env drives)."""
    import dataclasses

    import gymnasium as gym

    import sumo_scenarios
    from sumo_scenarios.scenarios import TrafficScenario
    from sumo_scenarios.teacher import make_teacher
    from torchcbl import ConfidentTeacher, IncompatibleRunDirError

    mine = TrafficScenario(name="mine", seed=7, mean_spacing_m=(80, 60, 200))
    run = tmp_path / "mine"
    _short(run, scenario=mine)
    before = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    env = gym.make(sumo_scenarios.ENV_ID, max_episode_steps=10, scenario=mine.with_seed(8))
    with pytest.raises(IncompatibleRunDirError) as err:
        ConfidentTeacher.resume(run, env, make_teacher(0), progress=False)
    env.close()
    msg = str(err.value)
    assert "scenario" in msg and "seed" in msg and "(7, 8)" in msg and "\n" not in msg, msg
    assert {p: p.read_bytes() for p in run.rglob("*") if p.is_file()} == before
    for same in (mine, dataclasses.replace(mine, name="renamed")):
        env = gym.make(sumo_scenarios.ENV_ID, max_episode_steps=10, scenario=same)
        ConfidentTeacher.resume(run, env, make_teacher(0), progress=False).close()
        env.close()


def test_a_driving_config_resumes_with_its_scenario_by_name_or_as_the_object(tmp_path):
    """DrivingConfig keeps ``scenario`` as given, a name or a TrafficScenario, and resume
    compared the kept forms as they were: a session of DrivingConfig(scenario="train") was
    refused the same env made with DrivingConfig(scenario=TRAIN), and the other way round
    ("config.scenario: ('train', '{...}')"). A name stands for the shipped scenario of that
    name: either spelling of the same traffic resumes the other, and other traffic behind
    the other spelling is refused in one line naming the fields that differ, touching no
    file."""
    import dataclasses

    import gymnasium as gym

    import sumo_scenarios
    from sumo_scenarios.env import DrivingConfig
    from sumo_scenarios.scenarios import SCENARIOS, TRAIN
    from sumo_scenarios.teacher import make_teacher
    from torchcbl import ConfidentTeacher, IncompatibleRunDirError
    from torchcbl.session import load_records

    def make(scenario):
        config = DrivingConfig(scenario=scenario, max_episode_steps=10)
        return gym.make(sumo_scenarios.ENV_ID, config=config)

    same = ("train", TRAIN, dataclasses.replace(TRAIN, name="renamed"))
    taught_on = {"train": dataclasses.replace(TRAIN, seed=7), TRAIN: "light"}
    for k, (spelled, other) in enumerate(taught_on.items()):
        run = tmp_path / f"run{k}"
        env = make(spelled)
        with ConfidentTeacher(env, make_teacher(0), run_dir=run, progress=False) as ct:
            ct.run(max_steps=2)  # closed: a session left open held each resume's close 2 s
        env.close()
        before = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
        env = make(other)
        with pytest.raises(IncompatibleRunDirError) as err:
            ConfidentTeacher.resume(run, env, make_teacher(0), progress=False)
        env.close()
        msg = str(err.value)
        seeds = (TRAIN.seed, 7) if k == 0 else (TRAIN.seed, SCENARIOS["light"].seed)
        assert "\n" not in msg and f"'config.scenario.seed': {seeds}" in msg, msg
        assert {p: p.read_bytes() for p in run.rglob("*") if p.is_file()} == before
        for spelling in same:
            env = make(spelling)
            ConfidentTeacher.resume(run, env, make_teacher(0), progress=False).close()
            env.close()
        assert len(load_records(run)) == 2


def test_a_session_refuses_other_traffic_given_as_a_name_against_an_object(tmp_path):
    """A session of gymnasium.make(ENV_ID, scenario="train") resumed without a word on an env
    made with scenario=LIGHT or scenario=dataclasses.replace(TRAIN, seed=99), and the other way
    round: resume compared a name with a name and an object with an object, never one with the
    other (nor an env made directly with anything). The env now describes the traffic it runs
    (describe_inputs(): the TrafficScenario's fields but its name), so other traffic is refused
    in one line naming the field and both values, touching no file, and the same traffic
    resumes whichever way it is given; a session stored before it had a description resumes
    as it did."""
    import dataclasses

    import gymnasium as gym

    import sumo_scenarios
    from sumo_scenarios.env import DrivingConfig, DrivingEnv
    from sumo_scenarios.scenarios import LIGHT, TRAIN
    from sumo_scenarios.teacher import make_teacher
    from torchcbl import ConfidentTeacher, IncompatibleRunDirError
    from torchcbl.session import load_config

    seed99 = dataclasses.replace(TRAIN, seed=99)

    def make(**kwargs):
        return gym.make(sumo_scenarios.ENV_ID, max_episode_steps=10, **kwargs)

    def files(run):
        return {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}

    def refused(run, env) -> str:
        before = files(run)
        with pytest.raises(IncompatibleRunDirError) as err:
            ConfidentTeacher.resume(run, env, make_teacher(0), progress=False)
        env.close()
        assert files(run) == before
        assert "\n" not in str(err.value), err.value
        return str(err.value)

    def resumes(run, env) -> None:
        ConfidentTeacher.resume(run, env, make_teacher(0), progress=False).close()
        env.close()

    def teach(run, env) -> None:
        with ConfidentTeacher(env, make_teacher(0), run_dir=run, progress=False) as ct:
            ct.run(max_steps=2)
        env.close()

    by_name, by_object = tmp_path / "by_name", tmp_path / "by_object"
    teach(by_name, make(scenario="train"))
    teach(by_object, make(scenario=seed99))
    msg = refused(by_name, make(scenario=seed99))
    assert "'traffic.seed': (1, 99)" in msg, msg
    msg = refused(by_name, make(scenario=LIGHT))
    assert "'traffic.seed': (1, 3)" in msg and "traffic.mean_spacing_m" in msg, msg
    assert "traffic.name" not in msg, msg
    assert "'traffic.seed': (99, 1)" in refused(by_object, make(scenario="train"))
    for same in ("train", TRAIN, dataclasses.replace(TRAIN, name="renamed")):
        resumes(by_name, make(scenario=same))
    resumes(by_object, make(scenario=dataclasses.replace(seed99, name="mine")))
    # inside a DrivingConfig alike: a name against an object of other traffic is refused
    in_config = tmp_path / "in_config"
    teach(in_config, make(config=DrivingConfig(scenario="train")))
    assert "'traffic.seed': (1, 99)" in refused(in_config, make(config=DrivingConfig(seed99)))
    resumes(in_config, make(config=DrivingConfig(scenario=TRAIN)))
    # an env made directly shows no make() argument: its traffic was not compared at all
    direct = tmp_path / "direct"
    teach(direct, DrivingEnv(scenario="light", max_episode_steps=10))
    assert "'traffic.seed': (3, 1)" in refused(direct, DrivingEnv(max_episode_steps=10))
    resumes(direct, DrivingEnv(scenario=LIGHT, max_episode_steps=10))
    # a session stored before the env described its traffic resumes as it did
    config = load_config(by_name)
    assert config["env"]["inputs"]["traffic.seed"] == 1
    del config["env"]["inputs"]
    (by_name / "config.json").write_text(json.dumps(config))
    resumes(by_name, make(scenario=seed99))


def test_a_refusal_for_other_traffic_says_how_to_make_the_sessions_env(tmp_path):
    """A resume refused for what the env describes (other traffic) said only "give it the
    inputs as they were", not how the session's env was made: it now names the make() call
    (or, for an env made directly, the env's class), as a refusal for other arguments does."""
    import dataclasses

    import gymnasium as gym

    import sumo_scenarios
    from sumo_scenarios.env import DrivingEnv
    from sumo_scenarios.scenarios import LIGHT, TRAIN
    from sumo_scenarios.teacher import make_teacher
    from torchcbl import ConfidentTeacher, IncompatibleRunDirError

    def refusal(taught, given) -> str:
        run = tmp_path / str(len(list(tmp_path.iterdir())))
        with ConfidentTeacher(taught, make_teacher(0), run_dir=run, progress=False) as ct:
            ct.run(max_steps=2)
        taught.close()
        with pytest.raises(IncompatibleRunDirError) as err:
            ConfidentTeacher.resume(run, given, make_teacher(0), progress=False)
        given.close()
        return str(err.value)

    def make(scenario):
        return gym.make(sumo_scenarios.ENV_ID, max_episode_steps=10, scenario=scenario)

    msg = refusal(make("train"), make(LIGHT))
    made = "gymnasium.make('torchcbl/Driving-v0', max_episode_steps=10, scenario='train')"
    assert "'traffic.seed': (1, 3)" in msg and made in msg, msg
    msg = refusal(make(dataclasses.replace(TRAIN, seed=99)), make("train"))
    assert "'traffic.seed': (99, 1)" in msg and "scenario=TrafficScenario(" in msg, msg
    assert "seed=99" in msg and "from sumo_scenarios.scenarios import TrafficScenario" in msg, msg
    msg = refusal(DrivingEnv(scenario=LIGHT), DrivingEnv())
    assert "a DrivingEnv (sumo_scenarios.env.DrivingEnv) made as it was" in msg, msg


def test_a_session_refuses_other_sumo_settings_or_start_lane_given_on_one_side_only(tmp_path):
    """A session of gymnasium.make(ENV_ID, sim=SimConfig(ego_start_m=500)) resumed without a
    word on gymnasium.make(ENV_ID), and one of config=DrivingConfig(start_lane=3) too: an
    object argument the given env lacks was not compared. The env describes the SUMO settings
    and start lane it runs as it does its traffic: refused in one line naming the field and
    both values; the same settings resume."""
    import gymnasium as gym

    import sumo_scenarios
    from sumo_scenarios.env import DrivingConfig
    from sumo_scenarios.sim import SimConfig
    from sumo_scenarios.teacher import make_teacher
    from torchcbl import ConfidentTeacher, IncompatibleRunDirError

    def make(**kwargs):
        return gym.make(sumo_scenarios.ENV_ID, max_episode_steps=10, **kwargs)

    further = {"sim": SimConfig(ego_start_m=500)}
    lane3 = {"config": DrivingConfig(start_lane=3, max_episode_steps=10)}
    for k, (kwargs, named) in enumerate(
        [(further, "'sim.ego_start_m': (500.0, 300.0)"), (lane3, "'start_lane': (3, 2)")]
    ):
        run = tmp_path / str(k)
        env = make(**kwargs)
        with ConfidentTeacher(env, make_teacher(0), run_dir=run, progress=False) as ct:
            ct.run(max_steps=2)
        env.close()
        env = make()
        with pytest.raises(IncompatibleRunDirError) as err:
            ConfidentTeacher.resume(run, env, make_teacher(0), progress=False)
        env.close()
        assert named in str(err.value) and "\n" not in str(err.value), err.value
        env = make(**kwargs)
        ConfidentTeacher.resume(run, env, make_teacher(0), progress=False).close()
        env.close()


def test_each_writer_of_a_driving_session_records_the_sumo_release_it_ran(tmp_path):
    """A driving session recorded nothing of the SUMO under it: one begun under one release
    resumed under another (another car-following, other traffic) without a word. Each writer
    records the release libsumo runs now (writers.jsonl's env_versions)."""
    from importlib.metadata import version

    from sumo_scenarios.env import DrivingEnv
    from sumo_scenarios.teacher import make_teacher
    from torchcbl import ConfidentTeacher

    run = tmp_path / "run"
    env = DrivingEnv(max_episode_steps=10)
    try:
        assert env.describe_versions() == {"sumo": version("libsumo")}
        with ConfidentTeacher(env, make_teacher(0), run_dir=run, progress=False) as ct:
            ct.run(max_steps=2)
    finally:
        env.close()
    (writer,) = [json.loads(line) for line in (run / "writers.jsonl").read_text().splitlines()]
    assert writer["env_versions"] == {"sumo": version("libsumo")}


def test_the_driving_env_describes_the_sumo_files_it_loads_less_their_comments(
    tmp_path, monkeypatch
):
    """describe_inputs() names the road network and vehicle types SUMO loads by their
    digest, so a session taught before either changed is refused naming the file; a comment
    (netconvert's header names its version) changes nothing SUMO reads, nor the digest."""
    import sumo_scenarios.env
    from sumo_scenarios.env import DrivingEnv
    from sumo_scenarios.scenarios import data_path
    from sumo_scenarios.teacher import make_teacher
    from torchcbl import ConfidentTeacher, IncompatibleRunDirError
    from torchcbl.session import load_config

    keys = ("road.net.xml_sha256", "driving.add.xml_sha256")
    shipped = DrivingEnv().describe_inputs()
    assert all(len(shipped[k]) == 64 for k in keys)
    copies = {name: tmp_path / name for name in ("road.net.xml", "driving.add.xml")}
    monkeypatch.setattr(sumo_scenarios.env, "data_path", lambda name: copies[name])
    for name, path in copies.items():
        text = data_path(name).read_text()
        path.write_text(text.replace("<!--", "<!-- rebuilt by netconvert 9.9, ", 1))
    assert DrivingEnv().describe_inputs() == shipped
    for path in copies.values():  # a checkout that converts line ends (core.autocrlf)
        path.write_bytes(path.read_bytes().replace(b"\n", b"\r\n"))
    assert DrivingEnv().describe_inputs() == shipped
    road = copies["road.net.xml"]
    road.write_text(road.read_text().replace('speed="33.00"', 'speed="30.00"'))
    described = DrivingEnv().describe_inputs()
    assert [k for k in shipped if described[k] != shipped[k]] == ["road.net.xml_sha256"]
    monkeypatch.undo()
    run = tmp_path / "run"
    with ConfidentTeacher(
        DrivingEnv(max_episode_steps=10), make_teacher(0), run_dir=run, progress=False
    ) as ct:
        ct.run(max_steps=2)
    config = load_config(run)
    config["env"]["inputs"]["road.net.xml_sha256"] = described["road.net.xml_sha256"]
    (run / "config.json").write_text(json.dumps(config))  # as taught on that network
    with pytest.raises(IncompatibleRunDirError, match=r"'road.net.xml_sha256': \('"):
        ConfidentTeacher.resume(run, DrivingEnv(max_episode_steps=10), make_teacher(0))


def test_a_seed_that_never_reaches_the_target_is_reported_as_such(tmp_path):
    """A seed whose window never reaches the target within max_noninteractive is not counted
    as reaching it at the cap: it is left out of "demonstrations to 80 %" and counted apart,
    and, having had no confident phase, out of arm (a)'s figures and the paired difference."""
    cfg = tiny_config(target_accuracy=1.0, max_noninteractive=40, arm_b_stages=(60,))
    res = run_experiment(cfg, tmp_path, workers=1, progress=False)
    s = res["summary"]
    assert res["per_seed"][0]["noninteractive_target_reached"] is False
    assert s["noninteractive_not_reached"] == 1 and s["noninteractive_demos"]["n"] == 0
    assert res["acceptance"]["noninteractive_demos_250_800"] is False
    assert "1 seeds never reached it" in format_summary(res)
    assert res["per_seed"][0]["arm_a_autonomy_in_confident_phase"] is None
    assert s["arm_a"]["collision_pct"]["n"] == 0 and s["autonomy_confident_phase"]["n"] == 0
    assert s["arm_a_minus_b_collision_pct"]["n"] == 0
    assert not res["acceptance"]["arm_a_le_2pct"] and not res["acceptance"]["arm_a_beats_arm_b"]
    # nor in Figure 8's "arm (a) +k" bars, which were its non-interactive demonstrations
    assert res["per_seed"][0]["stages"]["a_plus10"]  # evaluated, and kept per seed
    assert not [k for k in res["stages"] if k.startswith("a_plus")]
    assert {"a_end_noninteractive", "b_60", "expert"} <= set(res["stages"])


def test_two_seeds_give_a_paired_interval_and_a_writable_summary(tmp_path):
    """With two seeds the paired difference has its t interval (2 seeds: t = 12.71), the
    acceptance says "beats" only where the interval lies below 0, and results.json is written
    (numpy scalars would not be)."""
    res = run_experiment(tiny_config(seeds=(0, 1)), tmp_path, workers=2, progress=False)
    on_disk = json.loads((tmp_path / "results.json").read_text())
    d = on_disk["summary"]["arm_a_minus_b_collision_pct"]
    diffs = [
        100 * (r["stages"]["a_plus20"]["collision_rate"] - r["stages"]["b_80"]["collision_rate"])
        for r in on_disk["per_seed"]
    ]
    half = 12.706 * abs(diffs[0] - diffs[1]) / 2**0.5 / 2**0.5
    assert d["n"] == 2 and d["ci95"] == pytest.approx(
        [np.mean(diffs) - half, np.mean(diffs) + half], abs=1e-3
    )
    assert on_disk["acceptance"]["arm_a_beats_arm_b"] == (d["ci95"][1] < 0)
    assert on_disk["acceptance"] == res["acceptance"]


def test_a_run_dir_left_by_a_stopped_run_is_refused_before_any_seed_runs(tmp_path):
    """A run stopped before results.json leaves its seeds' sessions: a new run into that
    directory is refused at once, naming them, instead of failing in a worker on the session
    it would overwrite (after the seeds before it ran) with a pointer to ConfidentTeacher.resume."""
    run_experiment(tiny_config(seeds=(0,)), tmp_path, workers=1, progress=False)
    (tmp_path / "results.json").unlink()  # as if stopped before it was written
    with pytest.raises(FileExistsError, match=r"seed_0\), left by an earlier run"):
        run_experiment(tiny_config(seeds=(1, 0)), tmp_path, workers=1, progress=False)
    assert not (tmp_path / "seed_1").exists()


@pytest.fixture(scope="module")
def two_seeds(tmp_path_factory):
    """A tiny run of seeds (1, 0), given out of order: its results and directory."""
    run_dir = tmp_path_factory.mktemp("two_seeds")
    return run_experiment(tiny_config(seeds=(1, 0)), run_dir, workers=1, progress=False), run_dir


def _untimed(value):
    """A results.json without its timing keys (which a resumed run cannot share)."""
    timing = ("seconds", "cpu_seconds", "arm_a_seconds")
    if isinstance(value, dict):
        return {k: _untimed(v) for k, v in value.items() if k not in timing}
    if isinstance(value, list):
        return [_untimed(v) for v in value]
    return value


def test_a_stopped_run_resumes_to_the_results_and_figures_of_a_run_never_stopped(
    two_seeds, tmp_path
):
    """resume=True takes a finished seed from seed_<k>/seed_result.json, clears and runs
    again the seed that was stopped part-way, and writes the results.json and figures of the
    run never stopped; another config is refused, naming what differs."""
    import shutil

    from torchcbl.evaluation import ResumeError

    cfg = tiny_config(seeds=(1, 0))
    whole, stopped = two_seeds[1], tmp_path / "stopped"
    pngs = sorted(p.name for p in whole.glob("*.png"))
    assert len(pngs) == 5
    # as if killed while seed 0 ran: seed 1 finished, seed 0 left part of its directory
    shutil.copytree(whole, stopped)
    for name in ("results.json", *pngs):
        (stopped / name).unlink()
    (stopped / "seed_0" / "seed_result.json").unlink()
    (stopped / "seed_0" / "episodes.json").write_text("{")  # half-written
    kept = stopped / "seed_1" / "seed_result.json"
    marked = json.loads(kept.read_text())
    marked["result"]["arm_a_seconds"] = -1.0  # taken from the file, not run again
    kept.write_text(json.dumps(marked))
    other = tiny_config(seeds=(1, 0), eval_steps=90)
    with pytest.raises(ResumeError, match=r"seed 1's .* eval_steps \(100 there, 90 here\); resume"):
        run_experiment(other, stopped, workers=1, progress=False, resume=True)
    run_experiment(cfg, stopped, workers=1, progress=False, resume=True)
    resumed = json.loads((stopped / "results.json").read_text())
    assert resumed["per_seed"][0]["arm_a_seconds"] == -1.0
    assert _untimed(resumed) == _untimed(json.loads((whole / "results.json").read_text()))
    for name in pngs:
        assert (stopped / name).read_bytes() == (whole / name).read_bytes(), name
    assert (stopped / "seed_0" / "episodes.json").read_bytes() == (
        whole / "seed_0" / "episodes.json"
    ).read_bytes()


def test_a_figure_that_fails_raises_after_the_results_are_written(two_seeds, tmp_path):
    """The figures were drawn before results.json was written: one that failed (matplotlib
    missing, a full disk) lost every seed's result to the run. results.json comes first; the
    error (a FigureError, the figure's own as its cause) says so and how to draw them."""
    import shutil

    from sumo_scenarios.experiment import plot_results
    from torchcbl.evaluation import FigureError

    whole, run = two_seeds[1], tmp_path / "run"
    pngs = sorted(p.name for p in whole.glob("*.png"))
    shutil.copytree(whole, run)
    for name in ("results.json", *pngs):
        (run / name).unlink()
    (run / pngs[-1]).mkdir()  # no figure can be written in its place
    cfg = tiny_config(seeds=(1, 0))
    with pytest.raises(FigureError, match="its results are kept in .*results.json") as caught:
        run_experiment(cfg, run, workers=1, progress=False, resume=True)
    assert isinstance(caught.value.__cause__, OSError)
    assert f"torchcbl plot {run}" in str(caught.value) and caught.value.run_dir == run
    results = json.loads((run / "results.json").read_text(encoding="utf-8"))
    assert _untimed(results) == _untimed(json.loads((whole / "results.json").read_text()))
    (run / pngs[-1]).rmdir()
    plot_results(results, run)
    for name in pngs:
        assert (run / name).read_bytes() == (whole / name).read_bytes(), name


@pytest.mark.parametrize("workers", ["2", 2.5, None, 0, True])
def test_workers_must_be_a_whole_number_of_processes(tmp_path, workers):
    with pytest.raises(ValueError, match=r"workers must be an int >= 1, got "):
        run_experiment(tiny_config(), tmp_path / "run", workers=workers, progress=False)
    assert not (tmp_path / "run").exists()


def test_per_seed_follows_the_configs_order_of_seeds(two_seeds):
    """per_seed[i] is seeds[i]'s, with seeds given out of order, whichever worker ends first;
    Figure 7 draws the first seed given."""
    res, run_dir = two_seeds
    on_disk = json.loads((run_dir / "results.json").read_text())
    assert on_disk["seeds"] == [1, 0]
    assert [r["seed"] for r in on_disk["per_seed"]] == [1, 0]
    assert [r["seed"] for r in res["per_seed"]] == [1, 0]


def test_evaluate_drives_a_runs_session_on_the_segment_its_seed_was_evaluated_on(
    two_seeds, tmp_path, capsys
):
    """The experiment evaluates seed k on held-out segment eval_segment + k; `torchcbl
    evaluate` of seed 1's session drove segment 0 unless given --seed 1, with no word. A
    session of a run now defaults to its seed's segment, read from the seed's record, and says
    so in one line; --seed still picks another, and a session of no run drives segment 0."""
    import shutil

    from torchcbl.cli import main

    res, run_dir = two_seeds
    session = run_dir / "seed_1" / "sessions" / "arm_a"
    taught = res["per_seed"][0]["stages"]["a_plus20"]["segment"]
    assert res["per_seed"][0]["seed"] == 1 and taught == 1
    capsys.readouterr()
    assert main(["evaluate", str(session), "--steps", "20"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["eval_segment"] == taught
    assert len(err.splitlines()) == 1, err
    assert "held-out segment 1" in err and "seed_result.json" in err and "--seed" in err, err
    assert evaluate_saved_policy(session, n_steps=20)["eval_segment"] == taught
    assert main(["evaluate", str(session), "--steps", "20", "--seed", "0"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["eval_segment"] == 0 and err == ""
    alone = tmp_path / "arm_a"  # copied out of its run: no record says its segment
    shutil.copytree(session, alone)
    assert main(["evaluate", str(alone), "--steps", "20"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["eval_segment"] == 0 and err == ""


def test_evaluate_finds_a_runs_segment_from_a_relative_session_path(two_seeds, monkeypatch):
    """The segment was found from the path's parent folders as given: `torchcbl evaluate
    arm_a` from the seed's sessions/ folder (or `.` inside the session) found no record and
    drove segment 0, with no word."""
    from torchcbl.cli import main

    _, run_dir = two_seeds
    monkeypatch.chdir(run_dir / "seed_1" / "sessions")
    assert session_eval_segment("arm_a") == 1
    assert main(["evaluate", "arm_a", "--steps", "20"]) == 0
    monkeypatch.chdir("arm_a")
    assert session_eval_segment(".") == session_eval_segment("../arm_a") == 1


def test_a_seed_record_giving_a_negative_segment_gives_no_segment(tmp_path):
    """session_eval_segment is the seed record's eval_segment + seed, a road segment >= 0: a
    record edited to give a negative one says no segment (None, as an unreadable record
    does), not a segment no road has; 0 is a segment."""
    session = tmp_path / "seed_1" / "sessions" / "arm_a"
    session.mkdir(parents=True)
    record = tmp_path / "seed_1" / "seed_result.json"
    for eval_segment, segment in ((2, 3), (-1, 0), (-2, None), (-5, None)):
        kept = {"config": {"eval_segment": eval_segment}, "result": {"seed": 1}}
        record.write_text(json.dumps(kept), encoding="utf-8")
        assert session_eval_segment(session) == segment, eval_segment


def test_a_runs_stored_config_reads_back_as_the_config_it_ran(two_seeds):
    """The corridor's config reads a run's results.json "config" back (from_dict), the
    driving config had no way but DrivingExperimentConfig(**config): a round trip of the
    stored config, results.json's and a seed's record's, gives the config that ran, and
    to_dict writes what results.json holds."""
    import dataclasses

    _, run_dir = two_seeds
    ran = tiny_config(seeds=(1, 0))
    stored = json.loads((run_dir / "results.json").read_text())["config"]
    assert stored == ran.to_dict()
    assert DrivingExperimentConfig.from_dict(stored) == ran
    record = json.loads((run_dir / "seed_1" / "seed_result.json").read_text())["config"]
    assert DrivingExperimentConfig.from_dict(record) == ran
    full = DrivingExperimentConfig.full()
    assert full.to_dict() == json.loads(json.dumps(dataclasses.asdict(full)))
    assert DrivingExperimentConfig.from_dict(json.loads(json.dumps(full.to_dict()))) == full
    # seed k of a run alone, the rest its defaults
    again = dataclasses.replace(DrivingExperimentConfig.from_dict(stored), seeds=(1,))
    assert again.seeds == (1,) and again.eval_steps == ran.eval_steps
    assert DrivingExperimentConfig.from_dict({"seeds": [3]}) == DrivingExperimentConfig(seeds=(3,))
    on_disk = json.loads((run_dir / "results.json").read_text())
    for bad, says in (
        (on_disk, r'got a whole results.json; pass its "config"'),
        ({**stored, "seed": 3}, r"unknown DrivingExperimentConfig fields \['seed'\]"),
        ([stored], "expected a dict of DrivingExperimentConfig's fields"),
    ):
        with pytest.raises(ValueError, match=says):
            DrivingExperimentConfig.from_dict(bad)


def test_a_seed_rerun_alone_from_the_stored_config_gives_its_entry_again(two_seeds, tmp_path):
    """docs/reproduction.md's *Rerunning one seed*: seed k of a run, run alone from the config
    its results.json keeps, gives the run's entry for seed k again, but for its timing."""
    import dataclasses

    _, run_dir = two_seeds
    results = json.loads((run_dir / "results.json").read_text())
    config = DrivingExperimentConfig.from_dict(results["config"])
    rerun = run_experiment(
        dataclasses.replace(config, seeds=(1,)), tmp_path / "seed1", workers=1, progress=False
    )
    entry = results["per_seed"][results["seeds"].index(1)]
    assert entry["seed"] == 1
    assert _untimed(rerun["per_seed"][0]) == _untimed(entry)


def test_figure_9s_number_is_read_at_the_runs_own_arm_b_size(two_seeds):
    """Figure 9's number, the non-interactive learner's windowed accuracy at arm (b)'s last
    demonstration, is read at this run's arm_b_stages[-1] (80 here, the paper's 1000), and its
    results.json key and summary row name that number: it was read at the 1000th demonstration
    whatever the run's size (none here: no value) under a key and a row saying 1000."""
    _, run_dir = two_seeds
    on_disk = json.loads((run_dir / "results.json").read_text())
    s = on_disk["summary"]
    want = [r["accuracy_b"][79] for r in on_disk["per_seed"]]
    assert [len(r["accuracy_b"]) for r in on_disk["per_seed"]] == [80, 80] and None not in want
    assert s["ni_accuracy_at_80"] == pytest.approx(
        {"mean": np.mean(want), "sd": np.std(want, ddof=1), "n": 2}
    )
    assert not [k for k in s if "1000" in k]
    rows = [ln for ln in format_summary(on_disk).splitlines() if ln.startswith("| Fig 9 |")]
    assert rows == [
        f"| Fig 9 | windowed accuracy at 80 non-interactive demos | ≈ 0.8 | "
        f"{np.mean(want):.2f} ± {np.std(want, ddof=1):.2f} |"
    ]


@pytest.mark.parametrize(
    "argv, says",
    [
        (["--seeds", "0"], "--seeds: expected a number of seeds >= 1, got 0"),
        (["--workers", "0"], "--workers: expected >= 1, got 0"),
        ([], "exists and is not an empty directory"),
    ],
)
def test_the_module_command_refuses_a_mistake_before_writing(tmp_path, argv, says):
    """`python -m sumo_scenarios.experiment RUN_DIR --teacher expert` (docs/reproduction.md's way
    to the consistent expert): a mistake is argparse's message and exit code 2, no traceback."""
    import subprocess
    import sys

    run = tmp_path / "run"
    if not argv:  # a RUN_DIR that already holds a run
        run.mkdir()
        (run / "results.json").write_text("{}")
    proc = subprocess.run(
        [sys.executable, "-m", "sumo_scenarios.experiment", str(run), "--teacher", "expert", *argv],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2 and says in proc.stderr and "Traceback" not in proc.stderr
    assert sorted(p.name for p in tmp_path.rglob("*")) == ([] if argv else ["results.json", "run"])


def test_numpy_and_range_settings_are_kept_as_plain_json_values():
    """A config built from numpy values (a sweep over np.arange, say) must still write its
    results.json: the config is stored in it."""
    import dataclasses
    import json

    cfg = DrivingExperimentConfig(
        seeds=range(3), confident_demos=np.int64(150), arm_b_stages=np.array([600, 1000])
    )
    assert cfg.seeds == (0, 1, 2) and type(cfg.confident_demos) is int
    json.dumps(dataclasses.asdict(cfg))  # no numpy type left


def test_a_learner_that_stops_asking_ends_the_run_with_an_error_not_a_hang(tmp_path):
    """With a threshold so wide that the learner is always confident, arm (a)'s confident
    phase never collected its demonstrations: the run looped for ever, printing nothing. It
    now stops at max_confident_steps with an error naming how far it got."""
    cfg = tiny_config(max_std=1000.0, max_confident_steps=40)
    with pytest.raises(
        RuntimeError, match=r"max_confident_steps \(40\) steps and collected 0 of 20"
    ):
        run_experiment(cfg, tmp_path / "run", workers=1, progress=False)


def test_a_script_without_the_main_guard_fails_with_an_error_that_names_it(tmp_path):
    """A script that calls run_experiment at its top level: every spawned worker re-ran the
    script, failed at start-up (exit code 1), and the multiprocessing.Pool replaced it for
    ever: the run hung, printing a traceback per worker. It now stops with one error that
    names the script and the guard, before anything is written."""
    from _scripts import run_unguarded

    run_unguarded(
        tmp_path,
        "from _driving_tiny import tiny_config\n"
        "from sumo_scenarios.experiment import run_experiment\n"
        "run_experiment(tiny_config(), 'run', workers=1, progress=False)\n",
    )
    assert not (tmp_path / "run").exists()


_KILLS_ITS_WORKER = """
import threading
from _driving_tiny import tiny_config
from _scripts import kill_a_worker_when
from sumo_scenarios.experiment import run_experiment

if __name__ == "__main__":
    marker = "run/seed_0/sessions/arm_a/config.json"  # the seed is teaching
    threading.Thread(target=kill_a_worker_when, args=(marker,), daemon=True).start()
    run_experiment(tiny_config(eval_steps=1000), "run", workers=1, progress=False)
"""


def test_a_seed_worker_killed_by_a_signal_stops_the_run_with_an_error_not_a_hang(tmp_path):
    """A seed's worker killed mid-seed (the out-of-memory killer): the multiprocessing.Pool
    lost its task and run_experiment waited for its result for ever, saying nothing. The run
    now stops with an error that names the seed and the signal, and writes no results.json."""
    from _scripts import run_script, skip_without_proc_children

    skip_without_proc_children()
    code, err = run_script(tmp_path, _KILLS_ITS_WORKER, timeout=60)
    last = err.strip().splitlines()[-1]
    assert code == 1, err
    assert last.startswith("RuntimeError: the worker process of seed 0 was killed by signal 9")
    assert not (tmp_path / "run" / "results.json").exists()


_RAISES_WHAT_CANNOT_BE_PICKLED = """
import sumo_scenarios.experiment as experiment
from _driving_tiny import tiny_config


class Unpicklable(Exception):
    def __reduce__(self):
        raise TypeError("this exception stays in its process")


def failing_seed(cfg, seed, seed_dir):  # runs in the worker: this module is its __mp_main__
    raise Unpicklable("the seed's own message")


experiment._run_seed = failing_seed

if __name__ == "__main__":
    experiment.run_experiment(tiny_config(), "run", workers=1, progress=False)
"""


def test_a_seed_exception_that_cannot_be_pickled_keeps_its_message(tmp_path):
    """A seed whose exception cannot be pickled: the worker could not send it back and the run
    said only "the worker process of seed 0 exited with code 1 ... (with fewer workers if
    memory ran out)". The seed's message and traceback now come back as text."""
    from _scripts import run_script

    code, err = run_script(tmp_path, _RAISES_WHAT_CANNOT_BE_PICKLED, timeout=120)
    assert code == 1, err
    assert "RuntimeError: seed 0's worker could not send back its exception" in err
    assert "Unpicklable: the seed's own message" in err
    assert "exited with code" not in err


@pytest.mark.skipif(not hasattr(signal, "pthread_kill"), reason="signals a thread (POSIX)")
def test_a_ctrl_c_as_a_seed_worker_starts_leaves_no_worker_behind(tmp_path, monkeypatch):
    """A Ctrl-C (SIGINT) that came after a seed's worker process was started but before the
    run had kept it raised KeyboardInterrupt there; the run stopped the workers it knew of,
    and that one ran its seed on (in a notebook, for as long as the kernel). Here the SIGINT
    comes as the second seed's start returns; every seed worker started is gone (terminated
    and reaped: signal 0 finds no process) when run_experiment's KeyboardInterrupt comes out."""
    import threading
    from multiprocessing.context import SpawnProcess

    real_start = SpawnProcess.start
    pids = []

    def start(proc):
        seed = getattr(getattr(proc, "_target", None), "__name__", "") == "_seed_worker"
        real_start(proc)
        if seed:  # not the start-up check
            pids.append(proc.pid)
            if len(pids) == 2:  # a Ctrl-C to this thread: its handler runs before this returns
                signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    monkeypatch.setattr(SpawnProcess, "start", start)
    try:
        with pytest.raises(KeyboardInterrupt):
            run_experiment(tiny_config(seeds=(0, 1, 2)), tmp_path, workers=3, progress=False)
        assert len(pids) == 2
        assert [p for p in pids if exists(p)] == []
    finally:
        kill_left(pids)


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="lists open fds through /proc")
def test_a_seed_worker_that_cannot_start_leaves_no_pipe_open(tmp_path, monkeypatch):
    """A seed worker whose start raised (an OSError: no memory to fork, too many processes)
    left that seed's result pipe open, both ends: the error came out of run_experiment and
    the two descriptors stayed open for as long as its traceback was kept (a notebook keeps
    the last one; a loop that retries runs out of them). Here the seed workers' start raises;
    the OSError comes out and the process has the descriptors it had before. No seed runs."""
    import errno
    from multiprocessing.context import SpawnProcess

    real_start = SpawnProcess.start
    tried = []

    def start(proc):
        if getattr(getattr(proc, "_target", None), "__name__", "") != "_seed_worker":
            return real_start(proc)  # the start-up check
        tried.append(proc)
        raise OSError(errno.EAGAIN, "Resource temporarily unavailable")

    monkeypatch.setattr(SpawnProcess, "start", start)
    with pytest.raises(OSError, match="Resource temporarily unavailable"):
        # once first: what opens once per process (multiprocessing's resource tracker)
        run_experiment(tiny_config(), tmp_path / "first", workers=1, progress=False)
    before = sorted(os.listdir("/proc/self/fd"))
    with pytest.raises(OSError, match="Resource temporarily unavailable") as caught:
        run_experiment(tiny_config(), tmp_path / "run", workers=1, progress=False)
    after = sorted(os.listdir("/proc/self/fd"))
    assert len(tried) == 2 and caught.value.errno == errno.EAGAIN
    assert after == before


@pytest.mark.skipif(
    not hasattr(signal, "pthread_kill") or not Path("/proc/self/fd").is_dir(),
    reason="signals a thread (POSIX), lists open fds through /proc",
)
@pytest.mark.parametrize("where", ["waiting", "reading", "error"])
def test_a_run_stopped_by_a_ctrl_c_or_a_seed_error_leaves_no_worker_and_no_pipe(
    tmp_path, monkeypatch, where
):
    """A Ctrl-C while the run waited for its seed workers, or a seed's own error, left each
    worker's result pipe and process handle open for as long as the exception's traceback was
    kept (a notebook keeps the last one); a Ctrl-C while it read a worker's result (or reaped
    it) left that worker running its seed, never terminated nor reaped. Here the SIGINT comes
    as the run first waits for its worker ("waiting"), or as it reads the result of a worker
    it is told has one ("reading"); or the seed fails at once ("error": its directory is a
    file). With the exception (and its traceback) kept, the seed worker is gone (signal 0
    finds no process) and the process has the descriptors it had before."""
    import multiprocessing
    import multiprocessing.connection as connection
    import threading
    from multiprocessing.context import SpawnProcess

    from torchcbl.evaluation import check_workers_start

    real_start, real_wait, real_recv = (
        SpawnProcess.start,
        connection.wait,
        connection.Connection.recv,
    )
    pids = []

    def ctrl_c():  # to this thread: its handler runs before the caller's next line
        signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    def start(proc):
        seed = getattr(getattr(proc, "_target", None), "__name__", "") == "_seed_worker"
        real_start(proc)
        if seed:  # not the start-up check
            pids.append(proc.pid)

    def wait(objects, timeout=None):
        if where == "waiting":
            ctrl_c()
            return real_wait(objects, timeout)
        return list(objects)  # "reading": as if each worker had sent its result

    def recv(conn):
        ctrl_c()
        return real_recv(conn)

    monkeypatch.setattr(SpawnProcess, "start", start)
    if where != "error":
        monkeypatch.setattr(connection, "wait", wait)
        monkeypatch.setattr(connection.Connection, "recv", recv)
    stops = FileExistsError if where == "error" else KeyboardInterrupt

    def run(run_dir):
        run_dir.mkdir()
        (run_dir / "seed_0").write_text("a file where the seed's directory goes\n")
        with pytest.raises(stops) as caught:
            run_experiment(tiny_config(), run_dir, workers=1, progress=False)
        return caught

    # once first: what opens once per process (multiprocessing's resource tracker)
    check_workers_start(multiprocessing.get_context("spawn"))
    try:
        before = sorted(os.listdir("/proc/self/fd"))
        caught = run(tmp_path / "run")
        after = sorted(os.listdir("/proc/self/fd"))
        assert caught.value.__traceback__ is not None  # kept, with the run's frames
        assert len(pids) == 1
        assert [p for p in pids if exists(p)] == []
        assert after == before
    finally:
        kill_left(pids)


def test_evaluate_names_the_lanes_of_its_lane_shares(tmp_path, capsys):
    """`torchcbl evaluate` of a driving session printed "lanes": [0.02, 0.04, 0.2, 0.09, 0.65]
    with nothing saying which share is which lane: only a docstring gave the order. The JSON
    now has "lane_names" beside "lanes" (right shoulder first, left shoulder last) and
    `evaluate --help` says the order; "lanes" is unchanged for its readers."""
    from torchcbl.cli import main

    _taught(tmp_path / "session")
    capsys.readouterr()
    assert main(["evaluate", str(tmp_path / "session"), "--steps", "20"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["lane_names"] == ["right shoulder", "right", "middle", "left", "left shoulder"]
    assert len(report["lanes"]) == 5 and sum(report["lanes"]) == pytest.approx(1.0)
    want = _driven(tmp_path / "session", 20)["lanes"]
    assert report["lanes"] == [want.count(k) / 20 for k in range(5)]
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "lane_names" in help_text and "right shoulder first" in help_text


def test_the_threshold_is_read_literally_by_default_and_as_the_corridors_coverage_on_request():
    """The paper fixes its threshold, "two standard deviations for the most likely Gaussian
    component", in Section 5.1 (the corridor) only; Section 5.2 names none. The driving
    experiment keeps reading ``max_std`` literally by default (a Mahalanobis distance of 2),
    and with ``threshold_reading="coverage"`` reads it as the corridor does: the share of a
    1-D Gaussian within ``max_std`` std as a chi-square quantile, here in the driving env's
    D = 4 features (3.12 std). A config stored before the setting existed ran the literal
    reading and reads back as it."""
    import dataclasses
    import math

    from scipy.stats import chi2

    from sumo_scenarios.experiment import teaching_setup

    cfg = DrivingExperimentConfig()
    assert cfg.threshold_reading == "literal" and cfg.max_std == 2.0
    assert cfg.rule().quantile is None and cfg.rule().threshold(4) == 2.0
    assert teaching_setup()[1].quantile is None and teaching_setup()[1].threshold(4) == 2.0
    coverage = dataclasses.replace(cfg, threshold_reading="coverage")
    want = math.sqrt(chi2.ppf(chi2.cdf(4.0, 1), 4))  # P(|z| <= 2) = 0.9545, in 4-D
    assert want == pytest.approx(3.117, abs=1e-3)
    assert coverage.rule().threshold(4) == pytest.approx(want, rel=1e-9)
    assert teaching_setup(coverage)[1].threshold(4) == pytest.approx(want, rel=1e-9)
    stored = json.loads(json.dumps(coverage.to_dict()))
    assert stored["threshold_reading"] == "coverage"
    assert DrivingExperimentConfig.from_dict(stored) == coverage
    before = {k: v for k, v in stored.items() if k != "threshold_reading"}
    assert DrivingExperimentConfig.from_dict(before).threshold_reading == "literal"
    says = r"^threshold_reading: expected one of \('literal', 'coverage'\), got '2std'"
    with pytest.raises(ValueError, match=says):
        DrivingExperimentConfig(threshold_reading="2std")
    # a max_std whose coverage rounds to 1 gives no threshold: refused now, not in each worker
    with pytest.raises(
        ValueError, match=r"max_std = 9.0 gives no usable threshold with threshold_reading='cov"
    ):
        DrivingExperimentConfig(max_std=9.0, threshold_reading="coverage")
    assert DrivingExperimentConfig(max_std=9.0).rule().threshold(4) == 9.0


def test_a_run_under_the_coverage_reading_asks_and_counts_figure_10_at_its_threshold(
    tmp_path, two_seeds
):
    """run_experiment(replace(config, threshold_reading="coverage"), ...) teaches arm (a) with
    the quantile rule, records the reading in results.json, and counts Figure 10's share
    ("contact onsets preceded within 5 steps by a distance above the threshold") and draws its
    dashed line at the threshold in force (3.12 std), not at max_std; a results.json from
    before the setting existed is read as the literal 2 std it ran."""
    from torchcbl.session import load_config

    cfg = tiny_config(threshold_reading="coverage")
    thr = cfg.rule().threshold(4)
    run_experiment(cfg, tmp_path, workers=1, progress=False)
    on_disk = json.loads((tmp_path / "results.json").read_text())
    assert on_disk["config"]["threshold_reading"] == "coverage"
    rule = json.dumps(load_config(tmp_path / "seed_0" / "sessions" / "arm_a"))
    assert '"quantile": 0.9544997' in rule, rule
    s = on_disk["summary"]
    tr = on_disk["per_seed"][0]["fig10"]
    dist = tr["distance"]

    def base_rate(threshold):
        low = [any(d > threshold for d in dist[max(0, t - 4) : t + 1]) for t in range(len(dist))]
        return sum(low) / len(low)

    assert base_rate(thr) != base_rate(2.0)  # (the test tells the two apart)
    assert s["fig10_base_rate"] == pytest.approx(base_rate(thr))
    row = [ln for ln in format_summary(on_disk).splitlines() if "contact onsets" in ln]
    assert len(row) == 1 and "by distance > 3.12 (all steps)" in row[0], row
    assert len(plot_results(on_disk, tmp_path / "redrawn")) == 5
    # a results.json written before threshold_reading was stored: the literal reading
    old = json.loads((two_seeds[1] / "results.json").read_text())
    del old["config"]["threshold_reading"]
    row = [ln for ln in format_summary(old).splitlines() if "contact onsets" in ln]
    assert len(row) == 1 and "by distance > 2 (all steps)" in row[0], row
    assert len(plot_results(old, tmp_path / "old")) == 5


def _figure_7_title(results, run_dir, monkeypatch) -> str:
    """plot_results' Figure 7, drawn into ``run_dir``: the title it was drawn with."""
    import sumo_scenarios.experiment as experiment

    titles = []
    drawn = experiment.save_whole

    def keep_title(path, save, **kwargs):
        titles.append(save.__self__.axes[0].get_title())
        return drawn(path, save, **kwargs)

    monkeypatch.setattr(experiment, "save_whole", keep_title)
    assert plot_results(results, run_dir, only=["fig7_middle_lane_demos.png"])
    assert len(titles) == 1
    return titles[0]


def test_figure_7_draws_the_data_of_arm_as_final_model_and_an_old_run_still_redraws(
    two_seeds, tmp_path, monkeypatch
):
    """Paper 5.2: "The final learned model consisted of 34 Gaussian components ... Figure 7
    shows a sample of the data representing the policy for driving in the middle lane": the
    training data of confident execution's final model, arm (a)'s (non-interactive and
    confident demonstrations). Figure 7 drew arm (b)'s demonstrations. It now draws the first
    seed's arm (a) training set (the points its final model was fitted on, as its session
    keeps them) in the middle lane, and says so; a results.json written before (arm (b)'s
    points, no "arm" key) still redraws, its title saying arm b."""
    from torchcbl.session import load_demonstrations

    _, run_dir = two_seeds
    results = json.loads((run_dir / "results.json").read_text())
    first = results["per_seed"][0]
    assert first["seed"] == 1  # the config's first seed
    x, y = load_demonstrations(run_dir / "seed_1" / "sessions" / "arm_a")
    final = first["stages"]["a_plus20"]
    assert len(y) == final["fitted_on"] == final["demonstrations"]
    middle = np.rint(x[:, 3]) == 2
    assert middle.any() and not middle.all()
    f7 = first["fig7_middle_lane_demos"]
    assert f7["arm"] == "a"
    assert f7["x"] == x[middle, :3].tolist() and f7["action"] == y[middle].tolist()
    title = _figure_7_title(results, tmp_path / "new", monkeypatch)
    assert "arm (a)" in title and "seed 1" in title and "arm b" not in title, title
    # a run from before: arm (b)'s middle-lane demonstrations under the same key, no "arm"
    xb, yb = load_demonstrations(run_dir / "seed_1" / "sessions" / "arm_b")
    mb = np.rint(xb[:, 3]) == 2
    first["fig7_middle_lane_demos"] = {"x": xb[mb, :3].tolist(), "action": yb[mb].tolist()}
    title = _figure_7_title(results, tmp_path / "old", monkeypatch)
    assert title == "Figure 7: middle-lane demonstrations (seed 1, arm b)"
