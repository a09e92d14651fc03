"""`calibctl report --rig RIG[@N]`: the rig page's numbers match the rig artifact, self-contained,
byte-identical."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.config import load_settings
from calibctl.store.repository import Store
from calibctl.workflows.report.report_html import num
from calibctl.workflows.rig import rigs
from calibctl.workflows.rig.report_rig import compose_tree
from tests.artifacts.factories import measured_board
from tests.workflows.rig.test_rig_store_flow import WHO, _sources, _truth_artifact
from tests.workflows.rig_folders_data import rendered_rig

RUNNER = CliRunner()


@pytest.fixture(scope="module")
def solved(tmp_path_factory) -> tuple[str, object]:
    rig2 = rendered_rig(tmp_path_factory)
    root = tmp_path_factory.mktemp("rig-report")
    settings = load_settings(db=f"sqlite:///{root / 'r.db'}", station="st-test", operator="tester", env={})
    with Store.open(settings.db_url) as store:
        store.add_board(measured_board(square_mm=25.0))
        for name in ("CAM0", "CAM1"):
            store.add_artifact(_truth_artifact(rig2, name), activate=True, **WHO)
    rigs.add_rig(settings, "R1", ["CAM0", "CAM1"], None, ["CAM0:CAM1=75.0+-0.5"])
    rigs.capture_rig(settings, "R1", _sources(rig2), "A17")
    cal = rigs.solve_rig_stored(settings, "R1").calibration
    return settings.db_url, cal


def invoke(db: str, *args: str):
    return RUNNER.invoke(app, ["--db", db, *args], terminal_width=110)


def _keyed(html: str, key: str) -> str:
    match = re.search(rf'data-key="{re.escape(key)}"[^>]*>([^<]*)<', html)
    assert match, key
    return match.group(1)


def test_the_rig_page_shows_the_artifact_numbers_and_is_byte_identical(solved, tmp_path: Path) -> None:
    db, cal = solved
    out = tmp_path / "rig.html"
    done = invoke(db, "report", "--rig", "R1@1", "-o", str(out))
    assert done.exit_code == 0, done.output
    assert "rig R1@1 (accepted): report written to" in done.stdout
    html = out.read_text(encoding="utf-8")
    pair = cal.pairs[0]
    key = f"{pair.a}-{pair.b}"
    assert _keyed(html, f"baseline_{key}") == num(pair.baseline_mm, 3)
    assert _keyed(html, f"sigma_baseline_{key}") == num(pair.sigma_baseline_mm, 3)
    assert _keyed(html, f"epipolar_{key}") == num(pair.epipolar_rms_px)
    assert _keyed(html, f"vertical_{key}") == num(pair.rectified_rms_px)
    assert _keyed(html, "status") == "accepted" and _keyed(html, "lint") == "lint: clean"
    t_mm = compose_tree(cal)["CAM1"][:3, 3] * 1000
    assert _keyed(html, "t_CAM1_x") == num(float(t_mm[0]), 2)
    assert np.linalg.norm(t_mm) == pytest.approx(cal.edges[0].translation_mm, rel=1e-9)
    for serial in ("CAM0", "CAM1"):
        assert _keyed(html, f"member_{serial}") == "accepted"
        assert _keyed(html, f"rig_held_out_{serial}") == num(cal.held_out_rms_px[serial])
        assert f'href="{serial}-v1-report.html"' in html  # the member's own report, by serial@version
    # self-contained: no script, nothing fetched
    assert "<script" not in html and not re.search(r'(src|href)="(https?:)?//', html)
    assert len(html.encode()) < 1_000_000
    again = tmp_path / "again.html"
    assert invoke(db, "report", "--rig", "R1", "-o", str(again)).exit_code == 0
    assert again.read_bytes() == out.read_bytes()


def test_an_unknown_rig_exits_2_naming_the_known_ones(solved) -> None:
    db, _ = solved
    done = invoke(db, "report", "--rig", "NOPE")
    assert done.exit_code == 2
    assert "unknown rig 'NOPE'" in done.stderr and "R1" in done.stderr


def test_an_unknown_rig_version_exits_2(solved) -> None:
    db, _ = solved
    done = invoke(db, "report", "--rig", "R1@7")
    assert done.exit_code == 2 and "rig R1 has no version 7" in done.stderr


@pytest.mark.parametrize("args", [(), ("CAM0", "--rig", "R1")])
def test_report_needs_exactly_one_of_a_serial_and_a_rig(solved, args: tuple[str, ...]) -> None:
    db, _ = solved
    done = invoke(db, "report", *args)
    assert done.exit_code == 2 and "report needs one of SERIAL[@N] or --rig RIG[@N]" in done.stderr


@pytest.mark.slow
def test_the_rig_page_renders_in_chromium(solved, tmp_path: Path) -> None:
    from tests.cli.report.test_report_chromium import ink, screenshot

    db, _ = solved
    page = tmp_path / "rig.html"
    assert invoke(db, "report", "--rig", "R1", "-o", str(page)).exit_code == 0
    png = tmp_path / "rig.png"
    assert screenshot(page, png) == []
    # a blank page has ~0 ink; the rig page fills about a third of the 3800 px window (1.1 % ink measured)
    assert ink(png) > 0.005


def test_a_version_of_a_rig_with_no_active_version_gets_its_page(solved, tmp_path: Path) -> None:
    """R@N of a rig solved with --no-activate exited 2 "has no active version": the page asked for the active
    one."""
    db, cal = solved
    copy = tmp_path / "copy.db"
    copy.write_bytes(Path(db.removeprefix("sqlite:///")).read_bytes())
    url = f"sqlite:///{copy}"
    with Store.open(url) as store:
        store.add_rig(store.get_rig("R1").model_copy(update={"name": "R2"}))
        store.add_rig_calibration(cal.model_copy(update={"rig": "R2"}), activate=False, **WHO)
    out = tmp_path / "r2.html"
    done = invoke(url, "report", "--rig", "R2@1", "-o", str(out))
    assert done.exit_code == 0, done.output
    assert "rig R2@1 (accepted): report written to" in done.stdout
    assert "accepted</span></h1>" in out.read_text(encoding="utf-8")  # not followed by " (active)"


def test_the_rig_page_states_active_and_the_lint_of_now_beside_the_lint_at_solve_time(
    solved, tmp_path: Path, tmp_path_factory
) -> None:
    """It said "accepted (active)" while `lint --rig` failed the same rig for a stale member."""
    import shutil

    db, _ = solved
    copy = tmp_path / "db" / "r.db"
    copy.parent.mkdir()
    shutil.copy(db.removeprefix("sqlite:///"), copy)
    url = f"sqlite:///{copy}"
    fresh = tmp_path / "fresh.html"
    assert invoke(url, "report", "--rig", "R1", "-o", str(fresh)).exit_code == 0
    html = fresh.read_text(encoding="utf-8")
    assert (_keyed(html, "active"), _keyed(html, "lint_now"), _keyed(html, "lint_now_clean")) == (
        "yes",
        "pass",
        "lint: clean",
    )
    with Store.open(url) as store:  # CAM0 re-calibrated after the rig solve: the rig is stale
        store.add_artifact(_truth_artifact(rendered_rig(tmp_path_factory), "CAM0"), activate=True, **WHO)
    stale = tmp_path / "stale.html"
    assert invoke(url, "report", "--rig", "R1", "-o", str(stale)).exit_code == 0
    html = stale.read_text(encoding="utf-8")
    assert _keyed(html, "active") == "yes" and _keyed(html, "lint_now") == "FAIL"
    assert "rig-stale-member" in html and "the active one is now CAM0@2" in html
    assert _keyed(html, "lint") == "lint: clean"  # the lint stored at solve time, shown below it, unchanged
