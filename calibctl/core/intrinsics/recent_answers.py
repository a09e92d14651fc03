"""Answers remembered by a digest of the values they were computed from.

One ``calibrate`` asks some questions twice about the same corners: at capture (the ``one_camera`` gate,
the distance gauge's ``--model auto`` choice) and again at the solve. When an answer is a function of
the input values alone, ``RecentAnswers`` keeps the last few, keyed by ``values_digest`` of those values
(not of the array objects: a copy hits), so the second question costs a digest. Thread-safe; the oldest
answer is forgotten first, so memory stays bounded.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from collections.abc import Callable, Sequence
from typing import Generic, TypeVar

import numpy as np

T = TypeVar("T")


def values_digest(
    object_points_per_view: Sequence[np.ndarray], image_points_per_view: Sequence[np.ndarray], *params: object
) -> bytes:
    """A digest of corners (per view: (N, 3) and (N, 2), taken as float64) and ``params`` (repr-able)."""
    digest = hashlib.blake2b(repr((params, len(object_points_per_view))).encode(), digest_size=32)
    for o, i in zip(object_points_per_view, image_points_per_view, strict=True):
        for a in (np.ascontiguousarray(o, np.float64), np.ascontiguousarray(i, np.float64)):
            digest.update(repr(a.shape).encode())
            digest.update(a.tobytes())
    return digest.digest()


class RecentAnswers(Generic[T]):
    """The last ``size`` answers by key (``values_digest``); ``answer`` computes only on a miss."""

    def __init__(self, size: int) -> None:
        self.size = size
        self._answers: OrderedDict[bytes, T] = OrderedDict()
        self._lock = threading.Lock()

    def answer(self, key: bytes, compute: Callable[[], T]) -> T:
        with self._lock:
            if key in self._answers:
                self._answers.move_to_end(key)
                return self._answers[key]
        value = compute()
        with self._lock:
            self._answers[key] = value
            while len(self._answers) > self.size:
                self._answers.popitem(last=False)
        return value

    def take(self, key: bytes) -> T | None:
        """The answer remembered under ``key``, forgotten as it is handed out (asked once); None on a miss."""
        with self._lock:
            return self._answers.pop(key, None)

    def clear(self) -> None:
        with self._lock:
            self._answers.clear()

    def __len__(self) -> int:
        return len(self._answers)
