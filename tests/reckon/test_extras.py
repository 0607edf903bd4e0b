"""Install extras (pyproject.toml): a venue machine installs what it runs, and runs nothing of the evaluation.

For each runtime path (the edge, the hub, record, replay, doctor) two checks:
- at run time, in a fresh interpreter: the path's modules imported and its CLI handler run up to a
  user error (a missing file: after the handler's imports), then every loaded module's file is
  traced to the distribution that installed it, which must be the core's or the path's extra's,
  or one of their own requirements; and nothing of the evaluation is loaded;
- in the source: every import statement reachable from the path's CLI module, those inside
  functions too (the serial, BLE and phone sources are imported only when a URL asks for them),
  names a library declared directly in the core or the path's extra.
"""

from __future__ import annotations

import argparse
import ast
import importlib.metadata
import json
import re
import subprocess
import sys
import tomllib
from functools import cache
from pathlib import Path

import pytest
from packaging.requirements import Requirement

from reckon import cli

ROOT = Path(__file__).resolve().parents[2]
FIRST_PARTY = ("protocol", "edge", "hub", "sim_devices", "reckon")
VENUE = ROOT / "docs" / "examples" / "csv-session" / "session.toml"
EVAL_ONLY = ("matplotlib", "motmetrics", "foxglove", "pygeomag", "sim_devices", "reckon.evaluation",
             "reckon.importers", "reckon.bench", "reckon.tools.foxglove", "reckon.tools.demo")

# command: (its extra, None for the core alone; modules it may import; argv that runs its handler
# past its imports to a user error). The edge also imports its device sources (SOURCES). The
# doctor's run is a hub's: no device, so the core alone.
RUNTIME = {
    "edge": ("edge", ["reckon.processes.edge", "SOURCES"],
             ["edge", "--agent", "chair1", "--source", "mcap://{tmp}/missing.mcap"]),
    "hub": ("hub", ["reckon.processes.hub", "reckon.web.court_view"],
            ["hub", "--venue", str(VENUE), "--view", "no-port"]),
    "record": (None, ["reckon.transport.record"],
               ["record", "--venue", "v", "-o", "{tmp}/out.mcap", "--session", "{tmp}/missing.toml"]),
    "replay": (None, ["reckon.transport.replay"], ["replay", "{tmp}/missing.mcap"]),
    "doctor": (None, ["reckon.tools.doctor"], ["doctor", "--venue", str(VENUE), "--no-bus"]),
}
# The doctor's device checks (--source) import the edge's sources: in the source, it is an edge path.
STATIC_EXTRA = {"edge": "edge", "hub": "hub", "record": None, "replay": None, "doctor": "edge"}
STATIC_MORE = {"doctor": ["SOURCES"]}
CLI_MODULE = {"edge": "reckon.cli.edge", "hub": "reckon.cli.hub", "record": "reckon.cli.bus",
              "replay": "reckon.cli.bus", "doctor": "reckon.cli.doctor"}


def modules_of(names: list[str]) -> list[str]:
    """`names`, SOURCES replaced by the edge's source modules: the registry imports them by scheme
    name (edge/sources/registry.py), so no import statement leads to them."""
    from edge.sources.registry import SOURCE_MODULES

    return [module for name in names for module in (sorted(SOURCE_MODULES.values()) if name == "SOURCES" else [name])]


def normal(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


@cache
def project() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def declared(extra: str | None) -> set[str]:
    """Distributions the core plus `extra` name, following `reckon[...]` self-references."""
    extras = project()["optional-dependencies"]
    names: set[str] = set()
    todo = list(project()["dependencies"]) + (list(extras[extra]) if extra else [])
    while todo:
        requirement = Requirement(todo.pop())
        if normal(requirement.name) == "reckon":
            todo += [line for name in requirement.extras for line in extras[name]]
        else:
            names.add(normal(requirement.name))
    return names


def with_requirements(names: set[str]) -> set[str]:
    """`names` and everything they require, as installed here (markers evaluated without extras)."""
    found, todo = set(), list(names)
    while todo:
        name = todo.pop()
        if name in found:
            continue
        found.add(name)
        try:
            requires = importlib.metadata.requires(name) or []
        except importlib.metadata.PackageNotFoundError:
            continue
        for line in requires:
            requirement = Requirement(line)
            if requirement.marker is None or requirement.marker.evaluate({"extra": ""}):
                todo.append(normal(requirement.name))
    return found


@cache
def distribution_of_file() -> dict[Path, str]:
    files = {}
    for distribution in importlib.metadata.distributions():
        for file in distribution.files or ():
            if file.suffix in (".py", ".so", ".pyd"):
                files[Path(distribution.locate_file(file)).resolve()] = normal(distribution.metadata["Name"])
    return files


def loaded_modules(command: str, tmp_path: Path) -> dict[str, str | None]:
    """{module: file} after importing the path's modules and running its handler in a fresh interpreter."""
    _, modules, argv = RUNTIME[command]
    modules, argv = modules_of(modules), [part.format(tmp=tmp_path) for part in argv]
    code = ("import importlib, json, sys\n"
            "before = set(sys.modules)\n"  # the interpreter's own start (site, .pth hooks) is not the path's
            f"for name in {modules!r}: importlib.import_module(name)\n"
            "from reckon.cli import main\n"
            f"status = main(['-q', *{argv!r}])\n"
            "print(json.dumps({'status': status, 'modules': {name: getattr(module, '__file__', None) "
            "for name, module in list(sys.modules.items()) if name not in before}}))\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout.splitlines()[-1])
    assert report["status"] in (0, 1, 2), result.stderr  # 2: the user error that ends the handler
    return report["modules"]


def evaluation_only(modules) -> dict[str, str]:
    found: dict[str, str] = {}
    for name in sorted(modules):
        for root in EVAL_ONLY:
            if name == root or name.startswith(root + "."):
                found.setdefault(root, name)
    return found


@pytest.mark.parametrize("command", sorted(RUNTIME))
def test_a_runtime_path_loads_only_its_extra_and_nothing_of_the_evaluation(command, tmp_path):
    modules = loaded_modules(command, tmp_path)
    evaluation = evaluation_only(modules)
    assert evaluation == {}, f"reckon {command} loaded evaluation-only modules (of: first loaded): {evaluation}"
    extra = RUNTIME[command][0]
    allowed = with_requirements(declared(extra))
    owners = distribution_of_file()
    outside = {}
    for name, file in modules.items():
        if not file or name.partition(".")[0] in FIRST_PARTY:
            continue  # built in, a namespace package, or ours
        path = Path(file).resolve()
        if "site-packages" not in path.parts:
            continue  # the standard library
        owner = owners.get(path)
        if owner not in allowed:
            outside.setdefault(owner or str(path), name)
    assert outside == {}, (f"reckon {command} loaded modules of distributions outside the core + "
                           f"[{extra or 'no extra'}] (distribution: first module): {outside}")


def module_file(name: str) -> Path | None:
    path = ROOT.joinpath(*name.split("."))
    for candidate in (path / "__init__.py", path.with_suffix(".py")):
        if candidate.exists():
            return candidate
    return None


def imports_of(name: str, in_functions: bool) -> list[tuple[str, int]]:
    """(module, line) of the import statements in module `name`: those its import runs, and with
    `in_functions` those inside its functions too (they run when the function is called)."""
    file = module_file(name)
    package = name if file.name == "__init__.py" else name.rpartition(".")[0]
    found, todo = [], list(ast.parse(file.read_text()).body)
    while todo:
        node = todo.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)) and not in_functions:
            continue
        todo += ast.iter_child_nodes(node)
        if isinstance(node, ast.Import):
            found += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([node.module] if node.module else []))
            found += [(base, node.lineno)] + [(f"{base}.{alias.name}", node.lineno) for alias in node.names]
    return found


def reachable(starts: list[str]) -> tuple[set[str], dict[str, str]]:
    """First-party modules reachable from `starts` (the first: a CLI module), and {third-party
    top-level name: where it is imported}. A module an import names counts with its functions'
    imports; a package that is only the parent of one counts with what its own import runs. The CLI
    package's other command modules are not followed: building the parser imports them, but only
    the command's own handler runs (the runtime test shows that their top levels import nothing more)."""
    done: dict[str, bool] = {}
    libraries: dict[str, str] = {}
    start, todo = starts[0], [(name, True) for name in starts]
    while todo:
        name, in_functions = todo.pop()
        if done.get(name) in (in_functions, True) or (
                name.startswith("reckon.cli") and name not in (start, "reckon.cli.bus", "reckon.cli.common")):
            continue
        done[name] = in_functions
        parts = name.split(".")
        todo += [(".".join(parts[:i]), False) for i in range(1, len(parts))]  # its packages' imports run too
        for module, line in imports_of(name, in_functions):
            top = module.split(".")[0]
            if top in FIRST_PARTY:
                if module_file(module) is not None:
                    todo.append((module, True))
            elif top not in sys.stdlib_module_names and top != "__future__":
                libraries.setdefault(top, f"{name}:{line}")
    return set(done), libraries


@pytest.mark.parametrize("command", sorted(RUNTIME))
def test_every_library_a_runtime_path_imports_is_declared_in_its_extra(command):
    starts = [CLI_MODULE[command], *RUNTIME[command][1], *STATIC_MORE.get(command, [])]
    modules, libraries = reachable(modules_of(starts))
    evaluation = evaluation_only(modules)
    assert evaluation == {}, f"reckon {command} can import evaluation-only modules (of: first found): {evaluation}"
    extra = STATIC_EXTRA[command]
    allowed = declared(extra)
    distributions = importlib.metadata.packages_distributions()
    undeclared = {top: where for top, where in libraries.items()
                  if not {normal(d) for d in distributions.get(top, [top])} & allowed}
    assert undeclared == {}, (f"reckon {command} imports libraries that neither the core nor [{extra or 'no extra'}] "
                              f"declares (library: where): {undeclared}")


def test_the_clis_optional_modules_are_exactly_the_extras_libraries():
    extras = project()["optional-dependencies"]
    core = declared(None)
    optional = set().union(*(declared(name) for name in ("edge", "hub", "qr", "eval"))) - core
    distributions = importlib.metadata.packages_distributions()
    providers = {top: {normal(d) for d in names} for top, names in distributions.items()}
    for top in cli.OPTIONAL_MODULES:
        assert providers.get(top, set()) & optional, f"{top} in reckon.cli.OPTIONAL_MODULES is no extra's library"
    for name in optional:
        assert any(name in providers.get(top, set()) for top in cli.OPTIONAL_MODULES), (
            f"{name} is an extra's library but none of its modules is in reckon.cli.OPTIONAL_MODULES")
    assert set(cli.EXTRAS.values()) <= set(extras)
    commands = {name for action in cli.build_parser()._actions if isinstance(action, argparse._SubParsersAction)
                for name in action.choices}
    assert set(cli.EXTRAS) <= commands


def test_dev_py_installs_every_extra():
    assert declared("test") >= set().union(*(declared(name) for name in ("edge", "hub", "qr", "eval", "all")))
    assert '"-e", f"{ROOT}[test]"' in (ROOT / "dev.py").read_text()

