"""Drawing the corridor world with matplotlib: map, route, robot, sensor rays, path.

Nothing here simulates; the functions read a :class:`corridor.world.CorridorWorld` or a
:class:`corridor.maps.CorridorMap`. :func:`render_rgb` returns an RGB array (what
``CorridorEnv.render`` returns); :func:`save_png` writes one (used by experiments, never by envs).
Figures are built with :class:`matplotlib.figure.Figure` and drawn on an Agg canvas, never through
pyplot, so importing this module leaves the caller's matplotlib backend alone (a notebook keeps
its inline plots).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.image import imsave
from matplotlib.patches import Circle

from corridor.maps import CorridorMap
from corridor.world import SENSOR_NAMES, CorridorWorld
from torchcbl.evaluation import figure_style, save_whole

__all__ = [
    "ACTION_COLORS",
    "PATH_COLOR",
    "RAY_COLOR",
    "draw_map",
    "draw_robot",
    "map_figure",
    "render_rgb",
    "save_png",
]

#: One colour per action (index = :class:`corridor.world.Action`), used by every corridor figure:
#: forward, turn left, turn right, u-turn. They are matplotlib's first four default colours, so
#: a plain ``ax.scatter`` per action in action order matches them too.
ACTION_COLORS: tuple[str, str, str, str] = ("tab:blue", "tab:orange", "tab:green", "tab:red")
#: The sensor rays on the map (no action's colour).
RAY_COLOR = "tab:purple"
#: The robot's path on the map (no action's colour).
PATH_COLOR = "tab:brown"

_ANGLES = (math.pi / 2, 0.0, -math.pi / 2)
_RAY_STYLES = {"left": (0, (4, 2)), "front": "-", "right": (0, (1, 1.5))}


def draw_map(ax: Axes, corridor_map: CorridorMap, *, route: bool = True) -> None:
    """Draw the free space, the walls and (optionally) the target route on ``ax`` (metres)."""
    cells, (i0, j0) = corridor_map.free_cells()
    g = corridor_map.grid
    xmin, ymin, xmax, ymax = corridor_map.bounds()
    ax.imshow(
        np.where(cells.T, 1.0, 0.55),
        origin="lower",
        extent=(xmin, xmax, ymin, ymax),
        cmap="gray",
        vmin=0,
        vmax=1,
        interpolation="nearest",
    )
    for (x0, y0), (x1, y1) in corridor_map.walls():
        ax.plot([x0, x1], [y0, y1], color="black", linewidth=2)
    if route:
        pts = corridor_map.route_polyline().points
        ax.plot(
            pts[:, 0],
            pts[:, 1],
            color="black",
            linewidth=1,
            linestyle=":",
            label="target route (dotted)",
        )
    ax.set_xlim(xmin - g, xmax + g)
    ax.set_ylim(ymin - g, ymax + g)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def draw_robot(
    ax: Axes,
    world: CorridorWorld,
    readings: Sequence[float] | None = None,
) -> None:
    """Draw the robot (grey circle, black heading tick) and its three sensor rays in
    ``RAY_COLOR``, each as long as its reading (``readings`` in metres, default: the noise-free
    ranges): left dashed, front solid, right dotted. Each ray is labelled for a legend."""
    x, y, h = world.pose
    r = world.config.robot_radius
    ax.add_patch(Circle((x, y), r, facecolor="0.75", edgecolor="black", alpha=0.9, label="robot"))
    ax.plot([x, x + r * math.cos(h)], [y, y + r * math.sin(h)], color="black", linewidth=2)
    ranges = world.true_ranges() if readings is None else np.asarray(readings, dtype=float)
    if ranges.shape != (len(SENSOR_NAMES),):
        raise ValueError(
            f"readings: expected {len(SENSOR_NAMES)} ranges in metres "
            f"({', '.join(SENSOR_NAMES)}), got shape {ranges.shape}; pass the env's observation "
            "(or leave readings out for the noise-free ranges)"
        )
    for name, offset, d in zip(SENSOR_NAMES, _ANGLES, ranges, strict=True):
        a = h + offset
        ax.plot(
            [x, x + d * math.cos(a)],
            [y, y + d * math.sin(a)],
            color=RAY_COLOR,
            linestyle=_RAY_STYLES[name],
            linewidth=1.2,
            label=f"{name} sensor ray (to the reading)",
        )


def map_figure(
    world: CorridorWorld,
    path: Sequence[tuple[float, float]] | None = None,
    readings: Sequence[float] | None = None,
    *,
    title: str | None = None,
    size: float = 5.0,
) -> Figure:
    """A figure of the map, route, path so far (metres) and robot with its rays, with a legend
    saying what each line is."""
    fig = Figure(figsize=(size, size * 1.2), dpi=80)
    ax = fig.add_subplot()
    draw_map(ax, world.map)
    if path is not None and len(path) > 1:
        p = np.asarray(path, dtype=float)
        ax.plot(
            p[:, 0],
            p[:, 1],
            color=PATH_COLOR,
            linewidth=1,
            marker=".",
            markersize=3,
            label="robot path (a dot per action)",
        )
    draw_robot(ax, world, readings)
    ax.set_title(title or world.map.name)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2, fontsize=7, frameon=False)
    fig.tight_layout()
    return fig


@figure_style()
def render_rgb(
    world: CorridorWorld,
    path: Sequence[tuple[float, float]] | None = None,
    readings: Sequence[float] | None = None,
) -> np.ndarray:
    """The :func:`map_figure` as an RGB array ``[H, W, 3]`` uint8."""
    fig = map_figure(world, path, readings)
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def save_png(fig_or_rgb: Figure | np.ndarray, path: str | Path) -> Path:
    """Write a figure or an RGB array to a PNG file, whole or not at all (a temporary file
    renamed over ``path``: :func:`torchcbl.evaluation.save_whole`); returns the path."""
    if isinstance(fig_or_rgb, Figure):
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        FigureCanvasAgg(fig_or_rgb)
        return save_whole(path, fig_or_rgb.savefig)
    rgb = np.asarray(fig_or_rgb)
    return save_whole(path, lambda fname, **kwargs: imsave(fname, rgb, **kwargs))
