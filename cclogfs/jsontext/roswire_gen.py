"""The source of a message type's formatter: serialized bytes -> rosbridge JSON text.

`module_source(typestore, msgtype, wire)` writes a small Python module (print it to read
it) whose function `message(raw)` returns (JSON text, header stamp in ns or None). For a
ROS 1 `nav_msgs/Odometry` it reads `header.seq` and the stamp with one struct call, the two
strings, the pose, the covariances (through a memo) and the twist, renders its 16 numbers
with one call, and returns one f-string: nested messages are inlined into the f-string,
consecutive numbers are read together ("a run"), and only arrays of messages call another
generated function (`f_<type>`) per element.

Why generated source rather than a walk over the fields (or closures per field): the walk
costs a call and type tests per field per message, which is what the rosbags objects +
json.dumps path spent its time on; the generated function is the straight-line code one
would write by hand for the type, and can be read as such.

Reads mirror rosbags' generated deserializers (rosbags/serde/ros1.py, cdr.py): the same
struct codes (so the same ints, floats and bools), the same CDR alignment steps in the same
places (tracked the way rosbags tracks them), the same string and sequence checks.
"""

from __future__ import annotations

import re
import struct
from itertools import pairwise
from json.encoder import encode_basestring_ascii as json_string
from typing import Any, NamedTuple

from rosbags.interfaces import Nodetype
from rosbags.typesys.base import normalize_fieldname
from rosbags.serde.utils import SIZEMAP, align, align_after

from .ros import message_fields

# rosbags' struct codes (rosbags/serde/primitives.py).
CODES = {"bool": "?", "byte": "b", "char": "B", "int8": "b", "uint8": "B", "int16": "h", "uint16": "H",
         "int32": "i", "uint32": "I", "int64": "q", "uint64": "Q", "float32": "f", "float64": "d"}  # fmt: skip
# Arrays rosbags reads as numpy uint8/int8 (its ndtype: char -> uint8, byte -> int8): base64 in ros.py.
BYTES = {"uint8", "char", "int8", "byte"}
INTS = {"byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64"}
# Fixed-size numeric arrays shorter than this are part of the f-string; longer ones (a
# covariance: 9 or 36 numbers) are rendered on their own, through a memo (roswire.ArrayMemo).
MEMO_ARRAY = 9
STAMP = ("header.stamp.sec", "header.stamp.nanosec")
# rosbags' stand-in field of an empty message (std_msgs/Empty): a uint8 in CDR, nothing in
# ROS 1, never a field of the class (it has a default), so not in the JSON either: `{}`.
MARKER = "structure_needs_at_least_one_member"


class Unsupported(Exception):
    """A type this generator does not format (float128, a ROS 1 empty-struct marker, field
    names that differ from the class's): callers fall back to rosbags + ros.py."""


def module_source(typestore: Any, msgtype: str, wire: str) -> str:
    """The formatter module of `msgtype`; `wire` is "ros1", "le" or "be" (CDR)."""
    return _Module(typestore, wire).source(msgtype)


class Definitions(NamedTuple):
    """The part of rosbags' `Msgdef` the generator reads."""

    fields: list[tuple[str, Any]]
    cls: type


class _TypeTable:
    """A type store as the generator and rosbags' `align` helpers read it: `get_msgdef`
    giving each type's fields (named as rosbags' own `get_msgdef` names them) and class.

    rosbags' `get_msgdef` also compiles the type's eleven serializers, and `align` asks
    for every nested type: 25 ms for an Odometry and an Imu, 17x the formatters' own
    generation (issue 14). This reads the same `fielddefs` without compiling anything.
    """

    def __init__(self, typestore: Any) -> None:
        self.store = typestore
        self.max_sequence_length = typestore.max_sequence_length

    def get_msgdef(self, msgtype: str) -> Definitions:
        entries = [(normalize_fieldname(name), desc) for name, desc in self.store.fielddefs[msgtype][1]]
        return Definitions(entries, self.store.types[msgtype])


class _Module:
    """The constants (struct readers, memos) and functions of one generated module."""

    def __init__(self, typestore: Any, wire: str) -> None:
        self.typestore = _TypeTable(typestore)
        self.wire = wire
        self.cdr = wire != "ros1"
        self.endian = ">" if wire == "be" else "<"
        self.constants: list[str] = [f"u32 = Struct({self.endian + 'I'!r}).unpack_from",
                                     f"MAX_SEQUENCE = {typestore.max_sequence_length}"]  # fmt: skip
        self.functions: list[str] = []
        self.wanted: list[str] = []  # element types whose function is still to write
        self.written: set[str] = set()

    def source(self, msgtype: str) -> str:
        head = f"# rosbridge JSON of {msgtype} from {'ROS 1' if not self.cdr else 'CDR (' + self.wire + ')'} bytes"
        top = _Function(self, "message(raw)").message(msgtype, "")
        while self.wanted:
            name = self.wanted.pop()
            self.functions.append(_Function(self, f"{function_name(name)}(raw, pos)").message(name, ""))
        return "\n".join([head, "# (generated by cclogfs.jsontext.roswire_gen)", *self.constants, "", "",
                          top, *self.functions])  # fmt: skip

    def constant(self, prefix: str, value: str) -> str:
        name = f"{prefix}_{len(self.constants)}"
        self.constants.append(f"{name} = {value}")
        return name

    def element(self, msgtype: str) -> str:
        """The name of the function formatting one `msgtype` inside an array."""
        if msgtype not in self.written:
            self.written.add(msgtype)
            self.wanted.append(msgtype)
        return function_name(msgtype)

    def fields(self, msgtype: str) -> list[tuple[str, Any]]:
        """The fields of `msgtype` as rosbags reads them, checked against the class's."""
        msgdef = self.typestore.get_msgdef(msgtype)
        names = [f.name for f in message_fields(msgdef.cls) or ()]
        if [name for name, _ in msgdef.fields if name != MARKER] != names:
            raise Unsupported(f"{msgtype}: fields {names} are not those rosbags reads")
        return msgdef.fields


def function_name(msgtype: str) -> str:
    return "f_" + re.sub(r"\W", "_", msgtype.replace("/", "__"))


class _Function:
    """One generated function: its statements and the f-string of its JSON text.

    Numbers are gathered into a run (struct codes) that one struct call reads when
    something else comes (a string, an array, a CDR alignment step): `flush`. All the
    function's numbers are rendered at its end by one call (`number_texts`, orjson) into
    `t0, t1, ...`, the f-string's slots for them. An f-string, not a %-template: Python
    builds it by joining its pieces, where `%` parses its template again on every message
    (2-3x slower for an Odometry, issue 14).
    """

    def __init__(self, module: _Module, signature: str) -> None:
        self.m = module
        self.signature = signature
        self.top = signature.startswith("message(")
        self.lines: list[str] = []
        self.parts: list[str] = []  # the f-string's text, braces doubled, and its {slots}
        self.run: list[str] = []
        self.run_paths: list[str] = []
        self.run_var = ""  # the variable the run is read into
        self.run_count = 0  # values read so far by the run
        self.runs: list[str] = []  # the variables of the runs read, in order
        self.numbered = 0  # numbers in the runs so far: the next one's slot is t<numbered>
        self.names = 0
        self.aligned = 8  # rosbags' static alignment tracking (CDR)
        self.stamp: dict[str, str] = {}

    # -- the f-string ----------------------------------------------------------
    def text(self, s: str) -> None:
        self.parts.append(s.replace("{", "{{").replace("}", "}}"))

    def value(self, name: str) -> None:
        self.parts.append("{" + name + "}")

    def new(self, prefix: str) -> str:
        self.names += 1
        return f"{prefix}{self.names}"

    def step(self, path: str, *statements: str) -> None:
        """Statements reading `path` (named in errors), after the pending run."""
        self.flush()
        self.lines.append(f"at = {path!r}")
        self.lines.extend(statements)

    # -- fields ----------------------------------------------------------------
    def message(self, msgtype: str, path: str) -> str:
        """The whole function for `msgtype` (called once, on the function's own type)."""
        self.inline(msgtype, path)
        self.flush()
        return self.finish()

    def inline(self, msgtype: str, path: str) -> None:
        """A message's fields into the f-string, in definition order."""
        entries = self.m.fields(msgtype)
        self.aligned = 8  # what rosbags' function for a nested message assumes on entry
        self.text("{")
        first = True
        for current, following in pairwise([*entries, None]):
            name, desc = current
            here = f"{path}.{name}" if path else name
            if name == MARKER:  # read as rosbags reads it, left out of the text
                if self.m.cdr:
                    self.step(here, "take(raw, pos, 1)", "pos += 1")
                    self.aligned = 1
            else:
                self.text(("" if first else ", ") + json_string(name) + ": ")
                self.field(desc, here)
                first = False
            if self.m.cdr and following and self.aligned < (need := align(following[1], self.m.typestore)):
                self.align_to(need)
        self.text("}")

    def field(self, desc: Any, path: str) -> None:
        node, detail = desc
        if node == Nodetype.NAME:
            self.inline(detail, path)
            self.aligned = align_after(desc, self.m.typestore)
        elif node == Nodetype.BASE:
            self.base(detail[0], path)
        elif node == Nodetype.ARRAY:
            self.array(detail[0], detail[1], path)
        elif node == Nodetype.SEQUENCE:
            self.sequence(detail[0], path)
        else:
            raise Unsupported(f"{path}: node type {node}")

    def align_to(self, n: int) -> None:
        self.flush()
        self.lines.append(f"pos = (pos + {n - 1}) & -{n}")
        self.aligned = n

    def base(self, typ: str, path: str) -> None:
        if typ == "string":
            s = self.new("s")
            self.step(path, f"{s}, pos = {self.read_string()}(raw, pos, u32)")
            self.value(s)
            self.aligned = 1
        elif typ == "bool":
            s = self.new("s")
            self.step(path, f"{s} = 'true' if take(raw, pos, 1)[0] else 'false'", "pos += 1")
            self.value(s)
            self.aligned = 1
        elif typ in CODES:
            self.value(self.number(typ, 1, path)[0])
        else:
            raise Unsupported(f"{path}: base type {typ}")

    def read_string(self) -> str:
        return "cdr_string" if self.m.cdr else "ros1_string"

    def number(self, typ: str, n: int, path: str) -> list[str]:
        """`n` numbers of `typ` joining the run; their slots' names."""
        if not self.run:
            self.run_var = self.new("v")
            self.run_count = 0
        self.run.append(CODES[typ] * n if n < 4 else f"{n}{CODES[typ]}")
        self.run_paths.append(path)
        if path in STAMP and typ in INTS:
            self.stamp[path] = f"{self.run_var}[{self.run_count}]"
        self.run_count += n
        self.aligned = SIZEMAP[typ]
        self.numbered += n
        return [f"t{k}" for k in range(self.numbered - n, self.numbered)]

    def flush(self) -> None:
        """Read the pending run with one struct call."""
        if not self.run:
            return
        fmt = self.m.endian + "".join(self.run)
        reader = self.m.constant("unpack", f"Struct({fmt!r}).unpack_from")
        paths = self.run_paths[0] + (f" .. {self.run_paths[-1]}" if len(self.run_paths) > 1 else "")
        v = self.run_var
        self.lines += [f"at = {paths!r}", f"{v} = {reader}(raw, pos)", f"pos += {struct.calcsize(fmt)}"]
        self.runs.append(v)
        self.run, self.run_paths = [], []

    def array(self, sub: Any, length: int, path: str) -> None:
        """A fixed-size array (rosbags: numpy for numbers, lists otherwise)."""
        node, detail = sub
        s = self.new("s")
        if length == 0:
            raise Unsupported(f"{path}: an array of length 0")
        if node == Nodetype.NAME:
            before, after = align(sub, self.m.typestore), align_after(sub, self.m.typestore)
            each = before if self.m.cdr and before > after else 1
            fn = self.m.element(detail)
            self.step(path, f"{s}, pos = messages({fn}, raw, pos, {length}, {each}, {path!r})")
            self.value(s)
            self.aligned = after
            return
        typ = detail[0]
        if typ == "string":
            self.step(path, f"{s}, pos = strings(raw, pos, {length}, u32, {self.m.cdr}, False)")
            self.value(s)
            self.aligned = 1
        elif typ in BYTES or typ == "bool":
            render = "b64" if typ in BYTES else "bools"
            self.step(path, f"{s} = {render}(take(raw, pos, {length}))", f"pos += {length}")
            self.value(s)
            self.aligned = 1
        elif typ in CODES and length < MEMO_ARRAY:
            slots = self.number(typ, length, path)
            self.text("[")
            for k, slot in enumerate(slots):
                self.text(", " if k else "")
                self.value(slot)
            self.text("]")
        elif typ in CODES:
            fmt = f"{self.m.endian}{length}{CODES[typ]}"
            size = struct.calcsize(fmt)
            memo = self.m.constant("memo", f"ArrayMemo(Struct({fmt!r}).unpack).text")
            self.step(path, f"{s} = {memo}(raw[pos : pos + {size}])", f"pos += {size}")
            self.value(s)
            self.aligned = SIZEMAP[typ]
        else:
            raise Unsupported(f"{path}: array of {typ}")

    def sequence(self, sub: Any, path: str) -> None:
        """A variable-length sequence: uint32 count, then the elements (rosbags' checks)."""
        node, detail = sub
        typ = detail[0] if node == Nodetype.BASE else ""
        if node == Nodetype.BASE and typ not in CODES and typ != "string":
            raise Unsupported(f"{path}: sequence of {typ}")
        minimum = (5 if self.m.cdr else 4) if typ == "string" else SIZEMAP[typ] if typ else int(self.m.cdr)
        s = self.new("s")
        self.step(path, f"n, pos = count(raw, pos, u32, {minimum}, MAX_SEQUENCE)")
        self.aligned = 4
        if node == Nodetype.NAME:
            before = align(sub, self.m.typestore) if self.m.cdr else 1
            self.lines.append(f"{s}, pos = messages({self.m.element(detail)}, raw, pos, n, {before}, {path!r})")
            self.aligned = align_after(sub, self.m.typestore)
        elif typ == "string":
            self.lines.append(f"{s}, pos = strings(raw, pos, n, u32, {self.m.cdr}, True)")
            self.aligned = 1
        elif typ in BYTES or typ == "bool":
            self.lines += [f"{s} = {'b64' if typ in BYTES else 'bools'}(raw[pos : pos + n])", "pos += n"]
            self.aligned = 1
        else:
            size = SIZEMAP[typ]
            if self.m.cdr and self.aligned < size:
                self.lines += ["if n:", f"    pos = (pos + {size - 1}) & -{size}"]
            fmt = f"{self.m.endian}{{n}}{CODES[typ]}"
            self.lines += [f"{s} = numbers(unpack_from(f{fmt!r}, raw, pos))", f"pos += n * {size}"]
            self.aligned = size
        self.value(s)
        self.aligned = min(4, self.aligned)

    # -- the function ------------------------------------------------------------
    def finish(self) -> str:
        values = "f" + repr("".join(self.parts))  # the slots are plain names: no quotes, no backslashes
        out = [f"def {self.signature}:"]
        if self.top:
            out.append("    if raw.__class__ is not bytes:  # a memoryview slice has no decode()")
            out.append("        raw = bytes(raw)")
            out += ["    raw = raw[4:]  # past the CDR header"] if self.m.cdr else []
            out.append("    pos = 0")
        out += ["    at = ''", "    try:", *("        " + line for line in self.lines or ["pass  # no fields"]),
                "    except WireError:", "        raise", "    except Exception as err:",
                "        raise WireError.wrap(at, err) from err"]  # fmt: skip
        slots = ", ".join(f"t{k}" for k in range(self.numbered)) + ("," if self.numbered == 1 else "")
        render = [f"    {slots} = number_texts({' + '.join(self.runs)})"] if self.runs else []
        if not self.top:
            return "\n".join([*out, *render, f"    return {values}, pos", "", ""])
        # rosbags: a ROS 1 message must end exactly at its last field; CDR may pad to 4 bytes.
        slack = 3 if self.m.cdr else 0
        out += [f"    if pos + {slack} < len(raw):" if slack else "    if pos != len(raw):",
                "        raise WireError('', f'{len(raw) - pos} bytes left over after the message')"]  # fmt: skip
        stamp = "None"
        if len(self.stamp) == 2:
            stamp = f"{self.stamp[STAMP[0]]} * 1000000000 + {self.stamp[STAMP[1]]}"
        return "\n".join([*out, *render, f"    return {values}, {stamp}", "", ""])
