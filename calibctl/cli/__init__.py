"""The command line. Importing it makes Ctrl-C during start-up quiet (see ``startup_interrupt``)."""

from __future__ import annotations

import os
import signal

EXIT_INTERRUPTED = 130


def startup_interrupt(signum: int, frame: object) -> None:  # no typing import: this runs first
    """Ctrl-C before a command runs (while Python imports calibctl, typer parses): nothing has been done, so
    exit 130 with one line instead of a KeyboardInterrupt traceback from whichever import was running (the
    hostile-input sweep saw `solve` interrupted at 0.3 s and 0.8 s end in one). The group's ``invoke``
    hands SIGINT back to Python's KeyboardInterrupt, which each command's cleanup relies on."""
    os.write(2, b"Interrupted before anything was done.\n")
    os._exit(EXIT_INTERRUPTED)


if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # an ignored SIGINT stays ignored
    signal.signal(signal.SIGINT, startup_interrupt)
