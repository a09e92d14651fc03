"""Rig definitions are chained (revision 0008): the design baselines and tolerances rig lint checks
every version against, the members and the root every later rig solve starts from. Each change someone
with write access makes is named by `db verify` (SQLite with its triggers dropped; PostgreSQL with
triggers switched off), and a definition changed with its payload hash recomputed is refused on read."""

from __future__ import annotations

import json

import pytest

from calibctl.artifacts.rig import RigDefinition
from calibctl.errors import UnverifiedRecord
from calibctl.signing import TrustedKeys, create_key
from calibctl.store import codec
from calibctl.store.engine import make_engine
from calibctl.store.repository import Store
from tests.store.rig_documents import RIG, rig_calibration, rig_definition
from tests.store.tamper import rechain, run_underneath
from tests.store.test_chain_tamper import _select, problems_of

WHO = {"actor": "qa", "station": "st1", "reason": "rig solve"}
OTHER = "STEREO-2"


@pytest.fixture
def rigs(db_url: str) -> str:
    """STEREO-1 (with an active version) and STEREO-2 registered, in that order."""
    with Store.open(db_url) as store:
        store.add_rig(rig_definition())
        store.add_rig_calibration(rig_calibration(), activate=True, **WHO)
        store.add_rig(rig_definition(OTHER))
        assert store.verify().problems == []
    return db_url


def _widen_tolerance(url: str, name: str = RIG) -> None:
    """The design tolerance 0.5 mm -> 50 mm and payload_sha256 recomputed, as a careful forger would."""
    (payload,) = _select(url, f"SELECT payload FROM rig_definitions WHERE name = '{name}'")[0]
    doc = json.loads(payload)
    doc["design_baselines"][0]["tolerance_mm"] = 50.0
    forged = codec.canonical_text(RigDefinition.model_validate(doc))
    run_underneath(
        url,
        "UPDATE rig_definitions SET payload = %s, payload_sha256 = %s WHERE name = %s",
        params=(forged, codec.sha256_hex(forged.encode()), name),
    )


def test_definitions_are_one_chain_for_the_store(rigs: str):
    assert _select(rigs, "SELECT name, id, chain_seq FROM rig_definitions ORDER BY id") == [
        (RIG, 1, 1),
        (OTHER, 2, 2),
    ]
    (prev,) = _select(rigs, f"SELECT chain_prev FROM rig_definitions WHERE name = '{OTHER}'")[0]
    assert prev == _select(rigs, f"SELECT chain_hash FROM rig_definitions WHERE name = '{RIG}'")[0][0]


def test_a_widened_tolerance_with_its_hash_recomputed_is_named_and_refused_on_read(rigs: str):
    _widen_tolerance(rigs)
    message = f"rig definition {RIG} was changed after it was written (its chain hash no longer matches)"
    assert problems_of(rigs) == [message]
    with Store.open(rigs) as store, pytest.raises(UnverifiedRecord) as info:
        store.get_rig(RIG)
    assert info.value.message == message and info.value.exit_code == 2
    with Store.open(rigs) as store:
        assert store.get_rig(OTHER).name == OTHER  # the other rig still reads


def test_a_deleted_definition_breaks_the_chain(rigs: str):
    run_underneath(rigs, f"DELETE FROM rig_definitions WHERE name = '{RIG}'")
    assert problems_of(rigs) == [
        f"rig definition {OTHER} is at chain position 2 but 1 was expected: records before it are missing"
    ]


def test_the_last_definition_deleted_is_a_counter_mismatch(rigs: str):
    run_underneath(rigs, f"DELETE FROM rig_definitions WHERE name = '{OTHER}'")
    assert problems_of(rigs) == [
        "the chain counter of rig_definition is 2 but the highest chain_seq stored is 1: "
        "the counter or the records were changed"
    ]


def test_a_definition_inserted_outside_calibctl_is_named(rigs: str):
    (payload, created) = _select(
        rigs, f"SELECT payload, created_at FROM rig_definitions WHERE name = '{OTHER}'"
    )[0]
    forged = payload.replace(OTHER, "STEREO-9")
    run_underneath(
        rigs,
        "INSERT INTO rig_definitions (name, created_at, payload, payload_sha256) VALUES (%s, %s, %s, %s)",
        params=("STEREO-9", created, forged, codec.sha256_hex(forged.encode())),
    )
    assert problems_of(rigs) == [
        "rig definition STEREO-9 has no chain hash: it was inserted outside calibctl"
    ]


def test_0008_chains_the_definitions_stored_before_it(rigs: str):
    from calibctl.store import migrate

    engine = make_engine(rigs)
    try:
        assert migrate.downgrade(engine, "0007_chain_rigs_checks") == (
            "0016_chain_health_reports",
            "0007_chain_rigs_checks",
        )
        assert migrate.upgrade(engine) == ("0007_chain_rigs_checks", "0016_chain_health_reports")
    finally:
        engine.dispose()
    assert _select(rigs, "SELECT name, id, chain_seq FROM rig_definitions ORDER BY id") == [
        (RIG, 1, 1),
        (OTHER, 2, 2),
    ]
    assert problems_of(rigs) == []
    with Store.open(rigs) as store:  # the backfilled counter goes on from there
        store.add_rig(rig_definition("STEREO-3"))
    assert _select(rigs, "SELECT id, chain_seq FROM rig_definitions WHERE name = 'STEREO-3'") == [(3, 3)]
    run_underneath(rigs, "DELETE FROM rig_definitions WHERE name = 'STEREO-3'")
    assert problems_of(rigs) == [
        "the chain counter of rig_definition is 3 but the highest chain_seq stored is 2: "
        "the counter or the records were changed"
    ]


def test_a_rechained_definition_forgery_is_caught_by_the_signature(db_url: str, tmp_path):  # type: ignore[no-untyped-def]
    signer = create_key(tmp_path / "k.pem")
    with Store.open(db_url, signer=signer) as store:
        store.add_rig(rig_definition())
    trusted = TrustedKeys({signer.key_id: signer.public})
    _widen_tolerance(db_url)
    rechain(db_url)
    with Store.open(db_url) as reader:
        assert reader.verify().problems == []  # self-consistent without the key ...
        problems = reader.verify(trusted).problems
    assert len(problems) == 1 and problems[0].startswith(f"rig definition {RIG} has a signature by key")


def test_a_head_kept_elsewhere_catches_a_rechained_definition(rigs: str):
    with Store.open(rigs) as store:
        head = store.verify().head()
    _widen_tolerance(rigs, OTHER)
    rechain(rigs)
    with Store.open(rigs) as store:
        assert store.verify().problems == []
        assert any("rewritten or truncated" in p for p in store.verify(since=head).problems)


def test_a_head_printed_before_0008_checks_the_definitions_in_full(rigs: str):
    from calibctl.store import audit as audit_module

    with Store.open(rigs) as store:
        full = store.verify()
    old = ("artifact", "board", "event", "rig", "rig_event", "check")  # the streams a head named in 0007
    ids = ".".join(str(full.last_ids.get(name, 0)) for name in old)
    digest = audit_module._digest({n: full.heads[n] for n in old if n in full.heads})
    head = f"{audit_module.HEAD_PREFIX}:{ids}:{digest}"
    with Store.open(rigs) as store:
        resumed = store.verify(since=head)
    assert resumed.problems == [] and resumed.records_checked == 2  # the two definitions
    _widen_tolerance(rigs)
    with Store.open(rigs) as store:
        assert store.verify(since=head).problems == [
            f"rig definition {RIG} was changed after it was written (its chain hash no longer matches)"
        ]


def test_the_command_line_refuses_a_changed_definition_with_exit_2(rigs: str):
    from typer.testing import CliRunner

    from calibctl.cli.main import app

    _widen_tolerance(rigs)
    result = CliRunner().invoke(app, ["--db", rigs, "rig", "history", RIG], terminal_width=200)
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert f"rig definition {RIG} was changed after it was written" in " ".join(result.stderr.split())
