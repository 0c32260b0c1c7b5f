"""The teaching loop with a CUDA model: every shipped strategy decides as with the CPU model,
and a session taught on the GPU loads on a machine without one.

Skipped where torch sees no CUDA device (this project's CI machines); run on a machine with a
GPU (``pytest tests/test_teaching_cuda.py``). The oracle is the same run with the model on the
CPU: same seed, same env, same teacher. A CUDA model classifies a single observation through
torch (the CPU model through numpy), so distances may differ in their last bits; no decision
of these runs lies that close to a threshold.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from _toy_envs import oracle, rare_regions_world

from torchcbl import ConfidentTeacher, GaussianMixtureSet, TeachingConfig
from torchcbl.errors import CorruptSessionError
from torchcbl.session import load_records
from torchcbl.strategies import ConfidentExecution, correcting
from torchcbl.strategies.bc import BehaviourCloning
from torchcbl.strategies.cba import ConfidenceBasedAutonomy
from torchcbl.strategies.dagger import DAgger
from torchcbl.strategies.hg_dagger import HGDAgger
from torchcbl.strategies.novelty import NoveltyGated

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")

STRATEGIES = {
    "ce": (ConfidentExecution, False),
    "cba": (ConfidenceBasedAutonomy, True),
    "bc": (BehaviourCloning, False),
    "dagger": (lambda: DAgger(decay=0.5, iteration_steps=20, seed=1), False),
    "hg_dagger": (lambda: HGDAgger(warmup=3), True),
    "novelty": (lambda: NoveltyGated(target_rate=0.2, window=30, warmup=5, min_history=5), False),
}


def _teach(device: str, name: str, run_dir: Path, steps: int = 150) -> ConfidentTeacher:
    make, corrects = STRATEGIES[name]
    env = rare_regions_world(episode_length=10, spread=2.0)
    teacher = correcting(oracle(env)) if corrects else oracle(env)
    ct = ConfidentTeacher(
        env,
        teacher,
        strategy=make(),
        model=GaussianMixtureSet(3, 2, 4, seed=0).to(device),
        config=TeachingConfig(max_new=3, accuracy_window=10),
        run_dir=run_dir,
        seed=5,
        progress=False,
    )
    ct.run(max_steps=steps)
    ct.close()
    return ct


@pytest.mark.parametrize("name", sorted(STRATEGIES))
def test_every_strategy_decides_with_a_cuda_model_as_with_the_cpu_model(tmp_path, name):
    cpu = _teach("cpu", name, tmp_path / "cpu")
    gpu = _teach("cuda", name, tmp_path / "gpu")
    assert gpu.model.means_.device.type == "cuda" and gpu.model.is_fitted
    a, b = load_records(tmp_path / "cpu"), load_records(tmp_path / "gpu")
    assert len(a) == len(b) == 150
    for ra, rb in zip(a, b, strict=True):
        assert (ra.model_action, ra.teacher_action, ra.executed_action, ra.autonomous) == (
            rb.model_action,
            rb.teacher_action,
            rb.executed_action,
            rb.autonomous,
        ), f"step {ra.step}"
        if ra.distance is not None and np.isfinite(ra.distance):
            assert rb.distance == pytest.approx(ra.distance, rel=1e-9)
    assert [(c.step, c.action) for c in cpu.corrections] == [
        (c.step, c.action) for c in gpu.corrections
    ]
    assert any(r.model_action >= 0 for r in a)  # the model classified: its answers are compared


_RESUME_ON_CPU = """
import sys, numpy as np, torch
assert not torch.cuda.is_available()
from _toy_envs import oracle, rare_regions_world
from torchcbl import ConfidentTeacher
from torchcbl.session import load_model
env = rare_regions_world(episode_length=10, spread=2.0)
back = ConfidentTeacher.resume(sys.argv[1], env, oracle(env), progress=False)
back.close()
q = np.load(sys.argv[2])
out = []
for m in (back.model, load_model(sys.argv[1])):
    c = m.classify(q)
    out += [c.action.numpy().astype(float), c.distance.numpy()]
np.save(sys.argv[3], np.stack(out))
"""


def _resume_without_cuda(run_dir: Path, queries: np.ndarray, tmp_path: Path) -> np.ndarray:
    """Resume the session and load its model in a process that sees no CUDA device:
    [resumed action, resumed distance, loaded action, loaded distance] x [N]."""
    np.save(tmp_path / "q.npy", queries)
    env = dict(os.environ, CUDA_VISIBLE_DEVICES="")
    env["PYTHONPATH"] = os.pathsep.join([str(Path(__file__).parent), env.get("PYTHONPATH", "")])
    subprocess.run(
        [
            sys.executable,
            "-c",
            _RESUME_ON_CPU,
            str(run_dir),
            tmp_path / "q.npy",
            tmp_path / "o.npy",
        ],
        check=True,
        env=env,
        cwd=Path(__file__).parents[1],
    )
    return np.load(tmp_path / "o.npy")


def test_a_session_taught_on_cuda_loads_on_a_machine_without_cuda(tmp_path):
    gpu = _teach("cuda", "ce", tmp_path / "gpu")
    checkpoints = sorted((tmp_path / "gpu" / "checkpoints").glob("model-*.pt"))
    assert checkpoints
    writers = (tmp_path / "gpu" / "writers.jsonl").read_text().splitlines()
    assert json.loads(writers[0])["model_device"] == "cuda:0"
    state = torch.load(checkpoints[-1], weights_only=True)["state_dict"]
    assert {v.device.type for v in state.values()} == {"cpu"}  # device-neutral on disk
    q = np.random.default_rng(0).normal(scale=4.0, size=(200, 2))
    got = _resume_without_cuda(tmp_path / "gpu", q, tmp_path)
    c = gpu.model.classify(q)
    for i in (0, 2):  # resumed, loaded
        np.testing.assert_array_equal(got[i], c.action.cpu().numpy())
        np.testing.assert_allclose(got[i + 1], c.distance.cpu().numpy(), rtol=1e-9)
    # the resume took the checkpoint, not a refit after setting it aside as damaged
    assert not list((tmp_path / "gpu" / "checkpoints").glob("*.damaged*"))
    # and on a GPU again, into a CUDA model the caller passes
    env = rare_regions_world(episode_length=10, spread=2.0)
    back = ConfidentTeacher.resume(
        tmp_path / "gpu",
        env,
        oracle(env),
        model=GaussianMixtureSet(3, 2, 4, seed=0).to("cuda"),
        progress=False,
    )
    back.close()
    assert back.model.means_.device.type == "cuda"
    torch.testing.assert_close(back.model.means_, gpu.model.means_, rtol=0, atol=0)


def test_a_checkpoint_written_with_cuda_tensors_still_loads_without_cuda(tmp_path):
    """Sessions saved before 2026-11-26 hold the CUDA model's own tensors."""
    gpu = _teach("cuda", "ce", tmp_path / "gpu")
    for path in (tmp_path / "gpu" / "checkpoints").glob("model-*.pt"):
        payload = torch.load(path, weights_only=True)
        payload["state_dict"] = {k: v.cuda() for k, v in payload["state_dict"].items()}
        torch.save(payload, path)
    q = np.random.default_rng(1).normal(scale=4.0, size=(50, 2))
    got = _resume_without_cuda(tmp_path / "gpu", q, tmp_path)
    want = gpu.model.classify(q).action.cpu().numpy()
    np.testing.assert_array_equal(got[0], want)
    np.testing.assert_array_equal(got[2], want)
    assert not list((tmp_path / "gpu" / "checkpoints").glob("*.damaged*"))


@pytest.mark.parametrize("name", sorted(STRATEGIES))
def test_a_session_taught_on_cuda_is_reproduced_exactly_by_a_cuda_model(tmp_path, name):
    """The determinism note (README, torchcbl.session): a session taught on a GPU is reproduced
    exactly by a model on a GPU, both by teaching it again and by refitting it from its log, under
    every shipped strategy."""
    first = _teach("cuda", name, tmp_path / "a")
    _teach("cuda", name, tmp_path / "b")
    a, b = load_records(tmp_path / "a"), load_records(tmp_path / "b")
    assert len(a) == 150
    assert a == b  # every field, distances and posteriors to the last bit
    # refitted from the log on a GPU: the checkpoints after the first set aside by hand
    for path in sorted((tmp_path / "a" / "checkpoints").glob("model-*.pt"))[1:]:
        path.unlink()
    env = rare_regions_world(episode_length=10, spread=2.0)
    back = ConfidentTeacher.resume(
        tmp_path / "a",
        env,
        correcting(oracle(env)) if STRATEGIES[name][1] else oracle(env),
        model=GaussianMixtureSet(3, 2, 4, seed=0).to("cuda"),
        progress=False,
    )
    back.close()
    live, refit = first.model.state_dict(), back.model.state_dict()
    assert live.keys() == refit.keys()
    for key in live:
        assert torch.equal(live[key], refit[key]), key


def test_a_cuda_model_is_refused_a_lost_start_before_a_file_is_touched(tmp_path):
    """A session started from a fitted CUDA model whose checkpoint 0 reads but does not load
    (a key missing): the trial load on a copy was skipped for a CUDA model (a copy doubles its
    GPU memory), so resume refused it only after opening the session (writers.jsonl,
    writer.lock and the journal written). It is tried on a CPU shadow now: refused before any
    file is touched, the given model left as it was, no GPU memory taken; the checkpoint put
    back, the session resumes on the GPU."""
    env = rare_regions_world(episode_length=10, spread=2.0)
    fitted = GaussianMixtureSet(3, 2, 4, seed=0).fit(*env.sample(120, np.random.default_rng(0)))
    run = tmp_path / "gpu"
    config = TeachingConfig(max_new=50, noninteractive=False)
    with ConfidentTeacher(
        env, oracle(env), model=fitted.to("cuda"), config=config, run_dir=run, progress=False
    ) as ct:
        ct.run(max_steps=20)
    zero = run / "checkpoints" / "model-00000000.pt"
    good = zero.read_bytes()
    payload = torch.load(zero, weights_only=True)
    del payload["state_dict"]["means_"]
    torch.save(payload, zero)
    files = sorted(p for p in run.rglob("*") if p.is_file())
    before = {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in files}
    model = GaussianMixtureSet(3, 2, 4, seed=0).to("cuda")
    state = {k: v.clone() for k, v in model.state_dict().items()}
    torch.cuda.synchronize()
    torch.cuda.reset_peak_memory_stats()
    held = torch.cuda.memory_allocated()
    with pytest.raises(CorruptSessionError, match="unreadable as this model's state"):
        ConfidentTeacher.resume(run, env, oracle(env), model=model, progress=False)
    assert torch.cuda.max_memory_allocated() == held
    assert {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in files} == before
    assert sorted(p for p in run.rglob("*") if p.is_file()) == files
    assert all(torch.equal(v, state[k]) for k, v in model.state_dict().items())
    assert model.means_.device.type == "cuda"
    zero.write_bytes(good)
    with ConfidentTeacher.resume(run, env, oracle(env), model=model, progress=False) as back:
        assert back.model.means_.device.type == "cuda"
        torch.testing.assert_close(back.model.means_.cpu(), fitted.means_.cpu(), rtol=0, atol=0)
