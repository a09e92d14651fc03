"""The Store is built from parts; callers (and tests that wrap a method) still see one class."""

from __future__ import annotations

import pytest

from calibctl.store.repository import Store


def test_a_parts_method_wrapped_on_the_class_is_called_and_restored(monkeypatch: pytest.MonkeyPatch):
    real = Store.serials
    seen: list[str] = []

    def wrapped(store: Store) -> list[str]:
        seen.append("called")
        return real(store)  # the class attribute called as an unbound method

    with Store.open("sqlite://") as store:
        monkeypatch.setattr(Store, "serials", wrapped)
        assert store.serials() == [] and seen == ["called"]
        monkeypatch.undo()
        assert store.serials() == [] and seen == ["called"]  # the part's own method again
        assert Store.rollback.__doc__ and Store.rollback.__doc__ == store._cameras.rollback.__doc__  # noqa: SLF001


def test_a_parts_method_has_the_parts_signature():
    import inspect

    with Store.open("sqlite://") as store:
        assert list(inspect.signature(store.rollback_rig).parameters) == [
            "rig",
            "to_version",
            "reason",
            "actor",
            "station",
            "expected_active",
        ]
