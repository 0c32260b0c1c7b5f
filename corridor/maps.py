"""Corridor maps as data: nodes joined by straight, axis-aligned corridors, and a target route.

A map is a :class:`CorridorMap` (a frozen dataclass) usually loaded from a JSON file shipped in
``corridor/maps/`` (see :func:`load_map`, :func:`available_maps`). All lengths are in metres.

The free space is the union of the corridors: corridor ``(a, b)`` is the rectangle around the
segment from node ``a`` to node ``b``, ``corridor_width`` wide and extended by half the width
past both nodes, so every node is the centre of a square junction (or the centre of the last
square of a dead end). Walls are the boundary of that union (:meth:`CorridorMap.walls`),
computed exactly on a grid of ``grid`` metres, which every node coordinate and half the width
must be multiples of.

The target route is a closed walk over nodes (first == last). The robot starts
``start_offset`` metres from ``route[0]`` toward ``route[1]``, heading that way; the route
polyline (:class:`Route`) runs from that start point through the node centres back to it, and
progress along the circuit is measured along it. At each route node the robot does one
manoeuvre (:meth:`CorridorMap.manoeuvres`): straight on, turn left, turn right or u-turn
(when the route comes back the way it went: the end of a dead-end spur).

JSON format (all keys required unless marked)::

    {"name": "figure2", "description": "...",             (description optional)
     "corridor_width": 0.6, "grid": 0.1, "start_offset": 0.2,   (grid, start_offset optional)
     "nodes": {"P0": [0.0, 0.0], ...},
     "corridors": [["P0", "P1"], ...],
     "route": ["P0", "P1", ..., "P0"]}
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from torchcbl import _jsonfile

__all__ = [
    "CorridorMap",
    "Route",
    "RouteProgress",
    "available_maps",
    "load_map",
    "map_from_dict",
]

STRAIGHT, LEFT, RIGHT, UTURN = "straight", "left", "right", "uturn"
_EPS = 1e-9


def _on_grid(value: float, grid: float) -> bool:
    q = value / grid
    return math.isfinite(q) and abs(q - round(q)) < 1e-6


@dataclass(frozen=True)
class CorridorMap:
    """A circuit of corridors (metres) and the route the expert drives through it.

    Attributes:
        name: short identifier (the JSON file's stem for shipped maps).
        corridor_width: width of every corridor, metres.
        nodes: node name -> (x, y) centre, metres.
        corridors: pairs of node names joined by a straight axis-aligned corridor.
        route: closed walk over nodes, ``route[0] == route[-1]``; consecutive nodes must be
            joined by a corridor.
        start_offset: the start pose is this far from ``route[0]`` toward ``route[1]``, metres.
        grid: resolution of the wall computation, metres.
        description: free text.
    """

    # the name and description change nothing the robot drives (map_digest leaves them out):
    # a session resumes on the same map under another name (torchcbl.session.COMPARE_ON_RESUME,
    # spelled out: importing it would import torch; tests/test_resume_checks.py checks the two)
    name: str = field(metadata={"torchcbl.compare_on_resume": False})
    corridor_width: float
    nodes: Mapping[str, tuple[float, float]]
    corridors: tuple[tuple[str, str], ...]
    route: tuple[str, ...]
    start_offset: float = 0.2
    grid: float = 0.1
    description: str = field(default="", metadata={"torchcbl.compare_on_resume": False})
    # init=False: dataclasses.replace(m, route=...) builds a fresh, empty cache instead of
    # sharing (and silently reusing) the original map's walls and route.
    _cache: dict[str, Any] = field(
        default_factory=dict, init=False, repr=False, compare=False, hash=False
    )

    def __post_init__(self) -> None:
        # a map built in Python is held to what a map file is (map_from_dict): plain floats
        # (numpy numbers made to_dict() fail in json.dumps), its own copy of the nodes (one the
        # caller moved afterwards moved the map's, past these checks), and a named ValueError
        # for a slip (not a TypeError from deep inside)
        for key in ("corridor_width", "grid", "start_offset"):
            object.__setattr__(self, key, _metres(getattr(self, key), key))
        if not isinstance(self.nodes, Mapping):
            raise ValueError(
                f'map "nodes": expected a mapping {{name: (x, y)}} of metres, got '
                f"{self.nodes!r:.80}"
            )
        # node names as str, as a file has them (JSON keys are str): a map of int names wrote a
        # file that read back as another map, with another digest
        nodes = {str(k): _pair(v, f"node {k!r}", _metres) for k, v in self.nodes.items()}
        object.__setattr__(self, "nodes", nodes)
        corridors = tuple(_pair(c, "corridor", str) for c in _names(self.corridors, "corridors"))
        object.__setattr__(self, "corridors", corridors)
        object.__setattr__(self, "route", tuple(str(n) for n in _names(self.route, "route")))
        object.__setattr__(self, "name", str(self.name))
        object.__setattr__(self, "description", str(self.description or ""))
        if not (math.isfinite(self.corridor_width) and self.corridor_width > 0):
            raise ValueError(
                f"corridor_width must be a finite width > 0 m, got {self.corridor_width}"
            )
        if not (math.isfinite(self.grid) and self.grid > 0):
            raise ValueError(f"grid must be a finite step > 0 m, got {self.grid}")
        if not _on_grid(self.corridor_width / 2, self.grid):
            raise ValueError(
                f"half the corridor width ({self.corridor_width / 2}) must be a multiple of "
                f"grid={self.grid}"
            )
        for name, xy in self.nodes.items():
            if len(xy) != 2 or not all(_on_grid(float(v), self.grid) for v in xy):
                raise ValueError(f"node {name!r} at {xy} is not a point on the {self.grid} grid")
        pairs = set()
        for a, b in self.corridors:
            for n in (a, b):
                if n not in self.nodes:
                    raise ValueError(
                        f"corridor ({a!r}, {b!r}) names unknown node {n!r}; "
                        f"{_known_nodes(self.nodes, n)}"
                    )
            (ax, ay), (bx, by) = self.nodes[a], self.nodes[b]
            if (abs(ax - bx) > _EPS) == (abs(ay - by) > _EPS):
                raise ValueError(f"corridor ({a!r}, {b!r}) must be axis-aligned and non-empty")
            pairs.add((a, b))
            pairs.add((b, a))
        if len(self.route) < 4 or self.route[0] != self.route[-1]:
            raise ValueError(
                "route must be a closed walk of at least 3 nodes, its first node repeated at "
                f"the end (e.g. [A, B, C, A]), got {list(self.route)}"
            )
        for n in self.route:  # (else "route step 'B' -> 'X' is not a corridor")
            if n not in self.nodes:
                raise ValueError(f"route names unknown node {n!r}; {_known_nodes(self.nodes, n)}")
        for a, b in zip(self.route[:-1], self.route[1:], strict=True):
            if (a, b) not in pairs:
                raise ValueError(f"route step {a!r} -> {b!r} is not a corridor")
        first = np.subtract(self.nodes[self.route[1]], self.nodes[self.route[0]])
        length = float(np.linalg.norm(first))
        if not 0 < self.start_offset < length:
            raise ValueError(
                f"start_offset must lie inside the route's first corridor, "
                f"{self.route[0]!r} -> {self.route[1]!r}: in (0, {length:g}) m, got "
                f"{self.start_offset!r}"
            )

    # ------------------------------------------------------------------ geometry
    def free_cells(self) -> tuple[np.ndarray, tuple[int, int]]:
        """Boolean occupancy grid of free space ``[nx, ny]`` and ``(i0, j0)``, the global grid
        index of cell ``[0, 0]`` (its lower-left corner is at ``(i0 * grid, j0 * grid)`` m)."""
        if "cells" not in self._cache:
            h = self.corridor_width / 2
            rects = []
            for a, b in self.corridors:
                (ax, ay), (bx, by) = self.nodes[a], self.nodes[b]
                rects.append((min(ax, bx) - h, min(ay, by) - h, max(ax, bx) + h, max(ay, by) + h))
            g = self.grid
            idx = np.rint(np.asarray(rects) / g).astype(int)
            i0, j0 = idx[:, 0].min(), idx[:, 1].min()
            cells = np.zeros((idx[:, 2].max() - i0, idx[:, 3].max() - j0), dtype=bool)
            for x0, y0, x1, y1 in idx:
                cells[x0 - i0 : x1 - i0, y0 - j0 : y1 - j0] = True
            self._cache["cells"] = (cells, (int(i0), int(j0)))
        return self._cache["cells"]

    def walls(self) -> list[tuple[tuple[float, float], tuple[float, float]]]:
        """Wall segments ``((x0, y0), (x1, y1))`` in metres: the boundary of the free space,
        collinear pieces merged."""
        if "walls" in self._cache:
            return self._cache["walls"]
        cells, (i0, j0) = self.free_cells()
        padded = np.pad(cells, 1)
        g = self.grid
        segs: list[tuple[tuple[float, float], tuple[float, float]]] = []
        # Vertical edges: between column i-1 and i (padded coordinates).
        diff_x = padded[1:, :] != padded[:-1, :]  # [nx+1, ny+2]
        for i in range(diff_x.shape[0]):
            for start, stop in _runs(diff_x[i, 1:-1]):
                x = round((i + i0) * g, 9)
                y0, y1 = round((start + j0) * g, 9), round((stop + j0) * g, 9)
                segs.append(((x, y0), (x, y1)))
        diff_y = padded[:, 1:] != padded[:, :-1]  # [nx+2, ny+1]
        for j in range(diff_y.shape[1]):
            for start, stop in _runs(diff_y[1:-1, j]):
                y = round((j + j0) * g, 9)
                x0, x1 = round((start + i0) * g, 9), round((stop + i0) * g, 9)
                segs.append(((x0, y), (x1, y)))
        self._cache["walls"] = segs
        return segs

    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of the free space, metres."""
        cells, (i0, j0) = self.free_cells()
        g = self.grid
        nx, ny = cells.shape
        return (
            round(i0 * g, 9),
            round(j0 * g, 9),
            round((i0 + nx) * g, 9),
            round((j0 + ny) * g, 9),
        )

    def is_free(self, x: float, y: float) -> bool:
        """Whether the point (x, y) (metres) lies inside the free space."""
        cells, (i0, j0) = self.free_cells()
        i, j = math.floor(x / self.grid) - i0, math.floor(y / self.grid) - j0
        return 0 <= i < cells.shape[0] and 0 <= j < cells.shape[1] and bool(cells[i, j])

    def start_pose(self) -> tuple[float, float, float]:
        """``(x, y, heading)`` of the start: metres, radians."""
        p0 = np.asarray(self.nodes[self.route[0]], dtype=float)
        p1 = np.asarray(self.nodes[self.route[1]], dtype=float)
        d = (p1 - p0) / np.linalg.norm(p1 - p0)
        x, y = p0 + self.start_offset * d
        return (float(x), float(y), float(math.atan2(d[1], d[0])))

    def manoeuvres(self) -> list[str]:
        """The manoeuvre at each route node ``route[1:]`` ('straight', 'left', 'right', 'uturn');
        the last entry is the one at ``route[0]`` that closes the circuit."""
        pts = [np.asarray(self.nodes[n], dtype=float) for n in self.route]
        pts.append(pts[1])
        out = []
        for k in range(1, len(pts) - 1):
            d_in, d_out = pts[k] - pts[k - 1], pts[k + 1] - pts[k]
            cross = d_in[0] * d_out[1] - d_in[1] * d_out[0]
            dot = float(np.dot(d_in, d_out))
            if abs(cross) < _EPS:
                out.append(STRAIGHT if dot > 0 else UTURN)
            else:
                out.append(LEFT if cross > 0 else RIGHT)
        return out

    def route_polyline(self) -> Route:
        """The route as a :class:`Route` from the start point round to the start point."""
        if "route" not in self._cache:
            sx, sy, _ = self.start_pose()
            pts = [(sx, sy)]
            pts += [tuple(map(float, self.nodes[n])) for n in self.route[1:]]
            pts.append((sx, sy))
            kinds = [*self.manoeuvres(), STRAIGHT]
            # kinds[k] is the manoeuvre at the END of segment k (the start point: straight).
            self._cache["route"] = Route(np.asarray(pts, dtype=float), tuple(kinds))
        return self._cache["route"]

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready form :func:`map_from_dict` reads back."""
        return {
            "name": self.name,
            "description": self.description,
            "corridor_width": self.corridor_width,
            "grid": self.grid,
            "start_offset": self.start_offset,
            "nodes": {k: list(v) for k, v in self.nodes.items()},
            "corridors": [list(c) for c in self.corridors],
            "route": list(self.route),
        }


def map_digest(corridor_map: CorridorMap) -> str:
    """The SHA-256 (hex) of what a map makes the robot drive: its corridors, their width, the
    route and the start (:meth:`CorridorMap.to_dict` less ``name`` and ``description``, as
    canonical JSON). The same map from a JSON file, a shipped name or a ``CorridorMap`` gives
    the same digest; an edit that moves a wall or the route gives another."""
    data = corridor_map.to_dict()
    del data["name"], data["description"]
    text = json.dumps(_floats(data), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def _floats(value: Any) -> Any:
    """``value`` with every number a float (a map's 2 and 2.0 are one coordinate, and a map
    file gives 2.0), for :func:`map_digest`."""
    if isinstance(value, dict):
        return {str(k): _floats(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_floats(v) for v in value]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number)):
        return value
    return float(value)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs of True in a 1-D boolean array as (start, stop)."""
    out = []
    start = None
    for k, v in enumerate(mask):
        if v and start is None:
            start = k
        elif not v and start is not None:
            out.append((start, k))
            start = None
    if start is not None:
        out.append((start, len(mask)))
    return out


@dataclass(frozen=True)
class RouteProgress:
    """Where a pose lies on a route: unwrapped arc length (metres), segment index, the offset
    from the segment's line (metres) and the distance left to the segment's end (metres)."""

    s: float
    segment: int
    lateral: float
    remaining: float


@dataclass(frozen=True, eq=False)
class Route:
    """A closed polyline: ``points [K+1, 2]`` metres (first == last), ``kinds[k]`` the manoeuvre
    at the end of segment ``k``."""

    points: np.ndarray
    kinds: tuple[str, ...]

    def __post_init__(self) -> None:
        seg = np.diff(self.points, axis=0)
        lengths = np.linalg.norm(seg, axis=1)
        object.__setattr__(self, "_dirs", seg / lengths[:, None])
        object.__setattr__(self, "_lengths", lengths)
        object.__setattr__(self, "_cum", np.concatenate([[0.0], np.cumsum(lengths)]))
        # the segments that end in a u-turn (the end of a dead-end spur, or wherever the route
        # comes back the way it went)
        object.__setattr__(
            self, "_uturns", tuple(k for k, kind in enumerate(self.kinds) if kind == UTURN)
        )

    @property
    def length(self) -> float:
        """Total length of one circuit, metres."""
        return float(self._cum[-1])

    @property
    def segment_starts(self) -> np.ndarray:
        """``[K+1]`` metres: the arc length at which each segment starts (the last entry is the
        circuit's length)."""
        return self._cum

    @property
    def segment_lengths(self) -> np.ndarray:
        """``[K]`` metres."""
        return self._lengths

    def segment_direction(self, k: int) -> np.ndarray:
        """Unit vector ``[2]`` of segment ``k``."""
        return self._dirs[k]

    def locate(
        self,
        x: float,
        y: float,
        heading: float,
        s_prev: float,
        *,
        back: float = 0.5,
        ahead: float = 1.0,
        heading_weight: float = 0.3,
        max_offset: float = math.inf,
    ) -> RouteProgress:
        """Project a pose on the route near the previous unwrapped arc length ``s_prev``.

        Candidates are the nearest points of every segment whose arc length, unwrapped to lie in
        ``[s_prev - back, s_prev + ahead]`` (the world scales both up where the corridor's
        width plus the robot's longest action, a turn's 2 x 0.2 m by default, exceeds 1 m), is
        reachable, and which lie within ``max_offset``
        metres of the pose (the world passes the corridor width: a corridor the route does not
        take, e.g. one parallel to it, is not the route); among them the one minimising
        distance + ``heading_weight`` * (1 - cos(heading error)) wins, so a spur driven in and
        out is told apart by the heading. The progress passes a u-turn (from before its node to
        after it) only onto the way back, and onto the way back's last ``max_offset / 2``
        metres (the junction it ends in: half the corridor's width as the world calls it) only
        heading along it, within 60 degrees: at a short spur (out and back within ``ahead``) a
        robot that turned away at the spur's junction, never driving in, stood within the
        window of the way back and of the corridor after it, and was credited with the spur.
        With no candidate, the progress stays.
        """
        p = np.array([x, y])
        hd = np.array([math.cos(heading), math.sin(heading)])
        length = self.length
        best: tuple[float, float, int, float, float] | None = None
        rel = p - self.points[:-1]
        t = np.clip(np.einsum("kd,kd->k", rel, self._dirs), 0.0, self._lengths)
        for k in range(len(self._lengths)):
            q = self.points[k] + t[k] * self._dirs[k]
            s_loc = self._cum[k] + t[k]
            lap = math.floor((s_prev - back - s_loc) / length) + 1
            s_abs = s_loc + lap * length
            if s_abs > s_prev + ahead + _EPS:
                continue
            dist = float(np.linalg.norm(p - q))
            if dist > max_offset:
                continue
            if self._uturns and self._skips_uturn(k, s_prev, s_abs, hd, 0.5 * max_offset):
                continue
            cost = dist + heading_weight * (1.0 - float(np.dot(hd, self._dirs[k])))
            if best is None or cost < best[0] - _EPS:
                dk, rk = self._dirs[k], rel[k]
                lateral = abs(float(dk[0] * rk[1] - dk[1] * rk[0]))
                best = (cost, s_abs, k, lateral, float(self._lengths[k] - t[k]))
        if best is None:
            k = int(np.searchsorted(self._cum, s_prev % length, side="right") - 1)
            k = min(max(k, 0), len(self._lengths) - 1)
            return RouteProgress(s_prev, k, math.inf, math.inf)
        return RouteProgress(best[1], best[2], best[3], best[4])

    def _skips_uturn(
        self, k: int, s_prev: float, s_abs: float, hd: np.ndarray, junction: float
    ) -> bool:
        """Whether a candidate on segment ``k`` at unwrapped arc length ``s_abs`` passes a
        u-turn ahead of ``s_prev`` other than onto its way back (segment ``k`` must be the one
        after the u-turn, in the same lap), or onto the way back's last ``junction`` metres (the
        junction it ends in) with the heading ``hd`` (unit vector) not along it, within 60
        degrees."""
        length = self.length
        for ku in self._uturns:
            u = float(self._cum[ku + 1])
            # the u-turn's first unwrapped arc length after s_prev (a progress standing at the
            # node has passed it: the way back starts there)
            u_abs = u + math.ceil((s_prev + _EPS - u) / length) * length
            if not u_abs < s_abs - _EPS:
                continue  # the candidate does not lie beyond this u-turn
            back = (ku + 1) % len(self._lengths)
            end = u_abs + float(self._lengths[back])
            if k != back or s_abs > end + _EPS:
                return True
            if end - s_abs < junction and float(np.dot(hd, self._dirs[back])) < 0.5:
                return True
        return False


def map_from_dict(data: Mapping[str, Any]) -> CorridorMap:
    """Build a :class:`CorridorMap` from the JSON form (see the module docstring)."""
    allowed = {
        "name",
        "description",
        "corridor_width",
        "grid",
        "start_offset",
        "nodes",
        "corridors",
        "route",
    }
    if not isinstance(data, Mapping):
        raise ValueError(
            f"a map is a JSON object (a dict) of keys {sorted(allowed)}, got {data!r:.80}"
        )
    unknown = set(data) - allowed
    if unknown:
        raise ValueError(f"unknown map keys {sorted(unknown)}; allowed: {sorted(allowed)}")
    missing = {"name", "corridor_width", "nodes", "corridors", "route"} - set(data)
    if missing:
        raise ValueError(f"map is missing keys {sorted(missing)}")
    if not isinstance(data["nodes"], Mapping):
        raise ValueError(
            f'map "nodes": expected an object {{"name": [x, y], ...}}, got {data["nodes"]!r:.80}'
        )
    nodes = {str(k): _pair(v, f"node {k!r}", _metres) for k, v in data["nodes"].items()}
    corridors = tuple(_pair(c, "corridor", str) for c in _names(data["corridors"], "corridors"))
    kwargs: dict[str, Any] = {
        "name": str(data["name"]),
        "corridor_width": _metres(data["corridor_width"], "corridor_width"),
        "nodes": nodes,
        "corridors": corridors,
        "route": tuple(str(n) for n in _names(data["route"], "route")),
        "description": data.get("description") or "",  # (str in CorridorMap; null is "")
    }
    for key in ("grid", "start_offset"):
        if key in data:
            kwargs[key] = _metres(data[key], key)
    return CorridorMap(**kwargs)


def _metres(value: Any, what: str = "coordinate") -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"map {what}: expected a number of metres, got {value!r:.80}")
    return float(value)


def _known_nodes(nodes: Mapping[str, Any], unknown: str) -> str:
    """What to say of a node name ``unknown`` that ``nodes`` lacks: the names it has (the first
    20 of a larger map) and what to do."""
    names = list(nodes)
    shown = ", ".join(names[:20]) + (f", ... ({len(names)} in all)" if len(names) > 20 else "")
    return (
        f'the map\'s nodes are {shown or "none"}: add {unknown!r} to "nodes" or name one of these'
    )


def _names(value: Any, key: str) -> list[Any]:
    """A map's list (``corridors``, ``route``), refused if it is not a list."""
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, (list, tuple)):
        raise ValueError(f'map "{key}": expected a list, got {value!r:.80}')
    return list(value)


def _pair(value: Any, what: str, convert: Any) -> tuple[Any, Any]:
    """Two items (a node's [x, y], a corridor's [a, b]; a 1-D numpy array too), each
    converted."""
    listed = isinstance(value, (list, tuple)) or isinstance(value, np.ndarray) and value.ndim == 1
    if isinstance(value, (str, bytes, Mapping)) or not listed:
        raise ValueError(f"map {what}: expected a list of 2, got {value!r:.80}")
    if len(value) != 2:
        raise ValueError(f"map {what}: expected a list of 2, got {len(value)} items {value!r:.80}")
    if convert is _metres:
        return (_metres(value[0], what), _metres(value[1], what))
    return (convert(value[0]), convert(value[1]))


def available_maps() -> list[str]:
    """Names of the maps shipped in ``corridor/maps/``."""
    folder = resources.files("corridor") / "maps"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".json"))


def _read_map_file(path: Path) -> str:
    """A map file's text (UTF-8, as JSON is); a ValueError naming the file if it is not text
    (e.g. a PNG of the map given for its JSON) or cannot be read."""
    return _jsonfile.read_text(
        path,
        not_text=lambda why: (
            f"map file {str(path)!r} is not a map JSON file (not UTF-8 text: {why}); give the "
            "JSON file of the map (see corridor.maps)"
        ),
        unreadable=lambda why: (
            f"map file {str(path)!r} cannot be read ({why}); give a map JSON file this user "
            "can read"
        ),
    )


def load_map(name_or_path: str | os.PathLike[str]) -> CorridorMap:
    """Load a shipped map by name (``"figure2"``, ``"lshape"``) or any map JSON file by path
    (a name ending in ``.json``, in any case, is a path; so is any other existing file, unless
    it is a shipped map's bare name: ``"figure2"`` is the shipped map, ``"./figure2"`` the
    file)."""
    path = Path(name_or_path)
    shipped = str(name_or_path) in available_maps()  # a bare shipped name, never a path
    res = resources.files("corridor") / "maps" / f"{name_or_path}.json"
    if path.suffix.lower() == ".json":  # a file path (mine.json, MINE.JSON)
        if not path.is_file():
            raise ValueError(
                f"map file {str(path)!r} not found; give an existing map JSON file or one of the "
                f"shipped map names {available_maps()}"
            )
        text = _read_map_file(path)
    elif shipped:
        text = res.read_text(encoding="utf-8")
    elif path.is_file():  # a map file named otherwise (mymap.txt, a temporary file)
        text = _read_map_file(path)
    else:
        raise ValueError(
            f"unknown map {str(name_or_path)!r}; shipped maps: {available_maps()}, or the path "
            "of a map JSON file"
        )
    data = _jsonfile.loads(
        text,
        not_json=lambda why: (
            f"map {str(name_or_path)!r} is not valid JSON: {why}; fix the file, or give one of "
            f"the shipped map names {available_maps()}"
        ),
        given_twice=lambda key: (
            f"map {str(name_or_path)!r}: the key {key!r} is given twice in one object (a map "
            "key or a node name written twice; JSON would keep the last silently); give each "
            "once"
        ),
    )
    return map_from_dict(data)
