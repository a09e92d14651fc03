"""A real rig flow on a rendered 75 mm pair: a hand-eye edge added to the solved rig survives a re-solve of
the rig (carried forward), the whole tree lints clean, and the tf export chains flange -> CAM0 -> CAM1."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from calibctl.workflows.handeye import rig_handeye
from calibctl.workflows.handeye.handeye import SynthRequest, run_handeye, run_synth_motions
from calibctl.workflows.rig import rig_export, rig_lint, rigs
from tests.workflows.rig.test_rig_store_flow import _sources, rig2, settings  # noqa: F401 (fixtures)


def _solved_and_arm(settings, rig2, tmp_path):  # type: ignore[no-untyped-def]
    """R1 solved once (R1@1, no hand-eye edge) and an accepted flange -> CAM0 hand-eye result, not stored."""
    rigs.add_rig(settings, "R1", ["CAM0", "CAM1"], None, [], frames=["flange"])
    rigs.capture_rig(settings, "R1", _sources(rig2), "A17")
    rigs.solve_rig_stored(settings, "R1")
    csv = tmp_path / "arm.csv"
    run_synth_motions(SynthRequest(csv))
    return run_handeye(settings, csv, "flange", "CAM0").result


def test_a_hand_eye_edge_is_carried_through_a_rig_re_solve(settings, rig2, tmp_path):
    result = _solved_and_arm(settings, rig2, tmp_path)
    assert rig_handeye.store_handeye(settings, "R1", result).calibration.version == 2
    again = rigs.solve_rig_stored(settings, "R1").calibration
    assert again.version == 3 and again.status == "accepted" and again.handeye == [result]
    assert [(e.parent, e.child, e.source) for e in again.edges] == [
        ("CAM0", "CAM1", "rig-solve"),
        ("flange", "CAM0", "hand-eye"),
    ]
    assert not rig_lint.lint_rig(settings, "R1").failed
    tf = yaml.safe_load(
        "\n".join(
            x
            for x in rig_export.export(settings, "R1", "tf", None, force=False).splitlines()
            if not x.startswith("#")
        )
    )["transforms"]
    assert [(t["header"]["frame_id"], t["child_frame_id"]) for t in tf] == [
        ("flange", "cam0_optical_frame"),
        ("cam0_optical_frame", "cam1_optical_frame"),
    ]
    assert np.isclose(tf[0]["transform"]["translation"]["z"], result.transform.translation_m[2])


def test_a_hand_eye_edge_stored_during_a_re_solve_is_not_dropped(settings, rig2, tmp_path, monkeypatch):
    """The re-solve read RIG@1 (no hand-eye edge) to carry edges from; a hand-eye edge lands as RIG@2
    before it writes: the re-solve is refused (exit 2) instead of storing a tree without that edge."""
    from calibctl.errors import StaleActiveVersionError

    result = _solved_and_arm(settings, rig2, tmp_path)
    carry = rigs._with_carried_handeye

    def interleaved(cal, store):  # type: ignore[no-untyped-def]
        out = carry(cal, store)
        rig_handeye.store_handeye(settings, "R1", result)  # another station, between read and write
        return out

    monkeypatch.setattr(rigs, "_with_carried_handeye", interleaved)
    with pytest.raises(
        StaleActiveVersionError, match="it was built on R1@1, the active version is now R1@2"
    ) as info:
        rigs.solve_rig_stored(settings, "R1")
    assert info.value.exit_code == 2
    monkeypatch.undo()
    cals, active, _ = rig_lint.history(settings, "R1")
    assert [c.version for c in cals] == [1, 2] and active == 2 and cals[1].handeye == [result]
