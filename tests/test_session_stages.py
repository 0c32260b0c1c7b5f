"""The model at many stages of a session in one pass (``torchcbl.session.load_models``): a
post-hoc learning curve over a session that kept only its newest checkpoints."""

from __future__ import annotations

import copy
import threading
from pathlib import Path

import numpy as np
import pytest
import torch
from _toy_envs import oracle, rare_regions_world

import torchcbl
from torchcbl import ConfidentTeacher, GaussianMixtureSet, TeachingConfig
from torchcbl.errors import CorruptSessionError
from torchcbl.session import load_model, load_models


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
