"""Pictures of a channel's areas and path (``hli-server check --plot``, FCT-C14): the scene, drawn.

The geometry is not done here: :mod:`hli_server.scene` computes the scene (areas, how the path meets
each, the path with its height, the refused block, the violation and the stop point) and this module
only draws it, so the picture and the dashboard, which draws the same scene JSON in the browser, show
the same thing.

Two panels, because height is what a projection hides (docs/dashboard.md: a path 100 mm above a protection
cylinder looked as if it went through it):

* top view: the base plane with the areas (work green, protection red and hatched, inactive dashed),
  each styled by how the path meets it (through it: strong fill and a thick edge; only above or below
  it: an empty outline with a dotted fill; never over it: a light fill), the path coloured by its
  height (colour bar), the refused block (red, dashed), the exact violation point and the stop point;
* side view: the height over the path length in the base plane (the footprint unrolled), with the
  height band of every area drawn over the stretches where the path is over its base region. Above,
  below or through a band reads off directly, which colour alone cannot show exactly.

Colour by height alone would need the reader to compare a colour with the band's numbers; a side view
alone would lose where in the plane things happen. Both together answer both questions.

Matplotlib without pyplot (no global state, no display): a :class:`~matplotlib.figure.Figure` is drawn
and written in any format matplotlib writes, chosen by the file's suffix. :func:`check_plot_target`
refuses a format or a place that cannot work before a long check runs.
"""

from __future__ import annotations

import io
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from matplotlib.backend_bases import FigureCanvasBase
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Circle as CirclePatch
from matplotlib.patches import Polygon as PolygonPatch
from matplotlib.patches import Rectangle

from hli_server.scene import relation_text

__all__ = ["PlotTargetError", "check_plot_target", "plot_scene", "supported_formats"]

_WORK = "#2e8b57"  # green: the allowed space
_PROT = "#c0392b"  # red: never to be touched
_PATH = "#1f4e9c"
_REFUSED = "#e31a1c"
_TOOL = "#ff7f00"
"""The tool tip's path (TCP) where a kinematic transformation was on (K-06)."""
_STOP = "#d35400"


class PlotTargetError(ValueError):
    """The plot file cannot be written: unknown format, a format this installation cannot write, or a
    place that is not writable. The message says which and what to do."""


def supported_formats() -> dict[str, str]:
    """The formats matplotlib lists: suffix (without the dot) -> name."""
    return dict(FigureCanvasBase.get_supported_filetypes())


def check_plot_target(path: str | Path) -> None:
    """Raise :class:`PlotTargetError` unless a plot can be written to ``path``.

    Checked: the suffix is a format matplotlib lists, this installation writes it (a tiny figure is
    rendered in memory: ``.pgf`` needs a TeX installation, some raster formats a Pillow plugin), and the
    file can be created (the nearest existing directory is writable; an existing file is writable)."""
    out = Path(path)
    formats = supported_formats()
    suffix = out.suffix.lower().lstrip(".")
    listed = ", ".join(f".{k}" for k in sorted(formats))
    if not suffix:
        raise PlotTargetError(f"{out}: no file suffix to choose the format from; use one of {listed}")
    if suffix not in formats:
        raise PlotTargetError(f"{out}: matplotlib does not write .{suffix} files; use one of {listed}")
    probe = Figure(figsize=(1, 1), dpi=10)
    probe.add_subplot(1, 1, 1).plot([0, 1], [0, 1])
    try:
        probe.savefig(io.BytesIO(), format=suffix)
    except Exception as exc:  # whatever the backend raises: missing TeX, missing codec, ...
        raise PlotTargetError(
            f"{out}: matplotlib cannot write .{suffix} on this installation ({exc}); "
            f"use another format ({', '.join(f'.{k}' for k in sorted(formats) if k != suffix)})"
        ) from exc
    if out.exists():
        if out.is_dir():
            raise PlotTargetError(f"{out} is a directory; give a file name")
        if not os.access(out, os.W_OK):
            raise PlotTargetError(f"{out} exists and is not writable; choose another file")
        return
    parent = out.parent.resolve()
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise PlotTargetError(f"{out}: cannot create the file, {parent} is not a writable directory")


def _num(v: float) -> str:
    text = f"{v:.4f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _area_style(area: Mapping[str, Any]) -> tuple[str, dict[str, Any]]:
    protection = area.get("kind") == "PROT"
    colour = _PROT if protection else _WORK
    relation = area.get("relation", "apart")
    active = area.get("state") == "active"
    style: dict[str, Any] = {"facecolor": colour, "edgecolor": colour, "linestyle": "-" if active else "--"}
    if relation == "crosses":
        style |= {"alpha": 0.4 if active else 0.2, "linewidth": 2.5, "hatch": "//" if protection else None}
    elif relation == "apart":
        style |= {"alpha": 0.18 if active else 0.08, "linewidth": 1.2, "hatch": "//" if protection else None}
    else:  # above / below: the path is not in it; an outline with a sparse dotted fill
        style |= {"alpha": 0.35, "linewidth": 1.2, "hatch": "..", "fill": False}
    return colour, style


def _patch(area: Mapping[str, Any], **style: Any) -> CirclePatch | PolygonPatch:
    if area.get("shape") == "CIRC":
        cx, cy = area["center"]
        return CirclePatch((cx, cy), area["radius"], **style)
    return PolygonPatch([tuple(p) for p in area["points"]], closed=True, **style)


def _point_text(names: Sequence[str], point: Mapping[str, float]) -> str:
    return ", ".join(f"{n}={_num(point[n])}" if n[-1].isdigit() else f"{n}{_num(point[n])}" for n in names)


def plot_scene(scene: Mapping[str, Any], out_path: str | Path, *, title: str | None = None) -> Path:
    """Draw ``scene`` (:func:`hli_server.scene.build_scene`) into ``out_path``; the suffix chooses the
    format (any of :func:`supported_formats`). Returns the written path."""
    out = Path(out_path)
    suffix = out.suffix.lower().lstrip(".")
    if suffix not in supported_formats():
        raise PlotTargetError(f"{out}: matplotlib does not write .{suffix} files")
    view = scene["view"]
    va, vb, vh = view["a"], view["b"], view["height"]
    has_height = vh is not None
    fig = Figure(figsize=(9, 11 if has_height else 8), dpi=100, layout="constrained")
    if has_height:
        grid = fig.add_gridspec(2, 1, height_ratios=(3, 1.3))
        top = fig.add_subplot(grid[0])
        side = fig.add_subplot(grid[1])
    else:
        top = fig.add_subplot(1, 1, 1)
        side = None
    _draw_top(fig, top, scene)
    if side is not None:
        _draw_side(side, scene)
    skipped = [f"ID{a['id']} ({'/'.join(a['axes'])})" for a in scene["areas"] if not a["in_view"]]
    heading = title or f"work (green) and protection (red) areas, plane {va}/{vb}"
    if skipped:
        heading += "\nnot in this plane: " + ", ".join(skipped)
    top.set_title(heading, fontsize=10)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(str(out), format=suffix)
    return out


def _draw_top(fig: Figure, ax: Any, scene: Mapping[str, Any]) -> None:
    view = scene["view"]
    va, vb, vh = view["a"], view["b"], view["height"]
    for area in scene["areas"]:
        if not area["in_view"]:
            continue
        colour, style = _area_style(area)
        band = f"{area.get('height_axis')} {_num(area['min'])}..{_num(area['max'])}"
        how = area.get("relation_text") or relation_text(area, scene.get("refused"), scene.get("violation"))
        label = f"ID{area['id']} {area['kind']} {area['state']}, {band}: {how}"
        ax.add_patch(_patch(area, label=label, **style))
        outline = _patch(area, fill=False)  # the outline fully opaque, whatever the fill
        outline.set_edgecolor(colour)
        outline.set_linewidth(style["linewidth"])
        outline.set_linestyle(style["linestyle"])
        ax.add_patch(outline)
        anchor = area["center"] if area.get("shape") == "CIRC" else area["points"][0]
        ax.annotate(
            f"ID{area['id']}",
            tuple(anchor),
            xytext=(4, 4),
            textcoords="offset points",
            color=colour,
            fontsize=9,
        )
    all_heights = [p[2] for line in scene["path"] for p in line if p[2] is not None]
    coloured = vh is not None and bool(all_heights) and max(all_heights) - min(all_heights) > 1e-9
    for k, line in enumerate(scene["path"]):
        xs = [p[0] for p in line]
        ys = [p[1] for p in line]
        hs = [p[2] for p in line]
        path_label: str | None = ("axes' path" if scene.get("tool_path") else "path") if k == 0 else None
        if coloured and len(line) > 1:
            segments, heights = _coloured_segments(xs, ys, hs)
            coll = LineCollection(segments, cmap="viridis", linewidths=1.6, label=path_label)
            coll.set_array(heights)
            coll.set_clim(min(all_heights), max(all_heights))
            ax.add_collection(coll)
            if k == 0:
                fig.colorbar(coll, ax=ax, label=f"path height {vh} [mm]", shrink=0.8)
        else:
            height = f" ({vh} {_num(hs[0])})" if vh is not None and hs else ""
            ax.plot(xs, ys, color=_PATH, linewidth=1.4, label=f"path{height}" if path_label else None)
        ax.plot(xs[:1], ys[:1], marker="o", color=_PATH, linestyle="none", label="start" if k == 0 else None)
    tool = scene.get("tool_path")
    if tool:
        # K-06: with a kinematic transformation the path above is the axes'; the tool tip's beside it
        ax.plot(
            [p[0] for p in tool],
            [p[1] for p in tool],
            color=_TOOL,
            linestyle=":",
            linewidth=1.6,
            label="tool tip (TCP) with the transformation on",
        )
    refused = scene.get("refused")
    if refused is not None:
        pts = refused["points"]
        ax.plot(
            [p[0] for p in pts],
            [p[1] for p in pts],
            color=_REFUSED,
            linestyle="--",
            linewidth=2.0,
            label=f"refused block {refused.get('block')} (line {refused.get('line')}, "
            f"alarm {refused.get('alarm')})",
        )
    _draw_marks(ax, scene, 0, 1)
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel(f"{va} [mm]")
    ax.set_ylabel(f"{vb} [mm]")
    ax.grid(True, linewidth=0.3)
    if ax.get_legend_handles_labels()[0]:
        # "best" measures every drawn point against every place: seconds for a long program's path
        few = sum(len(line) for line in scene["path"]) < 5000
        ax.legend(loc="best" if few else "upper right", fontsize=7)


def _coloured_segments(
    xs: Sequence[float], ys: Sequence[float], hs: Sequence[float]
) -> tuple[list[list[tuple[float, float]]], list[float]]:
    """The path's segments for colouring by height, a long climb cut into pieces so that its colour
    changes along it (the scene's simplified path has few points on a straight climb)."""
    step = max((max(hs) - min(hs)) / 64.0, 1e-9)
    segments: list[list[tuple[float, float]]] = []
    heights: list[float] = []
    for k in range(len(xs) - 1):
        n = min(64, max(1, math.ceil(abs(hs[k + 1] - hs[k]) / step)))
        for m in range(n):
            f0, f1 = m / n, (m + 1) / n
            segments.append(
                [
                    (xs[k] + f0 * (xs[k + 1] - xs[k]), ys[k] + f0 * (ys[k + 1] - ys[k])),
                    (xs[k] + f1 * (xs[k + 1] - xs[k]), ys[k] + f1 * (ys[k + 1] - ys[k])),
                ]
            )
            heights.append(hs[k] + 0.5 * (f0 + f1) * (hs[k + 1] - hs[k]))
    return segments, heights


def _draw_marks(ax: Any, scene: Mapping[str, Any], i: int, j: int) -> None:
    """The violation point and the stop point, in coordinates ``i``/``j`` of the view points."""
    names = list(scene["axes"])
    violation = scene.get("violation")
    if violation is not None and violation["point"][j] is not None:
        p = violation["point"]
        ax.plot(
            [p[i]],
            [p[j]],
            marker="*",
            markersize=15,
            color=_REFUSED,
            markeredgecolor="black",
            linestyle="none",
            label=f"violation ({_point_text(names, violation['position'])}), "
            + (violation.get("cause") or f"area {violation.get('area')}"),
        )
    stop = scene.get("stop")
    if stop is not None and stop[j] is not None:
        ax.plot(
            [stop[i]],
            [stop[j]],
            marker="X",
            markersize=11,
            color=_STOP,
            linestyle="none",
            label=f"stopped at ({_num(stop[0])}, {_num(stop[1])})",
        )


def _draw_side(ax: Any, scene: Mapping[str, Any]) -> None:
    vh = scene["view"]["height"]
    for area in scene["areas"]:
        if not area["band_in_view"]:
            continue
        colour = _PROT if area.get("kind") == "PROT" else _WORK
        active = area.get("state") == "active"
        for span in area["spans"]:
            lo, hi = area["min"], area["max"]
            width = span["to"] - span["from"]
            if width <= 0.0:
                ax.vlines(span["from"], lo, hi, colors=colour, linewidth=2.0)
            else:
                ax.add_patch(
                    Rectangle(
                        (span["from"], lo),
                        width,
                        hi - lo,
                        facecolor=colour,
                        edgecolor=colour,
                        alpha=0.3 if active else 0.12,
                        linestyle="-" if active else "--",
                        hatch="//" if area.get("kind") == "PROT" else None,
                    )
                )
            ax.annotate(
                f"ID{area['id']}",
                (span["from"], hi),
                xytext=(2, 2),
                textcoords="offset points",
                color=colour,
                fontsize=8,
            )
    for line in scene["path"]:
        ax.plot([p[3] for p in line], [p[2] for p in line], color=_PATH, linewidth=1.4)
    refused = scene.get("refused")
    if refused is not None:
        pts = refused["points"]
        ax.plot([p[3] for p in pts], [p[2] for p in pts], color=_REFUSED, linestyle="--", linewidth=2.0)
    _draw_marks(ax, scene, 3, 2)
    ax.autoscale_view()
    ax.set_xlabel("path length in the base plane [mm]")
    ax.set_ylabel(f"{vh} [mm]")
    ax.set_title(
        f"side view: height {vh} along the path, with the height bands of the areas it passes", fontsize=9
    )
    ax.grid(True, linewidth=0.3)
