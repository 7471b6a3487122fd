#!/usr/bin/env python3
"""Generate feeder_ros's messages and services with rosidl and install them into a Python venv.

This is the plain (non-colcon) install path. It

1. rewrites the include directories that the ``ros-*`` wheels' CMake export files name
   (``/opt/python/cp311-cp311/...``, the wheel build machine) to this venv's Python and numpy;
2. configures, builds and installs ``CMakeLists.txt`` with ninja into the venv with
   ``FEEDER_ROS_INSTALL_PYTHON=OFF`` (only the generated interfaces and their libraries);
3. removes the two files rosidl installs that would hide the pip-installed (editable) package:
   the empty generated ``feeder_ros/__init__.py`` and the ``feeder_ros-*.egg-info`` it registers.
   What stays, ``site-packages/feeder_ros/{msg,srv}`` and the typesupport modules, joins the
   source package through ``pkgutil.extend_path`` in ``feeder_ros/__init__.py``.

Run by ``make``; every step is idempotent, and ninja rebuilds nothing when nothing changed.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

WHEEL_BUILD_PYTHON_INCLUDE = "/opt/python/cp311-cp311/include/python3.11"
WHEEL_BUILD_NUMPY_INCLUDE = (
    "/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include"
)


def fix_wheel_cmake_exports(prefix: Path) -> int:
    """Point the wheels' CMake exports at this venv's include dirs; returns files changed."""
    import numpy

    replacements = {
        WHEEL_BUILD_PYTHON_INCLUDE: sysconfig.get_paths()["include"],
        WHEEL_BUILD_NUMPY_INCLUDE: numpy.get_include(),
    }
    changed = 0
    for path in (prefix / "share").rglob("*.cmake"):
        text = path.read_text(encoding="utf-8")
        if "/opt/python/cp311-cp311" not in text:
            continue
        for old, new in replacements.items():
            text = text.replace(old, new)
        if "/opt/python/cp311-cp311" in text:
            raise SystemExit(f"{path}: unknown wheel-build path left after rewriting")
        tmp = path.with_suffix(".cmake.tmp")
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)
        changed += 1
    return changed


def run(command: list[str], env: dict[str, str], log: Path) -> None:
    with log.open("a", encoding="utf-8") as out:
        out.write("$ " + " ".join(command) + "\n")
        out.flush()
        result = subprocess.run(command, env=env, stdout=out, stderr=subprocess.STDOUT, check=False)
    if result.returncode != 0:
        tail = log.read_text(encoding="utf-8").splitlines()[-40:]
        sys.stderr.write("\n".join(tail) + "\n")
        raise SystemExit(f"failed ({result.returncode}): {' '.join(command)}; full log: {log}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--source", type=Path, default=Path(__file__).resolve().parents[1])
    parser.add_argument("--build", type=Path, required=True, help="CMake build directory")
    args = parser.parse_args()

    prefix = Path(sys.prefix)
    if prefix == Path(sys.base_prefix):
        raise SystemExit("run this with the project venv's python, not the system one")
    changed = fix_wheel_cmake_exports(prefix)
    if changed:
        print(f"rewrote wheel-build include paths in {changed} CMake files")

    args.build.mkdir(parents=True, exist_ok=True)
    log = args.build / "install_interfaces.log"
    log.write_text("", encoding="utf-8")
    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = str(prefix)
    env["CMAKE_PREFIX_PATH"] = str(prefix)
    env["PATH"] = f"{prefix / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    if not (args.build / "build.ninja").exists():
        run(
            [
                "cmake", "-S", str(args.source), "-B", str(args.build), "-G", "Ninja",
                f"-DCMAKE_INSTALL_PREFIX={prefix}",
                f"-DPython3_EXECUTABLE={sys.executable}",
                "-DFEEDER_ROS_INSTALL_PYTHON=OFF",
                "-DBUILD_TESTING=OFF",
            ],
            env, log,
        )  # fmt: skip
    run(["cmake", "--build", str(args.build)], env, log)
    run(["cmake", "--install", str(args.build)], env, log)

    site = Path(sysconfig.get_paths()["purelib"])
    (site / "feeder_ros" / "__init__.py").unlink(missing_ok=True)
    for egg_info in site.glob("feeder_ros-*.egg-info"):
        shutil.rmtree(egg_info)
    print(f"interfaces installed into {prefix}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
