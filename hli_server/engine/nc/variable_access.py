"""Variable access (N-03, N-04, N-05): the interpreter's layer that reads and writes ``P`` parameters,
``V.P.``/``V.L.``/``V.S.``/``V.CYC.`` variables (with ``#VAR``), ``V.E.``, ``V.A.``, ``V.G.`` and ``@P``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Final

from hli_server.engine.external import ExternalVariableError, ExternalVarSpec
from hli_server.engine.nc.blocks import NcError
from hli_server.engine.nc.directives import (
    ToolWrite,
)
from hli_server.engine.nc.expr import (
    ALARM_EXPRESSION,
    KIND_AT_P,
    KIND_CYC,
    KIND_MH,
    KIND_P,
    KIND_PP,
    KIND_RTA,
    KIND_RTG,
    KIND_VA,
    KIND_VE,
    KIND_VG,
    KIND_VL,
    KIND_VP,
    KIND_VS,
    EvalError,
    Ref,
    Value,
    as_number,
    format_value,
)
from hli_server.engine.nc.kinematic_commands import KinParamWrite
from hli_server.engine.nc.language import (
    A_CYCLE_PARAMETER,
    A_DECLARATION,
    A_INDEX,
    A_NOT_SIMULATED,
    A_NOT_WRITTEN,
    A_READ_ONLY,
    A_UNDECLARED,
    A_VE_READ_DENIED,
    A_VE_WRITE_DENIED,
    TOOL_WRITES,
)
from hli_server.engine.nc.levels import (
    Frame,
)
from hli_server.engine.nc.state import InterpreterState
from hli_server.engine.nc.statements import (
    Stmt,
    VarBlock,
)
from hli_server.engine.nc.variables import P_COUNT, Variable, coerce

__all__ = ["VariableAccess"]

_NO_INDICES: Final[list[float]] = []
"""The indices of a reference without any (never changed)."""


class VariableAccess(InterpreterState):
    """Reads and writes what a program names (N-03, N-04): ``P`` parameters, ``V.P.``/``V.L.``/``V.S.``/
    ``V.CYC.`` variables and their ``#VAR`` declarations, ``V.E.`` (the machine's external variables),
    ``V.A.`` and ``V.G.`` (the channel's state, read-only but for the tool's radius and length), ``@P``
    (a cycle's parameters)."""

    def _indices(self, ref: Ref) -> list[float]:
        if not ref.indices:
            return _NO_INDICES
        return [as_number(i.evaluate(self), f"the index of {ref.text}") for i in ref.indices]

    def _p_number(self, ref: Ref) -> int:
        assert ref.number is not None
        number = as_number(ref.number.evaluate(self), f"the number of {ref.text}")
        for _ in range(ref.depth - 1):
            number = as_number(self._param(number, ref), f"{ref.text}")
        return self._check_p(number, ref)

    def _check_p(self, number: float, ref: Ref) -> int:
        if number != int(number) or not 0 <= number < P_COUNT:
            raise EvalError(
                A_INDEX,
                f"{ref.text}: P{format_value(number)} is not a parameter (P0 .. P{P_COUNT - 1}, "
                "P-CHAN-00517)",
            )
        return int(number)

    def _param(self, number: float, ref: Ref) -> Value:
        p = self._check_p(number, ref)
        value = self._params.get(p)
        if value is None:
            raise EvalError(A_NOT_WRITTEN, f"P{p} is read before it was written or declared ({ref.text})")
        return value

    def _user_var(self, ref: Ref, declare: bool = False) -> Variable | None:
        """The declared V.P./V.L./V.S./V.CYC. variable ``ref`` names, or None."""
        kind = ref.kind
        name = ref.name
        if kind == KIND_VP:
            return self._program_vars.get(name)
        if kind == KIND_VS:
            return self._static_vars.get(name)
        if kind == KIND_VL:
            for frame in reversed(self._frames):
                var = frame.locals.get(name)
                if var is not None:
                    return var
            return None
        if kind == KIND_CYC:  # the most local declaration: a level's own, else its callers' (PM 486171019)
            for frame in reversed(self._frames):
                var = frame.cycle_vars.get(name)
                if var is not None:
                    return var
            return None
        return None

    def read(self, ref: Ref) -> Value:
        kind = ref.kind
        if kind == KIND_VP and not ref.indices:  # V.P.NAME: the fast path of a scalar
            found_var = self._program_vars.get(ref.name)
            if found_var is not None and not found_var.dims:
                return found_var.values[0]
        fixed = ref.fixed
        if fixed >= 0:  # P3, @P2: a constant number, no index
            if kind == KIND_P and fixed < P_COUNT:
                value = self._params.get(fixed)
                if value is not None:
                    return value
            elif kind == KIND_AT_P:
                params = self._frames[-1].params
                if params is not None:
                    found = params.get(fixed)
                    if found is not None:
                        return found
        if kind in (KIND_P, KIND_PP):
            p = self._p_number(ref)
            if ref.indices:
                key = (p, tuple(int(i) for i in self._indices(ref)))
                value = self._param_arrays.get(key)
                if value is None:
                    raise EvalError(A_NOT_WRITTEN, f"{ref.text} is read before it was written")
                return value
            value = self._params.get(p)
            if value is None:
                raise EvalError(
                    A_NOT_WRITTEN,
                    f"P{p} is read before it was written or declared"
                    + (f" ({ref.text})" if ref.text != f"P{p}" else ""),
                )
            return value
        if kind in (KIND_VP, KIND_VL, KIND_VS, KIND_CYC):
            var = self._user_var(ref)
            if var is None:
                raise EvalError(
                    A_UNDECLARED, f"{ref.text.split('[')[0]} is not declared (declare it in #VAR .. #ENDVAR)"
                )
            return var.get(self._indices(ref))
        if kind == KIND_VE:
            return self._read_external(ref)
        if kind == KIND_AT_P:
            return self._cycle_param(ref)
        if kind == KIND_VA:
            return self._axis_variable(ref)
        if kind == KIND_VG:
            if ref.indices:
                raise EvalError(A_NOT_SIMULATED, f"{ref.text} is not simulated: see docs/nc-language.md")
            self._effect()
            value = self.host.global_value(ref.name)
            if value is None:
                raise EvalError(
                    A_NOT_SIMULATED,
                    f"V.G.{ref.name} is not simulated (V.G.BLOCK_NR, FEEDRATE, FEEDRATE_MODE, I, J, K, "
                    "MASS_MM, MASS_360, WZ_AKT.R/.L/.NR, WZR, WZL, ROT_ACTIVE, ROT_ANGLE, ROT_CENTER1/2 "
                    "are): see docs/nc-language.md",
                )
            return value
        if kind in (KIND_RTA, KIND_RTG):
            raise _realtime_only(ref)
        raise EvalError(ALARM_EXPRESSION, f"{ref.text} cannot be read")

    def _axis_variable(self, ref: Ref) -> float:
        name = ref.name
        axis: str | None
        if ref.indices:
            if len(ref.indices) != 1:
                raise EvalError(A_INDEX, f"{ref.text}: one axis index")
            index = self._indices(ref)[0]
            axis = self.host.axis_name(int(index)) if index == int(index) else None
            if axis is None:
                raise EvalError(
                    A_INDEX, f"{ref.text}: no axis with index {format_value(index)} in this channel"
                )
            variable = name
        else:
            variable, _, axis = name.rpartition(".")
            if not variable:
                raise EvalError(
                    A_UNDECLARED, f"{ref.text}: write V.A.<variable>.<axis> or V.A.<variable>[index]"
                )
        self._effect()
        value = self.host.axis_value(variable, axis)
        if value is None:
            raise EvalError(
                A_NOT_SIMULATED,
                f"V.A.{variable}.{axis} is not simulated (V.A.ABS, PROG, ACT_POS, -SWE, +SWE, -SWE_MDS, "
                "+SWE_MDS "
                "of the channel's axes are): see docs/nc-language.md",
            )
        return value

    def _cycle_param(self, ref: Ref) -> Value:
        frame = self._frames[-1]
        assert ref.number is not None
        index = int(as_number(ref.number.evaluate(self), ref.text))
        if frame.params is None:
            raise EvalError(
                A_CYCLE_PARAMETER,
                f"{ref.text}: cycle parameters are read and written only in a cycle (L CYCLE [..])",
            )
        value = frame.params.get(index)
        if value is None:
            raise EvalError(
                A_UNDECLARED, f"{ref.text} was not given at the cycle's call (test it with EXIST[{ref.text}])"
            )
        return value

    def exists(self, ref: Ref) -> bool:
        kind = ref.kind
        if kind == KIND_MH:
            return True
        if kind in (KIND_P, KIND_PP):
            try:
                p = self._p_number(ref)
            except EvalError:
                return False
            if ref.indices:
                return (p, tuple(int(i) for i in self._indices(ref))) in self._param_arrays
            return p in self._params
        if kind in (KIND_VP, KIND_VL, KIND_VS, KIND_CYC):
            var = self._user_var(ref)
            if var is None:
                return False
            if not ref.indices:
                return True
            try:
                var.flat(self._indices(ref))
            except EvalError:
                return False
            return True
        if kind == KIND_VE:
            return self.host.external.spec(ref.name, self.host.channel_number) is not None
        if kind == KIND_AT_P:
            frame = self._frames[-1]
            assert ref.number is not None
            index = int(as_number(ref.number.evaluate(self), ref.text))
            return frame.params is not None and index in frame.params
        try:
            self.read(ref)
        except EvalError:
            return False
        return True

    def _assign(self, frame: Frame, stmt: Stmt, ref: Ref, value: Value) -> Callable[[], None] | None:
        """Write ``value`` to ``ref``; returns the action of a synchronous V.E. write (done when the
        path gets there) or None."""
        kind = ref.kind
        if isinstance(value, float) and math.isfinite(value) and not ref.indices:
            # the fast paths of P3 = .. and V.P.NAME = .. (a REAL64 scalar): what the general path does
            if kind == KIND_P and 0 <= ref.fixed < P_COUNT:
                self._params[ref.fixed] = value
                return None
            if kind == KIND_VP:
                var = self._program_vars.get(ref.name)
                if var is not None and not var.dims and var.type_name == "REAL64":
                    var.values[0] = value
                    return None
        try:
            if kind in (KIND_P, KIND_PP):
                p = self._p_number(ref)
                if ref.indices:
                    key = (p, tuple(int(i) for i in self._indices(ref)))
                    self._param_arrays[key] = coerce(value, "REAL64", 0, ref.text)
                else:
                    self._params[p] = (
                        value if isinstance(value, str) else coerce(value, "REAL64", 0, ref.text)
                    )
                return None
            if kind in (KIND_VP, KIND_VL, KIND_VS, KIND_CYC):
                var = self._user_var(ref)
                if var is None and not ref.indices:
                    # a write creates a scalar REAL64 variable (as in the kernel's own example of
                    # ID 21382: N25 V.L.VAR1=10 without #VAR)
                    var = Variable(ref.text, "REAL64", [], 0)
                    self._scope(frame, ref)[ref.name] = var
                if var is None:
                    raise EvalError(
                        A_UNDECLARED,
                        f"{ref.text.split('[')[0]} is not declared: declare it in #VAR .. #ENDVAR "
                        "before writing it",
                    )
                var.set(self._indices(ref), value)
                return None
            if kind == KIND_VE:
                return self._write_external(ref, value)
            if kind == KIND_AT_P:
                if frame.params is None:
                    raise EvalError(
                        A_CYCLE_PARAMETER,
                        f"{ref.text}: cycle parameters are read and written only in a cycle (L CYCLE [..])",
                    )
                assert ref.number is not None
                index = int(as_number(ref.number.evaluate(self), ref.text))
                frame.params[index] = value
                return None
            if kind == KIND_VG and ref.name.startswith("KIN."):
                self._pending.append(self._kinematic_write(frame, stmt, ref, value))
                return None
            if kind == KIND_VG and not ref.indices and ref.name in TOOL_WRITES:
                number = as_number(value, ref.text)
                self._pending.append(ToolWrite(self._place_block(frame, stmt), TOOL_WRITES[ref.name], number))
                return None
            if kind in (KIND_RTA, KIND_RTG):
                raise _realtime_only(ref)
            raise EvalError(A_READ_ONLY, f"{ref.text} is read-only")
        except EvalError as exc:
            raise stmt.error(exc.alarm, exc.message) from None

    def _kinematic_write(self, frame: Frame, stmt: Stmt, ref: Ref, value: Value) -> KinParamWrite:
        """``V.G.KIN[<id>].PARAM[<i>] = ..`` and the Universal Kinematics' named parameters
        (``ZERO_ORIENTATION[l]``, ``ZERO_POSITION[l]``, ``NUMBER_OF_AXES``, ``AXIS[k].TYPE``,
        ``AXIS[k].ORIENTATION[l]``, ``AXIS[k].POINT[l]``: PARAM[0..48] as TF5240 lays them out,
        https://infosys.beckhoff.com/content/1033/tf5240_universal_kinematic/882078603.html): a parameter of a
        kinematic data set, in program order (docs/kinematics.md)."""
        index = self._indices(ref)
        member = ref.name[4:]
        starts = {
            "PARAM": 0,
            "ZERO_ORIENTATION": 0,
            "ZERO_POSITION": 3,
            "AXIS.ORIENTATION": 8,
            "AXIS.POINT": 11,
        }
        arity = {"NUMBER_OF_AXES": 1, "AXIS.TYPE": 2, "AXIS.ORIENTATION": 3, "AXIS.POINT": 3}.get(member, 2)
        if (
            (member not in starts and arity == 2)
            or len(index) != arity
            or any(i != int(i) or i < 0 for i in index)
        ):
            raise EvalError(
                A_READ_ONLY,
                f"{ref.text}: the kinematic parameters written are V.G.KIN[<id>].PARAM[<i>] (and the "
                "Universal "
                "Kinematics' ZERO_ORIENTATION[l], ZERO_POSITION[l], NUMBER_OF_AXES, AXIS[k].TYPE, "
                "AXIS[k].ORIENTATION[l], AXIS[k].POINT[l])",
            )
        if member == "NUMBER_OF_AXES":
            param = 6
        elif member == "AXIS.TYPE":
            param = 7 + 7 * int(index[1])
        elif arity == 3:
            param = starts[member] + 7 * int(index[1]) + int(index[2])
        else:
            param = starts[member] + int(index[1])
        return KinParamWrite(self._place_block(frame, stmt), int(index[0]), param, as_number(value, ref.text))

    # --- V.E. (N-05): elementary, STRING, a structure's elements ----------------------------------------
    def _external_spec(self, ref: Ref) -> ExternalVarSpec:
        external = self.host.external
        spec = external.spec(ref.name, self.host.channel_number)
        if spec is None:
            raise EvalError(A_UNDECLARED, str(external.unknown(ref.name, self.host.channel_number)))
        return spec

    def _external_index(self, ref: Ref) -> list[int]:
        return [int(i) if i == int(i) else -1 for i in self._indices(ref)]

    def _read_external(self, ref: Ref) -> Value:
        """A V.E. element's value: a STRING's text, a number (a BOOLEAN as 1.0 or 0.0)."""
        spec = self._external_spec(ref)
        if spec.access_rights == "WRITE_ONLY":
            raise EvalError(
                A_VE_READ_DENIED,
                f"{ref.text}: {spec.path} is WRITE_ONLY for NC programs (access_rights, P-EXTV-00006); "
                "only the PLC reads it",
            )
        try:
            value = self.host.external.read(ref.name, self.host.channel_number, self._external_index(ref))
        except ExternalVariableError as exc:
            raise EvalError(exc.alarm, str(exc)) from None
        return value if isinstance(value, str) else float(value)

    def _write_external(self, ref: Ref, value: Value) -> Callable[[], None] | None:
        """Write a V.E. element now (asynchronous), or return the write the path makes when it passes the
        block (synchronous). A STRING takes a text of at most its length (else the kernel's 21462), a
        number a number in its type's range (914005); the other kind is 914006."""
        spec = self._external_spec(ref)
        if spec.access_rights == "READ_ONLY":
            raise EvalError(
                A_VE_WRITE_DENIED,
                f"{ref.text}: {spec.path} is READ_ONLY for NC programs (access_rights, P-EXTV-00006); "
                "only the PLC writes it",
            )
        index = self._external_index(ref)
        try:
            spec.flat_index(index)
            stored = spec.coerce(value)
        except ExternalVariableError as exc:
            raise EvalError(exc.alarm, str(exc)) from None
        external = self.host.external
        channel = self.host.channel_number
        name = ref.name
        if not spec.synchronous:
            self._effect()
            external.write(name, channel, stored, index)
            return None
        # a partial, not a closure: a recording's snapshot keeps the write the path has not reached yet
        # (hli_server/recording/snapshot.py)
        return functools.partial(external.write, name, channel, stored, index)

    # --- #VAR ------------------------------------------------------------------------------------------
    def _declare(self, frame: Frame, stmt: VarBlock) -> None:
        for declaration in stmt.declarations:
            ref = declaration.ref
            try:
                init = [self._evaluate(stmt, e) for e in declaration.init]
                if ref.kind == KIND_P:
                    assert ref.number is not None
                    p = self._check_p(as_number(ref.number.evaluate(self), ref.text), ref)
                    if declaration.dims:
                        for k, value in enumerate(init):
                            self._param_arrays[(p, (k,))] = as_number(value, ref.text)
                        continue
                    self._params[p] = init[0] if init else 0.0
                    continue
                var = Variable(ref.text, declaration.type_name, declaration.dims, declaration.string_size)
                if init:
                    if len(init) == 1 and not declaration.dims:
                        var.set([], init[0])
                    elif len(init) > len(var.values):
                        raise EvalError(
                            A_DECLARATION,
                            f"{ref.text}: {len(init)} initial values for {len(var.values)} elements",
                        )
                    else:
                        for k, value in enumerate(init):
                            var.values[k] = coerce(value, var.type_name, var.string_size, ref.text)
                scope = self._scope(frame, ref)
                if ref.name in scope:
                    raise EvalError(A_DECLARATION, f"{ref.text} is declared twice (at this program level)")
                scope[ref.name] = var
            except EvalError as exc:
                raise NcError(exc.alarm, declaration.line, stmt.place, exc.message) from None

    def set_cycle_result(self, name: str, value: float) -> None:
        """``V.CYC.<name> = value`` of a built-in cycle (engine/cycles): into the variable the cycle sees,
        the most local declaration (the caller's ``#VAR V.CYC.SysRetX #ENDVAR``), else a new one of the
        cycle's own level, deleted when it returns (PM 486123531)."""
        key = name.upper()
        for frame in reversed(self._frames):
            var = frame.cycle_vars.get(key)
            if var is not None:
                var.set([], value)
                return
        var = Variable(f"V.CYC.{name}", "REAL64", [], 0)
        var.set([], value)
        self._frames[-1].cycle_vars[key] = var

    def _scope(self, frame: Frame, ref: Ref) -> dict[str, Variable]:
        if ref.kind == KIND_VP:
            return self._program_vars
        if ref.kind == KIND_VS:
            return self._static_vars
        if ref.kind == KIND_CYC:  # in a cycle, or in a program or subroutine that calls one (PM 486123531)
            return frame.cycle_vars
        return frame.locals


def _realtime_only(ref: Ref) -> EvalError:
    """A realtime variable outside a realtime cycle (TF5261: it would flush the channel there)."""
    return EvalError(
        A_NOT_SIMULATED,
        f"{ref.text}: the realtime variables V.RTA. and V.RTG. are read and written here only in a realtime "
        "cycle (#RT CYCLE .. #RT CYCLE END): see docs/nc-language.md",
    )
