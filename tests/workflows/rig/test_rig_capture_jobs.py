"""`calibctl rig capture --jobs N` (and `capture --rig`, `rig solve-folders`): every member is detected on N
workers, and the stored sessions are the same at jobs 1, 2 and 4, on threads and on the process pool:
the same outcome (status, reason, hash) for every image, bit-identical corners, the same gates, frames
and verdict."""

from __future__ import annotations

import inspect
import json

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.core.capture import image_outcomes, worker_pool
from calibctl.errors import NotFoundError
from calibctl.store.repository import Store
from tests.workflows.rig.test_rig_store_flow import store_members
from tests.workflows.rig_folders_data import rendered_rig, rig_sources

RUNNER = CliRunner()
# the parts of a session that are the same whoever runs it, whenever (ids and times are not)
SESSION_KEYS = ("outcomes", "views", "gates", "status", "image_size")
RIG_KEYS = ("frames", "unmatched", "shared_views", "gates", "status")


@pytest.fixture(scope="module")
def rig2(tmp_path_factory):
    return rendered_rig(tmp_path_factory)


def _store(path, rig2) -> str:
    url = store_members(f"sqlite:///{path}", rig2)
    assert (
        RUNNER.invoke(
            app, ["--db", url, "rig", "add", "R1", "--camera", "CAM0", "--camera", "CAM1"]
        ).exit_code
        == 0
    )
    return url


@pytest.fixture
def workers_seen(monkeypatch) -> list[int | None]:
    """The ``workers`` each member's detection was given (the real detection still runs)."""
    seen: list[int | None] = []
    real = image_outcomes.classify_files

    def spy(*args, **kwargs):
        seen.append(inspect.signature(real).bind(*args, **kwargs).arguments.get("workers"))
        return real(*args, **kwargs)

    monkeypatch.setattr(image_outcomes, "classify_files", spy)
    return seen


def _rig_capture(url: str, rig2, *extra: str) -> dict:
    r = RUNNER.invoke(
        app,
        ["--db", url, "--json", "rig", "capture", "R1", "--board", "A17", *rig_sources(rig2), *extra],
    )
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    return {
        "rig": {k: doc["rig_session"][k] for k in RIG_KEYS},
        "cameras": {c: {k: s[k] for k in SESSION_KEYS} for c, s in doc["camera_sessions"].items()},
    }


def test_rig_capture_stores_the_same_sessions_at_jobs_1_2_and_4(tmp_path, rig2, workers_seen, monkeypatch):
    runs = {
        f"jobs {jobs}": _rig_capture(_store(tmp_path / f"j{jobs}.db", rig2), rig2, "--jobs", str(jobs))
        for jobs in (1, 2, 4)
    }
    assert workers_seen == [1, 1, 2, 2, 4, 4]  # each member, at the count asked for
    # 8 images per member run on threads; the warm pool's processes give the same sessions too
    monkeypatch.setattr(image_outcomes.worker_pool, "is_warm", lambda workers: True)
    try:
        runs["jobs 2, processes"] = _rig_capture(_store(tmp_path / "p2.db", rig2), rig2, "--jobs", "2")
    finally:
        worker_pool.shutdown_pool()
    first = runs.pop("jobs 1")
    assert first["rig"]["status"] == "accepted" and len(first["rig"]["frames"]) == 8
    assert all(len(s["views"]) >= 6 for s in first["cameras"].values())
    for name, run in runs.items():
        assert run == first, name  # floats compared exactly: the corners are bit-identical


def test_capture_rig_and_solve_folders_take_jobs(tmp_path, rig2, workers_seen):
    url = _store(tmp_path / "c.db", rig2)
    r = RUNNER.invoke(
        app,
        ["--db", url, "capture", "--rig", "R1", "--board", "A17", *rig_sources(rig2), "--jobs", "2"],
    )
    assert r.exit_code == 0, r.output
    grid = ["--cols", "9", "--rows", "6", "--square-mm", "25"]
    r = RUNNER.invoke(app, ["rig", "solve-folders", *rig_sources(rig2), *grid, "--jobs", "3"])
    assert r.exit_code in (0, 1), r.output  # the verdict is not this test's business; the detection is
    assert workers_seen == [2, 2, 3, 3]


def test_rig_capture_refuses_jobs_below_one_and_stores_nothing(tmp_path, rig2, monkeypatch):
    url = _store(tmp_path / "c.db", rig2)
    args = ["--db", url, "rig", "capture", "R1", "--board", "A17", *rig_sources(rig2)]
    zero = RUNNER.invoke(app, [*args, "--jobs", "0"])
    assert zero.exit_code == 2 and "--jobs" in zero.output
    monkeypatch.setenv("CALIBCTL_JOBS", "0")
    env = RUNNER.invoke(app, args)
    assert env.exit_code == 2 and "CALIBCTL_JOBS must be a whole number of 1 or more, got '0'" in env.output
    with Store.open(url) as store:
        assert store.list_sessions() == []
        with pytest.raises(NotFoundError):
            store.get_rig_session("R1")
