"""Top-down drawings of the driving scene with matplotlib (an Agg canvas; no display needed).

:func:`render_frame` draws the road around the ego (five lanes, shoulders shaded, traffic cars,
the ego in red, a car in contact with the ego outlined in orange) into an RGB array
[H, W, 3] uint8.
"""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from sumo_scenarios.scenarios import CAR_LENGTH_M, N_LANES, _is_real
from torchcbl.evaluation import figure_style

LANE_WIDTH_M = 3.2
_CAR_WIDTH_M = 1.8


@figure_style()
def render_frame(
    frame: object, *, behind_m: float = 30.0, ahead_m: float = 60.0, dpi: int = 80
) -> np.ndarray:
    """Draw one :class:`~sumo_scenarios.env.Frame` and return RGB uint8 [H, W, 3].

    ``behind_m`` / ``ahead_m`` set the visible stretch of road around the ego (metres).
    """
    for name, value in (("behind_m", behind_m), ("ahead_m", ahead_m), ("dpi", dpi)):
        if not _is_real(value) or not 0 < value < float("inf"):
            raise ValueError(f"{name} must be a number > 0, got {value!r}")
    ego_pos = float(frame.ego_pos)  # type: ignore[attr-defined]
    # A bare Figure on an Agg canvas: no pyplot, so the caller's backend is left alone.
    fig = Figure(figsize=(8, 2.2), dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.set_xlim(-behind_m, ahead_m)
    ax.set_ylim(0, N_LANES * LANE_WIDTH_M)
    ax.set_aspect("auto")
    for lane in range(N_LANES):
        shade = "#c8c8c8" if lane in (0, N_LANES - 1) else "#8c8c8c"
        ax.add_patch(
            Rectangle(
                (-behind_m, lane * LANE_WIDTH_M),
                behind_m + ahead_m,
                LANE_WIDTH_M,
                color=shade,
                zorder=0,
            )
        )
        if lane:
            ax.axhline(lane * LANE_WIDTH_M, color="white", lw=1, ls="--", zorder=1)
    contact = bool(frame.contact)  # type: ignore[attr-defined]
    rel = np.asarray(frame.car_pos) - ego_pos  # type: ignore[attr-defined]
    # the cars the contact is with: within a car length, in the ego's lane or the one it left
    # (the simulator's own test)
    ego_lane = int(frame.ego_lane)  # type: ignore[attr-defined]
    prev_lane = getattr(frame, "prev_lane", None)
    contact_lanes = {ego_lane} if prev_lane is None else {ego_lane, int(prev_lane)}
    for r, lane in zip(rel, np.asarray(frame.car_lane), strict=True):  # type: ignore[attr-defined]
        if -behind_m - CAR_LENGTH_M < r < ahead_m + CAR_LENGTH_M:
            touching = contact and abs(r) < CAR_LENGTH_M and int(lane) in contact_lanes
            _car(
                ax,
                r,
                int(lane),
                "#3a5fcd",
                "orange" if touching else "black",
                3 if touching else 0.5,
            )
    _car(
        ax,
        0.0,
        int(frame.ego_lane),
        "#d62728",
        "orange" if contact else "black",  # type: ignore[attr-defined]
        3 if contact else 0.5,
    )
    action = frame.action  # type: ignore[attr-defined]
    names = ("stay", "left", "right")
    label = f"t={frame.step}  lane={frame.ego_lane}"  # type: ignore[attr-defined]
    if action is not None:
        label += f"  action={names[int(action)]}"
    if contact:
        label += "  CONTACT"
    ax.set_title(label, fontsize=9)
    ax.set_yticks([(k + 0.5) * LANE_WIDTH_M for k in range(N_LANES)])
    ax.set_yticklabels(["R sh", "R", "M", "L", "L sh"], fontsize=7)
    ax.set_xlabel("metres relative to the ego", fontsize=8)
    ax.tick_params(axis="x", labelsize=7)
    fig.tight_layout()
    canvas.draw()
    rgb = np.asarray(canvas.buffer_rgba())[..., :3].copy()
    return rgb


def _car(ax: Axes, rel_front: float, lane: int, color: str, edge: str, lw: float) -> None:
    y = lane * LANE_WIDTH_M + (LANE_WIDTH_M - _CAR_WIDTH_M) / 2
    ax.add_patch(
        Rectangle(
            (rel_front - CAR_LENGTH_M, y),
            CAR_LENGTH_M,
            _CAR_WIDTH_M,
            facecolor=color,
            edgecolor=edge,
            lw=lw,
            zorder=3,
        )
    )
