"""The SUMO side of the driving domain: the ONLY module that imports libsumo, as its first
:class:`HighwaySim` is made (so the settings and records of the driving domain, this module's
:class:`SimConfig` among them, import without SUMO: listing a run's episodes needs none).

:class:`HighwaySim` runs one straight five-lane edge with background traffic that keeps its lane,
each car at its own desired speed (20-40 mph) under SUMO's car-following model, and one ego car at
exactly 60 mph that changes lane only when told.
It keeps the road endless (see :meth:`HighwaySim.step`) and counts contact geometrically (a
car whose front bumper is within a car length of the ego's, in the lane the ego is in or the one
it just left), because SUMO's own collision list is unreliable once the ego has driven through a
car.

libsumo holds one simulation per process. Several :class:`HighwaySim` objects may exist, but the
simulation belongs to the one whose :meth:`HighwaySim.reset` ran last: a reset of another takes it
over, and the first then raises :class:`RuntimeError` (saying so) until it is reset again, on a
fresh road segment. Two simulations running at once need two processes.

A simulation the user started with libsumo (``libsumo.start``, also after closing ours with
``libsumo.close()``) is never loaded over, closed or stepped: a reset refuses to start while it
runs, and close leaves it running. Before every step the simulation checks that libsumo still
holds ours as we left it, SUMO's clock included, and raises :class:`RuntimeError` saying what
happened (closed, stepped by hand, or replaced by the user's own) instead of stepping. A step
cut short (a Ctrl-C, or an error raised inside it) leaves SUMO and the bookkeeping apart: every
later step raises :class:`RuntimeError` saying so until a reset.
"""

from __future__ import annotations

import math
import operator
import os
import shutil
import tempfile
import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sumo_scenarios.build_network import SPEED_LIMIT_MS
from sumo_scenarios.scenarios import (
    CAR_LENGTH_M,
    EGO_SPEED_MS,
    N_LANES,
    TRAFFIC_LANES,
    TrafficScenario,
    _is_real,
    data_path,
)

# the libsumo module, imported by the first HighwaySim (_import_libsumo)
libsumo: Any = None


def _import_libsumo() -> None:
    """Import libsumo into this module (once): every use of it follows a HighwaySim's making."""
    global libsumo
    if libsumo is None:
        import libsumo as module

        libsumo = module


EDGE = "road"
ROUTE = "road"  # the one route, over EDGE (data/driving.add.xml)
EGO = "ego"
# libsumo's one simulation: whether it runs, and the ``_state`` dict of the HighwaySim whose
# reset placed the road it holds (a dict, not the object: one dropped without close() is
# collected, and its finaliser closes libsumo if it still owned it)
_SUMO: dict[str, Any] = {"running": False, "owner": None, "pid": None, "options": None}
# options SUMO reports for the simulation a reset of ours loaded (_SUMO["options"]): another
# simulation (libsumo.close() and a libsumo.start of the caller's own) reports others
_OPTIONS = ("net-file", "additional-files", "step-length", "collision.action", "seed", "fcd-output")


def _options() -> dict[str, str]:
    """The options of the simulation libsumo holds (it must hold one), as SUMO reports them."""
    return {k: libsumo.simulation.getOption(k) for k in _OPTIONS}


def _gone(time_ms: int, vehicles: int) -> str | None:
    """Why libsumo, believed to run our simulation, does not as we left it (checked before
    every step, so only what tells another simulation apart best, under 1 us): "closed" (the
    user closed it), "replaced" (and started their own), "stepped" (the user stepped ours),
    None while it is ours as we left it.

    ``time_ms`` is the time our simulation is at (its steps since the reset times the step
    length, milliseconds, SUMO's resolution); at 0 (no step since the reset) ``vehicles``,
    how many vehicles the reset placed, tells a fresh simulation of the user's apart too: its
    seed and additional file can be ours (SUMO's default seed with our vehicle types, as a
    ``write_sumocfg`` configuration runs), its time and vehicles hardly.
    """
    if not libsumo.simulation.isLoaded():
        return "closed"
    ours = _SUMO["options"]
    if ours is None:
        return None
    get = libsumo.simulation.getOption
    if get("seed") != ours["seed"] or get("additional-files") != ours["additional-files"]:
        return "replaced"
    if round(libsumo.simulation.getTime() * 1000.0) != time_ms:
        # ours, stepped by hand, still holds the ego and reports our options (a fresh one
        # of the user's, with our vehicle types, has no vehicle yet)
        return (
            "stepped" if _options() == ours and EGO in libsumo.vehicle.getIDList() else "replaced"
        )
    if time_ms == 0 and libsumo.vehicle.getIDCount() != vehicles:
        return "replaced"
    return None


def _replaced() -> bool:
    """Whether libsumo, believed to run our simulation, holds another: the user closed ours
    and started their own (its options differ from those of our last load)."""
    return (
        _SUMO["options"] is not None
        and libsumo.simulation.isLoaded()
        and _options() != _SUMO["options"]
    )


def _release(state: dict[str, bool]) -> None:
    """Close libsumo if this simulation owns it (close() or garbage collection); a simulation
    that another's reset took over leaves that one running, and so does one the user started
    after closing ours (libsumo.close() and a libsumo.start of their own)."""
    if state["owns"]:
        state["owns"] = False
        _SUMO["owner"] = None
        if _SUMO["running"]:
            _SUMO["running"] = False
            if not _replaced():
                libsumo.close()


def _sumo_inputs() -> tuple[list[str], Path | None]:
    """SUMO's ``-n`` and ``-a`` arguments (the shipped network and vehicle types), and the
    temporary directory of copies to remove once SUMO has loaded them (None: no copies).

    SUMO splits these options' file lists at commas, with no way to escape one: under a path
    holding a comma (a checkout in "OneDrive - Acme, Inc") every start failed. There SUMO is
    given copies in a fresh temporary directory, which the caller removes as soon as the start
    or load returns (SUMO reads them then only), so no process, forked worker or killed one,
    leaves copies behind for longer than a load.
    """
    net, add = data_path("road.net.xml"), data_path("driving.add.xml")
    if "," not in str(net) and "," not in str(add):
        return ["-n", str(net), "-a", str(add)], None
    copies = Path(tempfile.mkdtemp(prefix="torchcbl-sumo-"))
    if "," in str(copies):
        shutil.rmtree(copies, ignore_errors=True)
        raise RuntimeError(
            f"SUMO cannot open {net}: it splits file names at commas, and this path holds one, "
            f"as does the temporary directory ({copies.parent}) its copy would go to; set "
            "TMPDIR to a directory whose path has no comma (or move the package)"
        )
    try:
        for p in (net, add):
            shutil.copyfile(p, copies / p.name)
    except BaseException:
        shutil.rmtree(copies, ignore_errors=True)
        raise
    return ["-n", str(copies / net.name), "-a", str(copies / add.name)], copies


_MAX_EXTRA_GAP_M = 250.0  # spacings are capped so a recycled car always fits on the edge


def _insert(vid: str, type_id: str, lane: int, x: float, speed: float) -> None:
    """Add a vehicle at lane / position ``x`` (m) NOW, at ``speed`` (m/s).

    ``moveTo`` right after ``add`` skips SUMO's insertion checks, which would otherwise delay
    the car; lane-change mode 0 keeps it in its lane. The ego (type ``ego``) gets speed mode 32
    and a fixed speed: it never brakes. A traffic car gets ``speed`` as its desired speed
    (speed factor relative to the speed limit) and is left to SUMO's car-following model.
    """
    libsumo.vehicle.add(
        vid, ROUTE, typeID=type_id, departLane=str(lane), departPos=str(x), departSpeed=str(speed)
    )
    libsumo.vehicle.moveTo(vid, f"{EDGE}_{lane}", x)
    libsumo.vehicle.setLaneChangeMode(vid, 0)
    if type_id == "ego":
        libsumo.vehicle.setSpeedMode(vid, 32)
        libsumo.vehicle.setSpeed(vid, speed)
    else:
        libsumo.vehicle.setSpeedFactor(vid, speed / SPEED_LIMIT_MS)


@dataclass(frozen=True)
class SimConfig:
    """Simulation settings.

    Attributes:
        step_length_s: one decision = one SUMO step of this many seconds (0.25 s: the paper's
            500 timesteps were about 2.1 minutes of driving), a whole number of milliseconds
            (SUMO's time resolution), at most 0.5 s: contact is checked
            at the end of each step, and the ego (60 mph) passes a car of 20 mph within a car
            length (10 m of relative travel) in 0.56 s.
        ego_start_m: the ego's front-bumper position on the edge at reset, metres.
        shift_margin_m: when the ego comes this close (plus the traffic window) to the end of
            the edge, every vehicle is moved back by the same distance. Metres. On the shipped
            10 km road that first happens after about 1,350 steps, so a 1000-step episode never
            sees a car jump. It must be at least the scenario's ``min_spacing_m`` + 250 m (the
            largest extra spacing of a new car) + one step of the ego's travel, so that no car
            reaches the end of the edge (the environment refuses less).
    """

    step_length_s: float = 0.25
    ego_start_m: float = 300.0
    shift_margin_m: float = 400.0

    def __post_init__(self) -> None:
        for name in ("step_length_s", "ego_start_m", "shift_margin_m"):
            v = getattr(self, name)
            if not _is_real(v):
                raise ValueError(f"{name} must be a number, got {v!r}")
            # a plain float: SUMO gets it as text (``repr`` of a numpy float is not a number)
            object.__setattr__(self, name, float(v))
        ms = self.step_length_s * 1000.0
        if math.isfinite(ms) and abs(ms - round(ms)) <= 1e-3:
            # the float SUMO runs: np.float32(0.1) is 0.10000000149011612 as a float (a Python
            # float of whole milliseconds, 0.25 say, stays the same float)
            object.__setattr__(self, "step_length_s", round(ms) / 1000.0)
        if not 0.01 <= self.step_length_s <= 0.5:
            raise ValueError(
                f"step_length_s must lie in [0.01, 0.5] seconds, got {self.step_length_s}: "
                "contact is checked once a step, and a car at 20 mph stays within a car length "
                "of the ego for 0.56 s, so a longer step can pass through it unseen"
            )
        if abs(ms - round(ms)) > 1e-3:  # not snapped above
            # SUMO counts time in whole milliseconds: 0.0125 s ran as 0.013 s while speeds were
            # measured over (and the teachers told) 0.0125 s, 4 % off
            raise ValueError(
                f"step_length_s must be a whole number of milliseconds (SUMO's time step), got "
                f"{self.step_length_s!r}; e.g. {round(ms) / 1000.0!r}"
            )
        if not (math.isfinite(self.ego_start_m) and self.ego_start_m >= 0):
            raise ValueError(
                f"ego_start_m must be a finite distance >= 0 m, got {self.ego_start_m}"
            )
        if not (math.isfinite(self.shift_margin_m) and self.shift_margin_m >= 0):
            raise ValueError(
                f"shift_margin_m must be a finite distance >= 0 m, got {self.shift_margin_m}"
            )


class HighwaySim:
    """One libsumo simulation of the five-lane road.

    State after :meth:`reset` / :meth:`step` (positions are front bumpers along the edge, metres):
        ``ego_pos`` (float), ``ego_lane`` (int, 0 = right shoulder .. 4 = left shoulder),
        ``car_pos`` [N] float64, ``car_lane`` [N] int64 (1-3), ``car_speed`` [N] float64 (m/s,
        measured over the last step), ``car_vdes`` [N] float64 (desired speed, m/s),
        ``contact`` (bool).
    """

    def __init__(self, scenario: TrafficScenario, config: SimConfig | None = None) -> None:
        _import_libsumo()
        self.scenario = scenario
        self.config = config or SimConfig()
        # whether libsumo holds this simulation's road; shared with the finaliser (which must
        # not hold self) and cleared by another simulation's reset
        self._state = {"owns": False}
        self._closed = False
        self._ready = False  # a reset has completed since the last failure
        # a step is under way: set once step()'s checks passed, cleared when it completes (or
        # by a reset or close); still set before a step, the last one was cut short (a Ctrl-C
        # or an error inside it) and left SUMO and the bookkeeping out of step
        self._stepping = False
        self._road_length = float(libsumo_lane_length_from_net())
        if self.config.ego_start_m < scenario.behind_m:
            raise ValueError(
                f"SimConfig.ego_start_m = {self.config.ego_start_m} m leaves no room for the "
                f"scenario's {scenario.behind_m} m of traffic behind the ego"
            )
        room = self.config.ego_start_m + scenario.ahead_m + self.config.shift_margin_m
        if room >= self._road_length:
            raise ValueError(
                f"SimConfig: ego_start_m + the scenario's ahead_m + shift_margin_m = {room:.0f} m "
                f"must stay below the road's {self._road_length:.0f} m"
            )
        # a car is placed up to min_spacing_m + _MAX_EXTRA_GAP_M beyond the traffic window's
        # front, and the ego may pass the shift point by one step's travel before the shift:
        # with less margin a car reaches the end of the edge and SUMO removes it
        need = scenario.min_spacing_m + _MAX_EXTRA_GAP_M + EGO_SPEED_MS * self.config.step_length_s
        if self.config.shift_margin_m < need:
            raise ValueError(
                f"SimConfig.shift_margin_m = {self.config.shift_margin_m} m is too small for the "
                f"scenario's min_spacing_m = {scenario.min_spacing_m} m: a car would reach the "
                f"end of the road before the shift; it must be at least {need:.1f} m (the "
                f"scenario's min_spacing_m + {_MAX_EXTRA_GAP_M:.0f} m + one step of the ego)"
            )
        self._finalizer = weakref.finalize(self, _release, self._state)
        ranges = scenario.speed_ranges_ms
        self._speed_range = {lane: ranges[i] for i, lane in enumerate(TRAFFIC_LANES)}
        self.ego_pos = 0.0
        self.ego_lane = 2
        self.prev_lane = 2
        self.contact = False
        self.car_ids: list[str] = []
        self.car_lane = np.zeros(0, dtype=np.int64)
        self.car_pos = np.zeros(0, dtype=np.float64)
        self.car_speed = np.zeros(0, dtype=np.float64)
        self.car_vdes = np.zeros(0, dtype=np.float64)
        self.distance_m = 0.0
        self.n_recycled = 0
        self.n_shifts = 0
        self._steps = 0

    # ------------------------------------------------------------------ lifecycle
    def _args(self, inputs: list[str], seed: int, fcd_path: Path | None) -> list[str]:
        args = [
            "sumo",
            *inputs,
            "--step-length",
            repr(self.config.step_length_s),
            "--collision.action",
            "none",
            "--no-step-log",
            "true",
            "--no-warnings",
            "true",
            "--seed",
            str(seed % (2**31)),
            "--begin",
            "0",
        ]
        if fcd_path is not None:
            args += ["--fcd-output", str(fcd_path)]
        return args

    def reset(
        self,
        rng: np.random.Generator,
        seed: int,
        *,
        ego_lane: int = 2,
        fcd_path: Path | None = None,
    ) -> None:
        """Start (or reload) SUMO and place the ego and the traffic of a fresh road segment.

        ``rng`` draws the car spacings (the road segment); ``seed`` is SUMO's own seed.
        ``fcd_path``, if given, makes SUMO write FCD XML there (finalised on :meth:`close` or
        the next reset).
        """
        if self._closed:
            raise RuntimeError("this simulation is closed")
        if not 0 <= ego_lane < N_LANES:
            raise ValueError(f"ego_lane must lie in [0, {N_LANES - 1}]")
        self._ready = False  # until this reset completes: step() would crash SUMO before
        self._stepping = False  # the road a cut-short step left is replaced below
        if _SUMO["running"] and _SUMO["pid"] != os.getpid():
            raise RuntimeError(
                "this process was forked from one whose libsumo simulation is running, and the "
                "copy it inherited is that process's (its FCD output included): start the "
                "simulation in a process made with 'spawn' (multiprocessing.get_context('spawn'), "
                "gymnasium's AsyncVectorEnv(..., context='spawn')), or close the parent's env "
                "before forking"
            )
        if libsumo.simulation.isLoaded() and (
            not _SUMO["running"]
            # ours closed (libsumo.close()) and one of the caller's started in its place
            or _replaced()
        ):
            # a libsumo.start of the caller's own: a start here would replace it without a word
            raise RuntimeError(
                "this process's libsumo already runs a simulation not started by "
                "sumo_scenarios (a libsumo.start of your own), and libsumo holds one "
                "simulation per process: close it (libsumo.close()) before resetting a "
                "DrivingEnv, or run the two in separate processes"
            )
        owner = _SUMO["owner"]
        if owner is not None and owner is not self._state:
            owner["owns"] = False  # its road goes with the load below: taken over
        # owned from here, also if the load fails (close() then closes what is left of it)
        _SUMO["owner"] = self._state
        self._state["owns"] = True
        inputs, copies = _sumo_inputs()
        args = self._args(inputs, seed, fcd_path)
        _SUMO["options"] = None  # unknown until the load below completes
        try:
            if _SUMO["running"]:
                libsumo.load(args[1:])
            else:
                # running from before the call: a start cut short still gets its
                # libsumo.close() (which is harmless when nothing is loaded)
                _SUMO["running"], _SUMO["pid"] = True, os.getpid()
                libsumo.start(args)
        finally:
            if copies is not None:  # read by the load: not needed any more
                shutil.rmtree(copies, ignore_errors=True)
        _SUMO["options"] = _options()
        self._rng = rng
        self._next_id = 0
        self.n_recycled = 0
        self.n_shifts = 0
        self.distance_m = 0.0
        self._steps = 0  # SUMO steps since the load (its time: this many step lengths)
        x0 = self.config.ego_start_m
        _insert(EGO, "ego", ego_lane, x0, EGO_SPEED_MS)
        ids, lanes, pos, vdes = [], [], [], []
        # Per lane, where the frontmost car was placed and its desired speed: new cars always go
        # one fresh spacing ahead of where that car would be at its desired speed (it is never
        # farther ahead: car-following only slows it), so every lane stays a stream at its own
        # insertion density.
        self._front: dict[int, list[float]] = {}
        for lane in TRAFFIC_LANES:
            x = x0 - self.scenario.behind_m + float(rng.uniform(0.0, self._spacing(lane)))
            self._front[lane] = [x0 + self.scenario.ahead_m, 0.0]
            while True:  # up to the first car at or beyond the horizon
                if x0 - 15.0 < x < x0 + self.scenario.start_clear_m:
                    x += self._spacing(lane)
                    continue
                v = self._desired_speed(lane)
                cid = self._add_car(lane, x, v)
                ids.append(cid)
                lanes.append(lane)
                pos.append(x)
                vdes.append(v)
                self._front[lane] = [x, v]
                if x >= x0 + self.scenario.ahead_m:
                    break
                x += self._spacing(lane)
        self.car_ids = ids
        self.car_lane = np.asarray(lanes, dtype=np.int64)
        self.car_pos = np.asarray(pos, dtype=np.float64)
        self.car_vdes = np.asarray(vdes, dtype=np.float64)
        self.car_speed = self.car_vdes.copy()
        self.ego_pos = x0
        self.ego_lane = ego_lane
        self.prev_lane = ego_lane
        self.contact = self._contact()
        self._ready = True

    def close(self) -> None:
        """Release SUMO (finalising any FCD file) and let another simulation start."""
        if self._closed:
            return
        self._closed = True
        self._ready = False
        # _stepping stays: the bookkeeping a cut-short step left is still half updated
        self._finalizer()  # closes libsumo if this simulation owns it; runs once

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has run."""
        return self._closed

    @property
    def cut_short(self) -> bool:
        """True when the last :meth:`step` did not finish (a Ctrl-C or an error inside it):
        the state (``ego_pos``, ``car_pos`` ...) is half updated until a :meth:`reset`."""
        return self._stepping

    @property
    def steps(self) -> int:
        """SUMO steps since the last reset (its time is this many step lengths); a step cut
        short counts once SUMO has stepped."""
        return self._steps

    def __reduce_ex__(self, protocol: object) -> object:
        # copy.copy, copy.deepcopy and pickle all come here: a copy would share (or, unpickled,
        # lack) the process's one libsumo simulation while keeping its own bookkeeping
        raise TypeError(
            "a HighwaySim (and the DrivingEnv holding it) owns this process's one libsumo "
            "simulation and cannot be copied or pickled; make a new DrivingEnv instead (in "
            "another process for a second simulation, e.g. gymnasium's AsyncVectorEnv)"
        )

    # ------------------------------------------------------------------ traffic
    def _spacing(self, lane: int) -> float:
        i = TRAFFIC_LANES.index(lane)
        lo = self.scenario.min_spacing_m
        gap = float(self._rng.exponential(self.scenario.mean_spacing_m[i] - lo))
        return lo + min(gap, _MAX_EXTRA_GAP_M)

    def _desired_speed(self, lane: int) -> float:
        lo, hi = self._speed_range[lane]
        return float(self._rng.uniform(lo, hi))

    def _add_car(self, lane: int, x: float, speed: float) -> str:
        cid = f"c{self._next_id}"
        self._next_id += 1
        _insert(cid, "traffic", lane, x, speed)
        return cid

    # ------------------------------------------------------------------ stepping
    def step(self, target_lane: int) -> None:
        """Advance one decision period with the ego heading for ``target_lane``.

        ``target_lane`` is clamped to the road by the caller's contract (0..4; out of range
        raises). In the step SUMO moves every vehicle, then puts the ego in its new lane at once.
        Afterwards: cars more than ``behind_m`` behind the ego are recycled (remove + add +
        moveTo, which also restores SUMO's lane order) to the front of their lane at a fresh
        spacing, and when the ego nears the end of the edge every vehicle is moved back by the
        same distance. Contact never removes anything.
        """
        self._check_owned()
        try:
            target_lane = operator.index(target_lane)  # an int or numpy integer, not 2.0
        except TypeError:
            raise TypeError(
                f"target_lane must be a whole lane number in [0, {N_LANES - 1}], got "
                f"{target_lane!r}; pass int(lane)"
            ) from None
        if not 0 <= target_lane < N_LANES:
            raise ValueError(f"target_lane must lie in [0, {N_LANES - 1}], got {target_lane}")
        self._stepping = True  # until the end: cut short, the next step refuses
        if target_lane != self.ego_lane:
            libsumo.vehicle.changeLane(EGO, target_lane, self.config.step_length_s)
        libsumo.simulationStep()
        self._steps += 1
        get = libsumo.vehicle.getLanePosition
        old = self.ego_pos
        self.ego_pos = get(EGO)
        self.distance_m += self.ego_pos - old
        self.prev_lane = self.ego_lane
        self.ego_lane = libsumo.vehicle.getLaneIndex(EGO)
        ids = self.car_ids
        pos = self.car_pos
        old_pos = pos.copy()
        for i, cid in enumerate(ids):
            pos[i] = get(cid)
        self.car_speed = (pos - old_pos) / self.config.step_length_s
        self.contact = self._contact()
        behind = self.ego_pos - self.scenario.behind_m
        horizon = self.ego_pos + self.scenario.ahead_m
        for lane in TRAFFIC_LANES:  # nominal fronts move at their car's desired speed
            self._front[lane][0] += self._front[lane][1] * self.config.step_length_s
        if (pos.size and pos.min() < behind) or min(f[0] for f in self._front.values()) < horizon:
            self._recycle(behind, horizon)
        if self.ego_pos > self._road_length - self.scenario.ahead_m - self.config.shift_margin_m:
            self._shift_back()
        self._stepping = False

    def _recycle(self, behind: float, horizon: float) -> None:
        """Keep every lane filled from ``behind`` to ``horizon`` at its own density.

        Cars that fell more than ``behind_m`` behind the ego are taken off; each lane whose
        frontmost placed car is less than ``ahead_m`` ahead gets new cars, one fresh spacing
        after another, reusing the cars taken off (remove + add + moveTo, which also restores
        SUMO's lane order). Cars not needed again are removed for good. New cars therefore
        always enter far ahead of the ego, never next to it.
        """
        free = [int(i) for i in np.flatnonzero(self.car_pos < behind)]
        keep = np.ones(len(self.car_ids), dtype=bool)
        for i in free:
            libsumo.vehicle.remove(self.car_ids[i])
            keep[i] = False
        new_ids, new_lane, new_pos, new_v = [], [], [], []
        for lane in TRAFFIC_LANES:
            while self._front[lane][0] < horizon:
                x = self._front[lane][0] + self._spacing(lane)
                v = self._desired_speed(lane)
                self._front[lane] = [x, v]
                cid = self._add_car(lane, x, v)
                self.n_recycled += 1
                if free:
                    i = free.pop(0)
                    self.car_ids[i], self.car_lane[i], self.car_pos[i] = cid, lane, x
                    self.car_vdes[i] = self.car_speed[i] = v
                    keep[i] = True
                else:
                    new_ids.append(cid)
                    new_lane.append(lane)
                    new_pos.append(x)
                    new_v.append(v)
        if not keep.all() or new_ids:
            self.car_ids = [c for c, k in zip(self.car_ids, keep, strict=True) if k] + new_ids
            self.car_lane = np.concatenate([self.car_lane[keep], np.asarray(new_lane, np.int64)])
            self.car_pos = np.concatenate([self.car_pos[keep], np.asarray(new_pos, np.float64)])
            nv = np.asarray(new_v, np.float64)
            self.car_vdes = np.concatenate([self.car_vdes[keep], nv])
            self.car_speed = np.concatenate([self.car_speed[keep], nv])

    def _shift_back(self) -> None:
        shift = self.ego_pos - self.config.ego_start_m
        libsumo.vehicle.moveTo(EGO, f"{EDGE}_{self.ego_lane}", self.ego_pos - shift)
        for i, cid in enumerate(self.car_ids):
            lane = int(self.car_lane[i])
            libsumo.vehicle.moveTo(cid, f"{EDGE}_{lane}", float(self.car_pos[i]) - shift)
        self.ego_pos -= shift
        self.car_pos -= shift
        for lane in TRAFFIC_LANES:
            self._front[lane][0] -= shift
        self.n_shifts += 1

    def _contact(self) -> bool:
        near = np.abs(self.car_pos - self.ego_pos) < CAR_LENGTH_M
        if not near.any():
            return False
        lanes = self.car_lane[near]
        return bool(np.any((lanes == self.ego_lane) | (lanes == self.prev_lane)))

    def _check_owned(self) -> None:
        """Raise unless libsumo holds this simulation's road, saying why not."""
        if self._stepping and not self._closed:
            # a Ctrl-C raised as SUMO's step returned, or anything raised in the bookkeeping
            # after it: SUMO's clock, the cars and the env's arrays no longer agree
            raise RuntimeError(
                "the env's last step did not finish (interrupted or raised inside it), and "
                "SUMO and the env's road bookkeeping no longer agree: reset() to go on (on a "
                "fresh road segment)"
            )
        if self._ready and self._state["owns"]:
            ms = self._steps * round(self.config.step_length_s * 1000.0)
            gone = _gone(ms, len(self.car_ids) + 1)  # the cars and the ego
            if gone is None:
                return
            if gone == "closed":
                raise RuntimeError(
                    "this env's libsumo simulation was closed outside this env "
                    "(libsumo.close()): reset() this env to start a new one (on a fresh road "
                    "segment)"
                )
            if gone == "stepped":
                raise RuntimeError(
                    "this env's libsumo simulation was stepped outside this env (a "
                    f"libsumo.simulationStep() of your own: its time is "
                    f"{libsumo.simulation.getTime()!r} s, the env's {ms / 1000.0!r} s), and the "
                    "env's measured speeds and road bookkeeping no longer hold: reset() this env "
                    "to go on (on a fresh road segment); step it only through the env"
                )
            raise RuntimeError(
                "this process's libsumo runs a simulation not started by sumo_scenarios (a "
                "libsumo.start of your own, after this env's was closed with libsumo.close()), "
                "and libsumo holds one simulation per process: close it (libsumo.close()) and "
                "reset() this env, or run the two in separate processes"
            )
        if self._closed:
            raise RuntimeError("this simulation is closed")
        if self._ready:
            raise RuntimeError(
                "another DrivingEnv (HighwaySim) in this process was reset since this one, and "
                "libsumo holds only one simulation per process: it took this one's road over. "
                "reset() this env to go on (on a fresh road segment, taking the simulation "
                "back), or run the two in separate processes (e.g. gymnasium's AsyncVectorEnv)"
            )
        raise RuntimeError(
            "reset() first: no reset has completed since the simulation was made or since a "
            "reset failed"
        )

    def vehicle_positions(self) -> dict[str, tuple[float, int]]:
        """SUMO's own view: ``{id: (front-bumper position m, lane index)}`` for every vehicle."""
        self._check_owned()
        out = {}
        for vid in libsumo.vehicle.getIDList():
            out[vid] = (libsumo.vehicle.getLanePosition(vid), libsumo.vehicle.getLaneIndex(vid))
        return out


def sumo_versions() -> dict[str, str]:
    """The SUMO release libsumo runs, as libsumo itself reports it: ``{"sumo": "1.28.0"}``
    (a build from SUMO's sources names its commit). A teaching session's writers record it
    (:meth:`sumo_scenarios.env.DrivingEnv.describe_versions`): another release follows cars
    and places traffic otherwise."""
    _import_libsumo()
    release = str(libsumo.getVersion()[1])  # (API level, "SUMO 1.28.0")
    return {"sumo": release.removeprefix("SUMO ").strip()}


def libsumo_lane_length_from_net() -> float:
    """Length of the road edge in the shipped network, metres (read with sumolib).

    Raises:
        RuntimeError: the file is not a network holding the edge (changed or damaged), naming
            it and the command that rebuilds it.
    """
    import xml.sax

    import sumolib

    path = data_path("road.net.xml")
    try:
        return float(sumolib.net.readNet(str(path)).getEdge(EDGE).getLength())
    except (xml.sax.SAXException, KeyError) as exc:  # sumolib's words: "'road'", "syntax error"
        what = f"no edge {EDGE!r}" if isinstance(exc, KeyError) else f"not XML: {exc}"
        raise RuntimeError(
            f"{path} is not the shipped road network ({what}): it was changed or damaged; "
            "rebuild it with `python -m sumo_scenarios.build_network` (or reinstall the package)"
        ) from None
