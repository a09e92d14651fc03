"""A list cut for the terminal says how many rows it left out: nothing is dropped without a word."""

from __future__ import annotations

import pytest

from calibctl.cli.rig_render import MAX_UNMATCHED_ROWS, render_unmatched
from calibctl.cli.solve import MAX_OUTLIER_ROWS, render_outlier_corners


@pytest.mark.parametrize(
    ("rows", "footer"),
    [(3, None), (MAX_UNMATCHED_ROWS, None), (MAX_UNMATCHED_ROWS + 4, "  ... 4 more unmatched (see --json)")],
)
def test_unmatched_photos_past_the_cut_are_counted(
    capsys: pytest.CaptureFixture[str], rows: int, footer: str | None
) -> None:
    render_unmatched([("left", f"img-{i:03d}.png", "no partner within 5 ms") for i in range(rows)])
    lines = capsys.readouterr().out.splitlines()
    listed = [line for line in lines if line.startswith("  unmatched left img-")]
    assert (
        len(listed) == min(rows, MAX_UNMATCHED_ROWS)
        and listed[0] == "  unmatched left img-000.png: no partner within 5 ms"
    )
    assert lines[len(listed) :] == ([] if footer is None else [footer])


@pytest.mark.parametrize(
    ("rows", "footer"), [(1, None), (MAX_OUTLIER_ROWS + 7, "  ... 7 more outlier corners kept (see --json)")]
)
def test_kept_outlier_corners_past_the_cut_are_counted(
    capsys: pytest.CaptureFixture[str], rows: int, footer: str | None
) -> None:
    render_outlier_corners(
        [{"view": f"v{i:02d}.png", "corner_id": i, "residual_px": 2.5} for i in range(rows)]
    )
    lines = capsys.readouterr().out.splitlines()
    assert (
        lines[0]
        == "  outlier corner kept (its view has too few corners to lose it): v00.png id 0 residual 2.50 px"
    )
    assert len(lines) == min(rows, MAX_OUTLIER_ROWS) + (footer is not None)
    assert (lines[-1] == footer) if footer else "more" not in lines[-1]
