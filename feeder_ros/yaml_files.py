"""Reading the project's YAML files (parameters, plans, design spaces, cells, speed models).

One place for what every loader must say about a file it cannot parse: the file, and whether it
is not text at all or not valid YAML. A missing or unreadable file (``OSError``) is left to the
caller, which words it for its file kind.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

__all__ = ["YamlFileError", "read_yaml"]


class YamlFileError(ValueError):
    """A file that is not UTF-8 text or not valid YAML; the message starts with its path."""


def read_yaml(path: Path) -> Any:
    """The document of the YAML file at ``path`` (``OSError`` propagates)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError as error:
        reason = f"not UTF-8 text ({error.reason} at byte {error.start})"
        raise YamlFileError(f"{path}: {reason}") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise YamlFileError(f"{path}: not valid YAML: {error}") from None
