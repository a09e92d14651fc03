"""Child process of the capture kill sweep: store three images and SIGKILL itself at point N.

Points are counted in the order they happen: every fsync, every link/rename that names a file, every SQL
statement and the commit of the image rows. ``python -m tests.store.image_kill URL N TAG`` exits 0 when
the work finished before point N (the sweep is then complete).
"""

from __future__ import annotations

import os
import signal
import sys
from typing import Any

from sqlalchemy import Engine, event

from calibctl.store.repository import Store


def images(tag: str) -> list[bytes]:
    return [f"\x89PNG image {i} of run {tag}".encode() * 50 for i in range(3)]


def main(url: str, kill_at: int, tag: str) -> None:
    count = 0

    def point() -> None:
        nonlocal count
        count += 1
        if count == kill_at:
            os.kill(os.getpid(), signal.SIGKILL)

    def wrap(fn: Any) -> Any:
        def hooked(*args: Any, **kwargs: Any) -> Any:
            point()
            return fn(*args, **kwargs)

        return hooked

    store = Store.open(url)
    os.fsync = wrap(os.fsync)
    os.link = wrap(os.link)
    os.replace = wrap(os.replace)
    event.listen(Engine, "before_cursor_execute", lambda *a: point())
    event.listen(Engine, "commit", lambda *a: point())
    store.put_images(images(tag), retention_days=30)
    store.close()


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), sys.argv[3])
