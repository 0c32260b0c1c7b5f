"""`torchcbl teach driving --scenario` and `torchcbl evaluate --scenario`: the traffic a driving
session is taught and evaluated on, chosen at the command line (a few SUMO steps each)."""

from __future__ import annotations

import dataclasses
import errno
import json
import os
import re
from pathlib import Path

import pytest

from torchcbl.cli import main
from torchcbl.session import load_records


@pytest.fixture
def driving_person(monkeypatch):
    """`torchcbl teach driving` with a scripted person at the terminal (always "stay")."""
    import sumo_scenarios.human

    class Person:
        def __call__(self, observation, info):
            return 0

        def set_status(self, text):
            pass

    monkeypatch.setattr(sumo_scenarios.human, "make_teacher", lambda **kw: Person())


def _files(run: Path) -> dict[Path, bytes]:
    return {p: p.read_bytes() for p in sorted(run.rglob("*")) if p.is_file()}


def _one_line_error(capsys, *says: str) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for text in says:
        assert text in err, (text, err)
    return err


def test_teach_driving_on_traffic_of_ones_own_keeps_it_for_resume_replay_and_evaluate(
    tmp_path, driving_person, monkeypatch, capsys
):
    """`teach driving --scenario FILE.json` teaches on that traffic (a TrafficScenario made
    from the file's fields, its name the file's when it gives none); the session keeps it
    whole, so --resume drives it without --scenario (the file edited meanwhile changes
    nothing), refuses other traffic in one line (the same traffic given again goes on),
    replay rebuilds it and evaluate drives its held-out twin."""
    from sumo_scenarios.replay import session_episodes
    from sumo_scenarios.scenarios import TrafficScenario

    mine = TrafficScenario(name="mine", seed=7, mean_spacing_m=(80.0, 60.0, 200.0))
    path = tmp_path / "traffic" / "mine.json"
    path.parent.mkdir()
    path.write_text(json.dumps({"seed": 7, "mean_spacing_m": [80, 60, 200]}))
    run = tmp_path / "session"
    monkeypatch.chdir(tmp_path)
    argv = ["teach", "driving", "--run-dir", str(run), "--steps", "3"]
    assert main([*argv[:-1], "4", "--scenario", "traffic/mine.json"]) == 0, capsys.readouterr().err
    env = json.loads((run / "config.json").read_text())["env"]
    assert env["inputs"]["traffic.seed"] == 7, env
    assert env["inputs"]["traffic.mean_spacing_m"] == "[80.0, 60.0, 200.0]", env
    assert {e.scenario for e in session_episodes(run, check=True)} == {mine}
    # the file edited after: the session drives what it kept
    path.write_text(json.dumps({"seed": 8}))
    assert main([*argv, "--resume"]) == 0, capsys.readouterr().err
    assert len(load_records(run)) == 7
    assert {e.scenario for e in session_episodes(run)} == {mine}
    # other traffic on resume: refused in one line, nothing of the session changes
    kept = _files(run)
    for other in ("light", "traffic/mine.json"):
        capsys.readouterr()
        assert main([*argv, "--resume", "--scenario", other]) == 2
        _one_line_error(capsys, "--scenario", "differs from the traffic", "seed")
        assert _files(run) == kept
    # the same traffic given again (another name: the name changes nothing the traffic does)
    same = tmp_path / "same.json"
    same.write_text(json.dumps({"name": "again", "seed": 7, "mean_spacing_m": [80, 60, 200]}))
    assert main([*argv, "--resume", "--scenario", str(same)]) == 0, capsys.readouterr().err
    assert len(load_records(run)) == 10  # a first fit: a policy to evaluate
    capsys.readouterr()
    assert main(["evaluate", str(run), "--steps", "5"]) == 0, capsys.readouterr().err
    report = json.loads(capsys.readouterr().out)
    # evaluate drives its held-out twin: the same traffic, the next base seed
    assert report["scenario"]["name"] == "mine-held-out" and report["scenario"]["seed"] == 8
    assert report["scenario"]["mean_spacing_m"] == [80.0, 60.0, 200.0] and report["held_out"]
    assert main(["replay", str(run), "--list"]) == 0
    assert "session/episode 0" in capsys.readouterr().out


def test_a_session_episode_replays_from_the_lane_it_started_in(tmp_path, monkeypatch, capsys):
    """A person who moves left at every step takes the ego from the middle lane (2) to the
    left shoulder: the session's episode is rebuilt starting in lane 2, its first logged
    observation's lane, not the lane it ended in, and its replay equals the log."""
    import sumo_scenarios.human
    from sumo_scenarios.env import LEFT
    from sumo_scenarios.replay import session_episodes

    class LeftMover:
        def __call__(self, observation, info):
            return LEFT

        def set_status(self, text):
            pass

    monkeypatch.setattr(sumo_scenarios.human, "make_teacher", lambda **kw: LeftMover())
    run = tmp_path / "session"
    assert main(["teach", "driving", "--run-dir", str(run), "--steps", "3"]) == 0, (
        capsys.readouterr().err
    )
    lanes = [int(r.observation[3]) for r in load_records(run)]
    assert lanes[0] == 2 and lanes[-1] == 4, lanes
    (episode,) = session_episodes(run, check=True)
    assert episode.start_lane == 2


def test_teach_driving_on_a_shipped_scenario_by_name(tmp_path, driving_person, capsys):
    """`--scenario light` teaches on the shipped light traffic, kept by its name; a resume
    given the same name goes on, one given another is refused."""
    run = tmp_path / "session"
    argv = ["teach", "driving", "--run-dir", str(run), "--steps", "2"]
    assert main([*argv, "--scenario", "light"]) == 0, capsys.readouterr().err
    env = json.loads((run / "config.json").read_text())["env"]
    assert env["kwargs"]["scenario"] == "light" and env["inputs"]["traffic.seed"] == 3, env
    assert main([*argv, "--resume", "--scenario", "light"]) == 0, capsys.readouterr().err
    assert main([*argv, "--resume"]) == 0, capsys.readouterr().err
    assert len(load_records(run)) == 6
    capsys.readouterr()
    assert main([*argv, "--resume", "--scenario", "train"]) == 2
    _one_line_error(capsys, "'light'", "leave --scenario out")


@pytest.mark.parametrize(
    "content, says",
    [
        (None, "not found"),
        ("{not json", "is not valid JSON"),
        ("[1, 2]", "holds a JSON list; expected one JSON object"),
        ('{"name": "x"}', "'seed'"),
        ('{"seed": 1, "lanes": 3}', "'lanes'"),
        ('{"seed": -1}', "seed must be an int >= 0"),
        ('{"seed": 1, "seed": 2}', "given twice"),
        ('{"seed": 1, "speed_ranges_mph": [[10, 30], [25, 35], [30, 40]]}', "20 <= low"),
        ('{"seed": 1, "mean_spacing_m": [40, 31]}', "3 in all"),
        ('{"seed": 1, "name": ""}', "name must be a non-blank str"),
        ('{"seed": 1, "name": " \\t"}', "name must be a non-blank str"),
    ],
)
def test_teach_driving_refuses_a_scenario_file_it_cannot_take_in_one_line(
    content, says, tmp_path, capsys
):
    """A --scenario file that is missing, not JSON, not an object, lacks the seed, names a
    field TrafficScenario lacks, gives a key twice or a value TrafficScenario refuses: one line
    naming the file and what is wrong (TrafficScenario's own words), exit 2, nothing written."""
    path = tmp_path / "traffic.json"
    if content is not None:
        path.write_text(content)
    run = tmp_path / "session"
    assert main(["teach", "driving", "--run-dir", str(run), "--scenario", str(path)]) == 2
    _one_line_error(capsys, "--scenario", says)
    assert not run.exists()


def test_a_scenario_file_that_cannot_be_read_or_parsed_says_what_to_do(
    tmp_path, monkeypatch, capsys
):
    """A --scenario file that is not JSON, or that cannot be read (an I/O error), was refused
    saying only what was wrong ("is not valid JSON: ...", "cannot be read (...)"); each now
    says what to do, as a map file's does. A missing FILE.JSON, whatever the suffix's case, is
    a scenario file not found, as a map file's is."""
    run = tmp_path / "session"
    argv = ["teach", "driving", "--run-dir", str(run), "--scenario"]
    path = tmp_path / "traffic.json"
    path.write_text("{not json")
    assert main([*argv, str(path)]) == 2
    shipped = "give a shipped scenario's name (eval, light, train)"
    _one_line_error(capsys, "is not valid JSON: ", f"; fix the file, or {shipped}")
    path.write_text('{"seed": 7}')
    read_text = Path.read_text

    def failing(self, *args, **kwargs):
        if self == path:
            raise OSError(errno.EIO, os.strerror(errno.EIO), str(self))
        return read_text(self, *args, **kwargs)

    monkeypatch.setattr(Path, "read_text", failing)
    assert main([*argv, str(path)]) == 2
    _one_line_error(
        capsys,
        f"cannot be read ({os.strerror(errno.EIO)}); ",
        "give a JSON file of TrafficScenario fields this user can read",
    )
    monkeypatch.undo()
    assert main([*argv, str(tmp_path / "TRAFFIC.JSON")]) == 2
    _one_line_error(capsys, "scenario file ", "TRAFFIC.JSON' not found")
    assert not run.exists()


def test_scenario_and_map_each_belong_to_their_own_domain(tmp_path, capsys):
    """--scenario is driving's, --map the corridor's: each given to the other domain is one
    line, exit 2, nothing written; an unknown name lists the shipped scenarios."""
    run = tmp_path / "session"
    assert main(["teach", "corridor", "--run-dir", str(run), "--scenario", "light"]) == 2
    _one_line_error(capsys, "--scenario applies only to teach driving")
    assert main(["teach", "driving", "--run-dir", str(run), "--map", "lshape"]) == 2
    _one_line_error(capsys, "--map applies only to teach corridor", "--scenario")
    assert main(["teach", "driving", "--run-dir", str(run), "--scenario", "atlantis"]) == 2
    _one_line_error(capsys, "unknown scenario 'atlantis'", "eval, light, train", ".json")
    assert not run.exists()
    with pytest.raises(SystemExit):
        main(["teach", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "--scenario NAME|FILE.json" in help_text
    # the help names the one field a file must give and where the others are described, the
    # README, which names every TrafficScenario field (a copy of the list in the help drifts)
    assert '"seed" (an int >= 0, required)' in help_text, help_text
    assert "fields left out take train's values" in help_text, help_text
    assert "README.md" in help_text and "mean_spacing_m" in help_text, help_text
    from sumo_scenarios.scenarios import TrafficScenario

    readme = " ".join((Path(__file__).parents[1] / "README.md").read_text().split())
    described = readme.split("`teach driving --scenario NAME|FILE.json`", 1)[1][:1000]
    for f in dataclasses.fields(TrafficScenario):
        assert f'`"{f.name}"`' in described, f.name


def test_evaluate_drives_a_driving_session_on_the_traffic_given(tmp_path, driving_person, capsys):
    """Without --scenario evaluate drives a session taught on the train traffic on its held-out
    twin eval, as the reproduction does; `--scenario NAME|FILE.json` drives that traffic
    instead. A corridor session given --scenario is one line, exit 2."""
    run = tmp_path / "session"
    assert main(["teach", "driving", "--run-dir", str(run), "--steps", "10"]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(run), "--steps", "5"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["scenario"]["name"] == "eval" and report["held_out"] is True, report
    assert main(["evaluate", str(run), "--steps", "5", "--scenario", "light"]) == 0
    assert json.loads(capsys.readouterr().out)["scenario"]["name"] == "light"
    path = tmp_path / "held_out.json"
    path.write_text(json.dumps({"seed": 11, "mean_spacing_m": [80, 60, 200]}))
    assert main(["evaluate", str(run), "--steps", "5", "--scenario", str(path)]) == 0
    scenario = json.loads(capsys.readouterr().out)["scenario"]
    assert (scenario["name"], scenario["seed"]) == ("held_out", 11), scenario
    assert main(["evaluate", str(run), "--scenario", str(tmp_path / "none.json")]) == 2
    _one_line_error(capsys, "--scenario", "not found")
    from corridor.env import CorridorEnv
    from torchcbl import ConfidentTeacher

    corridor = tmp_path / "corridor"
    ConfidentTeacher(CorridorEnv(), lambda o, i: 0, run_dir=corridor, progress=False).run(
        max_steps=2
    ).close()
    assert main(["evaluate", str(corridor), "--scenario", "light"]) == 2
    _one_line_error(capsys, "--scenario applies only to a driving session", "leave --scenario out")


def test_teach_resume_compares_scenario_with_a_driving_config_sessions_traffic(
    tmp_path, driving_person, capsys
):
    """A session begun in Python on gymnasium.make(..., config=DrivingConfig(scenario=...))
    drives its DrivingConfig's traffic: teach --resume --scenario takes that traffic and
    refuses another in one line."""
    import gymnasium as gym

    import sumo_scenarios
    from sumo_scenarios.env import DrivingConfig
    from torchcbl import ConfidentTeacher

    run = tmp_path / "session"
    env = gym.make(sumo_scenarios.ENV_ID, config=DrivingConfig(scenario="light", start_lane=1))
    ConfidentTeacher(env, lambda o, i: 0, run_dir=run, progress=False).run(max_steps=2).close()
    env.close()
    argv = ["teach", "driving", "--run-dir", str(run), "--resume", "--steps", "2"]
    capsys.readouterr()
    assert main([*argv, "--scenario", "train"]) == 2
    _one_line_error(capsys, "taught on ('light')", "seed 1 (the session's: 3)")
    assert main([*argv, "--scenario", "light"]) == 0, capsys.readouterr().err
    assert len(load_records(run)) == 4


def test_evaluate_of_traffic_a_session_kept_only_as_text_says_and_takes_scenario(
    tmp_path, driving_person, capsys
):
    """A session written before 2026-11-27 kept a TrafficScenario given to gymnasium.make only
    as text: evaluate cannot know its traffic and says so in one line, naming --scenario (it
    said the command had no option for it); given --scenario it drives that traffic."""
    path = tmp_path / "mine.json"
    path.write_text(json.dumps({"seed": 7, "mean_spacing_m": [80, 60, 200]}))
    run = tmp_path / "session"
    argv = ["teach", "driving", "--run-dir", str(run), "--steps", "10"]
    assert main([*argv, "--scenario", str(path)]) == 0, capsys.readouterr().err
    config = json.loads((run / "config.json").read_text())
    del config["env"]["kwargs_objects"]  # as written before 2026-11-27
    (run / "config.json").write_text(json.dumps(config))
    capsys.readouterr()
    assert main(["evaluate", str(run), "--steps", "5"]) == 2
    _one_line_error(capsys, "given as an object", "torchcbl evaluate --scenario NAME|FILE.json")
    assert main(["evaluate", str(run), "--steps", "5", "--scenario", str(path)]) == 0
    assert json.loads(capsys.readouterr().out)["scenario"]["seed"] == 7


def test_evaluate_drives_a_session_of_other_traffic_on_road_it_was_not_taught_on(
    tmp_path, driving_person, capsys
):
    """A session taught on traffic other than train's (here `light`, base seed 3) was evaluated on
    that same traffic, segment 0: with teach's default --seed 0, the very road its first
    episode drove, a collision rate read as held out that was not. By default evaluate now
    drives the traffic's held-out twin (the same traffic, the next base seed: as eval is
    train's) and says so in its JSON; --scenario and --seed still choose, and a choice that
    drives road the session was taught on is driven, with a one-line note."""
    from sumo_scenarios.scenarios import LIGHT

    run = tmp_path / "session"
    argv = ["teach", "driving", "--run-dir", str(run), "--steps", "10", "--scenario", "light"]
    assert main(argv) == 0, capsys.readouterr().err
    assert {r.info["episode_seed"] for r in load_records(run)} == {0}
    capsys.readouterr()
    assert main(["evaluate", str(run), "--steps", "5"]) == 0
    out, err = capsys.readouterr()
    report = json.loads(out)
    light = json.loads(json.dumps(dataclasses.asdict(LIGHT)))
    assert report["scenario"] == {**light, "name": "light-held-out", "seed": 4}, report
    assert report["eval_segment"] == 0 and report["held_out"] is True, report
    assert err == "", err
    # the taught traffic given back: segment 0 is the road its episode 0 drove
    assert main(["evaluate", str(run), "--steps", "5", "--scenario", "light"]) == 0
    out, err = capsys.readouterr()
    report = json.loads(out)
    assert report["scenario"] == light and report["held_out"] is False, report
    assert err.count("\n") == 1 and "not held out" in err and "episode 0" in err, err
    # ... naming the options that drive held-out road (it named none), in Python the keywords
    assert "another segment (--seed S)" in err and "leave --scenario out" in err, err
    assert "seed=" not in err and "scenario=" not in err, err
    from sumo_scenarios.experiment import NotHeldOutWarning, evaluate_saved_policy

    with pytest.warns(NotHeldOutWarning, match="episode 0") as said:
        evaluate_saved_policy(run, n_steps=5, scenario="light")
    (warning,) = said
    assert "another segment (seed=)" in str(warning.message), warning.message
    assert "leave scenario out" in str(warning.message), warning.message
    # a segment none of its episodes drove is held out, though the traffic is the same
    assert main(["evaluate", str(run), "--steps", "5", "--scenario", "light", "--seed", "5"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["held_out"] is True and err == "", err


def test_evaluate_of_a_session_made_directly_on_eval_says_no_leave_scenario_out(tmp_path, capsys):
    """A session whose env was made directly (nothing kept but what it described) on the eval
    traffic is driven, by default, on the defaults' held-out traffic, eval itself: road it
    was taught on. The warning names --seed and --scenario, not "leave --scenario out", which
    was left out already."""
    from sumo_scenarios.env import DrivingConfig, DrivingEnv
    from sumo_scenarios.experiment import NotHeldOutWarning, evaluate_saved_policy
    from sumo_scenarios.scenarios import EVAL
    from torchcbl import ConfidentTeacher

    run = tmp_path / "session"
    env = DrivingEnv(DrivingConfig(scenario=EVAL))
    ConfidentTeacher(env, lambda o, i: 0, run_dir=run, progress=False).run(max_steps=3).close()
    env.close()
    assert main(["evaluate", str(run), "--steps", "5"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["held_out"] is False
    assert err.count("\n") == 1 and "not held out" in err and "(--seed S)" in err, err
    assert "--scenario NAME|FILE.json" in err and "leave --scenario out" not in err, err
    with pytest.warns(NotHeldOutWarning) as said:
        evaluate_saved_policy(run, n_steps=5)
    assert "(scenario=)" in str(said[0].message) and "leave" not in str(said[0].message)


def test_held_out_twin_is_eval_for_train_and_the_next_base_seed_otherwise():
    """One rule gives every traffic its held-out road: the same fields on the next base seed,
    named as the shipped scenario of those fields (train -> eval), else '<name>-held-out'."""
    from sumo_scenarios.scenarios import EVAL, LIGHT, TRAIN, TrafficScenario, held_out_twin

    assert held_out_twin("train") is EVAL and held_out_twin(TRAIN) is EVAL
    assert held_out_twin(TrafficScenario(name="mine", seed=1)) is EVAL  # train's traffic
    # train's base seed but other traffic: not eval's road, its own twin on seed 2
    sparse = TrafficScenario(name="m", seed=1, mean_spacing_m=(80.0, 80.0, 80.0))
    assert held_out_twin(sparse) == dataclasses.replace(sparse, name="m-held-out", seed=2)
    assert held_out_twin(LIGHT) == dataclasses.replace(LIGHT, name="light-held-out", seed=4)
    mine = TrafficScenario(name="mine", seed=7, mean_spacing_m=(80.0, 60.0, 200.0))
    assert held_out_twin(mine) == dataclasses.replace(mine, name="mine-held-out", seed=8)
    with pytest.raises(ValueError, match="unknown scenario 'atlantis'"):
        held_out_twin("atlantis")


def test_a_segment_driven_on_the_taught_base_seed_and_episode_seed_is_not_held_out(
    tmp_path, driving_person, capsys
):
    """A segment's random stream is SeedSequence([base seed, episode seed]), whatever the other
    fields: traffic that differs from the taught one only in a spacing or a speed range, driven
    on a segment the session drove, reuses the taught road's draws (a speed range 1 mph off
    puts every car where it was). `held_out` said True there, judging by every field; it is
    now False, with the one-line warning. Another segment, or another base seed (the twin), is
    held out."""
    taught = tmp_path / "taught.json"
    taught.write_text(json.dumps({"seed": 7}))
    run = tmp_path / "session"
    argv = ["teach", "driving", "--run-dir", str(run), "--steps", "10", "--seed", "3"]
    assert main([*argv, "--scenario", str(taught)]) == 0, capsys.readouterr().err
    assert {r.info["episode_seed"] for r in load_records(run)} == {3}
    edited = tmp_path / "edited.json"
    evaluate = ["evaluate", str(run), "--steps", "5", "--scenario", str(edited)]
    for fields in ({"min_spacing_m": 15}, {"speed_ranges_mph": [[21, 31], [25, 35], [30, 40]]}):
        edited.write_text(json.dumps({"seed": 7, **fields}))
        capsys.readouterr()
        assert main([*evaluate, "--seed", "3"]) == 0
        out, err = capsys.readouterr()
        assert json.loads(out)["held_out"] is False, (fields, out)
        assert err.count("\n") == 1 and "not held out" in err and "episode 0" in err, err
        assert main([*evaluate, "--seed", "4"]) == 0
        out, err = capsys.readouterr()
        assert json.loads(out)["held_out"] is True and err == "", (fields, err)
    edited.write_text(json.dumps({"seed": 8, "min_spacing_m": 15}))
    assert main([*evaluate, "--seed", "3"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["held_out"] is True and err == "", err


def test_road_the_prior_demonstrations_were_taught_on_is_not_held_out(
    tmp_path, driving_person, capsys
):
    """A session started from prior demonstrations (`teach --prior-demonstrations DIR`) was
    judged by its own episodes alone: driven on a segment the prior's session drove, it
    reported `held_out: true`, silently. That road now counts as taught (the warning names
    the prior's session, also when both sessions moved together); where the prior's road
    cannot be known (its session gone, a .npz file's arrays) `held_out` is null, with a
    one-line warning saying so, never true."""
    import numpy as np

    from sumo_scenarios.experiment import NotHeldOutWarning, evaluate_saved_policy
    from torchcbl.session import load_demonstrations

    runs = tmp_path / "runs"
    a, b = runs / "a", runs / "b"
    teach, prior = ["teach", "driving", "--steps"], "--prior-demonstrations"
    assert main([*teach, "10", "--run-dir", str(a), "--seed", "3", "--scenario", "light"]) == 0
    assert main([*teach, "5", "--run-dir", str(b), "--seed", "6", prior, str(a)]) == 0
    assert {r.info["episode_seed"] for r in load_records(b)} == {6}
    capsys.readouterr()

    def evaluated(run: Path, seed: int) -> tuple[object, str]:
        """`evaluate RUN --scenario light --seed SEED`: (held_out, stderr)."""
        argv = ["evaluate", str(run), "--steps", "5", "--scenario", "light"]
        assert main([*argv, "--seed", str(seed)]) == 0
        out, err = capsys.readouterr()
        return json.loads(out)["held_out"], err

    held, err = evaluated(b, 3)  # segment 3 of light: road a's episode drove
    assert held is False, err
    assert err.count("\n") == 1 and "not held out" in err and "prior" in err and str(a) in err, err
    assert evaluated(b, 6) == (True, "")  # b drove segment 6 of train, not of light
    assert evaluated(b, 4) == (True, "")
    with pytest.warns(NotHeldOutWarning, match="prior demonstrations"):
        report = evaluate_saved_policy(b, n_steps=5, scenario="light", seed=3)
    assert report["held_out"] is False
    # a taught further since: its first steps, those b's prior was read at, still count
    assert main([*teach, "3", "--run-dir", str(a), "--resume"]) == 0
    capsys.readouterr()
    held, err = evaluated(b, 3)
    assert held is False and str(a) in err, err
    runs.rename(tmp_path / "moved")  # both moved together: b finds a beside it
    b = tmp_path / "moved" / "b"
    held, err = evaluated(b, 3)
    assert held is False and str(tmp_path / "moved" / "a") in err, err
    (tmp_path / "moved" / "a").rename(tmp_path / "gone")  # the prior's session is not there
    for seed in (3, 4):
        held, err = evaluated(b, seed)
        assert held is None and err.count("\n") == 1 and "not known" in err, err
        assert "Traceback" not in err
    # arrays from a file: where they were taught is not recorded
    x, y = load_demonstrations(tmp_path / "gone")
    np.savez(tmp_path / "prior.npz", observations=x, actions=y)
    c = tmp_path / "c"
    assert main([*teach, "2", "--run-dir", str(c), prior, str(tmp_path / "prior.npz")]) == 0
    capsys.readouterr()
    held, err = evaluated(c, 3)
    assert held is None and "not known" in err and "given as arrays" in err, err
    with pytest.warns(NotHeldOutWarning, match="not known"):
        assert evaluate_saved_policy(c, n_steps=5)["held_out"] is None


def test_a_loop_of_prior_sessions_moved_over_one_another_is_not_held_out(
    tmp_path, driving_person, capsys
):
    """Sessions moved over one another's places can name each other as their prior's source
    (x deleted, z, made from y, renamed x: y's prior reads as x's, x's as y's). Following the
    chain then met a session it had passed and stopped with "not taught", so evaluate said
    `held_out: true` although where the prior was taught is lost. A loop is unknown: null,
    with a one-line warning saying so."""
    import shutil

    import gymnasium as gym

    import sumo_scenarios
    from sumo_scenarios.experiment import teaching_setup
    from torchcbl import ConfidentTeacher
    from torchcbl.session import load_demonstrations

    a = tmp_path / "a"
    argv = ["teach", "driving", "--steps", "10", "--run-dir", str(a), "--seed", "3"]
    assert main([*argv, "--scenario", "light"]) == 0
    _, _, make_model = teaching_setup()

    def started(run: Path, prior: object) -> None:
        """A session started from ``prior`` and closed at once (its training set: the prior)."""
        env = gym.make(sumo_scenarios.ENV_ID, scenario="light")
        ConfidentTeacher(
            env,
            lambda o, i: 0,
            model=make_model(),
            run_dir=run,
            prior_demonstrations=prior,
            progress=False,
        ).close()
        env.close()

    x, y, z = tmp_path / "x", tmp_path / "y", tmp_path / "z"
    started(x, load_demonstrations(a))
    started(y, load_demonstrations(x))
    started(z, load_demonstrations(y))
    shutil.rmtree(x)  # a drove segment 3 of light, but nothing leads to it any more
    z.rename(x)
    capsys.readouterr()
    assert main(["evaluate", str(y), "--steps", "5", "--scenario", "light", "--seed", "3"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["held_out"] is None, err
    assert err.count("\n") == 1 and "not known" in err and "loop" in err, err


def test_evaluate_reads_a_prior_session_once_and_only_its_steps_then(
    tmp_path, driving_person, monkeypatch, capsys
):
    """For each session up the prior chain, evaluate read the whole log twice (its training
    set, to check it, then every record again for the segments its episodes drove): a
    500,000-step prior took 15 s and about 1 GB before SUMO started. It now reads the steps
    the prior was read at, once, and scans those. (Counted where the log's rows are made
    records, the cost that grew with the log.)"""
    import torchcbl.session as session

    a, b = tmp_path / "a", tmp_path / "b"
    teach = ["teach", "driving", "--steps"]
    assert main([*teach, "10", "--run-dir", str(a), "--seed", "3", "--scenario", "light"]) == 0
    assert main([*teach, "2", "--run-dir", str(b), "--prior-demonstrations", str(a)]) == 0
    assert main([*teach, "30", "--run-dir", str(a), "--resume"]) == 0  # 40 steps now
    capsys.readouterr()
    made: dict[Path, int] = {}
    records_of = session._records_of

    def counted(rows, run_dir, *args):
        made[Path(run_dir)] = made.get(Path(run_dir), 0) + len(rows)
        return records_of(rows, run_dir, *args)

    monkeypatch.setattr(session, "_records_of", counted)
    assert main(["evaluate", str(b), "--steps", "5", "--scenario", "light", "--seed", "4"]) == 0
    assert json.loads(capsys.readouterr().out)["held_out"] is True
    assert made[a] == 10, made  # its first 10 steps, once (was 40 twice)
    assert made[b] == 2, made


def test_a_session_that_kept_its_traffic_as_text_drove_road_of_an_unknown_base_seed(
    tmp_path, driving_person, capsys
):
    """A session written before its env described its traffic (no traffic.seed) and before
    objects were kept whole (its TrafficScenario only as text) does not record its base seed.
    Evaluate took it for train's: a segment its episodes drove, on the base seed it was in fact
    taught on, was said held out (`true`), for the session and for one whose prior was read
    from it. Where one of its episodes drove the segment, whether that is taught road cannot
    be told: null, with a one-line warning; a segment none drove is still held out."""
    a, b = tmp_path / "a", tmp_path / "b"
    mine = tmp_path / "mine.json"
    mine.write_text(json.dumps({"name": "mine", "seed": 7}))
    teach = ["teach", "driving", "--steps"]
    assert main([*teach, "10", "--run-dir", str(a), "--seed", "3", "--scenario", str(mine)]) == 0
    prior = ["--prior-demonstrations", str(a)]
    assert main([*teach, "5", "--run-dir", str(b), "--seed", "6", *prior]) == 0
    assert {r.info["episode_seed"] for r in load_records(a)} == {3}
    path = a / "config.json"  # as a torchcbl before 2026-11-27 wrote it
    config = json.loads(path.read_text())
    del config["env"]["kwargs_objects"]
    config["env"]["kwargs"]["scenario"] = {"repr": "TrafficScenario(name='mine', seed=7)"}
    inputs = config["env"]["inputs"]
    config["env"]["inputs"] = {k: v for k, v in inputs.items() if not k.startswith("traffic.")}
    path.write_text(json.dumps(config))
    capsys.readouterr()

    def evaluated(run: Path, seed: int) -> tuple[object, str]:
        """`evaluate RUN --scenario mine.json --seed SEED`: (held_out, stderr)."""
        argv = ["evaluate", str(run), "--steps", "5", "--scenario", str(mine)]
        assert main([*argv, "--seed", str(seed)]) == 0
        out, err = capsys.readouterr()
        return json.loads(out)["held_out"], err

    for run in (a, b):
        held, err = evaluated(run, 3)  # segment 3 of base seed 7: a's episode 0 drove it
        assert held is None and err.count("\n") == 1 and "not known" in err, (run, err)
        assert "Traceback" not in err
        assert evaluated(run, 4) == (True, "")  # no episode drove segment 4


def test_evaluate_saved_policy_takes_a_scenario_file_as_the_cli_does(
    tmp_path, driving_person, capsys
):
    """evaluate_saved_policy(run, scenario="mytraffic.json") was refused as an "unknown
    scenario ...; known: eval, light, train" though `evaluate --scenario FILE.json` drives it:
    Python now takes a path (str or os.PathLike) too, through load_scenario as the CLI does,
    and an unknown name says a JSON file is taken. get_scenario, which takes no path, points
    to load_scenario(path) for one."""
    from sumo_scenarios.experiment import evaluate_saved_policy
    from sumo_scenarios.scenarios import get_scenario

    run = tmp_path / "session"
    assert main(["teach", "driving", "--run-dir", str(run), "--steps", "10"]) == 0
    path = tmp_path / "mytraffic.json"
    path.write_text(json.dumps({"seed": 11, "mean_spacing_m": [80, 60, 200]}))
    capsys.readouterr()
    assert main(["evaluate", str(run), "--steps", "5", "--scenario", str(path)]) == 0
    from_cli = json.loads(capsys.readouterr().out)
    for given in (str(path), path):
        report = evaluate_saved_policy(run, n_steps=5, scenario=given)
        assert report == from_cli, report
    assert report["scenario"]["name"] == "mytraffic" and report["scenario"]["seed"] == 11
    with pytest.raises(ValueError, match=r"unknown scenario 'atlantis'.*FILE\.json"):
        evaluate_saved_policy(run, n_steps=5, scenario="atlantis")
    with pytest.raises(ValueError, match="scenario file .*none.json' not found"):
        evaluate_saved_policy(run, n_steps=5, scenario=str(tmp_path / "none.json"))
    with pytest.raises(ValueError, match=r"known: eval, light, train; .*load_scenario\(path\)"):
        get_scenario(str(path))


def test_a_traffic_scenario_needs_a_name_that_is_not_blank():
    """A TrafficScenario named "" (a scenario file's "name": "") was taken: its held-out twin
    was "-held-out" and reports named no traffic. An empty or blank name is refused as the
    other fields are, saying what was given; a file that leaves "name" out takes its own."""
    from sumo_scenarios.scenarios import TrafficScenario

    for blank in ("", "   ", "\n"):
        with pytest.raises(ValueError, match=rf"non-blank str .* got {re.escape(repr(blank))}"):
            TrafficScenario(name=blank, seed=0)
    with pytest.raises(ValueError, match="name must be a non-blank str"):
        dataclasses.replace(TrafficScenario(name="mine", seed=0), name="")


@pytest.mark.parametrize("domain", ["driving", "corridor"])
def test_evaluate_refuses_a_negative_seed_in_its_own_words(domain, tmp_path, capsys):
    """evaluate_saved_policy(..., seed=-1) was refused by evaluate_policy, deep inside, as
    "evaluate_policy: seeds must be ints >= 0 ..." after the session had been read; each
    domain's evaluate_saved_policy now checks its own `seed` first, naming it, and `torchcbl
    evaluate --seed -1` is one line naming --seed."""
    import importlib

    evaluate = importlib.import_module(f"{domain}.experiment".replace("driving", "sumo_scenarios"))
    for bad in (-1, True, 2.0, "3"):
        with pytest.raises(ValueError, match=rf"^seed must be an int >= 0, got {bad!r}$"):
            evaluate.evaluate_saved_policy(tmp_path / "no session", n_steps=5, seed=bad)
    with pytest.raises(SystemExit) as exc:  # argparse's usage error
        main(["evaluate", str(tmp_path), "--domain", domain, "--seed", "-1"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "argument --seed: " in err and "got '-1'" in err, err
    assert "evaluate_policy" not in err, err
