"""Request and response bodies of the control API (pydantic at the edge)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StrictBool,
    StrictFloat,
    StrictInt,
    StrictStr,
    model_validator,
)

from hli_server.adapters.host import (
    CHECK_MAX_CYCLES,
    CHECK_MAX_ITERATIONS,
    CHECK_MAX_TIMEOUT_S,
    CHECK_TIMEOUT_S,
)

__all__ = [
    "MAX_PROGRAM_FILES",
    "MAX_STEP",
    "MAX_TRACE_SIGNALS",
    "MAX_TRACE_VALUES",
    "AcceptedBody",
    "CheckBody",
    "FaultsBody",
    "FeedholdBody",
    "ImageWriteBody",
    "JogBody",
    "ModeBody",
    "OverrideBody",
    "ProbeBody",
    "ProbeDeviationBody",
    "ProgramBody",
    "SelectBody",
    "StepBody",
]

MAX_STEP = 1_000_000
"""Most cycles one ``POST /api/step`` may ask for (1 000 s of simulated time at 1 ms; about ten seconds of
the compiled engine's CPU, a minute or two of the pure-Python one). Longer runs go in parts: one step runs
at a time, and closing its connection cancels it (reliability.md, round 2, finding 6)."""
MAX_TRACE_SIGNALS = 64
"""Most signals one ``POST /api/step`` may trace."""
MAX_TRACE_VALUES = 2_000_000
"""Most traced values (cycles x signals) in one answer (tens of MB of JSON)."""


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid")


MAX_PROGRAM_FILES = 256
"""Most subprogram files one program load may bring (``ProgramBody.files``)."""


class ProgramBody(_Body):
    text: str = Field(min_length=1, description="the NC program (DIN 66025 blocks, one per line)")
    name: str = Field(default="program", min_length=1, max_length=200, description="shown in the state")
    files: dict[Annotated[str, Field(min_length=1, max_length=255)], str] = Field(
        default_factory=dict,
        max_length=MAX_PROGRAM_FILES,
        description="its subprograms and cycles, file name -> NC text: `L name` finds them before the "
        "program directories (a name below a directory, e.g. cycles/drill.nc; no '..', not absolute)",
    )


class CheckBody(ProgramBody):
    """``POST /api/check``: a program (with its subprograms) to check offline, as ``hli-server check``."""

    channel: int = Field(default=1, ge=1, le=255, description="the channel to run it in")
    geometry_only: bool = Field(
        default=False,
        description="interpret and check every block's whole path without cycles (``check --geometry-only``)",
    )
    max_cycles: int = Field(
        default=CHECK_MAX_CYCLES,
        ge=1,
        le=50_000_000,
        description="a full check stops here (status `capped`) if the program has not ended",
    )
    max_iterations: int = Field(
        default=CHECK_MAX_ITERATIONS,
        ge=1,
        le=100_000_000,
        description="a geometry check stops after this many loop iterations and jumps back (status `capped`)",
    )
    timeout_s: float = Field(
        default=CHECK_TIMEOUT_S,
        gt=0,
        le=CHECK_MAX_TIMEOUT_S,
        description="wall-clock limit [s]: past it the check is ended and the answer is 504",
    )
    presets: dict[str, StrictBool | StrictInt | StrictFloat | StrictStr] = Field(
        default_factory=dict,
        max_length=4096,
        description='V.E. values before the start, as the PLC would give them (`{"V.E.PLC_READY": true}`; '
        "`check --set`): a number or a boolean (a string for a V.E. STRING)",
    )


class SelectBody(_Body):
    number: int = Field(ge=1, le=65535, description="program number in the channel's program table")


class FeedholdBody(_Body):
    on: StrictBool = Field(description="true: hold the path; false: release it")


class ProbeBody(_Body):
    on: StrictBool = Field(description="the probe input for G100 measuring moves (C14-23)")


class ProbeDeviationBody(_Body):
    deviation: dict[str, StrictInt] = Field(
        description='the simulated workpiece\'s deviation per axis name [0.1 µm], e.g. {"X": 2000} = 0.2 mm; '
        "the axes not named keep theirs",
        min_length=1,
    )


class ModeBody(_Body):
    mode: Literal["automatic", "manual"]


class OverrideBody(_Body):
    percent: float = Field(ge=0.0, le=120.0, description="feed override 0..120 %, in steps of 0.1 %")


class JogBody(_Body):
    axis: str = Field(description="axis name of this channel, e.g. X")
    direction: Literal[-1, 0, 1] = Field(description="+1 / -1: key pressed; 0: key released")


class StepBody(_Body):
    cycles: int = Field(default=1, ge=1, le=MAX_STEP, description="cycles of T_A to run")
    trace: list[str] = Field(
        default_factory=list,
        max_length=MAX_TRACE_SIGNALS,
        description="ST paths (either half) whose value in every stepped cycle the answer carries "
        "(`trace`: cycles and one list of values per signal); at most "
        f"{MAX_TRACE_SIGNALS} signals and {MAX_TRACE_VALUES:,} values (cycles x signals) per request",
    )

    @model_validator(mode="after")
    def _bounded(self) -> StepBody:
        if self.trace and self.cycles * len(self.trace) > MAX_TRACE_VALUES:
            raise ValueError(
                f"{self.cycles} cycles x {len(self.trace)} traced signals = "
                f"{self.cycles * len(self.trace):,} values, more than the {MAX_TRACE_VALUES:,} one answer "
                "may carry: step in smaller parts"
            )
        return self


class FaultsBody(_Body):
    """Fault injection (A3-05), units of the engine: mm/s for friction and drift. Fields left out
    keep their value; the engine checks the ranges (422 with the allowed range)."""

    friction: float | None = Field(default=None, ge=0.0, description="stiction dead band [mm/s]")
    gain_factor: float | None = Field(default=None, gt=0.0, le=100.0, description="multiplies kv")
    encoder_stuck: StrictBool | None = Field(default=None, description="the encoder stops counting")
    encoder_drift: float | None = Field(default=None, description="encoder drift [mm/s]")
    drive_error: StrictBool | None = Field(default=None, description="the drive reports an error")


class SoftLimitsBody(_Body):
    """The software limits in effect (E-06), 0.1 µm: they hold until the next reset or mode change, when
    the axis record's come back (P-AXIS-00177/00178), as the kernel's G98/G99 do."""

    swe_neg: StrictInt | None = Field(default=None, description="negative software limit [0.1 µm]")
    swe_pos: StrictInt | None = Field(default=None, description="positive software limit [0.1 µm]")


class AxisRecordBody(_Body):
    """The axis record's software limit parameters, 0.1 µm: a parameter download, taken over at the
    next reset or mode change (P-AXIS-00177/00178 "Anmerkungen"); ranges as in the machine file."""

    swe_neg: StrictInt | None = Field(default=None, description="P-AXIS-00177 [0.1 µm]")
    swe_pos: StrictInt | None = Field(default=None, description="P-AXIS-00178 [0.1 µm]")
    swe_toleranz: StrictInt | None = Field(default=None, description="P-AXIS-00179 [0.1 µm]")


class ImageWriteBody(_Body):
    # strict: "yes" or "300" are refused (422), not read as true or 300; the field's type is checked
    # by the layout afterwards (Signal.coerce), with its own one-line message
    value: StrictBool | StrictInt | StrictFloat | StrictStr = Field(
        description="BOOL: true/false or 0/1; DINT/UDINT: integer; LREAL: number; STRING(n) (a V.E. "
        "variable's): text of at most n Windows-1252 characters"
    )


class AcceptedBody(BaseModel):
    channel: int
    request: str
    cycle: int = Field(description="the machine's cycle when the request was taken")
    effective_cycle: int = Field(description="the cycle that latches the request")
