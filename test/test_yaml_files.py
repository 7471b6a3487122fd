"""The shared YAML reader: what a loader says of a file it cannot parse."""

from __future__ import annotations

from pathlib import Path

import pytest

from feeder_ros.cell import CellError, load_cell
from feeder_ros.yaml_files import YamlFileError, read_yaml


def test_a_yaml_file_is_read_and_bad_ones_are_named(tmp_path: Path) -> None:
    path = tmp_path / "f.yaml"
    path.write_text("a: [1, 2]\n", encoding="utf-8")
    assert read_yaml(path) == {"a": [1, 2]}
    path.write_bytes(b"a: 1\n\xff")
    with pytest.raises(YamlFileError) as not_text:
        read_yaml(path)
    assert str(not_text.value) == f"{path}: not UTF-8 text (invalid start byte at byte 5)"
    path.write_text("a: [1, 2\n", encoding="utf-8")
    with pytest.raises(YamlFileError, match=r"f\.yaml: not valid YAML: "):
        read_yaml(path)
    with pytest.raises(FileNotFoundError):  # the caller words a missing file for its kind
        read_yaml(tmp_path / "absent.yaml")


def test_the_cell_loader_names_a_file_that_is_not_text(tmp_path: Path) -> None:
    path = tmp_path / "cell.yaml"
    path.write_bytes(b"\xfe\xff")
    with pytest.raises(CellError, match=r"cell\.yaml: not UTF-8 text \(invalid start byte"):
        load_cell(path)
