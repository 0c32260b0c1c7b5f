"""The ``.sumocfg`` written beside a replay's FCD replays the episode in SUMO alone.

Oracle: the FCD the episode itself wrote through libsumo. ``sumo -c`` (the command-line SUMO
of the eclipse-sumo package, no Python in the loop) must reproduce every recorded vehicle's
x, y, lane and lane position EXACTLY as written (both files at SUMO's default 2 decimals; the
replay input is the recorded file, so there is no rounding to tolerate), report no error and
no teleport, and show nothing else but, for each car the episode removed, one step at the end
of the road (where SUMO lets it leave).
"""

from __future__ import annotations

import dataclasses
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from sumo_scenarios.env import DrivingEnv
from sumo_scenarios.expert import ScriptedExpert
from sumo_scenarios.replay import EpisodeRecorder, export_fcd, write_sumocfg
from sumo_scenarios.sim import libsumo_lane_length_from_net

_STEPS = 120


def _fcd(path: Path) -> dict[tuple[str, str], dict[str, str]]:
    out = {}
    for ts in ET.parse(path).getroot().iter("timestep"):
        for v in ts.iter("vehicle"):
            out[(ts.get("time"), v.get("id"))] = dict(v.attrib)
    return out


@pytest.fixture(scope="module")
def episode(tmp_path_factory):
    env = EpisodeRecorder(DrivingEnv(scenario="train", max_episode_steps=_STEPS), label="t")
    expert = ScriptedExpert(seed=3)
    try:
        obs, info = env.reset(seed=5)
        for _ in range(_STEPS):
            obs, _, _, _, info = env.step(expert(obs, info))
    finally:
        env.close()
    (rec,) = env.episodes
    d = tmp_path_factory.mktemp("replay")
    fcd = export_fcd(rec, d / "ep.fcd.xml")
    return rec, fcd, d


def test_sumo_alone_replays_the_recorded_positions_exactly(episode):
    rec, fcd, d = episode
    cfg = write_sumocfg(rec, fcd, d / "ep.sumocfg")
    sumo = Path(sys.executable).with_name("sumo")
    out = subprocess.run(
        [str(sumo), "-c", str(cfg), "--statistic-output", str(d / "stats.xml")],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        cwd="/",  # the configuration's relative file names resolve beside it, not in the cwd
    )
    log = (out.stdout + out.stderr).lower()
    assert out.returncode == 0, out.stderr
    assert "error" not in log and "teleport" not in log, log
    teleports = ET.parse(d / "stats.xml").getroot().find("teleports")
    assert teleports is not None and teleports.get("total") == "0"

    recorded, rerun = _fcd(fcd), _fcd(d / "ep.rerun.xml")
    times = sorted({t for t, _ in recorded}, key=float)
    assert len(times) == _STEPS
    ego_lanes = {a["lane"] for (t, vid), a in recorded.items() if vid == "ego"}
    assert len(ego_lanes) >= 2, "the episode should hold a lane change of the ego"
    missing = set(recorded) - set(rerun)
    assert not missing, sorted(missing)[:5]
    first_seen: dict[str, str] = {}
    last_seen: dict[str, str] = {}
    for t, vid in sorted(recorded, key=lambda k: float(k[0])):
        first_seen.setdefault(vid, t)
        last_seen[vid] = t
    for key, a in recorded.items():
        b = rerun[key]
        for field in ("x", "y", "lane", "pos", "angle"):
            assert a[field] == b[field], (key, field, a[field], b[field])
        if first_seen[key[1]] != key[0]:  # a car enters at a speed of SUMO's choosing
            assert a["speed"] == b["speed"], (key, a["speed"], b["speed"])

    # the only extra entries: each car the episode removed, one step later, at the road end
    extra = set(rerun) - set(recorded)
    removed = {vid for vid, t in last_seen.items() if t != times[-1]}
    assert removed, "the episode should remove (recycle) at least one car"
    assert {vid for _, vid in extra} == removed and len(extra) == len(removed)
    road_end = f"{libsumo_lane_length_from_net():.2f}"
    for t, vid in extra:
        assert times.index(t) == times.index(last_seen[vid]) + 1
        assert rerun[(t, vid)]["pos"] == road_end


def test_sumocfg_needs_the_exported_fcd(episode, tmp_path):
    rec, _, _ = episode
    with pytest.raises(FileNotFoundError, match="export_fcd"):
        write_sumocfg(rec, tmp_path / "absent.fcd.xml", tmp_path / "x.sumocfg")


def test_sumocfg_is_well_formed_whatever_the_label_and_file_names(episode, tmp_path):
    # a label or file name holding "--" ended the configuration's XML comment early and one
    # holding "&" broke an attribute: SUMO refused the file ("'--' sequence is illegal in
    # comment", "Could not load configuration")
    rec, fcd, _ = episode
    rec = dataclasses.replace(rec, label="seed0--arm_a & <b>")
    odd = tmp_path / "R&D--ep.fcd.xml"
    shutil.copy(fcd, odd)
    cfg = write_sumocfg(rec, odd, tmp_path / "R&D--ep.sumocfg")
    ET.parse(cfg)  # well-formed XML
    sumo = Path(sys.executable).with_name("sumo")
    out = subprocess.run(
        [str(sumo), "-c", str(cfg)], capture_output=True, text=True, timeout=120, check=False
    )
    assert out.returncode == 0, out.stderr
    assert _fcd(tmp_path / "R&D--ep.rerun.xml").keys() >= _fcd(odd).keys()


def test_sumocfg_is_utf8_as_it_declares_whatever_the_locale(episode, tmp_path, ascii_locale):
    """Its XML declaration says UTF-8, but it was written in the locale's encoding: under
    LC_ALL=C a label beyond ASCII raised UnicodeEncodeError (after the replay input was
    written), and under a latin-1 locale the file was latin-1."""
    rec, fcd, _ = episode
    rec = dataclasses.replace(rec, label="Straße ± 1")
    cfg = write_sumocfg(rec, fcd, tmp_path / "ep.sumocfg")
    assert "Straße ± 1" in cfg.read_bytes().decode("utf-8")
    ET.parse(cfg)  # as the declaration says


def test_sumocfg_names_the_replay_input_with_the_option_every_admitted_sumo_reads(
    episode, tmp_path
):
    """SUMO 1.28 renamed ``device.fcd-replay.file`` to ``device.fcd-replay.files`` and still
    reads the old name; SUMO 1.20-1.27 (1.22-1.27 an admitted eclipse-sumo, any of them a
    sumo-gui of the user's own) know only the old one. A configuration naming the new one made their
    ``sumo -c`` fail with "No option with the name 'device.fcd-replay.files' exists"."""
    rec, fcd, _ = episode
    cfg = ET.parse(write_sumocfg(rec, fcd, tmp_path / "ep.sumocfg")).getroot()
    (device,) = cfg.iter("fcd_replay_device")
    assert [option.tag for option in device] == ["device.fcd-replay.file"]
    assert Path(device[0].get("value")).name == "ep.replay.xml"


def test_a_file_name_with_a_comma_is_refused_before_anything_is_written(episode, tmp_path):
    """SUMO splits a .sumocfg's file lists at commas: for an FCD named 'seed0,arm_a.fcd.xml' a
    configuration naming 'seed0,arm_a.replay.xml' was written, and `sumo -c` failed with
    "Cannot read file 'seed0'". Now write_sumocfg says so and writes nothing, and torchcbl
    replay --fcd refuses such a name in one line before the replay."""
    from sumo_scenarios.replay import save_records

    rec, fcd, _ = episode
    odd = tmp_path / "seed0,arm_a.fcd.xml"
    shutil.copy(fcd, odd)
    with pytest.raises(ValueError, match="comma.*give the FCD a name without a comma"):
        write_sumocfg(rec, odd, tmp_path / "ep.sumocfg")
    assert sorted(p.name for p in tmp_path.iterdir()) == [odd.name]

    episodes = tmp_path / "episodes.json"
    save_records([dataclasses.replace(rec, actions=rec.actions[:3])], episodes)
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "torchcbl",
            "replay",
            str(episodes),
            "--fcd",
            str(tmp_path / "a,b.xml"),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert out.returncode == 2 and out.stdout == "", out
    assert out.stderr.count("\n") == 1 and "without a comma" in out.stderr, out.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([odd.name, episodes.name])


def test_replay_from_a_package_under_a_comma_path_refuses_before_writing(tmp_path):
    """The package installed under a path with a comma ("OneDrive - Acme, Inc/..."): the
    .sumocfg would name the shipped network and vehicle types by that path, which SUMO splits
    at the comma. torchcbl replay wrote the episode's FCD (and printed two lines) before
    refusing the .sumocfg; now it refuses in one line on stderr and writes nothing, naming the
    package's path as the cause (not the FCD's name)."""
    import sumo_scenarios
    from sumo_scenarios.replay import EpisodeRecord, save_records
    from sumo_scenarios.scenarios import get_scenario
    from sumo_scenarios.sim import SimConfig

    site = tmp_path / "Acme, Inc"
    shutil.copytree(
        Path(sumo_scenarios.__file__).parent,
        site / "sumo_scenarios",
        ignore=shutil.ignore_patterns("__pycache__"),
    )
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    episodes = out_dir / "episodes.json"
    save_records([EpisodeRecord(get_scenario("light"), SimConfig(), 0, 2, (0, 1, 0))], episodes)
    root = Path(__file__).resolve().parents[1]  # torchcbl itself from this checkout
    out = subprocess.run(
        [sys.executable, "-m", "torchcbl", "replay", str(episodes)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        env={"PYTHONPATH": f"{site}:{root}", "PATH": "/usr/bin:/bin"},
        cwd=tmp_path,
    )
    assert out.returncode == 2 and out.stdout == "", out
    assert out.stderr.count("\n") == 1, out.stderr
    assert "Acme, Inc" in out.stderr and "move the package" in out.stderr, out.stderr
    assert "give the FCD a name" not in out.stderr, out.stderr
    assert [p.name for p in out_dir.iterdir()] == [episodes.name]


def test_sumocfg_refuses_a_file_that_is_not_the_records_fcd(episode, tmp_path):
    """write_sumocfg given a file that is not an FCD (a ParseError from the XML reader, or a
    .sumocfg written for any XML), or the FCD of an episode of another length or step length
    (a .sumocfg written that replays it at the wrong times and stops at the wrong end): a
    ValueError naming the file and what was expected, and nothing written."""
    rec, fcd, _ = episode
    text = tmp_path / "notes.txt"
    text.write_text("not xml")
    other = tmp_path / "routes.xml"
    other.write_text("<routes/>")
    shorter = tmp_path / "short.fcd.xml"
    root = ET.parse(fcd).getroot()
    for ts in root.findall("timestep")[10:]:
        root.remove(ts)
    ET.ElementTree(root).write(shorter)
    before = sorted(p.name for p in tmp_path.iterdir())
    for path, says in [
        (text, r"notes\.txt is not XML"),
        (other, r"routes\.xml is not an FCD file"),
        (shorter, r"short\.fcd\.xml holds 10 timesteps.*120 steps of 0\.25 s"),
    ]:
        with pytest.raises(ValueError, match=says):
            write_sumocfg(rec, path, tmp_path / "ep.sumocfg")
    slower = dataclasses.replace(rec, sim=dataclasses.replace(rec.sim, step_length_s=0.1))
    with pytest.raises(ValueError, match=r"ep\.fcd\.xml holds 120 timesteps 0.25 s apart"):
        write_sumocfg(slower, fcd, tmp_path / "ep.sumocfg")
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_sumocfg_path_is_checked_before_anything_is_written(episode, tmp_path):
    """write_sumocfg to a directory, or into one that does not exist: the replay input beside
    the FCD was written first, and then open() failed (IsADirectoryError, FileNotFoundError).
    Now a ValueError says what to give, and nothing is written."""
    rec, fcd, _ = episode
    odd = tmp_path / "ep.fcd.xml"
    shutil.copy(fcd, odd)
    for path, says in [
        (tmp_path, "is a directory; give the .sumocfg's file path"),
        (tmp_path / "missing" / "ep.sumocfg", "does not exist; create it first"),
    ]:
        with pytest.raises(ValueError, match=says):
            write_sumocfg(rec, odd, path)
        assert [p.name for p in tmp_path.iterdir()] == [odd.name]
