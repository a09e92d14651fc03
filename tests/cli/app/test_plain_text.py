"""calibctl.cli.plain_text: lint's text without rich, coloured only on a terminal."""

from __future__ import annotations

import io

import pytest

from calibctl.artifacts.lint import Finding
from calibctl.cli import plain_text
from calibctl.cli.plain_text import finding_lines, terminal_paint

FINDINGS = [
    Finding(
        rule="sigma-fx",
        severity="error",
        message="sigma(fx) = 2.270 px; limit 2.000 px",
        fix="capture more views",
    ),
    Finding(rule="aspect-ratio", severity="warning", message="fx/fy = 1.06 [x]\x1b[2J", fix=None),
]


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_finding_lines_print_stored_text_safely_and_verbatim() -> None:
    assert finding_lines(FINDINGS) == [
        "  lint error sigma-fx: sigma(fx) = 2.270 px; limit 2.000 px",
        "       fix: capture more views",
        "  lint warning aspect-ratio: fx/fy = 1.06 [x]\\x1b[2J",  # brackets kept, the escape made visible
    ]
    assert finding_lines([]) == ["  lint: clean"]


def test_colour_only_on_a_terminal_and_never_with_no_color(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("NO_COLOR", raising=False)
    monkeypatch.setattr(plain_text.sys, "stdout", io.StringIO())
    assert terminal_paint("red", "FAIL") == "FAIL"  # a pipe, a file, a CI log
    monkeypatch.setattr(plain_text.sys, "stdout", _Tty())
    assert terminal_paint("red", "FAIL") == "\x1b[31mFAIL\x1b[0m"
    assert (
        finding_lines(FINDINGS[:1], terminal_paint)[0]
        == "  lint \x1b[31merror\x1b[0m sigma-fx: sigma(fx) = 2.270 px; limit 2.000 px"
    )
    monkeypatch.setenv("NO_COLOR", "1")
    assert terminal_paint("green", "pass") == "pass"
