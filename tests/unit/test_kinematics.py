"""The kinematic transformations (issue 35, docs/kinematics.md): forward(inverse(p)) = p per type, the
poses and singular positions, the kernel's errors where a pose cannot be reached."""

from __future__ import annotations

import math
from collections.abc import Sequence

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hli_server.engine.kinematics import (
    KinematicData,
    KinematicError,
    Transformation,
    build,
    mode_angles,
    mode_orientation,
    universal_params,
)
from hli_server.engine.kinematics.chain import two_axis_angles

SLOTS = (0, 1, 2, 3, 4, 5)
TOL = 1e-9
"""mm (and degrees): forward(inverse(p)) = p within this."""

X, Y, Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


def neg(v: Sequence[float]) -> tuple[float, float, float]:
    return (-v[0], -v[1], -v[2])


def um(v: Sequence[float]) -> tuple[float, float, float]:
    """mm -> the kernel's 0.1 µm."""
    return (v[0] * 1e4, v[1] * 1e4, v[2] * 1e4)


def universal(
    axes: Sequence[tuple[int, Sequence[float], Sequence[float]]],
    chain: Sequence[int] = (),
    zero_position: Sequence[float] = (0.0, 0.0, 0.0),
    mode: int = 0,
) -> KinematicData:
    """A Universal Kinematics data set: ``axes`` (1 linear / 2 rotary, direction, point in mm)
    by axis index."""
    params = universal_params(Z, um(zero_position), [(k, d, um(p)) for k, d, p in axes])
    return KinematicData(91, params=params, chain=tuple(chain), programming_mode=mode, rtcp=0 if mode else 1)


LINEAR = [(1, X, (0.0, 0.0, 0.0)), (1, Y, (0.0, 0.0, 0.0)), (1, Z, (0.0, 0.0, 0.0))]
DIRS = {"A": X, "B": Y, "C": Z}


def head(
    letters: str, p1: Sequence[float], p2: Sequence[float], mode: int = 0, zero=(0.0, 0.0, 0.0)
) -> KinematicData:
    """A fork head: X, Y, Z, then the head's two rotary axes (the first one nearer the machine)."""
    return universal(
        [*LINEAR, (2, DIRS[letters[0]], p1), (2, DIRS[letters[1]], p2)], zero_position=zero, mode=mode
    )


def table(letters: str, p1: Sequence[float], p2: Sequence[float], mode: int = 0) -> KinematicData:
    """A rotary/tilting table: the chain runs from the workpiece through the table's axes (directions
    reversed on the workpiece side, TF5240 ".../278732555.html") to X, Y, Z. Axis indices: X, Y, Z = 0, 1, 2,
    the table's axes 3 (nearer the machine) and 4 (carrying the workpiece)."""
    axes = [*LINEAR, (2, neg(DIRS[letters[0]]), p1), (2, neg(DIRS[letters[1]]), p2)]
    return universal(axes, chain=(4, 3, 0, 1, 2), mode=mode)


def head_table(p_table: Sequence[float], p_head: Sequence[float]) -> KinematicData:
    """One table axis (C, index 3) and one head axis (B, index 4): chain C, X, Y, Z, B."""
    axes = [*LINEAR, (2, neg(Z), p_table), (2, Y, p_head)]
    return universal(axes, chain=(3, 0, 1, 2, 4))


def tube(structure: int, ca_programming: bool, hd: dict[int, float] | None = None) -> KinematicData:
    params = {0: 1_000_000.0, 12: float(structure), 13: 1.0 if ca_programming else 0.0, **(hd or {})}
    return KinematicData(90, params=params)


coord = st.floats(-800.0, 800.0, allow_nan=False)
offset = st.floats(-200.0, 200.0, allow_nan=False)
angle = st.floats(-179.0, 179.0, allow_nan=False)
tilt = st.floats(-85.0, 85.0, allow_nan=False)
tool = st.floats(0.0, 300.0, allow_nan=False)
point = st.tuples(offset, offset, offset)


def roundtrip_rtcp(trafo: Transformation, p: tuple[float, ...]) -> None:
    axes = trafo.to_axes(p)
    back = trafo.to_tip(axes)
    assert all(abs(a - b) <= TOL for a, b in zip(back, p, strict=True)), (p, axes, back)


# --- RTCP transformations: forward(inverse(p)) = p over the whole space ------------------------------
@pytest.mark.req("K-02")
@settings(max_examples=150, deadline=None)
@given(
    letters=st.sampled_from(["AB", "BA", "CA", "AC", "BC", "CB"]),
    p1=point,
    p2=point,
    zero=point,
    length=tool,
    xyz=st.tuples(coord, coord, coord),
    a=angle,
    b=angle,
    u=coord,
)
def test_fork_heads_roundtrip(letters, p1, p2, zero, length, xyz, a, b, u) -> None:
    trafo, identity = build(head(letters, p1, p2, zero=zero), SLOTS, length)
    assert not identity
    roundtrip_rtcp(trafo, (*xyz, a, b, u))


@pytest.mark.req("K-02")
@settings(max_examples=150, deadline=None)
@given(
    letters=st.sampled_from(["CA", "CB", "AC", "BC"]),
    p1=point,
    p2=point,
    length=tool,
    xyz=st.tuples(coord, coord, coord),
    a=angle,
    b=angle,
)
def test_rotary_tilting_tables_roundtrip(letters, p1, p2, length, xyz, a, b) -> None:
    trafo, _ = build(table(letters, p1, p2), SLOTS, length)
    roundtrip_rtcp(trafo, (*xyz, a, b, 0.0))


@pytest.mark.req("K-02")
@settings(max_examples=150, deadline=None)
@given(pt=point, ph=point, length=tool, xyz=st.tuples(coord, coord, coord), c=angle, b=angle)
def test_head_and_table_roundtrip(pt, ph, length, xyz, c, b) -> None:
    trafo, _ = build(head_table(pt, ph), SLOTS, length)
    roundtrip_rtcp(trafo, (*xyz, c, b, 0.0))


@pytest.mark.req("K-02")
@settings(max_examples=150, deadline=None)
@given(
    structure=st.sampled_from([0, 1, 2, 4]),
    offsets=st.tuples(*(st.floats(-2_000_000.0, 2_000_000.0) for _ in range(9))),
    direction=st.tuples(st.booleans(), st.booleans()),
    angle_offsets=st.tuples(st.floats(-900_000.0, 900_000.0), st.floats(-900_000.0, 900_000.0)),
    length=tool,
    xyz=st.tuples(coord, coord, coord),
    a=angle,
    b=angle,
    u=coord,
)
def test_tube_heads_rtcp_roundtrip(
    structure, offsets, direction, angle_offsets, length, xyz, a, b, u
) -> None:
    hd = dict(enumerate(offsets))
    hd.update({14: float(direction[0]), 15: float(direction[1]), 16: angle_offsets[0], 17: angle_offsets[1]})
    trafo, _ = build(tube(structure, False, hd), SLOTS, length)
    roundtrip_rtcp(trafo, (*xyz, a, b, u))


# --- complete transformations: the programmed orientation -> the axes' angles and back ----------------
def roundtrip_complete(trafo: Transformation, p: tuple[float, ...], hint: tuple[float, ...]) -> None:
    axes = trafo.to_axes(p, hint)
    back = trafo.to_tip(axes, p)
    assert all(abs(a - b) <= TOL for a, b in zip(back[:3], p[:3], strict=True)), (p, axes, back)
    o1 = mode_orientation(trafo.mode, p[3], p[4])
    o2 = trafo.orientation(axes)
    assert all(abs(a - b) <= TOL for a, b in zip(o1, o2, strict=True))
    # away from the pole the programmed angles come back themselves
    if abs(math.sin(math.radians(p[4]))) > 1e-3:
        assert abs(back[3] - p[3]) <= 1e-7
        assert abs(back[4] - p[4]) <= 1e-7
    assert back[5] == p[5]


@pytest.mark.req("K-02")
@settings(max_examples=200, deadline=None)
@given(
    structure=st.sampled_from([0, 1]),
    length=tool,
    xyz=st.tuples(coord, coord, coord),
    c=angle,
    a=tilt,
    hint=st.tuples(angle, angle),
)
def test_tube_ab_ba_heads_with_ca_programming(structure, length, xyz, c, a, hint) -> None:
    """TF5290 AB/BA head programmed with virtual C-A angles (HD14 = 1): every tilt below 90° is reached."""
    trafo, _ = build(tube(structure, True), SLOTS, length)
    assert trafo.mode == 17
    roundtrip_complete(trafo, (*xyz, c, a, 7.0), (0.0, 0.0, 0.0, hint[0], hint[1], 0.0))


@pytest.mark.req("K-02")
@settings(max_examples=200, deadline=None)
@given(
    letters=st.sampled_from(["CA", "CB", "BA", "AB"]),
    p1=point,
    p2=point,
    length=tool,
    xyz=st.tuples(coord, coord, coord),
    c=angle,
    a=tilt,
)
def test_universal_complete_transformation(letters, p1, p2, length, xyz, c, a) -> None:
    """Universal Kinematics, complete transformation in CA mode (P-CHAN-00287 = 0,
    P-CHAN-00288 = 17): heads whose first axis is C reach every orientation; A-B gimbals every
    one off the pole (tilts below 90°)."""
    trafo, _ = build(head(letters, p1, p2, mode=17), SLOTS, length)
    roundtrip_complete(trafo, (*xyz, c, a, 0.0), (0.0,) * 6)


@pytest.mark.req("K-02")
@settings(max_examples=100, deadline=None)
@given(
    mode=st.sampled_from([14, 15, 16, 17, 18, 19]),
    a1=angle,
    a2=st.floats(1.0, 179.0),
    h=st.tuples(angle, angle),
)
def test_programming_modes_roundtrip(mode, a1, a2, h) -> None:
    """Mode angles -> orientation -> mode angles: one of the two poses is the programmed one."""
    o = mode_orientation(mode, a1, a2)
    b1, b2 = mode_angles(mode, o, a1, a2)
    assert abs(b1 - a1) < 1e-7
    assert abs(b2 - a2) < 1e-7
    c1, c2 = mode_angles(mode, o, *h)  # any hint: another pose of the same orientation
    o2 = mode_orientation(mode, c1, c2)
    assert all(abs(x - y) < 1e-9 for x, y in zip(o, o2, strict=True))


# --- worked examples of the manual ---------------------------------------------------------------
@pytest.mark.req("K-03")
def test_ca_head_two_poses_of_the_manual() -> None:
    """P-CHAN-00189 (https://infosys.beckhoff.com/content/1033/tf5200_channel_parameter/347022219.html): "With
    a C-A tool head, for example, there is an alternative position C=180° and A=-45° for the axis position
    C=0° and A=45°": both poses reach the same orientation, the one nearer the previous position is taken."""
    trafo, _ = build(head("CA", (0, 0, 0), (0, 0, 0), mode=17), SLOTS, 100.0)
    target = (0.0, 0.0, 0.0, 0.0, 45.0, 0.0)
    poses = two_axis_angles(Z, X, Z, mode_orientation(17, 0.0, 45.0), 0.0, 0.0)
    assert sorted((round(a1, 9) % 360, round(a2, 9)) for a1, a2 in poses) == [(0.0, 45.0), (180.0, -45.0)]
    near_first = trafo.to_axes(target, (0, 0, 0, 10.0, 30.0, 0))
    near_second = trafo.to_axes(target, (0, 0, 0, 170.0, -30.0, 0))
    assert near_first[3:5] == pytest.approx((0.0, 45.0), abs=1e-9)
    assert near_second[3:5] == pytest.approx((180.0, -45.0), abs=1e-9)
    # the tool tip is the same point either way; the head is 100 mm up the tool
    for axes in (near_first, near_second):
        assert trafo.to_tip(axes, target)[:3] == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
        assert math.dist(axes[:3], (0, 0, 0)) == pytest.approx(100.0)


@pytest.mark.req("K-02")
def test_tube_ab_head_of_the_corpus_example() -> None:
    """TF5290 "AB head, CA programming" (https://infosys.beckhoff.com/content/1033/tf5290_cnc_cutting_plus/
    297494283.html): HD1 = 100 mm, C0 A45 tilts the tool 45° about X (A 45°, B 0°) and the head sits 100 mm up
    the tool from the tip; C90 A45 tilts it about Y (A 0°, B 45°)."""
    trafo, _ = build(tube(0, True), SLOTS, 0.0)
    s = 100.0 / math.sqrt(2.0)
    axes = trafo.to_axes((0.0, 0.0, 0.0, 0.0, 45.0, 0.0))
    assert axes == pytest.approx((0.0, -s, s, 45.0, 0.0, 0.0), abs=1e-9)
    axes = trafo.to_axes((0.0, 0.0, 0.0, 90.0, 45.0, 0.0), axes)
    assert axes == pytest.approx((s, 0.0, s, 0.0, 45.0, 0.0), abs=1e-9)


@pytest.mark.req("K-03")
def test_pole_keeps_the_free_angle() -> None:
    """At the pole (the tool along the first axis of the head) the first axis' angle is free: it keeps the
    previous position instead of turning (no jump)."""
    trafo, _ = build(head("CA", (0, 0, 0), (0, 0, 0), mode=17), SLOTS, 50.0)
    for previous in (-120.0, 0.0, 37.5, 250.0):
        axes = trafo.to_axes((1.0, 2.0, 3.0, 77.0, 0.0, 0.0), (0, 0, 0, previous, 0, 0))
        assert axes[3] == pytest.approx(previous)
        assert axes[4] == pytest.approx(0.0, abs=1e-9)
        assert axes[:3] == pytest.approx((1.0, 2.0, 53.0))


@pytest.mark.req("K-03")
def test_shortest_way_across_180_degrees() -> None:
    """A complete transformation hands on each angle the shortest way from the previous one (the axes here
    are not modulo axes): 179° -> -179° programmed is 181° at the axis."""
    trafo, _ = build(head("CA", (0, 0, 0), (0, 0, 0), mode=17), SLOTS, 10.0)
    first = trafo.to_axes((0.0, 0.0, 0.0, 179.0, 30.0, 0.0), (0.0, 0.0, 0.0, 170.0, 30.0, 0.0))
    assert first[3:5] == pytest.approx((179.0, 30.0))
    second = trafo.to_axes((0.0, 0.0, 0.0, -179.0, 30.0, 0.0), first)
    assert second[3:5] == pytest.approx((181.0, 30.0))
    # from C 0°, A 0° the nearer pose of C 179°, A 30° is C -1°, A -30°
    other = trafo.to_axes((0.0, 0.0, 0.0, 179.0, 30.0, 0.0), (0.0,) * 6)
    assert other[3:5] == pytest.approx((-1.0, -30.0))


@pytest.mark.req("K-03")
def test_unreachable_orientation_is_292004() -> None:
    """A 45° head (the second axis inclined 45° to the first, a "45° BA machine" of TF5240) reaches only
    tilts up to 90°: a horizontal tool pointing down-side is out of reach -> the kernel's 292004."""
    inclined = (0.0, math.sqrt(0.5), math.sqrt(0.5))
    data = universal([*LINEAR, (2, Z, (0, 0, 0)), (2, inclined, (0, 0, 0))], mode=17)
    trafo, _ = build(data, SLOTS, 100.0)
    trafo.to_axes((0.0, 0.0, 0.0, 0.0, 80.0, 0.0))  # within reach
    with pytest.raises(KinematicError) as err:
        trafo.to_axes((0.0, 0.0, 0.0, 0.0, 120.0, 0.0))
    assert err.value.alarm == 292004


@pytest.mark.req("K-03")
@pytest.mark.parametrize(
    ("data", "alarm"),
    [
        (KinematicData(91), 292040),  # NUMBER_OF_AXES 0
        (universal([*LINEAR[:2], (2, Z, (0, 0, 0)), (1, Z, (0, 0, 0))]), 292040),  # no linear axis 2
        (universal([(1, X, (0, 0, 0)), (1, X, (0, 0, 0)), (1, Z, (0, 0, 0))]), 292016),  # X twice
        (KinematicData(91, params=universal_params(Z, (0, 0, 0), [(1, X, (0, 0, 0))] * 3), rtcp=0), 292045),
        (tube(8, False), 910110),
        (tube(3, False), 292040),
        (KinematicData(5, params={0: 1.0}), 910110),
    ],
)
def test_bad_data_sets_are_the_kernels_errors(data: KinematicData, alarm: int) -> None:
    def build_and_move() -> None:
        trafo, _ = build(data, SLOTS, 0.0)
        trafo.to_axes((1.0, 2.0, 3.0, 0.0, 0.0, 0.0))

    with pytest.raises(KinematicError) as err:
        build_and_move()
    assert err.value.alarm == alarm


@pytest.mark.req("K-02")
@given(xyz=st.tuples(coord, coord, coord), rest=st.tuples(angle, angle, coord), length=tool)
def test_undescribed_type_with_zero_parameters_is_the_identity(xyz, rest, length) -> None:
    """Kinematic type 5 (TF5240 names it, its geometry is not public) with every parameter 0: the identity,
    the tool length along Z as without a transformation (warning 913001 where it is selected)."""
    trafo, identity = build(KinematicData(5), SLOTS, length)
    assert identity
    p = (*xyz, *rest)
    axes = trafo.to_axes(p)
    assert axes == pytest.approx((xyz[0], xyz[1], xyz[2] + length, *rest), abs=1e-9)
    roundtrip_rtcp(trafo, p)


@pytest.mark.req("K-02")
def test_slots_follow_the_axis_configuration() -> None:
    """#SET AX puts other channel slots on the kinematic's indices: the transformation reads and writes
    those slots and passes every other one on."""
    trafo, _ = build(tube(0, False), (0, 1, 2, 5, 3, 6), 0.0)
    p = (0.0, 0.0, 0.0, 0.0, 12.0, 45.0, 13.0)  # B (slot 3) 0°, A (slot 5) 45°; slots 4 and 6 not its own
    axes = trafo.to_axes(p)
    assert axes[3:] == (0.0, 12.0, 45.0, 13.0)
    assert axes[1:3] == pytest.approx((-100.0 * math.sqrt(0.5), 100.0 * math.sqrt(0.5)))
