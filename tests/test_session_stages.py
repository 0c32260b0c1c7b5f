"""The model at many stages of a session in one pass (``torchcbl.session.load_models``): a
post-hoc learning curve over a session that kept only its newest checkpoints."""

from __future__ import annotations

import copy
import shutil
import threading
from pathlib import Path

import numpy as np
import pytest
import torch
from _toy_envs import ClusterWorld, oracle, rare_regions_world

import torchcbl
from torchcbl import ConfidentTeacher, GaussianMixtureSet, TeachingConfig
from torchcbl.errors import CorruptSessionError
from torchcbl.session import (
    load_corrections,
    load_demonstrations,
    load_labels,
    load_model,
    load_models,
)
from torchcbl.strategies import correcting
from torchcbl.strategies.cba import ConfidenceBasedAutonomy


def _state(model: torch.nn.Module) -> dict[str, torch.Tensor]:
    return copy.deepcopy(model.state_dict())


def _equal(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def _files(run: Path) -> dict[str, bytes]:
    return {str(p.relative_to(run)): p.read_bytes() for p in sorted(run.rglob("*")) if p.is_file()}


def _fitted_start() -> GaussianMixtureSet:
    start = GaussianMixtureSet(3, 2, seed=0)
    return start.fit(
        np.array([[0.1, 7.0], [0.3, 7.2], [5.0, 0.0], [5.2, 0.1], [9.0, 9.0], [9.1, 8.9]]),
        np.array([0, 0, 1, 1, 2, 2]),
    )


def _teach(run, refit, start="none", model=None, n_labels=30, max_new=4, keep=1):
    """A session keeping ``keep`` checkpoints, with a hand refit off the schedule at 6 labels
    (but with max_new=1, where every label is refitted);
    returns (its labels, {labels: the live model's state after each refit, 0: its start})."""
    env = rare_regions_world()
    live: dict[int, dict[str, torch.Tensor]] = {}
    if start == "fitted":
        model = _fitted_start()
    ct = ConfidentTeacher(
        env,
        oracle(env),
        model=model if model is not None else GaussianMixtureSet(3, 2, seed=0),
        prior_demonstrations=(
            env.sample(20, np.random.default_rng(1)) if start == "prior" else None
        ),
        config=TeachingConfig(noninteractive=False, max_new=max_new, refit=refit),
        run_dir=run,
        progress=False,
        keep_checkpoints=keep,
        on_refit=lambda m, n: live.__setitem__(n, _state(m)),
    )
    live[0] = _state(ct.model)  # unfitted, the prior's fit or the fitted start
    while ct.n_demonstrations < 6:
        ct.step()
    if max_new > 1:
        assert ct.refit()  # by hand, off the schedule (the loop refits max_new labels later)
    while ct.n_demonstrations < n_labels:
        ct.step()
    ct.close()
    return ct.n_demonstrations, live


@pytest.mark.parametrize("start", ["none", "prior", "fitted"])
@pytest.mark.parametrize("refit", ["full", "incremental"])
def test_every_stage_in_one_pass_is_load_models_and_the_live_model_bit_for_bit(
    tmp_path, refit, start
):
    """load_models gives, at every stage, the model load_model gives there and the live
    model had (its last refit's state), each its own object (kept all, then compared), and
    writes nothing into the session."""
    run = tmp_path / "run"
    n_labels, live = _teach(run, refit, start)
    stages = list(range(n_labels + 1))
    before = _files(run)
    got = list(load_models(run, stages))
    assert [n for n, _ in got] == stages
    assert len({id(m) for _, m in got}) == len(stages)
    for n, model in got:
        assert type(model) is GaussianMixtureSet
        stood_on = max(r for r in live if r <= n)
        assert _equal(model.state_dict(), live[stood_on]), (n, stood_on)
        assert _equal(model.state_dict(), load_model(run, n_demonstrations=n).state_dict()), n
    assert _files(run) == before


def test_the_stages_are_replayed_once_not_from_the_checkpoint_for_each(tmp_path):
    """An incremental session of 30 refits keeping one checkpoint: load_model at each stage
    replays every refit since the start (about 30 * 30 / 2 refits in all); load_models
    replays each refit at most once, and leaves the given model as it was."""
    calls = []

    class Counting(GaussianMixtureSet):
        def fit(self, *args):
            calls.append("fit")
            return super().fit(*args)

        def refit(self, *args):
            calls.append("refit")
            return super().refit(*args)

    run = tmp_path / "run"
    n_labels, live = _teach(run, "incremental", model=Counting(3, 2, seed=0), max_new=1)
    template = Counting(3, 2, seed=0)
    calls.clear()
    got = dict(load_models(run, range(n_labels + 1), model=template))
    assert len(calls) <= n_labels, len(calls)
    assert not template.is_fitted
    for n, model in got.items():
        assert type(model) is Counting and model is not template
        assert _equal(model.state_dict(), live[max(r for r in live if r <= n)]), n


class _FewStates(ClusterWorld):
    """rare_regions_world's layout (3 regions, 3 actions) whose observations are 12 fixed
    points, so they recur: CBA relabels a point taught again, and a correction relabels one."""

    def __init__(self) -> None:
        super().__init__([[0, 0], [6, 0], [0, 6]], [0, 1, 2], [0.6, 0.2, 0.2], episode_length=10)
        jitter = np.random.default_rng(0).standard_normal((12, 2))
        self.points = (np.repeat(self.centers, 4, axis=0) + jitter).astype(np.float32)

    def _draw(self) -> np.ndarray:
        self._obs = self.points[int(self.np_random.integers(12))].copy()
        return self._obs.copy()


def _fickle(env: _FewStates):
    """The optimal teacher, except that in every other block of 20 calls it wants action 1
    in the right half of region 0: the agent, confident there, is corrected again and again."""
    calls = [0]

    def teacher(obs, info):
        calls[0] += 1
        if (calls[0] // 20) % 2 and env.region_of(obs) == 0 and obs[0] > 0:
            return 1
        return env.optimal_action(obs)

    return teacher


class _Snapping(GaussianMixtureSet):
    """Calls ``before_fit`` (when set) as each fit or refit starts (once: a refit's own fit
    from scratch is part of it)."""

    before_fit = None
    _fitting = False

    def _around(self, fit, *args):
        if self.before_fit is not None and not self._fitting:
            self.before_fit()
        outer, self._fitting = self._fitting, True
        try:
            return fit(*args)
        finally:
            self._fitting = outer

    def fit(self, *args):
        return self._around(super().fit, *args)

    def refit(self, *args):
        return self._around(super().refit, *args)


def _teach_corrected(run, refit, max_new, start="none", model=None, on_step=None, live=None):
    """A CBA session taught by a correcting teacher, most of its labels corrections, keeping
    one checkpoint, with a hand refit at 7 labels (off the schedule of max_new 3 and 5);
    returns (the teacher, ``live``: {labels: the live model's state after each refit, 0: its
    start}, filled as the session runs, the label counts a correction brought).
    ``on_step(teacher, record)``: called after each step."""
    env = _FewStates()
    live = {} if live is None else live
    ct = ConfidentTeacher(
        env,
        correcting(_fickle(env)),
        strategy=ConfidenceBasedAutonomy(),
        model=_fitted_start() if start == "fitted" else model or GaussianMixtureSet(3, 2, seed=0),
        prior_demonstrations=(
            env.sample(20, np.random.default_rng(1)) if start == "prior" else None
        ),
        config=TeachingConfig(noninteractive=False, max_new=max_new, refit=refit),
        run_dir=run,
        progress=False,
        keep_checkpoints=1,
        on_refit=lambda m, n: live.__setitem__(n, _state(m)),
        on_step=None if on_step is None else lambda record: on_step(ct, record),
    )
    live[0] = _state(ct.model)
    while ct.n_demonstrations < 7:
        ct.step()
    assert ct.refit()  # by hand
    while ct.n_demonstrations < 40:
        ct.step()
    ct.close()
    corrected, n = [], 0
    by_step = {c.step for c in load_corrections(run)}
    for r in ct.records:
        assert not (r.is_demonstration and r.step in by_step)  # one label a step at most
        n += r.is_demonstration + (r.step in by_step)
        if r.step in by_step:
            corrected.append(n)
    assert n == ct.n_demonstrations == 40
    return ct, live, corrected


@pytest.mark.parametrize("start", ["none", "prior", "fitted"])
@pytest.mark.parametrize("refit", ["full", "incremental"])
@pytest.mark.parametrize("max_new", [3, 5])
def test_a_session_learning_from_corrections_is_rebuilt_at_every_stage(
    tmp_path, max_new, refit, start
):
    """CBA with a correcting teacher: a correction is a label of its own, so a refit falls
    due on one (here most of them do) and the schedule counts it like a demonstration; the
    stored points are relabelled (12 points at most for 40 labels). The loop refits every
    max_new labels from the last refit (by hand at 7), with or without a prior or a fitted
    start, and load_model and load_models rebuild the model it had at every stage, bit for
    bit (a rebuild on multiples of max_new counted from 0 would not: 7 is none)."""
    run = tmp_path / "run"
    ct, live, corrected = _teach_corrected(run, refit, max_new, start)
    assert sorted(live)[1:] == [*range(max_new, 7, max_new), *range(7, 41, max_new)]
    assert len(set(corrected) & set(live)) >= 3  # refits due on a correction
    # relabelled: 40 labels of at most 12 distinct observations (the prior's points first)
    assert len(load_demonstrations(run)[1]) <= (20 if start == "prior" else 0) + 12
    stages = list(range(41))
    for n, model in load_models(run, stages):
        stood_on = live[max(r for r in live if r <= n)]
        assert _equal(model.state_dict(), stood_on), n
        assert _equal(load_model(run, n_demonstrations=n).state_dict(), stood_on), n


@pytest.mark.parametrize("refit", ["full", "incremental"])
@pytest.mark.parametrize("max_new", [3, 5])
def test_a_session_learning_from_corrections_resumes_after_a_kill_at_any_label(
    tmp_path, max_new, refit
):
    """The run directory copied as a SIGKILL leaves it (its writer holding it, steps in the
    journal) after every step that recorded a label, and as every refit starts (its label,
    most often a correction, durable, the refit not done): each copy resumes with the model
    the live loop had then, or had after the refit it was doing, bit for bit, and the
    resumed loop refits next where the live schedule puts it."""
    run = tmp_path / "run"
    model = _Snapping(3, 2, seed=0)
    live: dict[int, dict[str, torch.Tensor]] = {}
    # (copy, the labels the live model stood on then, its state then; None for a refit the
    # loop had due: the state that refit gives)
    copies: list[tuple[Path, int, dict[str, torch.Tensor] | None]] = []
    seen = [0]

    def copy_now(refitting: bool) -> None:
        path = tmp_path / f"kill{len(copies)}"
        shutil.copytree(run, path)
        n = len(load_labels(path)[1])
        if refitting and n == max(live) + max_new:  # due: its label is durable, so it stands
            copies.append((path, n, None))
        else:  # between steps, or as the refit by hand starts (undone by the kill)
            copies.append((path, max(live), _state(model)))

    def on_step(ct, record) -> None:
        if ct.n_demonstrations != seen[0]:  # the step recorded a label
            seen[0] = ct.n_demonstrations
            copy_now(False)

    _Snapping.before_fit = staticmethod(lambda: copy_now(True))
    try:
        _teach_corrected(run, refit, max_new, model=model, on_step=on_step, live=live)
    finally:
        _Snapping.before_fit = None
    assert len(copies) == 40 + len(live) - 1  # after each label, as each refit starts
    refits: list[int] = []
    for path, stood_on, state in copies:
        env = _FewStates()
        refits.clear()
        back = ConfidentTeacher.resume(
            path,
            env,
            correcting(_fickle(env)),
            model=_Snapping(3, 2, seed=0),
            progress=False,
            on_refit=lambda m, k: refits.append(k),
        )
        want = live[stood_on] if state is None else state
        assert _equal(back.model.state_dict(), want), (path.name, stood_on)
        while not refits:
            back.step()
        assert refits[0] == stood_on + max_new, (path.name, stood_on, refits)
        back.close()


def test_damaged_and_foreign_checkpoints_give_what_load_model_gives(tmp_path):
    """A checkpoint cut short (passed over) and one holding another model's state (it does
    not load) are read as load_model reads them, and left where they are."""
    run = tmp_path / "run"
    n_labels, _ = _teach(run, "incremental", keep=3)
    checkpoints = sorted((run / "checkpoints").glob("model-*.pt"))
    assert [p.name[6:14] for p in checkpoints] == ["00000006", "00000022", "00000026", "00000030"]
    checkpoints[-1].write_bytes(checkpoints[-1].read_bytes()[:100])
    torch.save({"state_dict": {"weights_": torch.zeros(5, 5)}}, checkpoints[1])
    before = _files(run)
    for n, model in load_models(run, range(n_labels + 1)):
        assert _equal(model.state_dict(), load_model(run, n_demonstrations=n).state_dict()), n
    assert _files(run) == before


def test_a_lost_starting_model_is_refused_as_load_model_refuses_it(tmp_path):
    """A session started from a fitted model whose checkpoint 0 is gone: the stages that
    still stand on it are refused with load_model's CorruptSessionError; later ones, on a
    kept checkpoint, are read."""
    run = tmp_path / "run"
    n_labels, live = _teach(run, "incremental", "fitted")
    (run / "checkpoints" / "model-00000000.pt").unlink()
    with pytest.raises(CorruptSessionError) as single:
        load_model(run, n_demonstrations=3)
    stages = load_models(run, [3])  # refused when the stage is read, as load_model is
    with pytest.raises(CorruptSessionError) as many:
        next(stages)
    assert str(many.value) == str(single.value)
    ((n, model),) = load_models(run, [n_labels])
    assert _equal(model.state_dict(), live[n_labels])


@pytest.mark.parametrize(
    "bad, said",
    [
        ([4, 2], "got 2 after 4"),
        ([2, 2], "got 2 after 2"),
        ([-1], "got -1"),
        ([0, 13], "got 13"),
        ([2.5], "got 2.5"),
        ([True], "got True"),
        (5, "got 5"),
    ],
)
def test_stages_that_are_not_increasing_counts_of_the_log_are_refused_at_the_call(
    tmp_path, bad, said
):
    run = tmp_path / "run"
    env = rare_regions_world()
    ct = ConfidentTeacher(
        env,
        oracle(env),
        config=TeachingConfig(max_demonstrations=12, max_new=4),
        run_dir=run,
        progress=False,
    )
    ct.run()
    ct.close()
    with pytest.raises(ValueError) as caught:
        load_models(run, bad)  # at the call, before any stage is read
    msg = str(caught.value)
    assert msg.startswith("n_demonstrations: expected increasing ints from 0 to 12"), msg
    assert said in msg, msg
    if "after" not in said:  # the stages it suggests start at the first fit (max_new): the
        # range(0, ...) it gave began with the unfitted model, which no GreedyPolicy can run
        assert "e.g. range(4, 13, 10) (the session's first refit is due at max_new=4" in msg
    assert list(load_models(run, [])) == []


def test_a_model_that_cannot_be_copied_is_refused_at_the_call_pointing_to_load_model(tmp_path):
    """Each stage is a copy of the model given; one holding a lock cannot be copied."""

    class Locked(GaussianMixtureSet):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.lock = threading.Lock()

    run = tmp_path / "run"
    n_labels, _ = _teach(run, "full", model=Locked(3, 2, seed=0), n_labels=8)
    with pytest.raises(ValueError) as caught:
        load_models(run, [0, n_labels], model=Locked(3, 2, seed=0))
    msg = str(caught.value)
    assert msg.startswith("model: expected a model copy.deepcopy can copy"), msg
    assert "got a Locked that cannot be copied" in msg, msg
    assert "load_model(run_dir, n_demonstrations=n, model=Locked(...))" in msg, msg


def test_a_missing_prior_is_refused_at_the_call(tmp_path):
    run = tmp_path / "run"
    _teach(run, "full", "prior", n_labels=8)
    (run / "prior.npz").unlink()
    with pytest.raises(CorruptSessionError, match=r"prior\.npz is missing"):
        load_models(run, [0, 8])


def test_load_models_is_exported_beside_load_model():
    assert torchcbl.load_models is load_models


def test_describe_and_its_summary_are_exported_beside_load_model():
    """The README writes torchcbl.describe(run_dir); torchcbl had no describe."""
    from torchcbl.session import SessionSummary, describe

    assert torchcbl.describe is describe and torchcbl.SessionSummary is SessionSummary
    assert {"describe", "SessionSummary"} <= set(torchcbl.__all__)
