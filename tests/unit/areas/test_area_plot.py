"""``plot_areas``: the picture ``hli-server check --plot`` draws (areas, path, stop point)."""

from __future__ import annotations

from pathlib import Path

import pytest

from hli_server.plot import plot_areas

from .helpers import CIRC_PROT, EXTRA_AXES_AREA, U_AREA, areas, make_machine, run


@pytest.mark.req("C14-04", "C14-05")
@pytest.mark.parametrize("suffix", [".svg", ".png"])
def test_plot_areas_writes_svg_and_png(tmp_path: Path, suffix: str) -> None:
    m = make_machine()
    run(m, U_AREA + CIRC_PROT + EXTRA_AXES_AREA.replace("ID4", "ID5") + "M30\n")
    table = areas(m).to_json()
    out = plot_areas(table, [(0.0, 0.0), (-100.0, 50.0), (0.0, 10.0)], (50.0, 10.0), tmp_path / f"a{suffix}")
    assert out.exists()
    data = out.read_bytes()
    if suffix == ".svg":
        text = data.decode("utf-8")
        assert "ID3" in text
        assert "ID4" in text
        assert "not in this plane: ID5 (X2/Y2)" in text
        assert "stopped at (50.000, 10.000)" in text
    else:
        assert data[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_areas_refuses_other_formats(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"\.svg or \.png"):
        plot_areas([], [], None, tmp_path / "a.pdf")
