"""An env's ``describe_versions()``: each writer of a session records the versions of what its
env runs on (a simulator and its bindings) in writers.jsonl, ``describe`` and ``torchcbl show``
give them, and a resume under other versions than the last writer's says so in one warning."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import gymnasium as gym
import pytest
from _toy_envs import oracle, rare_regions_world

from torchcbl import ConfidentTeacher
from torchcbl.cli import main
from torchcbl.errors import EnvError
from torchcbl.session import describe, load_records


class _SimWorld(gym.Wrapper):
    """rare_regions_world, told to run on a simulator: describe_versions() gives ``versions``."""

    def __init__(self, versions: object) -> None:
        super().__init__(rare_regions_world())
        self.versions = versions

    def describe_versions(self) -> object:
        if isinstance(self.versions, Exception):
            raise self.versions
        return self.versions

    @property
    def unwrapped(self):  # an env of one's own: the hook sits on the unwrapped env
        return self


def _writers(run: Path) -> list[dict]:
    return [json.loads(line) for line in (run / "writers.jsonl").read_text().splitlines()]


def _session(run: Path, versions: object, steps: int = 10) -> _SimWorld:
    env = _SimWorld(versions)
    with ConfidentTeacher(env, oracle(env.env), run_dir=run, progress=False) as ct:
        ct.run(max_steps=steps)
    return env


def _resume(run: Path, versions: object, steps: int = 2) -> list[str]:
    """Resume ``run`` under ``versions`` for ``steps`` steps; the warnings it gave."""
    env = _SimWorld(versions)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        with ConfidentTeacher.resume(run, env, oracle(env.env), progress=False) as ct:
            ct.run(max_steps=ct.n_steps + steps)  # (a budget over the whole session)
    return [str(w.message) for w in said if issubclass(w.category, UserWarning)]


def test_each_writer_records_its_envs_versions_and_show_gives_them(tmp_path, capsys):
    run = tmp_path / "run"
    _session(run, {"sim": "1.2.0", "sim_bindings": "1.2.0"})
    assert _writers(run)[0]["env_versions"] == {"sim": "1.2.0", "sim_bindings": "1.2.0"}
    assert _resume(run, {"sim": "1.2.0", "sim_bindings": "1.2.0"}) == []  # the same: silent
    said = _resume(run, {"sim": "1.3.1", "sim_bindings": "1.2.0"})
    assert len(said) == 1, said
    (text,) = said
    assert "sim 1.2.0" in text and "sim 1.3.1" in text and "sim_bindings" not in text, text
    assert "steps from 12 on are taught under another simulator" in text, text
    assert "resume under sim 1.2.0 to continue as taught" in text, text
    assert text.count(". ") == 0 and "\n" not in text, text  # one sentence
    writers = _writers(run)
    assert [w["first_step"] for w in writers] == [0, 10, 12]
    assert [w["env_versions"]["sim"] for w in writers] == ["1.2.0", "1.2.0", "1.3.1"]
    assert [w["env_versions"] for w in describe(run).writers] == [
        w["env_versions"] for w in writers
    ]
    assert main(["show", str(run)]) == 0
    out = capsys.readouterr().out
    lines = [ln for ln in out.splitlines() if "from step " in ln]
    assert len(lines) == 3, out
    assert "sim 1.2.0, sim_bindings 1.2.0" in lines[0] and "sim 1.3.1" in lines[2], out
    # the warning compares with the LAST writer's: going back warns again, naming both
    (back,) = _resume(run, {"sim": "1.2.0", "sim_bindings": "1.2.0"})
    assert "sim 1.3.1" in back and "resume under sim 1.3.1" in back, back


def test_a_session_whose_writers_recorded_no_versions_resumes_silently(
    tmp_path, capsys, monkeypatch
):
    """A session written before writers recorded env_versions, or taught in an env without the
    hook, resumes under any versions without a word; a writer without the hook records None."""
    run = tmp_path / "run"
    _session(run, {"sim": "1.2.0"})
    old = [{k: v for k, v in w.items() if k != "env_versions"} for w in _writers(run)]
    (run / "writers.jsonl").write_text("".join(json.dumps(w) + "\n" for w in old))
    assert _resume(run, {"sim": "9.9.9"}) == []
    assert _writers(run)[-1]["env_versions"] == {"sim": "9.9.9"}
    plain = tmp_path / "plain"
    with monkeypatch.context() as patched:
        patched.delattr(_SimWorld, "describe_versions")  # an env without the hook
        _session(plain, {"sim": "1.2.0"}, steps=3)
    assert _writers(plain)[0]["env_versions"] is None
    assert _resume(plain, {"sim": "1.2.0"}) == []  # the last writer recorded none
    assert main(["show", str(plain)]) == 0
    assert "from step 0: torch " in capsys.readouterr().out


def _files(run: Path) -> dict[str, bytes]:
    return {str(p): p.read_bytes() for p in sorted(run.rglob("*")) if p.is_file()}


@pytest.mark.parametrize(
    "bad",
    [["1.2.0"], {"sim": 1.2}, {"sim": None}, {1: "1.2.0"}, None],
    ids=["list", "float", "none-value", "int-key", "none"],
)
def test_a_describe_versions_that_is_no_dict_of_str_is_refused_before_anything_is_written(
    tmp_path, bad
):
    env = _SimWorld(bad)
    with pytest.raises(TypeError, match=r"_SimWorld.describe_versions\(\) must return a dict of"):
        ConfidentTeacher(env, oracle(env.env), run_dir=tmp_path / "new", progress=False)
    assert not (tmp_path / "new").exists()
    run = tmp_path / "run"
    _session(run, {"sim": "1.2.0"}, steps=3)
    before = _files(run)
    with pytest.raises(TypeError, match=r"_SimWorld.describe_versions\(\) must return a dict of"):
        ConfidentTeacher.resume(run, env, oracle(env.env), progress=False)
    assert _files(run) == before
    assert len(load_records(run)) == 3


def test_a_describe_versions_that_raises_is_an_env_error_and_nothing_is_written(tmp_path):
    env = _SimWorld(OSError("no simulator found"))
    with pytest.raises(EnvError, match=r"_SimWorld.describe_versions\(\) raised OSError: no sim"):
        ConfidentTeacher(env, oracle(env.env), run_dir=tmp_path / "new", progress=False)
    assert not (tmp_path / "new").exists()
    run = tmp_path / "run"
    _session(run, {"sim": "1.2.0"}, steps=3)
    before = _files(run)
    with pytest.raises(EnvError, match=r"describe_versions\(\) raised OSError"):
        ConfidentTeacher.resume(run, env, oracle(env.env), progress=False)
    assert _files(run) == before


def test_a_resume_warns_only_on_a_key_both_writers_give_and_points_at_the_callers_line(tmp_path):
    """The comparison is of the keys both the last writer and the resuming env give: a key
    the env gives now that the last writer did not (a binding it has begun to report) is no
    change, and the warning of a change points at the line that called resume()."""
    run = tmp_path / "run"
    _session(run, {"sim": "1"}, steps=3)
    assert _resume(run, {"sim": "1", "bindings": "2"}) == []
    assert _writers(run)[-1]["env_versions"] == {"sim": "1", "bindings": "2"}
    (said,) = _recorded(run, {"sim": "3", "bindings": "2"})
    assert "last taught under sim 1 and is resumed under sim 3" in str(said.message)
    assert "bindings" not in str(said.message)
    assert said.filename == __file__, said.filename  # the caller's resume() line


def _recorded(run: Path, versions: object) -> list[warnings.WarningMessage]:
    env = _SimWorld(versions)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        ConfidentTeacher.resume(run, env, oracle(env.env), progress=False).close()
    return [w for w in said if issubclass(w.category, UserWarning)]


def test_a_last_writer_whose_env_versions_is_no_dict_resumes_silently(tmp_path):
    """A writers.jsonl edited by hand (or by another tool) whose last writer's env_versions is
    no dict, e.g. a list of names, is as a writer that recorded none: the resume says nothing
    and records its own versions (it did not fail on the list)."""
    run = tmp_path / "run"
    _session(run, {"sim": "1.2.0"}, steps=3)
    edited = _writers(run)
    edited[-1]["env_versions"] = ["sim"]
    (run / "writers.jsonl").write_text("".join(json.dumps(w) + "\n" for w in edited))
    assert _resume(run, {"sim": "9.9.9"}) == []
    assert _writers(run)[-1]["env_versions"] == {"sim": "9.9.9"}
    assert len(load_records(run)) == 5


def test_a_describe_versions_that_is_no_method_is_no_hook(tmp_path):
    """``describe_versions`` is read as ``describe_inputs`` is: an attribute of that name that
    cannot be called (a subclass setting it to a plain value) is no hook, so the writer records
    None, as for an env without it, rather than failing on the call."""
    run = tmp_path / "run"
    env = _SimWorld({"sim": "1.2.0"})
    env.describe_versions = "sim 1.2.0"  # type: ignore[method-assign,assignment]
    with ConfidentTeacher(env, oracle(env.env), run_dir=run, progress=False) as ct:
        ct.run(max_steps=3)
    assert _writers(run)[0]["env_versions"] is None


def test_a_describe_versions_of_an_empty_dict_is_recorded_as_given(tmp_path):
    """An env that runs on nothing it reports a version of gives ``{}``: the writer records
    ``{}`` (what the hook said), not None (no hook); show and a resume treat both alike."""
    run = tmp_path / "run"
    _session(run, {}, steps=3)
    assert _writers(run)[0]["env_versions"] == {}
    assert describe(run).writers[0]["env_versions"] == {}
    assert _resume(run, {"sim": "1.2.0"}) == []
