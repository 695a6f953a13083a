"""Machine configuration: the contract between configuration files, the engine and the tools.

Parameters carry the documents' names and units (P-AXIS-xxxxx, P-CHAN-xxxxx, P-MANU-xxxxx,
P-STUP-00070); positions in 0.1 µm (0.0001° rotary), times in µs, accelerations in mm/s².
Parameters the documents do not name (velocities, jog, drive model) are the project's own and are
marked so in ``docs/configuration.md``.

Every number has a range (E-07; reliability.md, round 1, finding 1): positions and distances a DINT in 0.1 µm,
times in µs within their type, velocities and accelerations positive and at most
:data:`~schemas.units.VELOCITY_LIMIT_MM_PER_MIN` / :data:`~schemas.units.ACCELERATION_LIMIT`; no
model takes inf or NaN (``allow_inf_nan=False``; TOML and the text lists can write ``inf`` and ``nan``).

The table :data:`AXIS_PARAMETERS` maps the ISG text-list paths (``kenngr.swe_neg``) to the fields
here; the text-list importer and the docs are derived from it.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Annotated, Any, ClassVar, Literal, Self

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from schemas.layout import check_external_fits
from schemas.units import ACCELERATION_LIMIT, DINT_MAX, DINT_MIN, UDINT_MAX, VELOCITY_LIMIT_MM_PER_MIN

__all__ = [
    "AXIS_PARAMETERS",
    "AXIS_PARAMETER_ALIASES",
    "CHANNEL_PARAMETERS",
    "COLLISION_MODE_BIT",
    "KINEMATIC_AXIS_PARAMETERS",
    "KINEMATIC_PARAMETERS",
    "MANUAL_PARAMETERS",
    "TOOL_PARAMETERS",
    "AdapterEntry",
    "AxisConfig",
    "AxisType",
    "ChannelConfig",
    "DriveModel",
    "ExternalElementConfig",
    "ExternalStructureConfig",
    "ExternalVariableConfig",
    "InterpolatorFunction",
    "KinematicAxis",
    "KinematicEntry",
    "MachineConfig",
    "ManualConfig",
    "ParameterInfo",
    "ParameterIssue",
    "ParameterIssues",
    "ProgramEntry",
    "ZeroOffset",
]

COLLISION_MODE_BIT = 0x8000
"""P-AXIS-00015 ``kenngr.achs_mode`` bit that switches axis collision monitoring on (FCT-C3)."""

Dint = Annotated[int, Field(ge=DINT_MIN, le=DINT_MAX)]
ProgName = Annotated[str, Field(max_length=83)]
"""A program's file name in a channel parameter (PROG_NAME: at most 83 characters; "" for none)."""
IMPLICIT_G800_COUNT = 40
"""``g800_prog_file[i]``, i = 0 .. 39 (P-CHAN-00187: G800..G819, or G800..G839 where the application
has them)."""


@dataclass(frozen=True, slots=True)
class ParameterIssue:
    """One finding of a cross-field check, with what it is about (E-07).

    ``field`` names the model field the finding is about; ``axis`` (an axis name) or ``channel``
    (a channel number) say which axis or channel it belongs to when a machine-wide check finds it.
    The configuration loader uses these to point at the file, line and key that set the value.
    """

    message: str
    field: str | None = None
    axis: str | None = None
    channel: int | None = None
    at: tuple[str | int, ...] = ()
    """Below ``field``: the entry of a list and its key (``(2, "type")`` of ``external_variables``)."""


class ParameterIssues(ValueError):  # noqa: N818 - a ValueError, so that pydantic reports it
    """All findings of one model's cross-field checks (raised once, so that none is lost; E-07)."""

    def __init__(self, issues: list[ParameterIssue]) -> None:
        super().__init__("; ".join(i.message for i in issues))
        self.issues = tuple(issues)


def _raise_issues(issues: list[ParameterIssue]) -> None:
    if issues:
        raise ParameterIssues(issues)


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


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
    feed_forward: float = Field(
        default=0.9, ge=0.0, le=1.0, description="velocity feed-forward factor (0 none .. 1 full)"
    )
    time_constant_us: int = Field(
        default=2_000, ge=0, le=1_000_000, description="drive velocity time constant [µs]"
    )
    standstill_noise: int = Field(
        default=0, ge=0, le=1_000_000, description="peak encoder noise at standstill [0.1 µm]"
    )


class AxisConfig(_Strict):
    """One axis, in the documents' units."""

    number: int = Field(ge=1, le=UDINT_MAX, description="logical axis number (A_ID), unique")
    name: str = Field(pattern=r"^[A-Z][A-Z0-9]{0,7}$", description="axis name in NC programs: X, Y, X2 ...")
    axis_type: AxisType = Field(
        default=AxisType.TRANSLATORY, description="axis type: T translatory, R rotary (0.0001° units)"
    )
    achs_mode: int = Field(
        default=0x00000001,
        ge=0x00000001,
        le=0x10000000,
        description="P-AXIS-00015 operating mode of the axis; bit 0x8000: collision monitoring (FCT-C3)",
    )
    a_emergency: float = Field(
        default=0.0,
        ge=0.0,
        le=ACCELERATION_LIMIT,
        description="P-AXIS-00003 emergency deceleration [mm/s²]; 0: P-AXIS-00008 a_max applies",
    )
    a_max: float = Field(
        default=1000.0, ge=1.0, le=ACCELERATION_LIMIT, description="P-AXIS-00008 maximum acceleration [mm/s²]"
    )
    coll_check_ax_nr: int = Field(
        default=0,
        ge=0,
        lt=UDINT_MAX,
        description="P-AXIS-00043 logical number of the collision partner (0: none)",
    )
    coll_decelerate_chan: bool = Field(
        default=False, description="P-AXIS-00044 stop both channels on a drive error of the pair"
    )
    coll_offset: int = Field(
        default=0,
        ge=0,
        lt=UDINT_MAX,
        description="P-AXIS-00045 minimum distance of the pair [0.1 µm] (0: none, else > 1)",
    )
    mess_offset: int = Field(
        default=0,
        ge=0,
        le=UDINT_MAX,
        description="P-AXIS-00114 distance a type 2 measuring move may run past its target [0.1 µm]",
    )
    messachse: bool = Field(
        default=False, description="P-AXIS-00118 the axis is a measuring axis (G100 may move it)"
    )
    offsetgrenze_neg: int = Field(
        default=-1_000_000,
        ge=DINT_MIN,
        le=0,
        description="P-AXIS-00137 relative negative offset limit in manual mode [0.1 µm]; both 0: off",
    )
    offsetgrenze_pos: int = Field(
        default=1_000_000,
        ge=0,
        le=DINT_MAX,
        description="P-AXIS-00138 relative positive offset limit in manual mode [0.1 µm]; both 0: off",
    )
    settling_time_legacy_us: int = Field(
        default=1_000_000,
        ge=0,
        le=UDINT_MAX // 1000,
        description="P-AXIS-00151 older settling-time parameter, used when P-AXIS-00532 < 0 [µs]; 0 off",
    )
    # FCT-C14 6.2: MIN(SGN32) < swe_neg < P-AXIS-00178 < swe_pos < MAX(SGN32)
    swe_neg: int = Field(
        default=-100_000_000,
        gt=DINT_MIN,
        le=DINT_MAX,
        description="P-AXIS-00177 negative software limit [0.1 µm]",
    )
    swe_pos: int = Field(
        default=100_000_000,
        ge=DINT_MIN,
        lt=DINT_MAX,
        description="P-AXIS-00178 positive software limit [0.1 µm]",
    )
    swe_toleranz: int = Field(
        default=1000, ge=0, le=UDINT_MAX, description="P-AXIS-00179 tolerance of actual positions [0.1 µm]"
    )
    vb_messen: int = Field(
        default=16666,
        ge=1,
        le=UDINT_MAX,
        description="P-AXIS-00215 measuring feed of measuring type 2 [µm/s] (at most the axis' v_max)",
    )
    window: int = Field(default=500, ge=0, le=DINT_MAX, description="P-AXIS-00236 exact-stop window [0.1 µm]")
    coll_moving_dir_inverted: bool = Field(
        default=False,
        description="P-AXIS-00262 the pair moves mechanically in opposite directions (master axis)",
    )
    # FCT-C3 4.2: MIN(SGN32) < coll_zero_position_offset < MAX(SGN32)
    coll_zero_position_offset: int = Field(
        default=0,
        gt=DINT_MIN,
        lt=DINT_MAX,
        description="P-AXIS-00263 zero point of the partner in the master axis' coordinates [0.1 µm]",
    )
    coll_use_a_emergency: bool = Field(
        default=False, description="P-AXIS-00267 brake with a_emergency instead of a_max on a collision"
    )
    meas_offset: int = Field(
        default=0,
        ge=0,
        le=UDINT_MAX,
        description="P-AXIS-00467 distance a measuring move (not type 3) may run past its target [0.1 µm]",
    )
    acs_limit_neg: Dint = Field(
        default=0,
        description="P-AXIS-00492 absolute negative ACS limit in manual mode [0.1 µm]; both 0: off",
    )
    acs_limit_pos: Dint = Field(
        default=0,
        description="P-AXIS-00493 absolute positive ACS limit in manual mode [0.1 µm]; both 0: off",
    )
    position_settling_time_us: Dint = Field(
        default=-1, description="P-AXIS-00532 max settling time into the window [µs]; 0 off, <0 P-AXIS-00151"
    )
    tr_beschl_ab: int = Field(
        default=50_000, ge=0, le=UDINT_MAX, description="P-AXIS-00195 ramp time, acceleration taken down [µs]"
    )
    tr_beschl_zu: int = Field(
        default=50_000, ge=0, le=UDINT_MAX, description="P-AXIS-00196 ramp time, acceleration built up [µs]"
    )
    tr_brems_ab: int = Field(
        default=50_000, ge=0, le=UDINT_MAX, description="P-AXIS-00197 ramp time, deceleration taken down [µs]"
    )
    tr_brems_zu: int = Field(
        default=50_000, ge=0, le=UDINT_MAX, description="P-AXIS-00198 ramp time, deceleration built up [µs]"
    )
    # project's own: what motion needs
    v_max: float = Field(
        default=30_000.0,
        gt=0.0,
        le=VELOCITY_LIMIT_MM_PER_MIN,
        description="maximum path/axis velocity [mm/min]",
    )
    v_rapid: float = Field(
        default=30_000.0, gt=0.0, le=VELOCITY_LIMIT_MM_PER_MIN, description="G00 velocity [mm/min]"
    )
    jog_velocity: float = Field(
        default=3_000.0,
        gt=0.0,
        le=VELOCITY_LIMIT_MM_PER_MIN,
        description="jog velocity in manual mode [mm/min]",
    )
    jog_acceleration: float = Field(
        default=1000.0, gt=0.0, le=ACCELERATION_LIMIT, description="jog acceleration [mm/s²]"
    )
    referenced: bool = Field(default=True, description="axis is homed at start-up")
    start_position: Dint = Field(default=0, description="position at start-up [0.1 µm]")
    reference_position: Dint | None = Field(
        default=None,
        description="where the referencing (homing) move ends and the axis counts as referenced [0.1 µm]; "
        "default: start_position",
    )
    drive: DriveModel = Field(default_factory=DriveModel)

    @model_validator(mode="after")
    def _check_ranges(self) -> AxisConfig:
        """E-06/E-07: the ranges that tie two fields together (FCT-C14 6.2, FCT-C3 4.2)."""
        issues: list[ParameterIssue] = []
        if not self.swe_neg < self.swe_pos:
            issues.append(
                ParameterIssue(
                    f"axis {self.name}: P-AXIS-00177 swe_neg ({self.swe_neg}) must be less than "
                    f"P-AXIS-00178 swe_pos ({self.swe_pos})",
                    field="swe_neg",
                )
            )
        if self.a_emergency > 2.0 * self.a_max:
            issues.append(
                ParameterIssue(
                    f"axis {self.name}: P-AXIS-00003 a_emergency ({self.a_emergency:g}) must be at most "
                    f"twice P-AXIS-00008 a_max ({self.a_max:g}): 1 ≤ a_emergency ≤ 2*a_max, or 0 for a_max",
                    field="a_emergency",
                )
            )
        if (self.acs_limit_neg, self.acs_limit_pos) != (0, 0):
            for name, value in (("acs_limit_neg", self.acs_limit_neg), ("acs_limit_pos", self.acs_limit_pos)):
                if not self.swe_neg <= value <= self.swe_pos:
                    pid = "P-AXIS-00492" if name == "acs_limit_neg" else "P-AXIS-00493"
                    issues.append(
                        ParameterIssue(
                            f"axis {self.name}: {pid} {name} ({value}) must lie within the software limits "
                            f"P-AXIS-00177 ≤ {name} ≤ P-AXIS-00178 ({self.swe_neg} .. {self.swe_pos}); "
                            "both 0 switch the ACS limits off",
                            field=name,
                        )
                    )
            if self.acs_limit_neg >= self.acs_limit_pos:
                issues.append(
                    ParameterIssue(
                        f"axis {self.name}: P-AXIS-00492 acs_limit_neg ({self.acs_limit_neg}) must be less "
                        f"than P-AXIS-00493 acs_limit_pos ({self.acs_limit_pos}) (both 0: off)",
                        field="acs_limit_neg",
                    )
                )
        vb_max_um_s = self.v_max * 1000.0 / 60.0
        if self.vb_messen > vb_max_um_s:
            issues.append(
                ParameterIssue(
                    f"axis {self.name}: P-AXIS-00215 vb_messen ({self.vb_messen} µm/s) must be at most the "
                    f"axis' maximum velocity (v_max {self.v_max:g} mm/min = {vb_max_um_s:.0f} µm/s)",
                    field="vb_messen",
                )
            )
        if self.coll_offset == 1:
            issues.append(
                ParameterIssue(
                    f"axis {self.name}: P-AXIS-00045 coll_offset must be 0 (none) or > 1 (1 < coll_offset)",
                    field="coll_offset",
                )
            )
        if self.axis_type is not AxisType.TRANSLATORY and (
            self.coll_check_ax_nr or self.collision_monitoring
        ):
            issues.append(
                ParameterIssue(
                    f"axis {self.name}: axis collision monitoring (FCT-C3) is for translatory axes only "
                    f"(axis type {self.axis_type.value})",
                    field="achs_mode" if self.collision_monitoring else "coll_check_ax_nr",
                )
            )
        _raise_issues(issues)
        return self

    @property
    def collision_monitoring(self) -> bool:
        """Bit 0x8000 of P-AXIS-00015 (FCT-C3)."""
        return bool(self.achs_mode & COLLISION_MODE_BIT)

    @property
    def emergency_deceleration(self) -> float:
        """P-AXIS-00003 in effect [mm/s²]: ``a_emergency``, or ``a_max`` where it is 0 (its page)."""
        return self.a_emergency or self.a_max


class ZeroOffset(_Strict):
    """One settable zero offset G54..G59 [0.1 µm per axis name]."""

    code: Literal["G54", "G55", "G56", "G57", "G58", "G59"] = Field(description="the zero offset's G code")
    offsets: dict[str, Dint] = Field(default_factory=dict, description="offset per axis name [0.1 µm]")


class ToolEntry(_Strict):
    """One tool compensation data block of the tool table (M-14): selected by ``D<number>``."""

    number: int = Field(ge=1, le=32767, description="the D number that selects this data block")
    tool: int | None = Field(
        default=None, ge=0, description="the tool number T this block belongs to (informative)"
    )
    length: Dint = Field(default=0, description="tool length, in the third main axis of the plane [0.1 µm]")
    radius: Dint = Field(default=0, description="tool radius for G41/G42 [0.1 µm]")
    kin_id: int = Field(
        default=0,
        ge=0,
        le=65535,
        description="P-TOOL-00011 the kinematic the tool selects (as #KIN ID; 0: the default or "
        "programmed one)",
    )


class ProbeConfig(_Strict):
    """The simulated touch probe of the built-in measuring cycles (docs/cycles.md, "The simulated probe"):
    the feeds the kernel's SysCalibConfigTouchprobe.nc gives, and the V.E. variables through which the PLC
    sets the simulated workpiece's deviation per axis."""

    measuring_feed: float = Field(
        default=100.0,
        gt=0.0,
        le=VELOCITY_LIMIT_MM_PER_MIN,
        description="feed of the measuring moves [mm/min]",
    )
    positioning_feed: float = Field(
        default=2000.0,
        gt=0.0,
        le=VELOCITY_LIMIT_MM_PER_MIN,
        description="feed of the measuring cycles' positioning moves [mm/min]",
    )
    deviation_variables: dict[str, Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]{0,19}$")]] = Field(
        default_factory=dict,
        description="axis -> V.E. variable (a REAL or integer scalar) holding the simulated workpiece's "
        "deviation along that axis [mm]; axes not named take the value set through the API or the harness",
    )


class ProgramEntry(_Strict):
    """A program the PLC can select by number (project's own program table)."""

    number: int = Field(ge=1, le=65535, description="program number the PLC selects")
    name: str = Field(description="program name")
    text: str | None = Field(default=None, description="the NC program text (DIN 66025)")
    path: str | None = Field(default=None, description="file of the NC program")

    @model_validator(mode="after")
    def _one_source(self) -> ProgramEntry:
        if (self.text is None) == (self.path is None):
            raise ValueError(f"program {self.number}: give exactly one of 'text' or 'path'")
        return self


KIN_PARAMS = 74
"""P-CHAN-00263: ``trafo[j].param[k]`` with k = 0..73."""


class KinematicAxis(_Strict):
    """One axis of a Universal Kinematics chain (type 91; P-CHAN-00291..00293), by axis index."""

    type: Literal[1, 2] = Field(description="P-CHAN-00291 1 linear (translator), 2 rotary (rotator)")
    orientation: tuple[float, float, float] = Field(description="P-CHAN-00292 direction, not the zero vector")
    point: tuple[float, float, float] = Field(
        default=(0.0, 0.0, 0.0), description="P-CHAN-00293 a point on a rotary axis [0.1 µm]"
    )


class KinematicEntry(_Strict):
    """One kinematic data set ``trafo[j]`` (P-CHAN-00262, P-CHAN-00263; TF5240, docs/kinematics.md)."""

    id: int = Field(ge=1, le=65535, description="P-CHAN-00262 kinematic ID")
    type: int = Field(default=0, ge=0, le=65535, description="P-CHAN-00829 kinematic type (0: the ID)")
    param: dict[int, float] = Field(
        default_factory=dict,
        description="P-CHAN-00263 param[k], k 0..73, in the kernel's units (0.1 µm, 0.0001°)",
    )
    zero_orientation: tuple[float, float, float] | None = Field(
        default=None, description="P-CHAN-00285 (Universal Kinematics) tool orientation in the zero position"
    )
    zero_position: tuple[float, float, float] | None = Field(
        default=None,
        description="P-CHAN-00286 (Universal Kinematics) tool position in the zero position [0.1 µm]",
    )
    axes: list[KinematicAxis] = Field(
        default_factory=list,
        description="P-CHAN-00289..00293 (Universal Kinematics) the chain's axes by axis index (3..6)",
    )
    chain: list[int] = Field(
        default_factory=list, description="P-CHAN-00290 (Universal Kinematics) axis indices in chain order"
    )
    programming_mode: int = Field(
        default=0, ge=0, le=19, description="P-CHAN-00288 (Universal Kinematics) programming mode"
    )
    rtcp: int = Field(
        default=0,
        ge=0,
        le=1,
        description="P-CHAN-00287 (Universal Kinematics) 1 RTCP, 0 complete transformation",
    )

    @property
    def universal(self) -> bool:
        return (self.type or self.id) == 91

    @model_validator(mode="after")
    def _check(self) -> KinematicEntry:
        issues: list[ParameterIssue] = []
        bad = sorted(k for k in self.param if not 0 <= k < KIN_PARAMS)
        if bad:
            issues.append(
                ParameterIssue(
                    f"kinematic {self.id}: param index {bad} outside 0..{KIN_PARAMS - 1}", field="param"
                )
            )
        named = self.zero_orientation is not None or self.zero_position is not None or bool(self.axes)
        if named and not self.universal:
            issues.append(
                ParameterIssue(
                    f"kinematic {self.id}: zero_orientation, zero_position and axes describe Universal "
                    "Kinematics (type 91); give type = 91",
                    field="axes",
                )
            )
        if named and any(k < 7 + 7 * max(len(self.axes), 1) for k in self.param):
            issues.append(
                ParameterIssue(
                    f"kinematic {self.id}: the named Universal Kinematics parameters fill param[0..]; "
                    "give them "
                    "either way, not both",
                    field="param",
                )
            )
        if self.axes and not 3 <= len(self.axes) <= 6:
            issues.append(
                ParameterIssue(
                    f"kinematic {self.id}: 3..6 axes (P-CHAN-00289), got {len(self.axes)}", field="axes"
                )
            )
        if self.chain and sorted(self.chain) != list(range(len(self.axes) or len(self.chain))):
            issues.append(
                ParameterIssue(
                    f"kinematic {self.id}: the chain {self.chain} must name each axis index once",
                    field="chain",
                )
            )
        _raise_issues(issues)
        return self


def _implicit(g: int, pid: str) -> str:
    return f'P-CHAN-{pid} the global subprogram G{g} calls ("" none: 20131)'


class ChannelConfig(_Strict):
    number: int = Field(default=1, ge=1, le=12, description="channel number (gpCh index + 1)")
    name: str = Field(default="Channel 1", description="channel name")
    axes: list[str] = Field(min_length=1, description="names of the axes of this channel")
    main_axes: tuple[str, str, str] = Field(
        default=("X", "Y", "Z"), description="first, second and third main axis (G17: X/Y, Z)"
    )
    interpolator_function: list[InterpolatorFunction] = Field(
        default_factory=lambda: [InterpolatorFunction.FCT_IPO_DEFAULT],
        description="P-STUP-00070 functions of the interpolator; FCT_DYN_POS_LIMIT enables FCT-C43",
    )
    messtyp: int = Field(
        default=1,
        ge=1,
        le=7,
        description="P-CHAN-00057 default measuring type of G100 (1..4; 5, 6 are G310's, 7 is not simulated)",
    )
    rel_offset_limits_std_manual_mode: bool = Field(
        default=False,
        description="P-CHAN-00114 the relative offset limits P-AXIS-00137/00138 apply in manual mode G200",
    )
    soft_limit_tolerance: bool = Field(
        default=False,
        description="P-CHAN-00120 software limit check of programmed positions with P-AXIS-00179 for axes "
        "the block does not move",
    )
    meas_error_no_signal: bool = Field(
        default=False, description="P-CHAN-00176 measuring type 1: error when no probe signal came"
    )
    meas_soft_limit_move_path: bool = Field(
        default=False, description="P-CHAN-00268 measuring moves (G100) may target beyond the software limits"
    )
    suppress_workspace_monitoring_manual_mode: int = Field(
        default=0,
        ge=0,
        le=2,
        description="P-CHAN-00442 work area monitoring in manual mode: 0 on, 1 off, 2 on without entry check",
    )
    dpl_tol_limit_change: int = Field(
        default=0,
        ge=0,
        lt=UDINT_MAX,
        description="P-CHAN-00751 tolerance for changing a dynamic position limit (FCT-C43) [0.1 µm]",
    )
    dpl_input_cycles: int = Field(
        default=0,
        ge=0,
        lt=UDINT_MAX,
        description="P-CHAN-00874 a new dynamic position limit is taken every n cycles (FCT-C43) [cycles]; "
        "0 and 1: every cycle",
    )
    slope_profile: int = Field(
        default=0,
        ge=0,
        le=3,
        description="P-CHAN-00071 acceleration profile at program start: 0 STEP, 1 TRAPEZ, 2 SIN2, 3 HSC "
        "(simulated as TRAPEZ)",
    )
    g80_prog_file: ProgName = Field(default="", description=_implicit(80, "00160"))
    g81_prog_file: ProgName = Field(default="", description=_implicit(81, "00161"))
    g82_prog_file: ProgName = Field(default="", description=_implicit(82, "00162"))
    g83_prog_file: ProgName = Field(default="", description=_implicit(83, "00163"))
    g84_prog_file: ProgName = Field(default="", description=_implicit(84, "00164"))
    g85_prog_file: ProgName = Field(default="", description=_implicit(85, "00165"))
    g86_prog_file: ProgName = Field(default="", description=_implicit(86, "00166"))
    g87_prog_file: ProgName = Field(default="", description=_implicit(87, "00167"))
    g88_prog_file: ProgName = Field(default="", description=_implicit(88, "00168"))
    g89_prog_file: ProgName = Field(default="", description=_implicit(89, "00169"))
    g800_prog_file: list[ProgName] = Field(
        default_factory=list,
        max_length=IMPLICIT_G800_COUNT,
        description='P-CHAN-00187 the global subprograms G800, G801, ... call (index i: G800+i; "" none: '
        "20131)",
    )
    feedhold_deceleration: float = Field(
        default=1000.0,
        gt=0.0,
        le=ACCELERATION_LIMIT,
        description="path deceleration of feedhold [mm/s²] (project's own)",
    )
    default_feedrate: float = Field(
        default=0.0,
        ge=0.0,
        le=VELOCITY_LIMIT_MM_PER_MIN,
        description="P-CHAN-00099 the feed of a G01/G02/G03 block at program start while no F is programmed "
        "[mm/min]; 0: an F word is needed",
    )
    kinematik_id: int = Field(
        default=0, ge=0, lt=1000, description="P-CHAN-00032 the default kinematic ID (0: none)"
    )
    kinematics: list[KinematicEntry] = Field(
        default_factory=list, description="the kinematic data sets trafo[j] (P-CHAN-00262/00263, TF5240)"
    )
    log_number_tracking_axis: int = Field(
        default=0,
        ge=0,
        le=65535,
        description="P-CHAN-00095 logical number of the #CAXTRACK axis (0: the axis named C of the channel)",
    )
    tool_ori_cs_axis: int = Field(
        default=0,
        ge=0,
        le=3,
        description="P-CHAN-00188 #TOOL ORI CS aligns the tool with X (1), Y (2), Z (3, and 0: the default)",
    )
    tool_ori_cs_mode: int = Field(
        default=0,
        ge=0,
        le=4,
        description="P-CHAN-00189 #TOOL ORI CS pose: 0 internal, 1 shortest way, 2 soft limits first, "
        "3/4 pose 1/2",
    )
    zero_offsets: list[ZeroOffset] = Field(default_factory=list)
    tools: list[ToolEntry] = Field(
        default_factory=list, description="tool table: D blocks with length and radius (M-14)"
    )
    programs: list[ProgramEntry] = Field(default_factory=list)
    cycle_directories: list[Annotated[str, Field(min_length=1, max_length=4096)]] = Field(
        default_factory=list,
        max_length=64,
        description="where `L CYCLE [NAME=..]` finds cycle files after the program directories, in order "
        "(relative to the machine file); a built-in stand-in runs where none has the file",
    )
    probe: ProbeConfig = Field(default_factory=ProbeConfig, description="the simulated touch probe")

    @property
    def dyn_pos_limit_enabled(self) -> bool:
        """C43-01: FCT_DYN_POS_LIMIT in P-STUP-00070."""
        return InterpolatorFunction.FCT_DYN_POS_LIMIT in self.interpolator_function

    @field_validator("interpolator_function", mode="before")
    @classmethod
    def _split_keywords(cls, value: Any) -> Any:
        """P-STUP-00070 as the documents write it: ``FCT_LOOK_AHEAD_STANDARD | FCT_DYN_POS_LIMIT``."""
        if isinstance(value, str):
            return [part.strip() for part in value.split("|")]
        return value

    @model_validator(mode="after")
    def _check_axes(self) -> ChannelConfig:
        issues: list[ParameterIssue] = []
        missing = [a for a in self.main_axes if a not in self.axes]
        if missing:
            issues.append(
                ParameterIssue(
                    f"channel {self.number}: main axes {missing} are not axes of the channel {self.axes}",
                    field="main_axes",
                )
            )
        if len(set(self.main_axes)) != len(self.main_axes):
            issues.append(
                ParameterIssue(
                    f"channel {self.number}: the three main axes must differ, got {list(self.main_axes)}",
                    field="main_axes",
                )
            )
        if len(set(self.axes)) != len(self.axes):
            issues.append(
                ParameterIssue(f"channel {self.number}: an axis is listed twice in {self.axes}", field="axes")
            )
        if len(set(self.interpolator_function)) != len(self.interpolator_function):
            issues.append(
                ParameterIssue(
                    f"channel {self.number}: P-STUP-00070 names a keyword twice: "
                    + " | ".join(f.value for f in self.interpolator_function),
                    field="interpolator_function",
                )
            )
        for axis in self.probe.deviation_variables:
            if axis not in self.axes:
                issues.append(
                    ParameterIssue(
                        f"channel {self.number}: probe.deviation_variables names axis {axis!r}, which is not "
                        f"an axis of the channel {self.axes}",
                        field="probe",
                    )
                )
        program_numbers = [p.number for p in self.programs]
        if len(set(program_numbers)) != len(program_numbers):
            issues.append(
                ParameterIssue(
                    f"channel {self.number}: program numbers must be unique, got {program_numbers}",
                    field="programs",
                )
            )
        codes = [z.code for z in self.zero_offsets]
        if len(set(codes)) != len(codes):
            issues.append(
                ParameterIssue(
                    f"channel {self.number}: each zero offset G54..G59 may be given once, got {codes}",
                    field="zero_offsets",
                )
            )
        kin_ids = [k.id for k in self.kinematics]
        if len(set(kin_ids)) != len(kin_ids):
            issues.append(
                ParameterIssue(
                    f"channel {self.number}: kinematic IDs (P-CHAN-00262) must be unique, got {kin_ids}",
                    field="kinematics",
                )
            )
        tool_numbers = [t.number for t in self.tools]
        if len(set(tool_numbers)) != len(tool_numbers):
            issues.append(
                ParameterIssue(
                    f"channel {self.number}: tool data numbers (D) must be unique, got {tool_numbers}",
                    field="tools",
                )
            )
        for z in self.zero_offsets:
            unknown = sorted(set(z.offsets) - set(self.axes))
            if unknown:
                issues.append(
                    ParameterIssue(
                        f"channel {self.number}: zero offset {z.code} names axes {unknown} "
                        f"that are not axes of the channel {self.axes}",
                        field="zero_offsets",
                    )
                )
        _raise_issues(issues)
        return self


class ManualConfig(_Strict):
    move_limit_warning: bool = Field(
        default=False, description="P-MANU-00014 warn when a manual move stops at a limit or area boundary"
    )


class AdapterEntry(_Strict):
    """An adapter ``hli-server run`` starts besides the HTTP API (project's own), e.g.
    ``[[adapters]]`` ``name = "modbus"`` ``options = { port = 5020, word_order = "CDAB" }``."""

    name: str = Field(pattern=r"^[a-z][a-z0-9_]*$", description="adapter name (modbus, ...)")
    options: dict[str, str | int | float | bool] = Field(
        default_factory=dict,
        description="the adapter's options, as for --adapter NAME:key=value (seconds end in _s; each door's "
        "options: docs/api.md, modbus.md, ads.md, mqtt.md)",
    )


_V_E_NAME = r"^[A-Za-z_][A-Za-z0-9_]{0,19}$"
MAX_EXTERNAL_INIT_LENGTH = 512
"""The characters of one ``external_init`` assignment (an NC block's worth; P-EXTV-00013)."""
"""A V.E. name, and each name of a structure's element: at most 20 characters, as the kernel allows."""
_ACCESS_RIGHTS = Literal["READ_WRITE", "READ_ONLY", "WRITE_ONLY"]


def _type_name(value: str) -> str:
    """The kernel's type names in upper case (``sgn32`` is SGN32); a structure's name as written."""
    from schemas.external_types import ELEMENTARY_TYPES, STRING_TYPES

    upper = value.upper()
    return upper if upper in ELEMENTARY_TYPES or upper in STRING_TYPES else value


class _ExternalTyped(_Strict):
    """What a V.E. variable and an element of a structure both declare: name, type, dimensions, size."""

    _what: ClassVar[str] = "V.E."
    _size_parameter: ClassVar[str] = "P-EXTV-00008"

    name: str = Field(
        pattern=_V_E_NAME,
        description="name without the prefix V.E. (an element's: V.E.variable.element; at most 20 "
        "characters, as the kernel allows)",
    )
    type: str = Field(
        default="REAL64",
        pattern=r"^[A-Za-z_][A-Za-z0-9_]{0,31}$",
        description="data type (the kernel's names: elementary, STRING, VSTRING, or a structure of "
        "external_structures)",
    )
    dims: list[Annotated[int, Field(ge=1, le=65535)]] = Field(
        default_factory=list, max_length=4, description="array dimensions; empty for a scalar"
    )
    size: int | None = Field(
        default=None,
        ge=1,
        le=800,
        description="VSTRING only: bytes of the string with its terminating NUL (default 128: 127 "
        "characters)",
    )

    @field_validator("type")
    @classmethod
    def _kernel_type_name(cls, value: str) -> str:
        return _type_name(value)

    @model_validator(mode="after")
    def _size_of_vstring(self) -> Self:
        if self.size is not None and self.type != "VSTRING":
            raise ValueError(
                f"{self._what}{self.name}: size is the length of a VSTRING ({self._size_parameter}); a "
                f"{self.type} has its type's size (a STRING's follows use_extended_string_var)"
            )
        return self


class ExternalVariableConfig(_ExternalTyped):
    """A ``V.E.`` variable shared by NC programs and the PLC (N-05): the kernel's configuration list of
    external variables, reduced to what the simulator needs (project's own shape; docs/nc-language.md)."""

    channel: int | None = Field(
        default=None, ge=1, le=12, description="the channel whose own area holds it; none: the global area"
    )
    synchronous: bool = Field(
        default=False, description="read by the interpolator (reading it empties the channel first)"
    )
    access_rights: _ACCESS_RIGHTS = Field(
        default="READ_WRITE",
        description="what an NC program may do with it (the PLC may always read and write)",
    )
    description: str = Field(
        default="", max_length=200, description="what it means (shown by `hli-server map` and the dashboard)"
    )


class ExternalElementConfig(_ExternalTyped):
    """One element of a V.E. structure (``struct[i].element[j].*``, P-EXTV-00016 .. 00021)."""

    _what: ClassVar[str] = "element "
    _size_parameter: ClassVar[str] = "P-EXTV-00021"

    synchronous: bool | None = Field(
        default=None, description="none: the variable's synchronisation (inherited)"
    )
    access_rights: _ACCESS_RIGHTS | None = Field(
        default=None, description="none: the variable's access rights (inherited)"
    )


class ExternalStructureConfig(_Strict):
    """A structure type of V.E. variables (``struct[i].*``, P-EXTV-00015): its elements in memory order."""

    name: str = Field(
        pattern=r"^[A-Za-z_][A-Za-z0-9_]{0,31}$",
        description="the type's name (what a variable's type names; the ADS type of its symbols)",
    )
    elements: list[ExternalElementConfig] = Field(
        min_length=1, max_length=256, description="the elements, in memory order"
    )
    description: str = Field(default="", max_length=200, description="what it means")

    @model_validator(mode="after")
    def _unique_elements(self) -> ExternalStructureConfig:
        seen: set[str] = set()
        for element in self.elements:
            if element.name.upper() in seen:
                raise ValueError(
                    f"structure {self.name}: element {element.name} is declared twice (names are "
                    "case-insensitive)"
                )
            seen.add(element.name.upper())
        return self


def _check_probe_variables(config: MachineConfig) -> list[ParameterIssue]:
    """Each channel's ``probe.deviation_variables``: a declared V.E. variable of the channel (or global), a
    numeric scalar (docs/cycles.md, "The simulated probe")."""
    from schemas.external_types import ELEMENTARY_TYPES

    issues: list[ParameterIssue] = []
    for ch in config.channels:
        for axis, var_name in ch.probe.deviation_variables.items():
            declared = [
                v
                for v in config.external_variables
                if v.name.upper() == var_name.upper() and v.channel in (None, ch.number)
            ]
            if not declared:
                what = f"{var_name!r}: no such V.E. variable in [[external_variables]]"
            elif (
                declared[0].dims or declared[0].type not in ELEMENTARY_TYPES or declared[0].type == "BOOLEAN"
            ):
                it = f"{declared[0].type}{declared[0].dims or ''}"
                what = f"V.E.{var_name} must be a numeric scalar (it is {it})"
            else:
                continue
            issues.append(
                ParameterIssue(
                    f"channel {ch.number}: probe.deviation_variables {axis} = {what}",
                    field="probe",
                    channel=ch.number,
                )
            )
    return issues


def _check_external_types(config: MachineConfig) -> list[ParameterIssue]:
    """The V.E. structures: unique names, no clash with the kernel's types, every type known, no structure
    that contains itself (schemas/external_types.py resolves them)."""
    from schemas.external_types import (
        ELEMENTARY_TYPES,
        STRING_TYPES,
        ExternalTypeError,
        resolve_structures,
        variable_type,
    )

    issues: list[ParameterIssue] = []
    seen: set[str] = set()
    for structure in config.external_structures:
        key = structure.name.upper()
        if key in ELEMENTARY_TYPES or key in STRING_TYPES:
            issues.append(
                ParameterIssue(
                    f"structure {structure.name}: the name of one of the kernel's types",
                    field="external_structures",
                )
            )
        elif key in seen:
            issues.append(
                ParameterIssue(
                    f"structure {structure.name} is declared twice (names are case-insensitive)",
                    field="external_structures",
                )
            )
        seen.add(key)
    if issues:
        return issues
    try:
        structures = resolve_structures(config.external_structures, extended=config.use_extended_string_var)
    except ExternalTypeError as exc:
        return [ParameterIssue(str(exc), field="external_structures")]
    for index, variable in enumerate(config.external_variables):
        try:
            variable_type(variable, structures, extended=config.use_extended_string_var)
        except ExternalTypeError as exc:
            issues.append(ParameterIssue(str(exc), field="external_variables", at=(index, "type")))
    return issues


class MachineConfig(_Strict):
    name: str = Field(default="machine", description="machine name (reports, MQTT topics)")
    cycle_time_us: int = Field(default=1000, ge=100, le=100_000, description="interpolation cycle T_A [µs]")
    axes: list[AxisConfig] = Field(min_length=1)
    channels: list[ChannelConfig] = Field(min_length=1)
    manual: ManualConfig = Field(default_factory=ManualConfig)
    adapters: list[AdapterEntry] = Field(
        default_factory=list,
        description="adapters `hli-server run` starts (its --adapter options add to or replace them by name)",
    )
    external_variables: list[ExternalVariableConfig] = Field(
        default_factory=list, max_length=1024, description="V.E. variables shared by NC programs and the PLC"
    )
    external_structures: list[ExternalStructureConfig] = Field(
        default_factory=list, max_length=256, description="structure types of V.E. variables"
    )
    external_init: list[
        Annotated[str, Field(min_length=1, max_length=MAX_EXTERNAL_INIT_LENGTH, pattern=r"^[^\r\n]*$")]
    ] = Field(
        default_factory=list,
        max_length=1024,
        description="assignments to V.E. variables run in order at each start of the machine "
        '(`V.E.TEACH_FILE_NAME = "teach.nc"`; values may use other V.E. variables; docs/nc-language.md)',
    )
    use_extended_string_var: bool = Field(
        default=False,
        description="P-EXTV-00022 a V.E. STRING holds 127 characters (128 bytes) instead of 20 (21 bytes)",
    )
    program_directories: list[Annotated[str, Field(min_length=1, max_length=4096)]] = Field(
        default_factory=list,
        max_length=64,
        description="where `L name` finds global subprograms and cycles, in order (relative to the machine "
        "file)",
    )

    @model_validator(mode="after")
    def _check_machine(self) -> MachineConfig:
        """E-07: machine-wide checks; C3-04: the collision pairs (FCT-C3 section 2 and 4.2)."""
        issues: list[ParameterIssue] = []
        names = [a.name for a in self.axes]
        seen_names: set[str] = set()
        seen_numbers: dict[int, str] = {}
        for a in self.axes:
            if a.name in seen_names:
                issues.append(
                    ParameterIssue(f"axis names must be unique: {names}", field="name", axis=a.name)
                )
            seen_names.add(a.name)
            if a.number in seen_numbers:
                issues.append(
                    ParameterIssue(
                        f"axis {a.name}: logical axis number (kopf.achs_nr) {a.number} is already used "
                        f"by axis {seen_numbers[a.number]}; the numbers must be unique",
                        field="number",
                        axis=a.name,
                    )
                )
            else:
                seen_numbers[a.number] = a.name
        owner: dict[str, int] = {}
        for ch in self.channels:
            for ax_name in ch.axes:
                if ax_name not in names:
                    issues.append(
                        ParameterIssue(
                            f"channel {ch.number}: unknown axis {ax_name!r} (axes: {names})",
                            field="axes",
                            channel=ch.number,
                        )
                    )
                elif ax_name in owner and owner[ax_name] != ch.number:
                    issues.append(
                        ParameterIssue(
                            f"axis {ax_name} belongs to channel {owner[ax_name]} and channel {ch.number}",
                            field="axes",
                            channel=ch.number,
                        )
                    )
                owner.setdefault(ax_name, ch.number)
        ch_numbers = [c.number for c in self.channels]
        if len(set(ch_numbers)) != len(ch_numbers):
            issues.append(
                ParameterIssue(
                    f"channel numbers must be unique: {ch_numbers}",
                    field="number",
                    channel=next(n for n in ch_numbers if ch_numbers.count(n) > 1),
                )
            )
        seen_vars: set[tuple[int | None, str]] = set()
        for var in self.external_variables:
            key = (var.channel, var.name.upper())
            area = "the global area" if var.channel is None else f"channel {var.channel}'s area"
            if var.channel is not None and var.channel not in ch_numbers:
                issues.append(
                    ParameterIssue(
                        f"V.E.{var.name}: channel {var.channel} does not exist (channels: {ch_numbers})",
                        field="external_variables",
                    )
                )
            if key in seen_vars:
                issues.append(
                    ParameterIssue(
                        f"V.E.{var.name} is declared twice in {area} (names are case-insensitive)",
                        field="external_variables",
                    )
                )
            seen_vars.add(key)
        issues += _check_external_types(self)
        issues += _check_probe_variables(self)
        if not issues:
            too_much = check_external_fits(self)
            if too_much is not None:
                issues.append(ParameterIssue(too_much, field="external_variables"))
        by_number = {a.number: a for a in self.axes}
        for ax in self.axes:
            if not ax.coll_check_ax_nr:
                continue
            partner = by_number.get(ax.coll_check_ax_nr)
            if partner is None:
                issues.append(
                    ParameterIssue(
                        f"axis {ax.name}: P-AXIS-00043 coll_check_ax_nr {ax.coll_check_ax_nr} "
                        f"is no logical axis number (numbers: {sorted(by_number)})",
                        field="coll_check_ax_nr",
                        axis=ax.name,
                    )
                )
                continue
            if partner is ax:
                issues.append(
                    ParameterIssue(
                        f"axis {ax.name}: P-AXIS-00043 coll_check_ax_nr names the axis itself",
                        field="coll_check_ax_nr",
                        axis=ax.name,
                    )
                )
                continue
            for member in (ax, partner):
                if not member.collision_monitoring:
                    issues.append(
                        ParameterIssue(
                            f"axes {ax.name}/{partner.name}: a collision pair needs bit 0x8000 in "
                            f"P-AXIS-00015 kenngr.achs_mode of both axes; axis {member.name} has "
                            f"0x{member.achs_mode:X} (set 0x{member.achs_mode | COLLISION_MODE_BIT:X})",
                            field="achs_mode",
                            axis=member.name,
                        )
                    )
            if ax.coll_offset <= 1 and partner.coll_offset <= 1:
                issues.append(
                    ParameterIssue(
                        f"axis {ax.name}: a collision pair needs P-AXIS-00045 coll_offset > 1 "
                        "(the minimum distance in 0.1 µm) on the master axis",
                        field="coll_offset",
                        axis=ax.name,
                    )
                )
        _raise_issues(issues)
        return self

    def collision_pairs(self) -> list[tuple[AxisConfig, AxisConfig]]:
        """C3-03/C3-04: (master, partner) per pair; a two-sided pair (older configuration) once."""
        by_number = {a.number: a for a in self.axes}
        pairs: list[tuple[AxisConfig, AxisConfig]] = []
        seen: set[frozenset[int]] = set()
        for ax in self.axes:
            partner = by_number.get(ax.coll_check_ax_nr) if ax.coll_check_ax_nr else None
            if partner is None or partner is ax:
                continue
            key = frozenset((ax.number, partner.number))
            if key not in seen:
                seen.add(key)
                pairs.append((ax, partner))
        return pairs

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
    """One ISG parameter the configuration accepts: its text-list path, model field, P-ID, unit, the
    kernel page that gives its default and range (B-04, docs/alarms.md), and why our default differs where
    it does (``note``; empty where ours is the kernel's)."""

    model_config = ConfigDict(frozen=True)
    path: str | None
    """ISG text-list path; None where the kernel's public pages do not name it (TOML only)."""
    field: str
    pid: str | None
    unit: str
    page: str = ""
    """URL of the kernel's parameter page, or the function description's section (``FCT-C3 4.2``)."""
    note: str = ""


_AX = "https://infosys.beckhoff.com/content/1033/tf5200_axis_parameter/"
_AX_DE = "https://infosys.beckhoff.com/content/1031/tf5200_axis_parameter/"
_CH = "https://infosys.beckhoff.com/content/1033/tf5200_channel_parameter/"
_FCT_C3 = "https://infosys.beckhoff.com/content/1033/tf5200_axis_collision_mon/286688651.html"
_OFFSET_LIMITS = "https://infosys.beckhoff.com/content/1033/tf5200_manual_mode_offset_limit/"


def _infos(rows: tuple[tuple[str | None, str, str | None, str, str, str], ...]) -> tuple[ParameterInfo, ...]:
    return tuple(ParameterInfo(path=p, field=f, pid=i, unit=u, page=g, note=n) for p, f, i, u, g, n in rows)


AXIS_PARAMETERS: tuple[ParameterInfo, ...] = _infos(
    (
        ("kopf.achs_nr", "number", None, "-", "", ""),
        ("kopf.achs_name", "name", None, "-", "", ""),
        ("kopf.achs_typ", "axis_type", None, "T|R", "", ""),
        ("kenngr.achs_mode", "achs_mode", "P-AXIS-00015", "-", "FCT-C3 4.2", ""),
        (
            "getriebe[0].dynamik.a_emergency",
            "a_emergency",
            "P-AXIS-00003",
            "mm/s²",
            _AX + "117643787.html",
            "",
        ),
        (
            "getriebe[0].dynamik.a_max",
            "a_max",
            "P-AXIS-00008",
            "mm/s²",
            _AX + "117642251.html",
            "range: the kernel allows up to 100000000 (a plausibility limit); we stop at 1000000 (about "
            "100 g), which keeps braking distances and ramp times meaningful",
        ),
        ("kenngr.coll_check_ax_nr", "coll_check_ax_nr", "P-AXIS-00043", "-", "FCT-C3 4.2", ""),
        ("kenngr.coll_decelerate_chan", "coll_decelerate_chan", "P-AXIS-00044", "0/1", "FCT-C3 4.2", ""),
        ("kenngr.coll_offset", "coll_offset", "P-AXIS-00045", "0.1 µm", "FCT-C3 4.2", ""),
        ("kenngr.mess_offset", "mess_offset", "P-AXIS-00114", "0.1 µm", _AX_DE + "117323787.html", ""),
        ("kenngr.messachse", "messachse", "P-AXIS-00118", "0/1", _AX_DE + "117319179.html", ""),
        (
            "handbetrieb.offsetgrenze_neg",
            "offsetgrenze_neg",
            "P-AXIS-00137",
            "0.1 µm",
            _AX + "118110347.html",
            "",
        ),
        (
            "handbetrieb.offsetgrenze_pos",
            "offsetgrenze_pos",
            "P-AXIS-00138",
            "0.1 µm",
            _AX + "118108811.html",
            "",
        ),
        (
            "getriebe[0].pos_einschw_zeit",
            "settling_time_legacy_us",
            "P-AXIS-00151",
            "µs",
            _AX + "117751051.html",
            "",
        ),
        ("kenngr.swe_neg", "swe_neg", "P-AXIS-00177", "0.1 µm", _AX + "117313035.html", ""),
        ("kenngr.swe_pos", "swe_pos", "P-AXIS-00178", "0.1 µm", _AX + "117311499.html", ""),
        ("kenngr.swe_toleranz", "swe_toleranz", "P-AXIS-00179", "0.1 µm", _AX + "117309963.html", ""),
        ("kenngr.vb_messen", "vb_messen", "P-AXIS-00215", "µm/s", _AX + "117322251.html", ""),
        (
            "getriebe[0].window",
            "window",
            "P-AXIS-00236",
            "0.1 µm",
            "https://infosys.beckhoff.com/content/1033/tf5200_axis_position_monitoring/92801291.html",
            "",
        ),
        (
            "kenngr.coll_moving_dir_inverted",
            "coll_moving_dir_inverted",
            "P-AXIS-00262",
            "0/1",
            "FCT-C3 4.2",
            "",
        ),
        (
            "kenngr.coll_zero_position_offset",
            "coll_zero_position_offset",
            "P-AXIS-00263",
            "0.1 µm",
            _AX + "117418507.html",
            "",
        ),
        ("kenngr.coll_use_a_emergency", "coll_use_a_emergency", "P-AXIS-00267", "0/1", "FCT-C3 4.2", ""),
        (
            None,
            "meas_offset",
            "P-AXIS-00467",
            "0.1 µm",
            _AX_DE + "117323787.html",
            "the kernel's public pages name P-AXIS-00467 (on the page of P-AXIS-00114, which it replaces, "
            "and in FCT-C14's P-CHAN-00268) but show neither its text-list path nor its default: TOML key "
            "only, default 0 as P-AXIS-00114's",
        ),
        (
            "handbetrieb.acs_limit_neg",
            "acs_limit_neg",
            "P-AXIS-00492",
            "0.1 µm",
            _OFFSET_LIMITS + "77659787.html",
            "",
        ),
        ("handbetrieb.acs_limit_pos", "acs_limit_pos", "P-AXIS-00493", "0.1 µm", _AX + "118116619.html", ""),
        (
            "getriebe[0].slope_profil.tr_beschl_ab",
            "tr_beschl_ab",
            "P-AXIS-00195",
            "µs",
            _AX + "117619339.html",
            "",
        ),
        (
            "getriebe[0].slope_profil.tr_beschl_zu",
            "tr_beschl_zu",
            "P-AXIS-00196",
            "µs",
            _AX + "117617803.html",
            "",
        ),
        (
            "getriebe[0].slope_profil.tr_brems_ab",
            "tr_brems_ab",
            "P-AXIS-00197",
            "µs",
            _AX + "117622411.html",
            "",
        ),
        (
            "getriebe[0].slope_profil.tr_brems_zu",
            "tr_brems_zu",
            "P-AXIS-00198",
            "µs",
            _AX + "117620875.html",
            "",
        ),
        (
            "getriebe[0].position_settling_time",
            "position_settling_time_us",
            "P-AXIS-00532",
            "µs",
            _AX + "117752587.html",
            "",
        ),
    )
)
"""ISG text-list paths of the axis parameters (and the three header entries)."""

AXIS_PARAMETER_ALIASES: dict[str, str] = {"getriebe[0].settling_time": "getriebe[0].pos_einschw_zeit"}
"""Paths of an earlier version of this project that a list may still use (read with a warning): the
kernel's path of P-AXIS-00151 is ``getriebe[i].pos_einschw_zeit`` (its parameter page)."""

CHANNEL_PARAMETERS: tuple[ParameterInfo, ...] = _infos(
    (
        (
            "messtyp",
            "messtyp",
            "P-CHAN-00057",
            "-",
            "https://infosys.beckhoff.com/content/1033/tf5200_measurement/342039563.html",
            'the kernel\'s page gives no default ("-"); we take 1, the type G100 had here before',
        ),
        (
            "rel_offset_limits_std_manual_mode",
            "rel_offset_limits_std_manual_mode",
            "P-CHAN-00114",
            "0/1",
            _OFFSET_LIMITS + "77661323.html",
            "",
        ),
        ("soft_limit_tolerance", "soft_limit_tolerance", "P-CHAN-00120", "0/1", _CH + "149357707.html", ""),
        (
            "meas_error_no_signal",
            "meas_error_no_signal",
            "P-CHAN-00176",
            "0/1",
            "https://infosys.beckhoff.com/content/1033/tccncchannelparameter/15274803083.html",
            "",
        ),
        ("meas_soft_limit_move_path", "meas_soft_limit_move_path", "P-CHAN-00268", "0/1", "FCT-C14 6.2", ""),
        (
            "suppress_workspace_monitoring_manual_mode",
            "suppress_workspace_monitoring_manual_mode",
            "P-CHAN-00442",
            "0/1/2",
            "FCT-C14 6.2",
            "",
        ),
        (
            "dpl_tol_limit_change",
            "dpl_tol_limit_change",
            "P-CHAN-00751",
            "0.1 µm",
            _CH + "915821323.html",
            "",
        ),
        ("dpl_input_cycles", "dpl_input_cycles", "P-CHAN-00874", "cycles", _CH + "1201698699.html", ""),
        ("prog_start.feedrate", "default_feedrate", "P-CHAN-00099", "mm/min", _CH + "149303051.html", ""),
        (
            "kinematik_id",
            "kinematik_id",
            "P-CHAN-00032",
            "-",
            "https://infosys.beckhoff.com/content/1033/tf5200_trafo_interface/441082251.html",
            "",
        ),
        (
            "log_number_tracking_axis",
            "log_number_tracking_axis",
            "P-CHAN-00095",
            "-",
            _CH + "149106571.html",
            "",
        ),
        ("tool_ori_cs.axis", "tool_ori_cs_axis", "P-CHAN-00188", "0..3", _CH + "149277323.html", ""),
        ("tool_ori_cs.mode", "tool_ori_cs_mode", "P-CHAN-00189", "0..4", _CH + "347022219.html", ""),
        *(
            (f"g8{k}_prog_file", f"g8{k}_prog_file", f"P-CHAN-0016{k}", "-", _CH + "149417611.html", "")
            for k in range(10)
        ),
        ("g800_prog_file[i]", "g800_prog_file", "P-CHAN-00187", "-", _CH + "149419147.html", ""),
        (
            "prog_start.slope.profile",
            "slope_profile",
            "P-CHAN-00071",
            "0..3",
            "https://infosys.beckhoff.com/content/1033/tf5200_oscillating_axis/222124555.html",
            "",
        ),
        # a start-up parameter (P-STUP) that belongs to one channel; [0] stands for the channel's index
        (
            "configuration.channel[0].interpolator.function",
            "interpolator_function",
            "P-STUP-00070",
            "-",
            "FCT-C43 3",
            "",
        ),
    )
)
"""ISG text-list names of the channel parameters."""

MANUAL_PARAMETERS: tuple[ParameterInfo, ...] = _infos(
    (("move_limit_warning", "move_limit_warning", "P-MANU-00014", "0/1", "FCT-C14 6.2", ""),)
)
"""ISG text-list names of the manual-mode parameters (FCT-C14 6.2)."""

_UK = "https://infosys.beckhoff.com/content/1033/tf5240_universal_kinematic/"
KINEMATIC_PARAMETERS: tuple[ParameterInfo, ...] = _infos(
    (
        ("trafo[0].id", "id", "P-CHAN-00262", "-", _CH + "149247371.html", ""),
        (
            "trafo[0].type",
            "type",
            "P-CHAN-00829",
            "-",
            "https://infosys.beckhoff.com/content/1033/tf5240_kinematic_transformation/893485323.html",
            "",
        ),
        ("trafo[0].param[k]", "param", "P-CHAN-00263", "0.1 µm / 0.0001°", _CH + "149248907.html", ""),
        ("trafo[0].zero_orientation[l]", "zero_orientation", "P-CHAN-00285", "-", _UK + "893810955.html", ""),
        ("trafo[0].zero_position[l]", "zero_position", "P-CHAN-00286", "0.1 µm", _UK + "893810955.html", ""),
        ("trafo[0].chain[k]", "chain", "P-CHAN-00290", "-", _CH + "149260683.html", ""),
        ("trafo[0].programming_mode", "programming_mode", "P-CHAN-00288", "-", _CH + "149257611.html", ""),
        ("trafo[0].rtcp", "rtcp", "P-CHAN-00287", "0/1", _CH + "149256075.html", ""),
    )
)
"""The channel parameters of a kinematic data set ``trafo[j]`` (TOML only: ``[[channels.kinematics]]``)."""
KINEMATIC_AXIS_PARAMETERS: tuple[ParameterInfo, ...] = _infos(
    (
        ("trafo[0].axis[k].type", "type", "P-CHAN-00291", "1/2", _CH + "149263755.html", ""),
        ("trafo[0].axis[k].orientation[l]", "orientation", "P-CHAN-00292", "-", _UK + "893810955.html", ""),
        ("trafo[0].axis[k].point[l]", "point", "P-CHAN-00293", "0.1 µm", _CH + "149266827.html", ""),
    )
)
"""The axes of a Universal Kinematics data set (``axes = [{...}]``; the count is P-CHAN-00289)."""
TOOL_PARAMETERS: tuple[ParameterInfo, ...] = _infos(
    (
        (
            "wz[0].kin_id",
            "kin_id",
            "P-TOOL-00011",
            "-",
            "https://infosys.beckhoff.com/content/1033/tf5200_tool_data/104788875.html",
            "",
        ),
    )
)
"""The tool data the tool table takes from the kernel's tool list (the rest of a D block is the project's)."""

_EXTV = "https://infosys.beckhoff.com/content/1033/tf5200_external_variables/"
EXTERNAL_VARIABLE_PARAMETERS: tuple[ParameterInfo, ...] = _infos(
    (
        ("var[0].name", "name", "P-EXTV-00001", "-", _EXTV + "307199243.html", ""),
        (
            "var[0].type",
            "type",
            "P-EXTV-00003",
            "-",
            _EXTV + "307199243.html",
            "the kernel's default is UNS32 (a list without var[i].type reads so); REAL64 here",
        ),
        ("var[0].array_elements", "dims", "P-EXTV-00007", "-", _EXTV + "307199243.html", ""),
        ("var[0].size", "size", "P-EXTV-00008", "byte", _EXTV + "112465803.html", ""),
        (
            "var[0].scope",
            "channel",
            "P-EXTV-00004",
            "-",
            _EXTV + "307199243.html",
            "the kernel's default is CHANNEL (the list's channel); a table names no channel: the global area",
        ),
        (
            "var[0].synchronisation",
            "synchronous",
            "P-EXTV-00005",
            "-",
            _EXTV + "112461195.html",
            "the kernel's default is TRUE (a list without the entry reads so); FALSE here",
        ),
        ("var[0].access_rights", "access_rights", "P-EXTV-00006", "-", _EXTV + "112462731.html", ""),
    )
)
"""The kernel's list of external variables (``external_variables_list``; ``var[i]`` stands for the
variable's index): which entry gives which field of :class:`ExternalVariableConfig` (N-05)."""

EXTERNAL_STRUCTURE_PARAMETERS: tuple[ParameterInfo, ...] = _infos(
    (
        ("struct[0].name", "name", "P-EXTV-00015", "-", _EXTV + "307199243.html", ""),
        ("struct[0].element[j]", "elements", "P-EXTV-00016", "-", _EXTV + "307199243.html", ""),
    )
)
"""A list's ``struct[i]`` entries: :class:`ExternalStructureConfig` (N-05)."""

MACHINE_EXTERNAL_PARAMETERS: tuple[ParameterInfo, ...] = _infos(
    (
        (
            "use_extended_string_var",
            "use_extended_string_var",
            "P-EXTV-00022",
            "-",
            _EXTV + "112451979.html",
            "",
        ),
        (
            "init",
            "external_init",
            "P-EXTV-00013",
            "-",
            _EXTV + "112479371.html",
            "one assignment a string, in the list's order; a failed one is warning 21840/21841 at start",
        ),
    )
)
"""The general entries of a list of external variables that are machine-wide fields here (N-05)."""

EXTERNAL_ELEMENT_PARAMETERS: tuple[ParameterInfo, ...] = _infos(
    (
        ("struct[0].element[j].name", "name", "P-EXTV-00016", "-", _EXTV + "307199243.html", ""),
        (
            "struct[0].element[j].type",
            "type",
            "P-EXTV-00017",
            "-",
            _EXTV + "112444299.html",
            "the kernel's default is UNS32 (a list without the entry reads so); REAL64 here",
        ),
        (
            "struct[0].element[j].synchronisation",
            "synchronous",
            "P-EXTV-00018",
            "-",
            _EXTV + "112445835.html",
            "",
        ),
        (
            "struct[0].element[j].access_rights",
            "access_rights",
            "P-EXTV-00019",
            "-",
            _EXTV + "307199243.html",
            "",
        ),
        ("struct[0].element[j].array_elements", "dims", "P-EXTV-00020", "-", _EXTV + "307199243.html", ""),
        ("struct[0].element[j].size", "size", "P-EXTV-00021", "byte", _EXTV + "112450443.html", ""),
    )
)
"""A list's ``struct[i].element[j]`` entries: :class:`ExternalElementConfig` (N-05)."""
