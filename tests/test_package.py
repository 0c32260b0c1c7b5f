import hashlib
import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import torchcbl


def test_unknown_attribute_is_a_clear_error():
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        torchcbl.Nope  # noqa: B018


def test_core_never_imports_a_simulator_or_a_domain():
    code = (
        "import sys, torchcbl\n"
        "for name in list(torchcbl._EXPORTS):\n"
        "    try:\n"
        "        getattr(torchcbl, name)\n"
        "    except (ImportError, AttributeError):\n"
        "        pass\n"
        "bad = [m for m in ('pymunk', 'libsumo', 'traci', 'corridor', 'sumo_scenarios')\n"
        "       if m in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_mean_sd_by_hand():
    from torchcbl.evaluation import mean_sd, run_versions

    assert mean_sd([1.0, 2.0, 3.0, None]) == {"mean": 2.0, "sd": 1.0, "n": 3}
    assert mean_sd([5]) == {"mean": 5.0, "sd": None, "n": 1}
    assert mean_sd([None]) == {"mean": None, "sd": None, "n": 0}
    v = run_versions(sim="1.2")
    assert v["sim"] == "1.2" and v["torchcbl"] == torchcbl.__version__


def test_paired_interval_is_one_function_of_the_core_that_the_driving_experiment_uses():
    """The benchmark and the driving experiment report a paired difference's 95 % t interval
    with the same code: the core's (the core never imports a domain, so it lives there)."""
    import sumo_scenarios.experiment
    from torchcbl.evaluation import paired_interval

    assert sumo_scenarios.experiment.paired_interval is paired_interval
    d = paired_interval([1.0, 2.0, 3.0, 4.0])  # t(0.975, 3) = 3.182, sd 1.291
    assert d["n"] == 4 and d["ci95"] == pytest.approx([0.4457, 4.5543], abs=1e-3)
    assert paired_interval([0.5]) == {"mean": 0.5, "sd": None, "n": 1, "ci95": None}


@pytest.mark.parametrize("n", [2, 5, 31, 32, 41, 101, 1001, 10_000])
def test_paired_interval_takes_t_at_every_n_as_scipy_does(n):
    """The interval is the mean +- t(0.975, n - 1) sd / sqrt(n) at every n: beyond 31 pairs
    it took 1.96 (z), 4 % too narrow at 32 (t(31) = 2.040), and the benchmark allows 10,000
    seeds. scipy's Student t is the oracle."""
    import numpy as np

    from torchcbl.evaluation import paired_interval

    stats = pytest.importorskip("scipy.stats")
    diffs = np.linspace(-1.0, 2.0, n) ** 2
    d = paired_interval(diffs.tolist())
    half = stats.t.ppf(0.975, n - 1) * np.std(diffs, ddof=1) / np.sqrt(n)
    assert d["ci95"][1] - d["mean"] == pytest.approx(half, rel=2e-4)
    assert d["mean"] - d["ci95"][0] == pytest.approx(half, rel=2e-4)


def test_run_versions_name_the_commit_of_the_checkout_that_ran():
    """A results.json said torchcbl 0.1.0 for every commit of the project, so two run
    directories made by different code (whose figures differ) could not be told apart, nor
    a run replayed on the code that made it. From a git checkout, the versions name its
    commit, and whether tracked files differed from it."""
    from torchcbl.evaluation import run_versions

    root = Path(torchcbl.__file__).resolve().parents[1]
    git = shutil.which("git")
    if git is None:
        pytest.skip("no git")
    top = subprocess.run(
        [git, "-C", str(root), "rev-parse", "--show-toplevel"], capture_output=True, text=True
    )
    if top.returncode or Path(top.stdout.strip()).resolve() != root:
        pytest.skip("torchcbl is not imported from a git checkout")
    head = subprocess.run(
        [git, "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, check=True
    ).stdout.strip()
    source = run_versions()["torchcbl_source"]
    dirty = subprocess.run(
        [git, "-C", str(root), "diff", "HEAD"], capture_output=True, check=True
    ).stdout
    new = subprocess.run(
        [git, "-C", str(root), "ls-files", "--others", "--exclude-standard", "--"]
        + ["torchcbl", "corridor", "sumo_scenarios"],
        capture_output=True,
        check=True,
    ).stdout
    if new:  # the other test checks what untracked files do to the code
        assert source.startswith(f"git {head} with uncommitted changes (diff "), source
    elif not dirty:
        assert source == f"git {head}", source
    else:  # which changes, too: two different edits of one commit are two codes
        digest = hashlib.sha256(dirty).hexdigest()[:12]
        assert source == f"git {head} with uncommitted changes (diff {digest})", source


def test_a_new_module_not_yet_added_to_git_marks_the_source_as_changed(tmp_path):
    """A results.json named its code "git SHA" with no change marked when the edit that made
    its figures was a new module not yet `git add`-ed (only tracked files were compared), so
    `reproduce --resume` took seeds of other code as this code's. Untracked files in the
    packages count now, by content; a file elsewhere in the checkout (notes, a scratch
    script) does not."""
    git = shutil.which("git")
    if git is None:
        pytest.skip("no git")
    clone = tmp_path / "clone"  # a checkout of this code, committed
    for package in ("torchcbl", "corridor", "sumo_scenarios"):
        shutil.copytree(
            Path(__file__).parents[1] / package,
            clone / package,
            ignore=shutil.ignore_patterns("__py*"),
        )
    (clone / ".gitignore").write_text("__pycache__/\n")
    for args in (["init", "-q"], ["add", "-A"], ["commit", "-qm", "code"]):
        subprocess.run(
            [git, "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=clone, check=True
        )
    script = """
from pathlib import Path
from torchcbl.evaluation import run_versions
def source():
    return run_versions()["torchcbl_source"]
clean = source()
Path("notes.md").write_text("my notes")
Path("scratch.py").write_text("print(1)")
aside = source()
Path("corridor/_mine.py").write_text("A = 1")
one = source()
Path("corridor/_mine.py").write_text("A = 2")
two = source()
import os
os.remove("corridor/_mine.py")
Path("corridor/__init__.py").write_bytes(Path("corridor/__init__.py").read_bytes() + b"# caf\\xe9")
latin = source()  # a tracked edit that is not UTF-8
open(b"corridor/_caf\\xe9.txt", "wb").write(b"x")
named = source()  # an untracked file whose name is not UTF-8
os.symlink("/nonexistent/target", "corridor/_link")
linked = source()  # a dangling link
print(repr((clean, aside, one, two, latin, named, linked)))
"""
    proc = subprocess.run(
        [sys.executable, "-c", script],
        cwd=clone,
        env={**os.environ, "PYTHONPATH": str(clone)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    clean, aside, one, two, latin, named, linked = eval(proc.stdout.strip().splitlines()[-1])
    assert clean.startswith("git ") and "uncommitted" not in clean, clean
    assert aside == clean
    assert one.startswith(clean + " with uncommitted changes (diff "), one
    assert two != one and two.startswith(clean + " with uncommitted changes (diff "), two
    # bytes that are not UTF-8 (a diff, a file name) and a dangling link: each another code
    later = [latin, named, linked]
    assert all(v.startswith(clean + " with uncommitted changes (diff ") for v in later), later
    assert len({one, two, *later}) == 5, later


ROOT = Path(__file__).parents[1]


def test_pyproject_builds_without_a_setuptools_deprecation_warning(monkeypatch):
    """The license as an SPDX string: the TOML-table form warns with setuptools >= 77."""
    setuptools = pytest.importorskip("setuptools", minversion="77")
    from setuptools.config.pyprojecttoml import apply_configuration
    from setuptools.dist import Distribution

    monkeypatch.chdir(ROOT)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        dist = apply_configuration(Distribution(), ROOT / "pyproject.toml")
    deprecations = [
        str(w.message).splitlines()[0]
        for w in caught
        if issubclass(w.category, (DeprecationWarning, setuptools.warnings.SetuptoolsWarning))
    ]
    assert deprecations == []
    assert dist.metadata.name == "torchcbl"
    # the MIT license's text ships with the package (the license requires its notice)
    assert dist.metadata.license_files == ["LICENSE"]
    assert "MIT License" in (ROOT / "LICENSE").read_text()


def test_a_test_run_ends_without_a_tool_advertisement():
    """nbmake prints a link to itself after every run that collects notebooks; the root
    conftest.py turns that off."""
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider"]
        + ["tests/test_package.py::test_mean_sd_by_hand"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "1 passed" in proc.stdout
    assert "nbmake" not in (proc.stdout + proc.stderr).lower()


def test_requires_python_admits_only_pythons_the_code_runs_on():
    """The loop and the session store add a note to the exception they re-raise (a Ctrl-C in
    env.step, a failed write: BaseException.add_note, PEP 678, new in Python 3.11); on 3.10
    that call is an AttributeError in place of the KeyboardInterrupt or SessionWriteError.
    So pip must refuse every Python before 3.11, as the README's set-up assumes 3.11."""
    import tomllib

    from packaging.specifiers import SpecifierSet

    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
    admits = SpecifierSet(meta["project"]["requires-python"])
    oldest = min(v for v in ((3, m) for m in range(6, 20)) if admits.contains(f"{v[0]}.{v[1]}.0"))
    assert oldest >= (3, 11), f"requires-python admits Python {oldest[0]}.{oldest[1]}"
    assert sys.version_info >= oldest  # the suite itself runs on an admitted Python
    # ruff lints for the same oldest Python (it would otherwise accept 3.11-only code)
    assert meta["tool"]["ruff"]["target-version"] == f"py{oldest[0]}{oldest[1]}"


def test_the_packages_ship_their_type_hints(monkeypatch):
    """The public API has type hints, but no package carried the PEP 561 marker, so a user's
    mypy or pyright ignored them (every torchcbl name was Any). Each package has a py.typed,
    pyproject's package data names it (setuptools >= 69 also adds it unasked; the declaration
    keeps it shipped whatever the backend) and the wheel gets it (what build_py would copy,
    worked out without building)."""
    pytest.importorskip("setuptools", minversion="77")
    import tomllib
    from importlib.resources import files

    from setuptools.config.pyprojecttoml import apply_configuration
    from setuptools.dist import Distribution

    monkeypatch.chdir(ROOT)
    dist = apply_configuration(Distribution(), ROOT / "pyproject.toml")
    dist.include_package_data = False  # only what pyproject declares (and no egg-info written)
    build_py = dist.get_command_obj("build_py")
    build_py.ensure_finalized()
    shipped = {(pkg, name) for pkg, _src, _build, names in build_py.data_files for name in names}
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    for package in ("torchcbl", "corridor", "sumo_scenarios"):
        assert files(package).joinpath("py.typed").is_file(), package
        assert "py.typed" in declared["package-data"].get(package, []), package
        assert (package, "py.typed") in shipped, package


def test_help_on_a_public_constructor_never_shows_another_librarys_text():
    """``GaussianMixtureSet?`` in IPython (and an editor's hover) shows the class's docstring
    and its ``__init__``'s: GaussianMixtureSet's was torch's inherited "Initialize internal
    Module state, shared by both nn.Module and ScriptModule.", which says nothing of the
    model a user builds. A public class's constructor help is its own, or Python's default
    pointer to the class's help."""
    import inspect

    python_default = inspect.getdoc(object.__init__)
    for name in torchcbl.__all__:
        obj = getattr(torchcbl, name)
        if not inspect.isclass(obj):
            continue
        doc = inspect.getdoc(obj.__init__)  # its own, else the nearest base's
        assert doc in (None, python_default) or obj.__init__.__doc__, name
    doc = inspect.getdoc(torchcbl.GaussianMixtureSet.__init__)
    assert "unfitted" in doc and "n_actions" in doc and "ValueError" in doc
