"""Which photos of a rig's cameras were taken together, and whether the camera graph holds together.

Frame matching rule (documented for operators in docs/rigs.md, "Capture"): a photo's frame key is the
LAST run of digits in its file name stem, read as an integer, so ``left01.jpg`` / ``right01.jpg`` ->
1, ``left_001772846782141.jpg`` / ``right_001772846782141.jpg`` -> 1772846782141 (a timestamp),
``cam0_frame_0042.png`` -> 42. Photos of different cameras with the same key form one synchronised
frame. A photo without digits, a second photo with a key the camera already has, and a photo whose
key no other camera has are unmatched, each with its reason; a key seen by two or more cameras is a
frame (cameras that miss it simply have no view in that frame).

Rig gate ``rig-connected``: pairs that saw the board together in at least ``min_shared_views``
frames are edges of the camera graph; the gate passes when that graph connects every camera. When
it does not, the hint names the pair across the split with the most shared views (the cheapest to
fix) and how many more views it needs.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from calibctl.core.gate import GateResult

MIN_SHARED_VIEWS = 5
MAX_MIN_SHARED_VIEWS = 10_000
_DIGITS = re.compile(r"\d+")


@dataclass(frozen=True)
class UnmatchedPhoto:
    camera: str
    path: str
    reason: str  # "no-frame-key", "duplicate-frame-key", "no-partner"


@dataclass(frozen=True)
class FrameMatch:
    """frames: key -> {camera: path}, sorted by key; unmatched photos with their reasons."""

    frames: tuple[tuple[int, Mapping[str, str]], ...]
    unmatched: tuple[UnmatchedPhoto, ...]


def frame_key(path: str | Path) -> int | None:
    """The last run of digits of the file name stem as an integer, or None."""
    runs = _DIGITS.findall(Path(path).stem)
    return int(runs[-1]) if runs else None


def match_frames(photos: Mapping[str, Sequence[str | Path]]) -> FrameMatch:
    """Group each camera's photos into synchronised frames by frame key (module docstring)."""
    by_key: dict[int, dict[str, str]] = {}
    unmatched: list[UnmatchedPhoto] = []
    for camera, paths in photos.items():
        for path in sorted(str(p) for p in paths):
            key = frame_key(path)
            if key is None:
                unmatched.append(UnmatchedPhoto(camera, path, "no-frame-key"))
            elif camera in by_key.get(key, {}):
                unmatched.append(UnmatchedPhoto(camera, path, "duplicate-frame-key"))
            else:
                by_key.setdefault(key, {})[camera] = path
    frames = []
    for key in sorted(by_key):
        members = by_key[key]
        if len(members) < 2:
            unmatched.extend(UnmatchedPhoto(c, p, "no-partner") for c, p in members.items())
        else:
            frames.append((key, dict(members)))
    return FrameMatch(tuple(frames), tuple(unmatched))


def _components(n: int, edges: Sequence[tuple[int, int]]) -> list[int]:
    label = list(range(n))

    def find(i: int) -> int:
        while label[i] != i:
            i = label[i]
        return i

    for a, b in edges:
        label[find(a)] = find(b)
    return [find(i) for i in range(n)]


def rig_connected_gate(
    cameras: Sequence[str],
    shared_views: Mapping[tuple[int, int], int],
    min_shared_views: int = MIN_SHARED_VIEWS,
) -> GateResult:
    """The ``rig-connected`` gate (module docstring). shared_views: (a, b) with a < b -> frames both saw.
    ValueError when ``min_shared_views`` is below 1 (a pair that shares no frame links nothing)."""
    if not 1 <= min_shared_views <= MAX_MIN_SHARED_VIEWS:
        raise ValueError(f"min_shared_views must be 1 to {MAX_MIN_SHARED_VIEWS}, got {min_shared_views}")
    edges = [p for p, n in shared_views.items() if n >= min_shared_views]
    comp = _components(len(cameras), edges)
    n_parts = len(set(comp))
    if n_parts == 1:
        weakest = min((n for p, n in shared_views.items() if p in edges), default=0)
        return GateResult(
            "rig-connected",
            True,
            float(weakest),
            float(min_shared_views),
            f"every camera is linked by pairs with >= {min_shared_views} shared views",
        )
    across = [(n, p) for p, n in shared_views.items() if comp[p[0]] != comp[p[1]]]
    n, (a, b) = max(across, key=lambda x: (x[0], -x[1][0], -x[1][1]))
    pair = f"{cameras[a]}-{cameras[b]}"
    return GateResult(
        "rig-connected",
        False,
        float(n),
        float(min_shared_views),
        f"the rig falls apart into {n_parts} groups; pair {pair} shares {n} view(s) (needs "
        f"{min_shared_views})",
        reason="rig-not-connected",
        hint=f"capture at least {min_shared_views - n} more frame(s) with the board seen by both "
        f"{cameras[a]} "
        f"and {cameras[b]}",
        detail={"pair": pair, "shared_views": n},
    )
