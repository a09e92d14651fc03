"""``errors.named_list``: the one "a, b, c and 4 more" of calibctl's messages."""

from __future__ import annotations

from calibctl.errors import named_list


def test_items_that_fit_are_all_named() -> None:
    assert named_list(["a", "b", "c"], 3) == "a, b, c"
    assert named_list([], 3) == ""
    assert named_list([7], 3) == "7"


def test_items_past_the_limit_are_counted() -> None:
    assert named_list(["a", "b", "c", "d", "e", "f", "g"], 3) == "a, b, c and 4 more"
    assert named_list(range(1, 12), 10) == "1, 2, 3, 4, 5, 6, 7, 8, 9, 10 and 1 more"


def test_a_separator_for_items_that_hold_commas() -> None:
    assert (
        named_list(["x: bad, very", "y: worse", "z: gone"], 2, sep="; ")
        == "x: bad, very; y: worse and 1 more"
    )


def test_only_the_items_shown_are_turned_into_text() -> None:
    class Loud:
        def __str__(self) -> str:
            raise AssertionError("an item past the limit was formatted")

    assert named_list(["a", "b", Loud(), Loud()], 2) == "a, b and 2 more"
