"""The notebooks render: a figure shows as an image, not as ``<Figure size ...>``.

(Every notebook is also run top to bottom by nbmake, see pyproject.toml; the root conftest.py
fails a notebook that leaves anything in its temporary directory.)
"""

from __future__ import annotations

from pathlib import Path

import pytest

NOTEBOOKS = Path(__file__).parents[1] / "notebooks"


def _code_cells(name: str) -> list[str]:
    """The sources of notebook ``name``'s code cells, in order."""
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    return [c.source for c in nb.cells if c.cell_type == "code"]


def _set_up_02(max_steps: int, display) -> tuple[dict, list[str]]:
    """Notebook 02's set-up cell run (its % magics left out), its teaching capped at
    ``max_steps`` and ``display`` standing in for IPython's; returns the scope and the code
    cells (the teaching cell is the third)."""
    import dataclasses

    code = _code_cells("02_corridor_teaching.ipynb")
    scope: dict = {}
    exec("\n".join(ln for ln in code[0].splitlines() if not ln.startswith("%")), scope)
    experiment = scope["experiment"]
    scope["experiment"] = dataclasses.replace(
        experiment, teaching=dataclasses.replace(experiment.teaching, max_steps=max_steps)
    )
    scope["display"] = display
    return scope, code


def _run_until_the_first_figure(path: Path):
    """Execute ``path``'s code cells in order until one outputs a matplotlib figure; return
    that cell (executed) or None if no cell shows a figure."""
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}
    )
    with client.setup_kernel():
        for index, cell in enumerate(nb.cells):
            if cell.cell_type != "code":
                continue
            client.execute_cell(cell, index)
            shown = [o for o in cell.outputs if o.get("output_type") != "stream"]
            if any("<Figure" in o.get("data", {}).get("text/plain", "") for o in shown):
                return cell
    return None


def test_notebook_02_shows_its_first_map_as_an_image():
    cell = _run_until_the_first_figure(NOTEBOOKS / "02_corridor_teaching.ipynb")
    assert cell is not None and "map_figure(" in cell.source  # the map of the corridor
    figures = [o for o in cell.outputs if "<Figure" in o.get("data", {}).get("text/plain", "")]
    assert all("image/png" in o["data"] for o in figures), [o["data"].keys() for o in figures]


def test_notebook_01_says_which_component_counts_its_fit_chose():
    """Its prose names the counts and action 1's AIC margin that its own fit prints (a single
    Gaussian split in two showed in the plot without a word)."""
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.read(NOTEBOOKS / "01_gmm_set.ipynb", as_version=4)
    code = [c.source for c in nb.cells if c.cell_type == "code"]
    scope: dict = {}
    exec("\n".join(code[:3]), scope)  # imports, the data, the fit
    counts = scope["gmm"].n_components_.tolist()
    aic = scope["gmm"].criterion_[1].tolist()
    prose = "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")
    assert f"Here the counts are {counts}" in prose
    assert f"({aic[1]:.1f} against {aic[0]:.1f})" in prose
    assert counts[1] == 2 and "bic" in prose
    bic = type(scope["gmm"])(3, 2, 6, criterion="bic", seed=0).fit(scope["X"], scope["y"])
    assert int(bic.n_components_[1]) == 1


def test_notebook_02_redraws_its_live_plot_at_most_about_once_a_second():
    """Its teaching cell redrew the live plot every 20 steps: 96 redraws of 0.15 s each made
    15 of the cell's 17 s, for a loop that teaches in under 2 s. Here its set-up and teaching cells
    run (the teaching capped at 400 steps) with a stand-in for ``display`` that counts the
    updates: at most one a second, plus the first and the last."""
    import time

    updates: list[float] = []

    class Handle:
        def update(self, figure):
            updates.append(time.monotonic())

    scope, code = _set_up_02(400, lambda *args, **kwargs: Handle())
    teach = code[2]
    assert "ct.run()" in teach and "on_step=" in teach
    start = time.monotonic()
    exec(teach, scope)
    elapsed = time.monotonic() - start
    assert len(scope["ct"].records) == 400
    assert len(updates) <= elapsed + 2, (len(updates), elapsed)


def test_notebook_02_prints_the_threshold_its_prose_gives(capsys):
    """Its prose reads the paper's rule as 2.83 std in 3-D; its set-up cell printed the rule as
    ``DistanceRule(quantile=0.9544997361036416)``, a number the prose never names."""
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.read(NOTEBOOKS / "02_corridor_teaching.ipynb", as_version=4)
    setup = next(c.source for c in nb.cells if c.cell_type == "code")
    scope: dict = {}
    exec("\n".join(ln for ln in setup.splitlines() if not ln.startswith("%")), scope)
    shown = f"{scope['rule'].threshold(3):.2f} std"
    assert shown == "2.83 std"
    prose = "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")
    assert shown in prose and shown in capsys.readouterr().out


def test_the_notebooks_import_nothing_they_do_not_use():
    """A newcomer copies a notebook's imports; 03 imported numpy and never used it (ruff
    skips the notebooks, see pyproject.toml, so only this catches it)."""
    import subprocess
    import sys

    pytest.importorskip("ruff")
    run = subprocess.run(
        [sys.executable, "-m", "ruff", "check", "--no-cache", "--select", "F401", str(NOTEBOOKS)],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stdout + run.stderr


def test_notebook_02_draws_the_robot_that_drove_the_learned_policys_circuit():
    """Its evaluation cell drove the learned policy on an env of its own but drew the teaching
    env's robot beside that path: a robot, with its sensor rays, where the evaluated one never
    ended. Here its set-up, teaching (capped at 400 steps) and evaluation cells run: the robot in
    the figure stands at the path's last pose."""
    from matplotlib.patches import Circle

    class Handle:
        def update(self, figure):
            pass

    scope, code = _set_up_02(400, lambda *args, **kwargs: Handle())
    evaluation = next(c for c in code if "evaluate_policy(" in c)
    assert "map_figure(" in evaluation
    exec(code[2], scope)
    *body, last = evaluation.rstrip().splitlines()
    exec("\n".join(body) + "\nfigure = " + last, scope)
    robots = [p for p in scope["figure"].axes[0].patches if isinstance(p, Circle)]
    assert len(robots) == 1
    assert robots[0].center == pytest.approx(scope["path"][-1], abs=1e-9)


def test_notebook_01_round_trip_cell_runs_after_the_fit_alone():
    """Its save-and-load cell, the one a newcomer copies to keep a model, compared the two
    models on ``grid``, a name the plotting cell defines: run without that figure it failed with
    a NameError. Here only the imports, the data, the fit and that cell run."""
    code = _code_cells("01_gmm_set.ipynb")
    round_trip = next(c for c in code if "load_state_dict(" in c)
    scope: dict = {}
    exec("\n".join([*code[:3], round_trip]), scope)
    fresh, gmm, X = scope["fresh"], scope["gmm"], scope["X"]
    assert fresh is not gmm and fresh.classify(X).action.tolist() == gmm.classify(X).action.tolist()


def test_notebook_01_labels_the_axes_of_its_figure():
    """Its figure of the components and the ask-region had a title but no axis labels, so a
    reader could not tell which of the observation's two features runs along which axis. Here its
    cells up to the figure run (without its ``plt.show()``, so no backend is involved)."""
    code = _code_cells("01_gmm_set.ipynb")
    figure_cell = next(i for i, c in enumerate(code) if "plt.show()" in c)
    scope: dict = {}
    exec("\n".join(code[: figure_cell + 1]).replace("plt.show()", ""), scope)
    scope["plt"].close(scope["fig"])
    (ax,) = scope["fig"].axes
    labels = ax.get_xlabel(), ax.get_ylabel()
    assert all(labels) and labels[0] != labels[1], labels


def test_notebook_02_labels_both_axes_of_both_live_panels():
    """Its live plot's right-hand panel (the windowed accuracy, a share from 0 to 1) had no
    y-axis label. Here its set-up and teaching cells run, the teaching capped at 30 steps, with a
    stand-in for ``display``; every panel of the live figure names both its axes."""

    class Handle:
        def update(self, figure):
            pass

    scope, code = _set_up_02(30, lambda *args, **kwargs: Handle())
    exec(code[2], scope)
    panels = scope["live"].axes
    assert len(panels) == 2
    assert all(ax.get_xlabel() and ax.get_ylabel() for ax in panels), [
        (ax.get_xlabel(), ax.get_ylabel()) for ax in panels
    ]


def test_notebook_03_draws_its_road_at_the_steps_its_titles_name():
    """Its road cell took frames where its loop index was 20, 60 and 100, after 21, 61 and 101
    steps: the frames, titled with the env's own count of steps since reset (``t=``), read
    t=21, 61, 101 under code that names 20, 60, 100. Here its set-up and road cells run (120
    SUMO steps in this process, without ``plt.show()``): the frames drawn are those at steps
    20, 60 and 100."""
    code = _code_cells("03_driving.ipynb")
    setup, road = code[0], next(c for c in code if "env.frame()" in c)
    assert "(20, 60, 100)" in road
    scope: dict = {}
    exec(setup, scope)
    try:
        exec(road.replace("plt.show()", ""), scope)
    finally:
        scope["run_tmp"].cleanup()
    scope["plt"].close(scope["fig"])
    # render_frame titles each image "t={frame.step}"
    assert [f.step for f in scope["frames"]] == [20, 60, 100]


def test_notebook_01_asks_by_the_confidence_rule_not_by_a_number_of_its_own(capsys):
    """Its probe cell printed "ask" as ``distance > 2``, a threshold of its own beside the
    figure's ``DistanceRule(2.0)``: copied for the corridor (2.83 std) it asked wrongly. Here
    the imports, the data, the fit and the probe cell run with another rule in the place of
    ``DistanceRule`` (a quantile rule, 0.67 std in 2-D, which also needs the observations to
    know D): the printed asks are that rule's."""
    import re

    import numpy as np

    from torchcbl import DistanceRule

    code = _code_cells("01_gmm_set.ipynb")
    probe_cell = next(c for c in code if "probe =" in c)
    scope: dict = {}
    exec("\n".join(code[:3]), scope)  # imports, the data, the fit
    stand_in = DistanceRule(quantile=0.2)
    scope["DistanceRule"] = lambda *args, **kwargs: stand_in
    capsys.readouterr()
    exec(probe_cell, scope)
    printed = re.findall(r"distance ([\d.]+) std.*ask: (True|False)", capsys.readouterr().out)
    probe = scope["probe"]
    wanted = (~stand_in.is_confident(scope["gmm"].classify(probe), probe)).tolist()
    assert [ask == "True" for _, ask in printed] == wanted
    assert len(wanted) == len(probe) and wanted != [float(d) > 2 for d, _ in printed]
    assert np.isclose(stand_in.threshold(2), 0.668, atol=1e-3)
