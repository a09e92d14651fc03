"""The station against PostgreSQL with the network to it cut and restored inside the test (a TCP proxy in front
of the suite's server, so the shared server itself never stops): units during the outage are stored after it,
in order, each signed with the station's key, none lost or doubled."""

from __future__ import annotations

import urllib.parse
from pathlib import Path

import pytest

from calibctl.config import load_settings
from calibctl.signing import TrustedKeys, create_key
from calibctl.store.repository import Store
from calibctl.workflows.station.station import PASS, QUEUED, SYNCED, StationRequest, UnitResult, run_station
from tests.workflows.station.spool_setup import TcpProxy, central_store, unit_folders

pytestmark = pytest.mark.postgres


def test_units_while_postgresql_is_cut_off_are_stored_signed_and_in_order_once_it_is_back(
        pg_url: str, tmp_path_factory: pytest.TempPathFactory, tmp_path: Path) -> None:
    server = urllib.parse.urlsplit(pg_url)
    proxy = TcpProxy((server.hostname or "127.0.0.1", server.port or 5432))
    proxy.restore()
    through_proxy = urllib.parse.urlunsplit(server._replace(netloc=f"{server.username}@127.0.0.1:{proxy.port}"))
    central_store(through_proxy)
    signer = create_key(tmp_path / "station.key")
    settings = load_settings(db=through_proxy, station="line-3", operator="op-ana", env={}, jobs=2).model_copy(
        update={"signing_key": str(tmp_path / "station.key")})
    shots = unit_folders(tmp_path_factory, tmp_path)
    request = StationRequest("A17", f"{shots}/{{serial}}", spool=tmp_path / "spool.sqlite")

    def run(*serials: str) -> list[UnitResult]:
        lines: list[UnitResult] = []
        run_station(settings, request, serials, lines.append)
        return lines

    assert [(r.serial, r.status, r.version) for r in run("CAM-1")] == [("CAM-1", PASS, 1)]
    proxy.cut()
    outage = run("CAM-2", "CAM-3") + run("CAM-2")  # CAM-2 calibrated twice while the store is away
    assert [(r.serial, r.status, r.spool_record) for r in outage] == [
        ("CAM-2", QUEUED, 1), ("CAM-3", QUEUED, 2), ("CAM-2", QUEUED, 3)]
    assert "cannot connect to the database" in outage[0].message
    proxy.restore()
    after = run("CAM-1")
    assert [(r.serial, r.status, r.version) for r in after] == [
        ("CAM-2", SYNCED, 1), ("CAM-3", SYNCED, 1), ("CAM-2", SYNCED, 2), ("CAM-1", PASS, 2)]
    proxy.cut()
    with Store.open(pg_url) as store:
        assert [a.version for a in store.list_artifacts("CAM-2")] == [1, 2]
        assert [a.provenance.session_id for a in store.list_artifacts("CAM-2")] == [
            outage[0].session_id, outage[2].session_id]
        assert len(store.list_sessions()) == 5
        assert store.active_version("CAM-2") == 2
        for serial in ("CAM-2", "CAM-3"):
            for art in store.list_artifacts(serial):
                assert art.signature is not None and art.signature.key_id == signer.key_id
        assert store.verify(TrustedKeys.load(None, signer)).problems == []
