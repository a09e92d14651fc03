"""What the spool tests share: a central store that can be taken away and brought back, a TCP proxy that
cuts a PostgreSQL connection the same way, and the unit folders."""

from __future__ import annotations

import shutil
import socket
import threading
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

import pytest

from calibctl.store.repository import Store
from calibctl.workflows.station.station import PASS, QUEUED, StationRequest, UnitResult, run_station
from tests.artifacts.factories import measured_board
from tests.workflows.synth_folders import rendered

SERIALS = ("CAM-1", "CAM-2", "CAM-3")


def central_folder(root: Path) -> Path:
    """A central SQLite store's folder: root/central/calibctl.db with board A17 registered."""
    (root / "central").mkdir()
    central_store(f"sqlite:///{root / 'central' / 'calibctl.db'}")
    return root / "central"


def unit_folders(factory: pytest.TempPathFactory, root: Path) -> Path:
    """One folder of 12 rendered views per unit (CAM-1 .. CAM-3), as the station's watched folder holds
    them."""
    good = rendered(factory, "good")  # rendered once per process
    for serial in SERIALS:
        shutil.copytree(good, root / "shots" / serial, ignore=shutil.ignore_patterns("*.json"))
    return root / "shots"


def central_store(url: str) -> str:
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    return url


def run(settings, shots: Path, serials, spool: Path, board: str = "A17") -> list[UnitResult]:
    lines: list[UnitResult] = []
    run_station(settings, StationRequest(board, f"{shots}/{{serial}}", spool=spool), serials, lines.append)
    return lines


def queue_three(settings, shots: Path, spool: Path, central: Path) -> None:
    """CAM-1 online (v1, the board is remembered), then CAM-1 twice and CAM-2 once with the store away."""
    assert [r.status for r in run(settings, shots, ["CAM-1"], spool)] == [PASS]
    with away(central):
        first = run(settings, shots, ["CAM-1", "CAM-2"], spool)
        again = run(
            settings, shots, ["CAM-1"], spool
        )  # a new station run: the same unit calibrated twice offline
    assert [(r.serial, r.status, r.verdict, r.spool_record, r.version) for r in first + again] == [
        ("CAM-1", QUEUED, PASS, 1, None),
        ("CAM-2", QUEUED, PASS, 2, None),
        ("CAM-1", QUEUED, PASS, 3, None),
    ]


@contextmanager
def away(folder: Path) -> Iterator[None]:
    """A SQLite store made unreachable: its folder is moved away (SQLite: "unable to open database file"),
    then put back."""
    hidden = folder.with_name(folder.name + "-away")
    folder.rename(hidden)
    try:
        yield
    finally:
        hidden.rename(folder)


class TcpProxy:
    """127.0.0.1:<port> forwarded to ``target``; ``cut()`` closes the listener and every open connection (a
    network cut: connects are refused, a connection in use breaks), ``restore()`` listens again on the same
    port.
    The PostgreSQL server behind it, shared with other tests, is never touched."""

    def __init__(self, target: tuple[str, int]) -> None:
        self.target = target
        probe = socket.socket()
        probe.bind(("127.0.0.1", 0))
        self.port = int(probe.getsockname()[1])
        probe.close()
        self._listener: socket.socket | None = None
        self._open: list[socket.socket] = []
        self._lock = threading.Lock()

    def restore(self) -> None:
        listener = socket.socket()
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind(("127.0.0.1", self.port))
        listener.listen(16)
        self._listener = listener
        threading.Thread(target=self._accept, args=(listener,), daemon=True).start()

    def cut(self) -> None:
        assert self._listener is not None
        self._listener.close()
        self._listener = None
        with self._lock:
            for sock in self._open:
                with suppress(OSError):
                    sock.shutdown(socket.SHUT_RDWR)
                sock.close()
            self._open.clear()

    def _accept(self, listener: socket.socket) -> None:
        while True:
            try:
                client, _ = listener.accept()
            except OSError:
                return  # cut
            try:
                upstream = socket.create_connection(self.target, timeout=5)
            except OSError:
                client.close()
                continue
            with self._lock:
                self._open += [client, upstream]
            for a, b in ((client, upstream), (upstream, client)):
                threading.Thread(target=self._pump, args=(a, b), daemon=True).start()

    @staticmethod
    def _pump(src: socket.socket, dst: socket.socket) -> None:
        try:
            while data := src.recv(65536):
                dst.sendall(data)
        except OSError:
            pass
        finally:
            for sock in (src, dst):
                with suppress(OSError):
                    sock.shutdown(socket.SHUT_RDWR)
