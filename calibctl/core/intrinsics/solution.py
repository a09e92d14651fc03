"""The vocabulary of an intrinsic solve: the lens-model table, the solution type and the input and output
checks that every solver (OpenCV's pinhole solve in ``solve``, calibctl's fisheye LM in
``fisheye_solve``) shares. Kept apart from the solvers so that neither imports the other for it.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from calibctl.core.blas_threads import single_threaded
from calibctl.core.intrinsics.covariance import IntrinsicCovariance
from calibctl.core.intrinsics.model_names import (
    DEFAULT_MODEL as DEFAULT_MODEL,  # the solve's default, re-exported
)
from calibctl.errors import InputError, NumericalError, UsageError

# Below this many degrees of freedom (residuals - parameters) the residual variance that scales
# the covariance is itself too uncertain: its relative std is sqrt(2 / dof), 20 % at 50.
MIN_SIGMA_DOF = 50
NO_UNCERTAINTY = "not computed: a fit solved only for its numbers (uncertainty=False)"
# OpenCV needs a homography per view for its initial guess: at least 4 corners.
MIN_CORNERS_PER_VIEW = 4
# A solve is declared diverged when it leaves the space of plausible pinhole cameras:
# focal length under MIN_FOCAL_FRAC * max(W, H) (a field of view over ~160 deg, which the
# pinhole + polynomial models cannot represent anyway), principal point more than one image size
# outside the image, or an RMS above MAX_RMS_PX (50x a sub-pixel detector's; the model explains
# nothing: mis-ordered corners, mixed boards, wrong board geometry).
MIN_FOCAL_FRAC = 0.1
MAX_RMS_PX = 10.0

DISTORTION_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")
FISHEYE_DIST_NAMES = ("k1", "k2", "k3", "k4")


# OpenCV 5 names these flags at the top level; OpenCV 4.x only in cv2.fisheye, with other values. The
# fisheye solve is calibctl's own and only records them, so the OpenCV 5 values serve on both.
CALIB_RECOMPUTE_EXTRINSIC = int(getattr(cv2, "CALIB_RECOMPUTE_EXTRINSIC", 1 << 23))
CALIB_FIX_SKEW = int(getattr(cv2, "CALIB_FIX_SKEW", 1 << 25))


@dataclass(frozen=True)
class DistortionModel:
    """One row of the model table: OpenCV flags and which parameters they leave free."""

    name: str
    flags: int
    free_intrinsics: tuple[str, ...]  # fx is listed but tied to fy when fx_tied_to_fy
    free_distortion: tuple[str, ...]
    n_coeffs: int  # length of the recorded distortion vector (5 or 8)
    min_views: int
    description: str
    kind: str = (
        "pinhole"  # "fisheye": equidistant Kannala-Brandt, solved by calibctl.core.intrinsics.fisheye_solve
    )

    @property
    def fx_tied_to_fy(self) -> bool:
        return self.kind == "pinhole" and bool(self.flags & cv2.CALIB_FIX_ASPECT_RATIO)

    @property
    def n_free_intrinsic_params(self) -> int:
        """Free non-pose parameters: intrinsics (fx counts 0 when tied) + distortion."""
        return len(self.free_intrinsics) - int(self.fx_tied_to_fy) + len(self.free_distortion)


_ASPECT = cv2.CALIB_FIX_ASPECT_RATIO
_FOCAL = ("fx", "fy", "cx", "cy")
MODELS: Mapping[str, DistortionModel] = {
    m.name: m
    for m in (
        DistortionModel(
            "k1k2",
            cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST | _ASPECT,
            _FOCAL,
            ("k1", "k2"),
            5,
            3,
            "production default (seed ch.1): fx=fy*a, k1 k2 free",
        ),
        DistortionModel(
            "k1k2k3",
            cv2.CALIB_ZERO_TANGENT_DIST | _ASPECT,
            _FOCAL,
            ("k1", "k2", "k3"),
            5,
            3,
            "k3 free, no tangential, fx=fy*a",
        ),
        DistortionModel(
            "k1k2p1p2k3",
            _ASPECT,
            _FOCAL,
            ("k1", "k2", "p1", "p2", "k3"),
            5,
            4,
            "full 5-term Brown-Conrady, fx=fy*a",
        ),
        DistortionModel(
            "rational",
            cv2.CALIB_RATIONAL_MODEL | _ASPECT,
            _FOCAL,
            DISTORTION_NAMES,
            8,
            5,
            "OpenCV rational 8-term model, fx=fy*a",
        ),
        DistortionModel(
            "opencv-default",
            0,
            _FOCAL,
            ("k1", "k2", "p1", "p2", "k3"),
            5,
            3,
            "plain OpenCV flags=0: fx and fy independent; for reference reproduction",
        ),
        DistortionModel(
            "fisheye",
            cv2.CALIB_USE_INTRINSIC_GUESS | CALIB_RECOMPUTE_EXTRINSIC | CALIB_FIX_SKEW,
            _FOCAL,
            FISHEYE_DIST_NAMES,
            4,
            3,
            "equidistant Kannala-Brandt (cv2.fisheye, ROS equidistant): fx fy cx cy k1..k4, skew 0",
            kind="fisheye",
        ),
    )
}


def get_model(name: str) -> DistortionModel:
    """Look a model up by name; UsageError naming the choices otherwise."""
    try:
        return MODELS[name]
    except KeyError:
        raise UsageError(
            f"unknown distortion model {name!r}", hint=f"choose one of: {', '.join(MODELS)} (or 'auto')"
        ) from None


@dataclass(frozen=True)
class IntrinsicsSolution:
    """Result of one intrinsic solve. Arrays are read-only.

    Attributes:
        model: DistortionModel name.
        image_size: (width, height) px the corners were detected at.
        camera_matrix: (3, 3) float64 K, px.
        dist_coeffs: (n_coeffs,) float64, OpenCV order k1 k2 p1 p2 k3 [k4 k5 k6].
        rms_px: OpenCV's RMS over all corners (2-D distance), px.
        per_view_rms_px: (V,) float64 per-view RMS, same definition.
        rvecs: (V, 3) float64 Rodrigues board->camera rotations. tvecs: (V, 3) board units.
        residuals_px: V arrays (N_i, 2) float64, observed - projected.
        sigma: one-sigma per FREE parameter, by name (fx fy cx cy px; k*, p* unitless). Empty
            when refused. Under a tied aspect ratio sigma['fx'] = aspect_ratio * sigma['fy'].
        sigma_refused_reason: why sigma is empty, else None.
        n_residuals: 2 * corners. n_parameters: free intrinsics + distortion + 6 per view.
        aspect_ratio: fx/fy held fixed during the solve, or None when fx and fy were free.
        covariance: the intrinsic covariance sigma comes from (calibctl.core.intrinsics.covariance), with
            its names, reciprocal condition number and residual variance.
        sigma_opencv: OpenCV's raw stdDeviationsIntrinsics for the free parameters, for reference
            only (0 for fx when tied; unreliable when nearly unobservable, see covariance.py).
    """

    model: str
    image_size: tuple[int, int]
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    rms_px: float
    per_view_rms_px: np.ndarray
    rvecs: np.ndarray
    tvecs: np.ndarray
    residuals_px: tuple[np.ndarray, ...]
    sigma: Mapping[str, float] = field(default_factory=dict)
    sigma_refused_reason: str | None = None
    n_residuals: int = 0
    n_parameters: int = 0
    aspect_ratio: float | None = None
    covariance: IntrinsicCovariance | None = None
    sigma_opencv: Mapping[str, float] = field(default_factory=dict)

    @property
    def fx(self) -> float:
        return float(self.camera_matrix[0, 0])

    @property
    def fy(self) -> float:
        return float(self.camera_matrix[1, 1])

    @property
    def cx(self) -> float:
        return float(self.camera_matrix[0, 2])

    @property
    def cy(self) -> float:
        return float(self.camera_matrix[1, 2])

    @property
    def dof(self) -> int:
        return self.n_residuals - self.n_parameters

    @property
    def n_views(self) -> int:
        return len(self.residuals_px)


# Where a warm start's Levenberg-Marquardt stops (cv2.TermCriteria: at most 100 iterations, as OpenCV's
# documented default, or an accepted step whose norm is under WARM_STEP_EPS). A solve started from the solve
# of more of the same views sits next to its minimum; under OpenCV's default (DBL_EPSILON) it takes 20-odd
# steps, most of them far below any printed digit. Stopped at 1e-10 it takes about half as many and lands
# within ~1e-8 of the same K and distortion (benchmarks/bench_warm_folds.py). Cold solves keep OpenCV's own
# criteria: far from their minimum, a run of rejected steps can leave an accepted one tiny, and a step
# tolerance would end the solve there.
WARM_STEP_EPS = 1e-10
WARM_CRITERIA = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, WARM_STEP_EPS)


@contextlib.contextmanager
def single_threaded_opencv() -> Iterator[None]:
    """Run OpenCV and the BLAS / OpenMP libraries single-threaded inside the block (bit-identical
    results, no spinning BLAS threads), restore afterwards (``core.blas_threads.single_threaded``).

    The counts are process-global, so this is not a per-thread setting: code that solves on several
    Python threads enters the block once around the whole pool (``validate_holdout``). Inside it, nested
    blocks see 1 thread already and change nothing, so one thread leaving its block never gives OpenCV
    its threads back while another thread's solve is running.
    """
    with single_threaded():
        yield


def readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


def check_inputs(
    object_points: Sequence[np.ndarray],
    image_points: Sequence[np.ndarray],
    image_size: tuple[int, int],
    model: DistortionModel,
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Validate shapes, finiteness, counts; return float32 copies the way OpenCV wants them."""
    width, height = (int(v) for v in image_size)
    if width <= 0 or height <= 0 or (width, height) != tuple(image_size):
        raise InputError(f"image size must be two positive integers (width, height), got {image_size}")
    if len(object_points) != len(image_points):
        raise InputError(f"{len(object_points)} object-point views but {len(image_points)} image-point views")
    n_views = len(image_points)
    if n_views < model.min_views:
        raise NumericalError(
            f"model {model.name} needs at least {model.min_views} board views, got {n_views}",
            hint="capture more views tilted 20-40 deg in at least three directions, "
            "or ask for a model with fewer coefficients (--model k1k2)",
        )
    objs, imgs = [], []
    for i, (obj, img) in enumerate(zip(object_points, image_points, strict=True)):
        obj = np.asarray(obj, dtype=np.float64).reshape(-1, 3)
        img = np.asarray(img, dtype=np.float64).reshape(-1, 2)
        if obj.shape[0] != img.shape[0]:
            raise InputError(f"view {i}: {obj.shape[0]} model points but {img.shape[0]} corners")
        if not (np.isfinite(obj).all() and np.isfinite(img).all()):
            raise InputError(
                f"view {i}: corners or model points contain NaN or infinity",
                hint="re-run detection for this view or drop it",
            )
        if obj.shape[0] < MIN_CORNERS_PER_VIEW:
            raise NumericalError(
                f"view {i} has {obj.shape[0]} corners; at least {MIN_CORNERS_PER_VIEW} are needed per view",
                hint="drop that view",
            )
        outside = (img[:, 0] < -1) | (img[:, 0] > width) | (img[:, 1] < -1) | (img[:, 1] > height)
        if outside.any():
            u, v = img[np.argmax(outside)]
            raise InputError(
                f"view {i}: corner ({u:.1f}, {v:.1f}) lies outside the {width}x{height} image",
                hint="the image size must be the resolution the corners were detected at",
            )
        objs.append(obj.astype(np.float32))
        imgs.append(img.astype(np.float32))
    return objs, imgs


def residual_rms_px(residuals: np.ndarray) -> float:
    """sqrt(mean squared 2-D residual length) of (N, 2) px, OpenCV's per-view RMS; nan for N = 0."""
    if len(residuals) == 0:
        return float("nan")
    return float(np.sqrt(np.mean(np.sum(residuals**2, axis=1))))


def too_few_dof_covariance(n_residuals: int, n_parameters: int) -> IntrinsicCovariance:
    """The covariance refused for a fit with under MIN_SIGMA_DOF degrees of freedom."""
    dof = n_residuals - n_parameters
    return IntrinsicCovariance(
        (),
        None,
        float("nan"),
        float("nan"),
        (
            f"only {dof} degrees of freedom ({n_residuals} residuals - {n_parameters} parameters); at least "
            f"{MIN_SIGMA_DOF} are needed for the residual variance to mean anything"
        ),
    )


def parameter_count(model: DistortionModel, n_views: int) -> int:
    """Free parameters of a solve: intrinsics + distortion + 6 pose parameters per view."""
    return model.n_free_intrinsic_params + 6 * n_views


def check_output(
    K: np.ndarray,
    dist: np.ndarray,
    rms: float,
    rvecs: np.ndarray,
    tvecs: np.ndarray,
    image_size: tuple[int, int],
) -> None:
    if not (
        np.isfinite(K).all()
        and np.isfinite(dist).all()
        and math.isfinite(rms)
        and np.isfinite(rvecs).all()
        and np.isfinite(tvecs).all()
    ):
        raise NumericalError(
            "the solve returned NaN or infinite values",
            hint="the views do not constrain the model; capture tilted views "
            "or use a model with fewer coefficients",
        )
    width, height = image_size
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    min_f = MIN_FOCAL_FRAC * max(width, height)
    if min(fx, fy) < min_f or not (-width <= cx <= 2 * width and -height <= cy <= 2 * height):
        raise NumericalError(
            f"the solve diverged: fx={fx:.4g} fy={fy:.4g} cx={cx:.4g} cy={cy:.4g} px "
            f"for a {width}x{height} image (focal length must be at least {min_f:.4g} px, "
            "principal point within one image size of the image)",
            hint="capture views tilted 20-40 deg in at least three directions covering the image",
        )
    if rms > MAX_RMS_PX:
        raise NumericalError(
            f"the solve does not explain the corners: RMS {rms:.2f} px (limit {MAX_RMS_PX:.0f} px)",
            hint="check the corner order and that every view shows the declared board",
        )
