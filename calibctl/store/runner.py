"""The one thing every part of the Store shares: running a unit of work as one transaction.

``Store`` owns a ``Runner`` and hands it to each of its parts (cameras, rigs, images, checks, fleet,
health) instead of the parts being mixins of one class: a part sees only the runner and the few
functions it is given, never the other parts' private state.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Concatenate, Generic, ParamSpec, TypeVar, overload

from sqlalchemy import Engine, text
from sqlalchemy import exc as sa_exc
from sqlalchemy.orm import Session

from calibctl.errors import DatabaseError
from calibctl.signing import Signer, TrustedKeys
from calibctl.store import chain, served
from calibctl.store.engine import (
    WRITE_OPTION,
    as_database_error,
    display_url,
    is_retryable,
    is_unique_violation,
)
from calibctl.store.models import Base

T = TypeVar("T")
R = TypeVar("R", bound=Base)
MAX_ATTEMPTS = 5


class Runner:
    """Transactions on one engine, and the signing and checking keys every write and read uses."""

    def __init__(self, engine: Engine, signer: Signer | None, trusted: TrustedKeys | None) -> None:
        self.engine = engine
        self.write_engine = engine.execution_options(**{WRITE_OPTION: True})
        self.signer = signer
        self.trusted = trusted

    @property
    def url(self) -> str:
        """The database URL with the password hidden."""
        return display_url(self.engine.url)

    def run(self, work: Callable[[Session], T], *, write: bool = False, retry_conflicts: bool = False) -> T:
        """Run ``work`` in one transaction; retry (bounded) on serialization failures and, when asked,
        on unique-key conflicts with a concurrent writer (the retry then sees the committed row)."""
        for attempt in range(1, MAX_ATTEMPTS + 1):
            try:
                engine = self.write_engine if write else self.engine
                with Session(engine, expire_on_commit=False) as session, session.begin():
                    return work(session)
            except sa_exc.DBAPIError as exc:
                retry = is_retryable(exc) or (retry_conflicts and is_unique_violation(exc))
                if retry and attempt < MAX_ATTEMPTS:
                    continue
                mapped = as_database_error(exc, self.engine)
                if mapped is None:
                    raise
                raise mapped from exc
        raise DatabaseError(f"the database {self.url} kept refusing the transaction")  # pragma: no cover

    def served(self, s: Session, stream: str, row: Base | None) -> None:
        """With keys configured, refuse ``row`` (a record a read serves) if ``db verify`` would flag it."""
        if row is not None and self.trusted is not None:
            served.check(
                stream,
                row,
                lambda sql, params: [dict(r) for r in s.execute(text(sql), params).mappings()],
                self.trusted,
            )

    def linked(self, stream: str, s: Session, row: R) -> R:
        """``row`` with its chain (and, with a key, signature) columns set; the caller holds the stream's
        lock."""
        chain.link(s, chain.STREAMS[stream], row, self.signer)
        return row


P = ParamSpec("P")


class Delegate(Generic[P, T]):
    """A ``Store`` method that is one of its parts' methods: ``add_check = Delegate("_checks",
    CheckStore.add_check)`` makes ``store.add_check(...)`` call ``store._checks.add_check(...)``, with the
    part's signature and docstring. Callers keep calling the Store; the code lives in the part."""

    def __init__(self, part: str, method: Callable[Concatenate[Any, P], T]) -> None:
        self._part = part
        self._name = method.__name__
        self.__doc__ = method.__doc__

    def _bound(self, store: object) -> Callable[P, T]:
        method: Callable[P, T] = getattr(getattr(store, self._part), self._name)
        return method

    def __call__(self, store: object, /, *args: P.args, **kwargs: P.kwargs) -> T:
        """Called off the class, as an unbound method is (``Store.put_images(store, ...)``)."""
        return self._bound(store)(*args, **kwargs)

    @overload
    def __get__(self, store: None, owner: type | None = None) -> Delegate[P, T]: ...
    @overload
    def __get__(self, store: object, owner: type | None = None) -> Callable[P, T]: ...
    def __get__(self, store: object | None, owner: type | None = None) -> Delegate[P, T] | Callable[P, T]:
        if store is None:  # looked up on the class (help(), monkeypatch): the delegate itself
            return self
        return self._bound(store)
