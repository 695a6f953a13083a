"""The engine's side of the PLC interface (HLI): plain objects shaped like the ST paths.

``gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w`` is
``machine.hli.axes[0].ipo_mc_control.dyn_pos_limit_low.command_w`` here: the process image
(``hli_server/image``) copies between shared memory and these objects by walking the ST path, so the
one layout table in ``schemas/layout.py`` is all that names a signal.

Fields ending in ``_w`` are written by the PLC (latched once per cycle, before the step), fields
ending in ``_r`` by the CNC (published after the step). Control units (H-02) keep the kernel's
field order: request_r, enable_w, command_w, state_r.

Names the documents give (FCT-C14 6.3, FCT-C43 3.1.1) are used as given; the rest are the
project's own and are marked so in the layout table.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from schemas.wire import Mode, ProgramState

__all__ = [
    "AxisHli",
    "AxisIpoMcControl",
    "AxisManual",
    "AxisState",
    "BahnMcControl",
    "BahnState",
    "ChannelHli",
    "ControlUnitBool",
    "ControlUnitSgn32",
    "DynCollMon",
    "MachineHli",
    "McCommand",
]


@dataclass(slots=True)
class ControlUnitBool:
    """MC_CONTROL_BOOL_UNIT (H-02)."""

    request_r: bool = False
    enable_w: bool = False
    command_w: bool = False
    state_r: bool = False

    def effective(self) -> bool:
        """The value the CNC uses: the PLC's command while enable_w is set, else its own request."""
        return self.command_w if self.enable_w else self.request_r


@dataclass(slots=True)
class ControlUnitSgn32:
    """MC_CONTROL_SGN32_UNIT (H-02)."""

    request_r: int = 0
    enable_w: bool = False
    command_w: int = 0
    state_r: int = 0

    def effective(self) -> int:
        return self.command_w if self.enable_w else self.request_r


@dataclass(slots=True)
class BahnState:
    """``gpCh[i]^bahn_state``: channel state, CNC -> PLC."""

    area_mon_violation_detected_r: bool = False  # FCT-C14 6.3
    mode_r: int = Mode.AUTOMATIC
    program_state_r: int = ProgramState.IDLE
    program_number_r: int = 0
    block_nr_r: int = 0
    line_nr_r: int = 0
    feedhold_active_r: bool = False
    hold_source_r: int = 0
    error_present_r: bool = False
    error_id_r: int = 0
    warning_id_r: int = 0
    alarm_count_r: int = 0
    cycle_r: int = 0
    kin_id_r: int = 0
    """The kinematic ID of the active transformation, 0 = none (K-07)."""
    trafo_active_r: bool = False
    tcp_x_r: int = 0
    """The tool tip (TCP) in machine coordinates of the first, second, third main axis [0.1 µm] (K-07)."""
    tcp_y_r: int = 0
    tcp_z_r: int = 0


@dataclass(slots=True)
class BahnMcControl:
    """``gpCh[i]^bahn_mc_control``: channel control units, PLC -> CNC."""

    suppress_area_mon_manual_mode: ControlUnitBool = field(default_factory=ControlUnitBool)  # FCT-C14 6.3
    feedhold: ControlUnitBool = field(default_factory=ControlUnitBool)
    override: ControlUnitSgn32 = field(default_factory=lambda: ControlUnitSgn32(request_r=1000, state_r=1000))
    """Feed override in 0.1 % (1000 = 100 %)."""


@dataclass(slots=True)
class McCommand:
    """``gpCh[i]^mc_command``: the PLC's operator panel (project's own). Start and reset act on a
    rising edge; ``probe_w`` is the measuring input for G100 (C14-23)."""

    mode_w: int = Mode.AUTOMATIC
    program_select_w: int = 0
    start_w: bool = False
    reset_w: bool = False
    probe_w: bool = False


@dataclass(slots=True)
class ChannelHli:
    bahn_state: BahnState = field(default_factory=BahnState)
    bahn_mc_control: BahnMcControl = field(default_factory=BahnMcControl)
    mc_command: McCommand = field(default_factory=McCommand)


@dataclass(slots=True)
class AxisIpoMcControl:
    """``gpAx[i]^ipo_mc_control`` (FCT-C43 3.1.1). state_r holds HLI_DYNPL_STATE_*."""

    dyn_pos_limit_low: ControlUnitSgn32 = field(default_factory=ControlUnitSgn32)
    dyn_pos_limit_high: ControlUnitSgn32 = field(default_factory=ControlUnitSgn32)


@dataclass(slots=True)
class AxisState:
    """``gpAx[i]^ipo_state``: axis state, CNC -> PLC (project's own names). Positions in 0.1 µm
    (0.0001°), velocity in 0.1 µm/s."""

    cmd_pos_r: int = 0
    act_pos_r: int = 0
    velocity_r: int = 0
    following_error_r: int = 0
    referenced_r: bool = False
    referencing_r: bool = False
    in_position_r: bool = False
    moving_r: bool = False
    error_r: bool = False


@dataclass(slots=True)
class AxisManual:
    """``gpAx[i]^manual``: jog keys (effective in manual mode) and the referencing (homing) command,
    PLC -> CNC (project's own)."""

    jog_plus_w: bool = False
    jog_minus_w: bool = False
    reference_w: bool = False


@dataclass(slots=True)
class DynCollMon:
    """The CNC objects of FCT-C3 4.3 (C3-10), read-only; ADS port 551, group 0x120300."""

    active: bool = False
    velocity: float = 0.0  # [0.1 µm/s]
    brake_dist: float = 0.0  # [0.1 µm]
    coll_offset: int = 0  # [0.1 µm]
    deceleration: float = 0.0  # [mm/s²]


@dataclass(slots=True)
class AxisHli:
    ipo_mc_control: AxisIpoMcControl = field(default_factory=AxisIpoMcControl)
    ipo_state: AxisState = field(default_factory=AxisState)
    manual: AxisManual = field(default_factory=AxisManual)
    dyn_coll_mon: DynCollMon = field(default_factory=DynCollMon)


@dataclass(slots=True)
class MachineHli:
    """All of it: ``channels[i]`` is ``gpCh[i]``, ``axes[i]`` is ``gpAx[i]`` (axis index = order of the
    axes in the configuration, 0-based; the logical axis number A_ID is separate)."""

    channels: list[ChannelHli]
    axes: list[AxisHli]
