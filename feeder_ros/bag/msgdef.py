"""Parse ROS 2 message definitions (.msg text and MCAP ``ros2msg`` schemas) into field lists.

A ``ros2msg`` schema is the .msg text of the top-level type followed by the text of every type it
depends on, each introduced by a line of 80 ``=`` and a ``MSG: pkg/Type`` line. Type names are
normalised to ``pkg/msg/Type``; ``pkg/Type`` and (inside a package) ``Type`` are accepted as well.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from feeder_ros.bag.errors import MessageDefinitionError

__all__ = [
    "PRIMITIVE_SIZES",
    "SEPARATOR",
    "Field",
    "MsgDefs",
    "normalize_type",
    "package_of",
    "parse_msg_text",
    "parse_ros2msg_schema",
    "short_type",
]

SEPARATOR = "=" * 80

# CDR size (and alignment) of each primitive; strings are handled separately.
PRIMITIVE_SIZES: dict[str, int] = {
    "bool": 1,
    "byte": 1,
    "char": 1,
    "int8": 1,
    "uint8": 1,
    "int16": 2,
    "uint16": 2,
    "int32": 4,
    "uint32": 4,
    "int64": 8,
    "uint64": 8,
    "float32": 4,
    "float64": 8,
}
STRING_TYPES = frozenset({"string", "wstring"})

_ARRAY_RE = re.compile(r"^(?P<base>[^\[\]]+)(?:\[(?P<bound><=)?(?P<size>\d*)\])?$")


@dataclass(frozen=True)
class Field:
    """One field of a message: ``type`` is a primitive, ``string``/``wstring`` or ``pkg/msg/Type``.

    ``array`` is ``None`` for a scalar, ``"fixed"`` for ``T[N]`` (``count`` = N) and ``"seq"`` for
    ``T[]`` and ``T[<=N]`` (both are length-prefixed in CDR).
    """

    name: str
    type: str
    array: str | None = None
    count: int = 0

    @property
    def is_primitive(self) -> bool:
        return self.type in PRIMITIVE_SIZES

    @property
    def is_string(self) -> bool:
        return self.type in STRING_TYPES


MsgDefs = dict[str, tuple[Field, ...]]


def package_of(type_name: str) -> str:
    return type_name.split("/", 1)[0]


def normalize_type(type_name: str, package: str | None = None) -> str:
    """``pkg/Type``, ``pkg/msg/Type`` or (with ``package``) ``Type`` -> ``pkg/msg/Type``."""
    parts = type_name.strip().split("/")
    if len(parts) == 3:
        return type_name.strip()
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    if len(parts) == 1 and parts[0]:
        if parts[0] == "Header" and package != "std_msgs":
            return "std_msgs/msg/Header"
        if package is None:
            raise MessageDefinitionError(type_name, "a type without package outside a package")
        return f"{package}/msg/{parts[0]}"
    raise MessageDefinitionError(type_name, "not a message type name")


def short_type(type_name: str) -> str:
    """``pkg/msg/Type`` -> ``pkg/Type`` (the form used after ``MSG:`` in schemas)."""
    parts = normalize_type(type_name).split("/")
    return f"{parts[0]}/{parts[2]}"


def _strip_comment(line: str) -> str:
    # A '#' inside a quoted default value is not a comment; constants are skipped anyway, so a
    # simple scan that respects quotes is enough.
    quote = ""
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = ""
        elif ch in "\"'":
            quote = ch
        elif ch == "#":
            return line[:i]
    return line


def _parse_field_type(type_name: str, token: str, package: str) -> tuple[str, str | None, int]:
    match = _ARRAY_RE.match(token)
    if match is None:
        raise MessageDefinitionError(type_name, f"cannot parse field type {token!r}")
    base = match["base"]
    if "<=" in base:  # bounded string: string<=N
        base = base.split("<=", 1)[0]
    if base not in PRIMITIVE_SIZES and base not in STRING_TYPES:
        base = normalize_type(base, package)
    if match.group(0).endswith("]"):
        if match["bound"] or not match["size"]:
            return base, "seq", 0
        return base, "fixed", int(match["size"])
    return base, None, 0


def parse_msg_text(type_name: str, text: str) -> tuple[Field, ...]:
    """Fields (constants dropped) of one .msg text; ``type_name`` resolves relative types."""
    type_name = normalize_type(type_name)
    package = package_of(type_name)
    fields: list[Field] = []
    for raw in text.splitlines():
        line = _strip_comment(raw).strip()
        if not line:
            continue
        head = line.split("=", 1)[0].split()
        if "=" in line and len(head) == 2:
            continue  # constant: TYPE NAME=VALUE
        tokens = line.split(None, 2)
        if len(tokens) < 2:
            raise MessageDefinitionError(type_name, f"cannot parse line {raw.strip()!r}")
        base, array, count = _parse_field_type(type_name, tokens[0], package)
        fields.append(Field(tokens[1], base, array, count))
    return tuple(fields)


def parse_ros2msg_schema(type_name: str, schema_text: str) -> MsgDefs:
    """All definitions of a ``ros2msg`` schema, keyed by ``pkg/msg/Type``; checks completeness."""
    top = normalize_type(type_name)
    defs: MsgDefs = {}
    sections = re.split(r"^={10,}\s*$", schema_text, flags=re.MULTILINE)
    defs[top] = parse_msg_text(top, sections[0])
    for section in sections[1:]:
        lines = section.strip("\n").splitlines()
        while lines and not lines[0].strip():
            lines.pop(0)
        if not lines or not lines[0].startswith("MSG:"):
            raise MessageDefinitionError(
                top, "a schema section does not start with 'MSG: pkg/Type'"
            )
        name = normalize_type(lines[0][4:].strip())
        defs.setdefault(name, parse_msg_text(name, "\n".join(lines[1:])))
    _check_complete(top, defs)
    return defs


def _check_complete(top: str, defs: MsgDefs) -> None:
    """Every type reachable from ``top`` is defined, and none contains itself (a ROS message
    cannot: a recursive schema is corrupt, and decoding it would never end)."""
    path: list[str] = []  # the chain of types from top being walked (depth first)
    done: set[str] = set()
    stack: list[tuple[str, bool]] = [(top, False)]
    while stack:
        name, leaving = stack.pop()
        if leaving:
            path.pop()
            done.add(name)
            continue
        if name in path:
            cycle = " -> ".join([*path[path.index(name) :], name])
            raise MessageDefinitionError(top, f"the schema is recursive ({cycle})")
        if name in done:
            continue
        if name not in defs:
            raise MessageDefinitionError(top, f"the schema lacks the definition of {name}")
        path.append(name)
        stack.append((name, True))
        stack.extend((f.type, False) for f in defs[name] if not f.is_primitive and not f.is_string)
