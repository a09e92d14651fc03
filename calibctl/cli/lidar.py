"""calibctl lidar solve / synth: camera-LiDAR extrinsics from a board both sensors see (docs/lidar.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.options import pair_mm
from calibctl.cli.render import emit_json, say
from calibctl.errors import UsageError

lidar_app = typer.Typer(
    name="lidar",
    help="Camera-LiDAR extrinsics: T_lidar_cam from a board seen by both, gated, with one-sigma.",
    no_args_is_help=True,
    rich_markup_mode=None,
)
JsonFlag = Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")]


def _pair_m(text: str, option: str) -> tuple[float, float]:
    a_mm, b_mm = pair_mm(text, option)
    return a_mm / 1e3, b_mm / 1e3


def _num(value: float | None, spec: str = ".1f") -> str:
    return "-" if value is None else format(value, spec)


def render_result(doc: dict[str, Any]) -> None:
    """Human report of ``lidar_solve.result_json``'s document."""
    counts = ", ".join(f"{k} {v}" for k, v in sorted(doc["outcome_counts"].items()))
    say(f"lidar solve: lens {doc['lens']} ({doc['lens_model']}); scans: {counts}")
    for r in doc["outcomes"]:
        name = r["scan"] or r["image"]
        frame = str(r["frame"]) if r["frame"] is not None else "-"
        say(f"  {frame:>5} {name:<24} {r['outcome']:<19} {r['message']}")
    for g in doc["gates"]:
        say(f"  gate {g['gate']:<20}{'pass' if g['passed'] else 'FAIL'}  {g['message']}")
        if not g["passed"] and g["hint"]:
            say(f"       hint: {g['hint']}")
    t = doc["transform"]
    if t is not None:
        m = doc["metrics"]
        say(f"{t['name']} ({t['convention']}):")
        say(
            "  translation "
            + ", ".join(
                f"{a} {v * 1e3:+.1f} +/- {s:.1f} mm"
                for a, v, s in zip("xyz", t["translation_m"], t["sigma_translation_mm"], strict=True)
            )
        )
        say(
            "  rotation    roll {:+.4f} pitch {:+.4f} yaw {:+.4f} rad (Rz Ry Rx)".format(*t["rpy_rad"])
            + "; sigma about x, y, z "
            + ", ".join(f"{v:.3f}" for v in t["sigma_rotation_deg"])
            + " deg"
        )
        say(
            f"  point-to-plane RMS {_num(m['plane_rms_mm'])} mm "
            f"(held-out {_num(m['held_out_plane_rms_mm'])} mm, "
            f"{m['folds']}-fold), edge RMS {_num(m['edge_rms_mm'])} mm "
            f"({_num(m['projected_edge_rms_px'])} px in "
            f"the image, held-out {_num(m['held_out_edge_rms_mm'])} mm, "
            f"{_num(m['held_out_projected_edge_rms_px'])} px)"
            f"; board dimension error {_num(m['dimension_error_mean_mm'][0], '+.1f')}, "
            f"{_num(m['dimension_error_mean_mm'][1], '+.1f')} mm"
        )
        say(
            "  range offset the board sizes ask for "
            f"{_num(m['range_offset_from_dimensions_mm'], '+.1f')} +/- "
            f"{_num(m['range_offset_from_dimensions_sigma_mm'])} mm"
            + (
                ""
                if m["range_offset_estimated_mm"] is None
                else f"; estimated in the solve {_num(m['range_offset_estimated_mm'], '+.1f')} +/- "
                f"{_num(m['range_offset_estimated_sigma_mm'])} mm"
            )
        )
    for note in doc.get("notes", []):
        say(f"  note: {note}")
    if doc["status"] == "accepted":
        say("Result: ACCEPTED")
    else:
        failed = [g["message"] for g in doc["gates"] if not g["passed"]]
        say("Result: REJECTED" + ("" if t else " (no transform reported)") + ": " + "; ".join(failed))


@lidar_app.command("solve")
def solve(
    ctx: typer.Context,
    images: Annotated[Path, typer.Option("--images", help="Folder of the camera's images of the board.")],
    scans: Annotated[
        Path,
        typer.Option(
            "--scans",
            help="Folder of LiDAR sweeps (.pcd, .npy, N x 3/4 text); "
            "paired with images by the last number in the file name.",
        ),
    ],
    box: Annotated[
        str,
        typer.Option(
            "--box",
            help="Station box xmin,ymin,zmin,xmax,ymax,zmax, metres, LiDAR frame: where the board is held.",
        ),
    ],
    board_ref: Annotated[
        str | None,
        typer.Option(
            "--board", help="Registered board NAME[@REV] with its backing board (board add ... --backing-mm)."
        ),
    ] = None,
    cols: Annotated[
        int | None, typer.Option("--cols", min=2, help="Without --board: inner corners per row.")
    ] = None,
    rows: Annotated[
        int | None, typer.Option("--rows", min=2, help="Without --board: inner corners per column.")
    ] = None,
    square_mm: Annotated[
        float | None, typer.Option("--square-mm", min=0.01, help="Without --board: square, mm.")
    ] = None,
    backing_mm: Annotated[
        str | None,
        typer.Option(
            "--backing-mm", help="Without --board: backing board W,H mm (W along the rows of --cols corners)."
        ),
    ] = None,
    pattern_offset_mm: Annotated[
        str,
        typer.Option(
            "--pattern-offset-mm",
            help="Without --board: pattern centre minus backing centre X,Y mm, pattern axes.",
        ),
    ] = "0,0",
    camera_info: Annotated[
        Path | None, typer.Option("--camera-info", help="ROS camera_info YAML (fisheye or plumb_bob).")
    ] = None,
    serial: Annotated[
        str | None, typer.Option("--serial", help="Use this camera's active calibration.")
    ] = None,
    scan_pattern: Annotated[str, typer.Option("--scan-pattern", help="Glob of the sweeps in --scans.")] = "*",
    scan_units: Annotated[
        str, typer.Option("--scan-units", help="m or mm: the unit the sweeps are written in.")
    ] = "m",
    range_offset_mm: Annotated[
        float,
        typer.Option("--range-offset-mm", help="Add this to every range first (acfr's distance_offset_mm)."),
    ] = 0.0,
    estimate_range_offset: Annotated[
        bool, typer.Option("--estimate-range-offset", help="Solve for one range offset too.")
    ] = False,
    min_rings: Annotated[int, typer.Option("--min-rings", min=2, help="Rings the board must span.")] = 7,
    max_dimension_error_mm: Annotated[
        float, typer.Option("--max-dimension-error-mm", min=1.0, help="Per scan: accepted board size error.")
    ] = 50.0,
    min_poses: Annotated[int, typer.Option("--min-poses", min=3, help="Accepted poses the solve needs.")] = 6,
    folds: Annotated[int, typer.Option("--folds", min=2, help="k of the k-fold held-out check.")] = 5,
    out: Annotated[Path | None, typer.Option("-o", "--out", help="Write the result JSON here.")] = None,
    tf_static: Annotated[
        Path | None, typer.Option("--tf-static", help="Write T as /tf_static YAML (accepted only).")
    ] = None,
    overlay: Annotated[
        Path | None,
        typer.Option(
            "--overlay",
            help="Folder for each accepted image with the LiDAR points drawn over it through the solved T.",
        ),
    ] = None,
    lidar_frame: Annotated[str, typer.Option("--lidar-frame", help="tf parent frame name.")] = "lidar",
    camera_frame: Annotated[str, typer.Option("--camera-frame", help="tf child frame name.")] = "camera",
    force: Annotated[
        bool, typer.Option("--force", help="Overwrite --out, --tf-static and --overlay files.")
    ] = False,
    rig: Annotated[
        str | None,
        typer.Option(
            "--rig",
            help="Store the result as the rig's next version: edge "
            "LIDAR_FRAME -> SERIAL of its tree (rejected results never active).",
        ),
    ] = None,
    json_output: JsonFlag = False,
) -> None:
    """Solve T_lidar_cam; exit 1 when a gate rejects the set or the transform."""
    from calibctl.cli.stored_edge import finish_solve
    from calibctl.core.lidar.target import BackingBoard
    from calibctl.workflows.lidar import lidar_run
    from calibctl.workflows.lidar import lidar_solve as wf

    if scan_units not in ("m", "mm"):
        raise UsageError(f"--scan-units {scan_units!r} is not m or mm")
    board: BackingBoard | str
    if board_ref is not None:
        if any(v is not None for v in (cols, rows, square_mm, backing_mm)):
            raise UsageError(
                "give the target as --board NAME or as --cols/--rows/--square-mm/--backing-mm, not both"
            )
        board = board_ref
    else:
        if cols is None or rows is None or square_mm is None or backing_mm is None:
            raise UsageError(
                "the target needs --board NAME, or all of --cols, --rows, --square-mm and --backing-mm",
                "register it once: calibctl board add NAME ... --backing-mm W,H",
            )
        board = BackingBoard(
            cols,
            rows,
            square_mm / 1e3,
            _pair_m(backing_mm, "--backing-mm"),
            _pair_m(pattern_offset_mm, "--pattern-offset-mm"),
        )
    req = wf.LidarRequest(
        images,
        scans,
        board,
        wf.parse_box(box),
        camera_info,
        serial,
        scan_pattern,
        1e-3 if scan_units == "mm" else 1.0,
        range_offset_mm / 1e3,
        estimate_range_offset,
        min_rings,
        max_dimension_error_mm / 1e3,
        min_poses,
        folds,
        overlay,
        force,
    )
    described = (
        board_ref
        or f"{cols}x{rows} corners, {square_mm:g} mm, backing {backing_mm} mm, offset {pattern_offset_mm} mm"
    )
    target = None if rig is None else lidar_run.RigTarget(rig, lidar_frame, described)
    files = lidar_run.LidarFiles(out, tf_static, lidar_frame, camera_frame, force)
    outcome = lidar_run.run_lidar(state(ctx).settings(), req, files, target)
    doc = wf.result_json(outcome)
    as_json = wants_json(ctx, json_output)
    finish_solve(doc, as_json, render_result, outcome.accepted, outcome.stored, outcome.written)


@lidar_app.command("synth")
def synth(
    ctx: typer.Context,
    out: Annotated[Path, typer.Argument(metavar="OUT_DIR", help="Folder for images/, scans/, truth.json.")],
    poses: Annotated[int, typer.Option("--poses", min=1, help="Board poses to render.")] = 12,
    seed: Annotated[int, typer.Option("--seed", help="Random seed.")] = 0,
    range_offset_mm: Annotated[float, typer.Option("--range-offset-mm", help="Ranges short by this.")] = 0.0,
    one_way: Annotated[bool, typer.Option("--one-way", help="Every board faces the LiDAR squarely.")] = False,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing set.")] = False,
    serial: Annotated[
        str | None,
        typer.Option(
            "--serial",
            metavar="SERIAL[@N]",
            help="Render through this camera's stored lens (default: its active calibration), e.g. the rig "
            "member `lidar solve --rig RIG --serial SERIAL` solves for.",
        ),
    ] = None,
    json_output: JsonFlag = False,
) -> None:
    """Render a camera + VLP-16-like LiDAR set with known T_lidar_cam (truth.json beside it)."""
    from calibctl.workflows.lidar.lidar_synth import run_lidar_synth, stored_lens

    lens = None if serial is None else stored_lens(state(ctx).settings(), serial)
    result = run_lidar_synth(out, poses, seed, range_offset_mm / 1e3, one_way, force, lens)
    if wants_json(ctx, json_output):
        emit_json(result)
        return
    through = f" through {result['camera']}'s lens" if result["camera"] else ""
    box = result["box"]
    say(f"{poses} poses (seed {seed}){through} in {out}; truth {result['truth']}; station box {box}")


def register(app: typer.Typer) -> None:
    """Add the ``lidar`` command group to the root app."""
    app.add_typer(lidar_app, name="lidar")
