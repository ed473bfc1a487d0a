"""Point the ros-jazzy wheels' CMake export files at this interpreter.

The wheels were built on a host whose Python lived in /opt/python/cp311-cp311; their
``share/**/*.cmake`` files name its include directory and its numpy include directory,
and CMake then refuses to generate a message package ("includes non-existent path").
This rewrites those paths to the running interpreter's. Running it twice changes nothing.
docs/command_line.md ("ROS 2 Jazzy from the `ros-jazzy-*` wheels") says what the wheels need.
"""

import pathlib
import sys
import sysconfig

import numpy

BUILD_HOST_PATHS = {
    "/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include": numpy.get_include(),
    "/opt/python/cp311-cp311/include/python3.11": sysconfig.get_paths()["include"],
}


def fix(prefix: pathlib.Path) -> int:
    """Rewrite every CMake file under ``prefix/share``; return how many changed."""
    changed = 0
    for path in (prefix / "share").rglob("*.cmake"):
        text = path.read_text()
        new = text
        for old, here in BUILD_HOST_PATHS.items():
            new = new.replace(old, here)
        if new != text:
            path.write_text(new)
            changed += 1
    return changed


if __name__ == "__main__":
    prefix = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else sys.prefix)
    print(f"fix_ros_cmake_paths: {fix(prefix)} CMake files rewritten under {prefix}/share")
