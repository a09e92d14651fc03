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
