"""Pictures of work and protection areas with a programmed path (``hli-server check --plot``, FCT-C14).

Matplotlib without pyplot (no global state, no display): a :class:`~matplotlib.figure.Figure` is drawn
and written as SVG or PNG, chosen by the file's suffix. The engine itself does no I/O; this module
only reads the JSON area table that ``channel_areas(machine, n).to_json()`` / ``check`` produce.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure
from matplotlib.patches import Circle as CirclePatch
from matplotlib.patches import Polygon as PolygonPatch

__all__ = ["plot_areas"]

_WORK = "#2e8b57"  # green: the allowed space
_PROT = "#c0392b"  # red: never to be touched
_PATH = "#1f4e9c"
_STOP = "#d35400"


def _area_list(areas: Mapping[str, Any] | Iterable[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    if isinstance(areas, Mapping):
        return list(areas.get("areas", []))
    return list(areas)


def plot_areas(
    areas_json: Mapping[str, Any] | Iterable[Mapping[str, Any]],
    path_points: Sequence[Sequence[float]],
    stop_point: Sequence[float] | None,
    out_path: str | Path,
    *,
    axes: tuple[str, str] | None = None,
    title: str | None = None,
) -> Path:
    """Draw the base plane: areas (work green, protection red hatched; inactive ones dashed), the
    path (``path_points`` in the plane's two coordinates) and where it stopped.

    ``areas_json`` is the ``"areas"`` list (or the whole table with it). ``axes`` chooses the plane;
    by default the plane most areas share (X/Y when there are none). Areas of other planes (additional
    axes, other G17/G18/G19 planes) are left out and named in the title. Returns the written path."""
    out = Path(out_path)
    suffix = out.suffix.lower()
    if suffix not in (".svg", ".png"):
        raise ValueError(f"plot file must end in .svg or .png, got {out.name!r}")
    entries = _area_list(areas_json)
    if axes is None:
        planes = Counter(tuple(e.get("axes", ("X", "Y"))) for e in entries)
        axes = planes.most_common(1)[0][0] if planes else ("X", "Y")
    assert axes is not None
    fig = Figure(figsize=(8, 7), dpi=100)
    ax = fig.add_subplot(1, 1, 1)
    skipped: list[str] = []
    for e in entries:
        if tuple(e.get("axes", ("X", "Y"))) != tuple(axes):
            skipped.append(f"ID{e.get('id')} ({'/'.join(e.get('axes', []))})")
            continue
        protection = e.get("kind") == "PROT"
        active = e.get("state") == "active"
        colour = _PROT if protection else _WORK
        style: dict[str, Any] = {
            "facecolor": colour,
            "edgecolor": colour,
            "alpha": 0.25 if active else 0.08,
            "linewidth": 1.5,
            "linestyle": "-" if active else "--",
            "hatch": "//" if protection else None,
        }
        label = f"ID{e.get('id')} {e.get('kind')} {e.get('state')} [{e.get('min')}, {e.get('max')}]"
        if e.get("shape") == "CIRC":
            cx, cy = e["center"]
            patch: CirclePatch | PolygonPatch = CirclePatch((cx, cy), e["radius"], label=label, **style)
            anchor = (cx, cy)
        else:
            pts = [tuple(p) for p in e["points"]]
            patch = PolygonPatch(pts, closed=True, label=label, **style)
            anchor = (pts[0][0], pts[0][1])  # the first corner: the centroid of a U lies outside it
        ax.add_patch(patch)
        # the outline fully opaque, the fill translucent
        outline = (
            CirclePatch((e["center"][0], e["center"][1]), e["radius"], fill=False)
            if e.get("shape") == "CIRC"
            else PolygonPatch([tuple(p) for p in e["points"]], closed=True, fill=False)
        )
        outline.set_edgecolor(colour)
        outline.set_linewidth(1.5)
        outline.set_linestyle("-" if active else "--")
        ax.add_patch(outline)
        ax.annotate(
            f"ID{e.get('id')}",
            anchor,
            xytext=(4, 4),
            textcoords="offset points",
            color=colour,
            fontsize=9,
        )
    if path_points:
        xs = [p[0] for p in path_points]
        ys = [p[1] for p in path_points]
        ax.plot(xs, ys, color=_PATH, linewidth=1.2, label="programmed path")
        ax.plot(xs[:1], ys[:1], marker="o", color=_PATH, linestyle="none", label="start")
    if stop_point is not None:
        ax.plot(
            [stop_point[0]],
            [stop_point[1]],
            marker="X",
            markersize=11,
            color=_STOP,
            linestyle="none",
            label=f"stopped at ({stop_point[0]:.3f}, {stop_point[1]:.3f})",
        )
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel(f"{axes[0]} [mm]")
    ax.set_ylabel(f"{axes[1]} [mm]")
    ax.grid(True, linewidth=0.3)
    heading = title or f"work (green) and protection (red) areas, plane {axes[0]}/{axes[1]}"
    if skipped:
        heading += "\nnot in this plane: " + ", ".join(skipped)
    ax.set_title(heading, fontsize=10)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize=8)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(str(out), format=suffix[1:], bbox_inches="tight")
    return out
