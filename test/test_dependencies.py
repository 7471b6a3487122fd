"""The package's dependencies are declared once in spirit and kept in step in four places.

``requirements.txt`` (the venv), ``setup.py`` (pip), ``distros/<distro>/requirements.txt`` (the ROS
wheels) and ``package.xml`` (rosdep, for a stock ROS workspace) must name the same dependencies:
a package added to one and not the others installs here and then fails at import in a workspace.
The rosdep key of each Python dependency is in ``distros/rosdep-keys.yaml``; what feeder_ros and
its tests import must be declared.
"""

from __future__ import annotations

import ast
import re
import sys
import xml.etree.ElementTree as ET
from importlib import metadata
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
DISTROS = ("jazzy", "kilted")
KEYS = yaml.safe_load((REPO / "distros" / "rosdep-keys.yaml").read_text())


def _sections(path: Path) -> dict[str, list[str]]:
    """Requirement lines by section; a comment ``# <name>: ...`` starts section <name>."""
    sections: dict[str, list[str]] = {}
    current = "head"
    for raw in path.read_text().splitlines():
        header = re.match(r"#\s*([a-z]+):", raw)
        if header:
            current = header.group(1)
        line = raw.split("#", 1)[0].strip()
        if line:
            sections.setdefault(current, []).append(line)
    return sections


def _name(requirement: str) -> str:
    return re.split(r"[\[<>=!~ ;]", requirement, maxsplit=1)[0].lower()


def _package_xml() -> dict[str, dict[str, str | None]]:
    """package.xml's dependencies by tag: {tag: {key: version_gte or None}}."""
    root = ET.parse(REPO / "package.xml").getroot()
    found: dict[str, dict[str, str | None]] = {}
    for element in root:
        if element.tag.endswith("depend") and element.text:
            found.setdefault(element.tag, {})[element.text.strip()] = element.get("version_gte")
    return found


def _imports(paths: list[Path]) -> set[str]:
    modules: set[str] = set()
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                modules.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules.add(node.module.split(".")[0])
    return modules


def test_python_dependencies_match_package_xml_and_setup_py() -> None:
    sections = _sections(REPO / "requirements.txt")
    xml = _package_xml()
    exec_deps = {**xml.get("exec_depend", {}), **xml.get("depend", {})}
    for section, tag_deps in (("runtime", exec_deps), ("tests", xml.get("test_depend", {}))):
        names = {_name(r): r for r in sections[section]}
        assert set(names) == set(KEYS[section]), (section, sorted(names), sorted(KEYS[section]))
        for name, key in KEYS[section].items():
            if key is None:
                continue
            assert key in tag_deps, f"package.xml lacks {key} ({name}, {section})"
            bound = re.search(r">=\s*([0-9.]+)", names[name])
            assert tag_deps[key] == (bound.group(1) if bound else None), (name, key)
        declared_keys = {
            k for k in tag_deps if k.startswith("python3-") or k in KEYS[section].values()
        }
        assert declared_keys <= set(KEYS[section].values()), (section, declared_keys)
    setup = ast.parse((REPO / "setup.py").read_text())
    call = next(
        n
        for n in ast.walk(setup)
        if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "setup"
    )
    args = {
        k.arg: ast.literal_eval(k.value)
        for k in call.keywords
        if k.arg in ("install_requires", "extras_require")
    }
    assert sorted(args["install_requires"]) == sorted(sections["runtime"])
    assert sorted(args["extras_require"]["test"]) == sorted(sections["tests"])


def test_ros_dependencies_match_each_distribution_s_wheels() -> None:
    xml = _package_xml()
    ros_deps = {
        k
        for tag in ("depend", "exec_depend")
        for k in xml.get(tag, {})
        if not k.startswith("python3-")
    }
    without_wheels = set(KEYS["ros_without_wheels"])
    for distro in DISTROS:
        prefix = "ros-jazzy-" if distro == "jazzy" else "ros-"
        runtime = _sections(REPO / "distros" / distro / "requirements.txt")["runtime"]
        wheels = {_name(r).removeprefix(prefix).replace("-", "_") for r in runtime}
        assert wheels == ros_deps - without_wheels, (
            distro,
            sorted(wheels ^ (ros_deps - without_wheels)),
        )


def test_everything_imported_is_declared() -> None:
    """Every third-party module feeder_ros (or its tests) imports is a declared dependency:
    a ROS package in package.xml, or a requirement of the matching section."""
    xml = _package_xml()
    ros = {k for deps in xml.values() for k in deps if not k.startswith("python3-")}
    distributions = metadata.packages_distributions()
    sections = _sections(REPO / "requirements.txt")
    # the package itself and the tests' own helper modules and packages
    local = {"feeder_ros"} | {
        p.stem for p in REPO.joinpath("test").rglob("*") if p.suffix in ("", ".py")
    }

    def undeclared(paths: list[Path], allowed: set[str]) -> dict[str, list[str]]:
        missing: dict[str, list[str]] = {}
        for module in sorted(_imports(paths) - set(sys.stdlib_module_names) - local - ros):
            owners = {d.lower() for d in distributions.get(module, [])}
            if not owners & allowed:
                missing[module] = sorted(owners)
        return missing

    runtime = {_name(r) for r in sections["runtime"]}
    package = [*REPO.joinpath("feeder_ros").rglob("*.py"), *REPO.joinpath("launch").glob("*.py")]
    assert undeclared(package, runtime) == {}
    tests = list(REPO.joinpath("test").rglob("*.py"))
    assert undeclared(tests, runtime | {_name(r) for r in sections["tests"]}) == {}


def test_the_readme_pip_installs_every_runtime_dependency_without_a_rosdep_key() -> None:
    """A stock ROS workspace gets these only from the README's pip line: none may be missing."""
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    [line] = [ln for ln in readme.splitlines() if ln.startswith("pip install ")]
    named = {_name(word.strip('"')) for word in line.split("#")[0].split()[2:]}
    without_key = {name for name, key in KEYS["runtime"].items() if key is None}
    assert named == without_key
