"""The shape of the core: no import cycles, no domain imports, old run directories still read."""

from __future__ import annotations

import ast
import json
import math
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from _toy_envs import oracle, rare_regions_world

from torchcbl import ConfidentTeacher, TeachingConfig
from torchcbl.errors import IncompatibleRunDirError
from torchcbl.session import load_config, load_demonstrations, load_model, load_records

ROOT = Path(__file__).resolve().parents[1]
FORBIDDEN = ("corridor", "sumo_scenarios", "libsumo", "traci", "sumolib", "pymunk", "pygame")


_TYPING = ("typing", "typing_extensions")


def _type_checking_only(node: ast.If, names: set[str]) -> bool:
    """Whether ``node`` is ``if TYPE_CHECKING:`` with the name imported from typing (in
    ``names``), or ``if typing.TYPE_CHECKING:``; another module's or a home-made
    TYPE_CHECKING may be true at run time."""
    test = node.test
    return (isinstance(test, ast.Name) and test.id in names) or (
        isinstance(test, ast.Attribute)
        and test.attr == "TYPE_CHECKING"
        and isinstance(test.value, ast.Name)
        and test.value.id in _TYPING
    )


def _runtime_imports(source: str) -> set[str]:
    """The torchcbl modules ``source`` imports at run time, anywhere (lazy ones included);
    an import under ``if TYPE_CHECKING:`` (for type checkers alone) is none (its ``else:``
    is)."""
    deps: set[str] = set()
    tree = ast.parse(source)
    flags = {  # the local names of typing's TYPE_CHECKING
        a.asname or a.name
        for n in ast.walk(tree)
        if isinstance(n, ast.ImportFrom) and n.module in _TYPING
        for a in n.names
        if a.name == "TYPE_CHECKING"
    }
    todo: list[ast.AST] = [tree]
    while todo:
        node = todo.pop()
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module.startswith("torchcbl"):
                deps.add(node.module)
                for alias in node.names:  # `from torchcbl import _em` imports a module
                    deps.add(f"{node.module}.{alias.name}")
        elif isinstance(node, ast.Import):
            deps |= {a.name for a in node.names if a.name.startswith("torchcbl")}
        if isinstance(node, ast.If) and _type_checking_only(node, flags):
            todo.extend(node.orelse)
        else:
            todo.extend(ast.iter_child_nodes(node))
    return deps


def _torchcbl_imports() -> dict[str, set[str]]:
    """module -> the torchcbl modules it imports at run time (see :func:`_runtime_imports`)."""
    graph: dict[str, set[str]] = {}
    for path in sorted((ROOT / "torchcbl").rglob("*.py")):
        rel = path.relative_to(ROOT).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        graph[".".join(parts)] = _runtime_imports(path.read_text())
    return {m: {d for d in deps if d in graph and d != m} for m, deps in graph.items()}


def test_an_import_for_type_checkers_alone_is_no_import_edge():
    """An import under ``if TYPE_CHECKING:`` never runs, so it makes no import cycle (the
    common convention: a module may name, for its hints, a module that imports it). The
    check below counted it as an edge: the typed re-exports of a package's lazily loaded
    names (torchcbl/__init__.py's) had to be taken out of the graph by hand. Every other
    import counts: at the top, inside a function (a lazy one), in ``else:``."""
    source = (
        "from typing import TYPE_CHECKING\n"
        "import typing\n"
        "from torchcbl.records import StepRecord\n"
        "if TYPE_CHECKING:\n"
        "    from torchcbl.gmm import Classification\n"
        "    import torchcbl.teaching\n"
        "else:\n"
        "    from torchcbl.policy import GreedyPolicy\n"
        "if typing.TYPE_CHECKING:\n"
        "    from torchcbl.session import load_model\n"
        "def f():\n"
        "    from torchcbl import _em\n"
        "    if TYPE_CHECKING:\n"
        "        from torchcbl.human import TerminalTeacher\n"
        "if settings.TYPE_CHECKING:\n"  # another module's flag: may be true at run time
        "    from torchcbl.confidence import DistanceRule\n"
    )
    assert _runtime_imports(source) == {
        "torchcbl.records",
        "torchcbl.records.StepRecord",
        "torchcbl.policy",
        "torchcbl.policy.GreedyPolicy",
        "torchcbl",
        "torchcbl._em",
        "torchcbl.confidence",
        "torchcbl.confidence.DistanceRule",
    }
    # a TYPE_CHECKING of the module's own making is no typing flag
    assert _runtime_imports(
        "TYPE_CHECKING = True\nif TYPE_CHECKING:\n    import torchcbl.gmm\n"
    ) == {"torchcbl.gmm"}


def test_no_import_cycle_inside_torchcbl():
    graph = _torchcbl_imports()
    graph = {m: deps - {"torchcbl"} for m, deps in graph.items()}
    assert {"torchcbl.teaching", "torchcbl.session", "torchcbl.policy"} <= set(graph)
    assert "torchcbl.session" in graph["torchcbl.teaching"]  # the check sees real edges
    cycles = []

    def visit(m: str, stack: list[str]) -> None:
        for d in graph.get(m, ()):
            if d in stack:
                cycles.append(stack[stack.index(d) :] + [d])
            elif len(stack) < 20:
                visit(d, stack + [d])

    for m in graph:
        visit(m, [m])
    assert not cycles, f"import cycles inside torchcbl: {cycles[:3]}"


def test_import_torchcbl_imports_no_domain_or_simulator():
    code = (
        "import sys, torchcbl, torchcbl.teaching, torchcbl.session, torchcbl.policy, "
        "torchcbl.confidence, torchcbl.records, torchcbl.strategies\n"
        f"print(sorted(m for m in sys.modules if m.split('.')[0] in {FORBIDDEN!r}))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    )
    assert out.stdout.strip() == "[]", out.stdout


def test_public_names_stay_importable_from_torchcbl():
    import torchcbl

    for name in torchcbl.__all__:
        assert getattr(torchcbl, name) is not None
    from torchcbl.teaching import EnvError, GreedyPolicy, TeacherError, evaluate_policy

    assert GreedyPolicy is torchcbl.GreedyPolicy and evaluate_policy is torchcbl.evaluate_policy
    assert EnvError is torchcbl.EnvError and TeacherError is torchcbl.TeacherError


def _session(run_dir: Path) -> list:
    env = rare_regions_world(episode_length=10)
    ct = ConfidentTeacher(
        env,
        oracle(env),
        config=TeachingConfig(max_new=2, accuracy_window=10, max_steps=60),
        run_dir=run_dir,
        seed=1,
        progress=False,
    )
    ct.run()
    ct.close()
    return load_records(run_dir)


def _downgrade_to_format1(run_dir: Path) -> None:
    """Make a run directory look like one written before strategies (format 1)."""
    from torchcbl.session import _FORMAT1_COLUMNS

    cols = ", ".join(_FORMAT1_COLUMNS)
    db = sqlite3.connect(run_dir / "steps.sqlite")
    schema = db.execute("SELECT sql FROM sqlite_master WHERE name = 'steps'").fetchone()[0]
    old = schema.split("pending INTEGER NOT NULL,")[0] + "pending INTEGER NOT NULL)"
    db.executescript(
        f"ALTER TABLE steps RENAME TO new; {old}; INSERT INTO steps SELECT {cols} FROM new; "
        "DROP TABLE new; DROP TABLE corrections;"
    )
    assert "actor" not in db.execute("SELECT sql FROM sqlite_master").fetchall()[0][0]
    db.commit()
    db.close()
    config = json.loads((run_dir / "config.json").read_text())
    config["format"] = "torchcbl.session/1"
    del config["strategy"]
    (run_dir / "config.json").write_text(json.dumps(config))


def test_format1_run_dir_loads_and_resumes(tmp_path):
    run = tmp_path / "run"
    want = _session(run)
    assert {r.actor for r in want} == {"teacher", "agent"}
    x, y = load_demonstrations(run)
    _downgrade_to_format1(run)
    assert load_records(run) == want  # actor derived: teacher when labelled, else agent
    got_x, got_y = load_demonstrations(run)
    assert (got_x == x).all() and (got_y == y).all()
    assert load_model(run).is_fitted
    env = rare_regions_world(episode_length=10)
    back = ConfidentTeacher.resume(run, env, oracle(env), progress=False)
    assert back.records == want
    back.run(max_steps=80)
    back.close()
    assert load_config(run)["format"] == "torchcbl.session/2"  # upgraded in place
    assert load_records(run)[:60] == want and len(load_records(run)) == 80


def test_unknown_format_fails_naming_the_version(tmp_path):
    run = tmp_path / "run"
    _session(run)
    config = json.loads((run / "config.json").read_text())
    config["format"] = "torchcbl.session/99"
    (run / "config.json").write_text(json.dumps(config))
    with pytest.raises(IncompatibleRunDirError, match=r"torchcbl\.session/99"):
        load_records(run)
    env = rare_regions_world(episode_length=10)
    with pytest.raises(IncompatibleRunDirError, match=r"got 'torchcbl\.session/99'"):
        ConfidentTeacher.resume(run, env, oracle(env), progress=False)


def test_record_says_who_chose_the_executed_action():
    from torchcbl.records import StepRecord

    base = dict(
        step=0,
        episode=0,
        observation=(0.0,),
        model_action=1,
        confidence=0.5,
        distance=1.0,
        posterior=(0.5, 0.5),
        phase="confident",
        reward=1.0,
        terminated=False,
        truncated=False,
    )
    assert StepRecord(**base, teacher_action=0, executed_action=0, autonomous=False).actor == (
        "teacher"
    )
    assert StepRecord(**base, teacher_action=None, executed_action=1, autonomous=True).actor == (
        "agent"
    )
    # DAgger: labelled, but the agent's action ran
    r = StepRecord(**base, teacher_action=0, executed_action=1, autonomous=False, actor="agent")
    assert r.is_demonstration and r.actor == "agent"
    with pytest.raises(ValueError, match="actor"):  # the teacher cannot execute another action
        StepRecord(**base, teacher_action=0, executed_action=1, autonomous=False, actor="teacher")
    with pytest.raises(ValueError, match="actor"):
        StepRecord(**base, teacher_action=None, executed_action=0, autonomous=True)
    with pytest.raises(ValueError, match="autonomous"):
        StepRecord(**base, teacher_action=0, executed_action=0, autonomous=True)


def test_records_refuse_at_creation_what_would_fail_later():
    """A value that JSON or the log cannot hold fails when the record is made, naming the
    field, not later in to_dict or a consumer; a correction is a label for a real observation
    and differs from what was executed."""
    from torchcbl.records import CorrectionRecord, StepRecord

    base = dict(
        step=0,
        episode=0,
        observation=(0.0,),
        model_action=1,
        posterior=(0.5, 0.5),
        teacher_action=None,
        executed_action=1,
        phase="confident",
        autonomous=True,
        reward=1.0,
        terminated=False,
        truncated=False,
    )
    ok = StepRecord(**base, confidence=0.5, distance=float("inf"), info={"x": [1, "a"]})
    assert ok.to_dict()["distance"] == "inf"
    for field, value in (  # numpy floats are taken (tests/test_records.py); these are not
        ("confidence", "0.5"),
        ("confidence", True),
        ("distance", np.float32("nan")),
        ("info", {"x": object()}),
        ("info", {"x": np.int64(3)}),
    ):
        kw = {"confidence": 0.5, "distance": 1.0, "info": {}, field: value}
        with pytest.raises(ValueError, match=rf"StepRecord\.{field}: expected"):
            StepRecord(**base, **kw)
    with pytest.raises(ValueError, match=r"StepRecord\.info: expected a dict JSON can hold"):
        ok.with_outcome(1.0, False, False, {"x": object()})
    CorrectionRecord(step=0, episode=0, observation=(0.5, 1.0), executed_action=0, action=1)
    for obs in ((float("nan"), 1.0), (), np.array([[0.5, 1.0]]), ("a",)):  # lists are taken
        with pytest.raises(ValueError, match=r"CorrectionRecord\.observation: expected"):
            CorrectionRecord(step=0, episode=0, observation=obs, executed_action=0, action=1)
    with pytest.raises(ValueError, match=r"CorrectionRecord\.action: expected another action"):
        CorrectionRecord(step=0, episode=0, observation=(0.5,), executed_action=1, action=1)


def _step_fields() -> dict:
    return dict(
        step=3,
        episode=0,
        observation=(0.0, 1.0),
        model_action=1,
        confidence=0.5,
        posterior=(0.5, 0.5),
        reward=1.0,
        terminated=False,
        truncated=False,
    )


def test_a_step_record_refuses_a_negative_or_nan_distance():
    """A Mahalanobis distance is >= 0 (inf before any model): a negative one or NaN is refused
    naming the field."""
    from torchcbl.records import StepRecord

    labelled = dict(teacher_action=1, executed_action=1, autonomous=False, phase="confident")
    for good in (0.0, 2.5, math.inf):
        assert StepRecord(**_step_fields(), distance=good, **labelled).distance == good
    for bad in (-1.0, -1e-300, math.nan):
        with pytest.raises(ValueError, match=r"StepRecord\.distance: expected a float >= 0"):
            StepRecord(**_step_fields(), distance=bad, **labelled)


def test_a_non_interactive_step_record_needs_a_teacher_label():
    """A step of the non-interactive phase asks by design: one without a teacher label is
    refused naming teacher_action; the same step in confident execution is an autonomous step,
    and a labelled non-interactive step is accepted."""
    from torchcbl.records import StepRecord

    unlabelled = dict(teacher_action=None, executed_action=1, autonomous=True, distance=1.0)
    assert StepRecord(**_step_fields(), **unlabelled, phase="confident").actor == "agent"
    with pytest.raises(
        ValueError, match=r"StepRecord\.teacher_action: expected a label on every non-interactive"
    ):
        StepRecord(**_step_fields(), **unlabelled, phase="noninteractive")
    labelled = dict(teacher_action=1, executed_action=1, autonomous=False, distance=1.0)
    assert StepRecord(**_step_fields(), **labelled, phase="noninteractive").actor == "teacher"


def _public_modules() -> list[str]:
    """Every module of the three packages whose name has no leading underscore."""
    import pkgutil

    import corridor
    import sumo_scenarios
    import torchcbl

    names = []
    for package in (torchcbl, corridor, sumo_scenarios):
        for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
            if not info.name.rsplit(".", 1)[-1].startswith("_"):
                names.append(info.name)
    return sorted(names)


# the domain modules a user imports from: each says what its public names are
_DOMAIN_API = {"baseline", "env", "experiment", "expert", "maps", "metrics", "replay"}
_DOMAIN_API |= {"scenarios", "world"}


@pytest.mark.parametrize("module", _public_modules())
def test_every_public_name_exists_and_its_classes_and_functions_say_what_they_are(module):
    """What a module's __all__ names is there, and each class or function of it has a
    docstring (help() is how a researcher in a notebook reads the API)."""
    import importlib
    import inspect

    mod = importlib.import_module(module)
    names = getattr(mod, "__all__", None)
    if not module.startswith("torchcbl.") and module.rsplit(".", 1)[-1] in _DOMAIN_API:
        assert names is not None, f"{module} has no __all__: its public names are undefined"
    for name in names or ():
        obj = getattr(mod, name)  # AttributeError: __all__ names a missing object
        if inspect.isclass(obj) or inspect.isfunction(obj):
            assert inspect.getdoc(obj), f"{module}.{name} has no docstring"


def test_a_format1_upgrade_that_cannot_write_its_config_is_a_session_write_error(
    tmp_path, monkeypatch
):
    """Disk full as a format-1 session's config.json is rewritten as format 2 on resume: a
    bare OSError escaped, and the log, already upgraded, left the config at format 1 for good.
    Now a SessionWriteError names the file and what to do, and the next resume upgrades it."""
    import errno
    import os

    from torchcbl.errors import SessionWriteError

    run = tmp_path / "run"
    want = _session(run)
    _downgrade_to_format1(run)
    real = os.replace

    def full(src, dst, *args, **kwargs):
        if str(dst).endswith("config.json"):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "replace", full)
    env = rare_regions_world(episode_length=10)
    with pytest.raises(SessionWriteError, match=r"config\.json.*Free space"):
        ConfidentTeacher.resume(run, env, oracle(env), progress=False)
    monkeypatch.setattr(os, "replace", real)
    assert load_config(run)["format"] == "torchcbl.session/1"
    back = ConfidentTeacher.resume(run, env, oracle(env), progress=False)
    assert back.records == want
    back.close()
    assert load_config(run)["format"] == "torchcbl.session/2"
