"""Database use cases: where the store's schema stands, migrating it, and auditing everything in it."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from calibctl.config import Settings
from calibctl.errors import IntegrityError, UnverifiedRecord
from calibctl.store import migrate
from calibctl.store.engine import display_url
from calibctl.store.repository import Store
from calibctl.workflows.store_admin import keys

_STATUS_WORDS = {
    "absent": "no database yet; it is created at head on first use (or by `calibctl db upgrade`)",
    "empty": "empty database; calibctl creates its tables at head on first use (or `calibctl db upgrade`)",
    "current": "up to date",
    "out_of_date": "out of date; run `calibctl db upgrade`",
    "unknown": "migrated by a newer calibctl; upgrade calibctl",
}


@dataclass(frozen=True)
class DatabaseStatus:
    url: str
    backend: str
    current: str | None
    head: str
    status: str
    counts: dict[str, int] | None = None

    @property
    def description(self) -> str:
        return _STATUS_WORDS[self.status]

    def as_json(self) -> dict[str, Any]:
        return {**asdict(self), "up_to_date": self.status == "current", "description": self.description}


@dataclass(frozen=True)
class UpgradeResult:
    url: str
    before: str | None
    after: str | None

    @property
    def changed(self) -> bool:
        return self.before != self.after

    def as_json(self) -> dict[str, Any]:
        return {**asdict(self), "changed": self.changed}


@dataclass(frozen=True)
class VerifyReport:
    url: str
    counts: dict[str, int]
    problems: list[str] = field(default_factory=list)
    head: str = ""
    since: str | None = None
    records_checked: int = 0
    signatures_checked: int = 0
    unsigned: int = 0
    trusted_keys: int = 0
    orphan_images: int = 0  # image files no row refers to (a failed capture's); `calibctl prune` removes them

    @property
    def ok(self) -> bool:
        return not self.problems

    def as_json(self) -> dict[str, Any]:
        return {**asdict(self), "ok": self.ok}


def status(settings: Settings) -> DatabaseStatus:
    """The schema revision of the configured database (and what it holds, when it is current)."""
    state = migrate.state_of(settings.db_url)
    backend = "postgresql" if state.url.startswith("postgresql") else "sqlite"
    counts = None
    if state.status == "current":
        with Store.open(settings.db_url, create=False) as store:
            counts = store.counts()
    return DatabaseStatus(state.url, backend, state.current, state.head, state.status, counts)


def upgrade(settings: Settings) -> UpgradeResult:
    """Create the database at head, or migrate an older one to head with its data."""
    before, after = migrate.upgrade_url(settings.db_url)
    return UpgradeResult(display_url(settings.db_url), before, after)


def verify(
    settings: Settings,
    *,
    trusted_keys: Path | None = None,
    require_signature: bool = False,
    since: str | None = None,
) -> VerifyReport:
    """Check every chain, signature, counter, event and stored hash (or only what came after ``since``)."""
    trusted = keys.trusted_of(settings, trusted_keys)
    with Store.open(settings.db_url, create=False) as store:
        try:
            audit = store.verify(trusted, require_signature=require_signature, since=since)
        except UnverifiedRecord as exc:  # a record too damaged to walk past (a date that does not parse)
            raise IntegrityError(exc.message, exc.hint) from exc  # the verdict, exit 1: it is db verify's job
        return VerifyReport(
            store.url,
            store.counts(),
            audit.problems,
            audit.head(),
            since,
            audit.records_checked,
            audit.signatures_checked,
            audit.unsigned,
            len(trusted.keys),
            orphan_images=len(store.orphan_images()),
        )
