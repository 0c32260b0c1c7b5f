"""The README's promises: its Python example runs, and its quickstart is what CI runs."""

from __future__ import annotations

import inspect
import re
import textwrap
from pathlib import Path

import pytest

import torchcbl
from torchcbl import ConfidentTeacher, GreedyPolicy, evaluate_policy, load_models

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

    # what the text says of the session's counts, with the names it calls on run_dir: each is
    # runnable as written after `import torchcbl` (describe was written bare, and torchcbl had
    # no describe to import)
    spans = re.findall(r"`([^`\n]*\bdescribe\(run_dir\)[^`\n]*)`", README)
    assert spans
    names = {"torchcbl": torchcbl, "run_dir": "runs/my-session"}
    said = {span: eval(span, names) for span in spans}  # noqa: S307 - the README's own code
    ct = scope["ct"]
    assert said["torchcbl.describe(run_dir).n_episodes_ended"] == ct.n_episodes
    assert said["torchcbl.describe(run_dir).n_episodes"] >= ct.n_episodes

    # the teacher's signature: the example after it runs in the same scope, and what its
    # comment and the text before it say a one-argument policy meets holds
    block = re.search(r"```python\n(policy = ct\.policy.*?)```", README, re.S).group(1)
    exec(compile(block, "README.md", "exec"), scope)
    assert isinstance(scope["student"], ConfidentTeacher)
    assert len(scope["expert_records"]) == 50
    env, policy, teacher = scope["env"], scope["policy"], scope["teacher"]
    with pytest.raises(TypeError, match=r"teacher\(observation, info\).*lambda obs, info"):
        ConfidentTeacher(env, policy)
    with pytest.raises(TypeError, match="uses_info=True"):
        evaluate_policy(teacher, env, n_steps=5)
    with pytest.raises(TypeError, match="leave uses_info out"):
        evaluate_policy(lambda obs: policy(obs), env, n_steps=5, uses_info=True)

    # the learning curve of that session, as the README and load_models' docstring write it,
    # runs as written: from the first fitted stage (stage 0 has no model: the examples began
    # there and stopped at once, evaluate_policy refusing the unfitted model's -1)
    block = re.search(r"```python\n(# a learning curve.*?)```", README, re.S).group(1)
    exec(compile(block, "README.md", "exec"), scope)
    n_labels = scope["ct"].n_demonstrations
    assert scope["first"] == 1  # the default max_new, no prior demonstrations
    assert [n for n, _ in scope["curve"]] == list(range(1, n_labels + 1, 10))
    assert all(0.0 <= rate <= 1.0 for _, rate in scope["curve"])
    ((_, unfitted),) = load_models("runs/my-session", [0])
    assert not unfitted.is_fitted
    with pytest.raises(RuntimeError, match="not fitted"):  # what the text says of stage 0
        evaluate_policy(GreedyPolicy(unfitted), env, n_steps=5)
    doc = inspect.getdoc(load_models).split("Example (a learning curve", 1)[1]
    example = textwrap.dedent(doc.split("::", 1)[1]).strip("\n")
    exec(compile(example, "load_models", "exec"), {**scope, "run_dir": "runs/my-session"})


def test_the_goal_is_success_example_runs_and_counts_mountaincars_goals():
    """The README's wrapper for an env whose episodes end (terminated) at the goal, the one the
    warning of an unjudged episode names: MountainCar taught with it stops on its streak, its
    last episodes goals, and an evaluation reads its goals as successes (the warning's tests
    are in test_stops_and_evaluation.py)."""
    blocks = [b for b in re.findall(r"```python\n(.*?)```", README, re.S) if "GoalIsSuccess" in b]
    assert len(blocks) == 1 and "Success is never assumed:" in README
    scope: dict = {}
    exec(compile(blocks[0], "README.md", "exec"), scope)
    ct = scope["ct"]
    assert ct.stop_reason == "autonomous_episodes" and ct.n_steps < 20_000
    ends = [r for r in ct.records if r.terminated or r.truncated][-5:]
    assert all(r.terminated and r.info["is_success"] is True for r in ends)
    # evaluation reads it too: a greedy episode that reaches the goal is a success
    from torchcbl import episode_results

    results = episode_results(evaluate_policy(ct.policy, scope["env"], seed=0, n_episodes=1))
    assert [e.success for e in results] == [True]


def test_quickstart_has_two_commands_and_ci_runs_the_test_one():
    block = re.search(r"## Quickstart.*?```bash\n(.*?)```", README, re.S).group(1)
    commands = [line.split("#")[0].strip() for line in block.splitlines() if line.strip()]
    assert commands == ["bash scripts/reproduce.sh", "bash scripts/test.sh"]
    ci = (ROOT / ".ci" / "run").read_text()
    assert "\nbash scripts/test.sh\n" in ci


def _section(text: str, heading: str) -> str:
    """The body of the Markdown section ``heading`` (a whole heading line), to the next heading
    of its level or above."""
    level = heading.split(" ")[0]
    body = text.split(f"\n{heading}\n", 1)[1]
    stop = re.search(rf"^#{{1,{len(level)}}} ", body, re.M)
    return body[: stop.start()] if stop else body


def _anchors(path: Path) -> set[str]:
    """GitHub's anchors of a Markdown file's headings."""
    headings = re.findall(r"^#+ (.*)$", path.read_text(encoding="utf-8"), re.M)
    return {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-") for h in headings}


def test_the_tables_section_opens_with_how_they_were_made_and_the_rerun_log_is_in_the_docs():
    """The tables' section opens with the command, the machine, how long and that the same seed
    gives the same run; the log of reruns (commits and their timings) is in
    docs/reproduction.md's "Reruns", which the opening points to."""
    section = _section(README, "## The paper's numbers beside ours")
    opening = section.strip().split("\n\n")[0]
    for fact in ("bash scripts/reproduce.sh", "2-core machine", "7-8 minutes", "same seed"):
        assert fact in opening, fact
    commit = r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7}\b"
    assert not re.findall(commit, opening), "commit hashes belong to docs/reproduction.md"
    assert "(docs/reproduction.md#reruns)" in opening
    reproduction = ROOT / "docs" / "reproduction.md"
    assert "reruns" in _anchors(reproduction)
    reruns = _section(reproduction.read_text(), "### Reruns")
    for run in ("790ca71", "81faa65", "2935d51", "9667e86", "8b3eef3", "82db9a9", "87cb124"):
        assert run in reruns, run


def test_the_readmes_links_into_the_docs_name_files_and_headings_that_exist():
    for target in re.findall(r"\]\((docs/[^)\s]+)\)", README):
        path, _, anchor = target.partition("#")
        assert (ROOT / path).exists(), target
        if anchor and path.endswith(".md"):
            assert anchor in _anchors(ROOT / path), target
