"""V.E. variables of every type the kernel's lists declare, in NC programs (N-05, issue 33 item 6).

STRING and VSTRING variables are assigned and read as text (``V.E.TEACH_FILE_NAME = "teach.dat"``), their
length bound is the kernel's 21462; a structure's elements are named ``V.E.UserInteraction.Message`` (as
RegenHU's programs write the HMI's message), an array of structures' ``V.E.TRACK[1].LABEL``; strings
compare and concatenate; ``L V.E.name`` calls the program a V.E. STRING names (PM "Parametric subroutine
call"); the access rights are the kernel's (20097, 20100). The machine is the test machine of
``tests.machines`` (its V.E. variables: STRING, VSTRING, a structure ``UserInteractionType`` in channel 1,
an array of structures ``TRACK`` in channel 2).

A synchronous V.E. variable read in a loop (issue 33's defect): every pass waits for the path, so it
reads the pass before's synchronous write; before, only the first pass waited and the count ended at 1.
Tested in every loop form, on a running machine (what the harness runs) and by both checks.
"""

from __future__ import annotations

import pytest

from hli_server.commands.check import check_program
from hli_server.engine import Machine
from hli_server.engine.external import ExternalVariables, external_specs
from hli_server.engine.programs import MemoryLibrary
from schemas.config import ExternalVariableConfig, MachineConfig
from schemas.wire import ProgramState
from tests.machines import demo_config
from tests.unit.engine_helpers import cycles_until_done, mill_config, start
from tests.unit.nc_helpers import FakeHost, Run, interpret

pytestmark = pytest.mark.req("N-05")

CONFIG = demo_config(external=True)


def run(
    text: str, channel: int = 1, files: dict[str, str] | None = None, config: MachineConfig = CONFIG
) -> Run:
    host = FakeHost(files)
    host.external = ExternalVariables(external_specs(config))
    host.channel_number = channel
    return interpret(text, host=host)


def test_a_string_is_assigned_read_compared_and_concatenated() -> None:
    result = run(
        'V.E.TEACH_FILE_NAME = "teach_0815.dat"\n'
        '$IF V.E.TEACH_FILE_NAME == "teach_0815.dat"\n'
        '  V.E.UserInteraction.Message = "file " + V.E.TEACH_FILE_NAME\n'
        "$ENDIF\n"
        '$IF V.E.UserInteraction.Message != ""\n'
        '  #MSG ["%s", V.E.UserInteraction.Message]\n'
        "$ENDIF\n"
        "M30\n"
    )
    assert result.error is None, result.error
    ext = result.host.external
    assert ext.read("TEACH_FILE_NAME", 1) == "teach_0815.dat"
    assert ext.read("UserInteraction.Message", 1) == "file teach_0815.dat"
    assert result.messages == ["file teach_0815.dat"]


def test_the_elements_of_a_structure_and_of_an_array_of_structures() -> None:
    result = run(
        "$FOR P1 = 0, 1\n"
        "  V.E.TRACK[P1].X = 2.5 * [P1 + 1]\n"
        '  V.E.TRACK[P1].LABEL = "P" + "1"\n'
        "  V.E.TRACK[P1].VALID = V.E.TRACK[P1].X > 3\n"
        "$ENDFOR\n"
        "X[V.E.TRACK[1].X]\n"
        "M30\n",
        channel=2,
    )
    assert result.error is None, result.error
    ext = result.host.external
    assert ext.read("TRACK.X", 2, (1,)) == 5.0
    assert [ext.read("TRACK.VALID", 2, (i,)) for i in (0, 1)] == [False, True]
    assert ext.read("TRACK.LABEL", 2, (0,)) == "P1"
    assert result.values("X") == [5.0]
    channel_1 = run(
        "V.E.UserInteraction.Answer = V.E.UserInteraction.Answer + 7\nV.E.UserInteraction.Done = 1\nM30\n"
    )
    assert channel_1.host.external.read("UserInteraction.Answer", 1) == 7
    assert channel_1.host.external.read("UserInteraction.Done", 1) is True


def test_a_string_longer_than_its_variable_is_the_kernels_21462() -> None:
    message = "Camera at A1 - trigger imaging, then click OK"  # RegenHU's HMI message: 45 characters
    result = run(f'V.E.UserInteraction.Message = "{message}"\nM30\n')
    assert result.alarm == 21462
    assert result.error is not None
    assert "holds at most 20 characters (STRING), 45 given" in result.error.message
    # declared long enough (a VSTRING, or a STRING of 127 with use_extended_string_var), it fits
    longer = CONFIG.model_copy(update={"use_extended_string_var": True})
    fits = run(f'V.E.UserInteraction.Message = "{message}"\nM30\n', config=longer)
    assert fits.error is None, fits.error
    assert fits.host.external.read("UserInteraction.Message", 1) == message
    too_long = run('V.E.NOTES[1] = "123456789"\nM30\n', channel=2)  # a VSTRING of 9 bytes: 8 characters
    assert too_long.alarm == 21462


@pytest.mark.parametrize(
    ("program", "channel", "alarm", "text"),
    [
        (
            "V.E.UserInteraction = 5\n",
            1,
            914003,
            "is a structure: name one of its elements (Message, Answer, Done)",
        ),
        ("P1 = V.E.UserInteraction.Mesage\n", 1, 914003, "V.E.UserInteraction has no element MESAGE"),
        ("P1 = V.E.TEACH_FILENAME\n", 1, 914003, "did you mean V.E.TEACH_FILE_NAME?"),
        ('V.E.UserInteraction.Answer = "yes"\n', 1, 914006, "is a number (SGN32)"),
        ("V.E.TEACH_FILE_NAME = 5\n", 1, 914006, "is a STRING"),
        ("P1 = V.E.TEACH_FILE_NAME + 1\n", 1, 914006, "needs a number"),
        ("V.E.TRACK[2].X = 1\n", 2, 914005, "index 1 is 2, allowed 0 to 1"),
        ("V.E.TRACK.X = 1\n", 2, 914005, "takes 1 index(es), got 0"),
        ('V.E.TEACH_FILE_NAME = "\u4e2d"\n', 1, 914006, "no Windows-1252 character"),
    ],
)
def test_each_mistake_with_a_v_e_variable_has_its_alarm(
    program: str, channel: int, alarm: int, text: str
) -> None:
    result = run(program + "M30\n", channel=channel)
    assert result.alarm == alarm, result.error
    assert result.error is not None
    assert text in result.error.message


def test_the_access_rights_are_the_kernels_20097_and_20100() -> None:
    config = demo_config().model_copy(
        update={
            "external_variables": [
                ExternalVariableConfig(name="IN", type="STRING", access_rights="READ_ONLY"),
                ExternalVariableConfig(name="OUT", type="SGN32", access_rights="WRITE_ONLY"),
            ]
        }
    )
    assert run('V.E.IN = "x"\nM30\n', config=config).alarm == 20100
    assert run("P1 = V.E.OUT\nM30\n", config=config).alarm == 20097
    fine = run('V.E.OUT = 3\n$IF V.E.IN == ""\nV.E.OUT = 4\n$ENDIF\nM30\n', config=config)
    assert fine.error is None, fine.error
    assert fine.host.external.read("OUT", 1) == 4


def test_l_v_e_calls_the_program_a_v_e_string_names() -> None:
    """PM "Parametric subroutine call (LL / L V.E.)": the local or global subroutine whose name a V.E.
    STRING holds when the call runs."""
    files = {"POCKET.NC": "%POCKET\nN10 X2\nN20 M17\n"}
    program = (
        "%L CONTOUR\nN10 X1\nN20 M17\n"
        "%MAIN\n"
        'V.E.NOTES[0] = "CONTOUR"\n'
        "LL V.E.NOTES[0]\n"
        'V.E.TEACH_FILE_NAME = " pocket.nc"\n'  # blanks around the name do not count; names ignore case
        "L V.E.TEACH_FILE_NAME\n"
        "M30\n"
    )
    result = run(program, channel=2, files=files)
    assert result.error is None, result.error
    assert result.values("X") == [1.0, 2.0]
    assert run("L V.E.NOTES[0]\nM30\n", channel=2).alarm == 914015  # empty
    assert run("L V.E.UserInteraction.Answer\nM30\n").alarm == 914006  # a number names no program
    missing = run('V.E.TEACH_FILE_NAME = "nowhere.nc"\nL V.E.TEACH_FILE_NAME\nM30\n')
    assert missing.alarm == 914010


# --- a synchronous V.E. variable read in a loop (the defect of issue 33) -----------------------------------

LOOPS = {
    "for": "$FOR P1 = 1, 4, 1\n  {body}\n$ENDFOR\n",
    "while": "P1 = 0\n$WHILE P1 < 4\n  {body}\n  P1 = P1 + 1\n$ENDWHILE\n",
    "while on the variable": "$WHILE V.E.PART_COUNT < 4\n  {body}\n$ENDWHILE\n",
    "do": "P1 = 0\n$DO\n  {body}\n  P1 = P1 + 1\n$ENDDO P1 < 4\n",
    "repeat": "$REPEAT\n  {body}\n$UNTIL V.E.PART_COUNT >= 4\n",
    "goto": "P1 = 0\nN10:\n{body}\nP1 = P1 + 1\n$IF P1 < 4 $GOTO N10\n",
    "for in a subroutine": "$FOR P1 = 1, 4\n  L count.nc\n$ENDFOR\n",
    "nested": "$FOR P1 = 1, 2\n  $FOR P2 = 1, 2\n    {body}\n  $ENDFOR\n$ENDFOR\n",
}
BODY = "V.E.PART_COUNT = V.E.PART_COUNT + 1"
FILES = {"count.nc": f"%count\n{BODY}\nM17\n"}


def _counting_machine() -> Machine:
    variable = ExternalVariableConfig(name="PART_COUNT", type="UNS32", synchronous=True)
    config = mill_config().model_copy(update={"external_variables": [variable]})
    return Machine(config, programs=MemoryLibrary(FILES))


def _program(loop: str) -> str:
    return "G01 X1 F6000\n" + LOOPS[loop].format(body=BODY) + '#MSG ["count %d", V.E.PART_COUNT]\nM30\n'


@pytest.mark.parametrize("loop", list(LOOPS))
def test_a_synchronous_read_in_a_loop_sees_the_pass_befores_write_on_the_machine(loop: str) -> None:
    machine = _counting_machine()
    start(machine, _program(loop))
    for _ in cycles_until_done(machine, limit=20_000):
        pass
    assert machine.channel(1).state == ProgramState.FINISHED, list(machine.alarm_history)
    assert machine.external.read("PART_COUNT", 1) == 4


@pytest.mark.parametrize("geometry_only", [False, True], ids=["full", "geometry"])
@pytest.mark.parametrize("loop", list(LOOPS))
def test_a_synchronous_read_in_a_loop_counts_alike_in_both_checks(loop: str, geometry_only: bool) -> None:
    result = check_program(_counting_machine(), _program(loop), geometry_only=geometry_only)
    assert result.completed, result.alarms
    assert [m.text for m in result.messages] == ["count 4"]


def test_a_synchronous_read_waits_in_every_pass_not_only_the_first() -> None:
    """Each pass's read empties the channel first (an implicit #FLUSH WAIT): four passes, four waits."""
    from hli_server.engine.nc.directives import FlushWait

    spec_host = FakeHost()
    config = mill_config().model_copy(
        update={"external_variables": [ExternalVariableConfig(name="N", type="SGN32", synchronous=True)]}
    )
    spec_host.external = ExternalVariables(external_specs(config))
    result = interpret("$FOR P1 = 1, 4\nV.E.N = V.E.N + 1\n$ENDFOR\nM30\n", host=spec_host)
    assert result.error is None, result.error
    assert sum(isinstance(o, FlushWait) for o in result.outputs) == 4
    assert spec_host.external.read("N", 1) == 4
