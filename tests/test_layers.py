"""Cores stay pure (style.md, Architecture 1): every module of edge/ (but the device adapters in
edge/sources/) and hub/ imports no I/O library, no clock, no thread and no logger, and neither do the
protocol/ modules, except one whose job is a file format's I/O (PROTOCOL_EXEMPT, with why).

The modules are found by walking the folders, so a new module is checked without being listed. Two
checks: what each module's source imports (by AST, every `import` anywhere in it), and what importing
all of them loads in a fresh interpreter (a core that imports a module that imports zenoh). The last
tests plant forbidden imports in temporary modules to show that both checks catch them.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# time: a core's time comes from its inputs' timestamps, or a clock the caller injects;
# os, pickle, socket, subprocess: files, processes and the network are the adapters' and the app's;
# threading, asyncio: the caller decides how work is scheduled; logging: a core counts what went wrong
# in its state or returns it, and the process logs it (style.md 6, 10); the rest are device, bus,
# recording and plotting libraries.
CORE_FORBIDDEN = frozenset({"time", "os", "pickle", "threading", "logging", "zenoh", "asyncio", "serial", "bleak",
                            "socket", "mcap", "mcap_protobuf", "matplotlib", "subprocess"})
PROTOCOL_FORBIDDEN = frozenset({"time", "threading", "logging", "os", "pickle"})
PROTOCOL_EXEMPT = {
    # The session log's MCAP layout (topics, schemas, the session metadata record) is a wire format, whose
    # one home is protocol/ (style.md 4); reading and writing it is file I/O, and a damaged file's problems
    # are logged as they are found. Nothing else in protocol/ imports them.
    "protocol/session_log.py": "reads and writes MCAP session logs: file I/O is its job",
    "protocol/log_index.py": "reads some channels of a complete MCAP session log through its index, for session_log",
}
# what importing every core (and protocol/, less PROTOCOL_EXEMPT) must not load, even indirectly
LOADED_FORBIDDEN = frozenset({"zenoh", "serial", "bleak", "mcap", "mcap_protobuf", "asyncio", "socket", "matplotlib"})


OURS = frozenset({"edge", "hub", "protocol", "reckon", "sim_devices"})  # this repository's packages


def imports(source: str) -> set[str]:
    """Dotted names of the absolute imports in `source`, wherever they are (a function's too);
    `from a.b import c` gives a.b and a.b.c (c may be a module or a name in a.b)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names |= {node.module} | {f"{node.module}.{alias.name}" for alias in node.names}
    return names


def direct_imports(source: str) -> set[str]:
    """Top-level names of the absolute imports in `source`."""
    return {name.split(".")[0] for name in imports(source)}


def modules_under(root: Path, folder: str, skip: tuple[str, ...] = ()) -> list[Path]:
    """Every .py file under root/folder, as paths relative to root, except under the folders `skip`."""
    return sorted(path.relative_to(root) for path in (root / folder).rglob("*.py")
                  if not any(path.relative_to(root).is_relative_to(s) for s in skip))


def core_modules(root: Path = ROOT) -> list[Path]:
    return modules_under(root, "edge", skip=("edge/sources",)) + modules_under(root, "hub")


def protocol_modules(root: Path = ROOT) -> list[Path]:
    return [p for p in modules_under(root, "protocol") if p.as_posix() not in PROTOCOL_EXEMPT]


def offenders(root: Path, modules: list[Path], forbidden: frozenset[str]) -> dict[str, list[str]]:
    """module path -> the forbidden names it imports, for every module that imports any."""
    found = {path.as_posix(): sorted(direct_imports((root / path).read_text(encoding="utf-8")) & forbidden)
             for path in modules}
    return {path: names for path, names in found.items() if names}


def loaded_by_importing(names: list[str], path: Path = ROOT, optional: bool = False) -> set[str]:
    """Top-level names of every module loaded by importing `names` in a fresh interpreter run in `path`;
    `optional`: a name that is not a module (`from numpy import ndarray` gives numpy.ndarray) is skipped."""
    skip = "ModuleNotFoundError" if optional else "()"
    code = ("import importlib, json, sys\n"
            f"for name in {names!r}:\n"
            "    try: importlib.import_module(name)\n"
            f"    except {skip}: pass\n"
            "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=path)
    assert result.returncode == 0, result.stderr
    return set(json.loads(result.stdout))


def libraries(root: Path, modules: list[Path], ours: frozenset[str] = OURS) -> list[str]:
    """What `modules` import from outside `ours` and the standard library, less the forbidden names."""
    names = set().union(*((imports((root / path).read_text(encoding="utf-8")) for path in modules)))
    return sorted(n for n in names if n.split(".")[0] not in ours | sys.stdlib_module_names | CORE_FORBIDDEN)


def io_loaded(root: Path, modules: list[Path], ours: frozenset[str] = OURS) -> tuple[set[str], set[str]]:
    """(the LOADED_FORBIDDEN names that importing `modules` loads, those that their libraries load alone)."""
    loaded = loaded_by_importing([module_name(p) for p in modules], root) & LOADED_FORBIDDEN
    return loaded, loaded_by_importing(libraries(root, modules, ours), root, optional=True) & LOADED_FORBIDDEN


def module_name(path: Path) -> str:
    parts = path.with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


# -- the code base --------------------------------------------------------------------------------


def test_the_walk_finds_the_cores():
    cores = {p.as_posix() for p in core_modules()}
    assert {"hub/identity/engine.py", "edge/chair/estimator.py", "edge/decoders/phone/parse.py"} <= cores
    assert not any(p.startswith("edge/sources/") for p in cores)
    assert "protocol/messages.py" in {p.as_posix() for p in protocol_modules()}
    assert set(PROTOCOL_EXEMPT) <= {p.as_posix() for p in modules_under(ROOT, "protocol")}  # no stale exemption


def test_cores_import_no_io_clock_thread_or_logger():
    assert offenders(ROOT, core_modules(), CORE_FORBIDDEN) == {}


def test_protocol_imports_no_clock_thread_logger_or_files():
    assert offenders(ROOT, protocol_modules(), PROTOCOL_FORBIDDEN) == {}


def test_importing_the_cores_loads_no_io_library():
    """Nothing forbidden beyond what the cores' own libraries load: scipy.optimize and numba load socket
    themselves (importlib.metadata reads package metadata through email.utils), which opens nothing."""
    loaded, by_libraries = io_loaded(ROOT, core_modules() + protocol_modules())
    assert loaded <= by_libraries, f"importing the cores loaded {sorted(loaded - by_libraries)}"
    assert by_libraries <= {"socket"}, f"a core's library loads {sorted(by_libraries)}: is it still pure?"


# -- the checks themselves: planted imports are caught ------------------------------------------------


@pytest.mark.parametrize("source, caught", [
    ("import time\n", {"time"}),
    ("import os.path\n", {"os"}),
    ("from logging import getLogger\n", {"logging"}),
    ("from threading import Thread as Worker\n", {"threading"}),
    ("import numpy as np, socket\n", {"socket"}),
    ("def later():\n    import pickle\n", {"pickle"}),
    ("try:\n    import zenoh\nexcept ImportError:\n    zenoh = None\n", {"zenoh"}),
    ("from mcap.reader import make_reader\n", {"mcap"}),
    ("import timeit\nimport hub.clocks\nfrom protocol import session_log\n", set()),  # names, not prefixes
    ("from . import time\n", set()),  # a relative import is the package's own module
])
def test_direct_imports_catch_a_planted_import(source, caught):
    assert direct_imports(source) & CORE_FORBIDDEN == caught


def test_the_walk_catches_a_planted_core_and_skips_the_adapters(tmp_path):
    for relative, source in {"edge/swim/edge.py": "import logging\n", "edge/sources/serial.py": "import serial\n",
                             "hub/identity/engine.py": "import numpy\n\ndef hop():\n    import time\n",
                             "hub/venue.py": "from hub.identity import engine\n"}.items():
        (tmp_path / relative).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / relative).write_text(source)
    assert offenders(tmp_path, core_modules(tmp_path), CORE_FORBIDDEN) == {
        "edge/swim/edge.py": ["logging"], "hub/identity/engine.py": ["time"]}


@pytest.mark.parametrize("helper, caught", [("import socket\n", {"socket"}), ("import asyncio\n", {"asyncio", "socket"}),
                                            ("import json\n", set())])
def test_the_fresh_interpreter_catches_an_indirect_import(tmp_path, helper, caught):
    (tmp_path / "planted").mkdir()
    (tmp_path / "planted" / "__init__.py").write_text("")
    (tmp_path / "planted" / "core.py").write_text("import numpy as np\nfrom planted import helper\n")
    (tmp_path / "planted" / "helper.py").write_text(helper)
    modules = modules_under(tmp_path, "planted")
    assert offenders(tmp_path, modules[:2], CORE_FORBIDDEN) == {}  # the core itself imports nothing forbidden
    loaded, by_libraries = io_loaded(tmp_path, modules[:2], ours=frozenset({"planted"}))
    assert loaded - by_libraries == caught
