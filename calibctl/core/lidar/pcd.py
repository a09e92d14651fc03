"""LiDAR sweeps from bytes: PCD v0.7 (ascii, binary, binary_compressed) and plain N x 3/4 arrays.

Bounded like every reader of untrusted input: at most ``max_points`` points; a header that disagrees
with its data (field lists of different lengths, WIDTH x HEIGHT != POINTS, fewer or more rows than
POINTS, a compressed block whose sizes do not add up) is an ``InputError`` naming the header field;
non-finite points (NaN/inf, which a Velodyne driver writes for no-return) are dropped and counted.

binary_compressed is PCL's layout: uint32 compressed size, uint32 raw size, then an LZF block whose
raw bytes are the fields one after the other (column-major). LZF is decompressed here in plain Python
(``lzf_decompress``: a dozen lines, no C extension to pin); the acfr sweeps are ascii.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np

from calibctl.errors import InputError

MAX_POINTS = 5_000_000  # a 128-beam sweep is ~260k points; 20x that is no sweep
HEADER_LINES_MAX = 64
_TYPES = {
    ("F", 4): "<f4",
    ("F", 8): "<f8",
    ("I", 1): "<i1",
    ("I", 2): "<i2",
    ("I", 4): "<i4",
    ("I", 8): "<i8",
    ("U", 1): "<u1",
    ("U", 2): "<u2",
    ("U", 4): "<u4",
    ("U", 8): "<u8",
}
_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")


@dataclass(frozen=True)
class PointCloud:
    """One sweep.

    Attributes:
        points_m: (N, 3) float64 x, y, z in the LiDAR frame, metres (finite only).
        intensity: (N,) float64 or None; ring: (N,) int64 laser index or None; time_s: (N,) float64 or None.
        dropped_nonfinite: points dropped because a coordinate was NaN or infinite.
    """

    points_m: np.ndarray
    intensity: np.ndarray | None = None
    ring: np.ndarray | None = None
    time_s: np.ndarray | None = None
    dropped_nonfinite: int = 0

    def select(self, mask: np.ndarray) -> PointCloud:
        """The points where ``mask`` ((N,) bool) is true, with their fields."""

        def pick(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[mask]

        return PointCloud(
            self.points_m[mask],
            pick(self.intensity),
            pick(self.ring),
            pick(self.time_s),
            self.dropped_nonfinite,
        )


def lzf_decompress(data: bytes, raw_size: int) -> bytes:
    """LZF (liblzf) block -> its ``raw_size`` bytes; InputError when the stream is corrupt."""
    out = bytearray()
    i, n = 0, len(data)
    while i < n:
        ctrl = data[i]
        i += 1
        if ctrl < 32:  # literal run of ctrl + 1 bytes
            run = ctrl + 1
            if i + run > n:
                raise InputError("LZF literal run past the end of the compressed block")
            out += data[i : i + run]
            i += run
            continue
        length = ctrl >> 5
        if length == 7:
            if i >= n:
                raise InputError("LZF back reference cut off")
            length += data[i]
            i += 1
        if i >= n:
            raise InputError("LZF back reference cut off")
        ref = len(out) - ((ctrl & 0x1F) << 8) - data[i] - 1
        i += 1
        if ref < 0:
            raise InputError("LZF back reference before the start of the data")
        for k in range(length + 2):  # byte by byte: a reference may overlap what it writes
            out.append(out[ref + k])
        if len(out) > raw_size:
            break
    if len(out) != raw_size:
        raise InputError(f"LZF block decompresses to {len(out)} bytes, the header says {raw_size}")
    return bytes(out)


def _header(data: bytes, source: str) -> tuple[dict[str, list[str]], int]:
    fields: dict[str, list[str]] = {}
    pos = 0
    for _ in range(HEADER_LINES_MAX):
        end = data.find(b"\n", pos)
        if end < 0:
            raise InputError(f"{source}: PCD header without a DATA line", "is this a PCD file?")
        line = data[pos:end].decode("ascii", errors="replace").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        if key.upper() not in _KEYS:
            raise InputError(f"{source}: unknown PCD header line {key!r}", "is this a PCD v0.7 file?")
        fields[key.upper()] = values
        if key.upper() == "DATA":
            return fields, pos
    raise InputError(f"{source}: PCD header longer than {HEADER_LINES_MAX} lines", "is this a PCD file?")


def _int(fields: dict[str, list[str]], key: str, source: str, default: int | None = None) -> int:
    if key not in fields:
        if default is None:
            raise InputError(f"{source}: PCD header has no {key}", "a PCD v0.7 header names it")
        return default
    try:
        value = int(fields[key][0])
    except (ValueError, IndexError):
        raise InputError(f"{source}: PCD header {key} {' '.join(fields[key])!r} is not an integer") from None
    if value < 0:
        raise InputError(f"{source}: PCD header {key} is negative ({value})")
    return value


def _layout(fields: dict[str, list[str]], source: str) -> tuple[list[str], list[int], np.dtype]:
    names = fields.get("FIELDS")
    if not names:
        raise InputError(f"{source}: PCD header has no FIELDS", "a PCD v0.7 header names its fields")
    sizes, types = fields.get("SIZE", []), fields.get("TYPE", [])
    counts = fields.get("COUNT", ["1"] * len(names))
    for key, vals in (("SIZE", sizes), ("TYPE", types), ("COUNT", counts)):
        if len(vals) != len(names):
            raise InputError(
                f"{source}: PCD header {key} lists {len(vals)} entries for {len(names)} FIELDS",
                "the header disagrees with itself; re-export the cloud",
            )
    try:
        count_list = [int(c) for c in counts]
        dtypes = [np.dtype(_TYPES[(t.upper(), int(s))]) for t, s in zip(types, sizes, strict=True)]
    except (KeyError, ValueError):
        raise InputError(
            f"{source}: PCD header SIZE/TYPE {sizes}/{types} is not a type PCD defines"
        ) from None
    if any(c < 1 or c > 1024 for c in count_list):
        raise InputError(f"{source}: PCD header COUNT {counts} out of range (1..1024)")
    for axis in "xyz":
        if axis not in names:
            raise InputError(f"{source}: PCD FIELDS {' '.join(names)} has no {axis}", "a sweep needs x y z")
    dtype = np.dtype(
        [
            (f"{n}_{i}" if n == "_" else n, dt, (c,)) if c > 1 else (f"{n}_{i}" if n == "_" else n, dt)
            for i, (n, dt, c) in enumerate(zip(names, dtypes, count_list, strict=True))
        ]
    )
    return names, count_list, dtype


def parse_pcd(data: bytes, source: str, max_points: int = MAX_POINTS) -> PointCloud:
    """A PCD v0.7 file's bytes -> PointCloud (module docstring for what is refused)."""
    fields, offset = _header(data, source)
    names, counts, dtype = _layout(fields, source)
    n = _int(fields, "POINTS", source, default=-1 if "WIDTH" in fields else None)
    width, height = _int(fields, "WIDTH", source), _int(fields, "HEIGHT", source, default=1)
    if n < 0:
        n = width * height
    if width * height != n:
        raise InputError(
            f"{source}: PCD header WIDTH x HEIGHT = {width} x {height} but POINTS says {n}",
            "the header disagrees with itself; re-export the cloud",
        )
    if n > max_points:
        raise InputError(
            f"{source}: PCD header POINTS says {n} points, over the limit of {max_points}",
            "no sweep is that large; is this the right file?",
        )
    kind = (fields["DATA"] or [""])[0].lower()
    body = data[offset:]
    if kind == "ascii":
        table = _ascii_rows(body, n, sum(counts), source)
        flat = [table[:, i] for i in range(table.shape[1])]
        record = {}
        col = 0
        for name, c in zip(dtype.names or (), counts, strict=True):
            record[name] = flat[col] if c == 1 else table[:, col : col + c]
            col += c
    elif kind == "binary":
        if len(body) < n * dtype.itemsize:
            raise InputError(
                f"{source}: PCD header POINTS says {n} but the binary data holds "
                f"{len(body) // dtype.itemsize} points",
                "the file is cut short or the header lies",
            )
        rows = np.frombuffer(body, dtype, count=n)
        record = {name: rows[name] for name in dtype.names or ()}
    elif kind == "binary_compressed":
        record = _compressed_rows(body, n, dtype, source)
    else:
        raise InputError(f"{source}: PCD DATA {kind!r} is not ascii, binary or binary_compressed")
    return _cloud(record, source)


def _ascii_rows(body: bytes, n: int, width: int, source: str) -> np.ndarray:
    lines = [ln for ln in body.split(b"\n") if ln.strip()]
    if len(lines) != n:
        raise InputError(
            f"{source}: PCD header POINTS says {n} but the ascii data holds {len(lines)} rows",
            "the file is cut short or the header lies; fix POINTS/WIDTH or re-export",
        )
    try:
        table = (
            np.loadtxt(io.BytesIO(b"\n".join(lines)), dtype=np.float64, ndmin=2)
            if n
            else np.zeros((0, width))
        )
    except ValueError as exc:
        raise InputError(
            f"{source}: PCD ascii data is not {width} numbers per row ({exc})",
            "the header's FIELDS/COUNT disagree with the data",
        ) from None
    if table.shape[1] != width:
        raise InputError(
            f"{source}: PCD header FIELDS/COUNT say {width} values per point, the data has {table.shape[1]}",
            "the header disagrees with the data; re-export the cloud",
        )
    return table


def _compressed_rows(body: bytes, n: int, dtype: np.dtype, source: str) -> dict[str, np.ndarray]:
    if len(body) < 8:
        raise InputError(f"{source}: PCD binary_compressed data shorter than its 8-byte size header")
    packed, raw = (int(v) for v in np.frombuffer(body[:8], "<u4"))
    if raw != n * dtype.itemsize:
        raise InputError(
            f"{source}: PCD header POINTS says {n} ({n * dtype.itemsize} bytes) but the compressed "
            f"block holds {raw} bytes",
            "the header lies or the file is damaged",
        )
    if packed > len(body) - 8:
        raise InputError(f"{source}: PCD compressed block says {packed} bytes, the file has {len(body) - 8}")
    try:
        flat = lzf_decompress(body[8 : 8 + packed], raw)
    except InputError as exc:
        raise InputError(f"{source}: {exc.message}", "the file is damaged; re-export the cloud") from None
    record, pos = {}, 0
    for name in dtype.names or ():
        sub = dtype.fields[name][0] if dtype.fields else dtype
        size = sub.itemsize * n
        record[name] = np.frombuffer(
            flat[pos : pos + size], sub.base, count=n * max(1, sub.itemsize // sub.base.itemsize)
        )
        if sub.shape:
            record[name] = record[name].reshape(n, *sub.shape)
        pos += size
    return record


def _cloud(record: dict[str, np.ndarray], source: str) -> PointCloud:
    xyz = np.column_stack([np.asarray(record[a], np.float64).reshape(-1) for a in "xyz"])
    finite = np.isfinite(xyz).all(axis=1)

    def opt(name: str, dtype: type) -> np.ndarray | None:
        if name not in record or np.ndim(record[name]) != 1:
            return None
        return np.asarray(record[name], dtype)[finite]

    ring = opt("ring", np.float64)
    if ring is not None and (not np.isfinite(ring).all() or (ring < 0).any() or (ring > 1023).any()):
        raise InputError(
            f"{source}: PCD field ring holds values outside 0..1023", "is ring really the laser index?"
        )
    time = opt("time", np.float64)
    if time is None:
        time = opt("t", np.float64)
    return PointCloud(
        xyz[finite],
        opt("intensity", np.float64),
        None if ring is None else ring.astype(np.int64),
        time,
        int((~finite).sum()),
    )


def parse_array(data: bytes, source: str, is_npy: bool, max_points: int = MAX_POINTS) -> PointCloud:
    """A plain N x 3 (x y z) or N x 4 (x y z intensity) array: ``.npy`` or whitespace text, metres."""
    try:
        if is_npy:
            arr = np.load(io.BytesIO(data), allow_pickle=False)
        else:
            arr = np.loadtxt(
                io.BytesIO(data), dtype=np.float64, ndmin=2, comments="#"
            )  # size bounded by the caller
    except (ValueError, OSError, EOFError) as exc:
        raise InputError(f"{source}: not an N x 3 or N x 4 array of numbers ({exc})") from None
    arr = np.asarray(arr)
    if arr.ndim != 2 or arr.shape[1] not in (3, 4) or not np.issubdtype(arr.dtype, np.number):
        raise InputError(
            f"{source}: array of shape {arr.shape}, expected N x 3 (x y z) or N x 4 (x y z intensity)"
        )
    if arr.shape[0] > max_points:
        raise InputError(
            f"{source}: more than {max_points} points", "no sweep is that large; is this the right file?"
        )
    arr = arr.astype(np.float64)
    finite = np.isfinite(arr[:, :3]).all(axis=1)
    return PointCloud(
        arr[finite, :3], arr[finite, 3] if arr.shape[1] == 4 else None, dropped_nonfinite=int((~finite).sum())
    )
