"""What every benchmark report states about the machine it ran on."""

from __future__ import annotations

import platform
from pathlib import Path


def cpu_model() -> str:
    """The CPU model as /proc/cpuinfo names it (platform's guess elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def load_1min() -> float:
    """The 1-minute load average now (printed beside each figure: the machine is shared)."""
    import os

    return os.getloadavg()[0]


def run_env(pycache: Path, code: Path | None = None) -> dict[str, str]:
    """The environment a timed subprocess runs in: bytecode written to and read from ``pycache`` (an installed
    package has its .pyc files; a session with PYTHONDONTWRITEBYTECODE=1 recompiles calibctl's ~100 modules in
    every process, 0.18 s on the 2-core VM, which no user pays), and ``code`` first on PYTHONPATH when given
    (the code before a change, ``git archive``d, measured in the same run)."""
    import os

    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPYCACHEPREFIX"] = str(pycache)
    if code is not None:
        env["PYTHONPATH"] = str(code)
    return env


def tree_cpu_s(pid: int) -> float:
    """CPU seconds (user + system) so far of process ``pid`` and its living descendants (worker pools), from
    /proc: what a unit costs the machine, which the other users' load disturbs much less than wall time."""
    import os

    ticks = os.sysconf("SC_CLK_TCK")
    parent: dict[int, int] = {}
    used: dict[int, float] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:  # ended while listed
            continue
        parent[int(entry.name)] = int(fields[1])
        used[int(entry.name)] = (int(fields[11]) + int(fields[12])) / ticks
    total = 0.0
    for p, cpu in used.items():
        q = p
        while q > 1 and q != pid:
            q = parent.get(q, 0)
        total += cpu if q == pid else 0.0
    return total
