"""Inline SVG drawn by hand from numbers: no plotting library, so a report is small, quick to make and
byte-identical when regenerated (every coordinate is printed with a fixed number of decimals)."""

from __future__ import annotations

from dataclasses import dataclass, field
from html import escape

import numpy as np

# viridis at 9 stops: readable in grey print and for colour-blind readers
_VIRIDIS = np.array(
    [
        [68, 1, 84],
        [71, 44, 122],
        [59, 81, 139],
        [44, 113, 142],
        [33, 144, 141],
        [39, 173, 129],
        [92, 200, 99],
        [170, 220, 50],
        [253, 231, 37],
    ],
    dtype=np.float64,
)


def colour(t: float) -> str:
    """viridis colour for t in [0, 1] as #rrggbb."""
    x = min(max(t, 0.0), 1.0) * (len(_VIRIDIS) - 1)
    i = min(int(x), len(_VIRIDIS) - 2)
    rgb = _VIRIDIS[i] + (x - i) * (_VIRIDIS[i + 1] - _VIRIDIS[i])
    return "#{:02x}{:02x}{:02x}".format(*(int(round(c)) for c in rgb))


def _f(x: float) -> str:
    return f"{x:.1f}"


@dataclass
class Plot:
    """One SVG chart: data x in [x0, x1] left to right, y in [y0, y1] (flip_y: y grows down, as pixels)."""

    title: str
    x_range: tuple[float, float]
    y_range: tuple[float, float]
    width: int = 480
    height: int = 320
    flip_y: bool = False
    x_label: str = ""
    y_label: str = ""
    margin: tuple[int, int, int, int] = (44, 12, 28, 56)  # top, right, bottom, left
    parts: list[str] = field(default_factory=list)

    def sx(self, x: float | np.ndarray) -> np.ndarray:
        x0, x1 = self.x_range
        left, right = self.margin[3], self.width - self.margin[1]
        return np.asarray(left + (np.asarray(x, dtype=np.float64) - x0) / ((x1 - x0) or 1.0) * (right - left))

    def sy(self, y: float | np.ndarray) -> np.ndarray:
        y0, y1 = self.y_range
        top, bottom = self.margin[0], self.height - self.margin[2]
        t = (np.asarray(y) - y0) / ((y1 - y0) or 1.0)
        return np.asarray(top + t * (bottom - top) if self.flip_y else bottom - t * (bottom - top))

    def rect(self, x0: float, y0: float, x1: float, y1: float, fill: str, extra: str = "") -> None:
        a, b = float(self.sx(x0)), float(self.sx(x1))
        c, d = float(self.sy(y0)), float(self.sy(y1))
        self.parts.append(
            f'<rect x="{_f(min(a, b))}" y="{_f(min(c, d))}" width="{_f(abs(b - a))}" '
            f'height="{_f(abs(d - c))}" fill="{fill}" shape-rendering="crispEdges"{extra}/>'
        )

    def dots(self, x: np.ndarray, y: np.ndarray, fill: str, r: float = 1.5) -> None:
        px, py = self.sx(x), self.sy(y)
        self.parts.append(
            f'<g fill="{fill}">'
            + "".join(f'<circle cx="{_f(a)}" cy="{_f(b)}" r="{r}"/>' for a, b in zip(px, py, strict=True))
            + "</g>"
        )

    def line(self, x: np.ndarray, y: np.ndarray, stroke: str, width: float = 1.5, dash: str = "") -> None:
        pts = " ".join(f"{_f(a)},{_f(b)}" for a, b in zip(self.sx(x), self.sy(y), strict=True))
        extra = f' stroke-dasharray="{dash}"' if dash else ""
        self.parts.append(
            f'<polyline points="{pts}" fill="none" stroke="{stroke}" stroke-width="{width}"{extra}/>'
        )

    def arrows(self, x: np.ndarray, y: np.ndarray, dx: np.ndarray, dy: np.ndarray, stroke: str) -> None:
        """Segments from (x, y) to (x + dx, y + dy) in data units, each with a dot at its tail."""
        x0, y0, x1, y1 = self.sx(x), self.sy(y), self.sx(x + dx), self.sy(y + dy)
        segs = "".join(f"M{_f(a)} {_f(b)}L{_f(c)} {_f(d)}" for a, b, c, d in zip(x0, y0, x1, y1, strict=True))
        self.parts.append(f'<path d="{segs}" stroke="{stroke}" stroke-width="1.2" fill="none"/>')
        self.dots(x, y, stroke, 1.0)

    def text(self, x: float, y: float, label: str, anchor: str = "middle", size: int = 10) -> None:
        self.parts.append(
            f'<text x="{_f(float(self.sx(x)))}" y="{_f(float(self.sy(y)))}" font-size="{size}" '
            f'text-anchor="{anchor}">{escape(label)}</text>'
        )

    def svg(self, ticks: bool = True) -> str:
        w, h = self.width, self.height
        top, right, bottom, left = self.margin
        axes = [
            f'<rect x="{left}" y="{top}" width="{w - left - right}" height="{h - top - bottom}" fill="none" '
            'stroke="#444"/>',
            f'<text x="{w / 2:.1f}" y="16" font-size="13" font-weight="bold" text-anchor="middle">'
            f"{escape(self.title)}</text>",
        ]
        if ticks:
            axes += self._ticks()
        if self.x_label:
            axes.append(
                f'<text x="{(left + w - right) / 2:.1f}" y="{h - 2}" font-size="11" '
                f'text-anchor="middle">{escape(self.x_label)}</text>'
            )
        if self.y_label:
            axes.append(
                f'<text x="12" y="{(top + h - bottom) / 2:.1f}" font-size="11" text-anchor="middle" '
                f'transform="rotate(-90 12 {(top + h - bottom) / 2:.1f})">{escape(self.y_label)}</text>'
            )
        return (
            f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" '
            f'font-family="sans-serif">' + "".join(self.parts) + "".join(axes) + "</svg>"
        )

    def _ticks(self) -> list[str]:
        out = []
        for value in nice_ticks(*self.x_range):
            x = float(self.sx(value))
            out.append(
                f'<text x="{_f(x)}" y="{self.height - self.margin[2] + 12}" font-size="9" '
                f'text-anchor="middle">{value:g}</text>'
            )
        for value in nice_ticks(*self.y_range):
            y = float(self.sy(value))
            out.append(
                f'<text x="{self.margin[3] - 4}" y="{_f(y + 3)}" font-size="9" '
                f'text-anchor="end">{value:g}</text>'
            )
        return out


def nice_ticks(lo: float, hi: float, count: int = 5) -> list[float]:
    """Round tick values (1, 2, 5 x 10^k steps) inside [lo, hi]."""
    lo, hi = min(lo, hi), max(lo, hi)
    span = hi - lo
    if not span > 0:
        return [lo]
    raw = span / count
    mag = 10.0 ** np.floor(np.log10(raw))
    step = next(m * mag for m in (1.0, 2.0, 5.0, 10.0) if m * mag >= raw)
    first = np.ceil(lo / step) * step
    return [float(f"{v:.6g}") for v in np.arange(first, hi + step * 1e-9, step)]


def colour_bar(lo: float, hi: float, unit: str, width: int = 480) -> str:
    """A horizontal viridis legend from lo to hi."""
    stops = "".join(f'<stop offset="{i / 8:.3f}" stop-color="{colour(i / 8)}"/>' for i in range(9))
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="30" font-family="sans-serif">'
        f'<defs><linearGradient id="vir">{stops}</linearGradient></defs>'
        f'<rect x="56" y="4" width="{width - 120}" height="10" fill="url(#vir)"/>'
        f'<text x="52" y="13" font-size="10" text-anchor="end">{lo:.2f}</text>'
        f'<text x="{width - 60}" y="13" font-size="10">{hi:.2f} {escape(unit)}</text></svg>'
    )


def heat(
    plot: Plot,
    values: np.ndarray,
    x_edges: np.ndarray,
    y_edges: np.ndarray,
    lo: float,
    hi: float,
    empty: str | None = None,
) -> None:
    """Fill each cell with its value's colour; NaN cells (or value 0 when ``empty``) get ``empty``."""
    span = (hi - lo) or 1.0
    for r in range(values.shape[0]):
        for c in range(values.shape[1]):
            v = float(values[r, c])
            blank = empty is not None and (not np.isfinite(v) or v == 0)
            fill = empty if blank and empty is not None else colour((v - lo) / span)
            plot.rect(x_edges[c], y_edges[r], x_edges[c + 1], y_edges[r + 1], fill)
