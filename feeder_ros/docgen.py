"""Generate the README's tables of node topics, services and parameters from the node code.

``python -m feeder_ros.docgen README.md`` rewrites the generated block in place;
``--check`` exits 1 (with a diff) when the README is out of date, which the tests run.
"""

from __future__ import annotations

import argparse
import difflib
import sys
from collections.abc import Iterable
from pathlib import Path

from feeder_ros.node_interfaces import NodeInterface

BEGIN = "<!-- BEGIN GENERATED: node interfaces (python -m feeder_ros.docgen README.md) -->"
END = "<!-- END GENERATED: node interfaces -->"


def _range(spec: object) -> str:
    from feeder_ros.physics.parameters import ParameterSpec

    assert isinstance(spec, ParameterSpec)
    if spec.choices:
        return " \\| ".join(f"`{choice}`" for choice in spec.choices)
    low = "" if spec.minimum is None else f"{spec.minimum:g}"
    high = "" if spec.maximum is None else f"{spec.maximum:g}"
    if not low and not high:
        return ""
    left = "(" if spec.exclusive_minimum else "["
    return f"{left}{low or '-inf'}, {high or 'inf'}]"


def render(interfaces: Iterable[NodeInterface]) -> str:
    lines: list[str] = []
    for interface in interfaces:
        lines += [f"#### `{interface.executable}` (node `{interface.node_name}`)", ""]
        lines += [interface.summary, ""]
        topics = [("pub", t) for t in interface.publishes] + [
            ("sub", t) for t in interface.subscribes
        ]
        if topics:
            lines += ["| | topic | type | QoS | meaning |", "|---|---|---|---|---|"]
            lines += [
                f"| {d} | `{t.name}` | `{t.type}` | {t.qos} | {t.description} |" for d, t in topics
            ]
            lines.append("")
        if interface.services:
            lines += ["| service or action | type | meaning |", "|---|---|---|"]
            lines += [f"| `{s.name}` | `{s.type}` | {s.description} |" for s in interface.services]
            lines.append("")
        if interface.parameters:
            lines += ["| parameter | type | unit | range | read-only | meaning |"]
            lines += ["|---|---|---|---|---|---|"]
            for spec in interface.parameters.values():
                lines.append(
                    f"| `{spec.name}` | {spec.kind.__name__} | {spec.unit} | {_range(spec)} | "
                    f"{'yes' if spec.read_only else ''} | {spec.description} |"
                )
            lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def replace_block(text: str, block: str) -> str:
    start = text.index(BEGIN) + len(BEGIN)
    end = text.index(END)
    return text[:start] + "\n\n" + block + "\n" + text[end:]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("readme", type=Path)
    parser.add_argument("--check", action="store_true", help="fail if the README is stale")
    args = parser.parse_args(argv)
    from feeder_ros.nodes.catalog import node_interfaces

    text = args.readme.read_text(encoding="utf-8")
    if BEGIN not in text or END not in text:
        print(f"{args.readme}: markers {BEGIN!r} ... {END!r} not found", file=sys.stderr)
        return 2
    updated = replace_block(text, render(node_interfaces()))
    if args.check:
        if updated != text:
            sys.stdout.writelines(
                difflib.unified_diff(
                    text.splitlines(True), updated.splitlines(True), "README.md", "generated"
                )
            )
            return 1
        return 0
    if updated != text:
        tmp = args.readme.with_suffix(".tmp")
        tmp.write_text(updated, encoding="utf-8")
        tmp.replace(args.readme)
    return 0


if __name__ == "__main__":
    sys.exit(main())
