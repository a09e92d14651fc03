"""Scans from files, pairing with images, and the acfr set: segmentation against the authors' crops."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calibctl.core.lidar.segment import StationBox, segment_board
from calibctl.errors import InputError
from calibctl.workflows.lidar.scans import pair, read_scan
from tests.datasets import ACFR, require_acfr

ACFR_BOX = StationBox((1.0, -2.2, -0.8), (3.6, 1.6, 0.6))


def _touch(folder: Path, *names: str) -> None:
    folder.mkdir(exist_ok=True)
    for n in names:
        (folder / n).write_bytes(b"x")


def test_pairing_by_last_number_reports_the_unpaired(tmp_path: Path) -> None:
    _touch(tmp_path / "img", "pose1.png", "pose2.png", "pose9.png")
    _touch(tmp_path / "pcd", "pose1_full.pcd", "pose2_full.pcd", "pose5_full.pcd", "notes.txt")
    p = pair(tmp_path / "img", tmp_path / "pcd", "*_full.pcd")
    assert [k for k, _, _ in p.pairs] == [1, 2]
    why = {path.name: reason for path, reason in p.unpaired}
    assert why == {"pose9.png": "no scan with this frame number", "pose5_full.pcd": "no image with this frame number"}


def test_two_scans_with_one_frame_number_are_an_error(tmp_path: Path) -> None:
    _touch(tmp_path / "img", "pose1.png")
    _touch(tmp_path / "pcd", "pose1_full.pcd", "pose1_target.pcd")
    with pytest.raises(InputError, match="two scans with frame number 1") as err:
        pair(tmp_path / "img", tmp_path / "pcd")
    assert err.value.exit_code == 2 and "pose1_full.pcd" in err.value.message


def test_a_scan_in_millimetres_is_refused_naming_the_unit(tmp_path: Path) -> None:
    path = tmp_path / "scan1.txt"
    rng = np.random.default_rng(0)
    np.savetxt(path, rng.uniform(1000.0, 3000.0, (50, 3)))
    with pytest.raises(InputError, match="millimetres") as err:
        read_scan(path)
    assert "--scan-units mm" in (err.value.hint or "")
    assert read_scan(path, 1e-3).points_m.max() < 3.1


def test_acfr_segmentation_matches_the_authors_crops() -> None:
    """Every acfr sweep, station box only: our board points are the authors' (precision), nearly all of
    theirs are ours (recall; theirs keep points >3 cm off the plane, ours do not)."""
    require_acfr()
    outcomes = {}
    for full in sorted((ACFR / "pcd").glob("*_full.pcd")):
        found = segment_board(read_scan(full), ACFR_BOX, (0.61, 0.85))
        outcomes[full.name] = found.outcome
        theirs = {tuple(np.round(p, 4)) for p in read_scan(Path(str(full).replace("_full", "_target"))).points_m}
        ours = {tuple(np.round(p, 4)) for p in found.points_m}
        common = len(ours & theirs)
        assert common / len(ours) > 0.99, full.name
        assert common / len(theirs) > 0.85, full.name
    assert len(outcomes) == 20
    assert sum(o == "accepted" for o in outcomes.values()) >= 18
