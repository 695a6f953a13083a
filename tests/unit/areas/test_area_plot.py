"""``plot_scene``: the picture ``hli-server check --plot`` draws (areas, path, stop point)."""

from __future__ import annotations

from pathlib import Path

import pytest

from hli_server.plot import PlotTargetError, plot_scene
from hli_server.scene import build_scene

from .helpers import CIRC_PROT, EXTRA_AXES_AREA, MAIN, U_AREA, areas, make_machine, run


@pytest.mark.req("C14-04", "C14-05")
@pytest.mark.parametrize("suffix", [".svg", ".png"])
def test_plot_scene_draws_areas_of_the_view_and_names_the_others(tmp_path: Path, suffix: str) -> None:
    m = make_machine()
    run(m, U_AREA + CIRC_PROT + EXTRA_AXES_AREA.replace("ID4", "ID5") + "M30\n")
    ch = m.channel(1)
    rest = (0.0, 0.0, 0.0)  # X2, Y2, Z2
    path = [(0.0, 0.0, 0.0, *rest), (-100.0, 50.0, 0.0, *rest), (0.0, 10.0, 0.0, *rest)]
    scene = build_scene(
        areas(m).to_json(),
        path,
        axis_names=ch.axis_names,
        main_axes=MAIN,
        stop=(50.0, 10.0, 0.0, *rest),
    )
    out = plot_scene(scene, tmp_path / f"a{suffix}")
    data = out.read_bytes()
    if suffix == ".svg":
        text = data.decode("utf-8")
        assert "ID3" in text
        assert "ID4" in text
        assert "not in this plane: ID5 (X2/Y2)" in text
        assert "stopped at (50, 10)" in text
    else:
        assert data[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_scene_refuses_a_format_matplotlib_does_not_write(tmp_path: Path) -> None:
    scene = build_scene([], [(0.0, 0.0, 0.0)], axis_names=MAIN, main_axes=MAIN)
    with pytest.raises(PlotTargetError, match=r"does not write \.doc"):
        plot_scene(scene, tmp_path / "a.doc")
