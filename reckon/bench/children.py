"""The bench's child processes and what they cost: peak and current RSS, CPU per process and per thread.

Read from /proc while the children run, and from wait4 when they are reaped, so the numbers are
those of each process alone (Linux only, as the venue's machines are).
"""

from __future__ import annotations

import math
import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path


def cli_command(*arguments: str) -> list[str]:
    """The command line of a `reckon` subcommand run by this interpreter, quiet (`-q`)."""
    return [sys.executable, "-m", "reckon.cli", "-q", *arguments]


@dataclass
class Exited:
    returncode: int
    max_rss_mb: float  # VmHWM: the process's peak resident set, MiB
    cpu_s: float  # user + system, from wait4


class Child:
    """A subprocess whose peak RSS is read from /proc while it runs, reaped with wait4 (CPU time).

    `command`: its argv (`cli_command(...)` for a `reckon` subcommand); stdout and stderr go to
    `log_path`. The peak is VmHWM, not wait4's ru_maxrss: Linux carries the parent's peak across
    fork and exec into it, so every child would report at least this (bigger) process's RSS.
    """

    def __init__(self, name: str, command: list[str], log_path: Path):
        self.name, self.log_path = name, log_path
        with open(log_path, "wb") as log_file:
            self.process = subprocess.Popen(command, stdout=log_file, stderr=subprocess.STDOUT)
        self.exited: Exited | None = None
        self.peak_kb = 0

    def poll(self) -> Exited | None:
        """None while it runs (noting its peak RSS so far: the last note before it exits is the result)."""
        if self.exited is None:
            self.peak_kb = max(self.peak_kb, vm_kb(self.process.pid, "VmHWM"))
            pid, status, usage = os.wait4(self.process.pid, os.WNOHANG)
            if pid:
                self.process.returncode = os.waitstatus_to_exitcode(status)
                self.exited = Exited(self.process.returncode, self.peak_kb / 1024.0, usage.ru_utime + usage.ru_stime)
        return self.exited

    def reap(self, timeout_s: float) -> Exited:
        """Wait for the exit, killing it after `timeout_s`."""
        deadline = time.monotonic() + timeout_s
        while (exited := self.poll()) is None:
            if time.monotonic() > deadline:
                self.process.kill()
                deadline = math.inf
            time.sleep(0.005)
        return exited

    def cpu_s(self) -> float:
        """CPU seconds (user + system) used so far, while it runs."""
        try:
            fields = Path(f"/proc/{self.process.pid}/stat").read_text().rpartition(")")[2].split()
        except OSError:
            return math.nan
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime: fields 14, 15

    def interrupt(self) -> None:
        if self.poll() is None:
            self.process.send_signal(signal.SIGINT)


def vm_kb(pid: int, field: str) -> int:
    """One `Vm...` line of /proc/<pid>/status in kB (VmRSS now, VmHWM the peak); 0 once it has exited."""
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def thread_cpu_s(pid: int) -> dict[str, float]:
    """CPU seconds (utime + stime) of a process's threads by name, numbers dropped: Zenoh's runtime
    threads (`rx`, `tx`, `net`, `app`, `acc`) apart from Python's (`python`: the main thread and
    any Python thread, which all keep the process's name); {} once it has exited."""
    out: dict[str, float] = {}
    tick = os.sysconf("SC_CLK_TCK")
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return out
    for task in tasks:
        try:
            text = Path(f"/proc/{pid}/task/{task}/stat").read_text()
        except OSError:
            continue
        name = re.sub(r"-\d+$", "", text[text.index("(") + 1:text.rindex(")")])
        fields = text[text.rindex(")") + 2:].split()
        out[name] = out.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / tick
    return out


def system_busy_s() -> float:
    """CPU seconds all cores have spent not idle since boot (/proc/stat), to notice foreign load."""
    try:
        fields = [int(word) for word in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    except (OSError, ValueError):
        return math.nan
    return (sum(fields[:8]) - fields[3] - fields[4]) / os.sysconf("SC_CLK_TCK")  # minus idle and iowait
