"""The command line: help texts, and a person teaching the driving agent through a terminal."""

from __future__ import annotations

import json
import os
import pty
import re
import select
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from torchcbl.cli import main
from torchcbl.session import load_records

BIN = Path(sys.executable).parent / "torchcbl"


@pytest.mark.parametrize("command", ["reproduce", "evaluate", "replay", "plot", "teach"])
def test_every_command_explains_itself(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: torchcbl " + command)
    assert len(out.splitlines()) > 4


def test_plot_refuses_a_directory_without_results(tmp_path):
    with pytest.raises(SystemExit, match="results.json"):
        main(["plot", str(tmp_path)])


_LINE = re.compile(r"lane: \S+ \((\d)\); nearest car: (.*)")


def _person(screen: str) -> str:
    """A careful driver who only reads the text view: leave a lane with a car close ahead,
    preferring to pass on the left; otherwise keep the lane."""
    lane_s, cars = _LINE.findall(screen.replace("\r", ""))[-1]
    lane = int(lane_s)
    dist = {1: None, 2: None, 3: None}
    for part in cars.split(", "):
        name, _, value = part.partition(" ")
        idx = {"right": 1, "middle": 2, "left": 3}[name]
        dist[idx] = None if value == "none" else float(value.split()[0])

    def clear(target: int) -> bool:
        d = dist.get(target)
        return target in (0, 4) or d is None or not -8.0 <= d <= 20.0

    ahead = dist.get(lane)
    if ahead is not None and 0.0 <= ahead <= 15.0:
        if lane < 4 and clear(lane + 1):
            return "a"
        if lane > 0 and clear(lane - 1):
            return "d"
    return "w"


def test_a_person_teaches_the_driving_agent_from_a_terminal_and_it_asks_less(tmp_path):
    """`torchcbl teach driving` in a real pseudo-terminal, answered key by key from the screen."""
    run_dir = tmp_path / "session"
    master, slave = pty.openpty()
    env = {**os.environ, "TERM": "dumb", "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(
        [str(BIN), "teach", "driving", "--run-dir", str(run_dir), "--steps", "800"]
        + ["--skip-noninteractive", "--seed", "3"],
        stdin=slave,
        stdout=slave,
        stderr=slave,
        env=env,
        start_new_session=True,
    )
    os.close(slave)
    screen, answered, deadline = "", 0, time.monotonic() + 240
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 1.0)
            if ready:
                try:
                    chunk = os.read(master, 65536).decode(errors="replace")
                except OSError:  # the child closed the terminal
                    break
                screen += chunk
                if screen.rstrip().endswith("action?"):
                    os.write(master, _person(screen).encode())
                    answered += 1
                    screen = screen[-2000:]
            elif proc.poll() is not None:
                break
        assert proc.wait(timeout=30) == 0, screen[-2000:]
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(master)
    records = load_records(run_dir)
    assert len(records) == 800
    asked = [r.teacher_action is not None for r in records]
    assert sum(asked) == answered  # every request reached the person, and only those
    per_100 = [sum(asked[i : i + 100]) for i in range(0, 800, 100)]
    assert per_100[0] >= 90, per_100  # at first it asks nearly every step
    # and then less often: over the second half it asks on average at most 80% as often as
    # over the first 200 steps (seen: [99, 77, 57, 69, 64, 31, 73, 61] requests per 100 steps)
    assert np.mean(per_100[4:]) < 0.8 * np.mean(per_100[:2]), per_100
    assert "saved in" in screen


def test_reproduce_corridor_writes_a_summary_then_plot_and_evaluate_read_it(tmp_path, capsys):
    out = tmp_path / "runs"
    argv = ["reproduce", "corridor", "--seeds", "2", "--workers", "1", "--no-progress"]
    assert main([*argv, "--out", str(out)]) == 0
    summary = (out / "summary.md").read_text()
    assert "## corridor" in summary and "demonstrations in all" in summary
    results = out / "corridor" / "results.json"
    assert results.exists() and (out / "corridor" / "figure3.png").exists()
    # plot redraws from the run directory alone
    (out / "corridor" / "figure4.png").unlink()
    assert main(["plot", str(out / "corridor")]) == 0
    assert (out / "corridor" / "figure4.png").stat().st_size > 1000
    # evaluate a saved policy (a teaching session directory)
    capsys.readouterr()
    session = out / "corridor" / "sessions" / "seed0"
    assert main(["evaluate", str(session), "--domain", "corridor", "--steps", "60"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["steps"] == 60 and report["circuits_clean"] == report["circuits_completed"] >= 1


def test_reproduce_never_overwrites_a_run_directory(tmp_path):
    from torchcbl.cli import _fresh_dir

    first = _fresh_dir(tmp_path / "r")
    (first / "results.json").write_text("{}")
    second = _fresh_dir(tmp_path / "r")
    assert first == tmp_path / "r" and second == tmp_path / "r-2" and second.is_dir()
    assert (first / "results.json").read_text() == "{}"


def test_replay_lists_episodes_and_exports_one_to_gif_and_fcd(tmp_path, capsys):
    import sumolib

    from sumo_scenarios.env import DrivingEnv
    from sumo_scenarios.replay import EpisodeRecorder, save_records

    env = EpisodeRecorder(DrivingEnv(scenario="eval", max_episode_steps=30), label="demo/a")
    try:
        for seed, label in ((0, "demo/a"), (1, "demo/b")):
            env.label = label
            env.reset(seed=seed)
            for t in range(30):
                env.step(1 if t == 5 else 0)
    finally:
        env.close()
    path = tmp_path / "episodes.json"
    save_records(env.episodes, path)
    assert main(["replay", str(path), "--list"]) == 0
    assert "demo/b" in capsys.readouterr().out
    assert main(["replay", str(path), "--label", "demo/b", "--max-frames", "8"]) == 0
    gif, fcd = tmp_path / "episodes-1.gif", tmp_path / "episodes-1.fcd.xml"
    assert gif.stat().st_size > 1000
    steps = list(sumolib.xml.parse(str(fcd), "timestep"))
    assert len(steps) >= 30 and any(v.id == "ego" for v in steps[-1].vehicle)
    with pytest.raises(SystemExit, match="--list"):
        main(["replay", str(path), "--episode", "7"])
