"""`rig rollback` is compare-and-set like the cameras' `rollback`: a rollback decided on an active rig
version that another writer has moved since (a solve, a hand-eye edge, another rollback) is refused with
exit 2 naming the newer version, and nothing is written."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.config import load_settings
from calibctl.errors import StaleActiveVersionError, UsageError
from calibctl.store.repository import Store
from calibctl.workflows.rig import rig_lint
from tests.store.rig_documents import RIG, rig_calibration, rig_definition

WHO = {"actor": "qa", "station": "st1"}


@pytest.fixture
def three_versions(db_url: str) -> str:
    """RIG v1, v2, v3 accepted, each activated when stored (v3 active)."""
    with Store.open(db_url) as store:
        store.add_rig(rig_definition())
        for baseline_m in (0.075, 0.0751, 0.0752):
            store.add_rig_calibration(
                rig_calibration(baseline_m=baseline_m), activate=True, reason="rig solve", **WHO
            )
    return db_url


def _events(url: str) -> list[tuple[int, str]]:
    with Store.open(url) as store:
        return [(e.version, e.kind) for e in store.rig_events(RIG)]


def test_a_rig_rollback_decided_before_a_solve_is_refused_and_the_solve_stays_active(
    three_versions: str, monkeypatch: pytest.MonkeyPatch
):
    settings = load_settings(db=three_versions, env={})
    real_active = Store.active_rig_version

    def interleaved(store: Store, rig: str) -> int | None:
        seen = real_active(store, rig)  # the technician's rollback has read v3 ...
        with Store.open(
            three_versions
        ) as other:  # ... and a station stores and activates v4 before it writes
            other.add_rig_calibration(
                rig_calibration(baseline_m=0.0753), activate=True, reason="re-solve", **WHO
            )
        return seen

    monkeypatch.setattr(Store, "active_rig_version", interleaved)
    with pytest.raises(StaleActiveVersionError) as info:
        rig_lint.rollback(settings, RIG, 1, "v3 drifted")
    monkeypatch.undo()
    assert info.value.exit_code == 2
    assert info.value.message == (
        f"rig {RIG}: the active version changed underneath this rollback (it saw v3, "
        "it is now v4); nothing rolled back to v1"
    )
    assert f"calibctl rig history {RIG}" in (info.value.hint or "")
    assert _events(three_versions) == [(1, "activate"), (2, "activate"), (3, "activate"), (4, "activate")]
    event = rig_lint.rollback(settings, RIG, 1, "v3 and v4 drifted")  # decided again on v4: done
    assert (event.version, event.previous_version, event.kind) == (1, 4, "rollback")


def test_two_technicians_rolling_back_on_the_same_view_one_is_refused(three_versions: str):
    with Store.open(three_versions) as first, Store.open(three_versions) as second:
        seen = first.active_rig_version(RIG)
        assert second.active_rig_version(RIG) == seen == 3
        first.rollback_rig(RIG, 2, reason="v3 drifted", expected_active=seen, **WHO)
        with pytest.raises(
            StaleActiveVersionError, match=r"it saw v3, it is now v2\); nothing rolled back to v1"
        ):
            second.rollback_rig(RIG, 1, reason="v3 drifted", expected_active=seen, **WHO)
        with pytest.raises(StaleActiveVersionError, match="it saw no active version, it is now v2"):
            second.rollback_rig(RIG, 1, reason="r", expected_active=None, **WHO)
    assert _events(three_versions)[-1] == (2, "rollback") and len(_events(three_versions)) == 4


def test_the_compare_comes_after_the_version_checks(three_versions: str):
    """An unknown or rejected target is named as such even on a stale view (the stale view is not the
    problem)."""
    with Store.open(three_versions) as store:
        store.add_rig_calibration(
            rig_calibration(status="rejected"), activate=False, reason="rig solve", **WHO
        )
        with pytest.raises(
            UsageError,
            match=rf"rig {RIG}@4 is rejected and can never become active; "
            "accepted versions: 1, 2, 3",
        ):
            store.rollback_rig(RIG, 4, reason="r", expected_active=1, **WHO)
        with pytest.raises(Exception, match=rf"rig {RIG} has no version 9; versions: 1, 2, 3, 4"):
            store.rollback_rig(RIG, 9, reason="r", expected_active=1, **WHO)
        with pytest.raises(
            StaleActiveVersionError, match="it saw v1, it is now v3"
        ):  # stale, though 3 is active
            store.rollback_rig(RIG, 3, reason="r", expected_active=1, **WHO)
        assert store.rollback_rig(RIG, 3, reason="r", expected_active=3, **WHO) is None  # already active


def _cli(url: str, *args: str):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(app, ["--db", url, "rig", "rollback", RIG, *args], terminal_width=120)


def test_rig_rollback_expect_active_on_the_command_line(three_versions: str):
    stale = _cli(three_versions, "--to", "1", "--reason", "bent mount", "--expect-active", "2")
    assert stale.exit_code == 2 and "Traceback" not in stale.output
    assert (
        f"rig {RIG}: the active version changed underneath this rollback (it saw v2, it is now v3); "
        "nothing rolled back to v1"
    ) in " ".join(stale.stderr.split())
    assert _events(three_versions)[-1] == (3, "activate")
    done = _cli(three_versions, "--to", "1", "--reason", "bent mount", "--expect-active", "3")
    assert done.exit_code == 0 and "active version 3 -> 1" in done.stdout
    assert _events(three_versions)[-1] == (1, "rollback")


def test_rig_rollback_to_the_active_version_is_a_success_that_writes_nothing(three_versions: str):
    for extra in ((), ("--expect-active", "3")):
        done = _cli(three_versions, "--to", "3", "--reason", "make sure", *extra)
        assert done.exit_code == 0, done.output
        assert f"rig {RIG}: version 3 is already the active version; nothing written" in done.stdout
    doc = CliRunner().invoke(
        app, ["--db", three_versions, "--json", "rig", "rollback", RIG, "--to", "3", "--reason", "r"]
    )
    assert doc.exit_code == 0 and json.loads(doc.stdout) == {"rig": RIG, "version": 3, "already_active": True}
    assert _events(three_versions) == [(1, "activate"), (2, "activate"), (3, "activate")]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--to", "1", "--reason", "bad\x1b[2Jreason"], "control character"),
        (["--to", "99999999999", "--reason", "r"], "out of range"),
        (["--to", "1", "--reason", "  "], "a rollback needs a reason"),
    ],
)
def test_rig_rollback_refuses_bad_requests_before_writing(three_versions: str, args: list[str], message: str):
    result = _cli(three_versions, *args)
    assert result.exit_code == 2 and message in result.stderr and "Traceback" not in result.output
    assert _events(three_versions)[-1] == (3, "activate")
