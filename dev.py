#!/usr/bin/env python3
"""Set up and run reckon from a fresh clone: `python3 dev.py demo` or `python3 dev.py test`.

Creates `.venv` beside this file on first use (and again when pyproject.toml changes), installs
reckon with `[test]` (every extra of pyproject.toml plus the test tools) and compiles the chair
filter for this machine, then runs the demo, the tests, or any `reckon` subcommand.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
BIN = VENV / ("Scripts" if os.name == "nt" else "bin")
STAMP = VENV / ".reckon-installed"


def ensure_environment() -> None:
    if sys.version_info < (3, 11):
        sys.exit(f"reckon needs Python 3.11 or newer; this is {sys.version.split()[0]}")
    wanted = hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()
    if STAMP.exists() and STAMP.read_text() == wanted:
        return
    if not (BIN / "python").exists():
        print("dev.py: creating .venv", file=sys.stderr)
        venv.EnvBuilder(with_pip=True).create(VENV)
    print("dev.py: installing reckon and its dependencies into .venv", file=sys.stderr)
    subprocess.run([str(BIN / "python"), "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
                    "-e", f"{ROOT}[test]"], check=True)
    # the chair filter, compiled ahead of time for this machine (reckon/kernels.py; else on first use)
    subprocess.run([str(BIN / "python"), "-m", "reckon.kernels"], check=False)
    STAMP.write_text(wanted)


def main(argv: list[str]) -> int:
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__.strip())
        return 0
    ensure_environment()
    command, rest = argv[0], argv[1:]
    if command == "test":
        run = [str(BIN / "python"), "-m", "pytest", *rest]
    elif command == "setup":
        return 0
    else:  # demo, or any reckon subcommand
        run = [str(BIN / "reckon"), command, *rest]
    return subprocess.run(run, cwd=ROOT).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
