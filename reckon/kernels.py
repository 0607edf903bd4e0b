"""A chair's compiled steps, ahead of time: built once per source and machine, loaded without numba.

edge/chair/merge_kernel.py's `merge_batch` and edge/chair/kernel.py's `run_batch`, `run_poses` and
`merge_and_run` are numba code.
Compiling them just in time in every edge process costs that process numba and LLVM (some 150 MiB
of its 230) and seconds of start-up, ten times over on a Pi with ten chairs. So they are compiled
once by numba's ahead-of-time compiler (numba.pycc) into an extension module beside their sources,
`edge/chair/_chair_kernel_<key>.<ext>`, and every process that runs chairs (`reckon edge`, `reckon
eval`, the bench) loads that with numpy alone.

The key hashes what the machine code depends on: the sources in SOURCES (their constants are
frozen into it), the exported signatures, numba's version, the Python build and the CPU (it is
compiled for the host's instruction set, as the just-in-time code is). A changed source or another machine
finds no module of its key and builds one: in a child process (so the caller never imports numba),
under a file lock (ten edges starting at once build it once), about 10 s. install.sh and dev.py
build it at install time (`python -m reckon.kernels`).

Where it cannot be built (no C compiler, a read-only install), `chair_kernels` falls back to the
just-in-time kernels in the calling process and says why, once: slower to start and heavier, never
wrong (tests/reckon/test_kernels.py holds the two to the same bits).
"""

from __future__ import annotations

import argparse
import fcntl
import functools
import hashlib
import importlib.metadata
import importlib.util
import logging
import os
import platform
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

import edge.chair
from edge.chair.layout import ChairKernels

log = logging.getLogger(__name__)
DIRECTORY = Path(edge.chair.__file__).resolve().parent
# of edge/chair: what the machine code is made from, constants included
SOURCES = ("kernel.py", "kernel_math.py", "mag_kernel.py", "layout.py", "state.py", "estimator.py", "magnetometer.py",
           "merge_kernel.py", "merge_layout.py", "merger.py", "wheel_clock.py")
PREFIX = "_chair_kernel_"
SIGNATURES = {  # C-contiguous arrays, as the just-in-time code specialises (loops over 'A' arrays are slower)
    # merge_batch(config, ints, floats, role, time_ns, offsets, accel, gyro, mag, flush)
    "merge_batch": "Tuple((i8[::1], f8[:, ::1]))(f8[::1], i8[::1], f8[::1], i8, i8, i8[::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], i8)",
    # run_batch(settings, state, times, values)
    "run_batch": "Tuple((f8[::1], i8[::1]))(f8[::1], f8[::1], i8[::1], f8[:, ::1])",
    # run_poses(settings, state, times, values, next_pose_ns, period_ns)
    "run_poses": "Tuple((i8, i8, i8, i8[::1], f8[:, ::1]))(f8[::1], f8[::1], i8[::1], f8[:, ::1], i8, i8)",
    # merge_and_run(merge_batch's arguments, then settings, state, next_pose_ns, period_ns)
    "merge_and_run": "Tuple((i8, i8, i8, i8, i8[::1], f8[:, ::1]))"
                     "(f8[::1], i8[::1], f8[::1], i8, i8, i8[::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], i8, f8[::1], f8[::1], i8, i8)",
}
BUILD_TIMEOUT_S = 600.0

_loaded: dict[str, tuple[ChairKernels, str]] = {}


def cpu_identity() -> str:
    """What names this CPU's instruction set: /proc/cpuinfo's model and feature lines, else platform's."""
    try:
        text = Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace")
    except OSError:
        return platform.processor()
    wanted = ("model name", "flags", "features", "cpu part", "cpu implementer")
    seen: dict[str, str] = {}
    for line in text.splitlines():
        name, _, value = line.partition(":")
        name = name.strip().lower()
        if name in wanted and name not in seen:
            seen[name] = value.strip()
    return "|".join(f"{name}={seen[name]}" for name in sorted(seen)) or platform.processor()


@functools.cache  # the sources this process runs cannot change under it: read them once
def build_key() -> str:
    digest = hashlib.sha256()
    for name in SOURCES:
        digest.update((DIRECTORY / name).read_bytes())
    try:
        numba_version = importlib.metadata.version("numba")
    except importlib.metadata.PackageNotFoundError:
        numba_version = "absent"
    for part in (repr(SIGNATURES), numba_version, sys.version, str(sysconfig.get_config_var("EXT_SUFFIX")), platform.machine(),
                 cpu_identity()):
        digest.update(b"\0" + part.encode())
    return digest.hexdigest()[:16]


def module_path(key: str) -> Path:
    return DIRECTORY / f"{PREFIX}{key}{sysconfig.get_config_var('EXT_SUFFIX')}"


def _load(path: Path, name: str) -> ChairKernels:
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"{path}: not an extension module")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return ChairKernels(module.merge_batch, module.run_batch, module.run_poses, module.merge_and_run)


def chair_kernels(build: bool = True) -> tuple[ChairKernels, str]:
    """(kernels, how they were loaded): the ahead-of-time module of these sources and this machine,
    built first when missing (`build`); else the just-in-time kernels, with a warning that says why."""
    key = build_key()
    if key in _loaded:
        return _loaded[key]
    path, name = module_path(key), PREFIX + key
    why = f"{path.name} not built"
    if not path.exists() and build:
        why = build_module(key) or why
    if path.exists():
        try:
            _loaded[key] = (_load(path, name), "ahead-of-time")
            return _loaded[key]
        except ImportError as error:
            why = f"{path} did not load: {error}"
    log.warning("chair kernels: %s; compiling them in this process instead (numba: about 150 MiB and a few "
                "seconds more; `python -m reckon.kernels` says why they cannot be built)", why)
    from edge.chair.kernel import just_in_time
    _loaded[key] = (just_in_time(), "just-in-time")
    return _loaded[key]


def build_module(key: str) -> str | None:
    """Compile the module of `key` in a child process unless another has; None, or why it failed."""
    path = module_path(key)
    try:
        lock = open(DIRECTORY / ".chair_kernel.lock", "a")
    except OSError as error:
        return f"cannot build in {DIRECTORY}: {error.strerror}"
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if path.exists():
            return None
        work = Path(tempfile.mkdtemp(prefix=".build-", dir=DIRECTORY))
        try:
            done = subprocess.run([sys.executable, "-m", "reckon.kernels", "--compile", str(work), PREFIX + key],
                                  capture_output=True, text=True, timeout=BUILD_TIMEOUT_S)
            built = work / path.name
            if done.returncode != 0 or not built.exists():
                tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
                return f"building {path.name} failed (exit {done.returncode}): {' / '.join(tail)}"
            os.replace(built, path)
        except subprocess.TimeoutExpired:
            return f"building {path.name} took over {BUILD_TIMEOUT_S:.0f} s"
        finally:
            shutil.rmtree(work, ignore_errors=True)
        for old in DIRECTORY.glob(f"{PREFIX}*"):
            if old != path:
                old.unlink(missing_ok=True)
    return None


def _compile(out: Path, name: str) -> None:
    """In the child: numba.pycc over the kernels' own Python functions, for this CPU."""
    import warnings

    import llvmlite.binding
    from numba.core.errors import NumbaPendingDeprecationWarning
    warnings.simplefilter("ignore", NumbaPendingDeprecationWarning)  # pycc's; numba has no successor yet
    from numba.pycc import CC

    from edge.chair import kernel, merge_kernel
    compiler = CC(name)
    compiler.output_dir = str(out)
    compiler.target_cpu = llvmlite.binding.get_host_cpu_name()
    compiler.verbose = False
    compiler.export("merge_batch", SIGNATURES["merge_batch"])(merge_kernel.merge_batch.py_func)
    compiler.export("run_batch", SIGNATURES["run_batch"])(kernel.run_batch.py_func)
    compiler.export("run_poses", SIGNATURES["run_poses"])(kernel.run_poses.py_func)
    compiler.export("merge_and_run", SIGNATURES["merge_and_run"])(kernel.merge_and_run.py_func)
    compiler.compile()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m reckon.kernels",
                                     description="Build a chair's ahead-of-time kernels for this machine.")
    parser.add_argument("--compile", nargs=2, metavar=("DIR", "NAME"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.compile:
        _compile(Path(args.compile[0]), args.compile[1])
        return 0
    key = build_key()
    why = None if module_path(key).exists() else build_module(key)
    if why:
        print(f"chair kernels: {why}", file=sys.stderr)
        return 1
    print(f"chair kernels: {module_path(key)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
