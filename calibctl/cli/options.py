"""Options that several command groups share (capture, calibrate, rig), defined once so that the
command modules import this and never each other."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from calibctl.errors import UsageError

StationOption = Annotated[str | None, typer.Option("--station", help="Station id (env CALIBCTL_STATION).")]
OperatorOption = Annotated[
    str | None, typer.Option("--operator", help="Who captures (env CALIBCTL_OPERATOR).")
]
JobsOption = Annotated[
    int | None,
    typer.Option(
        "--jobs",
        "-j",
        min=1,
        show_default=False,
        help="Detection workers (a folder's images, a video's or camera's frames), and threads "
        "for the verdict solves of capture and solve (env CALIBCTL_JOBS, "
        "station file 'jobs'; default: every core this process may use). The outcomes are the same at every "
        "count.",
    ),
]
ReferenceDistanceOption = Annotated[
    str | None,
    typer.Option(
        "--reference-distance",
        metavar="D+-S",
        show_default=False,
        help="Surveyed camera-to-board-centre distance of a fixture and its one-sigma, metres (or mm "
        "suffix), "
        "e.g. 0.450+-0.0005; needs --reference-source. Judged through the lens --model solves with (auto: "
        "the "
        "model auto chooses for the session; k1k2 without --model).",
    ),
]
OverrideGaugeOption = Annotated[
    str | None,
    typer.Option(
        "--override-gauge",
        metavar="REASON",
        show_default=False,
        help="Solve a session whose metric gauge (--reference-distance) failed, or whose board revision has "
        "a failed gauge, into a calibration lint can accept; REASON is recorded in its provenance and the "
        "failed gauge stays a lint warning.",
    ),
]
TrustedKeysOption = Annotated[
    Path | None,
    typer.Option(
        "--trusted-keys",
        metavar="DIR",
        help="Folder of trusted public keys (*.pem); default: the trusted_keys setting.",
    ),
]
RigTimestampsOption = Annotated[
    Path | None,
    typer.Option(
        "--timestamps",
        show_default=False,
        help="A rig's recorder's per-frame times (CSV cam_id,frame_index,frame_time; cam_id: the member's "
        "SERIAL; frame_index: the image's place in its source's order): the members' images pair up by time.",
    ),
]
RigTimeToleranceOption = Annotated[
    float | None,
    typer.Option(
        "--time-tolerance-ms",
        show_default=False,
        help="With --timestamps: images of different cameras at most this far apart form one rig frame "
        "(default 5).",
    ),
]


def pair_mm(text: str, option: str) -> tuple[float, float]:
    """The two millimetre numbers of an ``A,B`` option (--backing-mm, --pattern-offset-mm), or a usage error
    naming the option."""
    try:
        a, b = (float(v) for v in text.split(","))
    except ValueError:
        raise UsageError(
            f"{option} {text!r} is not two numbers A,B in millimetres", f"e.g. {option} 610,850"
        ) from None
    return a, b
