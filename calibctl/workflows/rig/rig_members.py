"""How ``rig solve-folders`` judges each self-calibrated member: by the stored path's own verdict.

The stored path (``capture``, ``solve``, then ``rig solve``, whose lint names every member's findings
``member:<rule>``) refuses a member whose capture gates fail (the session is rejected and ``solve`` refuses
it) or whose calibration lint fails. Here each camera's photos go through the same functions, in memory,
nothing stored: the capture session (workflows.camera.capture.photos_session: observability, views,
one_camera, the decisive projection gate over the station's region, tilt and coverage as guidance) and, when
it passes, the solve with its lint (workflows.camera.solve.build_artifact: principal-point, sigma-fx,
outer-ring-holdout, model-misfit, one-camera, aspect-ratio, distortion-foldover over the observed region).
Findings carry the stored path's names: ``member:<gate>`` for a failed capture gate, ``member:<rule>`` for a
lint finding.

Not applied, and why:
- ``square-size-provenance``: the square size is what ``--square-mm`` typed; no board registry says how it was
  measured, so every run would fail it. Register the board (``board add``) and use ``rig capture`` + ``rig
  solve`` to have it judged.
- ``rig-stale-member``: there is no stored member version to go stale.
- ``metric-gauge``: not a member rule; ``--reference-distance`` judges it for the whole run
  (``rig_folders.gauge_finding``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from calibctl.artifacts.board import BoardRevision, SquareMeasurement
from calibctl.artifacts.common import utc_now
from calibctl.artifacts.lint import Finding
from calibctl.config import Settings
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture.image_outcomes import ImageOutcome
from calibctl.workflows.camera import capture_sources
from calibctl.workflows.camera.capture import CaptureRequest, photos_session
from calibctl.workflows.camera.solve import SolveRequest, build_artifact
from calibctl.workflows.rig.rig_lint import member_finding

MEMBER_SERIAL = "solve-folders-member"  # the in-memory session's serial; every finding names the camera
BOARD_NAME = "solve-folders"
NOT_APPLIED = ("square-size-provenance",)
# A member's gates and lint are scale-free (the board poses scale with the square, the intrinsics do not): a
# square the board registry refuses (>= 1 m: unit squares, as in OpenCV's stereo sample) is judged at this
# size.
SCALE_FREE_SQUARE_M = 0.1


def typed_board(spec: BoardSpec, operator: str) -> BoardRevision:
    """The board as ``--cols --rows --square-mm`` typed it: a nominal square size."""
    return BoardRevision(
        name=BOARD_NAME,
        revision=1,
        kind="chessboard",
        cols=spec.cols,
        rows=spec.rows,
        measurement=SquareMeasurement(status="nominal", square_size_m=spec.square_size_m),
        created_at=utc_now(),
        created_by=operator,
    )


def member_findings(
    settings: Settings,
    camera: str,
    source: capture_sources.SourceSpec,
    outcomes: Sequence[ImageOutcome],
    max_gray: np.ndarray | None,
    spec: BoardSpec,
    model: str,
) -> list[Finding]:
    """The stored path's verdict on one camera's photos (module docstring), as rig findings."""
    if not spec.square_size_m < 1.0:
        spec = replace(spec, square_size_m=SCALE_FREE_SQUARE_M)
    board = typed_board(spec, settings.operator)
    request = CaptureRequest(
        serial=MEMBER_SERIAL,
        board=board.ref,
        source=source.label,
        lens_model=None if model == "auto" else model,
    )
    session = photos_session(settings, request, board, spec, source, outcomes, max_gray)
    if session.status != "accepted":
        return [
            Finding(
                rule=f"member:{g.gate}",
                severity="error",
                value=g.value,
                threshold=g.threshold,
                message=f"{camera}: the capture gate {g.gate} fails ({g.reason or 'failed'}: {g.value:.4g}, "
                f"threshold {g.threshold:.4g}): the stored path would not solve this camera",
                fix=g.hint,
            )
            for g in session.gates
            if not g.passed and not g.advisory
        ]
    art, _ = build_artifact(session, SolveRequest(model=model), settings)
    return [member_finding(camera, f) for f in art.lint if f.rule not in NOT_APPLIED]
