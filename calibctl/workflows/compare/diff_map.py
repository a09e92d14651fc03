"""The map of ``calibctl diff --map``: one self-contained HTML page of SVG heat maps over A's imager (the
difference as stored, after the fitted rotation, and its z against the expected spread), drawn with the
report's own SVG writers."""

from __future__ import annotations

from html import escape

import numpy as np

from calibctl.core.compare.projection_diff import DiffField, ProjectionDiff
from calibctl.workflows.report.report_svg import Plot, colour_bar, heat


def _grid_values(result: ProjectionDiff, values: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """(rows, cols) float64 of per-sample ``values`` (M,), NaN where a sample was outside a model."""
    cols, rows = result.grid
    w, h = image_size
    out = np.full((rows, cols), np.nan)
    c = np.clip(np.round((result.pixels_px[:, 0] + 0.5) * cols / w - 0.5).astype(int), 0, cols - 1)
    r = np.clip(np.round((result.pixels_px[:, 1] + 0.5) * rows / h - 0.5).astype(int), 0, rows - 1)
    out[r, c] = values
    return out


def _panel(
    result: ProjectionDiff, values: np.ndarray, image_size: tuple[int, int], title: str, unit: str
) -> str:
    w, h = image_size
    grid = _grid_values(result, values, image_size)
    lo, hi = 0.0, float(np.nanmax(grid)) if np.isfinite(grid).any() else 1.0
    plot = Plot(
        title,
        (0.0, float(w)),
        (0.0, float(h)),
        width=520,
        height=int(40 + 460 * h / w),
        flip_y=True,
        x_label="u (px)",
        y_label="v (px)",
    )
    heat(
        plot,
        grid,
        np.linspace(0, w, result.grid[0] + 1),
        np.linspace(0, h, result.grid[1] + 1),
        lo,
        hi,
        empty="#dddddd",
    )
    return plot.svg() + colour_bar(lo, hi, unit, 520)


def _magnitude(f: DiffField) -> np.ndarray:
    return np.linalg.norm(f.diff_px, axis=1)


def render_map(ref_a: str, ref_b: str, image_size: tuple[int, int], result: ProjectionDiff) -> str:
    """The HTML page: |difference| as stored and after the fitted rotation, and z where covariances exist."""
    verdict = {
        None: "no verdict (a covariance is missing)",
        True: "significantly different",
        False: "same within noise",
    }[result.significant]
    parts = [
        f"<h1>{escape(ref_a)} vs {escape(ref_b)}: {escape(verdict)}</h1>",
        "<p>" + "<br>".join(escape(r) for r in result.reasons) + "</p>",
        _panel(result, _magnitude(result.raw), image_size, "|q_B - q_A| as stored (px)", "px"),
        _panel(
            result,
            _magnitude(result.fit),
            image_size,
            f"|q_B - q_A| after a {result.rotation_fit_deg:.3f} deg rotation (px)",
            "px",
        ),
    ]
    if result.fit.z is not None:
        parts.append(
            _panel(
                result,
                result.fit.z,
                image_size,
                "z: difference / expected spread, after the rotation",
                "sigma",
            )
        )
    return (
        "<!doctype html><html><head><meta charset='utf-8'><title>calibctl diff</title></head>"
        "<body style='font-family:sans-serif'>" + "".join(parts) + "</body></html>\n"
    )
