"""A teaching session that starts from prior demonstrations (logged data, an earlier session's
labels, a BC data set): ``ConfidentTeacher(..., prior_demonstrations=(x, y))``."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from _toy_envs import oracle, rare_regions_world

from torchcbl import ConfidentTeacher, GaussianMixtureSet, TeachingConfig
from torchcbl.errors import CorruptSessionError, IncompatibleRunDirError
from torchcbl.records import training_set
from torchcbl.session import (
    load_config,
    load_demonstrations,
    load_labels,
    load_model,
    load_policy,
    load_prior_demonstrations,
    load_records,
    prior_source,
)
from torchcbl.strategies import ConfidenceBasedAutonomy, correcting


def prior(n=60, seed=1):
    return rare_regions_world().sample(n, np.random.default_rng(seed))


def make(run_dir, demos=None, teacher=None, strategy=None, seed=3, **cfg):
    env = rare_regions_world()
    return ConfidentTeacher(
        env,
        teacher or oracle(env),
        prior_demonstrations=demos,
        strategy=strategy,
        config=TeachingConfig(**{"noninteractive": False, **cfg}),
        run_dir=run_dir,
        seed=seed,
        progress=False,
    )


def same_state(a, b):
    sa, sb = a.state_dict(), b.state_dict()
    return sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)


def fit_on(demos, run_dir, k, relabel=False):
    """A model fitted as the session's should be: the prior first, then its first k labels."""
    x, y = load_labels(run_dir)
    xs = [*demos[0], *x[:k]]
    ys = [*np.asarray(demos[1]).tolist(), *y[:k].tolist()]
    model = GaussianMixtureSet(3, 2, seed=3)
    return model.fit(*training_set(xs, ys, relabel=relabel))


def test_a_prior_is_fitted_before_the_first_decision_and_in_every_refit(tmp_path):
    demos = prior()
    without = make(tmp_path / "none")
    without.run(max_steps=200)
    ct = make(tmp_path / "run", demos, max_new=3)
    first = ct.step()
    assert first.model_action >= 0 and np.isfinite(first.distance)  # a model from the start
    ct.run(max_steps=200)
    assert ct.n_demonstrations < without.n_demonstrations  # it asks less
    k = ct.n_demonstrations // 3 * 3
    assert k and same_state(ct.model, fit_on(demos, ct.run_dir, k))  # the prior is kept
    assert ct.n_prior == 60
    x, y = ct.prior_demonstrations
    assert np.array_equal(x, demos[0]) and np.array_equal(y, demos[1])
    with pytest.raises(ValueError, match="read-only"):
        x[0, 0] = 1.0
    ct.close()
    x, y = load_prior_demonstrations(ct.run_dir)
    assert np.array_equal(x, demos[0]) and np.array_equal(y, demos[1])
    assert same_state(load_model(ct.run_dir), ct.model)
    assert same_state(load_model(ct.run_dir, n_demonstrations=0), fit_on(demos, ct.run_dir, 0))
    for p in (ct.run_dir / "checkpoints").iterdir():  # refitted from the log and the prior
        p.unlink()
    assert same_state(load_model(ct.run_dir), ct.model)
    obs = np.array([0.2, 7.5])
    assert load_policy(ct.run_dir)(obs) == ct.policy(obs)


def test_the_budgets_and_counts_are_the_sessions_own_labels(tmp_path):
    ct = make(tmp_path / "run", prior(), max_demonstrations=5)
    ct.run()
    assert ct.stop_reason == "max_demonstrations"
    assert ct.n_demonstrations == 5 and ct.n_prior == 60
    assert max(r.n_demonstrations for r in load_records(ct.run_dir)) == 5
    assert len(load_labels(ct.run_dir)[1]) == 5
    assert len(load_demonstrations(ct.run_dir)[1]) == 65  # the training set: the prior too
    names = sorted(p.name for p in (ct.run_dir / "checkpoints").iterdir())
    # checkpoint 0 (the fit on the prior alone) and the newest three, numbered by own labels
    assert names == [f"model-{n:08d}.pt" for n in (0, 3, 4, 5)]
    ct.close()


def test_a_resumed_session_with_a_prior_goes_on_as_the_uninterrupted_one(tmp_path):
    """The prior is read back from the session directory, never given again: a session
    stopped at its first request resumes into exactly the run the uninterrupted one made (CBA,
    whose thresholds and distance gate come from observe_refit on the prior), and one stopped
    later resumes with the same counters, model and thresholds."""
    from torchcbl import TeachingInterrupted

    demos = prior()
    env = rare_regions_world()

    def cba():
        return ConfidenceBasedAutonomy()

    ref = make(tmp_path / "ref", demos, teacher=correcting(oracle(env)), strategy=cba(), max_new=5)
    start = ref.strategy.thresholds.copy()
    assert np.isfinite(start).any()  # computed on the prior before step 0
    ref.run(max_steps=80)

    def stops_at_once(obs, info):
        raise TeachingInterrupted("not now")

    run = tmp_path / "run"
    with pytest.warns(UserWarning, match="never correct one"):
        ct = make(run, demos, teacher=stops_at_once, strategy=cba(), max_new=5)
    with pytest.raises(TeachingInterrupted):
        ct.run(max_steps=80)
    ct.close()
    back = ConfidentTeacher.resume(run, env, correcting(oracle(env)), progress=False)
    assert back.n_prior == 60 and np.array_equal(back.strategy.thresholds, start)
    back.run(max_steps=80)
    assert back.records == ref.records and back.corrections == ref.corrections
    assert same_state(back.model, ref.model)
    back.close()
    # resumed mid-session: the same state, and the format stays the one of a prior session
    again = ConfidentTeacher.resume(run, env, correcting(oracle(env)), progress=False)
    assert again.records == ref.records and same_state(again.model, ref.model)
    assert np.array_equal(again.strategy.thresholds, ref.strategy.thresholds)
    again.run(max_steps=120)
    again.close()
    assert load_config(run)["format"] == "torchcbl.session/3"
    assert same_state(load_model(run), again.model)


def test_incremental_refits_with_a_prior_are_replayed_from_the_prior_fit(tmp_path):
    ct = make(tmp_path / "run", prior(), max_new=2, refit="incremental")
    ct.run(max_steps=60)
    ct.close()
    for p in (ct.run_dir / "checkpoints").iterdir():
        p.unlink()
    assert same_state(load_model(ct.run_dir), ct.model)


def test_a_missing_or_changed_prior_file_is_refused(tmp_path):
    run = tmp_path / "run"
    make(run, prior()).close()
    env = rare_regions_world()
    path = run / "prior.npz"
    data = path.read_bytes()
    writers = (run / "writers.jsonl").read_text()
    path.write_bytes(data[:-1] + bytes([data[-1] ^ 1]))
    for read in (
        lambda: ConfidentTeacher.resume(run, env, oracle(env), progress=False),
        lambda: load_model(run),
        lambda: load_prior_demonstrations(run),
    ):
        with pytest.raises(CorruptSessionError, match=r"prior\.npz was changed or damaged"):
            read()
    assert (run / "writers.jsonl").read_text() == writers  # resume opened nothing
    path.unlink()
    with pytest.raises(CorruptSessionError, match=r"prior\.npz is missing.*Restore the file"):
        ConfidentTeacher.resume(run, env, oracle(env), progress=False)
    path.write_bytes(data)
    ConfidentTeacher.resume(run, env, oracle(env), progress=False).close()
    # its config.json entry is what holds the session to its prior: without it, refused
    config = json.loads((run / "config.json").read_text())
    del config["prior"]
    (run / "config.json").write_text(json.dumps(config))
    with pytest.raises(CorruptSessionError, match="'prior'"):
        load_model(run)


def test_a_torchcbl_without_prior_demonstrations_refuses_such_a_session(tmp_path, monkeypatch):
    import torchcbl.session as S

    make(tmp_path / "plain").close()
    make(tmp_path / "run", prior()).close()
    assert load_config(tmp_path / "plain")["format"] == "torchcbl.session/2"
    monkeypatch.setattr(S, "READABLE_FORMATS", ("torchcbl.session/1", "torchcbl.session/2"))
    load_config(tmp_path / "plain")
    with pytest.raises(IncompatibleRunDirError, match="session/3"):
        load_config(tmp_path / "run")


@pytest.mark.parametrize(
    ("demos", "error", "match"),
    [
        ("prior.npz", TypeError, r"got the path 'prior.npz'; load it first"),
        (np.zeros((3, 2)), TypeError, r"expected a pair \(observations \[N, 2\], actions \[N\]\)"),
        ((np.zeros((3, 3)), np.zeros(3, int)), ValueError, r"shape \[N, 2\].*got float64 \(3, 3\)"),
        ((np.zeros(3), np.zeros(3, int)), ValueError, r"reshape\(-1, 1\)"),
        ((np.zeros((0, 2)), np.zeros(0, int)), ValueError, "at least one demonstration, got 0"),
        (([[0.0, np.nan]], [0]), ValueError, r"finite; row 0 is \[0.0, nan\]"),
        ((np.zeros((2, 2)), [0.0, 1.0]), ValueError, r"int array.*astype\(numpy.int64\)"),
        ((np.zeros((2, 2)), [0, 1, 2]), ValueError, r"shape \[2\].*got int64 \(3,\)"),
        ((np.zeros((2, 2)), [0, 3]), ValueError, r"in \[0, 3\).*action 3 at row 1"),
        (([[True, False]], [0]), ValueError, "real-number array"),
    ],
)
def test_bad_prior_demonstrations_say_what_was_expected(tmp_path, demos, error, match):
    with pytest.raises(error, match=match):
        make(tmp_path / "run", demos)
    assert not (tmp_path / "run").exists()  # refused before a session was written


def test_a_prior_of_other_width_for_a_one_feature_env_says_one_feature(tmp_path):
    """A prior whose rows are not as wide as a one-feature env's observations said "the
    env's 1 features"; it says "1 feature"."""
    from _toy_envs import ClusterWorld

    env = ClusterWorld([[0.0], [5.0]], [0, 1], [0.5, 0.5], episode_length=5)
    with pytest.raises(ValueError) as err:
        ConfidentTeacher(
            env,
            oracle(env),
            prior_demonstrations=(np.zeros((3, 2)), np.zeros(3, int)),
            run_dir=tmp_path / "run",
            progress=False,
        )
    assert "shape [N, 1] (the env's 1 feature), got float64 (3, 2)" in str(err.value), err.value
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("kind", ["npz", "dict", "array", "triple"])
def test_a_prior_that_is_not_a_pair_is_described_in_one_line_with_the_fix(tmp_path, kind):
    """A prior given as the .npz file `teach --prior-demonstrations` reads (numpy.load), a dict
    of its arrays, one array or three items was refused with the repr of the arrays cut at 80
    characters, several lines of zeros; and the loaded .npz was not told how to pass on."""
    x, y = np.zeros((200, 2)), np.zeros(200, dtype=np.int64)
    np.savez(tmp_path / "prior.npz", observations=x, actions=y)
    demos = {
        "npz": np.load(tmp_path / "prior.npz"),
        "dict": {"observations": x, "actions": y},
        "array": x,
        "triple": (x, y, 1),
    }[kind]
    with pytest.raises(TypeError) as err:
        make(tmp_path / "run", demos)
    message = str(err.value)
    assert "\n" not in message and "0., 0." not in message, message
    got = {
        "npz": "got NpzFile with keys ['observations', 'actions']",
        "dict": "got dict with keys ['observations', 'actions']",
        "array": "got ndarray of shape (200, 2)",
        "triple": "got tuple of 3 items",
    }[kind]
    assert got in message, message
    if kind in ("npz", "dict"):
        assert "prior_demonstrations=(d['observations'], d['actions'])" in message
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("as_path", [False, True], ids=["str", "Path"])
def test_a_session_directory_given_as_prior_points_to_load_demonstrations(tmp_path, as_path):
    """A session's directory given as prior_demonstrations was told "load it first, e.g. d =
    numpy.load(path)", which cannot load a directory. The advice is now the call that reads a
    session's demonstrations, and following it starts the session; a folder that holds no
    session is said to be that."""
    earlier = tmp_path / "t1"
    ct = make(earlier)
    ct.run(max_steps=10)
    ct.close()
    given = earlier if as_path else str(earlier)
    with pytest.raises(TypeError) as err:
        make(tmp_path / "run", given)
    message = str(err.value)
    call = f"prior_demonstrations=torchcbl.session.load_demonstrations({str(earlier)!r})"
    assert call in message and "numpy.load" not in message, message
    assert not (tmp_path / "run").exists()
    with make(tmp_path / "run", load_demonstrations(given)) as ct:
        assert ct.n_prior == len(load_demonstrations(earlier)[1]) > 0
    folder = tmp_path / "folder"
    folder.mkdir()
    with pytest.raises(TypeError, match=r"directory '.*folder', which holds no teaching session"):
        make(tmp_path / "other", folder if as_path else str(folder))
    # a folder of one's own with a config.json of one's own holds no session either (the
    # advice to load its demonstrations would fail)
    (folder / "config.json").write_text('{"lr": 0.1}')
    with pytest.raises(TypeError, match=r"directory '.*folder', which holds no teaching session"):
        make(tmp_path / "other", folder if as_path else str(folder))


def test_a_fitted_model_and_a_prior_are_refused_together(tmp_path):
    env = rare_regions_world()
    demos = prior()
    fitted = GaussianMixtureSet(3, 2, seed=0).fit(*demos)
    with pytest.raises(ValueError, match="prior_demonstrations= or a fitted model=, not both"):
        ConfidentTeacher(
            env, oracle(env), model=fitted, prior_demonstrations=demos, run_dir=tmp_path / "r"
        )
    assert not (tmp_path / "r").exists()


def test_an_earlier_sessions_training_set_starts_the_next_one_relabelled_as_it_was(tmp_path):
    """prior_demonstrations=load_demonstrations(earlier): the earlier session's training set,
    what its model stands on. With a relabelling strategy (CBA), a label for a prior
    observation replaces the prior's label; the README's recipe (its prior, then its labels,
    concatenated) kept both, so the next session was fitted on contradicting rows (review: 17
    of 81)."""
    env = rare_regions_world()
    probe = make(tmp_path / "probe")
    probe.run(max_steps=30)
    seen = np.stack([r.observation_array for r in probe.records[:20]])
    wrong = np.array([(env.optimal_action(o) + 1) % 3 for o in seen])  # at states it will see
    x, y = prior(40)
    demos = (np.concatenate([seen, x]), np.concatenate([wrong, y]))
    ct = make(
        tmp_path / "cba",
        demos,
        teacher=correcting(oracle(env)),
        strategy=ConfidenceBasedAutonomy(),
        max_new=3,
    )
    ct.run(max_steps=30)
    snapshot = ct.snapshot()
    ct.close()
    tx, ty = load_demonstrations(ct.run_dir)
    assert len(ty) < 60 + ct.n_demonstrations  # relabelled prior rows are not repeated
    assert same_state(GaussianMixtureSet(3, 2, seed=3).fit(tx, ty), snapshot)
    nxt = make(tmp_path / "next", (tx, ty))
    assert same_state(nxt.model, snapshot)  # the next session starts where this one stood
    nxt.close()


class CountingFits(GaussianMixtureSet):
    """A model whose fits are counted: a refused session must not fit its prior first."""

    fits = 0

    def fit(self, *args, **kwargs):
        type(self).fits += 1
        return super().fit(*args, **kwargs)


def _tree(path):
    return sorted(
        (str(p.relative_to(path)), p.read_bytes() if p.is_file() else None) for p in path.rglob("*")
    )


@pytest.mark.parametrize("held", ["own files", "a session", "a file"])
def test_a_refused_run_dir_is_refused_before_the_prior_is_fitted(tmp_path, monkeypatch, held):
    run_dir = tmp_path / "run"
    if held == "own files":
        run_dir.mkdir()
        (run_dir / "notes.txt").write_text("mine\n")
    elif held == "a session":
        make(run_dir).close()
    else:
        run_dir.write_text("a file\n")
    before = _tree(tmp_path)
    monkeypatch.setattr(CountingFits, "fits", 0)
    env = rare_regions_world()
    with pytest.raises(IncompatibleRunDirError):
        ConfidentTeacher(
            env,
            oracle(env),
            model=CountingFits(3, 2, seed=3),
            prior_demonstrations=prior(),
            run_dir=run_dir,
            progress=False,
        )
    assert CountingFits.fits == 0  # refused before the fit, not after it
    assert _tree(tmp_path) == before  # and the folder untouched


def test_a_prior_read_from_a_session_records_that_session_and_arrays_record_none(tmp_path):
    """A session kept only its prior's count and SHA-256, nothing of where it came from, so an
    evaluation could not tell the road it was taught on (and said held out). Given as
    load_demonstrations returns it, the new session records the session and its steps then:
    prior_source finds it (taught further since, or both moved together) where its first
    steps still give that prior; the two arrays apart record nothing; a session gone or
    holding other demonstrations is told as unknown, never as a source."""
    import pickle
    import shutil

    first = make(tmp_path / "runs" / "first")
    first.run(max_steps=20)
    first.close()
    demos = load_demonstrations(tmp_path / "runs" / "first")
    assert pickle.loads(pickle.dumps(demos)).source == demos.source  # kept in a copy too
    make(tmp_path / "runs" / "next", demos).close()
    make(tmp_path / "runs" / "arrays", tuple(demos)).close()
    assert prior_source(tmp_path / "runs" / "first") is None  # no prior demonstrations
    found = prior_source(tmp_path / "runs" / "next")
    assert found.session == tmp_path / "runs" / "first" and found.n_steps == 20, found
    again = ConfidentTeacher.resume(
        tmp_path / "runs" / "first", rare_regions_world(), lambda o, i: 0, progress=False
    )
    again.run(max_steps=25)  # taught further: its first 20 steps still give the prior
    assert len(load_records(tmp_path / "runs" / "first")) == 25
    again.close()
    assert prior_source(tmp_path / "runs" / "next").session == found.session
    arrays = prior_source(tmp_path / "runs" / "arrays")
    assert arrays.session is None and "given as arrays" in arrays.unknown, arrays
    (tmp_path / "runs").rename(tmp_path / "moved")
    moved = prior_source(tmp_path / "moved" / "next")
    assert moved.session == tmp_path / "moved" / "first", moved
    shutil.rmtree(tmp_path / "moved" / "first")
    other = make(tmp_path / "moved" / "first", seed=9)  # another session where it was
    other.run(max_steps=20)
    other.close()
    gone = prior_source(tmp_path / "moved" / "next")
    assert gone.session is None and "no longer holds them" in gone.unknown, gone


def test_a_session_moved_over_its_priors_source_is_not_its_own_source(tmp_path):
    """A session moved to where its prior's session was (that one deleted) found itself there:
    its first steps give its own prior, so prior_source named the session as its own source
    (and a driving evaluation then said held out). A place that is the session itself is not
    its source: where none other holds them, the source is unknown."""
    import shutil

    first = make(tmp_path / "first", prior())
    first.close()  # no steps: its training set is its prior alone
    then = make(tmp_path / "then", load_demonstrations(tmp_path / "first"))
    then.run(max_steps=5)
    then.close()
    shutil.rmtree(tmp_path / "first")
    (tmp_path / "then").rename(tmp_path / "first")
    found = prior_source(tmp_path / "first")
    assert found.session is None and "this session itself" in found.unknown, found


def test_a_session_from_before_the_source_was_recorded_is_not_said_given_as_arrays(tmp_path):
    """A session written before prior.source was recorded (`teach --prior-demonstrations DIR`
    by an older torchcbl) was told its prior "were given as arrays, not read from a session",
    which may be false: either may be so, and its reason says both."""
    first = make(tmp_path / "first")
    first.run(max_steps=20)
    first.close()
    make(tmp_path / "next", load_demonstrations(tmp_path / "first")).close()
    path = tmp_path / "next" / "config.json"
    config = json.loads(path.read_text())
    del config["prior"]["source"]  # as the older torchcbl wrote it
    path.write_text(json.dumps(config))
    older = prior_source(tmp_path / "next")
    assert older.session is None and "not read from a session" not in older.unknown, older
    assert "given as arrays, or read by a torchcbl that did not record" in older.unknown, older


def test_arrays_changed_after_they_were_read_record_no_source(tmp_path):
    """load_demonstrations' arrays scaled in place and then given as the prior still recorded
    the session they were read from, whose first steps then did not give them: the session was
    later said to "no longer hold them", blaming it for a change made to the arrays. The pair
    keeps a digest of what was read, and a session started from arrays that no longer match
    it records no source (they are arrays of one's own); unchanged arrays still do."""
    import copy

    first = make(tmp_path / "first")
    first.run(max_steps=20)
    first.close()
    demos = load_demonstrations(tmp_path / "first")
    make(tmp_path / "kept", demos).close()
    demos[0][:] = demos[0] * 2.0  # changed in place: no longer the session's
    make(tmp_path / "scaled", demos).close()
    make(tmp_path / "copied", copy.deepcopy(demos)).close()  # a copy keeps what was read
    assert "source" in load_config(tmp_path / "kept")["prior"]
    assert "source" not in load_config(tmp_path / "scaled")["prior"]
    assert "source" not in load_config(tmp_path / "copied")["prior"]
    scaled = prior_source(tmp_path / "scaled")
    assert scaled.session is None and "given as arrays" in scaled.unknown, scaled
    assert "no longer holds" not in scaled.unknown


def test_demonstrations_is_made_from_one_iterable_as_a_tuple_is(tmp_path):
    """Demonstrations required its arrays and keywords, so what makes a tuple's own type again
    from one iterable (dataclasses.asdict of a dataclass holding one, type(d)(iterable))
    raised TypeError. It takes the one iterable too, with no source (nothing recorded); its
    arrays are the pair given, and a session started from it records no source."""
    import dataclasses

    first = make(tmp_path / "first")
    first.run(max_steps=20)
    first.close()
    demos = load_demonstrations(tmp_path / "first")

    @dataclasses.dataclass
    class Holder:
        demos: tuple

    again = dataclasses.asdict(Holder(demos))["demos"]
    assert type(again) is type(demos) and again.source is None and again.n_steps is None
    assert np.array_equal(again[0], demos[0]) and np.array_equal(again[1], demos[1])
    remade = type(demos)(iter(demos))
    assert remade.source is None and len(remade) == 2 and remade[0] is demos[0]
    make(tmp_path / "next", remade).close()
    assert "source" not in load_config(tmp_path / "next")["prior"]
    with pytest.raises(TypeError, match="observations, actions"):
        type(demos)([demos[0]])
