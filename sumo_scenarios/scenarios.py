"""Named traffic scenarios for the driving domain, and where the shipped SUMO files live.

A :class:`TrafficScenario` fixes everything about the background traffic: the range each car's
desired speed is drawn from in each normal lane, how densely each lane is filled, and a base seed.
Each car keeps its lane and is driven by SUMO's car-following model (Krauss, no driver noise), so a
faster car closes up behind a slower one and platoons form. The road segment an
episode drives on is drawn from ``numpy.random.SeedSequence([scenario.seed, episode_seed])``:
the ``train`` and ``eval`` scenarios differ only in their base seed, so no training episode ever
sees the evaluation segment ("the same road segment" for every evaluation, paper Section 5.2.1).
:func:`held_out_twin` generalises the pair to any traffic: the same traffic on the next base seed
(``eval`` for ``train``), which ``torchcbl evaluate`` drives a session on by default.

Density calibration: with 5 m cars, the ego overlaps a car whenever their centres are closer than
5 m, i.e. over 10 m of relative travel per car, whatever the closing speed. Always driving straight
in a lane with ``n`` cars per metre is therefore in contact on about a ``10 n`` share of timesteps.
Platoons make the middle lane denser than its insertion spacing: the mean insertion spacing below
was measured to give the paper's 30 % (``tests/test_driving_teacher.py`` checks 28-32 %). The other
lanes' densities are free (the paper: "a busy road"); the left lane's ``mean_spacing_m``, 120 m
(a mean spacing of 109 m, after the cap on each spacing's exponential part), came out of the
human-like teacher's calibration search (``sumo_scenarios.calibrate_teacher``, which tried
35-150 m: denser left lanes brought the teacher more contacts, never fewer "stay" answers), the
right lane's 40 m is unchanged.
"""

from __future__ import annotations

import json
import math
import numbers
import os
from dataclasses import dataclass, field, fields, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from torchcbl import _jsonfile

__all__ = [
    "CAR_LENGTH_M",
    "EGO_SPEED_MS",
    "EVAL",
    "LANE_NAMES",
    "LIGHT",
    "MPH",
    "N_LANES",
    "SCENARIOS",
    "TRAFFIC_LANES",
    "TRAIN",
    "TrafficScenario",
    "compared_fields",
    "data_path",
    "described_fields",
    "get_scenario",
    "held_out_twin",
    "load_scenario",
]

MPH = 0.44704
"""Metres per second in one mile per hour."""

EGO_SPEED_MS = 60 * MPH
"""The ego's fixed speed, 60 mph = 26.8224 m/s."""

CAR_LENGTH_M = 5.0
"""Length of every car (ego and traffic), metres."""

N_LANES = 5
"""Lanes on the road: 0 right shoulder, 1-3 normal lanes (right, middle, left), 4 left shoulder."""

TRAFFIC_LANES = (1, 2, 3)
"""SUMO lane indices of the three normal lanes, right to left."""

LANE_NAMES = ("right shoulder", "right", "middle", "left", "left shoulder")


_SHIPPED_DATA = ("road.net.xml", "driving.add.xml", "src/road.nod.xml", "src/road.edg.xml")
"""The data files the package ships (paths under ``sumo_scenarios/data``); all but
``driving.add.xml`` (written by hand) are written by ``python -m sumo_scenarios.build_network``."""


def data_path(name: str) -> Path:
    """Path of a shipped data file (``road.net.xml`` or ``driving.add.xml``; also the network's
    plain-XML sources ``src/road.nod.xml`` and ``src/road.edg.xml``).

    Raises:
        FileNotFoundError: the file is missing. For a shipped name (a damaged install), naming
            it and how to restore it: the network and its sources are rebuilt by ``python -m
            sumo_scenarios.build_network``, the vehicle types (written by hand) only come back
            with the package. For any other name, saying it is no shipped data file and listing
            the shipped ones.
    """
    path = Path(str(resources.files("sumo_scenarios") / "data" / name))
    if not path.exists() and name not in _SHIPPED_DATA:
        raise FileNotFoundError(
            f"{name!r} is not a data file sumo_scenarios ships (no {path}); the shipped ones are "
            f"{', '.join(_SHIPPED_DATA)}: pass one of these, or open a file of your own by its "
            "own path"
        )
    if not path.exists():
        fix = (
            "rebuild it with `python -m sumo_scenarios.build_network` (or reinstall the package)"
            if name != "driving.add.xml"
            else "it is written by hand and shipped, not generated: reinstall the package "
            f"(sumo_scenarios), or in a git checkout restore it with `git checkout -- "
            f"sumo_scenarios/data/{name}`"
        )
        raise FileNotFoundError(f"{path} is missing: the install is damaged; {fix}")
    return path


#: a dataclass field whose metadata marks this key False is not compared on resume
#: (torchcbl.session.COMPARE_ON_RESUME, spelled out: importing it would import torch;
#: tests/test_resume_checks.py checks the two)
_COMPARE_ON_RESUME = "torchcbl.compare_on_resume"


def _as_int(value: Any) -> int | None:
    """``value`` as an int when it is an integer (a Python or numpy int, a 0-d integer array),
    else None; a bool, a float or a string is not. The domain's one integer check."""
    if isinstance(value, bool | np.bool_):
        return None
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, np.ndarray) and value.shape == () and value.dtype.kind in "iu":
        return int(value)
    return None


def _is_real(value: Any) -> bool:
    """Whether ``value`` is a real number (Python or numpy, int or float), not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _items(value: Any) -> list[Any] | None:
    """``value``'s items when it is a sequence (a tuple, a list, an array), else None."""
    if isinstance(value, str | bytes) or (isinstance(value, np.ndarray) and value.ndim == 0):
        return None
    try:
        return list(value)
    except TypeError:
        return None


def _per_lane(name: str, value: Any) -> list[Any]:
    """``value``'s three entries (normal lanes 1, 2, 3), else a ValueError naming ``name``."""
    items = _items(value)
    if items is None or len(items) != len(TRAFFIC_LANES):
        raise ValueError(
            f"{name} needs one entry per normal lane (right, middle, left), 3 in all, got {value!r}"
        )
    return items


@dataclass(frozen=True)
class TrafficScenario:
    """Background traffic on the five-lane road.

    Attributes:
        name: scenario name (``train``, ``eval``, ...): not empty or blank (it names the
            traffic in reports and its held-out twin, ``"<name>-held-out"``).
        seed: base seed; combined with the episode seed to draw the road segment.
        speed_ranges_mph: per normal lane 1, 2, 3 (right, middle, left), the (low, high) range,
            in mph, each car's desired speed is drawn from (uniformly, once per car), inside the
            paper's 20-40 mph. Actual speeds are lower behind a slower leader (car-following).
        mean_spacing_m: mean front-to-front distance between consecutive cars in lanes 1, 2, 3,
            metres, before a cap: spacings are ``min_spacing_m`` plus an exponential draw of
            mean ``mean_spacing_m - min_spacing_m``, cut at 250 m (so that a recycled car fits
            on the road). The cut matters only in a sparse lane: the ``train`` left lane's 120 m
            gives spacings of 109 m on average; its 40 m and 31 m lanes lose under 0.01 m.
        min_spacing_m: smallest front-to-front spacing, metres (> 10 m so the expert can always
            fit between two cars of a lane without contact).
        ahead_m: cars are kept in a window from ``behind_m`` behind to ``ahead_m`` ahead of the
            ego; a car falling out behind is recycled to the front of its lane. Metres.
        behind_m: see ``ahead_m``.
        start_clear_m: at reset no car is within 15 m behind or this many metres ahead of the
            ego (in any lane), so no episode starts in or right before a contact. At most
            ``ahead_m``.
    """

    # the name changes nothing the traffic does: a session resumes on the same traffic under
    # another name
    name: str = field(metadata={_COMPARE_ON_RESUME: False})
    seed: int
    speed_ranges_mph: tuple[tuple[float, float], ...] = ((20.0, 30.0), (25.0, 35.0), (30.0, 40.0))
    mean_spacing_m: tuple[float, float, float] = (40.0, 31.0, 120.0)
    min_spacing_m: float = 12.0
    ahead_m: float = 200.0
    behind_m: float = 60.0
    start_clear_m: float = 30.0

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            # it names the traffic in reports and names its held-out twin: "" made "-held-out"
            raise ValueError(
                "name must be a non-blank str (it names the traffic in reports, and its "
                f"held-out twin '<name>-held-out'), got {self.name!r}; give one, e.g. 'mine'"
            )
        if _as_int(self.seed) is None or self.seed < 0:
            raise ValueError(f"seed must be an int >= 0, got {self.seed!r}")
        for name in ("min_spacing_m", "ahead_m", "behind_m", "start_clear_m"):
            v = getattr(self, name)
            if not _is_real(v) or not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number of metres, got {v!r}")
        ranges = _per_lane("speed_ranges_mph", self.speed_ranges_mph)
        spacings = _per_lane("mean_spacing_m", self.mean_spacing_m)
        for rng in ranges:
            pair = _items(rng)
            if (
                pair is None
                or len(pair) != 2
                or not all(_is_real(v) and math.isfinite(v) for v in pair)
                or not 20.0 <= pair[0] <= pair[1] <= 40.0
            ):
                raise ValueError(
                    "speed_ranges_mph: each lane's range must be (low, high) with "
                    f"20 <= low <= high <= 40 mph, got {rng!r}"
                )
        if self.start_clear_m < 0:
            raise ValueError(f"start_clear_m must be >= 0 m, got {self.start_clear_m!r}")
        if self.min_spacing_m <= 10.0:
            raise ValueError(
                f"min_spacing_m must exceed 10 m (two car lengths), got {self.min_spacing_m!r}"
            )
        for v in spacings:
            if not _is_real(v) or not math.isfinite(v) or v < self.min_spacing_m:
                raise ValueError(
                    "mean_spacing_m: each lane's mean spacing must be a finite number of metres "
                    f">= min_spacing_m ({self.min_spacing_m!r}), got {self.mean_spacing_m!r}"
                )
        if self.behind_m < 30.0 or self.ahead_m < 60.0:
            raise ValueError(
                "the traffic window must cover the 25 m sensing range with margin: behind_m "
                f">= 30 m and ahead_m >= 60 m, got behind_m={self.behind_m!r}, "
                f"ahead_m={self.ahead_m!r}"
            )
        if self.start_clear_m > self.ahead_m:
            # the first car of each lane goes beyond the clear stretch: past the window, it can
            # pass the end of the road, where SUMO removes it and the next step fails on it
            raise ValueError(
                f"start_clear_m must be at most ahead_m = {self.ahead_m} m (the clear stretch "
                f"lies inside the traffic window ahead of the ego), got {self.start_clear_m}; "
                "for a longer empty road ahead raise ahead_m too"
            )
        # plain Python numbers and tuples: libsumo takes no numpy float32 (positions computed
        # from one stay float32) and a recorded episode's JSON no numpy int
        set_ = object.__setattr__
        set_(self, "seed", int(self.seed))
        for name in ("min_spacing_m", "ahead_m", "behind_m", "start_clear_m"):
            set_(self, name, float(getattr(self, name)))
        set_(self, "mean_spacing_m", tuple(float(v) for v in self.mean_spacing_m))
        set_(
            self,
            "speed_ranges_mph",
            tuple((float(lo), float(hi)) for lo, hi in self.speed_ranges_mph),
        )

    @property
    def speed_ranges_ms(self) -> tuple[tuple[float, float], ...]:
        """Desired-speed ranges of lanes 1-3 in m/s."""
        return tuple((lo * MPH, hi * MPH) for lo, hi in self.speed_ranges_mph)

    def with_seed(self, seed: int) -> TrafficScenario:
        """The same traffic with another base seed (another family of road segments): an
        int >= 0, checked as the field is (2.7 or True is refused, not truncated)."""
        return replace(self, seed=seed)


TRAIN = TrafficScenario(name="train", seed=1)
"""Training traffic: segments drawn from base seed 1."""

EVAL = TrafficScenario(name="eval", seed=2)
"""Evaluation traffic: the same traffic mix on segments never used for training (base seed 2)."""

LIGHT = TrafficScenario(name="light", seed=3, mean_spacing_m=(60.0, 60.0, 90.0))
"""Lighter traffic, for demos and quick checks."""

SCENARIOS: dict[str, TrafficScenario] = {s.name: s for s in (TRAIN, EVAL, LIGHT)}
"""Named scenarios by name."""


def held_out_twin(scenario: str | TrafficScenario) -> TrafficScenario:
    """The held-out twin of a traffic: the same traffic on road segments none of its own
    episodes drive, as ``eval`` is ``train``'s.

    One rule: the same fields with the base seed + 1 (a segment is drawn from
    ``SeedSequence([base seed, episode seed])``, so no episode seed of the traffic draws a
    segment of its twin); named as the shipped scenario of those fields where there is one
    (``train`` -> ``eval``, the reproduction's pair), else ``"<name>-held-out"`` (``light``,
    base seed 3 -> ``light-held-out``, base seed 4).

    Raises:
        ValueError: ``scenario`` is not a shipped scenario's name or a TrafficScenario
            (:func:`get_scenario`'s words).
    """
    traffic = get_scenario(scenario)
    twin = replace(traffic, seed=traffic.seed + 1, name=f"{traffic.name}-held-out")
    for shipped in SCENARIOS.values():
        if replace(shipped, name=twin.name) == twin:
            return shipped
    return twin


def get_scenario(scenario: str | TrafficScenario) -> TrafficScenario:
    """Look a shipped scenario up by name (or pass a TrafficScenario through); no path: a JSON
    file of TrafficScenario fields is :func:`load_scenario`'s.

    Raises:
        ValueError: an unknown name (listing the shipped ones and pointing to
            :func:`load_scenario` for a file), or neither a str nor a TrafficScenario.
    """
    if isinstance(scenario, TrafficScenario):
        return scenario
    if not isinstance(scenario, str):  # a dict or list was "unhashable type", a TypeError
        raise ValueError(
            f"scenario must be a name ({', '.join(sorted(SCENARIOS))}) or a TrafficScenario, "
            f"got {type(scenario).__name__} {scenario!r:.80}; e.g. "
            "TrafficScenario(name='mine', seed=0, mean_spacing_m=(40.0, 31.0, 60.0))"
        )
    try:
        return SCENARIOS[scenario]
    except KeyError:
        raise ValueError(
            f"unknown scenario {scenario!r}; known: {', '.join(sorted(SCENARIOS))}; for "
            "traffic of your own give a TrafficScenario, e.g. load_scenario(path) "
            "(sumo_scenarios.scenarios) of a JSON file of its fields"
        ) from None


def compared_fields(settings: Any) -> dict[str, Any]:
    """The fields of the dataclass ``settings`` (a :class:`TrafficScenario`, a ``SimConfig``)
    by name, as they are, but those whose metadata marks ``torchcbl.compare_on_resume`` False
    (a scenario's name, which changes nothing the traffic does): what a resume compares
    (``torchcbl.session.COMPARE_ON_RESUME``)."""
    return {
        f.name: getattr(settings, f.name)
        for f in fields(settings)
        if f.metadata.get(_COMPARE_ON_RESUME) is not False
    }


def described_fields(prefix: str, settings: Any) -> dict[str, str | int | float]:
    """:func:`compared_fields` of ``settings`` as ``DrivingEnv.describe_inputs`` gives them:
    ``<prefix>.<field>``, a number or str as it is, anything else (a tuple) as its JSON
    text."""
    return {
        f"{prefix}.{name}": value if isinstance(value, int | float | str) else json.dumps(value)
        for name, value in compared_fields(settings).items()
    }


_JSON_SHAPE = (
    'one JSON object of TrafficScenario fields: "seed" (an int >= 0, required) and any of '
    '"name" (default: the file\'s name less its suffix), "speed_ranges_mph" (a [low, high] per '
    'normal lane, right, middle, left, within 20-40), "mean_spacing_m" (metres, one per normal '
    'lane), "min_spacing_m", "ahead_m", "behind_m", "start_clear_m" (those left out: the train '
    'traffic\'s), e.g. {"seed": 7, "mean_spacing_m": [80, 60, 200]}'
)
"""What a scenario file (:func:`load_scenario`) holds, in words."""


def load_scenario(name_or_path: str | os.PathLike[str]) -> TrafficScenario:
    """A shipped scenario by name (``train``, ``eval``, ``light``), or a :class:`TrafficScenario`
    made from a JSON file of its fields, by path (a name ending in ``.json``, in any case, is a
    path; so is any other existing file, unless it is a shipped scenario's bare name:
    ``"light"`` is the shipped scenario, ``"./light"`` the file).

    The file holds one JSON object of the fields: ``seed`` (required) and any of the others,
    lists for tuples, e.g. ``{"seed": 7, "mean_spacing_m": [80, 60, 200]}``; a field left out
    takes TrafficScenario's default (the ``train`` traffic's), and ``name`` the file's name less
    its suffix. TrafficScenario checks the values itself.

    Raises:
        ValueError: an unknown name, a file that is missing, unreadable or not UTF-8 JSON, a key
            given twice, not an object, a field TrafficScenario lacks, no ``seed``, or a value
            TrafficScenario refuses (its own words); one line naming the file.
    """
    text_name = os.fspath(name_or_path)
    path = Path(text_name)
    if text_name in SCENARIOS:  # a bare shipped name, never a path
        return SCENARIOS[text_name]
    if path.suffix.lower() != ".json" and not path.is_file():
        raise ValueError(
            f"unknown scenario {text_name!r}; expected a shipped scenario's name "
            f"({', '.join(sorted(SCENARIOS))}) or the path of a JSON file of TrafficScenario "
            "fields (FILE.json)"
        )
    where = f"scenario file {text_name!r}"
    if not path.is_file():
        what = "is a directory" if path.is_dir() else "not found"
        raise ValueError(
            f"{where} {what}; give an existing JSON file of TrafficScenario fields or a shipped "
            f"scenario's name ({', '.join(sorted(SCENARIOS))})"
        )
    shipped = f"give a shipped scenario's name ({', '.join(sorted(SCENARIOS))})"
    text = _jsonfile.read_text(
        path,
        not_text=lambda why: f"{where} is not UTF-8 text ({why}); expected {_JSON_SHAPE}",
        unreadable=lambda why: (
            f"{where} cannot be read ({why}); give a JSON file of TrafficScenario fields this "
            "user can read"
        ),
    )
    data = _jsonfile.loads(
        text,
        not_json=lambda why: f"{where} is not valid JSON: {why}; fix the file, or {shipped}",
        given_twice=lambda key: (
            f"{where}: the key {key!r} is given twice (JSON would keep the last silently); "
            "give each once"
        ),
    )
    if not isinstance(data, dict):
        raise ValueError(f"{where} holds a JSON {type(data).__name__}; expected {_JSON_SHAPE}")
    known = [f.name for f in fields(TrafficScenario)]
    unknown = sorted(k for k in data if k not in known)
    if unknown:
        is_no = (
            "is no TrafficScenario field" if len(unknown) == 1 else "are no TrafficScenario fields"
        )
        raise ValueError(
            f"{where}: {', '.join(map(repr, unknown))} {is_no}; the fields are {', '.join(known)}"
        )
    if "seed" not in data:
        raise ValueError(
            f"{where} gives no 'seed' (the base seed its road segments are drawn from, an int "
            '>= 0), which a scenario needs; e.g. {"seed": 7}'
        )
    data.setdefault("name", path.stem)
    try:
        return TrafficScenario(**data)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
