"""The camera calibration artifact: immutable, serial-keyed, self-describing and hashed.

Everything a robot or an auditor needs is inside: the intrinsics with one-sigma uncertainty, the
model that was fitted, the evidence that it is right (held-out error, per-view residuals, gates,
lint) and where every input came from (board snapshot with its measured square size, image hashes,
versions). ``content_sha256`` covers every other field; the store re-checks it on every read.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.common import (
    CURRENT_HASH,
    LEGACY_HASH,
    MAX_VERSION,
    SERIAL_PATTERN,
    Document,
    HashAlgorithm,
    Sha256Hex,
    UtcDatetime,
    content_hash,
)
from calibctl.artifacts.lint import Finding
from calibctl.artifacts.session import GateResult, MetricGauge

CALIBRATION_SCHEMA_VERSION: Literal[1] = 1
_COVARIANCE_PARAMETERS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")


class DistortionModelInfo(Document):
    """Which coefficients were free and the exact OpenCV flags the solve used."""

    name: str = Field(
        description="calibctl model name: k1k2, k1k2k3, k1k2p1p2k3, rational, opencv-default, fisheye "
        "(equidistant Kannala-Brandt, cv2.fisheye), imported"
    )
    opencv_flags: int = Field(
        ge=0,
        description="OpenCV flags of the solve (cv2.calibrateCameraExtended; the fisheye "
        "model: cv2.fisheye.calibrate's equivalent)",
    )
    flag_names: list[str] = Field(
        default_factory=list, description="names of the set flags, e.g. CALIB_FIX_K3"
    )
    free_parameters: list[str] = Field(
        description="parameters the solve estimated, e.g. [fx, fy, cx, cy, k1, k2]"
    )
    selection: list[dict[str, float | str | bool]] = Field(
        default_factory=list, description="--model auto: each candidate with fit and held-out numbers"
    )


class ParameterCovariance(Document):
    """Full covariance of the free intrinsics and distortion, board poses marginalised
    (core/intrinsics/covariance.py)."""

    parameters: list[str] = Field(
        min_length=1,
        description="names in matrix order, e.g. [fy, cx, cy, k1, k2]; under a fixed aspect ratio "
        "fx is not listed: it is aspect_ratio * fy",
    )
    matrix: list[list[float]] = Field(
        description="symmetric covariance, px^2 for K entries, unitless^2 for distortion"
    )
    aspect_ratio: float | None = Field(None, gt=0, description="fx / fy when the solve tied them, else null")

    @model_validator(mode="after")
    def _square(self) -> ParameterCovariance:
        n = len(self.parameters)
        unknown = [p for p in self.parameters if p not in _COVARIANCE_PARAMETERS]
        if unknown or len(set(self.parameters)) != n:
            raise ValueError(
                f"covariance parameters must be distinct names from {', '.join(_COVARIANCE_PARAMETERS)}; "
                f"got {self.parameters}"
            )
        if len(self.matrix) != n or any(len(row) != n for row in self.matrix):
            raise ValueError(f"covariance matrix must be {n}x{n} for {n} parameters")
        if any(self.matrix[i][i] < 0 for i in range(n)):
            raise ValueError("covariance diagonal must be non-negative")
        return self


class ViewLevelSigma(Document):
    """The view-level check beside the Jacobian sigma, for per-view errors (core/intrinsics/covariance.py)."""

    sigma_factor: float = Field(
        ge=0,
        description="view-clustered (sandwich) sigma / Jacobian sigma, averaged over "
        "the whitened parameter directions; ~1 when every corner's error is independent",
    )
    views: int = Field(ge=0, description="views (clusters) the factor was computed from")
    used: Literal["jacobian", "view-level"] = Field(
        description="which covariance sigma and covariance are: view-level = the Jacobian one times "
        "sigma_factor^2"
    )
    rule: str = Field(description="when the view-level covariance replaces the Jacobian one")


class Uncertainty(Document):
    """One-sigma per estimated intrinsic parameter (pixels for K, unitless for distortion)."""

    sigma: dict[str, float] = Field(default_factory=dict, description="parameter name -> one-sigma")
    refused_reason: str | None = Field(None, description="why no sigma is reported (too few residuals)")
    residual_count: int = Field(0, ge=0, description="number of scalar residuals in the fit")
    parameter_count: int = Field(0, ge=0, description="number of estimated parameters incl. poses")
    # Left out of the document (and its hash) while None, so artifacts sealed before it existed still verify.
    covariance: ParameterCovariance | None = Field(
        None,
        exclude_if=lambda cov: cov is None,
        description="full covariance behind sigma; absent when refused, and in artifacts made before it "
        "was stored",
    )
    view_level: ViewLevelSigma | None = Field(
        None,
        exclude_if=lambda v: v is None,
        description="per-view error check: which covariance is reported and why; absent in older artifacts",
    )


class RingRms(Document):
    label: str = Field(description="quintile or octant label")
    fit_rms_px: float | None = Field(None, ge=0, description="RMS on the fitted views, pixels")
    held_out_rms_px: float | None = Field(None, ge=0, description="RMS on held-out views, pixels")
    count: int = Field(0, ge=0, description="corners in this bin")


class HeldOut(Document):
    """k-fold held-out validation: intrinsics frozen, each held-out pose re-fitted with solvePnP."""

    k_folds: int = Field(ge=0, description="number of folds (0 when not enough views)")
    rms_px: float | None = Field(None, ge=0, description="held-out RMS over all corners, pixels")
    outer_ring_rms_px: float | None = Field(
        None, ge=0, description="held-out RMS in the outer radial quintile"
    )
    fit_outer_ring_rms_px: float | None = Field(None, ge=0, description="fit RMS in the same outer ring")
    by_radius: list[RingRms] = Field(default_factory=list, description="residual RMS per radius quintile")
    by_octant: list[RingRms] = Field(default_factory=list, description="residual RMS per image octant")


class ViewResult(Document):
    name: str = Field(description="image the view came from")
    rms_px: float = Field(ge=0, description="this view's reprojection RMS, pixels")
    rvec: tuple[float, float, float] = Field(description="T_cam_board rotation, Rodrigues vector, radians")
    tvec_m: tuple[float, float, float] = Field(description="T_cam_board translation, metres")
    outlier: bool = Field(False, description="flagged as an outlier view")
    dropped: bool = Field(False, description="removed by --drop-outliers before the final solve")
    worst_corner_px: float | None = Field(None, ge=0, description="largest single-corner residual, pixels")


class RejectedCorner(Document):
    """A corner removed from the solve because its residual was implausible (the 5-sigma corner rule)."""

    view: str = Field(description="image the corner's view came from")
    corner_id: int = Field(ge=0, description="board corner id (row-major: row * cols + col)")
    residual_px: float = Field(
        ge=0, description="length of observed - projected under the final solve, pixels"
    )
    dx_px: float = Field(description="u component of observed - projected, pixels")
    dy_px: float = Field(description="v component of observed - projected, pixels")


class CameraConsistency(Document):
    """Do all views come from one camera? The best two-camera split, scored on held-out views."""

    group_a: list[str] = Field(
        description="views of the first group (the one holding the first view); the two "
        "groups name the views checked: every kept view, or 60 spread evenly over more "
        "(core.capture.camera_split.spread_views)"
    )
    group_b: list[str] = Field(description="views of the second group")
    holdout_rms_px: tuple[float, float] = Field(
        description="each group's k-fold held-out RMS under its own camera"
    )
    cross_rms_px: tuple[float, float] = Field(description="each group's RMS under the other group's camera")
    fx_px: tuple[float, float] = Field(description="fx solved from each group alone, pixels")
    cx_px: tuple[float, float] = Field(description="cx solved from each group alone, pixels")
    cy_px: tuple[float, float] = Field(description="cy solved from each group alone, pixels")
    ratio: float = Field(ge=0, description="smaller of the two groups' cross / held-out RMS")
    threshold: float = Field(gt=0, description="ratio from which two cameras are suspected")
    two_cameras_suspected: bool = Field(description="the views disagree the way two cameras would")


class CameraChange(Document):
    """Did the camera change during the session? Its views split in capture order, both sides solved apart
    (core.intrinsics.camera_change)."""

    first_view_after: str = Field(description="the first view (capture order) of the side after the change")
    views: tuple[int, int] = Field(description="views before and after the split")
    before_px: dict[str, float] = Field(description="fx, fy, cx, cy of the views before, solved alone, px")
    after_px: dict[str, float] = Field(description="the same of the views after, px")
    focal_step: float = Field(description="(f after - f before) / f before, fx and fy's mean")
    centre_step_px: float = Field(ge=0, description="how far the principal point moved, px")
    chi2: float = Field(ge=0, description="the step under both sides' own covariances (view-level widened)")
    limit: float = Field(gt=0, description="chi2 from which the camera changed")
    changed: bool = Field(description="chi2 over the limit and a step large enough to matter")


class Provenance(Document):
    calibctl_version: str = Field(description="calibctl version that produced the artifact")
    opencv_version: str = Field(description="OpenCV version used for the solve")
    station: str = Field(description="station id")
    operator: str = Field(description="who ran it")
    created_at: UtcDatetime = Field(description="UTC time of the solve")
    session_id: str | None = Field(None, description="capture session the corners came from")
    input_image_sha256: list[Sha256Hex] = Field(
        default_factory=list, description="sha256 of every input image"
    )
    imported_from: str | None = Field(None, description="set when the artifact came from another store/file")
    import_signature: str | None = Field(
        None,
        exclude_if=lambda mark: mark is None,
        description="set on import: how the source file was signed as this store judged it ('trusted key "
        "<id>', "
        "'untrusted key <id>', 'unsigned'); this store's own signature of the version says nothing about the "
        "source's. Absent on versions not imported, and on imports made before it was recorded",
    )
    gauge_override: str | None = Field(
        None,
        exclude_if=lambda reason: reason is None,
        description="--override-gauge: why a failed metric gauge was overridden, in the operator's words; "
        "absent "
        "when nothing was overridden",
    )


class RecordSignature(Document):
    """The signature the store made when it wrote this version (exports carry it; not in content_sha256)."""

    algorithm: Literal["ed25519"] = Field("ed25519", description="signature scheme")
    key_id: Sha256Hex = Field(description="sha256 of the signer's raw 32-byte public key")
    record_sha256: Sha256Hex = Field(description="the store's chain hash of this version's record")
    value: str = Field(
        pattern=r"^[A-Za-z0-9+/]{86}==$",
        description="base64 Ed25519 signature of 'calibctl-record-v1\\n<record_sha256>\\n<content_sha256>' "
        "(ASCII)",
    )
    public_key: str | None = Field(
        None,
        pattern=r"^[A-Za-z0-9+/]{43}=$",
        exclude_if=lambda key: key is None,
        description="base64 of the signer's raw 32-byte public key (its sha256 is key_id): lets any reader "
        "refuse a signature that does not match the content, trusted keys or none; says nothing about "
        "whether the key is trusted. Absent on signatures exported before it was carried",
    )


UNSIGNED_FIELDS = {"content_sha256", "signature"}


class CalibrationArtifact(Document):
    """One immutable version of one camera's calibration."""

    schema_version: Literal[1] = Field(
        CALIBRATION_SCHEMA_VERSION, description="version of this document's schema"
    )
    serial: str = Field(pattern=SERIAL_PATTERN, description="camera serial number (letters, digits, . _ : -)")
    version: int = Field(ge=1, le=MAX_VERSION, description="1, 2, 3, ... per serial, allocated by the store")
    status: Literal["accepted", "rejected"] = Field(
        description="accepted when lint passed; rejected is never active"
    )
    image_size: tuple[int, int] = Field(description="[W, H] pixels the corners were detected at")
    camera_matrix: tuple[
        tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]
    ] = Field(description="K, 3x3, pixels")
    dist_coeffs: list[float] = Field(
        description="OpenCV order: k1, k2, p1, p2[, k3[, k4, k5, k6]]; model fisheye: "
        "k1, k2, k3, k4 of cv2.fisheye (ROS equidistant)"
    )
    model: DistortionModelInfo = Field(description="which coefficients were free")
    stdev: Uncertainty = Field(description="one-sigma per estimated intrinsic parameter")
    rms_px: float = Field(ge=0, description="fit reprojection RMS (OpenCV's definition), pixels")
    detector_rms_px: float | None = Field(
        None,
        ge=0,
        exclude_if=lambda value: value is None,
        description="what the corners deliver on this set (the noise floor), per-corner RMS, pixels: the "
        "smaller "
        "of local quadratic fits of 4x4 corner blocks (no lens model) and the best lens model's (fisheye, "
        "rational) "
        "own residuals corrected for its degrees of freedom, or the 4x4 fits alone when rms_px is at most "
        "0.3 px (no "
        "floor can make such a fit a misfit, so the lens models are not solved); the model-misfit rule "
        "compares "
        "rms_px with it; absent in artifacts made before the rule",
    )
    held_out: HeldOut = Field(description="held-out validation")
    gates: list[GateResult] = Field(default_factory=list, description="capture-time gate values")
    board: BoardRevision = Field(description="full snapshot of the board revision used")
    views: list[ViewResult] = Field(default_factory=list, description="per-view RMS and pose")
    # Both fields below are left out of the document (and so of its hash) while empty, so artifacts
    # sealed before they existed still verify.
    rejected_corners: list[RejectedCorner] = Field(
        default_factory=list,
        exclude_if=lambda corners: not corners,
        description="corners removed from the solve (residual beyond the corner rule), largest first; "
        "absent when none was removed, and in artifacts made before the rule removed corners",
    )
    metric_gauge: MetricGauge | None = Field(
        None,
        exclude_if=lambda gauge: gauge is None,
        description="the capture session's metric gauge (--reference-distance), carried into the "
        "calibration; "
        "absent when the session had none",
    )
    observed_region_px: list[tuple[float, float]] | None = Field(
        None,
        exclude_if=lambda hull: hull is None,
        description="vertices of the convex hull of every corner the solve used, [u, v] pixels: where the "
        "calibration is used; lint judges distortion-foldover out to it (grown 10 %), not beyond; absent in "
        "artifacts made before the rule (then judged out to the image corner or circle)",
    )
    required_region_px: list[tuple[float, float]] | None = Field(
        None,
        exclude_if=lambda region: region is None,
        description="the station's declared region (gates.projection_region when not auto) at the solve, as "
        "[u, v] pixel vertices: where the robot will look; lint judges distortion-foldover over its union "
        "with "
        "observed_region_px; absent when the station declared none, and in artifacts made before the rule",
    )
    camera_consistency: CameraConsistency | None = Field(
        None,
        exclude_if=lambda check: check is None,
        description="two-camera check of the solved views; absent when too few views to split, and in "
        "artifacts made before the check existed",
    )
    camera_change: CameraChange | None = Field(
        None,
        exclude_if=lambda check: check is None,
        description="changed-camera check of the solved views in capture order; absent when too few views to "
        "split, and in artifacts made before the check existed",
    )
    lint: list[Finding] = Field(default_factory=list, description="lint findings at the time of the solve")
    provenance: Provenance = Field(description="how, where, when and from what it was made")
    content_hash_algorithm: HashAlgorithm = Field(
        LEGACY_HASH,
        description="how content_sha256 is computed: sha256-rfc8785 = sha256 of the RFC 8785 (JCS) form of "
        "every "
        "other field; sha256-python-json = artifacts written before it (absent field), hashed without this "
        "field",
    )
    content_sha256: Sha256Hex = Field(
        description="sha256 of the canonical JSON of every other field but signature"
    )
    signature: RecordSignature | None = Field(
        None, description="the writing store's signature, when it has a key (absent: unsigned); not hashed"
    )

    @field_validator("image_size")
    @classmethod
    def _positive_size(cls, value: tuple[int, int]) -> tuple[int, int]:
        if value[0] <= 0 or value[1] <= 0:
            raise ValueError(f"image size must be positive, got {value[0]}x{value[1]}")
        return value

    @field_validator("dist_coeffs")
    @classmethod
    def _dist_length(cls, value: list[float]) -> list[float]:
        if len(value) not in (4, 5, 8, 12, 14):
            raise ValueError(f"OpenCV distortion has 4, 5, 8, 12 or 14 coefficients, got {len(value)}")
        return value

    @model_validator(mode="after")
    def _k_shape(self) -> CalibrationArtifact:
        k = self.camera_matrix
        if k[1][0] != 0 or k[2][0] != 0 or k[2][1] != 0 or k[2][2] != 1:
            raise ValueError("camera_matrix must be upper triangular with K[2][2] = 1")
        if k[0][0] <= 0 or k[1][1] <= 0:
            raise ValueError("focal lengths must be positive")
        return self

    @property
    def fx(self) -> float:
        return self.camera_matrix[0][0]

    @property
    def ref(self) -> str:
        return f"{self.serial}@{self.version}"

    def computed_sha256(self) -> str:
        """The hash the content should have under its ``content_hash_algorithm``; compare with
        ``content_sha256``."""
        if self.content_hash_algorithm == LEGACY_HASH:
            return content_hash(self, UNSIGNED_FIELDS | {"content_hash_algorithm"}, LEGACY_HASH)
        return content_hash(self, UNSIGNED_FIELDS, CURRENT_HASH)

    def sealed(self) -> CalibrationArtifact:
        """A copy hashed with the current algorithm (RFC 8785), its ``content_sha256`` matching its
        content."""
        current = self.model_copy(update={"content_hash_algorithm": CURRENT_HASH})
        return current.model_copy(update={"content_sha256": current.computed_sha256()})


UNSEALED = "0" * 64
"""Placeholder hash for an artifact under construction; the store seals it when it allocates the version."""
