"""The bench scripts as a user runs them: ``python bench/bench_X.py ...`` from the repository."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(script: str, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, str(ROOT / "bench" / script), *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=120,
    )


@pytest.mark.parametrize(
    ("script", "args", "flag"),
    [
        ("bench_corridor.py", ["--repeats", "0"], "--repeats"),
        ("bench_corridor.py", ["--actions", "0"], "--actions"),
        ("bench_driving.py", ["--demos", "0"], "--demos"),
        ("bench_driving.py", ["--steps", "-5"], "--steps"),
        ("bench_kill_resume.py", ["--kills", "0"], "--kills"),
        ("bench_loop.py", ["--steps", "0"], "--steps"),
        ("bench_gmm.py", ["--repeats", "0"], "--repeats"),
        ("bench_refit.py", ["--n", "0"], "--n"),
        ("bench_gmm_device.py", ["--rows", "-3"], "--rows"),
    ],
)
def test_a_count_below_one_is_a_usage_error(script, args, flag):
    # Before, bench_corridor --repeats 0 died in max() of an empty list, bench_loop --steps 0
    # in a division by zero, bench_driving --demos 0 in np.stack, bench_kill_resume --kills 0
    # with IncompatibleRunDirError; bench_corridor --actions 0 and bench_driving --steps 0
    # printed a table of zeros and exited 0. And the error is one line, as the torchcbl
    # command's: before, argparse's usage block (one to three lines) came first.
    done = _run(script, *args)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert "Traceback" not in done.stderr, done.stderr
    assert done.stdout == ""
    (line,) = done.stderr.strip().splitlines()
    assert f"{script}: error: {flag}: expected an int >= 1, got {args[1]}" in line, line
    assert line.endswith(f"see {script} --help"), line


def test_bench_refit_refuses_a_stream_it_does_not_know():
    # Before, any name but "drift" ran the shuffled stream and labelled its row with the name
    # given: --streams drfit printed iid figures as "drfit" and exited 0.
    done = _run("bench_refit.py", "--sections", "long", "--n", "50", "--streams", "iid,drfit")
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert done.stdout == "" and "Traceback" not in done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert "error: --streams: expected some of ['drift', 'iid'], got 'iid,drfit'" in last


def test_bench_refit_ends_with_strict_json_when_an_action_has_no_point():
    # Before, a session too short for every action to have a point (--n 2 over 3 actions)
    # wrote NaN into the last line, which is no JSON (json.loads takes it only leniently).
    done = _run("bench_refit.py", "--sections", "long", "--n", "2", "--full-every", "2")
    assert done.returncode == 0, done.stderr

    def refuse(name: str) -> None:
        raise AssertionError(f"{name} in the JSON line")

    out = json.loads(done.stdout.strip().splitlines()[-1], parse_constant=refuse)
    assert None in out["long"][0]["mean_ll_full"]


def test_bench_gmm_device_names_the_case_it_does_not_know():
    # Before, any bad argument (--repeats 0, --rows -3, --cases a,d) printed the same
    # "error: --repeats and --rows must be >= 1, --cases from [...]": neither which flag
    # nor what was given. Checked before the CUDA device, so this runs without a GPU.
    done = _run("bench_gmm_device.py", "--cases", "a,d")
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert done.stdout == "" and "Traceback" not in done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert "error: --cases: expected some of ['a', 'b', 'c'], got 'a,d'" in last, done.stderr


@pytest.mark.parametrize("script", sorted(p.name for p in (ROOT / "bench").glob("bench_*.py")))
def test_help_says_what_every_flag_is_and_its_default(script):
    # Before, --help showed the flags of six of the seven scripts bare (--cases CASES,
    # --sections SECTIONS, ...: neither what they take nor their defaults; bench_driving's had
    # a text but no default), and only the first line of each docstring, not the one that
    # lists the cases and sections.
    done = _run(script, "--help")
    assert done.returncode == 0, done.stderr
    usage, _, options = done.stdout.partition("options:")
    flags = re.findall(r"\[(--[a-z-]+) [^]]", usage)  # the flags that take a value
    assert flags, usage
    blocks = re.split(r"\n  (?=-)", options)
    for flag in flags:
        text = " ".join(next(b for b in blocks if b.startswith(flag)).split())
        assert "default" in text, (flag, text)
    assert "Usage: " in usage  # the whole docstring, not its first line
