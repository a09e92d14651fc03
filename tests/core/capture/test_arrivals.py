"""Pictures landing in a folder: the completeness rule (times given explicitly), and early detections that
give ``classify_files`` exactly its own outcomes, at one job and on the warm process pool."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture.arrivals import Arrivals, EarlyDetections, signature
from calibctl.core.capture.image_circle import sized_half
from calibctl.core.capture.image_outcomes import classify_files, list_images
from calibctl.core.synth.pinhole import Photometry, PinholeCamera, render_view
from calibctl.core.synth.scenes import scenario_poses

BOARD = BoardSpec.chessboard(9, 6, 0.025)


@pytest.fixture(scope="module")
def renders(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    folder = tmp_path_factory.mktemp("renders")
    camera = PinholeCamera.seed_reference()
    rng = np.random.default_rng(5)
    for i, T in enumerate(scenario_poses("good", camera, BOARD, 4, rng)):
        assert cv2.imwrite(
            str(folder / f"v{i:02d}.png"), render_view(camera, BOARD, T, rng, Photometry.random(rng))
        )
    (folder / "w-broken.png").write_bytes(b"not a png")
    return list_images(folder)


def names(found: list[tuple[Path, object]]) -> list[str]:
    return [p.name for p, _ in found]


def test_a_renamed_picture_is_complete_when_seen_and_temporary_names_are_never_listed(tmp_path: Path) -> None:
    arrivals = Arrivals(tmp_path / "unit", settle_s=0.0)
    assert arrivals.poll(0.0) == [] and arrivals.last_in_ns() is None  # no folder yet
    (tmp_path / "unit").mkdir()
    (tmp_path / "unit" / "a.png.part").write_bytes(b"half")  # the app's temporary name
    (tmp_path / "unit" / "notes.txt").write_text("not a picture")
    assert arrivals.poll(0.1) == [] and arrivals.pending == 0
    os.replace(tmp_path / "unit" / "a.png.part", tmp_path / "unit" / "a.png")
    assert names(arrivals.poll(0.2)) == ["a.png"] and arrivals.poll(0.3) == []
    assert (arrivals.complete, arrivals.last_in_ns()) == (1, os.stat(tmp_path / "unit" / "a.png").st_ctime_ns)


def test_a_picture_written_in_place_is_complete_once_unchanged_for_the_settle_time(tmp_path: Path) -> None:
    arrivals = Arrivals(tmp_path, settle_s=0.25)
    shot = tmp_path / "b.png"
    with shot.open("wb") as writing:
        writing.write(b"x" * 100)
        writing.flush()
        assert arrivals.poll(0.0) == [] and arrivals.pending == 1
        assert arrivals.poll(0.2) == []
        writing.write(b"y" * 100)  # more bytes: its settle time starts again
        writing.flush()
        assert arrivals.poll(0.3) == [] and arrivals.poll(0.5) == []
    assert names(arrivals.poll(0.55)) == ["b.png"] and arrivals.pending == 0
    shot.write_bytes(b"z" * 50)  # written again after it was complete: a new arrival, judged again
    assert arrivals.poll(0.6) == [] and (arrivals.complete, arrivals.pending) == (0, 1)
    assert names(arrivals.poll(0.9)) == ["b.png"]
    shot.unlink()
    assert arrivals.poll(1.0) == [] and (arrivals.complete, arrivals.pending) == (0, 0)


@pytest.mark.parametrize("workers", [1, 2])
def test_early_detections_are_the_outcomes_classify_files_gives(renders: list[Path], workers: int) -> None:
    early = EarlyDetections(BOARD, workers, summarize=sized_half)
    for path in renders:
        early.start(path, signature(path))  # type: ignore[arg-type]
    for future in early.futures():
        future.result()
    batch_halves: list[object] = []
    batch = classify_files(
        renders, BOARD, workers=workers, summarize=sized_half, on_summary=batch_halves.append
    )
    calls: list[tuple[int, int, str]] = []
    halves: list[object] = []
    known = early.for_spec(BOARD, sized_half)
    assert known is not None
    reused = classify_files(
        renders,
        BOARD,
        workers=workers,
        summarize=sized_half,
        on_summary=halves.append,
        known=known,
        progress=lambda done, total, o: calls.append((done, total, o.name)),
    )
    assert [(o.name, o.status, o.reason, o.sha256, o.image_size) for o in reused] == [
        (o.name, o.status, o.reason, o.sha256, o.image_size) for o in batch
    ]
    for a, b in zip(reused, batch, strict=True):
        assert (a.corners_px is None) == (b.corners_px is None)
        if a.corners_px is not None:
            assert np.array_equal(a.corners_px, b.corners_px) and np.array_equal(a.corner_ids, b.corner_ids)
    assert [d for d, _, _ in calls] == list(range(1, len(renders) + 1))
    assert sorted(np.asarray(h[1]).tobytes() for h in halves) == sorted(
        np.asarray(h[1]).tobytes() for h in batch_halves
    )  # type: ignore[index]


def test_a_file_changed_since_its_early_detection_is_detected_again(
    renders: list[Path], tmp_path: Path
) -> None:
    shot = tmp_path / "v.png"
    shutil.copyfile(renders[0], shot)
    early = EarlyDetections(BOARD, 1, summarize=sized_half)
    early.start(shot, signature(shot))  # type: ignore[arg-type]
    assert early.known(shot) is not None
    shutil.copyfile(renders[-1], shot)  # the broken file, under the same name
    assert early.known(shot) is None
    [again] = classify_files([shot], BOARD, workers=1, summarize=sized_half, known=early.known)
    assert again.status == "unreadable"
    assert early.for_spec(BoardSpec.chessboard(7, 5, 0.025), sized_half) is None  # another board: all again
    assert early.for_spec(BOARD, None) is None
