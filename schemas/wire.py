"""The values that travel over the wire as numbers: one definition each, imported by both sides.

A PLC reads ``gpCh[0]^bahn_state.program_state_r`` as a UDINT and compares it with a constant; the
engine publishes it, the PLC-side blocks (``plc_clients``) and the tests compare with it, the layout
describes it in the address map, MQTT and the HTTP API name it. All of them take the number and its
name from here, so that they cannot drift apart (design.md, point 4).

* :class:`ProgramState`: ``bahn_state.program_state_r`` (project's own values);
* :class:`Mode`: ``mc_command.mode_w`` and ``bahn_state.mode_r`` (project's own values);
* :class:`HoldSource`: ``bahn_state.hold_source_r``, why the path is held (project's own bits);
* :class:`DynPosLimitState`: ``state_r`` of the dyn_pos_limit control units, HLI_DYNPL_STATE_* (FCT-C43
  3.1.1, C43-03).
"""

from __future__ import annotations

from enum import IntEnum, IntFlag

__all__ = ["DynPosLimitState", "HoldSource", "Mode", "ProgramState", "describe"]


class ProgramState(IntEnum):
    """``gpCh[i]^bahn_state.program_state_r``: the channel's program (project's own values).

    The transitions, and what causes each, are one table: ``hli_server/engine/channel_state.py``
    (docs/architecture.md draws it)."""

    IDLE = 0
    """No program runs: after start-up, a reset, or a program was (re)selected."""
    RUNNING = 1
    """A program runs; the path may be braking for a hold (see ``hold_source_r``)."""
    HELD = 2
    """A program runs, and the path rests because of a hold (feedhold, a dynamic limit)."""
    ABORTED = 3
    """An error ended the program (the alarm says why); the axes brake to a stop. Reset to go on."""
    FINISHED = 4
    """The program reached M30 / M02 (or the end of its text)."""

    @property
    def label(self) -> str:
        """``"running"``: the name the HTTP API, the events and MQTT use."""
        return self.name.lower()


class Mode(IntEnum):
    """``gpCh[i]^mc_command.mode_w`` and ``bahn_state.mode_r`` (project's own values)."""

    AUTOMATIC = 0
    """An NC program may run (E-03)."""
    MANUAL = 1
    """Jog (G200-like, exclusive); no program (E-03, E-05)."""

    @property
    def label(self) -> str:
        return self.name.lower()


class HoldSource(IntFlag):
    """``gpCh[i]^bahn_state.hold_source_r``: what holds the channel's path (project's own bits).

    A bit is set from the cycle the hold takes effect (the path starts braking) until it is lifted;
    ``bahn_state.feedhold_active_r`` is TRUE while any bit is set, and ``program_state_r`` is HELD
    while one is set and the path is at rest."""

    NONE = 0
    FEEDHOLD = 0x1
    """The feedhold control unit ``bahn_mc_control.feedhold`` (the PLC's command or the operator's)."""
    DYN_POS_LIMIT = 0x2
    """A dynamic position limit of an axis of the channel (FCT-C43: "ein bereichsspezifischer Feedhold")."""

    @property
    def labels(self) -> list[str]:
        """``["feedhold", "dyn_pos_limit"]``: the names of the set bits, lowest first."""
        return [bit.name.lower() for bit in HoldSource if bit and bit in self and bit.name]


class DynPosLimitState(IntEnum):
    """``state_r`` of ``gpAx[i]^ipo_mc_control.dyn_pos_limit_low`` / ``_high``: HLI_DYNPL_STATE_*
    (FCT-C43 3.1.1, C43-03). The transitions are the table in ``engine/monitors/dyn_pos_limit.py``."""

    INACTIVE = 0
    ACTIVATION = 1
    ACTIVE = 2
    ACTIVE_BRAKING = 3
    ACTIVE_BRAKE = 4


def describe(enum: type[IntEnum] | type[IntFlag], what: str, *, lower: bool = True) -> str:
    """``"program state: 0 idle, 1 running, ..."``: the value list the address map shows."""
    flags = issubclass(enum, IntFlag)
    items = []
    for member in enum:
        if member.name is None or (flags and not member.value):
            continue
        value = f"0x{member.value:X}" if flags else str(member.value)
        items.append(f"{value} {member.name.lower() if lower else member.name}")
    return f"{what}: {(' | ' if flags else ', ').join(items)}"
