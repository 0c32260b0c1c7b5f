"""A learner of a user's own class, a subclass of GaussianMixtureSet (another initialisation,
a prior), written as a researcher would: taught into a session, then resumed and read back
through the public API. The session keeps the model's class by its name."""

from __future__ import annotations

import pytest
import torch
from _toy_envs import oracle, rare_regions_world

from torchcbl import ConfidentTeacher, GaussianMixtureSet, TeachingConfig
from torchcbl.errors import IncompatibleRunDirError
from torchcbl.session import load_config


class MyGMM(GaussianMixtureSet):
    """A user's learner: the library's, with (say) an initialisation of its own."""


def _teach(run_dir, model_class=MyGMM):
    """Twelve labels (three refits) of a session whose model is a ``model_class``."""
    env = rare_regions_world()
    model = model_class(3, 2, 4, seed=0)
    ct = ConfidentTeacher(
        env,
        oracle(env),
        model=model,
        config=TeachingConfig(max_demonstrations=12, max_new=4),
        run_dir=run_dir,
        progress=False,
    )
    ct.run()
    ct.close()
    return ct


def _resume(run_dir, **kwargs):
    env = rare_regions_world()
    return ConfidentTeacher.resume(run_dir, env, oracle(env), progress=False, **kwargs)


def _same_state(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    sa, sb = a.state_dict(), b.state_dict()
    return sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)


def test_a_resume_with_a_model_of_another_class_is_refused(tmp_path):
    """The session keeps its model's class by name, but resume compared only the model's
    arguments: a session of MyGMM resumed with model=GaussianMixtureSet(...) went on as the
    parent, and a session of the library's class with model=MyGMM(...) went on as the
    subclass, with no word. Either is refused, naming both classes and what to pass; the
    session's own class passed resumes it."""
    run = tmp_path / "run"
    ct = _teach(run)
    assert load_config(run)["model"]["class"] == "MyGMM"
    with pytest.raises(IncompatibleRunDirError) as caught:
        _resume(run, model=GaussianMixtureSet(3, 2, 4, seed=0))
    msg = str(caught.value)
    assert "the session's model is a MyGMM, the given one a GaussianMixtureSet" in msg, msg
    assert "pass model=MyGMM(...) made as the session made it" in msg, msg
    back = _resume(run, model=MyGMM(3, 2, 4, seed=0))
    assert type(back.model) is MyGMM and _same_state(back.model, ct.model)
    back.close()

    plain = tmp_path / "plain"
    _teach(plain, GaussianMixtureSet)
    with pytest.raises(IncompatibleRunDirError) as caught:
        _resume(plain, model=MyGMM(3, 2, 4, seed=0))
    msg = str(caught.value)
    assert "the session's model is a GaussianMixtureSet, the given one a MyGMM" in msg, msg
    assert "pass model=GaussianMixtureSet(...) made as the session made it" in msg, msg
