"""Two `handeye --rig` writers on the same base rig version: the second is refused (exit 2, naming the
newer version) instead of silently dropping the first one's edge."""

from __future__ import annotations

from pathlib import Path

import pytest

from calibctl.errors import StaleActiveVersionError
from calibctl.workflows.handeye import rig_handeye
from calibctl.workflows.rig import rig_lint
from tests.store.rig_documents import RIG
from tests.workflows.handeye.test_rig_handeye import OTHER, ROOT, _result, settings  # noqa: F401 (fixture)


def test_a_second_writer_on_a_stale_base_is_refused_and_keeps_the_first_edge(
    settings,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
):
    flange = _result(tmp_path, settings, "flange", ROOT)
    imu = _result(tmp_path, settings, "imu", OTHER)
    real_with_handeye = rig_handeye.with_handeye

    def interleaved(base, result, versions, s):  # type: ignore[no-untyped-def]
        # writer A has read the base (RIG@1); writer B stores its edge before A writes
        if result is flange:
            assert base.version == 1
            rig_handeye.store_handeye(settings, RIG, imu)
        return real_with_handeye(base, result, versions, s)

    monkeypatch.setattr(rig_handeye, "with_handeye", interleaved)
    with pytest.raises(StaleActiveVersionError) as info:
        rig_handeye.store_handeye(settings, RIG, flange)
    monkeypatch.undo()
    assert info.value.exit_code == 2
    assert info.value.message == (
        f"rig {RIG}: the active version changed underneath this write (it was built on "
        f"{RIG}@1, the active version is now {RIG}@2); nothing stored"
    )
    assert f"calibctl rig history {RIG}" in (info.value.hint or "")
    cals, active, _ = rig_lint.history(settings, RIG)
    assert [c.version for c in cals] == [1, 2] and active == 2  # nothing written by A, B's edge active
    # run again: A builds on RIG@2 and both edges are in the tree
    again = rig_handeye.store_handeye(settings, RIG, flange).calibration
    assert again.version == 3
    assert {(e.parent, e.child) for e in again.edges if e.source == "hand-eye"} == {
        ("flange", ROOT),
        ("imu", OTHER),
    }
