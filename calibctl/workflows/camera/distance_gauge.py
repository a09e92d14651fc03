"""The gauge at the station: a board held by a fixture at a surveyed distance (seed chapter 0).

A wrong board scale s leaves K, the distortion and every residual exactly as they were and multiplies
every recovered translation by s. Only an independent metric distance can see it, so the recovered
camera-to-board-centre distance is compared with a surveyed one: a ratio outside 0.99-1.01 fails.

Two stations use it: ``calibctl check`` (poses of the fresh views with the stored intrinsics) and
``calibctl capture`` (``gauge_capture``: the captured session is solved - not stored - and the
fixture pictures' poses are fitted with those intrinsics), so a wrong scale is caught before a solve
is ever stored. Both go through one lens model: the stored calibration's at check, at capture the one
``calibrate --model`` asks for (``gauge_model``): a k1k2 lens fitted to a rendered 150 deg fisheye
session put its fixture board 13.6 % too far away (tests/workflows/camera/test_distance_gauge.py), so the
wrong lens fails a correct board (or passes a wrong one). ``--model auto`` gauges through the model
auto chooses for the session: the solve chooses it on the same corners (core.intrinsics.model_select, every
accepted view), so the capture runs that choice first; in one ``calibrate`` the solve's choice is then
the remembered answer (core.intrinsics.recent_answers), not a second ladder.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np

from calibctl.artifacts.check import DistanceCheck
from calibctl.artifacts.session import ViewCorners
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture import image_outcomes as outcomes_core
from calibctl.core.check.recheck import distance_ratio
from calibctl.core.intrinsics.model_select import select_model
from calibctl.core.intrinsics.solve import DEFAULT_MODEL, get_model, solve_intrinsics
from calibctl.core.intrinsics.validation import refit_pose
from calibctl.errors import InputError, NumericalError, UsageError, named_list
from calibctl.files import file_errors
from calibctl.workflows.camera import capture_sources as sources

RATIO_LIMITS = (0.99, 1.01)
MAX_RELATIVE_SIGMA = 0.003  # a survey looser than this cannot judge a 1 % scale error
MAX_SPREAD = 0.02  # views farther apart than this were not all in the fixture
_TEXT = re.compile(
    r"^\s*(?P<d>[0-9]*\.?[0-9]+)\s*(?:\+-|\+/-|±)\s*(?P<s>[0-9]*\.?[0-9]+)\s*(?P<unit>m|mm)?\s*$"
)
_UNIT_FACTORS = {
    10.0: "a factor of 10 (cm for m?)",
    100.0: "a factor of 100 (cm?)",
    1000.0: "a factor of 1000 (mm for m?)",
}


@dataclass(frozen=True)
class ReferenceDistance:
    distance_m: float
    sigma_m: float


def parse_reference_distance(text: str) -> ReferenceDistance:
    """``D+-S`` in metres (or with an ``mm`` suffix), e.g. ``0.600+-0.001`` or ``600+-1mm``."""
    match = _TEXT.match(text)
    if not match:
        raise UsageError(
            f"--reference-distance '{text}' is not D+-S",
            "the surveyed camera-to-board-centre distance and its one-sigma, e.g. 0.600+-0.001 (metres)",
        )
    scale = 0.001 if match.group("unit") == "mm" else 1.0
    d, s = float(match.group("d")) * scale, float(match.group("s")) * scale
    if d <= 0:
        raise UsageError(f"--reference-distance must be positive, got {text}")
    if s / d > MAX_RELATIVE_SIGMA:
        raise UsageError(
            f"--reference-distance {text}: a one-sigma of {100 * s / d:.2f} % cannot judge a 1 % scale error",
            f"survey the fixture to {100 * MAX_RELATIVE_SIGMA:.1f} % or better",
        )
    return ReferenceDistance(d, s)


AUTO = "auto"


def gauge_model(model: str | None) -> str:
    """The lens model the capture gauge solves with for a solve's ``--model`` (UsageError if unknown):
    a MODELS name, AUTO (the model auto chooses for the session, ``gauge_capture``), or DEFAULT_MODEL
    without one (a plain capture)."""
    return DEFAULT_MODEL if model is None else AUTO if model == AUTO else get_model(model).name


def judge_distance(ref: ReferenceDistance, recovered_m: np.ndarray, names: list[str]) -> DistanceCheck:
    """Compare the per-view recovered distances with the surveyed one (InputError when it cannot be
    judged)."""
    ratio, spread = distance_ratio(recovered_m, ref.distance_m)
    if spread > MAX_SPREAD:
        near, far = int(np.argmin(recovered_m)), int(np.argmax(recovered_m))
        raise InputError(
            f"the board was not held at one distance: {names[near]} at {recovered_m[near]:.3f} m, "
            f"{names[far]} at "
            f"{recovered_m[far]:.3f} m; a reference distance of {ref.distance_m:.3f} m cannot be matched "
            "by all views",
            "check with only the pictures taken with the board in the fixture",
        )
    for factor, what in _UNIT_FACTORS.items():
        for guess in (factor, 1.0 / factor):
            if abs(ratio / guess - 1.0) < 0.25:
                raise InputError(
                    f"the board is {float(np.median(recovered_m)):.3f} m away but --reference-distance says "
                    f"{ref.distance_m:g} m: off by {what}, not a scale error",
                    "give the distance in metres, e.g. 0.600+-0.001, or with an mm suffix: 600+-1mm",
                )
    if not 0.5 < ratio < 2.0:
        raise InputError(
            f"the board is {float(np.median(recovered_m)):.3f} m away, nowhere near the surveyed "
            f"{ref.distance_m:.3f} m "
            f"(ratio {ratio:.2f})",
            "put the board in the fixture, or check the surveyed distance and its units",
        )
    lo, hi = RATIO_LIMITS
    return DistanceCheck(
        reference_m=ref.distance_m,
        reference_sigma_m=ref.sigma_m,
        recovered_m=float(np.median(recovered_m)),
        spread=spread,
        ratio=ratio,
        ratio_limits=RATIO_LIMITS,
        passed=lo <= ratio <= hi,
    )


def distance_reason(d: DistanceCheck) -> str:
    """The seed's explanation of a failed gauge, with the numbers."""
    return (
        f"board distance {d.recovered_m:.4f} m is {d.ratio:.3f}x the surveyed {d.reference_m:.4f} m: the "
        "metric "
        "scale is wrong (board square size?); the residual cannot show it"
    )


def detect_fixture_views(
    spec: BoardSpec,
    board_ref: str,
    source: sources.SourceSpec,
    image_size: tuple[int, int],
    calibrated: str,
    jobs: int | None = None,
) -> tuple[list[outcomes_core.ImageOutcome], int]:
    """The accepted board views of an image source, all of ``image_size`` (InputError naming both sizes if
    not).

    Returns (accepted views with corners, images examined). ``calibrated`` names what the size belongs to;
    ``jobs``: detection workers (None: the cores available).
    """
    if source.kind not in sources.IMAGE_SETS:
        raise UsageError(
            f"the board pictures must be a folder, glob or list of images, not a {source.kind}",
            "save a few board pictures from the camera and give those",
        )
    with file_errors(f"read the source {source.kind}", source.label):
        images = sources.select_images(source)
        with sources.quiet_opencv():
            found = outcomes_core.classify_files(images.paths, spec, workers=jobs)
    found = [replace(o, name=name) for o, name in zip(found, images.names, strict=True)]
    w, h = image_size
    wrong = [o for o in found if o.image_size is not None and tuple(o.image_size) != (w, h)]
    if wrong:
        listed = named_list([f"{o.name} ({o.image_size[0]}x{o.image_size[1]})" for o in wrong], 5)  # type: ignore[index]
        raise InputError(
            f"{len(wrong)} image(s) are not {w}x{h}, the size {calibrated} was calibrated at: {listed}",
            "use images straight from the camera at its calibrated resolution; calibctl never rescales",
        )
    final = outcomes_core.finalize_session(found, (w, h))
    accepted = [o for o in final if o.accepted and o.corner_ids is not None]
    if not accepted:
        raise InputError(
            f"no board {board_ref} was found in the {len(final)} image(s) of {source.label}",
            "show the board the calibration was made with, whole and sharp",
        )
    return accepted, len(final)


def board_distances_m(
    spec: BoardSpec,
    views: Sequence[outcomes_core.ImageOutcome],
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    model: str,
) -> np.ndarray:
    """(V,) metres from the camera centre to the centre of the corners seen, poses fitted with the lens
    frozen."""
    obj = spec.object_points()
    out = []
    for v in views:
        o = obj[np.asarray(v.corner_ids)]
        _, rvec, tvec = refit_pose(o, np.asarray(v.corners_px), camera_matrix, dist_coeffs, model)
        R = cv2.Rodrigues(rvec.reshape(3, 1))[0]
        out.append(float(np.linalg.norm(R @ o.mean(axis=0) + tvec)))
    return np.array(out)


def gauge_capture(
    ref: ReferenceDistance,
    fixture: str,
    spec: BoardSpec,
    board_ref: str,
    views: Sequence[ViewCorners],
    image_size: tuple[int, int],
    model: str,
    jobs: int | None = None,
) -> tuple[DistanceCheck, str]:
    """The gauge at capture: solve the captured views with ``model`` (a MODELS name, the lens the session
    will be solved with, or AUTO: the model ``--model auto`` chooses for them; not stored), then judge
    the board distance of the ``fixture`` pictures through that lens. Returns the verdict and the lens.
    Raises CalibctlError (exit 2) when it cannot be judged (see ``judge_distance``,
    ``detect_fixture_views``) or the session cannot be solved with ``model``."""
    obj = spec.object_points()
    session_obj = [obj[np.asarray(v.corner_ids)] for v in views]
    session_px = [np.asarray(v.corners_px, np.float64) for v in views]
    try:
        if (
            model == AUTO
        ):  # the solve's own choice on these corners (workflows.camera.solve): its fit, no uncertainty
            chosen = select_model(session_obj, session_px, image_size)
            lens, fit = chosen.chosen, chosen.solution
        else:
            lens, fit = model, solve_intrinsics(session_obj, session_px, image_size, model, uncertainty=False)
    except NumericalError as exc:
        raise NumericalError(
            f"the distance gauge cannot judge this session: its {len(views)} views do not solve with the "
            f"{model} "
            f"lens model ({exc.message}); no session was stored",
            f"{exc.hint}; or gauge with the model the lens needs (--model)"
            if exc.hint
            else "gauge with the model the lens needs (--model)",
        ) from exc
    fixture_views, _ = detect_fixture_views(
        spec, board_ref, sources.resolve_source(fixture), image_size, "this session", jobs
    )
    distances = board_distances_m(spec, fixture_views, fit.camera_matrix, fit.dist_coeffs, lens)
    return judge_distance(ref, distances, [v.name for v in fixture_views]), lens
