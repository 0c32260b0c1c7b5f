"""A learner of a user's own class, a subclass of GaussianMixtureSet (another initialisation,
a prior), written as a researcher would: taught into a session, then resumed and read back
through the public API. The session keeps the model's class by its name."""

from __future__ import annotations

import numpy as np
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


def test_a_session_of_a_subclass_is_read_with_the_model_passed(tmp_path):
    """A session of MyGMM could not be read at all: resume without model=, load_model and
    load_policy said only GaussianMixtureSet can be rebuilt from a run directory (not what to
    do), and load_model / load_policy took no model. Each refusal now says to pass
    model=MyGMM(...) made as the session made it; load_model and load_policy take it (a fresh
    one, of the session's class and arguments, the session's state loaded into it) and give
    the model and the policy the session had."""
    from torchcbl.session import load_model, load_policy

    run = tmp_path / "run"
    ct = _teach(run)
    told = "pass model=MyGMM(...) made as the session made it, MyGMM(**{"
    for read in (_resume, load_model, load_policy):
        with pytest.raises(IncompatibleRunDirError) as caught:
            read(run)
        assert "the session's model is a MyGMM" in str(caught.value), caught.value
        assert told in str(caught.value), caught.value

    model = MyGMM(3, 2, 4, seed=0)
    assert load_model(run, model=model) is model
    assert _same_state(model, ct.model)
    at_8 = load_model(run, n_demonstrations=8, model=MyGMM(3, 2, 4, seed=0))
    assert type(at_8) is MyGMM and at_8.n_points_.sum() == 8
    policy = load_policy(run, model=MyGMM(3, 2, 4, seed=0))
    x, _ = rare_regions_world().sample(50, np.random.default_rng(0))
    assert [policy(o) for o in x] == [ct.policy(o) for o in x]


def test_load_model_refuses_a_model_the_session_was_not_taught_with(tmp_path):
    """The model given to load_model must be a fresh one of the session's class and
    arguments: another class, other arguments or a fitted one are refused, saying what to
    pass. For a session of the library's class the model given is loaded as the directory's
    own rebuild is, and its config.json keeps the model entry it always had."""
    from torchcbl.session import load_model

    run = tmp_path / "run"
    _teach(run)
    with pytest.raises(IncompatibleRunDirError, match="a MyGMM, the given one a Gaussian"):
        load_model(run, model=GaussianMixtureSet(3, 2, 4, seed=0))
    with pytest.raises(IncompatibleRunDirError, match=r"\{'max_components': \(4, 5\)\}"):
        load_model(run, model=MyGMM(3, 2, 5, seed=0))
    fitted = load_model(run, model=MyGMM(3, 2, 4, seed=0))
    with pytest.raises(ValueError, match="expected a fresh, unfitted MyGMM .* got a fitted"):
        load_model(run, model=fitted)

    plain = tmp_path / "plain"
    _teach(plain, GaussianMixtureSet)
    assert _same_state(
        load_model(plain, model=GaussianMixtureSet(3, 2, 4, seed=0)), load_model(plain)
    )
    args = dict(n_actions=3, n_features=2, max_components=4, criterion="aic", var_floor=1e-3)
    args.update(tol=1e-3, max_iter=200, seed=0, refit_growth=0.25)  # n_init=1 left out
    assert load_config(plain)["model"] == {"class": "GaussianMixtureSet", "args": args}


def test_the_command_line_says_to_read_a_session_of_a_subclass_in_python(tmp_path, capsys):
    """torchcbl evaluate and teach --resume cannot make a user's model class; they printed the
    library's Python advice (pass model=MyGMM(...)), which the command line takes no way to
    follow. Each now says, in one line, to do it in Python, with the call to make."""
    import gymnasium as gym

    import corridor  # noqa: F401  (registers torchcbl/Corridor-v0)
    from torchcbl.cli import main

    run = tmp_path / "run"
    env = gym.make("torchcbl/Corridor-v0")
    model = MyGMM(4, 3, 4, seed=0)
    ConfidentTeacher(env, lambda o, i: 0, model=model, run_dir=run, progress=False).run(
        max_steps=3
    ).close()
    capsys.readouterr()
    assert main(["evaluate", str(run)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert "model is a MyGMM" in err and "the command line cannot make" in err, err
    assert f"torchcbl.load_policy({str(run)!r}, model=MyGMM(" in err, err
    assert main(["teach", "corridor", "--resume", "--run-dir", str(run), "--steps", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the command line cannot make" in err, err
    assert f"torchcbl.ConfidentTeacher.resume({str(run)!r}, env, teacher, model=MyGMM(" in err


class WithPrior(GaussianMixtureSet):
    """A user's learner with state of its own beside the library's (a prior's weights)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.register_buffer("prior_weight_", torch.ones(self.n_actions, dtype=torch.float64))


def test_a_fitted_model_of_a_subclass_with_state_of_its_own_resumes(tmp_path):
    """Resume rebuilds the session's model, never taking the caller's fitted one: it first
    cleared a fitted model with a fresh GaussianMixtureSet's state, which a subclass holding
    state of its own refused (torch's bare RuntimeError, 'Missing key(s) in state_dict:
    "prior_weight_"'). The library's state is cleared and the session's loaded, as for the
    library's class."""
    from torchcbl.session import load_model

    run = tmp_path / "run"
    ct = _teach(run, WithPrior)
    fitted = load_model(run, model=WithPrior(3, 2, 4, seed=0))
    assert fitted.is_fitted
    back = _resume(run, model=fitted)
    assert back.model is fitted and _same_state(back.model, ct.model)
    back.close()


class OwnArgs(GaussianMixtureSet):
    """A user's learner that records its constructor arguments itself (``init_args``, read by
    the session in place of the attributes), written before ``refit_growth`` and ``n_init``
    existed: they are not among them."""

    def __init__(self, n_actions: int, n_features: int, max_components: int, seed: int) -> None:
        super().__init__(n_actions, n_features, max_components, seed=seed)
        self.init_args = dict(
            n_actions=n_actions, n_features=n_features, max_components=max_components, seed=seed
        )


def test_a_session_of_a_model_with_init_args_of_its_own_resumes(tmp_path):
    """A model whose ``init_args`` lack the arguments added after sessions were first written
    (refit_growth, n_init) could never resume its own session: the stored arguments were
    completed with those arguments' defaults, the given model's were not, and resume refused
    with "{'n_init': (1, None), 'refit_growth': (0.25, None)}". Both sides are completed alike:
    the session resumes, and other arguments are still refused."""
    run = tmp_path / "run"
    ct = _teach(run, OwnArgs)
    assert "refit_growth" not in load_config(run)["model"]["args"]
    back = _resume(run, model=OwnArgs(3, 2, 4, seed=0))
    assert type(back.model) is OwnArgs and _same_state(back.model, ct.model)
    back.close()
    with pytest.raises(IncompatibleRunDirError, match=r"\{'max_components': \(4, 5\)\}"):
        _resume(run, model=OwnArgs(3, 2, 5, seed=0))


class Tempered(GaussianMixtureSet):
    """A user's learner with a constructor argument of its own, kept in its ``init_args``."""

    def __init__(
        self,
        n_actions: int,
        n_features: int,
        max_components: int,
        *,
        seed: int,
        temper: float = 2.0,
    ) -> None:
        super().__init__(n_actions, n_features, max_components, seed=seed)
        self.temper = temper
        self.init_args = dict(
            n_actions=n_actions,
            n_features=n_features,
            max_components=max_components,
            seed=seed,
            temper=temper,
        )


def test_a_fitted_model_with_constructor_arguments_of_its_own_resumes(tmp_path):
    """Resume clears a fitted model given to it before loading the session's: it built the
    fresh state from a GaussianMixtureSet made with the model's recorded arguments, which for
    a model whose init_args hold arguments of its own (temper) raised TypeError
    ("unexpected keyword argument 'temper'"). The session's model is restored into the given
    one, as for any other model."""
    from torchcbl.session import load_model

    run = tmp_path / "run"
    ct = _teach(run, Tempered)
    assert load_config(run)["model"]["args"]["temper"] == 2.0
    fitted = load_model(run, n_demonstrations=4, model=Tempered(3, 2, 4, seed=0))
    assert fitted.is_fitted and not _same_state(fitted, ct.model)
    back = _resume(run, model=fitted)
    assert back.model is fitted and _same_state(back.model, ct.model)
    back.close()


class Unrecorded(GaussianMixtureSet):
    """A user's learner with a constructor argument of its own and no ``init_args``: the
    session records only GaussianMixtureSet's arguments."""

    def __init__(
        self, n_actions: int, n_features: int, max_components: int, *, seed: int, temperature=1.0
    ) -> None:
        super().__init__(n_actions, n_features, max_components, seed=seed)
        self.temperature = temperature


def test_a_subclass_whose_own_arguments_are_not_recorded_is_told_so(tmp_path):
    """A subclass's constructor argument of its own (temperature) not in an ``init_args`` was
    lost without a word: the session started silently, and a refusal advised
    ``Unrecorded(**{...})`` without temperature, as if the arguments shown were all. The
    session start warns, naming the argument and init_args, and the refusal's advice says the
    argument is not recorded and to give the class an init_args."""
    from torchcbl.session import load_model

    run = tmp_path / "run"
    with pytest.warns(UserWarning, match=r"Unrecorded's own arguments \(temperature\).*init_args"):
        _teach(run, Unrecorded)
    for read in (load_model, _resume):
        with pytest.raises(IncompatibleRunDirError) as caught:
            read(run, model=Unrecorded(3, 2, 5, seed=0, temperature=5.0))
        msg = str(caught.value)
        assert "its own arguments (temperature) are not recorded" in msg, msg
        assert "give the class an init_args" in msg, msg


def test_a_subclass_recording_its_arguments_starts_without_a_warning(tmp_path):
    """The warning is for arguments a session loses: a subclass that records its own in
    init_args (Tempered), or takes none beyond the library's (MyGMM), starts silently, and its
    refusals give the plain advice."""
    import warnings

    from torchcbl.session import load_model

    for cls in (Tempered, MyGMM):
        run = tmp_path / cls.__name__
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            _teach(run, cls)
        with pytest.raises(IncompatibleRunDirError) as caught:
            load_model(run, model=cls(3, 2, 5, seed=0))
        assert "not recorded" not in str(caught.value), caught.value
