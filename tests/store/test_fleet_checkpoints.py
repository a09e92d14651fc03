"""Fleet checkpoints (store/fleet_checkpoints.py): a read that starts from the newest checkpoint says what a
replay of
the whole log says, over random logs of assignments and rollouts (started, promoted, rolled back; camera and
rig
targets); a checkpoint that no longer matches the log is ignored by reads and named by `db verify`; one that
matches the log's hash but not its replay is named by `db verify`."""

from __future__ import annotations

import json
import random
import shutil
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sqlalchemy import select, text
from sqlalchemy.orm import Session
from typer.testing import CliRunner

from calibctl.artifacts.common import sha256_hex
from calibctl.artifacts.fleet import FleetEvent
from calibctl.cli.main import app
from calibctl.config import load_settings
from calibctl.errors import NotFoundError, UnverifiedRecord
from calibctl.signing import Signer, TrustedKeys, create_key
from calibctl.store import fleet_checkpoints
from calibctl.store.fleet_ledger import Fleet, replay, to_state
from calibctl.store.models import FleetCheckpointRow
from calibctl.store.repository import Store
from calibctl.workflows.fleet import rollouts
from calibctl.workflows.fleet.robots import robot_states
from tests.artifacts.factories import calibration
from tests.store.documents import FIXED_TIME
from tests.store.rig_documents import rig_calibration, rig_definition
from tests.store.tamper import patch_stored_bytes

CARRIES = {
    "amr-1": (["CAM-0001"], ["STEREO-1"]),
    "amr-2": (["CAM-0002"], []),
    "amr-3": (["CAM-0003"], ["STEREO-1"]),
}
VERSIONS = {"serial": 3, "rig": 2}  # accepted versions of each serial and of the rig
WHO = {"actor": "qa", "station": "st1", "reason": "test"}
Op = tuple[str, int, int, int]


def _event(kind: str, **fields: Any) -> FleetEvent:
    return FleetEvent(kind=kind, at=FIXED_TIME, **WHO, **fields)  # type: ignore[arg-type]


def _fill(url: str) -> str:
    """Three robots (amr-1 and amr-3 share rig STEREO-1), each serial @1..@3 and the rig @1..@2 accepted."""
    with Store.open(url, create=True) as store:
        for n in range(1, 4):
            for v in range(1, VERSIONS["serial"] + 1):
                store.add_artifact(calibration(serial=f"CAM-000{n}", version=v), activate=True, **WHO)
        store.add_rig(rig_definition("STEREO-1"))
        for _ in range(VERSIONS["rig"]):
            store.add_rig_calibration(
                rig_calibration().model_copy(update={"rig": "STEREO-1"}), activate=True, **WHO
            )
        store.append_fleet_events(
            [
                _event("register", robot=robot, serials=serials, rigs=rigs)
                for robot, (serials, rigs) in CARRIES.items()
            ]
        )
    return url


def _batch(fleet: Fleet, op: Op) -> list[FleetEvent]:
    """The events one step appends, as the workflows write them (any op becomes a valid step, or none)."""
    kind, a, b, v = op
    robots = list(CARRIES)
    if kind == "assign":
        robot = robots[a % len(robots)]
        t = fleet.carries[robot][b % len(fleet.carries[robot])]
        return [_event("assign", robot=robot, version=min(v, VERSIONS[t[0]]), **{t[0]: t[1]})]
    if kind == "start":
        every = sorted({t for carried in fleet.carries.values() for t in carried})
        targets = [t for i, t in enumerate(every) if a >> i & 1] or every[:1]
        canary = [r for i, r in enumerate(robots) if b >> i & 1] or robots[:1]
        name = f"r{len(fleet.rollouts) + 1}"
        wanted = {t: min(v, VERSIONS[t[0]]) for t in targets}
        head = _event(
            "rollout",
            rollout=name,
            canary=canary,
            targets={n: x for (k, n), x in wanted.items() if k == "serial"},
            rig_targets={n: x for (k, n), x in wanted.items() if k == "rig"},
        )
        return [
            head,
            *(
                _event("assign", robot=r, version=wanted[t], rollout=name, **{t[0]: t[1]})
                for r in canary
                for t in fleet.carries[r]
                if t in wanted
            ),
        ]
    closing = [
        r
        for r in fleet.rollouts.values()
        if (r.closed is None if kind == "promote" else r.closed != "rolled back")
    ]
    if not closing:
        return []
    r = closing[a % len(closing)]
    if kind == "promote":
        return [
            *(
                _event("assign", robot=robot, version=r.targets[t], rollout=r.name, **{t[0]: t[1]})
                for robot, state in r.state.items()
                if state == "pending"
                for t in fleet.carries[robot]
                if t in r.targets
            ),
            _event("promote", rollout=r.name),
        ]
    back = [
        _event("assign", robot=robot, version=prev, rollout=r.name, **{t[0]: t[1]})
        for (robot, t), found in sorted(fleet.found.items())
        if (prev := found.get(r.name)) is not None and fleet.running[(robot, t)] != prev
    ]
    return [*back, _event("rollback", rollout=r.name)]


def _view(fleet: Fleet) -> tuple[dict[str, Any], dict[str, Any], list[dict[str, Any]]]:
    """Everything `fleet status` and the rollout steps read of a replayed log."""
    return (
        to_state(fleet),
        robot_states(fleet, {}, {}).as_json(),
        [r.as_json() for r in fleet.rollouts.values()],
    )


def _play(url: str, ops: list[Op], every: int, signer: Signer | None = None) -> None:
    """Append each op's step; after each, the store's checkpointed read must equal the whole log replayed
    (with
    ``signer``: the store signs what it writes and trusts that key)."""
    trusted = None if signer is None else TrustedKeys.load(None, signer)
    with pytest.MonkeyPatch.context() as mp, Store.open(url, signer=signer, trusted=trusted) as store:
        mp.setattr(fleet_checkpoints, "EVERY", every)
        for op in ops:
            batch = _batch(replay(store.fleet_events()), op)
            if batch:
                store.append_fleet_events(batch)
            loaded = store.fleet()
            assert loaded.ignored == []
            assert _view(loaded.fleet) == _view(replay(store.fleet_events())), (op, loaded.since)
        positions = _positions(store)
        assert store.fleet().since == (positions[-1] if positions else 0)
        assert store.verify(trusted).problems == []


def _positions(store: Store) -> list[int]:
    with Session(store._engine) as s:  # noqa: SLF001 - the test looks at the derived table itself
        return list(s.scalars(select(FleetCheckpointRow.position).order_by(FleetCheckpointRow.position)))


def _sql(store: Store, sql: str, **params: object) -> None:
    """What someone with write access to the database can do underneath calibctl (no trigger guards this
    table)."""
    with Session(store._write_engine) as s, s.begin():  # noqa: SLF001
        s.execute(text(sql), params)


OPS = st.lists(
    st.tuples(
        st.sampled_from(["assign", "start", "start", "promote", "rollback"]),
        st.integers(0, 31),
        st.integers(0, 7),
        st.integers(1, 3),
    ),
    min_size=1,
    max_size=14,
)


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("fleet") / "template.db"
    _fill(f"sqlite:///{path}")
    return path


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(ops=OPS, every=st.integers(1, 4))
def test_a_read_from_a_checkpoint_says_what_the_whole_replay_says(
    template: Path, tmp_path: Path, ops: list[Op], every: int
) -> None:
    db = tmp_path / f"{random.getrandbits(64):x}.db"
    shutil.copy(template, db)
    _play(f"sqlite:///{db}", ops, every)


@pytest.mark.parametrize("seed", [1, 2])
def test_the_same_on_both_backends(db_url: str, seed: int) -> None:
    rng = random.Random(seed)
    ops = [
        (
            rng.choice(["assign", "start", "promote", "rollback"]),
            rng.randrange(32),
            rng.randrange(8),
            rng.randrange(1, 4),
        )
        for _ in range(12)
    ]
    _play(_fill(db_url), ops, every=2)


@pytest.fixture
def checkpointed(db_url: str) -> str:
    """Each robot assigned, then rollout r1 of every target @2 (canary amr-1) started and promoted, with
    checkpoints written every 2 events: at 4, 6, 9 and 13 (the log's end), the oldest pruned."""
    _play(
        _fill(db_url),
        [
            ("assign", 0, 0, 1),
            ("assign", 1, 0, 1),
            ("assign", 2, 1, 1),
            ("start", 31, 1, 2),
            ("promote", 0, 0, 0),
        ],
        every=2,
    )
    with Store.open(db_url) as store:
        assert _positions(store) == [6, 9, 13] and len(store.fleet_events()) == 13
    return db_url


def _newest(store: Store) -> int:
    return _positions(store)[-1]


@pytest.mark.parametrize(
    ("tamper", "ignored", "flagged"),
    [
        (
            "UPDATE fleet_checkpoints SET state = state || ' ' WHERE position = :p",
            "was changed after it was written",
            "was changed after it was written",
        ),
        (
            "UPDATE fleet_checkpoints SET chain_hash = :zero WHERE position = :p",
            "does not match the log's chain hash there (the log was rewritten",
            "does not match the log's chain hash there",
        ),
    ],
)
def test_a_tampered_or_stale_checkpoint_is_ignored_and_flagged(
    checkpointed: str, tamper: str, ignored: str, flagged: str
) -> None:
    with Store.open(checkpointed) as store:
        newest = _newest(store)
        _sql(store, tamper, p=newest, zero="0" * 64)
        loaded = store.fleet()
        assert loaded.since == _positions(store)[-2] and ignored in loaded.ignored[0]
        assert _view(loaded.fleet) == _view(replay(store.fleet_events()))
        problems = store.verify().problems
    assert [p for p in problems if "fleet checkpoint" in p] == [p for p in problems if flagged in p] != []


def test_a_checkpoint_past_the_end_of_the_log_is_ignored_and_flagged(checkpointed: str) -> None:
    with Store.open(checkpointed) as store:
        newest = _newest(store)
        _sql(
            store,
            "INSERT INTO fleet_checkpoints (position, chain_hash, format, written_at, state, state_sha256) "
            "SELECT position + 5, chain_hash, format, written_at, state, state_sha256 FROM fleet_checkpoints "
            "WHERE position = :p",
            p=newest,
        )
        loaded = store.fleet()
        assert loaded.since == newest and "no such event" in loaded.ignored[0]
        problems = store.verify().problems
    assert problems == [
        f"fleet checkpoint at event {newest + 5} is past the end of the log ({newest} events)"
    ]


def test_a_forged_checkpoint_is_used_by_reads_but_named_by_db_verify(checkpointed: str) -> None:
    """Its state rewritten with a matching sha256, in a store without keys: reads cannot tell (they would have
    to
    replay the log), `db verify` replays the log and exits 1 naming it (with keys: the next test)."""
    with Store.open(checkpointed) as store:
        newest = _forge_newest(store)
        assert store.fleet().since == newest
    result = CliRunner().invoke(app, ["--db", checkpointed, "db", "verify"])
    assert result.exit_code == 1
    assert (
        f"PROBLEM fleet checkpoint at event {newest} is not the log replayed up to event {newest} (derived "
        "data: delete the row, or restore the store)"
    ) in result.stdout
    assert "1 problem(s) in the stored history" in result.stderr


def _forge_newest(store: Store) -> int:
    """The newest checkpoint's state rewritten (amr-1 runs a version it never got) with a matching sha256."""
    newest = _newest(store)
    with Session(store._engine) as s:  # noqa: SLF001
        state = json.loads(
            s.scalar(select(FleetCheckpointRow.state).where(FleetCheckpointRow.position == newest))
        )
    state["running"][0][3] = 3
    forged = json.dumps(state)
    _sql(
        store,
        "UPDATE fleet_checkpoints SET state = :s, state_sha256 = :h WHERE position = :p",
        s=forged,
        h=sha256_hex(forged.encode()),
        p=newest,
    )
    return newest


def test_with_keys_checkpoints_are_signed_and_a_forged_one_is_not_served(db_url: str, tmp_path: Path) -> None:
    """A station key signs each checkpoint; a store with keys reads only checkpoints a trusted key signed, so
    the forgery reads cannot see without keys (state and sha256 rewritten together) is skipped, and db verify
    names
    its signature."""
    signer = create_key(tmp_path / "station.pem")
    trusted = TrustedKeys.load(None, signer)
    _play(
        _fill(db_url),
        [
            ("assign", 0, 0, 1),
            ("assign", 1, 0, 1),
            ("assign", 2, 1, 1),
            ("start", 31, 1, 2),
            ("promote", 0, 0, 0),
        ],
        every=2,
        signer=signer,
    )
    with Store.open(db_url, signer=signer, trusted=trusted) as store:
        positions = _positions(store)
        with Session(store._engine) as s:  # noqa: SLF001
            keys = set(s.scalars(select(FleetCheckpointRow.key_id)))
        assert keys == {signer.key_id}
        newest = _forge_newest(store)
        loaded = store.fleet()
        assert loaded.since == positions[-2]
        assert (
            "has a signature by key" in loaded.ignored[0]
            and "does not match its content" in loaded.ignored[0]
        )
        assert _view(loaded.fleet) == _view(replay(store.fleet_events()))
        problems = store.verify(trusted).problems
    assert any(f"fleet checkpoint at event {newest} has a signature by key" in p for p in problems)
    with Store.open(
        db_url
    ) as store:  # no keys: the sha256 matches, so a read serves it (db verify still names it)
        assert store.fleet().since == newest


def test_a_store_with_keys_skips_unsigned_checkpoints(checkpointed: str, tmp_path: Path) -> None:
    """Checkpoints written before the store had keys: reads with keys replay past them (no finding for db
    verify:
    they are legitimate, only unproven)."""
    signer = create_key(tmp_path / "station.pem")
    trusted = TrustedKeys.load(None, signer)
    with Store.open(checkpointed, signer=signer, trusted=trusted) as store:
        loaded = store.fleet()
        assert loaded.since == 0 and all("is not signed" in why for why in loaded.ignored)
        assert _view(loaded.fleet) == _view(replay(store.fleet_events()))
        assert [p for p in store.verify(trusted).problems if "fleet checkpoint" in p] == []


def test_a_checkpoint_of_another_format_is_ignored_without_a_finding(checkpointed: str) -> None:
    """Written by another calibctl (the state's shape changed): stale, not tampered; the next write replaces
    it."""
    with Store.open(checkpointed) as store:
        _sql(store, "UPDATE fleet_checkpoints SET format = 99")
        loaded = store.fleet()
        assert loaded.since == 0 and "state format 99" in loaded.ignored[0]
        assert _view(loaded.fleet) == _view(replay(store.fleet_events()))
        assert store.verify().problems == []


def test_a_rollback_after_the_checkpoint_puts_back_what_the_robots_ran(checkpointed: str) -> None:
    """The checkpoint is of the promoted rollout: the rollback reads what to put back from it (its compact
    history):
    the version each robot ran before r1; a target r1 gave a robot that ran nothing before keeps r1's
    version."""
    settings = load_settings(db=checkpointed, station="st1", operator="qa", env={})
    with Store.open(checkpointed) as store:
        before = store.fleet()
        assert before.since == before.fleet.length and before.fleet.rollouts["r1"].closed == "promoted"
    rolled = rollouts.rollback(settings, "r1", "bad batch")
    assert rolled.closed == "rolled back"
    robots, staged = rollouts.fleet_status(settings)
    running = {(r.robot, s.serial): s.running for r in robots.robots for s in [*r.sensors, *r.rigs]}
    assert running == {
        ("amr-1", "CAM-0001"): 1,
        ("amr-1", "STEREO-1"): 2,
        ("amr-2", "CAM-0002"): 1,
        ("amr-3", "CAM-0003"): 2,
        ("amr-3", "STEREO-1"): 1,
    }
    with Store.open(checkpointed) as store:
        assert _view(store.fleet().fleet) == _view(replay(store.fleet_events()))
        assert [r.as_json() for r in staged] == [
            r.as_json() for r in replay(store.fleet_events()).rollouts.values()
        ]


def test_checkpoints_are_written_by_the_fleet_writer_only(
    checkpointed: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A refused step writes none (same transaction); `fleet status` writes none (reads never write)."""
    monkeypatch.setattr(fleet_checkpoints, "EVERY", 1)
    settings = load_settings(db=checkpointed, station="st1", operator="qa", env={})
    with Store.open(checkpointed) as store:
        kept = _positions(store)
        length = len(store.fleet_events())
        with pytest.raises(NotFoundError):
            store.append_fleet_events(
                [
                    _event("assign", robot="amr-2", serial="CAM-0002", version=1),
                    _event("promote", rollout="no-such"),
                ]
            )
        rollouts.fleet_status(settings)
        assert _positions(store) == kept and len(store.fleet_events()) == length
        store.append_fleet_events([_event("assign", robot="amr-2", serial="CAM-0002", version=2)])
        assert _positions(store) == [*kept[1:], length + 1]


def test_an_event_changed_before_the_checkpoint_is_left_to_db_verify(
    db_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Reads no longer decode the events before the checkpoint (that is the point); `db verify` still walks
    and
    decodes them all, names the changed event, and says it could not re-derive the checkpoints after it."""
    monkeypatch.setattr(fleet_checkpoints, "EVERY", 1)
    _fill(db_url)
    with Store.open(db_url) as store:
        store.append_fleet_events(
            [
                FleetEvent(
                    kind="assign",
                    robot="amr-2",
                    serial="CAM-0002",
                    version=1,
                    at=FIXED_TIME,
                    actor="qa",
                    station="st1",
                    reason="old reason",
                )
            ]
        )
        store.append_fleet_events([_event("assign", robot="amr-2", serial="CAM-0002", version=2)])
        assert _positions(store) == [3, 4, 5]
    patch_stored_bytes(db_url, "fleet_events", '"reason":"old reason"', '"reason":"odd reason"')
    with Store.open(db_url) as store:
        loaded = store.fleet()
        assert loaded.since == 5 and loaded.fleet.running[("amr-2", ("serial", "CAM-0002"))] == 2
        with pytest.raises(UnverifiedRecord, match=r"fleet event 4 \(amr-2, assign\) does not match"):
            store.fleet_events()
        problems = store.verify().problems
    assert any(p.startswith("fleet event 4 (amr-2, assign)") for p in problems)
    assert "fleet checkpoint(s) at event(s) 4, 5 not checked: the log before them does not decode" in problems


@pytest.mark.parametrize("state", ["not json", "[]", '{"format": 1}', "[" * 100_000 + "]" * 100_000])
def test_a_checkpoint_that_holds_no_fleet_state_is_ignored_and_flagged(checkpointed: str, state: str) -> None:
    """Written with a matching sha256 (by hand, or by a broken writer): reads fall back, `db verify` names
    it."""
    with Store.open(checkpointed) as store:
        _sql(
            store,
            "UPDATE fleet_checkpoints SET state = :s, state_sha256 = :h WHERE position = 13",
            s=state,
            h=sha256_hex(state.encode()),
        )
        loaded = store.fleet()
        assert (
            loaded.since == 9
            and "fleet checkpoint at event 13 does not hold a fleet state (" in loaded.ignored[0]
        )
        assert _view(loaded.fleet) == _view(replay(store.fleet_events()))
        assert [p for p in store.verify().problems if "checkpoint" in p] == [
            "fleet checkpoint at event 13 is not the log replayed up to event 13 (derived data: delete the "
            "row, or "
            "restore the store)"
        ]
