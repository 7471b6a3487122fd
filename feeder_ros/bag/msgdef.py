"""Parse ROS 2 message definitions (.msg text and MCAP ``ros2msg`` schemas) into field lists.

Each .msg text is parsed by ROS's own parser (``rosidl_adapter.parser``); this module splits a
schema into its types and turns the parse into the flat :class:`Field` records the CDR decoder
walks.

A ``ros2msg`` schema is the .msg text of the top-level type followed by the text of every type it
depends on, each introduced by a line of 80 ``=`` and a ``MSG: pkg/Type`` line. Type names are
normalised to ``pkg/msg/Type``; ``pkg/Type`` and (inside a package) ``Type`` are accepted as well.
"""

from __future__ import annotations

import contextlib
import io
import re
from dataclasses import dataclass
from typing import Any

from rosidl_adapter.parser import (
    InvalidSpecification,
    is_valid_message_name,
    parse_message_string,
)

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


def _field(field: Any, package: str) -> Field:
    """One field of rosidl_adapter's parse as ours: ``T[]`` and ``T[<=N]`` are both sequences."""
    kind = field.type
    base = kind.type if kind.is_primitive_type() else normalize_type(f"{kind.pkg_name}/{kind.type}")
    if base not in PRIMITIVE_SIZES and base not in STRING_TYPES and "/" not in base:
        base = normalize_type(base, package)  # e.g. ROS 1's time/duration: no such type here
    if not kind.is_array:
        return Field(field.name, base)
    if kind.array_size is None or kind.is_upper_bound:
        return Field(field.name, base, "seq")
    return Field(field.name, base, "fixed", int(kind.array_size))


def parse_msg_text(type_name: str, text: str) -> tuple[Field, ...]:
    """Fields (constants dropped) of one .msg text, parsed by ROS's own ``rosidl_adapter``;
    ``type_name`` resolves relative types. A text it refuses raises MessageDefinitionError
    with its reason."""
    type_name = normalize_type(type_name)
    package = package_of(type_name)
    name = type_name.rsplit("/", 1)[-1]
    # rosidl_adapter checks the type's own name (an action's FeedParts_FeedbackMessage fails
    # it), which does not change the fields: such a name is parsed under a stand-in
    if not is_valid_message_name(name):
        name = "Message"
    refused = io.StringIO()  # rosidl_adapter also prints its refusal: it goes into our error
    try:
        with contextlib.redirect_stderr(refused):
            spec = parse_message_string(package, name, text)
    except (InvalidSpecification, ValueError, TypeError, IndexError) as error:
        raise MessageDefinitionError(type_name, str(error)) from None
    return tuple(_field(field, package) for field in spec.fields)


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
