"""The one layout table of the process image (H-01, H-02, H-08).

Every signal of the PLC interface (HLI) is listed once here, as a *template* per channel
(:data:`CHANNEL_TEMPLATES`, ``gpCh[i]^...``) and per axis (:data:`AXIS_TEMPLATES`, ``gpAx[i]^...``).
:func:`build_layout` expands the templates for the channels and axes of a machine (a
:class:`MachineShape`: what the layout reads of a :class:`~schemas.config.MachineConfig`; this module does
not import the configuration, the configuration imports it to check that its V.E. variables fit the
Modbus map); everything else is derived from the result and never written down a second time:

* the byte layout of the two halves of the shared-memory image (``struct`` format and
  ``construct`` description, :meth:`Layout.struct` / :meth:`Layout.construct`);
* the Modbus map (table and 0-based address, 1-based reference);
* the ADS addresses (port / index group / index offset) and symbol names (the ST paths);
* the address map of ``hli-server map`` (Markdown, CSV, JSON: :meth:`Layout.to_json`).

Names the documents give are used as given: ``bahn_state.area_mon_violation_detected_r`` and
``bahn_mc_control.suppress_area_mon_manual_mode`` (FCT-C14 6.3), ``ipo_mc_control.dyn_pos_limit_low``
/ ``_high`` (FCT-C43 3.1.1), the ``dyn_coll_mon`` CNC objects (FCT-C3 4.3, C3-10). The rest is the
project's own (``origin="project"``).

Addressing (documented in ``docs/process-image.md``):

* **Image / ADS offsets.** Each half starts with :data:`MAX_CHANNELS` fixed channel slots, then one
  fixed-size block per axis. The ADS index offset of an HLI signal is its byte offset in its half
  (group :data:`ADS_GROUP_PLC_TO_CNC` or :data:`ADS_GROUP_CNC_TO_PLC`, port :data:`ADS_PORT_HLI`);
  adding a channel or an axis moves no other signal. The ``dyn_coll_mon`` objects have the kernel's
  address instead: port 551, group 0x120300, offset ``(A_ID << 16) | element`` (C3-10).
* **Modbus.** In each of the four tables, channel ``i`` owns addresses
  ``MODBUS_CHANNEL_BASE + 100 * i`` .. ``+99`` and axis ``j`` owns ``MODBUS_AXIS_BASE + 100 * j``
  .. ``+99``. BOOL PLC->CNC = coil, BOOL CNC->PLC = discrete input, numbers PLC->CNC = holding
  registers, numbers CNC->PLC = input registers; DINT/UDINT take two registers, LREAL four (the
  word order is a setting of the Modbus adapter).

Control units (H-02) keep the kernel's field order request_r, enable_w, command_w, state_r in the
table and within each half; the image splits a unit between the halves (its ``_w`` fields are
PLC->CNC, its ``_r`` fields CNC->PLC) because each half has its own consistency protocol.
"""

from __future__ import annotations

import difflib
import hashlib
import itertools
import json
import math
import sys
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from functools import cached_property
from struct import Struct
from typing import Any, Final, Protocol, cast

import construct as cs
from typing_extensions import TypedDict

from schemas.external_types import ExternalShape, TypeNode, VariableShape, machine_types
from schemas.units import DINT_MAX, DINT_MIN, UDINT_MAX
from schemas.wire import DynPosLimitState, HoldSource, Mode, ProgramState, describe

__all__ = [
    "ADS_GROUP_CNC_TO_PLC",
    "ADS_GROUP_GEO_AXIS",
    "ADS_GROUP_PLC_TO_CNC",
    "ADS_PORT_GEO",
    "ADS_PORT_HLI",
    "AXIS_TEMPLATES",
    "CHANNEL_TEMPLATES",
    "EXTERNAL_TYPES",
    "LAYOUT_FORMAT",
    "LAYOUT_VERSION",
    "MAX_AXES",
    "MAX_CHANNELS",
    "MODBUS_AXIS_BASE",
    "MODBUS_BLOCK_STRIDE",
    "MODBUS_CHANNEL_BASE",
    "MODBUS_EXTERNAL_BASE",
    "MODBUS_EXTERNAL_END",
    "MODBUS_SNAPSHOT_REGISTER",
    "REAL32_MAX",
    "AxisInfo",
    "AxisShape",
    "ChannelInfo",
    "ChannelShape",
    "Direction",
    "ExternalVariableShape",
    "Layout",
    "LayoutAxis",
    "LayoutChannel",
    "LayoutError",
    "LayoutJson",
    "LayoutSignal",
    "MachineShape",
    "ModbusTable",
    "ReadOnlySignalError",
    "Scope",
    "Signal",
    "SignalTemplate",
    "SignalType",
    "SignalValueError",
    "UnknownSignalError",
    "build_layout",
    "check_external_fits",
    "external_modbus_use",
]

LAYOUT_VERSION: Final = 5
"""Bumped whenever the templates or the addressing rules change (the hash changes with any config)."""

LAYOUT_FORMAT: Final = "hli-layout"
"""The ``format`` key of the JSON export."""

MAX_CHANNELS: Final = 12
"""Channel slots reserved in each half (the configuration allows channel numbers 1..12)."""

MODBUS_CHANNEL_BASE: Final = 0
MODBUS_AXIS_BASE: Final = 2000
MODBUS_BLOCK_STRIDE: Final = 100
MAX_AXES: Final = (65536 - MODBUS_AXIS_BASE) // MODBUS_BLOCK_STRIDE
"""635: the axes that fit the 16-bit Modbus address space with the fixed blocks."""
MODBUS_SNAPSHOT_REGISTER: Final = 1900
"""Holding register of the Modbus adapter's consistent snapshot (not a signal: between the last
channel block, which ends at 1199, and the first axis block). Writing 1 freezes the connection's
reads of discrete inputs and input registers on one publish of the CNC->PLC half; 0 reads live
again (docs/modbus.md, "Consistent snapshots")."""
_CHANNEL_BLOCKS_END: Final = MODBUS_CHANNEL_BASE + MAX_CHANNELS * MODBUS_BLOCK_STRIDE
if not _CHANNEL_BLOCKS_END <= MODBUS_SNAPSHOT_REGISTER < MODBUS_AXIS_BASE:  # pragma: no cover - a typo
    raise RuntimeError("the snapshot register must lie between the channel and the axis blocks")

MODBUS_EXTERNAL_BASE: Final = _CHANNEL_BLOCKS_END
"""First coil and holding register of the V.E. variables (N-05): 1200."""
MODBUS_EXTERNAL_END: Final = MODBUS_SNAPSHOT_REGISTER
"""One past the last address of the V.E. variables: 1900 (the snapshot register follows)."""

ADS_PORT_HLI: Final = 851
"""ADS port of the HLI image (the port where a TwinCAT PLC runtime serves its symbols; project's choice)."""
ADS_GROUP_CNC_TO_PLC: Final = 0xF020
"""CNC->PLC half: the PLC's inputs (TwinCAT's %I group; project's choice)."""
ADS_GROUP_PLC_TO_CNC: Final = 0xF030
"""PLC->CNC half: the PLC's outputs (TwinCAT's %Q group; project's choice)."""
ADS_PORT_GEO: Final = 551
"""Task GEO of the kernel (C3-10)."""
ADS_GROUP_GEO_AXIS: Final = 0x120300
"""Index group of the position-controller axis objects, the dyn_coll_mon objects (C3-10)."""

_ALIGN_BLOCK: Final = 8


class LayoutError(ValueError):
    """The configuration does not fit the layout's addressing rules, or a JSON layout is damaged."""


class UnknownSignalError(KeyError):
    """No signal has this ST path; the message names the closest ones."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "unknown signal"


class ReadOnlySignalError(PermissionError):
    """A write to a CNC->PLC field (``_r`` or a CNC object) through a PLC door (H-02)."""


class SignalValueError(ValueError):
    """A value that the signal's type cannot hold."""


class SignalType(StrEnum):
    """IEC 61131-3 types used in the image. BOOL is one byte (0 or 1). STRING is a V.E. variable's
    (N-05): ``STRING(n)`` of TwinCAT, n characters in Windows-1252 and a NUL, n + 1 bytes; its length
    is its signal's (:attr:`Signal.string_size`), so the type itself has no size."""

    BOOL = "BOOL"
    DINT = "DINT"
    UDINT = "UDINT"
    LREAL = "LREAL"
    STRING = "STRING"

    @property
    def size(self) -> int:
        """Bytes of a value (not of a STRING: :attr:`Signal.size`)."""
        try:
            return _TYPE_SIZE[self]
        except KeyError:
            raise ValueError("a STRING's size is its signal's (Signal.size)") from None

    @property
    def struct_char(self) -> str:
        """The ``struct`` format character (with ``<`` in a layout format, ``@`` for single stores);
        a STRING's is its signal's (:attr:`Signal.struct_char`)."""
        try:
            return _TYPE_CHAR[self]
        except KeyError:
            raise ValueError("a STRING's format is its signal's (Signal.struct_char)") from None

    @property
    def modbus_count(self) -> int:
        """Bits (BOOL) or 16-bit registers the type takes in its Modbus table."""
        return 1 if self is SignalType.BOOL else self.size // 2


_TYPE_SIZE: Final = {SignalType.BOOL: 1, SignalType.DINT: 4, SignalType.UDINT: 4, SignalType.LREAL: 8}
_TYPE_CHAR: Final = {SignalType.BOOL: "?", SignalType.DINT: "i", SignalType.UDINT: "I", SignalType.LREAL: "d"}
_INT_RANGE: Final = {SignalType.DINT: (DINT_MIN, DINT_MAX), SignalType.UDINT: (0, UDINT_MAX)}

STRING_ENCODING: Final = "cp1252"
"""The bytes of a STRING field: Windows-1252, as TwinCAT's STRING (and the ADS upload info announces)."""

REAL32_MAX: Final = 3.4028234663852886e38
"""The largest finite REAL32 (IEEE 754 single)."""

EXTERNAL_TYPES: Final[dict[str, tuple[SignalType, tuple[float, float] | None]]] = {
    "BOOLEAN": (SignalType.BOOL, None),
    "SGN08": (SignalType.DINT, (-(2**7), 2**7 - 1)),
    "UNS08": (SignalType.UDINT, (0, 2**8 - 1)),
    "SGN16": (SignalType.DINT, (-(2**15), 2**15 - 1)),
    "UNS16": (SignalType.UDINT, (0, 2**16 - 1)),
    "SGN32": (SignalType.DINT, None),
    "UNS32": (SignalType.UDINT, None),
    "REAL32": (SignalType.LREAL, (-REAL32_MAX, REAL32_MAX)),
    "REAL64": (SignalType.LREAL, (-sys.float_info.max, sys.float_info.max)),
}
"""The kernel's V.E. data types (P-EXTV-00003) -> the image's type and the values it takes (N-05).

The image carries the four types of the HLI signals (BOOL, DINT, UDINT, LREAL), which every door
serves: an SGN08/SGN16 lies in a DINT, an UNS08/UNS16 in a UDINT and a REAL32 in an LREAL, and every
door refuses a value outside the kernel type's range (:attr:`Signal.limits`). The reals must be
finite, as the kernel's store keeps them."""


class Direction(StrEnum):
    PLC_TO_CNC = "plc_to_cnc"
    """Written by the PLC (``_w``), latched by the CNC once per cycle."""
    CNC_TO_PLC = "cnc_to_plc"
    """Written by the CNC only (``_r`` and the CNC objects), published once per cycle."""


class Scope(StrEnum):
    CHANNEL = "channel"
    """``gpCh[i]^...``: an HLI signal of channel index i."""
    AXIS = "axis"
    """``gpAx[i]^...``: an HLI signal of axis index i."""
    VE_GLOBAL = "ve_global"
    """``gpVEGlob^name``: a V.E. variable of the global area (index 0), N-05."""
    VE_CHANNEL = "ve_channel"
    """``gpVECh[i]^name``: a V.E. variable of the area of channel index i, N-05."""

    @property
    def external(self) -> bool:
        """A V.E. variable: written by the NC and by the PLC (not an object of ``MachineHli``)."""
        return self in (Scope.VE_GLOBAL, Scope.VE_CHANNEL)


class ModbusTable(StrEnum):
    COIL = "coil"
    DISCRETE_INPUT = "discrete_input"
    HOLDING_REGISTER = "holding_register"
    INPUT_REGISTER = "input_register"

    @property
    def reference_prefix(self) -> str:
        """Leading digit of the 1-based reference: 0xxxx coils, 1xxxx, 3xxxx, 4xxxx."""
        return _MODBUS_PREFIX[self]


_MODBUS_PREFIX: Final = {
    ModbusTable.COIL: "0",
    ModbusTable.DISCRETE_INPUT: "1",
    ModbusTable.INPUT_REGISTER: "3",
    ModbusTable.HOLDING_REGISTER: "4",
}


def _modbus_table(sig_type: SignalType, direction: Direction) -> ModbusTable:
    if sig_type is SignalType.BOOL:
        return ModbusTable.COIL if direction is Direction.PLC_TO_CNC else ModbusTable.DISCRETE_INPUT
    return ModbusTable.HOLDING_REGISTER if direction is Direction.PLC_TO_CNC else ModbusTable.INPUT_REGISTER


# --------------------------------------------------------------------------------------------
# The templates
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SignalTemplate:
    """One signal of a channel or an axis, relative to ``gpCh[i]^`` / ``gpAx[i]^``.

    ``unit`` may contain ``{pos}`` (0.1 µm, rotary 0.0001°) and ``{acc}`` (mm/s², rotary °/s²),
    resolved per axis type. ``ads_element`` is the kernel's element number of a CNC object
    (dyn_coll_mon, C3-10); such a signal is addressed over ADS on port 551, not in the HLI groups.
    """

    path: str
    type: SignalType
    direction: Direction
    unit: str
    description: str
    reqs: tuple[str, ...]
    origin: str
    ads_element: int | None = None


_B, _DI, _UDI, _LR = SignalType.BOOL, SignalType.DINT, SignalType.UDINT, SignalType.LREAL
_W, _R = Direction.PLC_TO_CNC, Direction.CNC_TO_PLC
_C14, _C43, _C3, _OWN = "FCT-C14 6.3", "FCT-C43 3.1.1", "FCT-C3 4.3", "project"


def _unit_templates(
    path: str,
    value_type: SignalType,
    unit: str,
    what: str,
    reqs: tuple[str, ...],
    origin: str,
    request: str = "the value the CNC itself would use",
    state: str = "the value in effect",
    state_unit: str | None = None,
) -> tuple[SignalTemplate, ...]:
    """The four fields of a control unit in the kernel's order (H-02)."""
    state_unit = unit if state_unit is None else state_unit
    return (
        SignalTemplate(f"{path}.request_r", value_type, _R, unit, f"{what}: {request}", reqs, origin),
        SignalTemplate(
            f"{path}.enable_w", _B, _W, "-", f"{what}: TRUE = the CNC uses command_w", reqs, origin
        ),
        SignalTemplate(f"{path}.command_w", value_type, _W, unit, f"{what}: the PLC's value", reqs, origin),
        SignalTemplate(f"{path}.state_r", value_type, _R, state_unit, f"{what}: {state}", reqs, origin),
    )


_DYNPL_STATE = describe(DynPosLimitState, "monitoring state HLI_DYNPL_STATE_*", lower=False)

CHANNEL_TEMPLATES: Final[tuple[SignalTemplate, ...]] = (
    # gpCh[i]^bahn_state: CNC -> PLC
    SignalTemplate(
        "bahn_state.area_mon_violation_detected_r",
        _B, _R, "-", "work area monitoring detected a violation", ("C14-22", "H-01"), _C14,
    ),
    SignalTemplate(
        "bahn_state.mode_r", _UDI, _R, "-", describe(Mode, "active mode"), ("E-03", "H-01"), _OWN
    ),
    SignalTemplate(
        "bahn_state.program_state_r",
        _UDI, _R, "-", describe(ProgramState, "program state"), ("E-04", "H-01"), _OWN,
    ),
    SignalTemplate(
        "bahn_state.program_number_r",
        _UDI, _R, "-", "number of the selected program (program table), 0 = none", ("E-04", "H-01"), _OWN,
    ),
    SignalTemplate(
        "bahn_state.block_nr_r",
        _UDI, _R, "-", "N number of the active block, 0 = none", ("E-04", "H-01"), _OWN,
    ),
    SignalTemplate(
        "bahn_state.line_nr_r",
        _UDI, _R, "-", "program line of the active block (1-based), 0 = none", ("E-04", "H-01"), _OWN,
    ),
    SignalTemplate(
        "bahn_state.feedhold_active_r",
        _B, _R, "-", "a hold is in effect (the feedhold unit or a monitor's hold: see hold_source_r)",
        ("E-05", "C43-04"), _OWN,
    ),
    SignalTemplate(
        "bahn_state.hold_source_r",
        _UDI, _R, "-", describe(HoldSource, "what holds the path (bits)"), ("E-05", "C43-04"), _OWN,
    ),
    SignalTemplate(
        "bahn_state.error_present_r", _B, _R, "-", "an error alarm is pending in the channel", ("H-01",), _OWN
    ),
    SignalTemplate(
        "bahn_state.error_id_r", _UDI, _R, "-", "number of the last error alarm, 0 = none", ("H-01",), _OWN
    ),
    SignalTemplate(
        "bahn_state.warning_id_r", _UDI, _R, "-", "number of the last warning, 0 = none", ("H-01",), _OWN
    ),
    SignalTemplate("bahn_state.alarm_count_r", _UDI, _R, "-", "number of pending alarms", ("H-01",), _OWN),
    SignalTemplate(
        "bahn_state.cycle_r",
        _UDI, _R, "cycles", "interpolation cycle counter (wraps around)", ("E-01",), _OWN,
    ),
    SignalTemplate(
        "bahn_state.kin_id_r",
        _UDI, _R, "-", "kinematic ID of the active transformation (#TRAFO ON), 0 = none", ("K-07",), _OWN,
    ),
    SignalTemplate(
        "bahn_state.trafo_active_r", _B, _R, "-", "a kinematic transformation is on (RTCP)", ("K-07",), _OWN
    ),
    SignalTemplate(
        "bahn_state.tcp_x_r",
        _DI, _R, "0.1 µm", "tool tip (TCP), first main axis, machine coordinates", ("K-07",), _OWN,
    ),
    SignalTemplate(
        "bahn_state.tcp_y_r",
        _DI, _R, "0.1 µm", "tool tip (TCP), second main axis, machine coordinates", ("K-07",), _OWN,
    ),
    SignalTemplate(
        "bahn_state.tcp_z_r",
        _DI, _R, "0.1 µm", "tool tip (TCP), third main axis, machine coordinates", ("K-07",), _OWN,
    ),
    # gpCh[i]^bahn_mc_control: control units
    *_unit_templates(
        "bahn_mc_control.suppress_area_mon_manual_mode",
        _B, "-", "suppress work area errors in manual mode", ("C14-22", "C14-20", "H-02"), _C14,
    ),
    *_unit_templates("bahn_mc_control.feedhold", _B, "-", "feedhold", ("E-05", "H-02"), _OWN),
    *_unit_templates("bahn_mc_control.override", _DI, "0.1 %", "feed override", ("E-05", "H-02"), _OWN),
    # gpCh[i]^mc_command: the PLC's operator panel
    SignalTemplate(
        "mc_command.mode_w", _UDI, _W, "-", describe(Mode, "requested mode"), ("E-03", "H-01"), _OWN
    ),
    SignalTemplate(
        "mc_command.program_select_w",
        _UDI, _W, "-", "program (number in the program table) to select when it changes, 0 = keep",
        ("E-04", "H-01"), _OWN,
    ),
    SignalTemplate(
        "mc_command.start_w", _B, _W, "-", "program start (rising edge)", ("E-04", "H-01"), _OWN
    ),
    SignalTemplate("mc_command.reset_w", _B, _W, "-", "channel reset (rising edge)", ("E-03", "H-01"), _OWN),
    SignalTemplate(
        "mc_command.probe_w", _B, _W, "-", "measuring input (probe) for G100 moves", ("C14-23",), _OWN
    ),
)  # fmt: skip
"""Per channel, in the field order of ``hli_server/engine/hli.py`` (a unit test keeps them in step)."""

AXIS_TEMPLATES: Final[tuple[SignalTemplate, ...]] = (
    # gpAx[i]^ipo_mc_control (FCT-C43 3.1.1)
    *_unit_templates(
        "ipo_mc_control.dyn_pos_limit_low",
        _DI, "{pos}", "dynamic lower position limit", ("C43-02", "C43-03", "H-02"), _C43,
        request="not supported by the kernel (always 0)", state=_DYNPL_STATE, state_unit="-",
    ),
    *_unit_templates(
        "ipo_mc_control.dyn_pos_limit_high",
        _DI, "{pos}", "dynamic upper position limit", ("C43-02", "C43-03", "H-02"), _C43,
        request="not supported by the kernel (always 0)", state=_DYNPL_STATE, state_unit="-",
    ),
    # gpAx[i]^ipo_state
    SignalTemplate(
        "ipo_state.cmd_pos_r", _DI, _R, "{pos}", "commanded position (setpoint)", ("E-02", "H-01"), _OWN
    ),
    SignalTemplate("ipo_state.act_pos_r", _DI, _R, "{pos}", "actual position", ("E-02", "H-01"), _OWN),
    SignalTemplate("ipo_state.velocity_r", _DI, _R, "{pos}/s", "actual velocity", ("E-02", "H-01"), _OWN),
    SignalTemplate(
        "ipo_state.following_error_r",
        _DI, _R, "{pos}", "following error (setpoint - actual)", ("E-02", "A3-02"), _OWN,
    ),
    SignalTemplate(
        "ipo_state.referenced_r", _B, _R, "-", "axis is referenced (homed)", ("E-02", "C3-06"), _OWN
    ),
    SignalTemplate(
        "ipo_state.referencing_r", _B, _R, "-", "the referencing (homing) move runs", ("E-02", "C3-06"), _OWN
    ),
    SignalTemplate(
        "ipo_state.in_position_r",
        _B, _R, "-", "actual position inside the exact-stop window P-AXIS-00236", ("A3-02",), _OWN,
    ),
    SignalTemplate("ipo_state.moving_r", _B, _R, "-", "the setpoint is moving", ("E-02",), _OWN),
    SignalTemplate("ipo_state.error_r", _B, _R, "-", "an axis error is pending", ("E-02", "A3-04"), _OWN),
    # gpAx[i]^manual
    SignalTemplate("manual.jog_plus_w", _B, _W, "-", "jog key + (manual mode)", ("E-05", "C14-19"), _OWN),
    SignalTemplate("manual.jog_minus_w", _B, _W, "-", "jog key - (manual mode)", ("E-05", "C14-19"), _OWN),
    SignalTemplate(
        "manual.reference_w",
        _B, _W, "-", "reference (home) the axis (rising edge; no program may run)", ("E-02", "C3-06"), _OWN,
    ),
    # dyn_coll_mon: the CNC objects of FCT-C3 4.3 (read-only; ADS port 551, group 0x120300)
    SignalTemplate(
        "dyn_coll_mon.active", _B, _R, "-", "dynamic collision monitoring is active", ("C3-10",), _C3,
        ads_element=0x0234,
    ),
    SignalTemplate(
        "dyn_coll_mon.velocity", _LR, _R, "{pos}/s", "collision monitoring: current velocity",
        ("C3-10",), _C3,
        ads_element=0x0244,
    ),
    SignalTemplate(
        "dyn_coll_mon.brake_dist", _LR, _R, "{pos}", "collision monitoring: current braking distance",
        ("C3-10",), _C3, ads_element=0x0245,
    ),
    SignalTemplate(
        "dyn_coll_mon.coll_offset", _UDI, _R, "{pos}", "collision monitoring: distance between the axes",
        ("C3-10",), _C3, ads_element=0x0246,
    ),
    SignalTemplate(
        "dyn_coll_mon.deceleration", _LR, _R, "{acc}", "collision monitoring: deceleration on collision",
        ("C3-10",), _C3, ads_element=0x0247,
    ),
)  # fmt: skip
"""Per axis, in the field order of ``hli_server/engine/hli.py`` (a unit test keeps them in step)."""


# --------------------------------------------------------------------------------------------
# Blocks: where each template lands inside a channel or axis block
# --------------------------------------------------------------------------------------------


def _round_up(value: int, step: int) -> int:
    return -(-value // step) * step


@dataclass(frozen=True, slots=True)
class _Placed:
    template: SignalTemplate
    offset: int
    """byte offset inside the block of its half"""
    modbus: int
    """address inside the block of its Modbus table"""


@dataclass(frozen=True, slots=True)
class _Block:
    placed: tuple[_Placed, ...]
    size: dict[Direction, int]
    """bytes per half, rounded up to 8 (the stride of the block in that half)"""


def _place(templates: Sequence[SignalTemplate], what: str) -> _Block:
    """Natural alignment in the image (a field never straddles its own size), Modbus values of
    two/four registers at even/multiple-of-four addresses inside the block."""
    byte_cursor = dict.fromkeys(Direction, 0)
    modbus_cursor = dict.fromkeys(ModbusTable, 0)
    placed = []
    seen: set[str] = set()
    for t in templates:
        if t.path in seen:
            raise LayoutError(f"{what} template {t.path!r} is listed twice")
        seen.add(t.path)
        leaf = t.path.rsplit(".", 1)[-1]
        if leaf.endswith("_w") and t.direction is not Direction.PLC_TO_CNC:
            raise LayoutError(f"{what} template {t.path}: a _w field must be PLC->CNC (H-02)")
        if leaf.endswith("_r") and t.direction is not Direction.CNC_TO_PLC:
            raise LayoutError(f"{what} template {t.path}: a _r field must be CNC->PLC (H-02)")
        size = t.type.size
        offset = _round_up(byte_cursor[t.direction], size)
        byte_cursor[t.direction] = offset + size
        table = _modbus_table(t.type, t.direction)
        count = t.type.modbus_count
        address = _round_up(modbus_cursor[table], count)
        modbus_cursor[table] = address + count
        if modbus_cursor[table] > MODBUS_BLOCK_STRIDE:
            raise LayoutError(f"{what} block overflows the Modbus stride {MODBUS_BLOCK_STRIDE} in {table}")
        placed.append(_Placed(t, offset, address))
    return _Block(tuple(placed), {d: _round_up(byte_cursor[d], _ALIGN_BLOCK) for d in Direction})


_CHANNEL_BLOCK: Final = _place(CHANNEL_TEMPLATES, "channel")
_AXIS_BLOCK: Final = _place(AXIS_TEMPLATES, "axis")


def _axis_area_start(direction: Direction) -> int:
    return MAX_CHANNELS * _CHANNEL_BLOCK.size[direction]


# --------------------------------------------------------------------------------------------
# Signals and the layout
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Signal:
    """One signal of the image with all its addresses (H-08).

    ``offset`` is the byte offset in its half; ``index`` is the 0-based channel or axis index of
    the ST path (``gpCh[index]``/``gpAx[index]``); ``path`` is the template path below it.
    """

    name: str
    st_path: str
    scope: Scope
    index: int
    path: str
    type: SignalType
    direction: Direction
    unit: str
    description: str
    reqs: tuple[str, ...]
    origin: str
    offset: int
    modbus_table: ModbusTable
    modbus_address: int
    ads_port: int
    ads_group: int
    ads_offset: int
    limits: tuple[float, float] | None = None
    """The values a V.E. variable takes, where its kernel type is narrower than the field (an SGN16 in
    a DINT) or a real must be finite; None: the field type's own range."""
    string_size: int = 0
    """A STRING field's bytes, the terminating NUL included (``STRING(n)``: n + 1); 0 for the others."""
    structures: tuple[str, ...] = ()
    """A V.E. variable's element inside structures: the structure type of each level of its path but
    the last (``("typcurve", "typ_pos")`` for ``curve[2].point[5].X``); the ADS door names its types
    so."""

    @property
    def size(self) -> int:
        return self.string_size or _TYPE_SIZE[self.type]

    @property
    def alignment(self) -> int:
        """A number is aligned to its size, a STRING to one byte."""
        return 1 if self.string_size else _TYPE_SIZE[self.type]

    @property
    def struct_char(self) -> str:
        """The ``struct`` format of the field: ``i``, ``d``, ..., ``21s`` for a STRING(20)."""
        return f"{self.string_size}s" if self.string_size else _TYPE_CHAR[self.type]

    @property
    def type_name(self) -> str:
        """The IEC type as the PLC declares it: ``DINT``, ``STRING(20)``."""
        return f"STRING({self.string_size - 1})" if self.string_size else self.type.value

    @property
    def modbus_count(self) -> int:
        if self.string_size:
            return (self.string_size + 1) // 2
        return self.type.modbus_count

    @property
    def plc_writable(self) -> bool:
        return self.direction is Direction.PLC_TO_CNC

    @property
    def access(self) -> str:
        """The PLC's access: ``read/write`` for PLC->CNC fields, ``read`` for CNC->PLC (H-02)."""
        return "read/write" if self.plc_writable else "read"

    @property
    def symbol(self) -> str:
        """ADS symbol name: the ST path."""
        return self.st_path

    @property
    def engine_path(self) -> str:
        """Attribute path below ``MachineHli``: ``axes[1].ipo_mc_control.dyn_pos_limit_low.command_w``;
        a V.E. variable's element in the engine's store: ``external[ch1].V.E.name[2]``."""
        if self.scope.external:
            area = "global" if self.scope is Scope.VE_GLOBAL else f"channel index {self.index}"
            return f"external[{area}].V.E.{self.path}"
        container = "channels" if self.scope is Scope.CHANNEL else "axes"
        return f"{container}[{self.index}].{self.path}"

    @property
    def external_element(self) -> tuple[str, tuple[int, ...]]:
        """A V.E. signal's leaf name and element index: ``("POS", (1, 2))`` for ``POS[1,2]``,
        ``("curve.point.X", (2, 5))`` for ``curve[2].point[5].X`` (schemas/external_types.py)."""
        if not self.scope.external:
            raise ValueError(f"{self.st_path} is no V.E. variable")
        names: list[str] = []
        index: list[int] = []
        for part in self.path.split("."):
            name, _, rest = part.partition("[")
            names.append(name)
            if rest:
                index += (int(i) for i in rest.rstrip("]").split(","))
        return ".".join(names), tuple(index)

    @property
    def image_ads_group(self) -> int:
        """Index group of the signal's half on :data:`ADS_PORT_HLI` (raw reads of a half cover it)."""
        return ADS_GROUP_PLC_TO_CNC if self.plc_writable else ADS_GROUP_CNC_TO_PLC

    def coerce(self, value: object) -> bool | int | float | str:
        """Check a value for this signal and return it in the signal's Python type.

        BOOL takes ``bool`` or the integers 0/1; DINT/UDINT take integers in range (no bool,
        no float); LREAL takes int or float; STRING a ``str`` of at most ``string_size - 1``
        Windows-1252 characters without NUL.
        """
        t = self.type
        if t is SignalType.STRING:
            return self._coerce_string(value)
        if t is SignalType.BOOL:
            if isinstance(value, bool):
                return value
            if isinstance(value, int) and value in (0, 1):
                return bool(value)
            raise SignalValueError(f"{self.st_path}: BOOL takes True/False or 0/1, got {value!r}")
        if t is SignalType.LREAL:
            if not isinstance(value, (int, float)) or isinstance(value, bool):
                raise SignalValueError(f"{self.st_path}: LREAL takes a number, got {value!r}")
            real = float(value)
            if self.limits is not None and not self.limits[0] <= real <= self.limits[1]:
                raise SignalValueError(
                    f"{self.st_path}: {value} is out of range for the V.E. variable "
                    f"[{self.limits[0]:.7g}, {self.limits[1]:.7g}] (finite numbers only)"
                )
            return real
        if not isinstance(value, int) or isinstance(value, bool):
            raise SignalValueError(f"{self.st_path}: {t} takes an integer, got {value!r}")
        low, high = self.limits or _INT_RANGE[t]
        if not low <= value <= high:
            what = "the V.E. variable" if self.limits else str(t)
            raise SignalValueError(f"{self.st_path}: {value} is out of range for {what} [{low}, {high}]")
        return value

    def _coerce_string(self, value: object) -> str:
        if not isinstance(value, str):
            raise SignalValueError(f"{self.st_path}: {self.type_name} takes a string, got {value!r}")
        try:
            raw = value.encode(STRING_ENCODING)
        except UnicodeEncodeError as exc:
            raise SignalValueError(
                f"{self.st_path}: {value[exc.start : exc.end]!r} is no Windows-1252 character "
                f"({self.type_name} holds Windows-1252 text)"
            ) from None
        if b"\0" in raw:
            raise SignalValueError(f"{self.st_path}: a {self.type_name} ends at its first NUL; none inside")
        if len(raw) >= self.string_size:
            raise SignalValueError(
                f"{self.st_path}: {len(raw)} characters, a {self.type_name} holds at most "
                f"{self.string_size - 1}"
            )
        return value

    def encode(self, value: bool | int | float | str) -> bool | int | float | bytes:
        """A coerced value as ``struct`` packs it with :attr:`struct_char` (a STRING's bytes, which the
        pack pads with NUL to the field)."""
        if isinstance(value, str):
            return value.encode(STRING_ENCODING)
        return value

    def decode(self, raw: bool | int | float | bytes) -> bool | int | float | str:
        """A value as ``struct`` unpacked it with :attr:`struct_char`, in the signal's Python type: a
        STRING's bytes up to the first NUL as text. :class:`SignalValueError` for a STRING field
        without a NUL (one character too many) or with a byte that is no Windows-1252 character."""
        if not isinstance(raw, bytes):
            return raw
        text, nul, _ = raw.partition(b"\0")
        if not nul:
            raise SignalValueError(
                f"{self.st_path}: no NUL in the {self.string_size} bytes of the field: a {self.type_name} "
                f"holds at most {self.string_size - 1} characters"
            )
        try:
            return text.decode(STRING_ENCODING)
        except UnicodeDecodeError as exc:
            raise SignalValueError(
                f"{self.st_path}: byte 0x{text[exc.start]:02X} is no Windows-1252 character"
            ) from None

    def check_plc_write(self) -> None:
        """Raise :class:`ReadOnlySignalError` unless the PLC may write this field (H-02)."""
        if not self.plc_writable:
            raise ReadOnlySignalError(
                f"{self.st_path} is CNC->PLC: only the CNC writes it (H-02). "
                "The PLC writes the _w fields (command_w, enable_w, ...) and reads the _r fields."
            )


@dataclass(frozen=True, slots=True)
class ChannelInfo:
    index: int
    number: int
    name: str
    axes: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class AxisInfo:
    index: int
    number: int
    """logical axis number A_ID (kopf.achs_nr)"""
    name: str
    axis_type: str
    """T translatory, R rotary"""


_SIGNAL_KEYS: Final = (
    "name",
    "st_path",
    "scope",
    "index",
    "path",
    "type",
    "direction",
    "unit",
    "description",
    "reqs",
    "origin",
    "offset",
    "modbus_table",
    "modbus_address",
    "ads_port",
    "ads_group",
    "ads_offset",
    "limits",
    "string_size",
    "structures",
)


class LayoutChannel(TypedDict):
    index: int
    number: int
    name: str
    axes: list[str]


class LayoutAxis(TypedDict):
    index: int
    number: int
    name: str
    axis_type: str


class LayoutSignal(TypedDict):
    """One field of the image (:class:`Signal`): where it is in the halves, in the Modbus tables, over ADS."""

    name: str
    st_path: str
    scope: str
    index: int
    path: str
    type: str
    direction: str
    unit: str
    description: str
    reqs: list[str]
    origin: str
    offset: int
    modbus_table: str
    modbus_address: int
    ads_port: int
    ads_group: int
    ads_offset: int
    limits: list[int | float] | None  # as written (an int stays an int: the hash sees -128 and -128.0 apart)
    string_size: int
    structures: list[str]
    size: int
    access: str
    symbol: str
    modbus_count: int
    modbus_reference: str
    image_ads_group: int


class LayoutJson(TypedDict):
    """:meth:`Layout.to_dict`: the machine-readable contract (H-08), ``hli-server map --format json`` and
    ``GET /api/layout``."""

    format: str
    layout_version: int
    layout_hash: str
    machine: str
    sizes: dict[str, int]
    addressing: dict[str, int]
    channels: list[LayoutChannel]
    axes: list[LayoutAxis]
    signals: list[LayoutSignal]


_HASHED_KEYS: Final = (
    "st_path",
    "type",
    "direction",
    "unit",
    "offset",
    "modbus_table",
    "modbus_address",
    "ads_port",
    "ads_group",
    "ads_offset",
    "limits",
    "string_size",
)
"""What the layout hash covers: everything a peer relies on to read and write the right bytes.
Names, descriptions, requirement IDs and origins are documentation and do not change it."""


class Layout:
    """The expanded table: all signals of one machine, with lookups and derived formats.

    Immutable once built. Build it with :func:`build_layout` (server, tools, tests) or
    :meth:`from_json` (a client that takes the layout from the image it attaches to).
    """

    def __init__(
        self,
        *,
        machine: str,
        channels: Sequence[ChannelInfo],
        axes: Sequence[AxisInfo],
        signals: Sequence[Signal],
        sizes: Mapping[Direction, int],
        version: int = LAYOUT_VERSION,
    ) -> None:
        self.machine = machine
        self.version = version
        self.channels: tuple[ChannelInfo, ...] = tuple(channels)
        self.axes: tuple[AxisInfo, ...] = tuple(axes)
        self.signals: tuple[Signal, ...] = tuple(signals)
        self._sizes = dict(sizes)
        self._by_path = {s.st_path: s for s in self.signals}
        if len(self._by_path) != len(self.signals):
            raise LayoutError("two signals share an ST path")
        self._check_overlaps()

    # --- lookups -------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.signals)

    def __iter__(self) -> Iterator[Signal]:
        return iter(self.signals)

    def __contains__(self, st_path: object) -> bool:
        return st_path in self._by_path

    def signal(self, st_path: str) -> Signal:
        """The signal of an ST path (``gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w``)."""
        try:
            return self._by_path[st_path]
        except KeyError:
            close = difflib.get_close_matches(st_path, self._by_path, n=3, cutoff=0.6)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise UnknownSignalError(
                f"no signal {st_path!r} in the layout of machine {self.machine!r} "
                f"({len(self.channels)} channels, {len(self.axes)} axes){hint} "
                "(`hli-server map` lists them all)"
            ) from None

    def half(self, direction: Direction) -> tuple[Signal, ...]:
        """The signals of one half in byte order."""
        return self._halves[direction]

    def hli_half(self, direction: Direction) -> tuple[Signal, ...]:
        """The HLI signals (channels and axes, the objects of ``MachineHli``) of one half in byte
        order: the half without its V.E. area."""
        return self._hli_halves[direction]

    @cached_property
    def _hli_halves(self) -> dict[Direction, tuple[Signal, ...]]:
        return {d: tuple(s for s in self.half(d) if not s.scope.external) for d in Direction}

    @cached_property
    def external_signals(self) -> tuple[Signal, ...]:
        """The V.E. variables' elements (N-05) in byte order: global area first, then each channel's."""
        return tuple(s for s in self.half(Direction.PLC_TO_CNC) if s.scope.external)

    def size(self, direction: Direction) -> int:
        """Bytes of one half (a multiple of 8)."""
        return self._sizes[direction]

    @property
    def p2c_size(self) -> int:
        return self._sizes[Direction.PLC_TO_CNC]

    @property
    def c2p_size(self) -> int:
        return self._sizes[Direction.CNC_TO_PLC]

    @cached_property
    def _halves(self) -> dict[Direction, tuple[Signal, ...]]:
        return {
            d: tuple(sorted((s for s in self.signals if s.direction is d), key=lambda s: s.offset))
            for d in Direction
        }

    def signals_in_range(self, direction: Direction, offset: int, size: int) -> tuple[Signal, ...]:
        """The signals of a byte range of a half (for raw ADS access). A range must not cut a field
        and must lie inside the half; padding bytes in it are allowed."""
        end = offset + size
        if offset < 0 or size < 0 or end > self.size(direction):
            raise LayoutError(
                f"bytes {offset}..{end} lie outside the {direction} half (0..{self.size(direction)})"
            )
        found = []
        for s in self.half(direction):
            s_end = s.offset + s.size
            if s_end <= offset or s.offset >= end:
                continue
            if s.offset < offset or s_end > end:
                raise LayoutError(
                    f"bytes {offset}..{end} cut {s.st_path} (bytes {s.offset}..{s_end}): "
                    "access whole fields only"
                )
            found.append(s)
        return tuple(found)

    @cached_property
    def reference_digits(self) -> int:
        """5 (40001 style) while every address fits, else 6 (400001 style) for the whole map."""
        highest = max((s.modbus_address + s.modbus_count for s in self.signals), default=0)
        return 5 if highest <= 9999 else 6

    def modbus_reference(self, signal: Signal) -> str:
        """The 1-based reference of the first register/bit: ``40001`` for holding address 0."""
        width = self.reference_digits - 1
        return f"{signal.modbus_table.reference_prefix}{signal.modbus_address + 1:0{width}d}"

    def modbus_index(self, table: ModbusTable) -> dict[int, tuple[Signal, int]]:
        """Every occupied address of a table -> (signal, number of the register inside the value)."""
        index: dict[int, tuple[Signal, int]] = {}
        for s in self.signals:
            if s.modbus_table is table:
                for k in range(s.modbus_count):
                    index[s.modbus_address + k] = (s, k)
        return index

    def ads_index(self) -> dict[tuple[int, int, int], Signal]:
        """(port, index group, index offset) -> signal, for the signals' own ADS addresses."""
        return {(s.ads_port, s.ads_group, s.ads_offset): s for s in self.signals}

    def control_units(self) -> dict[str, tuple[Signal, ...]]:
        """ST path of each control unit -> its four fields in the kernel's order (H-02)."""
        units: dict[str, list[Signal]] = {}
        for s in self.signals:
            head, _, leaf = s.st_path.rpartition(".")
            if leaf in ("request_r", "enable_w", "command_w", "state_r"):
                units.setdefault(head, []).append(s)
        return {k: tuple(v) for k, v in units.items()}

    # --- derived binary formats ----------------------------------------------------------
    def struct_format(self, direction: Direction) -> str:
        """``struct`` format of one half, little-endian with explicit padding."""
        parts = ["<"]
        cursor = 0
        for s in self.half(direction):
            if s.offset > cursor:
                parts.append(f"{s.offset - cursor}x")
            parts.append(s.struct_char)
            cursor = s.offset + s.size
        if self.size(direction) > cursor:
            parts.append(f"{self.size(direction) - cursor}x")
        return "".join(parts)

    def struct(self, direction: Direction) -> Struct:
        """Precompiled ``Struct`` of one half (values in :meth:`half` order)."""
        compiled = Struct(self.struct_format(direction))
        if compiled.size != self.size(direction):  # pragma: no cover - guarded by construction
            raise LayoutError(f"{direction} format size {compiled.size} != half size {self.size(direction)}")
        return compiled

    @cached_property
    def _structs(self) -> dict[Direction, Struct]:
        return {d: self.struct(d) for d in Direction}

    def unpack(self, direction: Direction, data: bytes | bytearray | memoryview) -> dict[str, Any]:
        """Decode a copy of one half: ST path -> value (bool, int, float or, for a STRING, str)."""
        values = self._structs[direction].unpack_from(data)
        half = self.half(direction)
        if direction is Direction.PLC_TO_CNC and self._has_strings:
            return {s.st_path: s.decode(v) for s, v in zip(half, values, strict=True)}
        return dict(zip((s.st_path for s in half), values, strict=True))

    @cached_property
    def _has_strings(self) -> bool:
        return any(s.string_size for s in self.signals)

    def pack(self, direction: Direction, values: Mapping[str, object]) -> bytes:
        """Encode one half from ST path -> value; missing fields are zero. Values are checked."""
        unknown = set(values) - {s.st_path for s in self.half(direction)}
        if unknown:
            raise UnknownSignalError(f"not in the {direction} half: {sorted(unknown)[:5]}")
        half = self.half(direction)
        args = [s.encode(s.coerce(values[s.st_path]) if s.st_path in values else _ZERO[s.type]) for s in half]
        packed: bytes = self._structs[direction].pack(*args)
        return packed

    def construct(self, direction: Direction) -> Any:
        """``conStruct`` of one half; the keys are the ST paths (for parsing, docs, tests)."""
        fields: list[Any] = []
        cursor = 0
        for s in self.half(direction):
            if s.offset > cursor:
                fields.append(cs.Padding(s.offset - cursor))
            kind = _construct_string(s.size) if s.string_size else _CONSTRUCT_TYPE[s.type]
            fields.append(s.st_path / kind)
            cursor = s.offset + s.size
        if self.size(direction) > cursor:
            fields.append(cs.Padding(self.size(direction) - cursor))
        return cs.Struct(*fields)

    # --- identity and export -------------------------------------------------------------
    @cached_property
    def hash(self) -> str:
        """SHA-256 (hex) of the addressing content: version, half sizes and, per signal,
        :data:`_HASHED_KEYS`. Stable across Python versions and runs."""
        content = {
            "version": self.version,
            "sizes": {d.value: self._sizes[d] for d in Direction},
            "signals": [[_plain(getattr(s, k)) for k in _HASHED_KEYS] for s in self.signals],
        }
        text = json.dumps(content, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
        return hashlib.sha256(text.encode("ascii")).hexdigest()

    def to_dict(self) -> LayoutJson:
        """The machine-readable contract (H-08): everything needed to rebuild this layout."""
        return {
            "format": LAYOUT_FORMAT,
            "layout_version": self.version,
            "layout_hash": self.hash,
            "machine": self.machine,
            "sizes": {d.value: self._sizes[d] for d in Direction},
            "addressing": {
                "max_channels": MAX_CHANNELS,
                "modbus_channel_base": MODBUS_CHANNEL_BASE,
                "modbus_axis_base": MODBUS_AXIS_BASE,
                "modbus_block_stride": MODBUS_BLOCK_STRIDE,
                "modbus_reference_digits": self.reference_digits,
                "ads_port_hli": ADS_PORT_HLI,
                "ads_group_plc_to_cnc": ADS_GROUP_PLC_TO_CNC,
                "ads_group_cnc_to_plc": ADS_GROUP_CNC_TO_PLC,
                "ads_port_geo": ADS_PORT_GEO,
                "ads_group_geo_axis": ADS_GROUP_GEO_AXIS,
            },
            "channels": [
                {"index": c.index, "number": c.number, "name": c.name, "axes": list(c.axes)}
                for c in self.channels
            ],
            "axes": [
                {"index": a.index, "number": a.number, "name": a.name, "axis_type": a.axis_type}
                for a in self.axes
            ],
            "signals": [self._signal_dict(s) for s in self.signals],
        }

    def _signal_dict(self, s: Signal) -> LayoutSignal:
        d: dict[str, Any] = {k: _plain(getattr(s, k)) for k in _SIGNAL_KEYS}
        d.update(
            size=s.size,
            access=s.access,
            symbol=s.symbol,
            modbus_count=s.modbus_count,
            modbus_reference=self.modbus_reference(s),
            image_ads_group=s.image_ads_group,
        )
        return cast(LayoutSignal, d)

    def to_json(self, indent: int | None = 1) -> str:
        return json.dumps(self.to_dict(), indent=indent, ensure_ascii=False)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Layout:
        """Rebuild a layout from :meth:`to_dict`; the stored hash must match the content."""
        if data.get("format") != LAYOUT_FORMAT:
            raise LayoutError(f"not a layout: format is {data.get('format')!r}, expected {LAYOUT_FORMAT!r}")
        try:
            signals = [
                Signal(
                    name=d["name"],
                    st_path=d["st_path"],
                    scope=Scope(d["scope"]),
                    index=int(d["index"]),
                    path=d["path"],
                    type=SignalType(d["type"]),
                    direction=Direction(d["direction"]),
                    unit=d["unit"],
                    description=d["description"],
                    reqs=tuple(d["reqs"]),
                    origin=d["origin"],
                    offset=int(d["offset"]),
                    modbus_table=ModbusTable(d["modbus_table"]),
                    modbus_address=int(d["modbus_address"]),
                    ads_port=int(d["ads_port"]),
                    ads_group=int(d["ads_group"]),
                    ads_offset=int(d["ads_offset"]),
                    limits=_limits(d.get("limits")),
                    string_size=int(d.get("string_size", 0)),
                    structures=tuple(str(n) for n in d.get("structures", ())),
                )
                for d in data["signals"]
            ]
            layout = cls(
                machine=data["machine"],
                channels=[
                    ChannelInfo(int(c["index"]), int(c["number"]), c["name"], tuple(c["axes"]))
                    for c in data["channels"]
                ],
                axes=[
                    AxisInfo(int(a["index"]), int(a["number"]), a["name"], a["axis_type"])
                    for a in data["axes"]
                ],
                signals=signals,
                sizes={Direction(k): int(v) for k, v in data["sizes"].items()},
                version=int(data["layout_version"]),
            )
        except LayoutError as exc:
            raise LayoutError(f"damaged layout JSON: {exc}") from exc
        except (KeyError, TypeError, ValueError) as exc:
            raise LayoutError(f"damaged layout JSON: {exc!r}") from exc
        if layout.hash != data.get("layout_hash"):
            raise LayoutError(
                f"layout JSON hash {data.get('layout_hash')!r} does not match its content ({layout.hash}): "
                "the file was edited or damaged; export it again with `hli-server map --format json`"
            )
        return layout

    @classmethod
    def from_json(cls, text: str | bytes) -> Layout:
        try:
            data = json.loads(text)
        except ValueError as exc:
            raise LayoutError(f"layout JSON does not parse: {exc}") from exc
        if not isinstance(data, dict):
            raise LayoutError("layout JSON must be an object")
        return cls.from_dict(data)

    def __repr__(self) -> str:
        return (
            f"Layout(machine={self.machine!r}, channels={len(self.channels)}, axes={len(self.axes)}, "
            f"signals={len(self.signals)}, p2c={self.p2c_size} B, c2p={self.c2p_size} B, "
            f"hash={self.hash[:12]})"
        )

    def _check_overlaps(self) -> None:
        """No two signals share bytes of a half, Modbus addresses of a table, or an ADS address."""
        for d in Direction:
            end = 0
            for s in self.half(d):
                if s.offset < end or s.offset % s.alignment:
                    raise LayoutError(f"{s.st_path}: offset {s.offset} overlaps or is misaligned")
                end = s.offset + s.size
            if end > self._sizes[d]:
                raise LayoutError(f"{d} half ({self._sizes[d]} bytes) is too small for its signals ({end})")
        for table in ModbusTable:
            taken: set[int] = set()
            for s in self.signals:
                if s.modbus_table is table:
                    span = set(range(s.modbus_address, s.modbus_address + s.modbus_count))
                    if span & taken or s.modbus_address + s.modbus_count > 65536:
                        raise LayoutError(f"{s.st_path}: Modbus {table} address {s.modbus_address} collides")
                    taken |= span
        if len(self.ads_index()) != len(self.signals):
            raise LayoutError("two signals share an ADS address")


_ZERO: Final[dict[SignalType, bool | int | float | str]] = {
    SignalType.BOOL: False,
    SignalType.DINT: 0,
    SignalType.UDINT: 0,
    SignalType.LREAL: 0.0,
    SignalType.STRING: "",
}

_CONSTRUCT_TYPE: Final[dict[SignalType, Any]] = {
    SignalType.BOOL: cs.Flag,
    SignalType.DINT: cs.Int32sl,
    SignalType.UDINT: cs.Int32ul,
    SignalType.LREAL: cs.Float64l,
}


def _construct_string(size: int) -> Any:
    """A STRING field for ``construct``: Windows-1252 up to the first NUL, NUL-padded (construct's own
    string types know no Windows-1252)."""
    return cs.ExprAdapter(
        cs.Bytes(size),
        lambda raw, _: bytes(raw).partition(b"\0")[0].decode(STRING_ENCODING),
        lambda text, _: text.encode(STRING_ENCODING).ljust(size, b"\0"),
    )


def _limits(raw: Any) -> tuple[float, float] | None:
    if raw is None:
        return None
    low, high = raw
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in (low, high)):
        raise TypeError(f"limits must be two numbers, got {raw!r}")
    return low, high  # as written: the hash sees -128 and -128.0 apart


def _plain(value: object) -> object:
    if isinstance(value, StrEnum):
        return value.value
    if isinstance(value, tuple):
        return list(value)
    return value


def _resolve_unit(unit: str, axis_type: str) -> str:
    rotary = axis_type == "R"
    return unit.replace("{pos}", "0.0001°" if rotary else "0.1 µm").replace(
        "{acc}", "°/s²" if rotary else "mm/s²"
    )


class ChannelShape(Protocol):
    """What the layout reads of a channel (:class:`~schemas.config.ChannelConfig`)."""

    @property
    def number(self) -> int: ...
    @property
    def name(self) -> str: ...
    @property
    def axes(self) -> Sequence[str]: ...


class AxisShape(Protocol):
    """What the layout reads of an axis (:class:`~schemas.config.AxisConfig`)."""

    @property
    def number(self) -> int: ...
    @property
    def name(self) -> str: ...
    @property
    def axis_type(self) -> StrEnum: ...


ExternalVariableShape = VariableShape
"""What the layout reads of a V.E. variable (:class:`~schemas.config.ExternalVariableConfig`): its
declaration (schemas/external_types.py)."""


class MachineShape(ExternalShape, Protocol):
    """What the layout reads of a machine: :class:`~schemas.config.MachineConfig` is one. The layout does
    not import the configuration (the configuration imports the layout: :func:`check_external_fits`). Its
    V.E. declarations (variables, structures, the STRING length) are an :class:`ExternalShape`."""

    @property
    def name(self) -> str: ...
    @property
    def channels(self) -> Sequence[ChannelShape]: ...
    @property
    def axes(self) -> Sequence[AxisShape]: ...


def build_layout(config: MachineShape) -> Layout:
    """Expand the templates for the channels and axes of ``config`` (H-01, H-08).

    Channel ``i`` and axis ``j`` are the positions in ``config.channels`` / ``config.axes``
    (0-based, the ``gpCh[i]``/``gpAx[j]`` indices); the logical axis number A_ID addresses the
    dyn_coll_mon objects over ADS.
    """
    if len(config.channels) > MAX_CHANNELS:
        raise LayoutError(f"{len(config.channels)} channels: the image has slots for {MAX_CHANNELS}")
    if len(config.axes) > MAX_AXES:
        raise LayoutError(
            f"{len(config.axes)} axes: the Modbus map has blocks for {MAX_AXES} "
            f"(base {MODBUS_AXIS_BASE}, stride {MODBUS_BLOCK_STRIDE})"
        )
    signals: list[Signal] = []
    for i, ch in enumerate(config.channels):
        for p in _CHANNEL_BLOCK.placed:
            t = p.template
            base = _CHANNEL_BLOCK.size[t.direction] * i
            offset = base + p.offset
            signals.append(
                _signal(
                    t,
                    name=f"ch{ch.number}.{t.path}",
                    st_path=f"gpCh[{i}]^{t.path}",
                    scope=Scope.CHANNEL,
                    index=i,
                    unit=_resolve_unit(t.unit, "T"),
                    offset=offset,
                    modbus_address=MODBUS_CHANNEL_BASE + MODBUS_BLOCK_STRIDE * i + p.modbus,
                    ads=(ADS_PORT_HLI, _hli_group(t.direction), offset),
                )
            )
    for j, ax in enumerate(config.axes):
        a_id = ax.number
        if a_id > 0xFFFF:
            raise LayoutError(
                f"axis {ax.name}: logical axis number {a_id} does not fit the 16 bits the ADS index "
                "offset of the dyn_coll_mon objects has for it (FCT-C3 4.3); use numbers up to 65535"
            )
        for p in _AXIS_BLOCK.placed:
            t = p.template
            offset = _axis_area_start(t.direction) + _AXIS_BLOCK.size[t.direction] * j + p.offset
            if t.ads_element is not None:
                ads = (ADS_PORT_GEO, ADS_GROUP_GEO_AXIS, (a_id << 16) | t.ads_element)
            else:
                ads = (ADS_PORT_HLI, _hli_group(t.direction), offset)
            signals.append(
                _signal(
                    t,
                    name=f"{ax.name}.{t.path}",
                    st_path=f"gpAx[{j}]^{t.path}",
                    scope=Scope.AXIS,
                    index=j,
                    unit=_resolve_unit(t.unit, str(ax.axis_type.value)),
                    offset=offset,
                    modbus_address=MODBUS_AXIS_BASE + MODBUS_BLOCK_STRIDE * j + p.modbus,
                    ads=ads,
                )
            )
    sizes = {
        d: _axis_area_start(d) + _AXIS_BLOCK.size[d] * len(config.axes)  # multiples of 8 already
        for d in Direction
    }
    external, p2c_end = _external_signals(config, sizes[Direction.PLC_TO_CNC])
    signals.extend(external)
    sizes[Direction.PLC_TO_CNC] = _round_up(p2c_end, _ALIGN_BLOCK)
    return Layout(
        machine=config.name,
        channels=[ChannelInfo(i, c.number, c.name, tuple(c.axes)) for i, c in enumerate(config.channels)],
        axes=[AxisInfo(j, a.number, a.name, str(a.axis_type.value)) for j, a in enumerate(config.axes)],
        signals=signals,
        sizes=sizes,
    )


def _hli_group(direction: Direction) -> int:
    return ADS_GROUP_PLC_TO_CNC if direction is Direction.PLC_TO_CNC else ADS_GROUP_CNC_TO_PLC


def _signal(
    t: SignalTemplate,
    *,
    name: str,
    st_path: str,
    scope: Scope,
    index: int,
    unit: str,
    offset: int,
    modbus_address: int,
    ads: tuple[int, int, int],
) -> Signal:
    return Signal(
        name=name,
        st_path=st_path,
        scope=scope,
        index=index,
        path=t.path,
        type=t.type,
        direction=t.direction,
        unit=unit,
        description=t.description,
        reqs=t.reqs,
        origin=t.origin,
        offset=offset,
        modbus_table=_modbus_table(t.type, t.direction),
        modbus_address=modbus_address,
        ads_port=ads[0],
        ads_group=ads[1],
        ads_offset=ads[2],
    )


# --------------------------------------------------------------------------------------------
# V.E. variables (N-05)
# --------------------------------------------------------------------------------------------


def _external_order(
    config: MachineShape,
) -> list[tuple[int | None, VariableShape, TypeNode]]:
    """(channel index or None, variable, its type): the global area first, then each channel's area in
    the order of ``config.channels``; inside an area the order of the machine file."""
    _, types = machine_types(config)
    typed = list(zip(config.external_variables, types, strict=True))
    ordered: list[tuple[int | None, VariableShape, TypeNode]] = [
        (None, v, t) for v, t in typed if v.channel is None
    ]
    for i, ch in enumerate(config.channels):
        ordered += [(i, v, t) for v, t in typed if v.channel == ch.number]
    return ordered


def external_modbus_use(config: MachineShape) -> dict[ModbusTable, int]:
    """How far the V.E. variables reach in the coils and in the holding registers (one past the
    last address), without expanding their elements: the check of the machine file uses it."""
    cursor = {ModbusTable.COIL: MODBUS_EXTERNAL_BASE, ModbusTable.HOLDING_REGISTER: MODBUS_EXTERNAL_BASE}
    for _, var, node in _external_order(config):
        count = math.prod(var.dims or [1])
        _, cursor[ModbusTable.COIL] = node.coils.place(cursor[ModbusTable.COIL], count)
        _, cursor[ModbusTable.HOLDING_REGISTER] = node.registers.place(
            cursor[ModbusTable.HOLDING_REGISTER], count
        )
    return cursor


def check_external_fits(config: MachineShape) -> str | None:
    """None when the V.E. variables fit the Modbus area reserved for them, else what is too much."""
    for table, end in external_modbus_use(config).items():
        if end > MODBUS_EXTERNAL_END:
            room = MODBUS_EXTERNAL_END - MODBUS_EXTERNAL_BASE
            what = (
                "coils for their BOOLEAN elements"
                if table is ModbusTable.COIL
                else "holding registers for their numbers and strings"
            )
            return (
                f"the V.E. variables need {end - MODBUS_EXTERNAL_BASE} Modbus {what}; the map "
                f"reserves {room} ({MODBUS_EXTERNAL_BASE}..{MODBUS_EXTERNAL_END - 1}) for them: declare "
                "fewer or smaller arrays, or shorter strings"
            )
    return None


def _element_indices(dims: Sequence[int]) -> Iterator[tuple[int, ...]]:
    """Row-major, as ``ExternalVarSpec.flat_index`` counts them."""
    if not dims:
        yield ()
        return
    yield from itertools.product(*(range(d) for d in dims))


@dataclass(slots=True)
class _Cursor:
    """Where the next V.E. element goes: byte offset in the PLC->CNC half, coil, holding register."""

    byte: int
    coil: int = MODBUS_EXTERNAL_BASE
    register: int = MODBUS_EXTERNAL_BASE

    def align(self, node: TypeNode) -> None:
        self.byte, _ = node.image.place(self.byte)
        self.coil, _ = node.coils.place(self.coil)
        self.register, _ = node.registers.place(self.register)


@dataclass(frozen=True, slots=True)
class _Area:
    scope: Scope
    index: int
    head: str
    prefix: str
    text: str


def _external_signals(config: MachineShape, start: int) -> tuple[list[Signal], int]:
    """Place every element of every V.E. variable after the axis blocks of the PLC->CNC half
    and in the V.E. area of the coils / holding registers: each element at its alignment, a structure
    at its most aligned element's and each of its elements in order (schemas/external_types.py)."""
    problem = check_external_fits(config)
    if problem is not None:
        raise LayoutError(problem)
    signals: list[Signal] = []
    cursor = _Cursor(start)
    for ch_index, var, node in _external_order(config):
        if ch_index is None:
            scope, index, head, prefix = Scope.VE_GLOBAL, 0, "gpVEGlob^", ""
            area = "global area"
        else:
            number = config.channels[ch_index].number
            scope, index, head, prefix = Scope.VE_CHANNEL, ch_index, f"gpVECh[{ch_index}]^", f"ch{number}."
            area = f"area of channel {number}"
        dims = "".join(f"[{d}]" for d in var.dims)
        type_text = var.type + (f"({node.string_size - 1})" if node.is_string else "")
        text = (
            f"V.E.{var.name} ({type_text}{dims}, {area}): read and written by NC programs and the PLC "
            "(last writer wins)"
        )
        if var.description:
            text = f"{var.description}. {text}"
        where = _Area(scope, index, head, prefix, text)
        for element in _element_indices(var.dims):
            path = var.name + (f"[{','.join(map(str, element))}]" if element else "")
            _place_external(signals, cursor, where, path, node, ())
    return signals, cursor.byte


def _place_external(
    signals: list[Signal],
    cursor: _Cursor,
    area: _Area,
    path: str,
    node: TypeNode,
    structures: tuple[str, ...],
) -> None:
    """One element of type ``node`` at ``path`` (``curve[2].point[5]``): a leaf's signal, or a
    structure's elements in order."""
    cursor.align(node)
    if node.is_structure:
        start = _Cursor(cursor.byte, cursor.coil, cursor.register)
        for member in node.members:
            for element in _element_indices(member.dims):
                sub = f"{path}.{member.name}" + (f"[{','.join(map(str, element))}]" if element else "")
                _place_external(signals, cursor, area, sub, member.type, (*structures, node.name))
        # the structure's size is a multiple of its alignment (an array's elements share one shape)
        cursor.byte = start.byte + node.image.size
        cursor.coil = start.coil + node.coils.size
        cursor.register = start.register + node.registers.size
        return
    if node.is_string:
        sig_type, limits = SignalType.STRING, None
    else:
        sig_type, limits = EXTERNAL_TYPES[node.name]
    table = _modbus_table(sig_type, Direction.PLC_TO_CNC)
    offset = cursor.byte
    address = cursor.coil if table is ModbusTable.COIL else cursor.register
    size = node.image.size
    cursor.byte += size
    if table is ModbusTable.COIL:
        cursor.coil += 1
    else:
        cursor.register += node.registers.size
    signals.append(
        Signal(
            name=f"{area.prefix}V.E.{path}",
            st_path=area.head + path,
            scope=area.scope,
            index=area.index,
            path=path,
            type=sig_type,
            direction=Direction.PLC_TO_CNC,
            unit="-",
            description=area.text,
            reqs=("N-05",),
            origin="machine file",
            offset=offset,
            modbus_table=table,
            modbus_address=address,
            ads_port=ADS_PORT_HLI,
            ads_group=ADS_GROUP_PLC_TO_CNC,
            ads_offset=offset,
            limits=limits,
            string_size=node.string_size,
            structures=structures,
        )
    )
