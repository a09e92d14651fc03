"""The motions CSV of ``calibctl handeye``: columns, strict validation, and the file synth-motions writes.

One row per synchronised sample (header on line 1, comma-separated). For each sensor prefix
(``a`` and ``b``; ``gripper`` in the robot-arm file) the rotation is given one of three ways and the
translation in metres:

=====================================  =====================================================
rotation as a unit quaternion          ``{p}_qw, {p}_qx, {p}_qy, {p}_qz`` (Hamilton, w first)
or as a rotation vector                ``{p}_rx_rad, {p}_ry_rad, {p}_rz_rad`` (axis * angle)
or as a rotation matrix                ``{p}_r11 ... {p}_r33`` (row-major)
translation                            ``{p}_tx_m, {p}_ty_m, {p}_tz_m`` (metres)
timestamps                             ``t_s`` (shared) or ``a_t_s`` and ``b_t_s`` (each sensor's)
=====================================  =====================================================

A row holds poses ``T_wa_a``, ``T_wb_b`` (each sensor in its own fixed world; consecutive rows make
the motions) or, with ``--input motions``, relative motions ``T_a0_a1``, ``T_b0_b1`` directly.
Every problem is an InputError (exit 2) naming the file and the line.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from calibctl import files
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.handeye import Motions
from calibctl.errors import InputError
from calibctl.workflows.diagnostics import diagnostics_io as dio

QUATERNION_NORM_TOL = 1e-3  # a CSV rounded to 6 decimals is ~1e-6 off; an unnormalised average is far more
ORTHONORMAL_TOL = 1e-4
UNIT_RATIO_MAX = 50.0  # rigidly attached sensors move about as far as each other; mm vs m is 1000x
LEVER_ARM_MAX_M = 5.0  # no two sensors on one rigid body (arm, vehicle) are further apart than this
ROBOT_REACH_MAX_M = 5.0  # a base->gripper translation beyond this is millimetres, not an arm
TIME_COLUMNS = ("t_s", "a_t_s", "b_t_s")

MAX_TRANSLATION_M = 1e8  # ECEF coordinates are ~6.4e6 m; nothing a robot logs is 100 000 km away


def rotation_columns(prefix: str) -> dict[str, tuple[str, ...]]:
    return {
        "quaternion": tuple(f"{prefix}_q{c}" for c in "wxyz"),
        "rotvec": tuple(f"{prefix}_r{c}_rad" for c in "xyz"),
        "matrix": tuple(f"{prefix}_r{i}{j}" for i in "123" for j in "123"),
    }


def translation_columns(prefix: str) -> tuple[str, ...]:
    return tuple(f"{prefix}_t{c}_m" for c in "xyz")


def all_pose_columns(prefix: str) -> tuple[str, ...]:
    return tuple(c for cols in rotation_columns(prefix).values() for c in cols)


def _stack(table: dio.Table, cols: tuple[str, ...]) -> np.ndarray:
    return np.column_stack([table.numeric[c] for c in cols])


def _bad_lines(table: dio.Table, bad: np.ndarray) -> str:
    return dio.lines_text(table.lines[bad])


def read_rotations(table: dio.Table, prefix: str) -> np.ndarray:
    """(n, 3, 3) rotations of ``prefix`` from whichever complete representation the file has."""
    found = [kind for kind, cols in rotation_columns(prefix).items() if all(c in table.numeric for c in cols)]
    name = table.path.name
    if len(found) != 1:
        options = "; ".join(", ".join(c) for c in rotation_columns(prefix).values())
        raise InputError(
            f"{name}: {'no' if not found else 'more than one'} complete rotation for {prefix} "
            f"({', '.join(found) or 'none found'})",
            hint=f"give exactly one of: {options}",
        )
    kind = found[0]
    values = _stack(table, rotation_columns(prefix)[kind])
    if kind == "quaternion":
        norm = np.linalg.norm(values, axis=1)
        bad = np.abs(norm - 1.0) > QUATERNION_NORM_TOL
        if bad.any():
            first = int(np.flatnonzero(bad)[0])
            raise InputError(
                f"{name}: {prefix} quaternion not normalised at {_bad_lines(table, bad)} "
                f"(norm {norm[first]:.4f} at line {int(table.lines[first])})",
                hint="divide each quaternion by its norm (w, x, y, z order)",
            )
        return np.array([se3.rotation_from_quaternion(q / np.linalg.norm(q)) for q in values])
    if kind == "rotvec":
        angle = np.linalg.norm(values, axis=1)
        bad = angle > 2 * math.pi
        if bad.any():
            raise InputError(
                f"{name}: {prefix} rotation vector longer than a full turn at {_bad_lines(table, bad)} "
                f"(up to {angle.max():.1f}): degrees where radians are expected?",
                hint="rotation vectors are axis * angle in radians",
            )
        return np.array([se3.rotation_from_rotvec(v) for v in values])
    matrices = values.reshape(-1, 3, 3)
    error = np.array([se3.orthonormality_error(R) for R in matrices])
    bad = error > ORTHONORMAL_TOL
    if bad.any():
        raise InputError(
            f"{name}: {prefix} rotation matrix not orthonormal at {_bad_lines(table, bad)} "
            f"(|R^T R - I| or |det R - 1| up to {error.max():.2g})",
            hint="a rotation matrix has orthonormal rows and determinant +1; re-export it at full precision",
        )
    return matrices


def read_transforms(table: dio.Table, prefix: str) -> np.ndarray:
    """(n, 4, 4) transforms of ``prefix``."""
    R = read_rotations(table, prefix)
    t = _stack(table, translation_columns(prefix))
    bad = ~(np.abs(t) <= MAX_TRANSLATION_M).all(axis=1)
    if bad.any():  # 1e308 passed the finite check, then overflowed the solve into an SVD traceback
        raise InputError(
            f"{table.path.name}: {prefix} translation over {MAX_TRANSLATION_M:g} m at "
            f"{_bad_lines(table, bad)} (up to {np.abs(t).max():.3g} m)",
            hint="translations are in metres; is a column in another unit, or corrupt?",
        )
    return np.array([se3.transform(Ri, ti) for Ri, ti in zip(R, t, strict=True)])


def read_timestamps(table: dio.Table, max_skew_s: float) -> np.ndarray | None:
    """(n,) sample times, or None when the file has none. Unsynchronised or unsorted rows: InputError."""
    name = table.path.name
    if "a_t_s" in table.numeric or "b_t_s" in table.numeric:
        if not ("a_t_s" in table.numeric and "b_t_s" in table.numeric):
            raise InputError(f"{name}: give both a_t_s and b_t_s (or one shared t_s)")
        skew = np.abs(table.numeric["a_t_s"] - table.numeric["b_t_s"])
        bad = skew > max_skew_s
        if bad.any():
            raise InputError(
                f"{name}: unsynchronised rows: a_t_s and b_t_s differ by up to {skew.max() * 1e3:.1f} ms "
                f"at {_bad_lines(table, bad)} (limit {max_skew_s * 1e3:g} ms)",
                hint="resample b at a's timestamps (interpolate the poses), or raise --max-skew-ms",
            )
        dio.require_increasing(table, "a_t_s")
        return table.numeric["a_t_s"]
    if "t_s" in table.numeric:
        dio.require_increasing(table, "t_s")
        return table.numeric["t_s"]
    return None


def check_units(motions: Motions, path: Path, names: tuple[str, str] = ("a", "b")) -> None:
    """Rigidly attached sensors move about equally far; a 1000x ratio is millimetres against metres.

    Unless a lever arm explains it: with A X = X B, ``| |t_A| - |t_B| | <= 2 sin(theta/2) |t_X|`` for a
    motion turning by theta, so a sensor turning about its own origin (a robot arm rotating about its
    tool point: t_A ~ 0) moves far less than one on a lever arm. The verdict is millimetres only when
    most moving motions differ by more than a lever arm of ``LEVER_ARM_MAX_M`` could make them.
    """
    norm_a, norm_b = np.linalg.norm(motions.t_A_m, axis=1), np.linalg.norm(motions.t_B_m, axis=1)
    moving = (norm_a > 0) & (norm_b > 0)
    if not moving.any():
        return
    ratio = float(np.median(norm_a[moving] / norm_b[moving]))
    if 1.0 / UNIT_RATIO_MAX <= ratio <= UNIT_RATIO_MAX:
        return
    theta = np.array([se3.rotation_angle_rad(R) for R in motions.R_A])
    lever_arm_reach_m = 2.0 * np.sin(np.minimum(theta, np.pi) / 2.0) * LEVER_ARM_MAX_M
    unexplained = np.abs(norm_a - norm_b) > lever_arm_reach_m
    if np.count_nonzero(unexplained & moving) * 2 <= np.count_nonzero(moving):
        return
    big = names[0] if ratio > 1 else names[1]
    raise InputError(
        f"{path.name}: {names[0]}'s motions translate {ratio:.4g}x as far as {names[1]}'s "
        f"(median), more than a lever arm of up to {LEVER_ARM_MAX_M:g} m explains: {big}'s "
        "translations look like millimetres (or another unit), not metres",
        hint="convert every translation to metres",
    )


def read_motions(path: Path, shape: str, max_skew_s: float) -> tuple[Motions, np.ndarray | None, dio.Table]:
    """Motions from a generic CSV (``shape`` poses or motions); labels name the CSV lines."""
    optional = (*TIME_COLUMNS, *all_pose_columns("a"), *all_pose_columns("b"))
    table = dio.read_table(
        path,
        (*translation_columns("a"), *translation_columns("b")),
        optional_numeric=optional,
        what="motions CSV",
    )
    times = read_timestamps(table, max_skew_s)
    T_a, T_b = read_transforms(table, "a"), read_transforms(table, "b")
    labels = tuple(f"line {int(line)}" for line in table.lines)
    if shape == "motions":
        if table.n_rows < 2:
            raise InputError(
                f"{path.name} has {table.n_rows} motion; hand-eye needs at least 2 (about two axes)"
            )
        motions = Motions.from_transforms(T_a, T_b, labels)
    else:
        if table.n_rows < 3:
            raise InputError(
                f"{path.name} has {table.n_rows} pose rows, i.e. {max(table.n_rows - 1, 0)} motion(s); "
                "hand-eye needs at least 3 poses (2 motions about two axes)"
            )
        motions = Motions.from_poses(T_a, T_b, tuple(str(int(line)) for line in table.lines), prefix="lines ")
    check_units(motions, path)
    return motions, times, table


MATRIX_ROW_NUMBERS = 16  # a row-major 4x4 per line, as RWHE-Calib's RobotPosesVec.txt and many robot exports
_SEPARATORS = re.compile(r"[\s,;]+")


def _numbers(line: str) -> list[float] | None:
    try:
        return [float(v) for v in _SEPARATORS.split(line.strip()) if v]
    except ValueError:
        return None


def read_matrix_rows(path: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """A robot pose file without a header: one row-major 4x4 ``T_base_gripper`` (16 numbers, metres) per line,
    separated by whitespace, tabs, commas or semicolons; blank lines and ``#`` comments are skipped.

    Returns:
        ((n, 4, 4) transforms, (n,) file line numbers), or None when the first line is not all numbers
        (a CSV with a header). Any other problem is an InputError naming the line.
    """
    try:
        with files.open_regular(path) as handle:  # a FIFO is refused, not waited on
            text = handle.read().decode("utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read {path}: {getattr(exc, 'strerror', None) or exc}") from None
    rows = [
        (i, line)
        for i, line in enumerate(text.splitlines(), start=1)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not rows or _numbers(rows[0][1]) is None:
        return None
    name = path.name
    values = []
    for line_no, line in rows:
        numbers = _numbers(line)
        if numbers is None:
            raise InputError(
                f"{name} line {line_no}: not all numbers ({line.strip()[:60]!r})",
                hint="a pose file without a header has 16 numbers per line: a row-major 4x4 in metres",
            )
        if len(numbers) != MATRIX_ROW_NUMBERS:
            raise InputError(
                f"{name} line {line_no}: {len(numbers)} numbers; a pose file without a header has "
                f"{MATRIX_ROW_NUMBERS} per line (a row-major 4x4 T_base_gripper, metres)",
                hint="or write the CSV with a header: image, gripper_r11..gripper_r33 (or gripper_q*), "
                "gripper_tx_m, gripper_ty_m, gripper_tz_m",
            )
        values.append(numbers)
    T = np.array(values, np.float64).reshape(-1, 4, 4)
    lines = np.array([line_no for line_no, _ in rows], np.int64)
    bad = ~np.isfinite(T).reshape(len(T), -1).all(axis=1)
    if bad.any():
        raise InputError(
            f"{name}: non-finite numbers (nan or inf) at {dio.lines_text(lines[bad])}",
            hint="export every pose in full",
        )
    bad = np.abs(T[:, 3, :] - [0.0, 0.0, 0.0, 1.0]).max(axis=1) > ORTHONORMAL_TOL
    if bad.any():
        raise InputError(
            f"{name}: the 4x4 does not end in 0 0 0 1 at {dio.lines_text(lines[bad])}",
            hint="each line is a row-major 4x4 T_base_gripper (a column-major export ends its "
            "lines with the translation; transpose it)",
        )
    error = np.array([se3.orthonormality_error(Ti[:3, :3]) for Ti in T])
    bad = error > ORTHONORMAL_TOL
    if bad.any():
        raise InputError(
            f"{name}: rotation block not a rotation at {dio.lines_text(lines[bad])} "
            f"(|R^T R - I| or |det R - 1| up to {error.max():.2g})",
            hint="a rigid transform's 3x3 block has orthonormal rows and determinant +1; "
            "re-export it at full precision",
        )
    return T, lines


def write_motion_log(
    path: Path, t_s: np.ndarray, T_first: np.ndarray, T_second: np.ndarray, *, force: bool
) -> Path:
    """The CSV ``read_motions`` reads: t_s, a and b as quaternion + translation."""
    columns: dict[str, np.ndarray] = {"t_s": np.asarray(t_s, np.float64)}
    for prefix, T in (("a", T_first), ("b", T_second)):
        q = np.array([se3.quaternion_from_rotation(Ti[:3, :3]) for Ti in T])
        columns.update({c: q[:, i] for i, c in enumerate(rotation_columns(prefix)["quaternion"])})
        columns.update({c: T[:, i, 3] for i, c in enumerate(translation_columns(prefix))})
    return dio.write_table(path, columns, force=force)
