"""The station against PostgreSQL with the network to it cut and restored inside the test (a TCP proxy in
front
of the suite's server, so the shared server itself never stops): units during the outage are stored after it,
in order, each signed with the station's key, none lost or doubled."""

from __future__ import annotations

import threading
import urllib.parse
from pathlib import Path

import pytest

from calibctl.config import load_settings
from calibctl.signing import TrustedKeys, create_key
from calibctl.store.repository import Store
from calibctl.workflows.station.station import PASS, QUEUED, SYNCED, StationRequest, UnitResult, run_station
from calibctl.workflows.station.sync import open_spool, sync
from tests.workflows.station.spool_setup import TcpProxy, central_store, unit_folders

pytestmark = pytest.mark.postgres


@pytest.fixture
def proxied(pg_url: str, tmp_path_factory: pytest.TempPathFactory, tmp_path: Path):
    """(proxy, the store's URL through it, the unit folders): a fresh database with board A17 behind a
    proxy."""
    server = urllib.parse.urlsplit(pg_url)
    proxy = TcpProxy((server.hostname or "127.0.0.1", server.port or 5432))
    proxy.restore()
    through_proxy = urllib.parse.urlunsplit(
        server._replace(netloc=f"{server.username}@127.0.0.1:{proxy.port}")
    )
    central_store(through_proxy)
    return proxy, through_proxy, unit_folders(tmp_path_factory, tmp_path)


def test_units_while_postgresql_is_cut_off_are_stored_signed_and_in_order_once_it_is_back(
    pg_url: str, proxied, tmp_path: Path
) -> None:
    proxy, through_proxy, shots = proxied
    signer = create_key(tmp_path / "station.key")
    settings = load_settings(
        db=through_proxy, station="line-3", operator="op-ana", env={}, jobs=2
    ).model_copy(update={"signing_key": str(tmp_path / "station.key")})
    request = StationRequest("A17", f"{shots}/{{serial}}", spool=tmp_path / "spool.sqlite")

    def run(*serials: str) -> list[UnitResult]:
        lines: list[UnitResult] = []
        run_station(settings, request, serials, lines.append)
        return lines

    assert [(r.serial, r.status, r.version) for r in run("CAM-1")] == [("CAM-1", PASS, 1)]
    proxy.cut()
    outage = run("CAM-2", "CAM-3") + run("CAM-2")  # CAM-2 calibrated twice while the store is away
    assert [(r.serial, r.status, r.spool_record) for r in outage] == [
        ("CAM-2", QUEUED, 1),
        ("CAM-3", QUEUED, 2),
        ("CAM-2", QUEUED, 3),
    ]
    assert "cannot connect to the database" in outage[0].message
    proxy.restore()
    after = run("CAM-1")
    assert [(r.serial, r.status, r.version) for r in after] == [
        ("CAM-2", SYNCED, 1),
        ("CAM-3", SYNCED, 1),
        ("CAM-2", SYNCED, 2),
        ("CAM-1", PASS, 2),
    ]
    proxy.cut()
    with Store.open(pg_url) as store:
        assert [a.version for a in store.list_artifacts("CAM-2")] == [1, 2]
        assert [a.provenance.session_id for a in store.list_artifacts("CAM-2")] == [
            outage[0].session_id,
            outage[2].session_id,
        ]
        assert len(store.list_sessions()) == 5
        assert store.active_version("CAM-2") == 2
        for serial in ("CAM-2", "CAM-3"):
            for art in store.list_artifacts(serial):
                assert art.signature is not None and art.signature.key_id == signer.key_id
        assert store.verify(TrustedKeys.load(None, signer)).problems == []


def test_two_stations_syncing_their_spools_at_once_get_consecutive_versions_of_one_serial(
    pg_url: str, proxied, tmp_path: Path
) -> None:
    proxy, through_proxy, shots = proxied
    stations = {
        name: load_settings(db=through_proxy, station=name, operator="op", env={}, jobs=1)
        for name in ("line-3", "line-4")
    }
    for (
        name,
        settings,
    ) in stations.items():  # each station calibrates CAM-1 online once: the board is remembered
        run_station(
            settings,
            StationRequest("A17", f"{shots}/{{serial}}", spool=tmp_path / f"{name}.sqlite"),
            ["CAM-1"],
            lambda r: None,
        )
    proxy.cut()
    for name, settings in stations.items():
        for _ in range(2):  # CAM-2 twice at each station, in two runs, while the store is away
            lines: list[UnitResult] = []
            run_station(
                settings,
                StationRequest("A17", f"{shots}/{{serial}}", spool=tmp_path / f"{name}.sqlite"),
                ["CAM-2"],
                lines.append,
            )
            assert [r.status for r in lines] == [QUEUED]
    proxy.restore()
    reports = {}

    def sync_station(name: str) -> None:
        settings = stations[name]
        with open_spool(settings, tmp_path / f"{name}.sqlite") as spool:
            reports[name] = sync(settings, spool)

    threads = [threading.Thread(target=sync_station, args=(name,)) for name in stations]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for name in stations:
        assert reports[name].error is None and reports[name].left == 0
        mine = [u.version for u in reports[name].synced]
        assert len(mine) == 2 and mine == sorted(mine)  # each station's two units in its own order
    proxy.cut()
    with Store.open(pg_url) as store:
        cam2 = store.list_artifacts("CAM-2")
        assert [a.version for a in cam2] == [1, 2, 3, 4]  # none skipped, none twice
        assert sorted(a.provenance.station for a in cam2) == ["line-3", "line-3", "line-4", "line-4"]
        assert len(store.list_sessions()) == 6
