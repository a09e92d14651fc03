"""A real rig flow on a rendered 75 mm pair: a hand-eye edge added to the solved rig survives a re-solve of
the rig (carried forward), the whole tree lints clean, and the tf export chains flange -> CAM0 -> CAM1."""

from __future__ import annotations

import numpy as np
import yaml

from calibctl.workflows import rig_handeye, rig_lint, rigs
from calibctl.workflows.handeye import SynthRequest, run_handeye, run_synth_motions
from tests.workflows.test_rig_store_flow import _sources, rig2, settings  # noqa: F401 (fixtures)


def test_a_hand_eye_edge_is_carried_through_a_rig_re_solve(settings, rig2, tmp_path):  # noqa: F811
    rigs.add_rig(settings, "R1", ["CAM0", "CAM1"], None, [], frames=["flange"])
    rigs.capture_rig(settings, "R1", _sources(rig2), "A17")
    rigs.solve_rig_stored(settings, "R1")
    csv = tmp_path / "arm.csv"
    run_synth_motions(SynthRequest(csv))
    result = run_handeye(settings, csv, "flange", "CAM0").result
    assert rig_handeye.store_handeye(settings, "R1", result).calibration.version == 2
    again = rigs.solve_rig_stored(settings, "R1").calibration
    assert again.version == 3 and again.status == "accepted" and again.handeye == [result]
    assert [(e.parent, e.child, e.source) for e in again.edges] == [("CAM0", "CAM1", "rig-solve"),
                                                                     ("flange", "CAM0", "hand-eye")]
    assert not rig_lint.lint_rig(settings, "R1").failed
    tf = yaml.safe_load("\n".join(x for x in rig_lint.export(settings, "R1", "tf", None, force=False).splitlines()
                                  if not x.startswith("#")))["transforms"]
    assert [(t["header"]["frame_id"], t["child_frame_id"]) for t in tf] == [("flange", "CAM0"), ("CAM0", "CAM1")]
    assert np.isclose(tf[0]["transform"]["translation"]["z"], result.transform.translation_m[2])
