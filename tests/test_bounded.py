"""Hostile input files: each is refused with exit 2 and a message naming what is wrong, in bounded memory.
The same matrix runs through lint, import, the station file and a CSV log."""

from __future__ import annotations

import json
import tracemalloc
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl import bounded
from calibctl.cli.main import app
from calibctl.errors import InputError
from tests.artifacts.factories import calibration

BILLION_LAUGHS = "a: &a ['lol','lol','lol','lol','lol','lol','lol','lol','lol']\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 9)}]\n" for i in range(8)
)
DEEP = 100_000


def _artifact_doc() -> dict:
    return calibration().model_dump(mode="json")


def hostile_files(tmp: Path) -> dict[str, tuple[Path, str]]:
    """name -> (file, words the message must hold)."""
    doc = _artifact_doc()
    nul = json.loads(json.dumps(doc))
    nul["provenance"]["operator"] = "op\u0000erator"
    escape = json.loads(json.dumps(doc))
    escape["provenance"]["station"] = "st\u001b[2J"
    big_int = json.dumps(doc).replace('"version": 1', '"version": ' + "9" * 5000)
    cases = {
        "laughs.yaml": (BILLION_LAUGHS, "aliases are not accepted"),
        "deep.json": ("[" * DEEP + "]" * DEEP, "nested more than"),
        "deep.yaml": ("[" * DEEP + "]" * DEEP, "nested more than"),
        "deepmap.yaml": (
            "".join(f"{' ' * i}k:\n" for i in range(200)) + " " * 200 + "k: 1\n",
            "nested more than",
        ),
        "bigint.json": (big_int, "an integer of 5000 digits"),
        "bigint.yaml": ("version: " + "9" * 5000 + "\n", "an integer of 5000 digits"),
        "nul.json": (json.dumps(nul), "a NUL character"),
        "escape.json": (json.dumps(escape), "control character \\x1b"),
    }
    out = {}
    for name, (text, words) in cases.items():
        path = tmp / name
        path.write_text(text, encoding="utf-8")
        out[name] = (path, words)
    return out


@pytest.fixture
def hostile(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    return hostile_files(tmp_path)


@pytest.mark.parametrize(
    "name",
    [
        "laughs.yaml",
        "deep.json",
        "deep.yaml",
        "deepmap.yaml",
        "bigint.json",
        "bigint.yaml",
        "nul.json",
        "escape.json",
    ],
)
def test_each_hostile_file_is_an_input_error_in_bounded_memory(hostile, name):
    path, words = hostile[name]
    tracemalloc.start()
    try:
        with pytest.raises(InputError) as caught:
            bounded.load_file(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert words in caught.value.message and str(path) in caught.value.message
    assert peak < 16 * 2**20  # the bomb expands to ~10^9 nodes unbounded; refused, it allocates little


@pytest.mark.parametrize("command", ["lint", "import"])
@pytest.mark.parametrize(
    "name", ["laughs.yaml", "deep.json", "deep.yaml", "bigint.json", "nul.json", "escape.json"]
)
def test_lint_and_import_answer_hostile_files_with_exit_2(hostile, sqlite_url, command, name):
    path, words = hostile[name]
    result = CliRunner().invoke(app, ["--db", sqlite_url, command, str(path)])
    assert result.exit_code == 2, result.output
    assert words in result.stderr and "Traceback" not in result.output


def test_an_oversized_file_is_refused_before_it_is_read(tmp_path, monkeypatch, sqlite_url):
    path = tmp_path / "big.json"
    path.write_text(json.dumps(_artifact_doc()) + " " * (2 * 2**20))
    monkeypatch.setenv(bounded.MAX_INPUT_ENV, "1")
    result = CliRunner().invoke(app, ["--db", sqlite_url, "import", str(path)])
    assert result.exit_code == 2
    assert "over the 1 MiB input limit" in result.stderr and bounded.MAX_INPUT_ENV in result.stderr
    monkeypatch.setenv(bounded.MAX_INPUT_ENV, "3")
    assert bounded.load_file(path)["serial"] == "CAM-0001"  # the same file under a raised limit


def test_a_bad_size_setting_is_a_usage_error(monkeypatch, tmp_path):
    monkeypatch.setenv(bounded.MAX_INPUT_ENV, "lots")
    with pytest.raises(Exception, match="CALIBCTL_MAX_INPUT_MB='lots' is not a size"):
        bounded.load_file(tmp_path / "x.json")


@pytest.mark.parametrize("name", ["laughs.yaml", "deep.yaml", "bigint.yaml"])
def test_a_hostile_station_file_exits_2(hostile, tmp_path, name):
    path, words = hostile[name]
    result = CliRunner().invoke(
        app, ["--station-config", str(path), "--db", f"sqlite:///{tmp_path / 'x.db'}", "history", "CAM"]
    )
    assert result.exit_code == 2 and words in result.stderr


def test_an_oversized_csv_log_exits_2(tmp_path, monkeypatch):
    path = tmp_path / "residuals.csv"
    path.write_text("t_s,u_px,v_px\n" + "1,2,3\n" * 400_000)
    monkeypatch.setenv(bounded.MAX_INPUT_ENV, "1")
    from calibctl.workflows.diagnostics import diagnostics_io

    with pytest.raises(InputError, match="over the 1 MiB input limit"):
        diagnostics_io.read_table(path, ("t_s",))


def test_real_documents_still_load(tmp_path):
    """The limits are far above what a real file uses: an artifact with YAML and JSON round trips."""
    import yaml

    doc = _artifact_doc()
    (tmp_path / "a.json").write_text(json.dumps(doc))
    (tmp_path / "a.yaml").write_text(yaml.safe_dump(doc))
    assert bounded.load_file(tmp_path / "a.json") == doc
    assert bounded.load_file(tmp_path / "a.yaml") == doc
    fixture = Path(__file__).resolve().parents[1] / "fixtures" / "camera_front.json"
    assert bounded.load_file(fixture)["content_sha256"]
