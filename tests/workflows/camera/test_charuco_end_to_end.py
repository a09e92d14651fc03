"""ChArUco end to end: rendered ChArUco views -> board registry -> calibrate -> accepted, near truth."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from calibctl.cli.main import app

runner = CliRunner()


def test_charuco_board_calibrates_end_to_end(tmp_path, sqlite_url):
    shots = tmp_path / "shots"
    assert (
        runner.invoke(
            app, ["synth", str(shots), "--scenario", "good", "--pattern", "charuco", "--seed", "5"]
        ).exit_code
        == 0
    )
    truth = json.loads((shots / "truth.json").read_text())
    board = truth["board"]
    added = runner.invoke(
        app,
        [
            "--db",
            sqlite_url,
            "board",
            "add",
            "CH1",
            "--kind",
            "charuco",
            "--cols",
            str(board["cols"]),
            "--rows",
            str(board["rows"]),
            "--square-mm",
            str(board["square_size_m"] * 1000),
            "--marker-mm",
            str(board["marker_size_m"] * 1000),
            "--dictionary",
            board["dictionary"],
            "--uncertainty-mm",
            "0.02",
            "--instrument",
            "calipers",
            "--measured-by",
            "qa",
            "--measured-on",
            "2026-03-11",
        ],
    )
    assert added.exit_code == 0, added.output
    result = runner.invoke(
        app,
        [
            "--db",
            sqlite_url,
            "calibrate",
            "--serial",
            "CH-1",
            "--board",
            "CH1",
            "--source",
            str(shots),
            "--json",
        ],
    )
    assert result.exit_code == 0, result.output
    art = json.loads(result.stdout)["calibration"]
    assert art["status"] == "accepted" and art["board"]["kind"] == "charuco"
    fx_true = truth["camera"]["K"][0][0]
    assert abs(art["camera_matrix"][0][0] - fx_true) < 4 * art["stdev"]["sigma"]["fx"]
