"""Installed message definitions: find .msg files and build ``ros2msg`` schemas with every
dependency.

Packages are looked up as ``<prefix>/share/<pkg>/msg/<Type>.msg`` for every prefix in
``AMENT_PREFIX_PATH`` and then ``sys.prefix`` (the venv, where this project installs its
interfaces). The type description hash (``RIHS01_...``) comes from the ``<Type>.json`` rosidl
installs next to the .msg file; it is empty when that file is absent.
"""

from __future__ import annotations

import json
import os
import sys
from functools import lru_cache
from pathlib import Path

from feeder_ros.bag.errors import UnknownTypeError
from feeder_ros.bag.msgdef import (
    SEPARATOR,
    MsgDefs,
    normalize_type,
    parse_msg_text,
    short_type,
)

__all__ = [
    "find_msg_file",
    "installed_definitions",
    "ros2msg_schema",
    "search_prefixes",
    "type_description_hash",
]


def search_prefixes() -> list[Path]:
    """Install prefixes searched for interface packages, in order."""
    prefixes = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for extra in (Path(sys.prefix), Path(sys.base_prefix)):
        if extra not in prefixes:
            prefixes.append(extra)
    return prefixes


def _type_parts(type_name: str) -> tuple[str, str]:
    pkg, _, name = normalize_type(type_name).split("/")
    return pkg, name


@lru_cache(maxsize=256)
def find_msg_file(type_name: str) -> Path:
    """Path of the installed .msg file of ``type_name``; raises ``UnknownTypeError``."""
    pkg, name = _type_parts(type_name)
    prefixes = search_prefixes()
    for prefix in prefixes:
        candidate = prefix / "share" / pkg / "msg" / f"{name}.msg"
        if candidate.is_file():
            return candidate
    raise UnknownTypeError(normalize_type(type_name), [p / "share" for p in prefixes])


def _dependencies(type_name: str) -> list[str]:
    """``type_name`` and every type it uses, depth first in order of first use."""
    order: list[str] = []

    def visit(name: str) -> None:
        if name in order:
            return
        order.append(name)
        text = find_msg_file(name).read_text(encoding="utf-8")
        for field in parse_msg_text(name, text):
            if not field.is_primitive and not field.is_string:
                visit(field.type)

    visit(normalize_type(type_name))
    return order


def installed_definitions(type_name: str) -> MsgDefs:
    """Parsed definitions of ``type_name`` and its dependencies from the installed .msg files."""
    return {
        name: parse_msg_text(name, find_msg_file(name).read_text(encoding="utf-8"))
        for name in _dependencies(type_name)
    }


@lru_cache(maxsize=256)
def ros2msg_schema(type_name: str) -> str:
    """The ``ros2msg`` schema text of ``type_name`` as rosbag2 stores it: its .msg text, then for
    each dependency a separator line, ``MSG: pkg/Type`` and that type's .msg text."""
    names = _dependencies(type_name)
    parts = [find_msg_file(names[0]).read_text(encoding="utf-8").rstrip("\n") + "\n"]
    for name in names[1:]:
        text = find_msg_file(name).read_text(encoding="utf-8").rstrip("\n")
        parts.append(f"{SEPARATOR}\nMSG: {short_type(name)}\n{text}\n")
    return "".join(parts)


@lru_cache(maxsize=256)
def type_description_hash(type_name: str) -> str:
    """``RIHS01_...`` hash of ``type_name`` from rosidl's installed .json; "" when unavailable."""
    full = normalize_type(type_name)
    try:
        path = find_msg_file(full).with_suffix(".json")
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnknownTypeError, OSError, ValueError):
        return ""
    for entry in data.get("type_hashes", []):
        if entry.get("type_name") == full:
            return str(entry.get("hash_string", ""))
    return ""
