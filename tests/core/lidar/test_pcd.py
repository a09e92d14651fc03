"""PCD v0.7 and plain arrays: every DATA kind, bounded, and a lying header named by its field."""

from __future__ import annotations

import io

import numpy as np
import pytest

from calibctl.core.lidar.pcd import lzf_decompress, parse_array, parse_pcd
from calibctl.errors import InputError

XYZIR = np.array([[1.0, 2.0, 3.0, 10.0, 0], [4.0, 5.0, 6.0, 20.0, 1], [7.0, 8.0, 9.0, 30.0, 2]])


def header(n: int, data: str, points: int | None = None, sizes: str = "4 4 4 4 2") -> bytes:
    return (
        f"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity ring\nSIZE {sizes}\nTYPE F F F F U\n"
        f"COUNT 1 1 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS "
        f"{n if points is None else points}\n"
        f"DATA {data}\n"
    ).encode()


def records(rows: np.ndarray) -> np.ndarray:
    dt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("ring", "<u2")])
    out = np.zeros(len(rows), dt)
    for k, name in enumerate(dt.names or ()):
        out[name] = rows[:, k]
    return out


def lzf_literals(raw: bytes) -> bytes:
    """A valid LZF stream of literal runs only (<= 32 bytes each)."""
    out = bytearray()
    for i in range(0, len(raw), 32):
        chunk = raw[i : i + 32]
        out.append(len(chunk) - 1)
        out += chunk
    return bytes(out)


def test_ascii_binary_and_compressed_read_the_same_points() -> None:
    ascii_body = "".join(f"{r[0]} {r[1]} {r[2]} {r[3]} {int(r[4])}\n" for r in XYZIR)
    a = parse_pcd(header(3, "ascii") + ascii_body.encode(), "a.pcd")
    b = parse_pcd(header(3, "binary") + records(XYZIR).tobytes(), "b.pcd")
    rec = records(XYZIR)
    columns = b"".join(rec[name].tobytes() for name in rec.dtype.names or ())  # PCL: field after field
    packed = lzf_literals(columns)
    c = parse_pcd(
        header(3, "binary_compressed") + np.array([len(packed), len(columns)], "<u4").tobytes() + packed,
        "c.pcd",
    )
    for cloud in (a, b, c):
        np.testing.assert_allclose(cloud.points_m, XYZIR[:, :3])
        np.testing.assert_array_equal(cloud.ring, [0, 1, 2])
        np.testing.assert_allclose(cloud.intensity, [10, 20, 30])


def test_lzf_back_references_repeat_earlier_bytes() -> None:
    # literal "ab", then a back reference of length 4 (ctrl len field 2 -> 2 + 2) at distance 2: "abab" again
    stream = bytes([1]) + b"ab" + bytes([(2 << 5) | 0, 1])
    assert lzf_decompress(stream, 6) == b"ababab"
    with pytest.raises(InputError, match="decompresses to 6 bytes"):
        lzf_decompress(stream, 7)
    with pytest.raises(InputError, match="before the start"):
        lzf_decompress(bytes([(2 << 5) | 0, 5]), 4)


def test_nan_points_are_dropped_and_counted() -> None:
    body = b"1 2 3 4 0\nnan nan nan 0 1\n5 6 inf 1 2\n7 8 9 1 3\n"
    cloud = parse_pcd(header(4, "ascii") + body, "n.pcd")
    assert cloud.points_m.shape == (2, 3)
    assert cloud.dropped_nonfinite == 2
    np.testing.assert_array_equal(cloud.ring, [0, 3])


@pytest.mark.parametrize(
    ("blob", "field"),
    [
        (header(3, "ascii", points=4) + b"1 2 3 4 0\n1 2 3 4 0\n1 2 3 4 0\n", "WIDTH x HEIGHT"),
        (
            header(4, "ascii") + b"1 2 3 4 0\n1 2 3 4 0\n1 2 3 4 0\n",
            "POINTS says 4 but the ascii data holds 3",
        ),
        (header(3, "ascii", sizes="4 4 4 4") + b"1 2 3 4 0\n", "SIZE lists 4 entries for 5 FIELDS"),
        (header(3, "binary") + records(XYZIR).tobytes()[:-5], "POINTS says 3 but the binary data holds 2"),
        (
            header(3, "binary_compressed") + np.array([4, 999], "<u4").tobytes() + b"\0\0\0\0",
            "compressed block holds 999",
        ),
        (header(2, "ascii") + b"1 2 3\n4 5 6\n", "5 values per point, the data has 3"),
        (
            b"VERSION 0.7\nFIELDS a b\nSIZE 4 4\nTYPE F F\nCOUNT 1 1\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2\n",
            "has no x",
        ),
    ],
)
def test_a_header_that_disagrees_with_its_data_is_named(blob: bytes, field: str) -> None:
    with pytest.raises(InputError, match=field) as err:
        parse_pcd(blob, "lying.pcd")
    assert err.value.exit_code == 2
    assert "lying.pcd" in err.value.message


def test_point_count_is_bounded_before_reading() -> None:
    with pytest.raises(InputError, match="over the limit of 2"):
        parse_pcd(header(3, "ascii") + b"", "big.pcd", max_points=2)


def test_plain_arrays_npy_and_text() -> None:
    buf = io.BytesIO()
    np.save(buf, XYZIR[:, :4])
    cloud = parse_array(buf.getvalue(), "a.npy", is_npy=True)
    np.testing.assert_allclose(cloud.intensity, [10, 20, 30])
    text = parse_array(b"# x y z\n1 2 3\n4 5 nan\n", "a.txt", is_npy=False)
    assert text.points_m.shape == (1, 3) and text.dropped_nonfinite == 1
    with pytest.raises(InputError, match="expected N x 3"):
        parse_array(b"1 2 3 4 5\n", "five.txt", is_npy=False)
