"""CSV in and out for the field diagnostics: strict validation that names columns and line numbers.

Every problem a technician can cause with a file is an InputError (exit 2) that says what is wrong
and where: a missing column by name, a non-numeric or non-finite cell by line number (the header is
line 1), a short row, timestamps that do not increase. Nothing is guessed and nothing is dropped
silently. Writes go to a temporary file in the same directory and are renamed into place, so an
interrupted write never leaves half a CSV behind, and an existing file is never overwritten without
``force``.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calibctl import bounded, files
from calibctl.errors import InputError, named_list

MAX_LISTED = 5


@dataclass
class Table:
    """Parsed CSV: numeric columns as (n,) float64, text columns as (n,) str; lines (n,) file line numbers.

    Label columns (keyframe ids) are float64 when every cell is a number and str otherwise.
    """

    path: Path
    numeric: dict[str, np.ndarray]
    text: dict[str, np.ndarray]
    lines: np.ndarray
    labels: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def n_rows(self) -> int:
        return int(self.lines.size)


def lines_text(lines: np.ndarray) -> str:
    return f"line{'s' if lines.size > 1 else ''} {named_list(lines.tolist(), MAX_LISTED)}"


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _parse_numeric(name: str, cells: list[str], lines: np.ndarray, path: Path) -> np.ndarray:
    try:
        values = np.array(cells, dtype=np.float64)
    except ValueError:
        bad = [f"line {int(lines[i])} ({cell!r})" for i, cell in enumerate(cells) if not _is_number(cell)]
        raise InputError(
            f"{path.name}: column {name} has non-numeric cells: {named_list(bad, MAX_LISTED)}",
            hint="every cell of a numeric column must be a number",
        ) from None
    finite = np.isfinite(values)
    if not finite.all():
        raise InputError(
            f"{path.name}: column {name} has non-finite values (nan/inf) at {lines_text(lines[~finite])}",
            hint="drop or repair those rows; a diagnosis cannot be built on NaN",
        )
    return values


def _fast_read(
    path: Path, header: list[str], numeric_cols: list[str], text_cols: list[str], label_cols: list[str]
):
    """np.loadtxt fast path for well-formed files; None whenever anything needs a line-numbered message."""
    raw = path.read_bytes()
    n_lines = raw.count(b"\n") + (0 if raw.endswith(b"\n") else 1)
    n_rows = n_lines - 1
    if n_rows < 1 or b'"' in raw or raw.count(b",") != n_lines * (len(header) - 1) or b"\r" in raw:
        return None

    def load(cols: list[str], dtype):
        if not cols:
            return None
        return np.loadtxt(
            path,
            usecols=[header.index(c) for c in cols],
            dtype=dtype,
            delimiter=",",
            skiprows=1,
            comments=None,
            ndmin=2,
            encoding="utf-8-sig",
        )

    try:
        values = load(numeric_cols + label_cols, np.float64)
        text = load(text_cols, str)
        labels = {c: values[:, len(numeric_cols) + i] for i, c in enumerate(label_cols)}
    except ValueError:
        try:  # labels that are not numbers (kf_0001) are fine; anything else goes the careful way
            values, text = load(numeric_cols, np.float64), load(text_cols + label_cols, str)
        except ValueError:
            return None
        labels = {c: np.char.strip(text[:, len(text_cols) + i]) for i, c in enumerate(label_cols)}
    if values.shape[0] != n_rows or not np.isfinite(values[:, : len(numeric_cols)]).all():
        return None
    numeric = {c: np.ascontiguousarray(values[:, i]) for i, c in enumerate(numeric_cols)}
    texts = {c: np.char.strip(text[:, i]) for i, c in enumerate(text_cols)}
    return numeric, texts, np.arange(2, n_rows + 2, dtype=np.int64), labels


def _label_column(cells: list[str]) -> np.ndarray:
    try:
        values = np.array(cells, dtype=np.float64)
    except ValueError:
        return np.array(cells)
    return values if np.isfinite(values).all() else np.array(cells)


def read_table(
    path: Path,
    required: tuple[str, ...],
    optional_numeric: tuple[str, ...] = (),
    optional_text: tuple[str, ...] = (),
    what: str = "CSV",
    optional_labels: tuple[str, ...] = (),
) -> Table:
    """Read ``path`` (comma-separated, header on line 1). Required columns are numeric.

    Well-formed files take a fast np.loadtxt path (about a second per million rows); any file that
    fails it is re-read cell by cell so the error can name the line.
    """
    path = Path(path)
    if path.is_file():
        bounded.check_size(path, f"read the {what}")
    try:
        handle = io.TextIOWrapper(
            files.open_regular(path, f"read the {what}"), newline="", encoding="utf-8-sig"
        )
    except FileNotFoundError:
        raise InputError(f"{what} {path} does not exist", hint="check the path") from None
    except OSError as exc:
        raise InputError(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    with handle:
        reader = csv.reader(handle)
        try:
            header = next(reader, None)
            if header is None:
                raise InputError(
                    f"{what} {path} is empty", hint=f"expected a header with columns {', '.join(required)}"
                )
            header = [h.strip() for h in header]
            dupes = sorted({h for h in header if header.count(h) > 1})
            if dupes:
                raise InputError(
                    f"{path.name}: column(s) {', '.join(dupes)} appear more than once in the header"
                )
            missing = [c for c in required if c not in header]
            if missing:
                raise InputError(
                    f"{path.name} is missing column(s) {', '.join(missing)} (found: {', '.join(header)})",
                    hint=f"a {what} needs columns {', '.join(required)}",
                )
            numeric_cols = [c for c in (*required, *optional_numeric) if c in header]
            text_cols = [c for c in optional_text if c in header]
            label_cols = [c for c in optional_labels if c in header]
            fast = _fast_read(path, header, numeric_cols, text_cols, label_cols)
            if fast is not None:
                return Table(path, *fast)
            rows, line_numbers = [], []
            for row in reader:
                if not row or (len(row) == 1 and not row[0].strip()):
                    continue
                if len(row) != len(header):
                    raise InputError(
                        f"{path.name}: line {reader.line_num} has {len(row)} cells, the header has "
                        f"{len(header)}"
                    )
                rows.append(row)
                line_numbers.append(reader.line_num)
        except (csv.Error, UnicodeDecodeError) as exc:
            raise InputError(f"{path.name} is not a readable CSV file: {exc}") from None
    if not rows:
        raise InputError(f"{path.name} has a header but no data rows")
    lines = np.asarray(line_numbers, dtype=np.int64)
    by_column = dict(zip(header, zip(*rows, strict=True), strict=True))
    numeric = {c: _parse_numeric(c, [s.strip() for s in by_column[c]], lines, path) for c in numeric_cols}
    text = {c: np.array([s.strip() for s in by_column[c]]) for c in text_cols}
    labels = {c: _label_column([s.strip() for s in by_column[c]]) for c in label_cols}
    return Table(path, numeric, text, lines, labels)


def require_increasing(table: Table, column: str) -> None:
    """Raise InputError naming the first line where ``column`` does not strictly increase."""
    values = table.numeric[column]
    bad = np.flatnonzero(np.diff(values) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise InputError(
            f"{table.path.name}: {column} does not increase at line {int(table.lines[i])} "
            f"({values[i]:g} after {values[i - 1]:g}); {bad.size} such step(s)",
            hint="timestamps must be strictly increasing; sort the log and drop duplicates",
        )


def require_nonnegative(table: Table, column: str) -> None:
    values = table.numeric[column]
    bad = values < 0
    if bad.any():
        raise InputError(
            f"{table.path.name}: column {column} must not be negative; negative at "
            f"{lines_text(table.lines[bad])}"
        )


def require_min_rows(table: Table, n_min: int, purpose: str) -> None:
    if table.n_rows < n_min:
        raise InputError(f"{table.path.name} has {table.n_rows} data rows; {purpose} needs at least {n_min}")


def _format_column(values: np.ndarray) -> list[str]:
    if values.dtype.kind in "iub":
        return [str(int(v)) for v in values]
    if values.dtype.kind == "f":
        return [f"{v:.9g}" for v in values.tolist()]
    return [str(v) for v in values]


def write_table(path: Path, columns: dict[str, np.ndarray], force: bool = False) -> Path:
    """Write columns (each (n,)) as CSV, atomically. Refuses to overwrite unless ``force``."""
    formatted = [_format_column(np.asarray(v)) for v in columns.values()]
    lines = [",".join(columns)] + [",".join(cells) for cells in zip(*formatted, strict=True)]
    files.write_atomic(Path(path), "\n".join(lines) + "\n", force=force)
    return path
