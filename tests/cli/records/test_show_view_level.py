"""`show` says when the reported sigma is the view-level one, and why."""

from __future__ import annotations

from calibctl.artifacts.calibration import ViewLevelSigma
from calibctl.cli.render import stdout
from calibctl.cli.report import print_calibration
from tests.artifacts.factories import calibration


def _shown(used: str) -> str:
    base = calibration()
    check = ViewLevelSigma(sigma_factor=2.41, views=13, used=used, rule="r")  # type: ignore[arg-type]
    art = base.model_copy(update={"stdev": base.stdev.model_copy(update={"view_level": check})})
    with stdout.capture() as cap:
        print_calibration(art)
    return cap.get()


def test_show_names_the_view_level_sigma_and_its_cause():
    text = " ".join(_shown("view-level").split())
    assert "sigma x 2.41" in text and "13 views scatter more than their corner noise explains" in text


def test_show_is_silent_when_the_jacobian_sigma_is_reported():
    assert "sigma x" not in _shown("jacobian")
