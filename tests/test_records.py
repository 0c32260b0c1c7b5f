"""StepRecord and CorrectionRecord built by a loop of one's own: numpy / gymnasium values are
taken as the plain values the teaching loop passes, and what is wrong is still refused."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from torchcbl.records import CorrectionRecord, StepRecord


def _fields(**over):
    kw = dict(
        step=0,
        episode=0,
        observation=(0.5, -0.25),
        model_action=1,
        confidence=0.5,
        distance=1.0,
        posterior=(0.25, 0.75),
        teacher_action=None,
        executed_action=1,
        phase="confident",
        autonomous=True,
        reward=1.0,
        terminated=False,
        truncated=False,
        autonomy_rate=0.5,
        windowed_accuracy=0.75,
    )
    kw.update(over)
    return kw


def test_a_record_takes_numpy_and_gymnasium_values_and_holds_plain_ones():
    """A user's own loop passes obs (an ndarray), np.float64 confidences, int / np.float32
    rewards, np.bool_ flags: they were refused as 'a bug or a corrupted log'."""
    plain = StepRecord(**_fields())
    for over in (
        dict(observation=np.array([0.5, -0.25])),
        dict(observation=np.array([0.5, -0.25], dtype=np.float32)),
        dict(observation=[0.5, -0.25]),
        dict(observation=(np.float64(0.5), np.float32(-0.25))),
        dict(posterior=np.array([0.25, 0.75])),
        dict(posterior=[0.25, 0.75]),
        dict(confidence=np.float64(0.5), distance=np.float32(1.0)),
        dict(reward=1, terminated=np.bool_(False), truncated=np.bool_(False)),
        dict(reward=np.float32(1.0), autonomous=np.bool_(True)),
        dict(autonomy_rate=np.float64(0.5), windowed_accuracy=np.float32(0.75)),
    ):
        r = StepRecord(**_fields(**over))
        assert r == plain, over
        for name, value in r.__dict__.items():
            if name not in ("observation", "posterior", "info"):
                assert type(value) is type(getattr(plain, name)), (name, over)
        assert all(type(x) is float for x in r.observation + r.posterior)
        assert json.dumps(r.to_dict()) == json.dumps(plain.to_dict())
    r = plain.with_outcome(np.float32(2.0), np.bool_(True), np.bool_(False), {})
    assert (r.reward, r.terminated, r.truncated) == (2.0, True, False)
    assert type(r.reward) is float and type(r.terminated) is bool


@pytest.mark.parametrize(
    "field,value",
    [
        ("observation", np.array([[0.5, -0.25]])),
        ("observation", np.array([0.5, math.nan])),
        ("observation", ["a", "b"]),
        ("observation", [True, 0.5]),
        ("observation", np.array([], dtype=np.float64)),
        ("confidence", True),
        ("confidence", np.float64(math.nan)),
        ("confidence", "0.5"),
        ("distance", np.float32(math.nan)),
        ("posterior", [0.5, "a"]),
        ("reward", True),
        ("reward", np.float64(math.nan)),
        ("reward", "1"),
        ("terminated", 0),
        ("terminated", "False"),
    ],
)
def test_a_record_still_refuses_what_is_wrong_and_says_what_to_pass(field, value):
    with pytest.raises(ValueError, match=rf"StepRecord\.{field}: expected") as err:
        StepRecord(**_fields(**{field: value}))
    msg = str(err.value)
    assert "if you built this record yourself" in msg and "teaching loop" in msg


def test_a_correction_takes_numpy_values_like_a_step_record_and_holds_plain_ones():
    """CorrectionRecord refused the observation a loop of one's own holds (an ndarray, a list,
    numpy floats) that StepRecord takes, and said corrections 'are built by the teaching
    loop'. It now stores them as the plain tuple of floats, as StepRecord does."""
    plain = CorrectionRecord(
        step=4, episode=1, observation=(0.5, -0.25), executed_action=0, action=1
    )
    for obs in (
        np.array([0.5, -0.25]),
        np.array([0.5, -0.25], dtype=np.float32),
        [0.5, -0.25],
        (np.float64(0.5), np.float32(-0.25)),
    ):
        c = CorrectionRecord(
            step=np.int64(4),
            episode=np.int32(1),
            observation=obs,
            executed_action=np.uint8(0),
            action=np.int64(1),
        )
        assert c == plain, obs
        assert type(c.observation) is tuple and all(type(x) is float for x in c.observation)
        assert all(type(v) is int for v in (c.step, c.episode, c.executed_action, c.action))
        assert c.observation_array.dtype == np.float64


@pytest.mark.parametrize(
    "field,value",
    [
        ("observation", np.array([[0.5, -0.25]])),
        ("observation", np.array([0.5, math.nan])),
        ("observation", np.array([], dtype=np.float64)),
        ("observation", ["a", "b"]),
        ("observation", [True, 0.5]),
        ("observation", (np.float64(math.inf), 0.5)),
        ("step", np.bool_(True)),
        ("step", True),
        ("step", np.float64(4.0)),
        ("episode", np.int64(-1)),
        ("action", np.bool_(True)),
        ("executed_action", np.float32(0.0)),
    ],
)
def test_a_correction_still_refuses_what_is_wrong_and_says_what_to_pass(field, value):
    kw = dict(step=4, episode=1, observation=(0.5, -0.25), executed_action=0, action=1)
    kw[field] = value
    with pytest.raises(ValueError, match=rf"CorrectionRecord\.{field}: expected") as err:
        CorrectionRecord(**kw)
    msg = str(err.value)
    assert "if you built this record yourself" in msg and "teaching loop" in msg
