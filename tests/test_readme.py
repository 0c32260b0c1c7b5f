"""The README's promises: its Python example runs, and its quickstart is what CI runs."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def test_the_python_example_runs(tmp_path, monkeypatch):
    block = re.search(r"```python\n(.*?)```", README, re.S).group(1)
    monkeypatch.chdir(tmp_path)  # it writes runs/my-session
    scope: dict = {}
    exec(compile(block, "README.md", "exec"), scope)
    assert scope["c"].action.shape == (5,)
    assert scope["ct"].stop_reason == "autonomous_episodes"
    ends = [r for r in scope["records"] if r.terminated or r.truncated]
    assert len(ends) == 10 and all(r.info["is_success"] for r in ends)
    results = scope["results"]
    assert [e.success for e in results] == [True] * 10
    assert sum(e.steps for e in results) == len(scope["records"])
    # leaving the with block closed the step log: SQLite removes its write-ahead log then
    assert not (tmp_path / "runs" / "my-session" / "steps.sqlite-wal").exists()
    assert (tmp_path / "runs" / "my-session" / "config.json").exists()


def test_quickstart_has_two_commands_and_ci_runs_the_test_one():
    block = re.search(r"## Quickstart.*?```bash\n(.*?)```", README, re.S).group(1)
    commands = [line.split("#")[0].strip() for line in block.splitlines() if line.strip()]
    assert commands == ["bash scripts/reproduce.sh", "bash scripts/test.sh"]
    ci = (ROOT / ".ci" / "run").read_text()
    assert "\nbash scripts/test.sh\n" in ci
