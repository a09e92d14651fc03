"""A live camera unit's capture held in memory until it is complete, then written whole.

A camera unit cannot be captured twice: its frames are gone once the stream ends. So the station captures it
into ``HeldCapture`` (the ``CaptureStore`` of ``capture(..., into=...)``): the board the station fetched, the
kept frames' PNG bytes by sha256, the session. Nothing reaches the store while the operator moves the board,
so a Ctrl-C or an unplugged camera leaves nothing behind; once the stream has ended, ``write_to_store`` stores
the images then the session (the order ``capture`` keeps: no record names an image that is not durable), or,
with the store away, ``spool_images`` copies the same bytes into the spool for the unit's queued record, so
nothing is captured twice.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.common import sha256_hex
from calibctl.artifacts.session import CaptureSession
from calibctl.config import Settings
from calibctl.store.repository import Store
from calibctl.store.spool import Spool


class HeldCapture:
    """The ``CaptureStore`` of a camera unit: board given, images and session kept here."""

    image_dir = Path()  # capture() reports it; nothing is written anywhere until the unit is complete

    def __init__(self, board: BoardRevision) -> None:
        self.board = board
        self.images: dict[str, bytes] = {}
        self.session: CaptureSession | None = None

    def get_board(self, name: str, revision: int | None = None) -> BoardRevision:
        return (
            self.board
        )  # the one the station fetched for its --board (store, else spool), asked by that name

    def put_image(self, data: bytes, *, retention_days: int) -> str:
        return self.put_images([data], retention_days=retention_days)[0]

    def put_images(self, images: Sequence[bytes], *, retention_days: int) -> list[str]:
        shas = [sha256_hex(data) for data in images]
        self.images.update(zip(shas, images, strict=True))
        return shas

    def add_session(self, session: CaptureSession) -> None:
        self.session = session


def write_to_store(settings: Settings, held: HeldCapture) -> None:
    """Store the held images, then the session (``DatabaseUnreachableError`` when the store is away)."""
    assert held.session is not None
    with Store.open(settings.db_url) as store:
        store.put_images(list(held.images.values()), retention_days=settings.image_retention_days)
        store.add_session(held.session)


def spool_images(spool: Spool, held: HeldCapture) -> None:
    """Copy the held images into the spool (before its record names them)."""
    spool.put_images(list(held.images.values()))
