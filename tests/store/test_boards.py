"""Board revisions in the store: allocation, lookup, messages, and a property round trip."""

from __future__ import annotations

import datetime as dt
import itertools
from collections.abc import Iterator

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from calibctl.artifacts.board import BoardRevision, SquareMeasurement
from calibctl.errors import NotFoundError, UsageError
from calibctl.store.history import KNOWN_SHOWN
from calibctl.store.repository import Store
from tests.artifacts.factories import measured_board, nominal_board


@pytest.fixture
def store(db_url: str) -> Iterator[Store]:
    with Store.open(db_url) as opened:
        yield opened


def test_adding_a_board_again_creates_the_next_revision(store: Store):
    first = store.add_board(measured_board(square_mm=25.03))
    second = store.add_board(measured_board(revision=9, square_mm=25.01))  # the given revision is ignored
    assert (first.revision, second.revision) == (1, 2)
    assert store.get_board("A17") == second
    assert store.get_board("A17", 1) == first
    assert store.get_board("A17", 1).square_size_m == 0.02503
    assert store.board_revisions("A17") == [1, 2]
    assert [b.ref for b in store.list_boards()] == ["A17@1", "A17@2"]


def test_revisions_are_counted_per_name(store: Store):
    store.add_board(measured_board(name="A17"))
    assert store.add_board(nominal_board(name="B2")).revision == 1
    assert store.add_board(measured_board(name="A17")).revision == 2
    assert [b.ref for b in store.list_boards()] == ["A17@1", "A17@2", "B2@1"]


def test_a_new_revision_may_not_change_the_pattern(store: Store):
    store.add_board(measured_board())
    other = measured_board().model_copy(update={"cols": 8})
    with pytest.raises(UsageError, match=r"board A17@1 is a 9x6 chessboard; .* but cols differ"):
        store.add_board(other)
    assert store.board_revisions("A17") == [1]


def test_unknown_board_and_revision_name_what_exists(store: Store):
    with pytest.raises(NotFoundError, match="unknown board 'A17'; no boards are registered yet"):
        store.get_board("A17")
    store.add_board(measured_board(name="B2"))
    store.add_board(measured_board(name="A17"))
    store.add_board(measured_board(name="A17"))
    with pytest.raises(NotFoundError, match="unknown board 'C3'; known: A17, B2") as info:
        store.get_board("C3")
    assert info.value.exit_code == 2
    with pytest.raises(NotFoundError, match="board A17 has no revision 5; revisions: 1, 2"):
        store.get_board("A17", 5)


def test_a_long_list_of_what_exists_names_the_first_and_counts_the_rest(store: Store):
    for _ in range(KNOWN_SHOWN + 2):
        store.add_board(measured_board(name="A17"))
    with pytest.raises(NotFoundError) as missing:
        store.get_board("A17", 99)
    first = ", ".join(str(r) for r in range(1, KNOWN_SHOWN + 1))
    assert f"board A17 has no revision 99; revisions: {first} and 2 more" in missing.value.message
    assert missing.value.exit_code == 2


UNIQUE = itertools.count(1)
measurements = st.one_of(
    st.builds(
        SquareMeasurement,
        status=st.just("nominal"),
        square_size_m=st.floats(min_value=1e-4, max_value=0.5),
    ),
    st.builds(
        SquareMeasurement,
        status=st.just("measured"),
        square_size_m=st.floats(min_value=1e-4, max_value=0.5),
        uncertainty_m=st.floats(min_value=1e-9, max_value=1e-3),
        instrument=st.text(min_size=1, max_size=30),
        measured_by=st.text(min_size=1, max_size=20),
        measured_on=st.dates(min_value=dt.date(2000, 1, 1), max_value=dt.date(2030, 12, 31)),
        evidence_sha256=st.one_of(st.none(), st.text("0123456789abcdef", min_size=64, max_size=64)),
        evidence_name=st.one_of(st.none(), st.text(min_size=1, max_size=20)),
    ),
)
boards = st.builds(
    BoardRevision,
    name=st.from_regex(r"[A-Za-z0-9][A-Za-z0-9._-]{0,40}", fullmatch=True),
    revision=st.just(1),
    kind=st.just("chessboard"),
    cols=st.integers(2, 200),
    rows=st.integers(2, 200),
    measurement=measurements,
    created_at=st.datetimes(
        min_value=dt.datetime(2000, 1, 1), max_value=dt.datetime(2100, 1, 1), timezones=st.just(dt.UTC)
    ),
    created_by=st.text(min_size=1, max_size=20),
    note=st.one_of(st.none(), st.text(max_size=60)),
)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(board=boards)
def test_any_board_round_trips_through_the_store(store: Store, board: BoardRevision):
    # One store serves every example: a unique name keeps each example's board at revision 1.
    board = board.model_copy(update={"name": f"{board.name}-{next(UNIQUE)}"})
    stored = store.add_board(board)
    assert stored == board  # revision 1, every field as given
    assert store.get_board(board.name) == stored
    assert store.get_board(board.name, 1).measurement == board.measurement
