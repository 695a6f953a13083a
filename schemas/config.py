"""Machine configuration: the contract between configuration files, the engine and the tools.

Parameters carry the documents' names and units (P-AXIS-xxxxx, P-CHAN-xxxxx, P-MANU-xxxxx,
P-STUP-00070); positions in 0.1 µm (0.0001° rotary), times in µs, accelerations in mm/s².
Parameters the documents do not name (velocities, jog, drive model) are the project's own and are
marked so in ``docs/configuration.md``.

The table :data:`AXIS_PARAMETERS` maps the ISG text-list paths (``kenngr.swe_neg``) to the fields
here; the text-list importer and the docs are derived from it.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from schemas.units import DINT_MAX, DINT_MIN, UDINT_MAX

__all__ = [
    "AXIS_PARAMETERS",
    "CHANNEL_PARAMETERS",
    "COLLISION_MODE_BIT",
    "AxisConfig",
    "AxisType",
    "ChannelConfig",
    "DriveModel",
    "InterpolatorFunction",
    "MachineConfig",
    "ManualConfig",
    "ParameterInfo",
    "ProgramEntry",
    "ZeroOffset",
]

COLLISION_MODE_BIT = 0x8000
"""P-AXIS-00015 ``kenngr.achs_mode`` bit that switches axis collision monitoring on (FCT-C3)."""

Dint = Annotated[int, Field(ge=DINT_MIN, le=DINT_MAX)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True, frozen=False)


class AxisType(StrEnum):
    TRANSLATORY = "T"
    ROTARY = "R"


class InterpolatorFunction(StrEnum):
    """Keywords of P-STUP-00070 ``configuration.channel[i].interpolator.function``."""

    FCT_IPO_DEFAULT = "FCT_IPO_DEFAULT"
    FCT_LOOK_AHEAD_STANDARD = "FCT_LOOK_AHEAD_STANDARD"
    FCT_DYN_POS_LIMIT = "FCT_DYN_POS_LIMIT"


class DriveModel(_Strict):
    """The position-control loop that turns setpoints into actual positions (project's own, E-02).

    A proportional position controller with velocity feed-forward, driving a first-order drive:
    the following error in steady motion is about ``v * (1 - feed_forward) / kv``. Faults
    (friction, encoder drift) are injected at run time, not configured here.
    """

    kv: float = Field(default=60.0, gt=0.0, le=10_000.0, description="position loop gain [1/s]")
    feed_forward: float = Field(default=0.9, ge=0.0, le=1.0, description="velocity feed-forward [0..1]")
    time_constant_us: int = Field(
        default=2_000, ge=0, le=1_000_000, description="drive velocity time constant [µs]"
    )
    standstill_noise: int = Field(
        default=0, ge=0, le=1_000_000, description="peak encoder noise at standstill [0.1 µm]"
    )


class AxisConfig(_Strict):
    """One axis, in the documents' units."""

    number: int = Field(ge=1, le=UDINT_MAX, description="kopf.achs_nr: logical axis number (A_ID)")
    name: str = Field(pattern=r"^[A-Z][A-Z0-9]{0,7}$", description="axis name in NC programs: X, Y, X2 ...")
    axis_type: AxisType = AxisType.TRANSLATORY
    achs_mode: int = Field(
        default=0x00000001, ge=0x00000001, le=0x10000000, description="P-AXIS-00015 kenngr.achs_mode"
    )
    a_emergency: float = Field(
        default=5000.0, gt=0.0, description="P-AXIS-00003 emergency deceleration [mm/s²]"
    )
    a_max: float = Field(default=2000.0, gt=0.0, description="P-AXIS-00008 maximum acceleration [mm/s²]")
    coll_check_ax_nr: int = Field(
        default=0, ge=0, le=UDINT_MAX, description="P-AXIS-00043 logical number of the collision partner"
    )
    coll_decelerate_chan: bool = Field(
        default=False, description="P-AXIS-00044 stop both channels on a drive error of the pair"
    )
    coll_offset: int = Field(
        default=0, ge=0, le=UDINT_MAX, description="P-AXIS-00045 minimum distance of the pair [0.1 µm]"
    )
    settling_time_legacy_us: int = Field(
        default=0,
        ge=DINT_MIN,
        le=DINT_MAX,
        description="P-AXIS-00151 older settling-time parameter, used when P-AXIS-00532 < 0 [µs]",
    )
    swe_neg: Dint = Field(default=-100_000_000, description="P-AXIS-00177 negative software limit [0.1 µm]")
    swe_pos: Dint = Field(default=100_000_000, description="P-AXIS-00178 positive software limit [0.1 µm]")
    swe_toleranz: int = Field(
        default=0, ge=0, le=DINT_MAX, description="P-AXIS-00179 tolerance of actual positions [0.1 µm]"
    )
    window: int = Field(default=500, ge=0, le=DINT_MAX, description="P-AXIS-00236 exact-stop window [0.1 µm]")
    coll_moving_dir_inverted: bool = Field(default=False, description="P-AXIS-00262")
    coll_zero_position_offset: Dint = Field(default=0, description="P-AXIS-00263 [0.1 µm]")
    coll_use_a_emergency: bool = Field(default=False, description="P-AXIS-00267")
    position_settling_time_us: Dint = Field(
        default=-1, description="P-AXIS-00532 max settling time into the window [µs]; 0 off, <0 P-AXIS-00151"
    )
    # project's own: what motion needs
    v_max: float = Field(default=30_000.0, gt=0.0, description="maximum path/axis velocity [mm/min]")
    v_rapid: float = Field(default=30_000.0, gt=0.0, description="G00 velocity [mm/min]")
    jog_velocity: float = Field(default=3_000.0, gt=0.0, description="jog velocity in manual mode [mm/min]")
    jog_acceleration: float = Field(default=1000.0, gt=0.0, description="jog acceleration [mm/s²]")
    referenced: bool = Field(default=True, description="axis is homed at start-up")
    start_position: Dint = Field(default=0, description="position at start-up [0.1 µm]")
    drive: DriveModel = Field(default_factory=DriveModel)

    @model_validator(mode="after")
    def _check_ranges(self) -> AxisConfig:
        if not self.swe_neg < self.swe_pos:
            raise ValueError(
                f"axis {self.name}: P-AXIS-00177 swe_neg ({self.swe_neg}) must be less than "
                f"P-AXIS-00178 swe_pos ({self.swe_pos})"
            )
        if self.coll_offset == 1:
            raise ValueError(f"axis {self.name}: P-AXIS-00045 coll_offset must be > 1 (1 < coll_offset)")
        return self

    @property
    def collision_monitoring(self) -> bool:
        """Bit 0x8000 of P-AXIS-00015 (FCT-C3)."""
        return bool(self.achs_mode & COLLISION_MODE_BIT)


class ZeroOffset(_Strict):
    """One settable zero offset G54..G59 [0.1 µm per axis name]."""

    code: Literal["G54", "G55", "G56", "G57", "G58", "G59"]
    offsets: dict[str, Dint] = Field(default_factory=dict)


class ProgramEntry(_Strict):
    """A program the PLC can select by number (project's own program table)."""

    number: int = Field(ge=1, le=65535)
    name: str
    text: str | None = None
    path: str | None = None

    @model_validator(mode="after")
    def _one_source(self) -> ProgramEntry:
        if (self.text is None) == (self.path is None):
            raise ValueError(f"program {self.number}: give exactly one of 'text' or 'path'")
        return self


class ChannelConfig(_Strict):
    number: int = Field(default=1, ge=1, le=12)
    name: str = "Channel 1"
    axes: list[str] = Field(min_length=1, description="names of the axes of this channel")
    main_axes: tuple[str, str, str] = Field(
        default=("X", "Y", "Z"), description="first, second and third main axis (G17: X/Y, Z)"
    )
    interpolator_function: list[InterpolatorFunction] = Field(
        default_factory=lambda: [InterpolatorFunction.FCT_IPO_DEFAULT],
        description="P-STUP-00070 configuration.channel[i].interpolator.function",
    )
    meas_soft_limit_move_path: bool = Field(default=False, description="P-CHAN-00268")
    suppress_workspace_monitoring_manual_mode: int = Field(default=0, ge=0, le=2, description="P-CHAN-00442")
    dpl_tol_limit_change: int = Field(default=0, ge=0, le=DINT_MAX, description="P-CHAN-00751 [0.1 µm]")
    dpl_input_cycles: int = Field(default=1, ge=1, le=1000, description="P-CHAN-00874 [cycles]")
    feedhold_deceleration: float = Field(
        default=1000.0, gt=0.0, description="path deceleration of feedhold [mm/s²] (project's own)"
    )
    zero_offsets: list[ZeroOffset] = Field(default_factory=list)
    programs: list[ProgramEntry] = Field(default_factory=list)

    @property
    def dyn_pos_limit_enabled(self) -> bool:
        """C43-01: FCT_DYN_POS_LIMIT in P-STUP-00070."""
        return InterpolatorFunction.FCT_DYN_POS_LIMIT in self.interpolator_function

    @model_validator(mode="after")
    def _check_axes(self) -> ChannelConfig:
        missing = [a for a in self.main_axes if a not in self.axes]
        if missing:
            raise ValueError(f"channel {self.number}: main axes {missing} are not axes of the channel")
        if len(set(self.axes)) != len(self.axes):
            raise ValueError(f"channel {self.number}: an axis is listed twice in {self.axes}")
        return self


class ManualConfig(_Strict):
    move_limit_warning: bool = Field(default=False, description="P-MANU-00014")


class MachineConfig(_Strict):
    name: str = "machine"
    cycle_time_us: int = Field(default=1000, ge=100, le=100_000, description="interpolation cycle T_A [µs]")
    axes: list[AxisConfig] = Field(min_length=1)
    channels: list[ChannelConfig] = Field(min_length=1)
    manual: ManualConfig = Field(default_factory=ManualConfig)

    @model_validator(mode="after")
    def _check_machine(self) -> MachineConfig:
        names = [a.name for a in self.axes]
        numbers = [a.number for a in self.axes]
        if len(set(names)) != len(names):
            raise ValueError(f"axis names must be unique: {names}")
        if len(set(numbers)) != len(numbers):
            raise ValueError(f"logical axis numbers (kopf.achs_nr) must be unique: {numbers}")
        owner: dict[str, int] = {}
        for ch in self.channels:
            for ax_name in ch.axes:
                if ax_name not in names:
                    raise ValueError(f"channel {ch.number}: unknown axis {ax_name!r} (axes: {names})")
                if ax_name in owner:
                    raise ValueError(
                        f"axis {ax_name} belongs to channel {owner[ax_name]} and channel {ch.number}"
                    )
                owner[ax_name] = ch.number
        ch_numbers = [c.number for c in self.channels]
        if len(set(ch_numbers)) != len(ch_numbers):
            raise ValueError(f"channel numbers must be unique: {ch_numbers}")
        by_number = {a.number: a for a in self.axes}
        for ax in self.axes:
            if ax.coll_check_ax_nr:
                partner = by_number.get(ax.coll_check_ax_nr)
                if partner is None:
                    raise ValueError(
                        f"axis {ax.name}: P-AXIS-00043 coll_check_ax_nr {ax.coll_check_ax_nr} "
                        "is no logical axis number"
                    )
                if partner.number == ax.number:
                    raise ValueError(f"axis {ax.name}: P-AXIS-00043 names the axis itself")
                if not (ax.collision_monitoring and partner.collision_monitoring):
                    raise ValueError(
                        f"axes {ax.name}/{partner.name}: a collision pair needs bit 0x8000 in "
                        "P-AXIS-00015 kenngr.achs_mode of both axes"
                    )
                if ax.coll_offset <= 1 and partner.coll_offset <= 1:
                    raise ValueError(f"axis {ax.name}: a collision pair needs P-AXIS-00045 coll_offset > 1")
        return self

    def axis(self, name: str) -> AxisConfig:
        for a in self.axes:
            if a.name == name:
                return a
        raise KeyError(name)

    def channel_of(self, axis_name: str) -> ChannelConfig:
        for ch in self.channels:
            if axis_name in ch.axes:
                return ch
        raise KeyError(axis_name)


class ParameterInfo(BaseModel):
    model_config = ConfigDict(frozen=True)
    path: str
    field: str
    pid: str | None
    unit: str


AXIS_PARAMETERS: tuple[ParameterInfo, ...] = tuple(
    ParameterInfo(path=p, field=f, pid=i, unit=u)
    for p, f, i, u in (
        ("kopf.achs_nr", "number", None, "-"),
        ("kopf.achs_name", "name", None, "-"),
        ("kopf.achs_typ", "axis_type", None, "T|R"),
        ("kenngr.achs_mode", "achs_mode", "P-AXIS-00015", "-"),
        ("getriebe[0].dynamik.a_emergency", "a_emergency", "P-AXIS-00003", "mm/s²"),
        ("getriebe[0].dynamik.a_max", "a_max", "P-AXIS-00008", "mm/s²"),
        ("kenngr.coll_check_ax_nr", "coll_check_ax_nr", "P-AXIS-00043", "-"),
        ("kenngr.coll_decelerate_chan", "coll_decelerate_chan", "P-AXIS-00044", "0/1"),
        ("kenngr.coll_offset", "coll_offset", "P-AXIS-00045", "0.1 µm"),
        ("getriebe[0].settling_time", "settling_time_legacy_us", "P-AXIS-00151", "µs"),
        ("kenngr.swe_neg", "swe_neg", "P-AXIS-00177", "0.1 µm"),
        ("kenngr.swe_pos", "swe_pos", "P-AXIS-00178", "0.1 µm"),
        ("kenngr.swe_toleranz", "swe_toleranz", "P-AXIS-00179", "0.1 µm"),
        ("getriebe[0].window", "window", "P-AXIS-00236", "0.1 µm"),
        ("kenngr.coll_moving_dir_inverted", "coll_moving_dir_inverted", "P-AXIS-00262", "0/1"),
        ("kenngr.coll_zero_position_offset", "coll_zero_position_offset", "P-AXIS-00263", "0.1 µm"),
        ("kenngr.coll_use_a_emergency", "coll_use_a_emergency", "P-AXIS-00267", "0/1"),
        ("getriebe[0].position_settling_time", "position_settling_time_us", "P-AXIS-00532", "µs"),
    )
)
"""ISG text-list paths of the axis parameters the documents name (and the two header entries)."""

CHANNEL_PARAMETERS: tuple[ParameterInfo, ...] = tuple(
    ParameterInfo(path=p, field=f, pid=i, unit=u)
    for p, f, i, u in (
        ("meas_soft_limit_move_path", "meas_soft_limit_move_path", "P-CHAN-00268", "0/1"),
        (
            "suppress_workspace_monitoring_manual_mode",
            "suppress_workspace_monitoring_manual_mode",
            "P-CHAN-00442",
            "0/1/2",
        ),
        ("dpl_tol_limit_change", "dpl_tol_limit_change", "P-CHAN-00751", "0.1 µm"),
        ("dpl_input_cycles", "dpl_input_cycles", "P-CHAN-00874", "cycles"),
    )
)
"""ISG text-list names of the channel parameters the documents name."""
