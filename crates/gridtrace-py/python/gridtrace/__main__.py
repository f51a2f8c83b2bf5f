"""``python -m gridtrace ARGS``: runs the ``gridtrace`` command-line tool that the wheel installs
(the same as running ``gridtrace ARGS`` with the environment's bin/ on PATH)."""

import os
import shutil
import subprocess
import sys
import sysconfig


def _tool() -> str:
    name = "gridtrace.exe" if os.name == "nt" else "gridtrace"
    schemes = [None, f"{os.name}_user"]  # this environment's scripts, then `pip install --user`'s
    for scheme in schemes:
        try:
            folder = sysconfig.get_path("scripts", scheme) if scheme else sysconfig.get_path("scripts")
        except KeyError:
            continue
        path = os.path.join(folder, name)
        if os.path.isfile(path) and os.access(path, os.X_OK):
            return path
    found = shutil.which("gridtrace")
    if found:
        return found
    sys.exit(
        "gridtrace: the command-line tool is not installed with this package: the wheel from "
        "scripts/build-wheel.sh carries it (a build from source, `maturin develop` or "
        "`pip install ./crates/gridtrace-py`, does not); or: cargo install --locked --profile dist "
        "--path crates/gridtrace-cli"
    )


def main() -> int:
    return subprocess.call([_tool(), *sys.argv[1:]])


if __name__ == "__main__":
    sys.exit(main())
