"""How the project writes one value into a CSV cell (read back exactly by ``float``/``int``)."""

from __future__ import annotations


def csv_cell(value: object) -> str:
    """Booleans as 1/0, floats by ``repr`` (shortest round-trip form; nan and inf as Python
    spells them), anything else by ``str``."""
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return repr(value)
    return str(value)
