"""The command line: help texts, and a person teaching the driving agent through a terminal."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import pty
import re
import select
import shutil
import subprocess
import sys
import termios
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from sumo_scenarios.experiment import DrivingExperimentConfig
from torchcbl.cli import main
from torchcbl.session import load_records

BIN = Path(sys.executable).parent / "torchcbl"


@pytest.mark.parametrize("command", ["reproduce", "evaluate", "replay", "plot", "show", "teach"])
def test_every_command_explains_itself(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: torchcbl " + command)
    assert len(out.splitlines()) > 4


def _help_of(command: str, capsys) -> str:
    """``torchcbl COMMAND --help`` as one line (argparse wraps it at the terminal's width)."""
    with pytest.raises(SystemExit):
        main([command, "--help"])
    return " ".join(capsys.readouterr().out.split())


def test_teach_help_says_what_the_status_line_counts(capsys):
    """teach's status line ("prediction accuracy 85% | autonomy 40%") was explained nowhere a
    command-line user looks: over what window the accuracy is taken, the target that ends
    the non-interactive phase, what autonomy measures. teach --help says it, each domain's
    window and target as teach sets them, and so does README."""
    from torchcbl import cli

    said = _help_of("teach", capsys)
    readme = " ".join((Path(__file__).parents[1] / "README.md").read_text().split())
    for text in (said, readme):
        assert "prediction accuracy (the share of your last W demonstrations" in text, text
        assert "autonomy (the share of the last W confident-phase steps" in text, text
        for domain, (*_, settings, _) in cli._TEACH.items():
            window, target = settings["accuracy_window"], 100 * settings["target_accuracy"]
            assert f"{domain} W = {window} and {target:g}%" in text, (domain, text)


def test_every_field_evaluate_prints_is_defined_in_its_help_and_the_readme(
    tmp_path, monkeypatch, capsys
):
    """evaluate's JSON (corridor: circuits_completed, circuits_clean, wall_contacts; driving:
    collision_pct, lanes) was defined neither in evaluate --help nor in README: whether a
    clean circuit is a success, whether wall_contacts counts steps or touches, whether
    collision_pct is a percent or a share. Each field of both reports is defined in both."""
    import sumo_scenarios.human

    class Person:
        def __call__(self, observation, info):
            return 0

        def set_status(self, text):
            pass

    _scripted_corridor_person(monkeypatch)
    monkeypatch.setattr(sumo_scenarios.human, "make_teacher", lambda **kw: Person())
    keys = set()
    for domain in ("corridor", "driving"):
        run = tmp_path / domain
        assert main(["teach", domain, "--run-dir", str(run), "--steps", "10"]) == 0
        capsys.readouterr()
        assert main(["evaluate", str(run), "--steps", "5"]) == 0, capsys.readouterr().err
        keys |= set(json.loads(capsys.readouterr().out))
    said = _help_of("evaluate", capsys)
    readme = " ".join((Path(__file__).parents[1] / "README.md").read_text().split())
    for key in sorted(keys):
        assert f"{key} (" in said, (key, said)
        assert f"`{key}` (" in readme, key
    for text in (said.replace("`", ""), readme.replace("`", "")):
        assert "circuits_clean (those of them without a wall contact: each a success)" in text
        assert "wall_contacts (the steps on which the robot touched a wall" in text, text
        assert "collision_pct (the percentage, 0 to 100, of timesteps" in text, text
        assert "lanes (the fraction, 0 to 1, of timesteps in each lane" in text, text


def test_version_names_torchcbl_and_torch(capsys):
    """`torchcbl --version` (and `python -m torchcbl --version`) prints the package's version
    with torch's and Python's, exit 0; it said "error: the following arguments are required:
    command". It reads torch's version from its metadata, so torch is not imported for it."""
    import importlib.metadata
    import platform

    import torchcbl

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    expected = (
        f"torchcbl {torchcbl.__version__} (torch {importlib.metadata.version('torch')}, "
        f"Python {platform.python_version()})"
    )
    assert capsys.readouterr().out == expected + "\n"
    code = "import sys, runpy; sys.argv = ['torchcbl', '--version']\n"
    code += "try:\n    runpy.run_module('torchcbl', run_name='__main__')\n"
    code += "except SystemExit as e:\n    print(e.code, 'torch' in sys.modules)\n"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.stdout == expected + "\n0 False\n", done
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "--version" in capsys.readouterr().out


def test_plot_refuses_a_directory_without_results(tmp_path, capsys):
    assert main(["plot", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("torchcbl plot: error: ") and "results.json" in err


def test_plot_of_a_benchmark_directory_says_where_its_plot_is(tmp_path, capsys):
    """`torchcbl plot OUT` on a torchcbl benchmark's OUT said "results.json names domain
    None; expected one of ['corridor', 'driving']", as if the file were damaged."""
    out = tmp_path / "bench"
    out.mkdir()
    results = {"table": {}, "sweep": {}, "envs": [], "strategies": [], "cells": []}
    (out / "results.json").write_text(json.dumps(results))
    assert main(["plot", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "None" not in err
    assert "torchcbl benchmark" in err and str(out / "learning_curves.png") in err
    assert "left no plot" in err  # a sweep run with plots=False: none to point at
    (out / "learning_curves.png").write_bytes(b"")
    assert main(["plot", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"whose plot is {out / 'learning_curves.png'}" in err and "no plot" not in err


def test_plot_of_a_folder_names_only_the_reproductions_run_directories_in_it(tmp_path, capsys):
    """`torchcbl plot /tmp` took every */results.json below for a reproduction's run directory:
    it said "/tmp holds one run directory per domain" and listed a benchmark's folder and
    unrelated ones. Only a results.json naming a domain, as torchcbl reproduce writes it, is
    listed; with none, the error says what RUN_DIR should be."""
    bench = tmp_path / "bench"
    other = tmp_path / "other"
    broken = tmp_path / "broken"
    for folder in (bench, other, broken):
        folder.mkdir()
    sweep = {"table": {}, "sweep": {}, "envs": [], "strategies": [], "cells": []}
    (bench / "results.json").write_text(json.dumps(sweep))
    (other / "results.json").write_text(json.dumps({"accuracy": 0.9}))
    (broken / "results.json").write_bytes(b"\xff not json")
    assert main(["plot", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert str(bench) not in err and str(other) not in err and str(broken) not in err, err
    assert "expected a run directory written by torchcbl reproduce" in err, err
    corridor = tmp_path / "corridor"
    corridor.mkdir()
    (corridor / "results.json").write_text(json.dumps({"domain": "corridor"}))
    assert main(["plot", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert str(corridor) in err and "pass one of them" in err, err
    assert str(bench) not in err and str(other) not in err and str(broken) not in err, err


def _arguments(parser):
    import argparse

    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, command in sub.choices.items():
        for action in command._actions:
            if not isinstance(action, argparse._HelpAction):
                yield name, action


def test_every_argument_and_option_has_help_text():
    from torchcbl.cli import _parser

    missing = [
        f"{name} {action.option_strings or action.dest}"
        for name, action in _arguments(_parser())
        if not (action.help or "").strip()
    ]
    assert not missing


# What the README says of its command block: which command prints what
README_CLI_INTRO = (
    "The command line (`torchcbl --help` lists the commands; `torchcbl COMMAND --help`, e.g.\n"
    "`torchcbl teach --help`, prints a command's options, as below):"
)


def test_the_readme_says_which_help_prints_the_options_of_its_command_block(capsys):
    """The README introduced its command block, every command's options, as "The command line
    (`torchcbl --help`):", which prints only the list of commands."""
    with pytest.raises(SystemExit):
        main(["--help"])
    top = capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["teach", "--help"])
    teach = capsys.readouterr().out
    assert "--run-dir" not in top and "{reproduce,evaluate" in top and "--run-dir" in teach
    assert README_CLI_INTRO in (Path(__file__).parents[1] / "README.md").read_text()


def _readme_command_lines() -> list[str]:
    """The README's command block, one line per command (continuation lines joined)."""
    readme = (Path(__file__).parents[1] / "README.md").read_text()
    block = readme.split(README_CLI_INTRO, 1)[1].split("```")[1]
    lines: list[str] = []
    for ln in block.splitlines():  # a command's continuation lines are indented
        if ln.startswith("torchcbl "):
            lines.append(ln)
        elif ln.strip() and lines:
            lines[-1] += " " + ln.strip()
    return lines


def test_the_readme_command_lines_use_the_names_of_the_help(capsys):
    """Every placeholder (SESSION_DIR, N, ...) and option of the README's command block appears,
    spelled the same, in that command's --help, and every option of the help in the block; the
    options of torchcbl itself (--version), on lines of their own, as `torchcbl --help` has them."""
    lines = _readme_command_lines()
    own = [ln for ln in lines if ln.split()[1].startswith("-")]
    with pytest.raises(SystemExit):
        main(["--help"])
    usage = " ".join(capsys.readouterr().out.split("\n\n")[0].split())
    shown = set(re.findall(r"--[a-z-]+", " ".join(own)))
    assert shown == set(re.findall(r"--[a-z-]+", usage)) - {"--help"} == {"--version"}, own
    lines = [ln for ln in lines if ln not in own]
    assert {ln.split()[1] for ln in lines} == {
        "reproduce",
        "evaluate",
        "replay",
        "plot",
        "show",
        "teach",
        "benchmark",
    }
    for line in lines:
        command = line.split()[1]
        with pytest.raises(SystemExit):
            main([command, "--help"])
        usage = " ".join(capsys.readouterr().out.split("\n\n")[0].split())
        for token in re.findall(r"--[a-z-]+|\b[A-Z][A-Z_]*(?:\.json|\.gif|\.xml)?\b", line):
            assert token in usage, (command, token, usage)
        for option in set(re.findall(r"--[a-z-]+", usage)) - {"--help"}:
            assert option in line, (command, option, "missing from the README's block")


def test_each_readme_placeholder_means_what_the_readme_says(capsys):
    """The README defines RUN_DIR as a run directory of torchcbl reproduce and SESSION_DIR as a
    teaching session. replay's directory is a driving teaching session (a reproduce run
    directory is refused), so it is a SESSION_DIR, in the block and in replay's --help; show
    takes a session (or a folder of them, DIR); only plot takes a RUN_DIR."""
    readme = (Path(__file__).parents[1] / "README.md").read_text()
    assert "`RUN_DIR` is a run directory of\n`torchcbl reproduce`" in readme
    assert "`SESSION_DIR` is a teaching session" in readme
    lines = {ln.split()[1]: ln for ln in _readme_command_lines()}
    assert {c for c, ln in lines.items() if "RUN_DIR" in ln} == {"plot"}
    assert {c for c, ln in lines.items() if "SESSION_DIR" in ln} == {"evaluate", "replay", "show"}
    with pytest.raises(SystemExit):
        main(["replay", "--help"])
    help_text = capsys.readouterr().out
    assert "RUN_DIR" not in help_text and "EPISODES.json|SESSION_DIR" in help_text


def _tiny_corridor(domain, module, args):
    """The corridor experiment at a size that runs in seconds (exact motion, no CBA arm, 2
    evaluation circuits, 300 PS steps), in place of the CLI's ``_experiment_config``."""
    from corridor.baseline import PrioritizedSweepingConfig
    from corridor.experiment import CorridorExperimentConfig

    return CorridorExperimentConfig.exact_motion(
        seeds=tuple(range(args.seeds)),
        cba=False,
        eval_circuits=2,
        ps=PrioritizedSweepingConfig(max_steps=300),
    )


@pytest.fixture(scope="module")
def corridor_run(tmp_path_factory):
    """`torchcbl reproduce corridor` into a run directory holding two sessions, at a size that
    runs in seconds (:func:`_tiny_corridor`: the quick reproduction's two seeds took half a
    minute, which the CLI's readers do not need)."""
    import torchcbl.cli as cli

    out = tmp_path_factory.mktemp("cli") / "runs"
    argv = ["reproduce", "corridor", "--seeds", "2", "--workers", "1", "--no-progress"]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cli, "_experiment_config", _tiny_corridor)
        assert main([*argv, "--out", str(out)]) == 0
    return out


def _stopped_before_results(run: Path, out: Path) -> Path:
    """``out`` holding a copy of the corridor run of ``run`` (:func:`corridor_run`) as a run
    stopped after its seeds finished, before its summary, figures and results.json."""
    kept = shutil.ignore_patterns("results.json", "summary.txt", "*.png")
    shutil.copytree(run / "corridor", out / "corridor", ignore=kept)
    return out


def test_reproduce_writes_its_files_in_utf8_whatever_the_locale(
    corridor_run, tmp_path, monkeypatch, ascii_locale
):
    """Under LC_ALL=C (an ASCII locale) `torchcbl reproduce corridor` computed every seed, then
    failed writing summary.txt ('±': UnicodeEncodeError) and wrote no results.json; under
    latin-1 the summary came out in latin-1. Its files are UTF-8 whatever the locale."""
    import torchcbl.cli as cli

    out = _stopped_before_results(corridor_run, tmp_path / "runs")
    monkeypatch.setattr(cli, "_experiment_config", _tiny_corridor)
    argv = ["reproduce", "corridor", "--seeds", "2", "--workers", "1", "--no-progress"]
    assert main([*argv, "--resume", "--out", str(out)]) == 0
    summary = (out / "corridor" / "summary.txt").read_bytes().decode("utf-8")
    assert "±" in summary
    assert summary == (corridor_run / "corridor" / "summary.txt").read_text(encoding="utf-8")
    assert (out / "corridor" / "results.json").is_file()


def _session_without_labels(run_dir: Path) -> Path:
    """A corridor session that was started and closed before its first demonstration."""
    from corridor.env import CorridorEnv
    from torchcbl import ConfidentTeacher

    ConfidentTeacher(CorridorEnv(), lambda o, i: 0, run_dir=run_dir).close()
    return run_dir


def _user_mistakes(run: Path, tmp: Path) -> list[list[str]]:
    session = run / "corridor" / "sessions" / "seed0"
    not_json = tmp / "notes.md"
    not_json.write_text("# notes\n")
    empty = tmp / "empty"
    empty.mkdir()
    partial = tmp / "partial"  # a results.json without what the figures need
    partial.mkdir()
    (partial / "results.json").write_text('{"domain": "corridor"}')
    alone = tmp / "alone"  # a corridor results.json copied without its sessions
    alone.mkdir()
    (alone / "results.json").write_text((run / "corridor" / "results.json").read_text())
    return [
        ["evaluate", str(empty), "--domain", "corridor"],  # a directory, but no session
        ["evaluate", str(_session_without_labels(tmp / "unlabelled"))],
        ["evaluate", str(run / "corridor"), "--domain", "corridor"],  # a run directory
        ["evaluate", str(tmp / "nonexistent"), "--domain", "corridor"],
        ["evaluate", str(session), "--domain", "driving"],  # a session of the other domain
        ["evaluate", str(session), "--steps", "-5"],
        ["evaluate", str(session), "--steps", "many"],
        ["replay", str(tmp / "nonexistent.json")],
        ["replay", str(not_json)],  # not JSON
        ["replay", str(run / "corridor" / "results.json")],  # JSON, but not episodes
        ["replay", str(tmp)],  # a directory
        ["reproduce", "corridor", "--seeds", "0", "--out", str(tmp / "X")],
        # it ended in "MemoryError" with exit 1 (a tuple of 1e11 seeds)
        ["reproduce", "corridor", "--seeds", "99999999999", "--out", str(tmp / "X")],
        ["reproduce", "corridor", "--workers", "0", "--out", str(tmp / "X")],
        ["reproduce", "corridor", "--seeds", "1", "--out", str(not_json / "X")],  # under a file
        ["reproduce", "corridor", "--seeds", "1", "--out", str(not_json)],  # a file
        ["benchmark", "--quick", "--out", str(not_json)],
        ["teach", "corridor", "--run-dir", str(not_json)],  # a file
        ["teach", "corridor", "--run-dir", str(partial)],  # other files, no session
        ["teach", "corridor", "--resume", "--skip-noninteractive", "--run-dir", str(session)],
        ["plot", str(tmp / "nonexistent")],
        ["plot", str(session)],
        ["plot", str(partial)],
        ["plot", str(alone)],
        ["teach", "corridor", "--run-dir", str(session)],  # holds a session: --resume?
        ["teach", "corridor", "--seed", "-1", "--run-dir", str(tmp / "X")],
        ["teach", "driving", "--resume", "--run-dir", str(session)],
        ["teach", "corridor", "--resume", "--run-dir", str(empty)],
        ["teach", "corridor", "--resume", "--run-dir", str(session)],  # a reproduction's
        ["teach", "corridor", "--seed", str(2**64), "--run-dir", str(tmp / "X")],
        ["evaluate", str(session), "--seed", str(2**64)],
        ["replay", str(not_json), "--episode", "3", "--label", "a"],  # one or the other
        ["benchmark", "--quick", "--envs", "corridor", "--out", str(run / "corridor")],
        ["benchmark", "--gym-env", "CartPol-v1", "--teacher", "m:f", "--out", str(tmp / "X")],
        ["frobnicate"],
    ]


def test_a_users_mistakes_get_one_line_and_no_traceback(corridor_run, tmp_path, capfd, monkeypatch):
    """Each command run as a user would: exit code 2, one line on stderr that names the
    problem, nothing on stdout, no traceback, and nothing left behind. The first mistake of
    each command runs as its own process (the console script, as a user runs it); the rest
    through main() in this one (a process each took the test 20 s on 2 cores)."""
    cases = _user_mistakes(corridor_run, tmp_path)
    firsts = {argv[0]: i for i, argv in reversed(list(enumerate(cases)))}
    procs = {
        i: subprocess.Popen(
            [str(BIN), *cases[i]],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            stdin=subprocess.DEVNULL,
            env={**os.environ, "TORCHCBL_TRACEBACK": ""},
        )
        for i in firsts.values()
    }
    monkeypatch.setenv("TORCHCBL_TRACEBACK", "")
    results = []
    for i, argv in enumerate(cases):
        if i in procs:
            continue
        # (a warning, which the console script would print on stderr, and anything written
        # to the file descriptors count as output too)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                code = main(list(argv))
            except SystemExit as exc:  # argparse's own refusals
                code = exc.code
        captured = capfd.readouterr()
        err = captured.err + "".join(f"{w.category.__name__}: {w.message}\n" for w in caught)
        results.append((argv, code, captured.out, err))
    for i, proc in procs.items():
        out, err = proc.communicate(timeout=120)
        results.append((cases[i], proc.returncode, out, err))
    assert len(results) == len(cases) and len(procs) == 7
    for argv, code, out, err in results:
        assert code == 2, (argv, out, err)
        assert "Traceback" not in out + err, (argv, err)
        assert out == "", (argv, out)
        lines = err.strip().splitlines()
        assert len(lines) == 1, (argv, err)
        prog = "torchcbl" if argv[0] == "frobnicate" else f"torchcbl {argv[0]}"
        assert lines[0].startswith(f"{prog}: error: "), (argv, err)
    assert not (tmp_path / "X").exists()  # a refused reproduce leaves no directory behind


def test_a_missing_dependency_is_one_line_naming_it_and_its_install(tmp_path, monkeypatch, capsys):
    """A missing dependency gave 'error: ModuleNotFoundError: No module named ...' (exit 1),
    and where only a later part needs it (SUMO in reproduce's driving part and a benchmark's
    driving cells, after the corridor's), only once the work before was done. One line names
    the package, what needs it and how to install it (exit 2); reproduce and benchmark check
    before anything runs or is written."""
    monkeypatch.setitem(sys.modules, "libsumo", None)  # import libsumo: ModuleNotFoundError
    out, bench = tmp_path / "runs", tmp_path / "bench"
    for argv in (
        ["benchmark", "--quick", "--envs", "driving", "--workers", "1", "--out", str(bench)],
        ["reproduce", "all", "--no-progress", "--out", str(out)],
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1, err
        assert f"torchcbl {argv[0]}: error: libsumo is missing" in err
        assert "the driving domain" in err
        assert "pip install 'libsumo>=1.22' 'eclipse-sumo>=1.22' 'sumolib>=1.22'" in err
        assert "bash scripts/setup.sh" in err
    assert not out.exists() and not bench.exists()
    # where the command reaches it as it goes: the figures torchcbl plot draws
    monkeypatch.setitem(sys.modules, "matplotlib.style", None)
    run = tmp_path / "run"
    run.mkdir()
    (run / "results.json").write_text(json.dumps({"domain": "corridor", "config": {}}))
    assert main(["plot", str(run)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert "matplotlib is missing" in err and "`pip install 'matplotlib>=3.7'`" in err


def test_the_dependencies_the_cli_names_are_pyprojects_runtime_dependencies():
    """The CLI's table of dependencies (what a missing one's line names and tells to install)
    repeated pyproject.toml's without their versions, unchecked: SUMO's install line lacked
    the >=1.22 the network builder asks for. It names exactly pyproject's requirements."""
    import tomllib

    from torchcbl import cli

    pyproject = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text("utf-8"))
    required = [requirement for requirement, _ in cli._DEPENDENCIES.values()]
    assert sorted(required) == sorted(pyproject["project"]["dependencies"])
    assert all(need in cli._DEPENDENCIES for needs in cli._DOMAIN_NEEDS.values() for need in needs)


def test_an_output_directory_that_is_a_file_is_called_a_file(tmp_path, capsys):
    f = tmp_path / "afile"
    f.write_text("x")
    assert main(["benchmark", "--quick", "--envs", "corridor", "--out", str(f)]) == 2
    assert f"--out {f} cannot be a directory: it is a file;" in capsys.readouterr().err
    assert main(["benchmark", "--quick", "--envs", "corridor", "--out", str(f / "below")]) == 2
    assert f"cannot be a directory: {f} is a file;" in capsys.readouterr().err


def test_benchmark_never_writes_over_another_commands_run_directory(corridor_run, tmp_path):
    """A benchmark's --out pointed at a reproduction's run directory is refused before any
    cell runs, and the run's results.json is untouched."""
    run = corridor_run / "corridor"
    before = {p: p.read_bytes() for p in run.glob("*.json")}
    argv = ["benchmark", "--quick", "--envs", "corridor", "--strategies", "confident"]
    assert main([*argv, "--seeds", "1", "--out", str(run)]) == 2
    assert {p: p.read_bytes() for p in run.glob("*.json")} == before
    assert not (run / "cells").exists()


def test_plot_of_reproduces_out_directory_names_the_run_directories_in_it(corridor_run, capsys):
    assert main(["plot", str(corridor_run)]) == 2
    err = capsys.readouterr().err
    assert (
        "holds run directories of torchcbl reproduce" in err
        and str(corridor_run / "corridor") in err
    )


def test_plot_into_a_read_only_run_directory_is_one_line_and_exit_2(corridor_run, tmp_path, capsys):
    """A run directory where no figure can be written (a read-only mount, another user's run):
    plot drew the first figure and failed writing it, exit code 1 with the bare OSError. It is
    a usage mistake: one line that says where the figures go and how to plot, exit code 2,
    before anything is drawn."""
    import shutil

    src, ro = tmp_path / "src", tmp_path / "ro"
    shutil.copytree(corridor_run / "corridor", src)
    before = sorted(p.name for p in src.iterdir())
    if os.geteuid() != 0:
        ro = src
        ro.chmod(0o555)
    else:
        ro.mkdir()
        mount = ["mount", "--bind", str(src), str(ro)]
        if subprocess.run(mount, capture_output=True).returncode != 0:
            pytest.skip("cannot bind-mount here")
    try:
        if ro != src:
            remount = ["mount", "-o", "remount,bind,ro", str(ro)]
            if subprocess.run(remount, capture_output=True).returncode != 0:
                pytest.skip("cannot remount read-only here")
        code = main(["plot", str(ro)])
    finally:
        if ro != src:
            subprocess.run(["umount", "-l", str(ro)], capture_output=True)
        src.chmod(0o755)
    out, err = capsys.readouterr()
    assert code == 2 and out == "", err
    assert err.count("\n") == 1, err
    assert err.startswith(f"torchcbl plot: error: cannot write the figures into {ro} (")
    assert "plot the copy" in err
    assert sorted(p.name for p in src.iterdir()) == before


def test_evaluate_names_the_problem(corridor_run, tmp_path, capsys):
    """What the one line says: which sessions a run directory holds, which domain a session is
    of, what is missing."""
    session = corridor_run / "corridor" / "sessions" / "seed0"
    messages = {}
    for key, argv in {
        "run_dir": ["evaluate", str(corridor_run / "corridor")],
        "other_domain": ["evaluate", str(session), "--domain", "driving"],
        "missing": ["evaluate", str(tmp_path / "nope")],
        "replay_results": ["replay", str(corridor_run / "corridor" / "results.json")],
    }.items():
        assert main(argv) == 2
        messages[key] = capsys.readouterr().err
    assert "sessions/seed0" in messages["run_dir"] and "sessions/seed1" in messages["run_dir"]
    assert "is a corridor session" in messages["other_domain"]
    assert "--domain corridor" in messages["other_domain"]
    assert "does not exist" in messages["missing"]
    assert "not a list of recorded episodes" in messages["replay_results"]
    assert main(["evaluate", str(_session_without_labels(tmp_path / "unlabelled"))]) == 2
    assert "holds 0 demonstrations and its first fit comes at" in capsys.readouterr().err
    # a user's own env of the driving domain's shape is not taken for the driving domain
    from _toy_envs import ClusterWorld

    from torchcbl import ConfidentTeacher

    own = ClusterWorld(np.eye(4)[:3] * 5, [0, 1, 2], [1, 1, 1], episode_length=5)
    ConfidentTeacher(own, lambda o, i: own.optimal_action(o), run_dir=tmp_path / "own").close()
    assert main(["evaluate", str(tmp_path / "own")]) == 2
    err = capsys.readouterr().err
    assert "an env torchcbl does not know" in err and "4 features, 3 actions" in err
    alone = tmp_path / "alone"
    alone.mkdir()
    (alone / "results.json").write_text((corridor_run / "corridor" / "results.json").read_text())
    assert main(["plot", str(alone)]) == 2
    assert "sessions/seed0 holds no teaching session" in capsys.readouterr().err


def test_a_session_whose_checkpoints_the_file_system_fails_to_list_is_one_line_and_exit_2(
    tmp_path, capsys, monkeypatch
):
    """A corridor session without journal and writers file (read as possibly left by a
    killed creation, which its ``checkpoints/`` tells) whose ``checkpoints/`` the file system
    fails to list (an I/O error): show, evaluate and teach --resume said "error: OSError:
    [Errno 5] ..." with exit 1 (a failure of torchcbl, no word of what to do); they now say
    which folder and what failed in one line and exit 2, as for a folder this user may not
    list, and leave the session as it was."""
    import errno

    import gymnasium as gym

    import corridor  # noqa: F401 - registers the env id
    from torchcbl import ConfidentTeacher

    run = tmp_path / "run"
    ConfidentTeacher(gym.make("torchcbl/Corridor-v0"), lambda o, i: 0, run_dir=run).close()
    for name in ("steps.journal", "writers.jsonl"):
        (run / name).unlink()
    before = sorted((p.name, p.read_bytes()) for p in run.rglob("*") if p.is_file())
    real_iterdir = Path.iterdir

    def iterdir(self: Path):
        if self == run / "checkpoints":
            raise OSError(errno.EIO, os.strerror(errno.EIO), str(self))
        return real_iterdir(self)

    monkeypatch.setattr(Path, "iterdir", iterdir)
    for argv in (
        ["show", str(run)],
        ["evaluate", str(run)],
        ["teach", "corridor", "--resume", "--run-dir", str(run)],
    ):
        assert main(argv) == 2, argv
        (line,) = capsys.readouterr().err.splitlines()
        assert line.startswith(
            f"torchcbl {argv[0]}: error: {run / 'checkpoints'} cannot be read: Input/output error"
        ), line
        assert "changed nothing" in line and "OSError" not in line, line
    monkeypatch.undo()
    assert sorted((p.name, p.read_bytes()) for p in run.rglob("*") if p.is_file()) == before


def test_the_domain_table_matches_the_envs():
    """evaluate tells a session's domain by its env id or its (features, actions, observation
    space): both as the domains' envs really are."""
    import gymnasium as gym

    import corridor
    import sumo_scenarios
    from torchcbl.cli import _ENV_IDS, _SPACES

    assert _ENV_IDS == {corridor.ENV_ID: "corridor", sumo_scenarios.ENV_ID: "driving"}
    for env_id, domain in _ENV_IDS.items():
        env = gym.make(env_id)
        try:
            space = (
                env.observation_space.shape[0],
                int(env.action_space.n),
                repr(env.observation_space),
            )
        finally:
            env.close()
        assert _SPACES[space] == domain


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
    # the person taught the reproduction's learner (its cap, variance floor and tolerance)
    model = json.loads((run_dir / "config.json").read_text())["model"]["args"]
    cfg = DrivingExperimentConfig()
    assert (model["max_components"], model["var_floor"], model["tol"]) == (
        cfg.max_components,
        cfg.var_floor,
        cfg.gmm_tol,
    )


def test_reproduce_corridor_writes_a_summary_then_plot_and_evaluate_read_it(corridor_run, capsys):
    out = corridor_run
    summary = (out / "summary.md").read_text()
    assert "## corridor" in summary and "demonstrations in all" in summary
    results = out / "corridor" / "results.json"
    assert results.exists() and (out / "corridor" / "figure3.png").exists()
    # plot redraws from the run directory alone
    (out / "corridor" / "figure4.png").unlink()
    assert main(["plot", str(out / "corridor")]) == 0
    assert (out / "corridor" / "figure4.png").stat().st_size > 1000
    # evaluate a saved policy (a teaching session directory); the domain is read from it
    capsys.readouterr()
    session = out / "corridor" / "sessions" / "seed0"
    assert main(["evaluate", str(session), "--steps", "60"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["steps"] == 60 and report["circuits_clean"] == report["circuits_completed"] >= 1


def test_a_figure_that_fails_loses_no_result_and_says_how_to_draw_it(
    corridor_run, tmp_path, monkeypatch, capsys
):
    """reproduce computed every seed and only then drew the figures: one that failed
    (matplotlib missing, a full disk) left no results.json, every seed's work lost to the run.
    The results and summary are written first; the one line says they are kept and how to
    finish the run, which draws them."""
    import torchcbl.cli as cli

    out = _stopped_before_results(corridor_run, tmp_path / "runs")
    run = out / "corridor"
    (run / "figure4.png").mkdir()  # no figure can be written in its place
    monkeypatch.setattr(cli, "_experiment_config", _tiny_corridor)
    argv = ["reproduce", "corridor", "--seeds", "2", "--workers", "1", "--no-progress"]
    argv += ["--resume", "--out", str(out)]
    capsys.readouterr()
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert f"the corridor figures could not be drawn into {run}" in err
    assert f"its results are kept in {run / 'results.json'}" in err
    assert "once that is fixed, finish the run with the same command (it draws them)" in err
    whole = corridor_run / "corridor"
    kept = json.loads((run / "results.json").read_text(encoding="utf-8"))
    assert kept["summary"] == json.loads((whole / "results.json").read_text())["summary"]
    assert (run / "summary.txt").read_text() == (whole / "summary.txt").read_text()
    (run / "figure4.png").rmdir()
    assert main(argv) == 0 and (out / "summary.md").is_file()  # as the line says
    for name in ("figure3.png", "figure4.png", "map.png"):
        assert (run / name).read_bytes() == (whole / name).read_bytes(), name


def test_a_corridor_run_draws_exactly_the_figures_its_module_names(corridor_run):
    """reproduce --resume draws a finished domain's missing figures again by its module's
    FIGURES, which the corridor's plot_results does not save through (it names each file
    itself): a name changed on one side only would have --resume miss a figure, or draw all
    of them again at every resume. The PNGs a corridor run writes are FIGURES."""
    from corridor.experiment import FIGURES

    assert sorted(p.name for p in (corridor_run / "corridor").glob("*.png")) == sorted(FIGURES)


def test_reproduce_resume_draws_the_missing_figures_of_a_finished_domain(
    corridor_run, tmp_path, monkeypatch, capsys
):
    """A run whose figure failed (its results.json written) was told to finish with --resume,
    but --resume took a domain with a results.json as finished whatever its figures: it wrote
    summary.md, which marks the run finished, with figure3.png missing and nothing said. A
    finished domain's missing figures are drawn again, said in one line; the figures there are
    left as they are; one that still fails is the one-line error of a figure that fails."""
    import torchcbl.cli as cli

    out = tmp_path / "runs"
    shutil.copytree(corridor_run, out)
    run, whole = out / "corridor", corridor_run / "corridor"
    (out / "summary.md").unlink()  # stopped after the corridor run, before the summary
    (run / "figure3.png").unlink()
    (run / "figure4.png").write_bytes(b"a figure of one's own")  # there: kept as it is
    monkeypatch.setattr(cli, "_experiment_config", _tiny_corridor)
    argv = ["reproduce", "corridor", "--seeds", "2", "--workers", "1", "--no-progress"]
    argv += ["--resume", "--out", str(out)]
    capsys.readouterr()
    assert main(argv) == 0
    printed = capsys.readouterr().out
    notes = [ln for ln in printed.splitlines() if "figure3.png" in ln]
    assert len(notes) == 1 and "missing" in notes[0] and "drawn again" in notes[0], printed
    assert (run / "figure3.png").read_bytes() == (whole / "figure3.png").read_bytes()
    assert (run / "figure4.png").read_bytes() == b"a figure of one's own"
    assert (run / "map.png").read_bytes() == (whole / "map.png").read_bytes()
    assert (out / "summary.md").is_file()
    # all there: nothing is drawn, nothing said; one that cannot be drawn again: said in one
    # line, the run finished without it (a finished domain does not hold up the run: before
    # the figures were drawn again on resume, it resumed whatever its figures)
    (out / "summary.md").unlink()
    assert main(argv) == 0 and "missing" not in capsys.readouterr().out
    (out / "summary.md").unlink()
    (run / "map.png").unlink()
    (run / "map.png").mkdir()  # no figure can be written in its place
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert "corridor: map.png could not be drawn again" in err, err
    assert f"torchcbl plot {run}" in err and "the run goes on without them" in err, err
    assert (out / "summary.md").is_file()
    assert (run / "figure4.png").read_bytes() == b"a figure of one's own"
    assert (run / "figure3.png").read_bytes() == (whole / "figure3.png").read_bytes()
    # the sessions the corridor's figures are drawn from gone: the same
    (out / "summary.md").unlink()
    (run / "map.png").rmdir()
    shutil.rmtree(run / "sessions")
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "map.png could not be drawn again" in err, err
    assert (out / "summary.md").is_file() and not (run / "map.png").exists()
    assert (run / "figure4.png").read_bytes() == b"a figure of one's own"


@pytest.mark.parametrize(
    ("cause", "says"),
    [
        (RuntimeError("no room\n  on the device"), "(RuntimeError: no room on the device)"),
        (RuntimeError(), "(RuntimeError: RuntimeError)"),
    ],
)
def test_a_figure_not_drawn_again_names_its_whole_cause_on_one_line(
    corridor_run, tmp_path, monkeypatch, capsys, cause, says
):
    """The warning of a finished domain's figure that could not be drawn again kept only the
    first line of its cause's message, and printed a bare "RuntimeError: " for one without a
    message; it says the cause as every other one-line error does (FigureError's too)."""
    import corridor.experiment
    import torchcbl.cli as cli

    out = tmp_path / "runs"
    shutil.copytree(corridor_run, out)
    (out / "summary.md").unlink()
    (out / "corridor" / "figure3.png").unlink()
    monkeypatch.setattr(cli, "_experiment_config", _tiny_corridor)

    def fails(results, run_dir, only=None):
        raise cause

    monkeypatch.setattr(corridor.experiment, "plot_results", fails)
    argv = ["reproduce", "corridor", "--seeds", "2", "--workers", "1", "--no-progress"]
    capsys.readouterr()
    assert main([*argv, "--resume", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert f"figure3.png could not be drawn again {says}; the run goes on" in err, err


def test_output_a_terminal_cannot_show_is_escaped_not_a_crash(corridor_run, tmp_path):
    """On a terminal whose encoding lacks '±' (the summaries) or '≠' (the benchmark's table),
    printing raised UnicodeEncodeError at the very end of a command (exit 1, the summary.md
    of a finished reproduction unwritten). Such a character is written escaped (\\xb1)."""
    out = tmp_path / "runs"  # the corridor run, stopped before its summary.md
    shutil.copytree(corridor_run / "corridor", out / "corridor")
    code = (  # the settings of the run it resumes: those of its results.json
        "import json, sys\n"
        "import torchcbl.cli as cli\n"
        "from corridor.experiment import CorridorExperimentConfig as C\n"
        "stored = json.load(open(sys.argv[1], encoding='utf-8'))['config']\n"
        "cli._experiment_config = lambda domain, module, args: C.from_dict(stored)\n"
        "sys.exit(cli.main(sys.argv[2:]))\n"
    )
    argv = ["reproduce", "corridor", "--resume", "--no-progress", "--out", str(out)]
    done = subprocess.run(
        [sys.executable, "-c", code, str(out / "corridor" / "results.json"), *argv],
        capture_output=True,
        env={**os.environ, "PYTHONIOENCODING": "ascii"},
        timeout=60,
    )
    assert done.returncode == 0, done.stderr.decode()
    assert done.stderr == b""
    printed = done.stdout.decode("ascii")
    assert "\\xb1" in printed and "Summary written to" in printed
    assert "±" in (out / "summary.md").read_text(encoding="utf-8")


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
    assert (
        main(["replay", str(path), "--label", "demo/b", "--max-frames", "8", "--every", "2"]) == 0
    )
    gif, fcd = tmp_path / "episodes-1.gif", tmp_path / "episodes-1.fcd.xml"
    assert gif.stat().st_size > 1000
    import imageio.v3 as iio

    assert iio.improps(gif, index=None).shape[0] == 8  # the frames the message names
    assert (
        "(8 frames, every 2 timestep(s): the first 14 of 30 timesteps)" in capsys.readouterr().out
    )
    steps = list(sumolib.xml.parse(str(fcd), "timestep"))
    assert len(steps) >= 30 and any(v.id == "ego" for v in steps[-1].vehicle)
    capsys.readouterr()
    assert main(["replay", str(path), "--episode", "7"]) == 2
    assert "--list" in capsys.readouterr().err
    # output paths that cannot be files, and damaged episodes: one line, nothing written
    before = sorted(tmp_path.iterdir())
    for flag in ("--gif", "--fcd"):
        assert main(["replay", str(path), flag, str(tmp_path)]) == 2
        assert f"{flag} {tmp_path} is a directory" in capsys.readouterr().err
    good = json.loads(path.read_text())[0]
    for field, value, says in (
        ("actions", [0, 7, 0], "0 (stay), 1 (left) or 2 (right)"),
        ("actions", [0, 1.7], "0 (stay), 1 (left) or 2 (right)"),
        ("actions", "0101", "expected a JSON list"),
        ("actions", [], "non-empty"),
        ("start_lane", 9, "lane index 0-4"),
        ("episode_seed", -3, "int >= 0"),
    ):
        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps([{**good, field: value}]))
        assert main(["replay", str(bad)]) == 2, field
        err = capsys.readouterr().err
        assert says in err and err.count("\n") == 1, (field, err)
        bad.unlink()
    assert sorted(tmp_path.iterdir()) == before


def test_replay_list_needs_no_simulator_and_a_replay_checks_for_one_first(tmp_path):
    """`torchcbl replay EPISODES --list` imported the simulator (libsumo) before listing, which
    needs none: without SUMO, listing a run's episodes failed. It lists them; a replay
    without SUMO is one line naming it (exit 2), before anything is written."""
    from sumo_scenarios.replay import EpisodeRecord, save_records
    from sumo_scenarios.scenarios import get_scenario
    from sumo_scenarios.sim import SimConfig

    record = EpisodeRecord(get_scenario("eval"), SimConfig(), 0, 2, (0, 1, 0), "demo/a")
    path = tmp_path / "episodes.json"
    save_records([record], path)
    code = (  # libsumo missing: `import libsumo` raises ModuleNotFoundError
        "import sys\n"
        "sys.modules['libsumo'] = None\n"
        "from torchcbl.cli import main\n"
        "print('exit', main(['replay', sys.argv[1], '--list']), flush=True)\n"
        "print('exit', main(['replay', sys.argv[1]]), flush=True)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    listed, replayed = done.stdout.split("exit 0\n")
    assert "demo/a" in listed and "3 steps" in listed, done.stdout
    assert replayed == "exit 2\n", done.stdout
    assert done.stderr.startswith("torchcbl replay: error: libsumo is missing")
    assert done.stderr.count("\n") == 1, done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["episodes.json"]


def test_replay_a_driving_teaching_session_checked_against_its_log(tmp_path, capsys, monkeypatch):
    import gymnasium as gym

    import sumo_scenarios  # noqa: F401  (registers torchcbl/Driving-v0)
    from sumo_scenarios.replay import session_episodes
    from sumo_scenarios.teacher import make_teacher
    from torchcbl import ConfidentTeacher, TeachingConfig
    from torchcbl.session import load_records

    run = tmp_path / "session"
    env = gym.make(  # render_mode is kept with the make kwargs; it draws, it drives nothing
        "torchcbl/Driving-v0", scenario="light", max_episode_steps=25, render_mode="rgb_array"
    )
    with ConfidentTeacher(
        env, make_teacher(0), config=TeachingConfig(max_new=10), run_dir=run, progress=False
    ) as ct:
        ct.run(max_steps=60)
    episodes = session_episodes(run, check=True)  # each replay equals the log
    steps = load_records(run)
    assert [len(e.actions) for e in episodes] == [25, 25, 10]
    assert [a for e in episodes for a in e.actions] == [r.executed_action for r in steps]
    assert {e.scenario.name for e in episodes} == {"light"}
    assert main(["replay", str(run), "--list"]) == 0
    assert "session/episode 2" in capsys.readouterr().out
    assert main(["replay", str(run), "--episode", "1", "--max-frames", "3"]) == 0
    out = capsys.readouterr().out
    assert "the replay equals the session's log" in out
    assert (tmp_path / "session-1.gif").is_file() and (tmp_path / "session-1.fcd.xml").is_file()
    monkeypatch.chdir(run)  # from inside the session: its name still labels the outputs
    assert main(["replay", ".", "--episode", "2", "--max-frames", "2"]) == 0
    assert "session/episode 2" in capsys.readouterr().out
    assert (tmp_path / "session-2.gif").is_file()
    # the session's env given other traffic: the replay diverges, and says where
    config = json.loads((run / "config.json").read_text())
    config["env"]["kwargs"]["scenario"] = "train"
    (run / "config.json").write_text(json.dumps(config))
    assert main(["replay", str(run), "--episode", "0", "--gif", str(tmp_path / "x.gif")]) == 2
    err = capsys.readouterr().err
    assert "the replay diverges from the logged observations at step 0" in err
    assert err.count("\n") == 1 and not (tmp_path / "x.gif").exists()


def test_a_driving_session_given_its_settings_as_objects_replays_and_evaluates_on_them(
    tmp_path, capsys
):
    """README said a ConfidentTeacher session on gymnasium.make("torchcbl/Driving-v0", ...)
    replays the same way, but one given a TrafficScenario, a SimConfig or a DrivingConfig was
    refused ("its episodes cannot be rebuilt"): the session kept them only as text. It keeps
    them rebuildably now, and its episodes replay (equal to its log) and its policy is
    evaluated on them; a session written before is refused in one line, as it was."""
    import dataclasses

    import gymnasium as gym

    import sumo_scenarios
    from sumo_scenarios.env import DrivingConfig
    from sumo_scenarios.experiment import evaluate_saved_policy
    from sumo_scenarios.replay import session_episodes
    from sumo_scenarios.scenarios import TrafficScenario
    from sumo_scenarios.sim import SimConfig
    from sumo_scenarios.teacher import make_teacher
    from torchcbl import ConfidentTeacher, TeachingConfig

    mine = TrafficScenario(name="mine", seed=7, mean_spacing_m=(80, 60, 200))
    fast = SimConfig(step_length_s=0.1)
    for name, made in (
        ("apart", dict(scenario=mine, sim=fast)),
        ("whole", dict(config=DrivingConfig(scenario=mine, start_lane=3, sim=fast))),
    ):
        run = tmp_path / name
        env = gym.make(sumo_scenarios.ENV_ID, max_episode_steps=8, **made)
        teacher = make_teacher(0, step_length_s=0.1)
        with ConfidentTeacher(
            env, teacher, config=TeachingConfig(max_new=5), run_dir=run, progress=False
        ) as ct:
            ct.run(max_steps=12)
        env.close()
        episodes = session_episodes(run, check=True)  # each replay equals the log
        assert [len(e.actions) for e in episodes] == [8, 4]
        assert {(e.scenario, e.sim) for e in episodes} == {(mine, fast)}
        assert main(["replay", str(run), "--list"]) == 0, capsys.readouterr().err
        assert f"{name}/episode 1" in capsys.readouterr().out
        report = evaluate_saved_policy(run, n_steps=10)
        # its traffic's held-out twin (the next base seed), its own SUMO settings
        assert report["scenario"] == {
            **json.loads(json.dumps(dataclasses.asdict(mine))),
            "name": "mine-held-out",
            "seed": 8,
        }
        assert report["held_out"] and report["sim"] == dataclasses.asdict(fast)
        assert report["start_lane"] == (3 if name == "whole" else 2)
        # as a session written before the objects were kept: refused in one line, as before
        _as_written_before_objects_were_kept(run)
        assert main(["replay", str(run), "--list"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "given as an object" in err, err
        assert main(["evaluate", str(run), "--steps", "10"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "given as an object" in err, err


def _markdown_tables(text: str) -> dict[str, list[list[list[str]]]]:
    """The tables of a Markdown document by the ``##`` heading they follow (its first word),
    each as rows of cell texts, as markdown-it-py (CommonMark + GFM tables) parses them."""
    from markdown_it import MarkdownIt

    tokens = MarkdownIt("commonmark").enable("table").parse(text)
    sections: dict[str, list[list[list[str]]]] = {}
    section, row, in_heading = None, None, False
    for tok in tokens:
        if tok.type == "heading_open":
            in_heading = tok.tag == "h2"
        elif tok.type == "inline" and in_heading:
            section = tok.content.split()[0] if tok.content else ""
            sections.setdefault(section, [])
            in_heading = False
        elif tok.type == "table_open":
            sections.setdefault(section, []).append([])
        elif tok.type == "tr_open":
            row = []
            sections[section][-1].append(row)
        elif tok.type == "inline" and row is not None:
            row.append(tok.content.strip())
        elif tok.type == "tr_close":
            row = None
    return sections


def test_the_markdown_reader_finds_tables_and_not_a_dash_underlined_heading():
    good = "## corridor (1 s)\n\n| figure | paper |\n|---|---:|\n| a | 1 |\n| b | 2 |\n"
    assert _markdown_tables(good) == {"corridor": [[["figure", "paper"], ["a", "1"], ["b", "2"]]]}
    dashes = "## corridor (1 s)\n\nfigure | paper\n---------------\na | 1\n"
    assert _markdown_tables(dashes) == {"corridor": [], "figure": []}  # a setext heading


def test_summary_md_is_markdown_and_its_table_parses_as_a_table(corridor_run):
    text = (corridor_run / "summary.md").read_text()
    sections = _markdown_tables(text)
    assert list(sections) == ["corridor"]  # one heading per domain, no stray headings
    tables = sections["corridor"]
    header, *rows = tables[0]
    assert header[0] == "figure" and "paper" in header and len(header) >= 3
    assert "demonstrations in all" in [r[0] for r in rows]
    for table in tables:
        assert {len(r) for r in table} == {len(table[0])}
    table_lines = [ln for ln in text.splitlines() if "|" in ln]
    # every line of a table is a row, plus its rule
    assert len(table_lines) == sum(len(t) + 1 for t in tables)
    assert "+-" not in text  # one notation for ±


def test_summary_md_of_a_driving_run_is_markdown_too(tmp_path, monkeypatch):
    """`torchcbl reproduce driving` at a tiny size (the settings of
    test_driving_experiment's tiny run): its summary.md table parses as a table."""
    from _driving_tiny import tiny_config

    import torchcbl.cli as cli

    tiny = tiny_config(extra_eval_segments=())
    monkeypatch.setattr(cli, "_experiment_config", lambda domain, module, args: tiny)
    out = tmp_path / "runs"
    argv = ["reproduce", "driving", "--workers", "1", "--no-progress", "--out", str(out)]
    assert main(argv) == 0
    text = (out / "summary.md").read_text()
    sections = _markdown_tables(text)
    assert list(sections) == ["driving"]
    (table,) = sections["driving"]
    header, *rows = table
    assert header[0] == "figure" and "paper" in header and len(header) >= 3
    assert {len(r) for r in rows} == {len(header)}
    assert any("arm (a) final, collisions %" in cell for r in rows for cell in r)
    table_lines = [ln for ln in text.splitlines() if "|" in ln]
    assert len(table_lines) == len(rows) + 2
    assert "+-" not in text


def test_reproduce_resume_continues_a_stopped_run_and_refuses_other_settings(
    tmp_path, monkeypatch, capsys
):
    """`torchcbl reproduce --resume --out DIR` (tiny driving runs, --seeds honoured): a domain
    that finished is taken from its results.json, a stopped one from its seeds' files, and the
    run ends as the one never stopped; other settings, other domains, a finished run and a
    missing directory are refused with one line and exit code 2, naming what differs."""
    from _driving_tiny import tiny_config

    import torchcbl.cli as cli

    monkeypatch.setattr(
        cli,
        "_experiment_config",
        lambda domain, module, args: tiny_config(seeds=tuple(range(args.seeds or 1))),
    )
    out = tmp_path / "runs"
    argv = ["reproduce", "driving", "--workers", "1", "--no-progress", "--out", str(out)]
    assert main(argv) == 0
    untimed = re.compile(r"\(\d+ s, ")
    summary = untimed.sub("", (out / "summary.md").read_text())
    results = (out / "driving" / "results.json").read_text()
    from sumo_scenarios.experiment import FIGURES

    assert sorted(p.name for p in (out / "driving").glob("*.png")) == sorted(FIGURES)
    figure = out / "driving" / "fig10_confidence.png"
    drawn = figure.read_bytes()
    capsys.readouterr()

    def refused(*extra: str) -> str:
        assert main([*argv[:-1], *extra]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1, err
        return err

    assert "holds summary.md: its run finished" in refused(str(out), "--resume")
    (out / "summary.md").unlink()  # stopped after the driving run, before the summary
    err = refused(str(out), "--resume", "--seeds", "2")
    assert "finished with other settings: seeds ([0] there, [0, 1] here)" in err
    corridor = ["reproduce", "corridor", "--no-progress", "--resume", "--out", str(out)]
    assert main(corridor) == 2
    assert "holds a driving run too, which this command does not run" in capsys.readouterr().err
    assert "does not exist" in refused(str(tmp_path / "nowhere"), "--resume")
    figure.unlink()  # (a figure that failed after results.json): drawn again
    assert main([*argv, "--resume"]) == 0
    assert untimed.sub("", (out / "summary.md").read_text()) == summary
    assert (
        figure.read_bytes() == drawn and "fig10_confidence.png missing" in capsys.readouterr().out
    )
    assert (out / "driving" / "results.json").read_text() == results
    # stopped in the driving run: seed 0 finished, no results.json
    (out / "summary.md").unlink()
    (out / "driving" / "results.json").unlink()
    err = refused(str(out), "--resume", "--seeds", "2")
    assert "seed 0's finished result" in err and "seeds ([0] there, [0, 1] here)" in err
    assert not (out / "driving" / "seed_1").exists()
    assert main([*argv, "--resume"]) == 0
    assert untimed.sub("", (out / "summary.md").read_text()) == summary
    on_disk = json.loads((out / "driving" / "results.json").read_text())
    expected = json.loads(results)
    for key in ("seconds", "cpu_seconds"):
        on_disk.pop(key), expected.pop(key)
    assert on_disk == expected
    # stopped again; another run still writing into it (it survived a lost terminal): refused
    (out / "summary.md").unlink()
    (out / "driving" / "results.json").unlink()
    import fcntl

    with open(out / "driving" / ".run.lock", "a", encoding="utf-8") as held:
        fcntl.flock(held.fileno(), fcntl.LOCK_EX)
        assert "is being written by another run" in refused(str(out), "--resume")
    assert (out / "driving" / "seed_0" / "seed_result.json").is_file()
    # a directory that holds something else than a run: refused, not filled with a new run
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    assert "holds no driving directory" in refused(str(other), "--resume")
    assert sorted(p.name for p in other.iterdir()) == ["notes.txt"]
    # a finished seed computed by other code: said so, with what to do about code (not settings)
    kept = out / "driving" / "seed_0" / "seed_result.json"
    stored = json.loads(kept.read_text())
    stored["versions"]["torch"] = "0.0.1"
    kept.write_text(json.dumps(stored))
    err = refused(str(out), "--resume")
    assert "computed by other code: torch ('0.0.1' there" in err, err
    assert "resume with the code it was started with" in err and "give the settings" not in err


def test_reproduce_interrupted_says_how_to_go_on(tmp_path, monkeypatch, capsys):
    """Ctrl-C during a reproduction printed 'interrupted' alone, though its finished seeds are
    kept and --resume goes on from them."""
    import corridor.experiment

    def stopped(config, run_dir, **kwargs):
        (run_dir / "sessions").mkdir(parents=True)  # a seed or more written
        raise KeyboardInterrupt

    monkeypatch.setattr(corridor.experiment, "run_experiment", stopped)
    out = tmp_path / "runs"
    assert main(["reproduce", "corridor", "--no-progress", "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert err.strip() == (
        f"torchcbl reproduce: interrupted (its finished seeds are kept: go on with the same "
        f"command plus --resume --out {out})"
    )


def test_evaluate_drives_a_corridor_session_on_the_map_it_was_taught_on(
    corridor_run, tmp_path, capsys
):
    """An experiment's session: the map of its results.json; a session of gymnasium.make's env:
    the corridor_map it was made with; neither: the default map."""
    import shutil

    import gymnasium as gym

    import corridor  # registers the env id
    from corridor.experiment import evaluate_saved_policy
    from torchcbl import ConfidentTeacher

    results = json.loads((corridor_run / "corridor" / "results.json").read_text())
    assert results["config"]["map_name"] == "figure2"
    session = corridor_run / "corridor" / "sessions" / "seed0"
    assert evaluate_saved_policy(session, n_steps=5)["map"] == "figure2"
    # a session without a record of its own (a run from before the seed records): the
    # results.json names the map (here as a file of the same map), not the env's kwargs; one
    # that names a map other than the session drove is refused
    mine = tmp_path / "mine.json"
    shutil.copy(Path(corridor.__file__).with_name("maps") / "figure2.json", mine)
    results["config"]["map_name"] = str(mine)
    copy = tmp_path / "run"
    shutil.copytree(session, copy / "sessions" / "seed0")
    (copy / "sessions" / "seed0" / "seed_result.json").unlink()
    (copy / "results.json").write_text(json.dumps(results))
    assert evaluate_saved_policy(copy / "sessions" / "seed0", n_steps=5)["map"] == str(mine)
    results["config"]["map_name"] = "lshape"
    (copy / "results.json").write_text(json.dumps(results))
    with pytest.raises(ValueError, match="on another map than the shipped map 'lshape', which"):
        evaluate_saved_policy(copy / "sessions" / "seed0", n_steps=5)
    assert main(["evaluate", str(copy / "sessions" / "seed0"), "--steps", "5"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "to corridor.experiment.evaluate_saved_policy in Python" in err
    env = gym.make("torchcbl/Corridor-v0", corridor_map="lshape")
    ConfidentTeacher(env, lambda o, i: 0, run_dir=tmp_path / "made", progress=False).run(
        max_steps=3
    ).close()
    assert evaluate_saved_policy(tmp_path / "made", n_steps=5)["map"] == "lshape"
    env = gym.make("torchcbl/Corridor-v0")
    ConfidentTeacher(env, lambda o, i: 0, run_dir=tmp_path / "plain", progress=False).run(
        max_steps=3
    ).close()
    plain = evaluate_saved_policy(tmp_path / "plain", n_steps=5)
    assert plain["map"] == "figure2" and plain["world"]["forward_noise"] == 0.0
    # a robot given as an object: kept whole, and driven
    from corridor.world import WorldConfig

    env = gym.make("torchcbl/Corridor-v0", world_config=WorldConfig.legged_robot())
    ConfidentTeacher(env, lambda o, i: 0, run_dir=tmp_path / "object", progress=False).run(
        max_steps=3
    ).close()
    noisy = evaluate_saved_policy(tmp_path / "object", n_steps=5)
    assert noisy["world"] == dataclasses.asdict(WorldConfig.legged_robot())
    # a session written before objects were kept whole keeps it only as text: evaluate says so
    # instead of driving the default robot
    _as_written_before_objects_were_kept(tmp_path / "object")
    with pytest.raises(ValueError, match="robot given as an object"):
        evaluate_saved_policy(tmp_path / "object", n_steps=5)
    assert main(["evaluate", str(tmp_path / "object")]) == 2
    noisy = evaluate_saved_policy(
        tmp_path / "object", n_steps=5, world_config=WorldConfig.legged_robot()
    )
    assert noisy["world"]["forward_noise"] > 0


def test_evaluate_drives_a_corridor_session_copied_out_of_its_run_on_its_own_robot(
    tmp_path, monkeypatch, capsys
):
    """A reproduction's session copied out of its run directory was driven on the exact robot
    of the default WorldConfig(), though its own seed_result.json holds the noisy robot it was
    taught on: evaluate read only the run's results.json two folders up. The session's own
    record now decides; where nothing says (an env made without gymnasium.make, no record, no
    run), one line says which robot is driven."""
    import shutil

    import corridor.experiment
    from corridor.baseline import PrioritizedSweepingConfig
    from corridor.env import CorridorEnv
    from corridor.experiment import CorridorExperimentConfig, run_experiment
    from torchcbl import ConfidentTeacher

    score = corridor.experiment.score_tables  # for time: its ranking over 50 steps, not 1000
    monkeypatch.setattr(
        corridor.experiment, "score_tables", lambda *a, **k: score(*a, steps=50, **k)
    )
    cfg = CorridorExperimentConfig(  # the noisy robot, the default
        seeds=(0,), cba=False, eval_circuits=1, ps=PrioritizedSweepingConfig(max_steps=50)
    )
    cfg = dataclasses.replace(cfg, teaching=dataclasses.replace(cfg.teaching, max_steps=30))
    run_experiment(cfg, tmp_path / "run", workers=1, progress=False)
    noisy = dataclasses.asdict(cfg.world)
    assert noisy["forward_noise"] > 0
    inside = tmp_path / "run" / "sessions" / "seed0"
    elsewhere = tmp_path / "x" / "seed0"
    shutil.copytree(inside, elsewhere)
    for session in (inside, elsewhere):
        capsys.readouterr()
        assert main(["evaluate", str(session), "--steps", "20"]) == 0
        out, err = capsys.readouterr()
        assert json.loads(out)["world"] == noisy, session
        assert err == ""
    # the session's own record first: a session put into another run's folder keeps its robot
    other = tmp_path / "other"
    shutil.copytree(inside, other / "sessions" / "seed0")
    results = json.loads((tmp_path / "run" / "results.json").read_text())
    results["config"]["world"] = dataclasses.asdict(CorridorExperimentConfig.exact_motion().world)
    (other / "results.json").write_text(json.dumps(results))
    assert main(["evaluate", str(other / "sessions" / "seed0"), "--steps", "20"]) == 0
    assert json.loads(capsys.readouterr().out)["world"] == noisy
    # a record that names another map than the session drove is refused, naming the record
    record = elsewhere / "seed_result.json"
    kept = json.loads(record.read_text())
    kept["config"]["map_name"] = "lshape"
    record.write_text(json.dumps(kept))
    assert main(["evaluate", str(elsewhere), "--steps", "20"]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and f"which its own {record} names" in err, err
    # nothing says: the env was made directly (no gymnasium.make), no record, no run
    ConfidentTeacher(CorridorEnv(), lambda o, i: 0, run_dir=tmp_path / "own", progress=False).run(
        max_steps=3
    ).close()
    assert main(["evaluate", str(tmp_path / "own"), "--steps", "5"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["world"]["forward_noise"] == 0.0
    assert len(err.splitlines()) == 1, err
    assert "keeps no record of the robot it was taught with" in err
    assert "WorldConfig() (exact motion)" in err and "world_config=" in err


def _as_written_before_objects_were_kept(run: Path) -> None:
    """Make ``run`` as a session written before 2026-11-27, which kept an object given to
    gymnasium.make only as text (no ``env.kwargs_objects``)."""
    config = json.loads((run / "config.json").read_text())
    del config["env"]["kwargs_objects"]
    (run / "config.json").write_text(json.dumps(config))


def test_evaluate_of_a_session_it_cannot_rebuild_names_the_python_call(tmp_path, capsys):
    """A session whose env was given its map, robot or SUMO settings as objects kept them only
    as text (before 2026-11-27): `torchcbl evaluate` cannot drive it, and its one line names
    the function and the keyword that can (it said "pass map_name=", an option the command
    does not have)."""
    import gymnasium as gym

    import sumo_scenarios  # noqa: F401  (registers torchcbl/Driving-v0)
    from corridor.maps import load_map
    from corridor.world import WorldConfig
    from sumo_scenarios.sim import SimConfig
    from torchcbl import ConfidentTeacher

    cases = {
        "map": ("Corridor", {"corridor_map": load_map("lshape")}, "map_name=", "corridor"),
        "robot": (
            "Corridor",
            {"world_config": WorldConfig.legged_robot()},
            "world_config=",
            "corridor",
        ),
        "sim": ("Driving", {"sim": SimConfig(step_length_s=0.5)}, "sim=", "sumo_scenarios"),
    }
    for name, (domain, kwargs, keyword, package) in cases.items():
        env = gym.make(f"torchcbl/{domain}-v0", **kwargs)
        ConfidentTeacher(env, lambda o, i: 0, run_dir=tmp_path / name, progress=False).run(
            max_steps=2
        ).close()
        env.close()
        _as_written_before_objects_were_kept(tmp_path / name)
        capsys.readouterr()
        assert main(["evaluate", str(tmp_path / name)]) == 2
        err = capsys.readouterr().err
        assert len(err.splitlines()) == 1, err
        assert f"pass {keyword} (" in err
        assert f"to {package}.experiment.evaluate_saved_policy in Python" in err, err


def _scripted_corridor_person(monkeypatch, max_demonstrations: int | None = 5) -> None:
    """`torchcbl teach corridor` with a scripted person at the terminal (answering "forward"
    to every request) and a budget of 5 demonstrations (by default)."""
    import corridor.human
    from torchcbl import cli

    class Scripted:
        def __call__(self, observation, info):
            return 0

        def set_status(self, text):
            pass

    monkeypatch.setattr(corridor.human, "make_teacher", lambda **kw: Scripted())
    package, env_id, human, settings, model = cli._TEACH["corridor"]
    budget = {
        **settings,
        "max_demonstrations": max_demonstrations,
        "autonomous_episodes_to_stop": None,
    }
    monkeypatch.setitem(cli._TEACH, "corridor", (package, env_id, human, budget, model))


def test_teach_corridor_on_a_map_of_ones_own_and_evaluate_drives_it(tmp_path, monkeypatch, capsys):
    import corridor
    from corridor.experiment import evaluate_saved_policy
    from corridor.maps import load_map

    _scripted_corridor_person(monkeypatch)
    mine = json.loads(Path(corridor.__file__).with_name("maps").joinpath("lshape.json").read_text())
    mine["name"] = "my_lab"
    path = tmp_path / "maps" / "my_lab.json"
    path.parent.mkdir()
    path.write_text(json.dumps(mine))
    run = tmp_path / "session"
    monkeypatch.chdir(tmp_path)  # a relative path is kept as the full one
    argv = ["teach", "corridor", "--run-dir", str(run), "--steps", "10"]
    assert main([*argv, "--map", "maps/my_lab.json"]) == 0
    stored = json.loads((run / "config.json").read_text())["env"]["kwargs"]
    assert stored["corridor_map"] == str(path.resolve())
    assert load_map(stored["corridor_map"]).name == "my_lab"
    assert evaluate_saved_policy(run, n_steps=5)["map"] == str(path.resolve())
    capsys.readouterr()
    for extra, says in (
        (["--map", "nowhere.json"], "--map: map file 'nowhere.json' not found"),
        (["--map", "atlantis"], "--map: unknown map 'atlantis'"),
    ):
        assert main([*argv[:3], str(tmp_path / "other"), *argv[4:], *extra]) == 2, extra
        err = capsys.readouterr().err
        assert says in err and err.count("\n") == 1, err
        assert not (tmp_path / "other").exists()  # nothing written
    assert main(["teach", "driving", "--map", "lshape", "--run-dir", str(tmp_path / "d")]) == 2
    assert "--map applies only to teach corridor" in capsys.readouterr().err


def test_teach_resume_of_a_session_taught_in_another_env_id_says_so(tmp_path, monkeypatch, capsys):
    """A session taught in another registered env of corridor's space (its config.json keeps
    that env's id) was taken for a corridor session: teach --resume made torchcbl's corridor
    env, then the library refused it, telling to "resume with matching arguments", which
    teach takes none of. It is refused before any env is made, in one line (exit code 2)
    naming both ids and the Python call that resumes it; the session is left as it was."""
    import gymnasium

    _scripted_corridor_person(monkeypatch)
    run = tmp_path / "session"
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "3"]) == 0
    config = json.loads((run / "config.json").read_text())
    config["env"]["id"] = "mypkg/MyCorridor-v0"
    (run / "config.json").write_text(json.dumps(config))
    files = {p: p.read_bytes() for p in sorted(run.rglob("*")) if p.is_file()}

    def make(*args, **kwargs):
        raise AssertionError(f"an env was made: {args}")

    monkeypatch.setattr(gymnasium, "make", make)
    capsys.readouterr()
    for domain in ("corridor", "driving"):
        assert main(["teach", domain, "--resume", "--run-dir", str(run), "--steps", "3"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1, err
        assert "taught in the env 'mypkg/MyCorridor-v0'" in err, err
        assert "'torchcbl/Corridor-v0'" in err and "ConfidentTeacher.resume(" in err, err
    assert {p: p.read_bytes() for p in sorted(run.rglob("*")) if p.is_file()} == files


def test_teach_resume_makes_again_the_objects_a_python_session_gave_its_env(
    tmp_path, monkeypatch, capsys
):
    """A session begun in Python on gymnasium.make with objects (a CorridorMap and a
    WorldConfig, a DrivingConfig holding its TrafficScenario) keeps them whole in config.json,
    as evaluate and replay read them; teach --resume refused it all the same ("given as an
    object, which teach --resume does not make again"). It makes them again as those do and
    goes on: the same map, robot and traffic, the session's steps kept and added to."""
    import dataclasses as dc

    import gymnasium as gym

    import corridor.human
    import sumo_scenarios.human
    from corridor.maps import load_map
    from corridor.world import WorldConfig
    from sumo_scenarios.env import DrivingConfig
    from sumo_scenarios.scenarios import TRAIN
    from torchcbl import ConfidentTeacher

    class Person:
        def __call__(self, observation, info):
            return 0

        def set_status(self, text):
            pass

    for human in (corridor.human, sumo_scenarios.human):
        monkeypatch.setattr(human, "make_teacher", lambda **kw: Person())
    sessions = {
        "corridor": {
            "corridor_map": load_map("lshape"),
            "world_config": WorldConfig.legged_robot(),
        },
        "driving": {"config": DrivingConfig(scenario=dc.replace(TRAIN, seed=7), start_lane=1)},
    }
    made = []  # what teach gave gymnasium.make
    monkeypatch.setattr(gym, "make", lambda *a, _m=gym.make, **kw: made.append(kw) or _m(*a, **kw))
    for domain, kwargs in sessions.items():
        run = tmp_path / domain
        env = gym.make(f"torchcbl/{domain.capitalize()}-v0", **kwargs)
        ConfidentTeacher(env, Person(), run_dir=run, progress=False).run(max_steps=3).close()
        env.close()
        made.clear()
        argv = ["teach", domain, "--resume", "--run-dir", str(run), "--steps", "2"]
        assert main(argv) == 0, capsys.readouterr().err
        assert len(made) == 1 and {k: made[0][k] for k in kwargs} == kwargs, made
        assert len(load_records(run)) == 5


def test_teach_resume_of_objects_a_session_keeps_only_as_text_names_the_python_call(
    tmp_path, monkeypatch, capsys
):
    """A session written before 2026-11-27 kept an object given to gymnasium.make only as
    text: teach --resume cannot make it again, and says so in one line naming the argument
    and the Python call that resumes it; no env is made and no file of the session changes."""
    import gymnasium as gym

    from corridor.world import WorldConfig
    from torchcbl import ConfidentTeacher

    run = tmp_path / "session"
    env = gym.make("torchcbl/Corridor-v0", world_config=WorldConfig.legged_robot())
    ConfidentTeacher(env, lambda o, i: 0, run_dir=run, progress=False).run(max_steps=2).close()
    env.close()
    _as_written_before_objects_were_kept(run)
    files = {p: p.read_bytes() for p in sorted(run.rglob("*")) if p.is_file()}

    def make(*args, **kwargs):
        raise AssertionError(f"an env was made: {args}")

    monkeypatch.setattr(gym, "make", make)
    capsys.readouterr()
    assert main(["teach", "corridor", "--resume", "--run-dir", str(run)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "world_config given as an object" in err and "only as text" in err, err
    assert f"torchcbl.ConfidentTeacher.resume({str(run)!r}, " in err, err
    assert "gymnasium.make('torchcbl/Corridor-v0', world_config=" in err, err
    assert {p: p.read_bytes() for p in sorted(run.rglob("*")) if p.is_file()} == files


def test_teach_says_why_it_stopped_and_resume_goes_past_the_sessions_budget(
    tmp_path, monkeypatch, capsys
):
    """A session whose demonstration budget is spent (the driving protocol's 650) says so, and
    --resume teaches on past it instead of returning at once forever."""

    _scripted_corridor_person(monkeypatch)
    run = tmp_path / "session"
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "30"]) == 0
    out = capsys.readouterr().out
    assert "5 demonstrations over 5 steps" in out and "budget is reached" in out
    assert main(["teach", "corridor", "--run-dir", str(run), "--resume", "--steps", "10"]) == 0
    out = capsys.readouterr().out
    assert "over 15 steps" in out and "(--steps done)" in out
    assert len(load_records(run)) == 15
    # the person taught the reproduction's learner (its cap and variance floor)
    from corridor.experiment import CorridorExperimentConfig

    stored = json.loads((run / "config.json").read_text())
    model = stored["model"]["args"]
    cfg = CorridorExperimentConfig()
    assert (model["max_components"], model["var_floor"]) == (cfg.max_components, cfg.var_floor)
    # ... at the reproduction's threshold (2.83 std, not 2) on its robot and map, which the
    # session keeps, so that evaluate drives the robot the person taught
    assert stored["strategy"]["rule"] == cfg.rule().to_config()
    assert stored["env"]["kwargs"] == {
        "corridor_map": cfg.map_name,
        "world_config": dataclasses.asdict(cfg.world),
    }
    from corridor.experiment import evaluate_saved_policy

    report = evaluate_saved_policy(run, n_steps=5)
    assert report["world"] == dataclasses.asdict(cfg.world) and report["world"]["forward_noise"] > 0


def test_teach_resume_of_a_session_that_met_its_streak_says_it_is_done(
    tmp_path, monkeypatch, capsys
):
    """A session that stopped on its streak said "teaching is done; continue with: ...
    --resume", and that resume taught on until another streak. The session is done now: its
    end says how to evaluate it, and --resume is a one-line refusal saying so and what to do,
    before a step is taught."""
    from torchcbl import cli

    _scripted_corridor_person(monkeypatch, max_demonstrations=None)
    package, env_id, human, settings, model = cli._TEACH["corridor"]
    streak = {**settings, "accuracy_window": 3, "autonomous_steps_to_stop": 3}
    monkeypatch.setitem(cli._TEACH, "corridor", (package, env_id, human, streak, model))
    run = tmp_path / "session"
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "200"]) == 0
    out = capsys.readouterr().out
    assert (
        "teaching is done); evaluate it with: torchcbl evaluate " in out and "--resume" not in out
    )
    n = len(load_records(run))
    assert n < 200
    before = _bytes_of(run)
    assert main(["teach", "corridor", "--run-dir", str(run), "--resume", "--steps", "50"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1, captured
    assert captured.err.startswith(
        f"torchcbl teach: error: --resume: the session in {run} is done: the agent drove its "
        "last 3 steps on its own (autonomous_steps_to_stop=3), so there is nothing to resume"
    ), captured.err
    assert "--prior-demonstrations" in captured.err
    # a refused command changes nothing: the session was not opened as a writer (no line in
    # writers.jsonl for a writer with no step, no lock taken, no -wal or journal left)
    assert _bytes_of(run) == before
    assert len(load_records(run)) == n


def _done_corridor_session(run: Path, monkeypatch) -> None:
    """A corridor session taught by the scripted person until it met its streak (3 steps the
    agent drove on its own, with a window of 3): done, ``describe(run).streak_met`` set."""
    from torchcbl import cli, describe

    _scripted_corridor_person(monkeypatch, max_demonstrations=None)
    package, env_id, human, settings, model = cli._TEACH["corridor"]
    streak = {**settings, "accuracy_window": 3, "autonomous_steps_to_stop": 3}
    monkeypatch.setitem(cli._TEACH, "corridor", (package, env_id, human, streak, model))
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "200"]) == 0
    assert describe(run).streak_met == "autonomous_steps"


def test_teach_resume_of_a_done_session_in_the_other_domain_says_it_is_done(
    tmp_path, monkeypatch, capsys
):
    """`teach driving --resume` of a done corridor session said "resume it with torchcbl teach
    corridor --resume --run-dir ...", a command refused next as done. Where the session is
    done the domain mistake says so and gives the done refusal's ways on (evaluate it, or
    teach on from its demonstrations), each of which runs as printed; no file changes."""
    import shlex

    from torchcbl import describe

    run = tmp_path / "my runs" / "c1"
    run.parent.mkdir()
    _done_corridor_session(run, monkeypatch)
    capsys.readouterr()
    before = _bytes_of(run)
    assert main(["teach", "driving", "--resume", "--run-dir", str(run)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1, captured
    err = captured.err
    assert "is a corridor session" in err and "not a driving one" in err, err
    assert "is done: the agent drove its last 3 steps on its own" in err, err
    assert "--resume --run-dir" not in err, err
    assert _bytes_of(run) == before
    evaluate = shlex.split(re.search(r"\(torchcbl (evaluate [^)]*)\)", err)[1])
    assert main([*evaluate, "--steps", "5"]) == 0, capsys.readouterr().err
    capsys.readouterr()
    teach = shlex.split(re.search(r"\(torchcbl (teach [^)]*)\)", err)[1])
    assert teach[:2] == ["teach", "corridor"] and "--prior-demonstrations" in teach, teach
    new = tmp_path / "new"
    teach[teach.index("NEW_DIR")] = str(new)
    assert main([*teach, "--steps", "3"]) == 0, capsys.readouterr().err
    assert describe(new).n_prior == describe(run).n_labels


@pytest.mark.parametrize("what", ["missing", "empty"])
def test_show_and_teach_resume_of_no_session_say_how_to_start_one_at_the_command_line(
    tmp_path, monkeypatch, capsys, what
):
    """`torchcbl show` of a path that does not exist said to "start a session there with
    ConfidentTeacher(..., run_dir=...)", a Python call, and `teach --resume` of a path holding
    no session said only what it expected. Each says the command line's way now, in one line
    (exit 2): show names `torchcbl teach corridor --run-dir PATH`, teach --resume says to
    leave --resume out; the commands run as printed and start a session there."""
    import shlex

    _scripted_corridor_person(monkeypatch)
    run = tmp_path / "my runs" / "it's"
    if what == "empty":
        run.mkdir(parents=True)

    def one_line(argv: list[str]) -> str:
        assert main(argv) == 2
        captured = capsys.readouterr()
        assert captured.out == "" and captured.err.count("\n") == 1, captured
        assert "ConfidentTeacher" not in captured.err, captured.err
        return captured.err

    said = one_line(["teach", "corridor", "--resume", "--run-dir", str(run), "--steps", "3"])
    assert "so there is no session to resume" in said, said
    told = said.rsplit("leave out --resume to start a new session there: ", 1)[1].strip()
    assert shlex.split(told) == ["torchcbl", "teach", "corridor", "--run-dir", str(run)], told
    if what == "missing":
        assert f"(relative paths are taken from the working directory, {os.getcwd()})" in said
        said = one_line(["show", str(run)])
        assert f"{run} does not exist" in said and os.getcwd() in said, said
        told = said.rsplit("or start a session there: ", 1)[1]
        command, other = told.rsplit(" (or ", 1)
        assert other.strip() == "teach driving)", told
        assert shlex.split(command) == ["torchcbl", "teach", "corridor", "--run-dir", str(run)]
        # a '~' the shell did not expand: no session is offered in a folder named '~'
        for argv in (["show", "~/nowhere"], ["teach", "corridor", "--resume", "--run-dir", "~/n"]):
            said = one_line(argv)
            assert "a '~' in quotes is not expanded" in said and "teach corridor --" not in said
    assert not run.exists() or not any(run.iterdir())  # nothing written
    assert main([*shlex.split(told.split(" (or ")[0])[1:], "--steps", "3"]) == 0
    assert len(load_records(run)) == 3


def test_teach_resume_of_a_folder_of_ones_own_files_does_not_offer_a_start_there(
    tmp_path, monkeypatch, capsys
):
    """`teach --resume` of a folder holding no session says to leave out --resume only where
    a new session may start; a folder of one's own files (x.txt) is refused for a start too,
    so the resume's refusal does not offer it: it says that no new session can start there
    either, why, and what to do (another --run-dir, new or empty). Each command is one line
    (exit 2) and the folder is left as it was."""
    _scripted_corridor_person(monkeypatch)
    run = tmp_path / "mine"
    run.mkdir()
    (run / "x.txt").write_text("my notes\n")
    before = _bytes_of(run)
    start_refused = f"{run} holds other files (x.txt) and no session"
    for argv, says in (
        (["--resume"], f"--resume: there is no session to resume in {run} (it holds no "),
        (["--resume"], "no new session can start there either: " + start_refused),
        (["--resume"], "new or empty: choose another --run-dir"),
        (["--steps", "3"], start_refused),
    ):
        assert main(["teach", "corridor", "--run-dir", str(run), *argv]) == 2
        captured = capsys.readouterr()
        assert captured.out == "" and captured.err.count("\n") == 1, captured
        assert says in captured.err and "leave out --resume" not in captured.err, captured.err
    assert _bytes_of(run) == before


def test_teach_resume_of_a_session_log_without_its_config_says_to_put_it_back(
    tmp_path, monkeypatch, capsys
):
    """`teach --resume` of a folder holding a session's log but no config.json (moved away)
    says to put the config back, not only that the folder is no session: one line, exit 2,
    the folder unchanged."""
    _scripted_corridor_person(monkeypatch)
    run = tmp_path / "lost"
    run.mkdir()
    (run / "steps.sqlite").write_bytes(b"")
    before = _bytes_of(run)
    assert main(["teach", "corridor", "--resume", "--run-dir", str(run)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1, captured
    assert "no new session can start there either" in captured.err, captured.err
    assert "Put it back to continue that session" in captured.err, captured.err
    assert _bytes_of(run) == before


def _bytes_of(run: Path) -> dict[str, tuple[bytes | None, int]]:
    """{relative path: (its bytes, None for a folder; its mtime in ns)} of ``run`` and
    everything under it (a file written again with the same bytes, or one made and removed
    in a folder, changes an mtime)."""
    return {
        str(p.relative_to(run)): (p.read_bytes() if p.is_file() else None, p.stat().st_mtime_ns)
        for p in sorted([run, *run.rglob("*")])
    }


def test_teach_resume_under_another_pymunk_says_so_in_one_line(tmp_path, monkeypatch, capsys):
    """A resume under another simulator release than the session's last writer ran warns
    (UserWarning); `teach --resume` left it to Python, which printed it as the file and line
    of the library's warn call and that line's source. It is one line on stderr now, and the
    session goes on (not a refusal)."""
    import corridor.env

    _scripted_corridor_person(monkeypatch)
    run = tmp_path / "session"
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "3"]) == 0
    ran = corridor.env.pymunk_versions()["pymunk"]
    monkeypatch.setattr(corridor.env, "pymunk_versions", lambda: {"pymunk": "6.0.0"})
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("default")  # as Python shows a UserWarning by default
        assert main(["teach", "corridor", "--run-dir", str(run), "--resume", "--steps", "2"]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith("torchcbl teach: warning: "), err
    assert f"pymunk {ran}" in err and "pymunk 6.0.0" in err and "steps from 3 on" in err, err
    assert len(load_records(run)) == 5


def test_teach_resume_says_each_of_its_warnings_in_a_line_of_its_own(tmp_path, monkeypatch, capsys):
    """Every warning a resume gives is said, one line each: here the env's describe_versions()
    warns on its own (a simulator's binding saying something as it is asked its release) and
    the release differs from the last writer's, so two lines, the version change among them."""
    import corridor.env

    _scripted_corridor_person(monkeypatch)
    run = tmp_path / "session"
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "3"]) == 0

    def versions() -> dict[str, str]:
        warnings.warn("pymunk: this build is a test build", UserWarning, stacklevel=2)
        return {"pymunk": "6.0.0"}

    monkeypatch.setattr(corridor.env, "pymunk_versions", versions)
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("default")  # as Python shows a UserWarning by default
        assert main(["teach", "corridor", "--run-dir", str(run), "--resume", "--steps", "2"]) == 0
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2 and all(ln.startswith("torchcbl teach: warning: ") for ln in lines)
    assert lines[0].endswith("pymunk: this build is a test build"), lines
    assert "pymunk 6.0.0" in lines[1] and "steps from 3 on" in lines[1], lines
    assert len(load_records(run)) == 5


def test_ctrl_c_between_two_requests_stops_as_at_a_request(tmp_path, monkeypatch, capsys):
    """Ctrl-C (the help's "[q/Ctrl-C] quit") pressed while no key is awaited (the env steps, the
    agent drives on its own between two requests) ended with "torchcbl teach: interrupted" and
    exit code 130: no word that the demonstrations were saved, nor how to continue. It now
    stops as at a request."""
    import signal

    from corridor.env import CorridorEnv

    _scripted_corridor_person(monkeypatch, max_demonstrations=None)
    step, calls = CorridorEnv.step, []

    def step_then_ctrl_c(self, action):
        calls.append(action)
        if len(calls) == 7:  # Ctrl-C lands while the env steps, as it mostly would
            signal.raise_signal(signal.SIGINT)
        return step(self, action)

    monkeypatch.setattr(CorridorEnv, "step", step_then_ctrl_c)
    run = tmp_path / "session"
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "30"]) == 0
    captured = capsys.readouterr()
    assert "interrupted" not in captured.err
    assert "Stopped by the teacher" in captured.out
    assert "7 demonstrations over 7 steps saved in" in captured.out and "--resume" in captured.out
    assert len(load_records(run)) == 7
    assert main(["teach", "corridor", "--run-dir", str(run), "--resume", "--steps", "3"]) == 0
    assert len(load_records(run)) == 10


def test_a_resumed_session_shows_its_counts_from_its_first_request(tmp_path, monkeypatch):
    """The status line (step, phase, demonstrations, accuracy, autonomy) was set after each
    step only, so the first request of a resumed session showed a bare "decision #1": the
    person coming back saw neither how many demonstrations they had given nor the phase."""
    import corridor.human

    _scripted_corridor_person(monkeypatch)
    seen = []

    class Person:
        status = ""

        def __call__(self, observation, info):
            seen.append(self.status)
            return 0

        def set_status(self, text):
            self.status = text

    run = tmp_path / "session"
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "3"]) == 0
    monkeypatch.setattr(corridor.human, "make_teacher", lambda **kw: Person())
    assert main(["teach", "corridor", "--run-dir", str(run), "--resume", "--steps", "1"]) == 0
    assert seen and "step 3 " in seen[0] and "demonstrations 3 " in seen[0], seen
    assert "phase noninteractive" in seen[0]


def test_a_resumed_session_numbers_its_decisions_on_from_the_stored_ones(
    tmp_path, monkeypatch, capsys
):
    """The status line's "decision #N" counted this process's answers only: the first request
    of `teach --resume` after 3 answered ones said "decision #1" beside "demonstrations 3". It
    goes on from the session's answered requests now (4, 5)."""
    run = tmp_path / "session"
    monkeypatch.setattr(sys, "stdin", io.StringIO("w\nw\nw\n"))
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "3"]) == 0
    assert "decision #3 | step 2 " in capsys.readouterr().out
    monkeypatch.setattr(sys, "stdin", io.StringIO("w\nw\n"))
    assert main(["teach", "corridor", "--run-dir", str(run), "--resume", "--steps", "2"]) == 0
    shown = re.findall(
        r"decision #(\d+) \| step (\d+) \| .*demonstrations (\d+) ", capsys.readouterr().out
    )
    assert shown == [("4", "3", "3"), ("5", "4", "4")], shown


def test_a_resumed_session_says_where_it_stands_before_the_agent_drives(
    tmp_path, monkeypatch, capsys
):
    """teach --resume printed nothing until its first request: a session whose agent was sure
    everywhere drove its --steps on its own and printed only its last line, so the person who
    came back saw a silent terminal, then the end, never where the session had stood nor that
    a new episode began. It now says so before the first step."""
    _scripted_corridor_person(monkeypatch)
    run = tmp_path / "session"
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "3"]) == 0
    capsys.readouterr()
    assert main(["teach", "corridor", "--run-dir", str(run), "--resume", "--steps", "2"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith(f"Resuming the session in {run} at step 3"), first
    assert "3 demonstrations" in first and "phase noninteractive" in first
    assert "new episode" in first and "2 more steps" in first


@pytest.mark.parametrize("skip", [False, True], ids=["noninteractive", "confident"])
def test_a_resumed_session_says_what_the_agent_does_in_its_phase(
    tmp_path, monkeypatch, capsys, skip
):
    """teach --resume said "phase noninteractive ...: the agent acts on its own where it is
    sure and asks you where it is not", while in that phase it asks at every step. It says
    what the phase it names does: asking at every step until the accuracy window (20 of the
    corridor's) reaches its target (90%), or, in confident execution, acting where sure."""
    _scripted_corridor_person(monkeypatch)
    run = tmp_path / "session"
    start = ["teach", "corridor", "--run-dir", str(run), "--steps", "3"]
    assert main([*start, *(["--skip-noninteractive"] if skip else [])]) == 0
    capsys.readouterr()
    assert main(["teach", "corridor", "--run-dir", str(run), "--resume", "--steps", "2"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    if skip:
        assert "phase confident" in first, first
        assert "the agent acts on its own where it is sure and asks you where it is not" in first
        assert "every step" not in first, first
    else:
        assert "phase noninteractive" in first, first
        assert "episode: the agent asks you at every step until its prediction accuracy" in first
        assert "your last 20 demonstrations reaches 90%, then acts on its own" in first, first


@pytest.mark.parametrize(
    ("typed", "said"),
    [("w\nw\n", "Stopped: the input ended"), ("w\nq\n", "Stopped by the teacher.")],
    ids=["input-ends", "q"],
)
def test_teach_says_whether_the_person_stopped_or_the_input_ended(
    tmp_path, monkeypatch, capsys, typed, said
):
    """Keys piped in (a script, a notebook-like stdin) that ran out ended with "Stopped by the
    teacher.", as if the person had pressed q: nothing said that the input had ended."""
    monkeypatch.setattr(sys, "stdin", io.StringIO(typed))
    run = tmp_path / "session"
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "10"]) == 0
    out = capsys.readouterr().out
    assert said in out, out
    n = typed.count("w")  # each key before the end kept
    assert f"{n} demonstration{'' if n == 1 else 's'} over" in out
    assert ("Stopped by the teacher" in out) == (said == "Stopped by the teacher.")


@pytest.mark.parametrize("stdin", ["devnull", "closed-pipe", "closed"])
def test_teach_on_an_input_that_has_ended_stops_at_its_first_request(
    tmp_path, monkeypatch, capsys, stdin
):
    """stdin at its end (`< /dev/null`, a pipe whose writer is gone after one key, fd 0 closed:
    Python's sys.stdin None) stops teach at the first request it cannot answer, as q would:
    one line saying so, exit code 0, the answers read before it kept."""
    if stdin == "devnull":
        source = open(os.devnull, encoding="utf-8")  # noqa: SIM115 - closed below
    elif stdin == "closed-pipe":
        read_fd, write_fd = os.pipe()
        os.write(write_fd, b"w\n")
        os.close(write_fd)
        source = os.fdopen(read_fd)
    else:
        source = None
    monkeypatch.setattr(sys, "stdin", source)
    run = tmp_path / "session"
    try:
        assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "10"]) == 0
    finally:
        if source is not None:
            source.close()
    out = capsys.readouterr().out
    assert "\nStopped: the input ended, no key left to read.\n" in out, out
    n = 1 if stdin == "closed-pipe" else 0
    assert f"{n} demonstration{'' if n == 1 else 's'} over {n} step" in out, out
    assert len(load_records(run)) == n


def _corridor_prior(path: Path, n_steps: int) -> Path:
    """The corridor's scripted teleoperator's labels over its first ``n_steps`` from seed 0, as
    a .npz for --prior-demonstrations. On a session of seed 0 started in confident execution,
    400 make the agent sure enough to drive 150 steps on its own; 30 make it drive about 45
    steps on its own, then ask now and then (seen)."""
    import gymnasium as gym

    from corridor.benchmark import teacher
    from corridor.experiment import teaching_setup

    env = gym.make("torchcbl/Corridor-v0", **teaching_setup()[0])
    try:
        expert = teacher(env)
        obs, info = env.reset(seed=0)
        observations, actions = [], []
        for _ in range(n_steps):
            action = expert(obs, info)
            observations.append(obs)
            actions.append(action)
            obs, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                obs, info = env.reset()
    finally:
        env.close()
    np.savez(path, observations=np.array(observations), actions=np.array(actions))
    return path


class _PersonAtATerminal(threading.Thread):
    """`torchcbl teach` run in a pseudo-terminal (its stdin and stdout), and the person at it:
    reads all it shows, answers each request ("action? ") with "w" (forward), and types a key
    at an env step of the agent's (:meth:`type_at`), returning once the terminal has echoed it
    (Ctrl-D, which it does not echo, once its line is there to read), so the key waits in the
    terminal's input as one typed then would."""

    def __init__(self, monkeypatch) -> None:
        super().__init__(daemon=True)
        self.master, self.slave = pty.openpty()
        self.shown = bytearray()
        self.lock = threading.Lock()
        self.done = threading.Event()
        self.before = termios.tcgetattr(self.slave)
        monkeypatch.setattr(sys, "stdin", open(self.slave, encoding="utf-8", closefd=False))  # noqa: SIM115
        monkeypatch.setattr(sys, "stdout", open(self.slave, "w", encoding="utf-8", closefd=False))  # noqa: SIM115
        self.start()

    def run(self) -> None:
        answered = 0
        while not self.done.is_set():
            if select.select([self.master], [], [], 0.02)[0]:
                try:
                    chunk = os.read(self.master, 4096)
                except OSError:
                    return
                with self.lock:
                    self.shown += chunk
                    asks = self.shown.count(b"action? ")
                if asks > answered:
                    os.write(self.master, b"w")
                    answered += 1

    def type_at(self, monkeypatch, typed: dict[int, bytes]) -> None:
        """Type ``typed[k]`` while the env takes the agent's k-th step (from 1)."""
        from corridor.env import CorridorEnv

        step, calls = CorridorEnv.step, []

        def step_and_type(env, action):
            calls.append(action)
            key = typed.get(len(calls))
            if key is not None:
                with self.lock:
                    start = len(self.shown)
                os.write(self.master, key)
                echoed = key.replace(b"\x04", b"")  # Ctrl-D ends a line, unechoed

                def there() -> bool:
                    with self.lock:
                        seen = echoed in self.shown[start:]
                    ended = b"\x04" not in key or select.select([self.slave], [], [], 0)[0]
                    return seen and bool(ended)

                deadline = time.monotonic() + 20
                while not there() and time.monotonic() < deadline:
                    time.sleep(0.005)
                assert there(), "the terminal never echoed the key"
            return step(env, action)

        monkeypatch.setattr(CorridorEnv, "step", step_and_type)

    def finish(self) -> str:
        sys.stdout.flush()
        time.sleep(0.05)
        self.done.set()
        self.join(timeout=10)
        while select.select([self.master], [], [], 0.05)[0]:
            try:
                chunk = os.read(self.master, 4096)
            except OSError:
                break
            self.shown += chunk
        after = termios.tcgetattr(self.slave)
        for fd in (self.master, self.slave):
            os.close(fd)
        assert after == self.before  # the terminal is left as it was
        return self.shown.decode(errors="replace")


def _teach_corridor_at_a_terminal(tmp_path, monkeypatch, n_prior, steps, keys):
    """``teach corridor`` on a pseudo-terminal, confident execution from ``n_prior`` prior
    demonstrations, with ``keys`` typed at the given steps (see _PersonAtATerminal); returns
    the exit code, what the terminal showed, the run directory and the command (without its
    --skip-noninteractive and --prior-demonstrations)."""
    prior = _corridor_prior(tmp_path / "prior.npz", n_prior)
    person = _PersonAtATerminal(monkeypatch)
    person.type_at(monkeypatch, keys)
    run = tmp_path / "session"
    argv = ["teach", "corridor", "--run-dir", str(run), "--steps", str(steps)]
    try:
        code = main([*argv, "--skip-noninteractive", "--prior-demonstrations", str(prior)])
    finally:
        shown = person.finish()
    return code, shown, run, argv


@pytest.mark.timeout(60)
def test_q_typed_while_the_agent_drives_on_its_own_stops_the_run_then(tmp_path, monkeypatch):
    """The key legend's "[q/Ctrl-C] quit": q typed while the agent drove on its own (between two
    requests, the terminal in line mode and nothing reading it) acted only at the next request,
    so an agent sure of itself drove all of --steps with the person's q on the screen; only
    Ctrl-C stopped it. q now stops the run after the step under way is logged, as at a request:
    same words, exit code 0, and the session resumes."""
    code, shown, run, argv = _teach_corridor_at_a_terminal(
        tmp_path, monkeypatch, 400, 150, {10: b"q"}
    )
    assert code == 0, shown
    assert "action?" not in shown  # the agent drove on its own throughout
    assert "Stopped by the teacher." in shown, shown
    assert "0 demonstrations over 10 steps saved in" in shown and "--resume" in shown, shown
    assert len(load_records(run)) == 10  # the step under way when q was typed, logged whole
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))  # (the terminal is closed by now)
    monkeypatch.setattr(sys, "stdout", io.StringIO())
    assert main([*argv[:4], "--resume", "--steps", "3"]) == 0, sys.stdout.getvalue()
    assert len(load_records(run)) == 13


@pytest.mark.timeout(60)
@pytest.mark.parametrize("typed", [b"\x04", b"d\x04"], ids=["ctrl-d", "key-then-ctrl-d"])
def test_ctrl_d_typed_while_the_agent_drives_on_its_own_stops_the_run_then(
    tmp_path, monkeypatch, typed
):
    """Ctrl-D (end of input) typed while the agent drove on its own was dropped: the agent
    drove on through all of --steps, and the next request would have waited for a key. It
    stops the run after the step under way, as q does: same words, exit code 0, every step
    and demonstration so far saved, and the session resumes."""
    code, shown, run, argv = _teach_corridor_at_a_terminal(
        tmp_path, monkeypatch, 30, 80, {60: typed}
    )
    assert code == 0, shown
    assert "Stopped by the teacher." in shown, shown
    records = load_records(run)
    assert len(records) == 60  # the step under way when Ctrl-D was typed, logged whole
    asked = [r for r in records if r.teacher_action is not None]
    assert asked and records[-1].teacher_action is None  # taught, then typed as the agent drove
    assert f"{len(asked)} demonstrations over 60 steps saved in" in shown, shown
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))  # (the terminal is closed by now)
    monkeypatch.setattr(sys, "stdout", io.StringIO())
    assert main([*argv[:4], "--resume", "--steps", "3"]) == 0, sys.stdout.getvalue()
    assert len(load_records(run)) >= 60


@pytest.mark.timeout(60)
def test_a_key_other_than_q_typed_while_the_agent_drives_on_its_own_is_not_acted_on(
    tmp_path, monkeypatch
):
    """ "d" (turn right) typed while the agent drives on its own neither stops the run nor
    answers the next request: the person answers that one ("w", forward) after seeing it."""
    code, shown, run, _ = _teach_corridor_at_a_terminal(tmp_path, monkeypatch, 30, 80, {5: b"d"})
    assert code == 0, shown
    assert "(--steps done)" in shown, shown
    records = load_records(run)
    asked = [r for r in records if r.teacher_action is not None]
    assert len(records) == 80 and asked and asked[0].step > 5, len(asked)
    assert {r.teacher_action for r in asked} == {0}  # each request answered by its own "w"


def _recorded_episodes(path: Path) -> Path:
    """An episodes.json of one 5-step driving episode, as the driving experiment writes."""
    from sumo_scenarios.env import DrivingEnv
    from sumo_scenarios.replay import EpisodeRecorder, save_records

    env = EpisodeRecorder(DrivingEnv(scenario="eval", max_episode_steps=5), label="demo/a")
    try:
        env.reset(seed=0)
        for _ in range(5):
            env.step(0)
    finally:
        env.close()
    save_records(env.episodes, path)
    return path


def test_replay_never_writes_over_the_recording_it_replays(tmp_path, capsys):
    """--gif or --fcd naming the episodes file, a file of the session being replayed, or each
    other (or the .sumocfg / fcd-replay input written beside the FCD): one line, exit code 2,
    nothing written. (--fcd EPISODES.json wrote the FCD over the recorded episodes.)"""
    import gymnasium as gym

    import sumo_scenarios  # noqa: F401  (registers torchcbl/Driving-v0)
    from sumo_scenarios.teacher import make_teacher
    from torchcbl import ConfidentTeacher

    episodes = _recorded_episodes(tmp_path / "episodes.json")
    run = tmp_path / "session"
    env = gym.make("torchcbl/Driving-v0", scenario="light", max_episode_steps=5)
    with ConfidentTeacher(env, make_teacher(0), run_dir=run, progress=False) as ct:
        ct.run(max_steps=5)
    files = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    ep, a = str(episodes), tmp_path / "a"
    clash = "one output would overwrite the other"
    for argv, says in (
        ([ep, "--fcd", ep], "is the episodes file being replayed"),
        ([str(run), "--fcd", str(run / "steps.sqlite")], "is a file of the session"),
        ([str(run), "--fcd", str(run / "config.json")], "is a file of the session"),
        ([ep, "--gif", f"{a}.gif", "--fcd", f"{a}.gif"], clash),
    ):
        assert main(["replay", *argv, "--max-frames", "2"]) == 2, argv
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1, (argv, err)
        assert says in err, (argv, err)
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == files
    assert main(["replay", str(episodes), "--max-frames", "2"]) == 0  # the defaults, beside it
    assert episodes.read_bytes() == files[episodes]


def test_replay_refuses_a_sumocfg_or_replay_input_path_that_is_a_directory(tmp_path, capsys):
    """The .sumocfg (EP.sumocfg) or the fcd-replay input (EP.replay.xml) written beside --fcd
    EP.fcd.xml is a directory: one line, exit code 2, nothing written. (The FCD was written
    first, and only then was the .sumocfg refused; a replay input that was a directory ended
    in a bare IsADirectoryError.)"""
    episodes = _recorded_episodes(tmp_path / "episodes.json")
    fcd = tmp_path / "ep.fcd.xml"
    for name in ("ep.sumocfg", "ep.replay.xml"):
        (tmp_path / name).mkdir()
        files = sorted(p.name for p in tmp_path.iterdir())
        argv = ["replay", str(episodes), "--fcd", str(fcd), "--max-frames", "2"]
        assert main(argv) == 2, name
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1, (name, out, err)
        assert f"{tmp_path / name}, is a directory; expected a file path" in err, (name, err)
        assert sorted(p.name for p in tmp_path.iterdir()) == files, name
        (tmp_path / name).rmdir()


def test_replay_to_a_gzipped_fcd_writes_a_sumocfg_that_sumo_runs(tmp_path, capsys):
    """--fcd EP.fcd.xml.gz (SUMO writes a gzipped FCD for a name ending in .gz): the FCD, a
    .sumocfg named EP.sumocfg and the GIF are written, and `sumo -c` replays the recorded
    positions. (The replay stopped after the FCD with 'ParseError: not well-formed (invalid
    token): line 1, column 0': the .sumocfg's writer read the gzipped file as plain XML.)"""
    import gzip
    import xml.etree.ElementTree as ET

    episodes = _recorded_episodes(tmp_path / "episodes.json")
    fcd = tmp_path / "ep.fcd.xml.gz"
    gif = tmp_path / "ep.gif"
    argv = ["replay", str(episodes), "--fcd", str(fcd), "--gif", str(gif), "--max-frames", "2"]
    assert main(argv) == 0, capsys.readouterr().err
    assert fcd.read_bytes()[:2] == b"\x1f\x8b" and gif.stat().st_size > 0
    cfg = tmp_path / "ep.sumocfg"
    assert f"SUMO configuration written to {cfg}" in capsys.readouterr().out
    sumo = Path(sys.executable).with_name("sumo")
    out = subprocess.run(
        [str(sumo), "-c", str(cfg)], capture_output=True, text=True, timeout=60, check=False
    )
    assert out.returncode == 0, out.stderr

    def rows(root: ET.Element) -> dict[tuple[str | None, str | None], tuple]:
        return {
            (ts.get("time"), v.get("id")): (v.get("x"), v.get("lane"), v.get("pos"))
            for ts in root.iter("timestep")
            for v in ts.iter("vehicle")
        }

    with gzip.open(fcd) as f:
        recorded = rows(ET.parse(f).getroot())
    rerun = rows(ET.parse(tmp_path / "ep.rerun.xml").getroot())
    assert len(recorded) > 5 and all(rerun.get(k) == v for k, v in recorded.items())


def test_replay_gif_path_must_name_a_gif(tmp_path):
    """--gif without .gif: one line, exit code 2 and nothing written. (The image writer, which
    picks its format by the name, failed after the FCD and .sumocfg were written, with a
    warning and an "Exception ignored ... Traceback" on stderr, and left an empty file.)"""
    episodes = _recorded_episodes(tmp_path / "episodes.json")
    for name in ("replay", "replay.png"):
        proc = subprocess.run(
            [str(BIN), "replay", str(episodes), "--gif", str(tmp_path / name), "--max-frames", "2"],
            capture_output=True,
            text=True,
            env={**os.environ, "TORCHCBL_TRACEBACK": ""},
        )
        assert proc.returncode == 2 and proc.stdout == "", (name, proc)
        assert proc.stderr.count("\n") == 1, (name, proc.stderr)
        assert "expected a file name ending in .gif" in proc.stderr
        assert sorted(p.name for p in tmp_path.iterdir()) == ["episodes.json"]
    assert (
        main(["replay", str(episodes), "--gif", str(tmp_path / "r.GIF"), "--max-frames", "2"]) == 0
    )
    assert (tmp_path / "r.GIF").stat().st_size > 0


# where each domain's seed k saves its models (only inside its teaching loop)
_CHECKPOINTS = {
    "corridor": "corridor/sessions/seed{k}/checkpoints",
    "driving": "driving/seed_{k}/sessions/arm_a/checkpoints",
}


@pytest.mark.parametrize("domain", ["corridor", "driving"])
def test_ctrl_c_during_a_run_with_worker_processes_is_one_line(domain, tmp_path):
    """Ctrl-C at a terminal (SIGINT to the whole process group) while two worker processes
    teach: exit code 130 and the one line "interrupted". (corridor: the workers, terminated,
    left the multiprocessing lock of their tqdm bars behind, and the resource tracker added a
    two-line "leaked semaphore objects" warning; driving: a worker of the multiprocessing.Pool
    that took the SIGINT printed its traceback, in most runs.)"""
    import signal

    out = tmp_path / "runs"
    proc = subprocess.Popen(
        [str(BIN), "reproduce", domain, "--seeds", "2", "--workers", "2", "--no-progress"]
        + ["--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
        start_new_session=True,  # a process group of its own, as a terminal's job
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        env={**os.environ, "TORCHCBL_TRACEBACK": ""},
    )
    try:
        deadline = time.monotonic() + 300
        # both workers are teaching
        while not all(any((out / _CHECKPOINTS[domain].format(k=k)).glob("*.pt")) for k in (0, 1)):
            assert proc.poll() is None and time.monotonic() < deadline, proc.poll()
            time.sleep(0.1)
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, err
    assert err == (
        "torchcbl reproduce: interrupted (its finished seeds are kept: go on with the same "
        f"command plus --resume --out {out})\n"
    )


def _unwritable_directory(tmp_path: Path) -> Path:
    """A directory no file can be made in: a read-only one of the test's own, or, for root
    (whom permission bits do not stop), Linux's /sys."""
    import tempfile

    if os.geteuid() != 0:
        readonly = tmp_path / "readonly"
        readonly.mkdir()
        readonly.chmod(0o555)
        return readonly
    try:
        tempfile.TemporaryFile(dir="/sys").close()
    except OSError:
        return Path("/sys")
    pytest.skip("no directory here that this user cannot write to")


def test_an_output_directory_that_cannot_be_written_is_refused_before_the_run(tmp_path):
    """--out, --run-dir, --gif and --fcd where no file can be made: exit code 2 and one line
    that names the directory, before anything runs. (The run started and failed at its first
    file, exit code 1 with the bare OSError; replay --gif wrote the FCD and .sumocfg first and
    then added imageio's "Exception ignored ... Traceback" to stderr.)"""
    locked = _unwritable_directory(tmp_path)
    episodes = _recorded_episodes(tmp_path / "episodes.json")
    cases = [
        ["reproduce", "corridor", "--seeds", "1", "--out", str(locked / "runs")],
        ["benchmark", "--quick", "--envs", "corridor", "--seeds", "1"]
        + ["--strategies", "bc", "--out", str(locked / "bench")],
        ["teach", "corridor", "--steps", "3", "--run-dir", str(locked / "session")],
        ["replay", str(episodes), "--max-frames", "2", "--gif", str(locked / "r.gif")],
        ["replay", str(episodes), "--max-frames", "2", "--fcd", str(locked / "r.fcd.xml")],
    ]
    for argv in cases:
        proc = subprocess.run(
            [str(BIN), *argv],
            capture_output=True,
            text=True,
            stdin=subprocess.DEVNULL,
            env={**os.environ, "TORCHCBL_TRACEBACK": ""},
        )
        assert proc.returncode == 2 and proc.stdout == "", (argv, proc)
        assert proc.stderr.count("\n") == 1, (argv, proc.stderr)
        assert f"cannot write in {locked}" in proc.stderr, (argv, proc.stderr)
    assert sorted(p.name for p in tmp_path.iterdir() if p != locked) == ["episodes.json"]


@pytest.mark.parametrize("budgets", ["20,10", "10,10"])
def test_benchmark_budgets_not_increasing_are_refused_as_the_option_given(
    budgets, tmp_path, capsys, monkeypatch
):
    """--budgets 20,10 (or 10,10): exit code 2 and one line naming --budgets and what was
    typed, before anything runs or is written (not an error about the --gym-env's EnvSpec,
    an option the user got right)."""
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parent))  # tests/_bench_env.py
    out = tmp_path / "bench"
    argv = ["benchmark", "--envs", "", "--gym-env", "_bench_env:BenchCluster-v0"]
    argv += ["--teacher", "_bench_env:teacher", "--strategies", "bc", "--seeds", "1"]
    argv += ["--workers", "1", "--budgets", budgets, "--max-steps", "30", "--out", str(out)]
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own refusal
        code = exc.code
    stdout, err = capsys.readouterr()
    assert code == 2 and stdout == "" and err.count("\n") == 1, (code, stdout, err)
    assert "argument --budgets: expected increasing" in err, err
    assert f"got {budgets!r}" in err, err
    assert not out.exists()


def test_benchmark_names_a_non_strategy_by_its_type_not_its_repr(tmp_path, capsys):
    """--strategies builtins:object: the one line names the spec as written and the type, and
    which methods it lacks, not the object's repr. (It said "got <object object at
    0x7f46531362f0> without bind()": a memory address, different in every run.)"""
    out = tmp_path / "bench"
    assert main(["benchmark", "--strategies", "builtins:object", "--out", str(out)]) == 2
    stdout, err = capsys.readouterr()
    assert stdout == "" and err.count("\n") == 1, err
    assert "--strategies builtins:object: object is not a strategy" in err, err
    assert " at 0x" not in err and "<object" not in err, err
    assert "it has no bind(), episode_start(), decide()" in err, err
    assert not out.exists()


@pytest.mark.parametrize(
    "argv, says",
    [
        (["--strategies", "nope:Thing"], "--strategies nope:Thing: cannot import it (No module"),
        (["--strategies", ".rel:X"], "--strategies .rel:X: cannot make it (TypeError"),
        (
            ["--strategies", "torchcbl.gmm:GaussianMixtureSet"],
            "--strategies torchcbl.gmm:GaussianMixtureSet: cannot make it (TypeError",
        ),
        (
            ["--strategies", "collections:OrderedDict"],
            "--strategies collections:OrderedDict: OrderedDict is not a strategy",
        ),
        (["--strategies", ",,"], "--strategies ',,' names no strategy"),
        (
            ["--envs", "driving", "--driving-teacher", "expert"],
            "--driving-teacher expert: expected",
        ),
        (
            ["--envs", "driving", "--driving-teacher", "nope:x"],
            "--driving-teacher nope:x: No module",
        ),
    ],
)
def test_benchmark_checks_strategy_and_teacher_paths_before_the_run(argv, says, tmp_path, capsys):
    """An import path of --strategies or --driving-teacher that gives no strategy / teacher:
    one line naming the option, exit code 2, nothing printed or written. (A class that needs
    arguments, a relative name or a non-strategy failed with exit code 1 after the run's header
    was printed, some leaving an empty OUT/cells behind; a missing module's error named no
    option.)"""
    out = tmp_path / "bench"
    args = ["benchmark", "--quick", "--envs", "corridor", "--seeds", "1", "--out", str(out)]
    assert main([*args, *argv]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1, captured
    assert captured.err.startswith(f"torchcbl benchmark: error: {says}"), captured.err
    assert not out.exists()


def test_the_commands_teach_says_to_run_work_for_a_path_with_a_space(tmp_path, monkeypatch, capsys):
    """The "continue with: torchcbl teach ..." line (and the "resume it with" of a domain
    mistake) is a command that runs as printed: a --run-dir with a space or a quote is quoted.
    (It was printed bare, so a copied `--run-dir my runs/it's` was three words and a quote.)"""
    import shlex

    _scripted_corridor_person(monkeypatch)
    run = tmp_path / "my runs" / "it's"
    run.parent.mkdir()
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "3"]) == 0
    told = capsys.readouterr().out.rsplit("continue with: ", 1)[1].strip()
    argv = shlex.split(told)
    assert argv[:2] == ["torchcbl", "teach"] and argv[argv.index("--run-dir") + 1] == str(run)
    assert main([*argv[1:], "--steps", "3"]) == 0  # it resumes the session
    assert len(load_records(run)) == 6
    capsys.readouterr()
    assert main(["teach", "driving", "--resume", "--run-dir", str(run)]) == 2
    told = capsys.readouterr().err.rsplit("resume it with ", 1)[1].strip()
    assert shlex.split(told)[1:] == ["teach", "corridor", "--resume", "--run-dir", str(run)]


def _teach_on_a_map_file(tmp_path, monkeypatch) -> tuple[Path, Path, str]:
    """teach corridor --map tmp_path/mine.json (a copy of lshape) for 3 steps; returns the
    map file, the session directory and the map's text."""
    import corridor

    _scripted_corridor_person(monkeypatch)
    mine = tmp_path / "mine.json"
    original = Path(corridor.__file__).with_name("maps").joinpath("lshape.json").read_text()
    mine.write_text(original)
    run = tmp_path / "session"
    assert (
        main(["teach", "corridor", "--run-dir", str(run), "--map", str(mine), "--steps", "3"]) == 0
    )
    return mine, run, original


def _evaluate_and_resume_refuse(run: Path, capsys) -> list[str]:
    """evaluate and teach --resume of the session in ``run``, each refused in one line with exit
    code 2: their stderr."""
    capsys.readouterr()
    said = []
    for argv in (
        ["evaluate", str(run), "--steps", "3"],
        ["teach", "corridor", "--resume", "--run-dir", str(run), "--steps", "3"],
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1, err
        said.append(err)
    return said


def test_a_session_whose_own_map_file_moved_says_to_put_it_back(tmp_path, monkeypatch, capsys):
    """teach corridor --map PATH keeps the map by its full path; once the file is moved,
    evaluate and teach --resume say so in one line (exit code 2) and that the file goes back
    there. (teach --resume failed with exit code 1 and, like evaluate, told the user to "give
    an existing map JSON file", which neither command takes for a session.)"""
    mine, run, _ = _teach_on_a_map_file(tmp_path, monkeypatch)
    mine.rename(tmp_path / "moved.json")
    for err in _evaluate_and_resume_refuse(run, capsys):
        assert f"taught on the map file {mine}" in err, err
        assert "put that file back there" in err
    assert len(load_records(run)) == 3
    (tmp_path / "moved.json").rename(mine)
    assert main(["teach", "corridor", "--resume", "--run-dir", str(run), "--steps", "3"]) == 0
    assert len(load_records(run)) == 6


def test_a_session_whose_own_map_file_changed_refuses_it(tmp_path, monkeypatch, capsys):
    """teach corridor --map PATH kept only the file's path: once the file was edited, evaluate
    and teach --resume drove the edited map without a word, though the session "keeps it". The
    session keeps the map's digest now; a changed file is one line (exit code 2) at the
    command line and a ValueError in Python, naming the file; the file put back as it was goes
    on, and so does one only renamed or reworded. A session that kept no digest (started
    before) drives the file as it is, as before."""
    from corridor.experiment import evaluate_saved_policy

    mine, run, original = _teach_on_a_map_file(tmp_path, monkeypatch)
    edited = json.loads(original)
    edited["nodes"]["B"] = [2.5, 0.0]  # a longer first corridor
    edited["nodes"]["C"] = [2.5, 1.0]
    mine.write_text(json.dumps(edited))
    for err in _evaluate_and_resume_refuse(run, capsys):
        assert f"taught on the map file {mine}, which has changed" in err, err
        assert "put the file back as it was" in err, err
    with pytest.raises(ValueError, match="which has changed since"):
        evaluate_saved_policy(run, n_steps=3)
    assert len(load_records(run)) == 3  # nothing recorded on the changed map
    renamed = {**json.loads(original), "name": "mine", "description": "my copy"}
    mine.write_text(json.dumps(renamed, indent=4))
    assert main(["teach", "corridor", "--resume", "--run-dir", str(run), "--steps", "3"]) == 0
    assert len(load_records(run)) == 6
    assert evaluate_saved_policy(run, n_steps=3)["map"] == str(mine)
    # a session started before the digest was kept: the file as it is
    config = json.loads((run / "config.json").read_text())
    del config["env"]["inputs"]
    (run / "config.json").write_text(json.dumps(config))
    mine.write_text(json.dumps(edited))
    assert main(["evaluate", str(run), "--steps", "3"]) == 0


def test_teach_resume_takes_the_sessions_own_map_again_and_refuses_another(
    tmp_path, monkeypatch, capsys
):
    """teach corridor --map NAME|PATH --resume was refused outright ("a resumed session keeps
    the map it was taught on"), so re-running one's teach command with --resume appended
    failed, while teach driving --scenario --resume takes the session's own traffic. --map is
    taken now where it is the map the session was taught on (by its digest, as resume
    compares the map: the same file by another path, or the shipped map it copies, its name
    aside), and another map is refused in one line (exit code 2) naming what differs and to
    leave --map out; nothing is recorded on it."""
    import corridor

    mine, run, original = _teach_on_a_map_file(tmp_path, monkeypatch)  # a copy of lshape
    monkeypatch.chdir(tmp_path)
    resume = ["teach", "corridor", "--resume", "--run-dir", str(run), "--steps", "3"]
    copy = tmp_path / "copy.json"
    copy.write_text(json.dumps({**json.loads(original), "name": "renamed"}))
    capsys.readouterr()
    for given in (str(mine), "mine.json", "lshape", str(copy)):
        assert main([*resume, "--map", given]) == 0, capsys.readouterr().err
    assert len(load_records(run)) == 3 + 4 * 3
    config = json.loads((run / "config.json").read_text())
    assert config["env"]["kwargs"]["corridor_map"] == str(mine)  # still the session's own map

    edited = json.loads(original)
    edited["corridor_width"] = 0.8
    edited["nodes"]["B"] = [2.5, 0.0]  # a longer first corridor
    edited["nodes"]["C"] = [2.5, 1.0]
    (tmp_path / "wider.json").write_text(json.dumps(edited))
    for given, says in (
        ("figure2", "--map figure2: "),
        ("wider.json", "corridor_width 0.8 (the session's: 0.6)"),
    ):
        assert main([*resume, "--map", given]) == 2, given
        err = capsys.readouterr().err
        assert err.count("\n") == 1, err
        assert says in err and f"{run}" in err and str(mine) in err, err
        assert "leave --map out with --resume" in err, err
    assert "nodes.B[0] 2.5 (the session's: 2.0)" in err, err
    assert len(load_records(run)) == 15  # nothing recorded on another map
    config = json.loads((run / "config.json").read_text())
    del config["env"]["inputs"]  # a session that kept no digest: its own map's is compared
    (run / "config.json").write_text(json.dumps(config))
    assert main([*resume, "--map", "figure2"]) == 2
    assert "nodes (12 values)" in capsys.readouterr().err
    assert main([*resume, "--map", "lshape"]) == 0
    assert len(load_records(run)) == 18

    # a session on the default map (no --map when it began): figure2 again, lshape refused
    shipped = Path(corridor.__file__).with_name("maps")
    default = tmp_path / "default"
    assert main(["teach", "corridor", "--run-dir", str(default), "--steps", "3"]) == 0
    resume_default = ["teach", "corridor", "--resume", "--run-dir", str(default)]
    assert main([*resume_default, "--steps", "3", "--map", "figure2"]) == 0
    assert main([*resume_default, "--steps", "3", "--map", str(shipped / "figure2.json")]) == 0
    capsys.readouterr()
    assert main([*resume_default, "--steps", "3", "--map", "lshape"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'figure2'" in err and "leave --map out" in err, err
    assert len(load_records(default)) == 9


def test_teach_that_could_not_start_on_a_full_disk_starts_when_run_again(
    tmp_path, monkeypatch, capsys
):
    """A teach whose session could not start (the disk full as config.json was written) said
    to free space and start the session again; the same command then said "--run-dir ... holds
    other files and no session": the run directory kept the writer.lock of the failed start
    and the config.json.tmp it could not finish."""
    from test_session_faults import file_size_limit

    _scripted_corridor_person(monkeypatch)
    run = tmp_path / "session"
    argv = ["teach", "corridor", "--run-dir", str(run), "--steps", "1"]
    with file_size_limit(500):  # the lock's note fits, config.json does not
        assert main(argv) == 1
    err = capsys.readouterr().err
    assert str(run / "config.json") in err and "free space" in err and err.count("\n") == 1
    assert not (run / "config.json.tmp").exists()
    assert main(argv) == 0, capsys.readouterr().err  # space freed: the same command
    assert len(load_records(run)) == 1


def test_teach_and_python_refuse_a_run_dir_holding_files_of_ones_own_alike(
    tmp_path, monkeypatch, capsys
):
    """ConfidentTeacher(..., run_dir=folder), the folder holding one's own script, wrote the
    session beside it, while teach --run-dir refused that folder; and teach refused a folder
    holding the empty journal a session leaves once its log and config went, where Python
    started. One rule (the store's) for both: each refuses the first, writing nothing there,
    and starts in the second."""
    import gymnasium as gym

    from corridor.expert import CorridorExpert
    from torchcbl import ConfidentTeacher
    from torchcbl.errors import IncompatibleRunDirError

    _scripted_corridor_person(monkeypatch)
    proj = tmp_path / "proj"
    proj.mkdir()
    (proj / "myteach.py").write_text("print('mine')\n")
    assert main(["teach", "corridor", "--run-dir", str(proj), "--steps", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "myteach.py" in err and "choose another --run-dir" in err, err
    env = gym.make("torchcbl/Corridor-v0")
    with pytest.raises(IncompatibleRunDirError, match=r"myteach\.py.*choose another run_dir"):
        ConfidentTeacher(env, CorridorExpert(env.unwrapped.world.map), run_dir=proj)
    env.close()
    assert sorted(p.name for p in proj.iterdir()) == ["myteach.py"]
    left = tmp_path / "left"  # what torchcbl leaves where no session is
    left.mkdir()
    (left / "writer.lock").write_bytes(b"")
    (left / "steps.journal").write_bytes(b"")
    assert main(["teach", "corridor", "--run-dir", str(left), "--steps", "1"]) == 0
    assert len(load_records(left)) == 1


def test_teach_in_a_folder_holding_a_config_json_of_ones_own_does_not_say_resume(
    tmp_path, monkeypatch, capsys
):
    """teach --run-dir on a folder holding one's own config.json said it "already holds a
    teaching session; add --resume", and --resume then failed ("expected a session format
    ... got None"). It says that config.json is no torchcbl session's and to choose another
    --run-dir, in one line, and writes nothing."""
    _scripted_corridor_person(monkeypatch)
    proj = tmp_path / "proj"
    proj.mkdir()
    (proj / "config.json").write_text('{"lr": 0.1}')
    assert main(["teach", "corridor", "--run-dir", str(proj), "--steps", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a torchcbl session" in err, err
    assert "--resume" not in err and "choose another --run-dir" in err, err
    assert sorted(p.name for p in proj.iterdir()) == ["config.json"]


def test_reproduce_on_a_full_disk_names_the_file_it_could_not_write(tmp_path, capsys):
    """reproduce on a full disk said only "error: OSError: [Errno 28] No space left on device":
    the pid written into the run directory's .run.lock stayed in the file object's buffer, and
    closing the lock raised that bare OSError. The run now meets the full disk at its first
    real write, and the line names that file and says to free space."""
    from test_session_faults import file_size_limit

    out = tmp_path / "out"
    argv = ["reproduce", "corridor", "--seeds", "1", "--workers", "1", "--no-progress"]
    with file_size_limit(0):
        assert main([*argv, "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "free space" in err, err
    assert str(out / "corridor" / "sessions" / "seed0" / "config.json") in err, err


def test_teach_stopped_by_a_full_disk_says_how_to_continue_at_the_command_line(
    tmp_path, monkeypatch, capsys
):
    """The disk filling up while a person teaches ended teach with the session's error alone,
    whose advice is the Python API's ("call run() again or resume"), without what the line of
    a teach stopped otherwise says: what is saved and the command that continues. The person
    now reads both, and that command continues the session with every demonstration kept."""
    import resource
    import signal

    import corridor.human

    _scripted_corridor_person(monkeypatch, max_demonstrations=None)
    hard = resource.getrlimit(resource.RLIMIT_FSIZE)[1]
    answers = []

    class Person:
        def __call__(self, observation, info):
            answers.append(0)
            if len(answers) == 4:  # the disk is full from the 4th answer on
                resource.setrlimit(resource.RLIMIT_FSIZE, (0, hard))
            return 0

        def set_status(self, text):
            pass

    monkeypatch.setattr(corridor.human, "make_teacher", lambda **kw: Person())
    run = tmp_path / "session"
    handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    limits = resource.getrlimit(resource.RLIMIT_FSIZE)
    try:
        rc = main(["teach", "corridor", "--run-dir", str(run), "--steps", "10"])
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, limits)
        signal.signal(signal.SIGXFSZ, handler)
    err = capsys.readouterr().err
    assert rc == 1 and err.count("\n") == 1 and "steps.sqlite failed" in err, err
    assert f"Saved in {run}: 3 demonstrations over 3 steps;" in err, err
    assert f"continue with: torchcbl teach corridor --run-dir {run} --resume" in err, err
    assert main(["teach", "corridor", "--run-dir", str(run), "--resume", "--steps", "2"]) == 0
    assert len(load_records(run)) == 5


def test_teach_resume_of_a_damaged_session_is_a_one_line_mistake(tmp_path, monkeypatch, capsys):
    """teach --resume of a session with a damaged log is told as evaluate tells it: one line,
    exit code 2, and the session's files untouched. (It was exit code 1, with the error's
    class name and the TORCHCBL_TRACEBACK hint around the same text.)"""
    _scripted_corridor_person(monkeypatch)
    run = tmp_path / "session"
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "3"]) == 0
    with open(run / "steps.journal", "a", encoding="utf-8") as journal:
        journal.write('garbage\n{"x":')
    files = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    capsys.readouterr()
    for argv in (["evaluate", str(run)], ["teach", "corridor", "--resume", "--run-dir", str(run)]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "steps.journal: line" in err and "is damaged" in err, err
        assert "CorruptSessionError" not in err and "TORCHCBL_TRACEBACK" not in err, err
    assert {p: p.read_bytes() for p in run.rglob("*") if p.is_file()} == files


def test_output_into_a_pipe_whose_reader_left_ends_quietly(corridor_run):
    """``torchcbl evaluate DIR | head -1``: once the reader has gone, the command stops as a
    command killed by SIGPIPE does (exit 141, nothing on stderr), where it used to report
    'error: BrokenPipeError' with exit code 1. Also run as ``python -m torchcbl``."""
    session = corridor_run / "corridor" / "sessions" / "seed0"
    for cmd in ([str(BIN)], [sys.executable, "-m", "torchcbl"]):
        proc = subprocess.Popen(
            [*cmd, "evaluate", str(session), "--steps", "30"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
            env={**os.environ, "TORCHCBL_TRACEBACK": ""},
        )
        proc.stdout.close()  # the reader leaves before the command writes anything
        err = proc.stderr.read().decode()
        proc.wait(timeout=120)
        assert proc.returncode == 141, (cmd, err)
        assert err == "", (cmd, err)
    # with a reader the same command writes its JSON and exits 0
    done = subprocess.run(
        [sys.executable, "-m", "torchcbl", "evaluate", str(session), "--steps", "30"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["steps"] == 30


def test_teach_starts_from_prior_demonstrations_of_a_file_or_an_earlier_session(
    tmp_path, monkeypatch, capsys
):
    """--prior-demonstrations FILE.npz or DIR: the session keeps them and every fit includes
    them; a file that is not what it reads is one line and exit code 2, nothing taught."""
    from torchcbl.session import load_demonstrations, load_labels, load_prior_demonstrations

    _scripted_corridor_person(monkeypatch)
    first = tmp_path / "first"
    assert main(["teach", "corridor", "--run-dir", str(first), "--steps", "30"]) == 0
    x, y = load_demonstrations(first)
    prior = tmp_path / "prior.npz"
    np.savez(prior, observations=x, actions=y)
    for source, run, n in ((prior, tmp_path / "second", 5), (tmp_path / "second", None, 10)):
        run = run or tmp_path / "third"
        argv = ["teach", "corridor", "--run-dir", str(run), "--steps", "30"]
        assert main([*argv, "--prior-demonstrations", str(source)]) == 0
        px, py = load_prior_demonstrations(run)
        assert len(py) == n and np.array_equal(px[:5], x) and np.array_equal(py[:5], y)
        assert len(load_labels(run)[1]) == 5  # its own budget, the prior aside
    capsys.readouterr()
    np.save(tmp_path / "one.npy", x)
    np.savez(tmp_path / "keys.npz", obs=x, act=y)
    np.savez(tmp_path / "flat.npz", observations=x[:, 0], actions=y)
    np.savez(tmp_path / "range.npz", observations=x, actions=y + 7)
    (tmp_path / "text.npz").write_text("not numpy")
    for source, says in (
        (tmp_path / "nowhere.npz", "no such file or directory; expected a .npz file"),
        (tmp_path / "one.npy", "a single array (.npy), not a .npz"),
        (tmp_path / "text.npz", "not a readable .npz"),
        (tmp_path / "keys.npz", "without 'observations' and 'actions'"),
        (tmp_path / "flat.npz", "shape [N, 3]"),
        (tmp_path / "range.npz", "actions must be in [0, 4)"),
        (_session_without_labels(tmp_path / "empty"), "that session holds no demonstrations"),
    ):
        argv = ["teach", "corridor", "--run-dir", str(tmp_path / "bad"), "--steps", "30"]
        assert main([*argv, "--prior-demonstrations", str(source)]) == 2, source
        err = capsys.readouterr().err
        assert says in err and err.count("\n") == 1, err
        assert not (tmp_path / "bad" / "config.json").exists()
    argv = ["teach", "corridor", "--run-dir", str(first), "--resume", "--steps", "3"]
    assert main([*argv, "--prior-demonstrations", str(prior)]) == 2
    assert "a resumed session keeps the prior" in capsys.readouterr().err


def test_prior_demonstrations_of_a_directory_that_is_no_session_says_which_are(tmp_path, capsys):
    """--prior-demonstrations DIR with DIR a run directory holding sessions (a reproduction's
    runs/reproduce/corridor, a folder of one's sessions) or no session at all was told
    "config.json is missing. Start a session with ConfidentTeacher(..., run_dir=...) first",
    a Python hint for a command-line mistake; it names the sessions below DIR to pass instead,
    or says what the option reads, as evaluate does."""
    from _toy_envs import ClusterWorld

    from torchcbl import ConfidentTeacher

    world = ClusterWorld(np.eye(3) * 5, [0, 1, 2], [1, 1, 1], episode_length=5)
    session = tmp_path / "runs" / "sessions" / "seed0"
    ConfidentTeacher(world, lambda o, i: world.optimal_action(o), run_dir=session).close()
    (tmp_path / "empty").mkdir()
    argv = ["teach", "corridor", "--run-dir", str(tmp_path / "new"), "--steps", "3"]
    for given, says in (
        (tmp_path / "runs", f"is not a teaching session but holds sessions: {session}; pass"),
        (tmp_path / "empty", "holds no config.json; expected a .npz file"),
    ):
        assert main([*argv, "--prior-demonstrations", str(given)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and says in err, err
        assert "ConfidentTeacher" not in err, err
    assert not (tmp_path / "new" / "config.json").exists()


def test_teach_resume_of_a_session_being_taught_elsewhere_says_what_to_do_at_the_terminal(
    tmp_path, monkeypatch, capsys
):
    """teach --resume of a session another writer holds said "close the other
    ConfidentTeacher (close() or a with-block)": Python advice, at the command line, to a
    person whose other teach runs in another terminal. It says to stop that teach there."""
    import fcntl

    _scripted_corridor_person(monkeypatch)
    run = tmp_path / "session"
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "3"]) == 0
    capsys.readouterr()
    with open(
        run / "writer.lock", "r+", encoding="utf-8"
    ) as other:  # another writer holds the session
        fcntl.flock(other.fileno(), fcntl.LOCK_EX)
        assert main(["teach", "corridor", "--resume", "--run-dir", str(run)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "with-block" not in err and "close()" not in err, err
    assert "is being taught by another writer" in err and "q or Ctrl-C" in err, err
    assert "(process " in err, err  # the holder, as writer.lock names it


def test_teach_resume_of_a_done_session_another_writer_holds_says_it_is_held(
    tmp_path, monkeypatch, capsys
):
    """A done session that another process holds (writer.lock locked: e.g. a Python resume
    teaching it on under a raised stop) is not refused as done from a log that writer is
    changing: `teach --resume` says it is being taught by another writer, in one line."""
    import fcntl

    run = tmp_path / "session"
    _done_corridor_session(run, monkeypatch)
    capsys.readouterr()
    with open(run / "writer.lock", "r+", encoding="utf-8") as other:
        fcntl.flock(other.fileno(), fcntl.LOCK_EX)
        assert main(["teach", "corridor", "--resume", "--run-dir", str(run)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1, captured
    assert "is being taught by another writer" in captured.err, captured.err
    assert "is done" not in captured.err, captured.err


def test_teach_counts_one_demonstration_and_one_step_in_the_singular(tmp_path, monkeypatch, capsys):
    """A teach stopped after its first key said "1 demonstrations over 1 steps saved"."""
    monkeypatch.setattr(sys, "stdin", io.StringIO("w\n"))
    run = tmp_path / "session"
    assert main(["teach", "corridor", "--run-dir", str(run), "--steps", "10"]) == 0
    out = capsys.readouterr().out
    assert "1 demonstration over 1 step saved in" in out, out


def test_benchmark_keep_sessions_help_says_which_sessions_evaluate_reads(capsys):
    """--keep-sessions' help said the kept sessions are read with torchcbl evaluate, which
    refuses those of a --gym-env env torchcbl does not know; it says evaluate reads the
    corridor and driving cells', the others are read in Python with torchcbl.load_policy."""
    with pytest.raises(SystemExit):
        main(["benchmark", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert (
        "torchcbl evaluate (corridor and driving cells; others in Python with "
        "torchcbl.load_policy)" in text
    ), text


def test_teach_on_a_kept_session_of_no_step_says_in_one_line_it_holds_none(
    tmp_path, capsys, monkeypatch
):
    """`torchcbl teach --run-dir` on a session stopped at its first request: one line that
    says to add --resume, and that the session holds no step, so the folder may be removed."""
    from _toy_envs import rare_regions_world

    from torchcbl import ConfidentTeacher
    from torchcbl.errors import TeachingInterrupted

    def stop(obs, info):
        raise TeachingInterrupted("q")

    world = rare_regions_world()
    run = tmp_path / "run"
    with ConfidentTeacher(world, stop, run_dir=run, progress=False) as ct:
        with pytest.raises(TeachingInterrupted):
            ct.run(max_steps=3)
    monkeypatch.setenv("TORCHCBL_TRACEBACK", "")
    assert main(["teach", "corridor", "--run-dir", str(run)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.strip().splitlines()) == 1, captured.err
    assert "--resume" in captured.err and "holds no step" in captured.err, captured.err
    assert f"rm -r {run}" in captured.err, captured.err


def _checkpoints_of(run: Path) -> list[int]:
    return sorted(int(p.stem.split("-")[1]) for p in (run / "checkpoints").glob("model-*.pt"))


def test_teach_keeps_the_checkpoints_asked_for_and_a_resume_keeps_the_sessions_choice(
    tmp_path, monkeypatch, capsys
):
    """`teach` passed no keep_checkpoints, so a person could not keep every stage's
    checkpoint (nor fewer) outside Python. --keep-checkpoints N|all chooses it for a new
    session; --resume without it keeps what the session kept (ConfidentTeacher.resume's
    "as_before"), with it the new value (the stages beyond it go at the first refit)."""
    from torchcbl.session import kept_checkpoints
    from torchcbl.teaching import DEFAULT_KEEP_CHECKPOINTS

    _scripted_corridor_person(monkeypatch)  # 5 demonstrations, a refit after each
    default, every = tmp_path / "default", tmp_path / "every"
    assert main(["teach", "corridor", "--run-dir", str(default), "--steps", "30"]) == 0
    assert (kept_checkpoints(default), _checkpoints_of(default)) == (3, [3, 4, 5])
    argv = ["teach", "corridor", "--run-dir", str(every), "--steps", "30"]
    assert main([*argv, "--keep-checkpoints", "all"]) == 0
    assert (kept_checkpoints(every), _checkpoints_of(every)) == (None, [1, 2, 3, 4, 5])
    resume = ["teach", "corridor", "--run-dir", str(every), "--resume", "--steps", "3"]
    assert main(resume) == 0  # as before: every one
    assert (kept_checkpoints(every), _checkpoints_of(every)) == (None, list(range(1, 9)))
    assert main([*resume, "--keep-checkpoints", "2"]) == 0
    assert (kept_checkpoints(every), _checkpoints_of(every)) == (2, [10, 11])
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["teach", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert f"(default {DEFAULT_KEEP_CHECKPOINTS}; with --resume what the session kept)" in help_text


@pytest.mark.parametrize("bad", ["0", "-1", "three", "none", "1.5", ""])
def test_teach_refuses_a_keep_checkpoints_it_cannot_take_in_one_line(bad, tmp_path, capsys):
    run = tmp_path / "session"
    with pytest.raises(SystemExit) as exc:
        main(["teach", "corridor", "--run-dir", str(run), "--keep-checkpoints", bad])
    out, err = capsys.readouterr()
    assert exc.value.code == 2 and out == "" and err.count("\n") == 1, (out, err)
    assert "argument --keep-checkpoints: expected a whole number >= 1" in err, err
    assert "or all" in err and f"got {bad!r}" in err, err
    assert not run.exists()


@pytest.mark.parametrize("spelt", ["ALL", " all ", "All"])
def test_teach_takes_keep_checkpoints_all_whatever_its_case_and_spaces(
    spelt, tmp_path, monkeypatch
):
    """--keep-checkpoints all, as a person may type it (capitals, spaces): every one kept."""
    from torchcbl.session import kept_checkpoints

    _scripted_corridor_person(monkeypatch)  # 5 demonstrations, a refit after each
    run = tmp_path / "session"
    argv = ["teach", "corridor", "--run-dir", str(run), "--steps", "30"]
    assert main([*argv, "--keep-checkpoints", spelt]) == 0
    assert (kept_checkpoints(run), _checkpoints_of(run)) == (None, [1, 2, 3, 4, 5])
