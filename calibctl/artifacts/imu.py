"""The camera-IMU result as evidence of a rig-tree edge ``imu_frame -> camera`` (docs/imu.md).

``calibctl imu solve ... --rig RIG`` stores it inside the rig's next version (``RigCalibration.imu``), so
it is part of that version's sealed content: T_imu_cam and the time offset td_s with their 7x7
covariance, the biases and gravity, the IMU noise model used, every gate, the fit and held-out
residuals, the camera calibration it was pinned to and the sha256 of every input file. A rejected
result keeps its gates but adds no edge (``estimate`` may still hold the rejected estimate: the rig
tree never carries it).

Conventions: ``p_imu = R p_cam + t`` with (R, t) = T_imu_cam, metres; ``t_imu = t_cam + td_s`` (a frame
stamped t_cam on the camera clock was seen at t_cam + td_s on the IMU clock), the same number as
Kalibr's ``timeshift_cam_imu``.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from calibctl.artifacts.common import SERIAL_PATTERN, Document, Sha256Hex, UtcDatetime
from calibctl.artifacts.handeye import FRAME_PATTERN, RosFrames, SolveGate, ros_frames_field

IMU_SCHEMA_VERSION: Literal[1] = 1
Matrix4 = tuple[tuple[float, float, float, float], ...]
Vector3 = tuple[float, float, float]
Matrix3 = tuple[Vector3, Vector3, Vector3]
TdConvention = Literal["t_imu = t_cam + td_s (Kalibr's timeshift_cam_imu, same sign)"]
TD_CONVENTION: TdConvention = "t_imu = t_cam + td_s (Kalibr's timeshift_cam_imu, same sign)"
COVARIANCE_LAYOUT = (
    "7x7 over rotation about IMU x, y, z (rad; left perturbation R = Exp(d) R_hat), translation x, y, z "
    "(m), td (s); td's row and column zero when td was held"
)


class ImuGate(SolveGate):
    """One gate of the camera-IMU solve (core.imu.gates), before or after the solve."""

    gate: str = Field(
        description="rotational_excitation, td_observability, td_rotation_correlation, td_sigma, "
        "saturation, imu_gaps or dropped_frames (core.imu.gates)"
    )


class ImuNoiseModel(Document):
    """The IMU noise model the residuals were weighted with (Kalibr imu.yaml fields, continuous time)."""

    gyro_noise_density: float = Field(gt=0, description="rad/s/sqrt(Hz)")
    accel_noise_density: float = Field(gt=0, description="m/s^2/sqrt(Hz)")
    gyro_random_walk: float = Field(gt=0, description="rad/s^2/sqrt(Hz)")
    accel_random_walk: float = Field(gt=0, description="m/s^3/sqrt(Hz)")
    gravity_m_s2: float = Field(gt=0, description="magnitude of gravity, m/s^2")
    rate_hz: float = Field(gt=0, description="the IMU's sample rate as measured from its stamps, Hz")
    variance_factors: tuple[float, float] = Field(
        description="gyro, accel: how far the solve raised each group's variance over the densities' "
        "(1: the residuals were no larger than the noise model says)"
    )
    source: str = Field(description="the imu.yaml it came from, or 'defaults'")


class ImuModelEstimate(Document):
    """The IMU's own intrinsics the solve estimated beside the extrinsic (core.imu.intrinsics), in Kalibr's
    scale-misalignment meaning: gyro = M_gyro C_gyro_i w + A_gyro C_gyro_i a + b_g, accel = M_accel a +
    b_a (w, a: body rate and specific force in the IMU frame, the accelerometer triad's)."""

    model: Literal["scale-misalignment"] = Field(description="the IMU model (Kalibr's --imu-models name)")
    gyro_M: Matrix3 = Field(description="M_gyro: gyro scale and misalignment, lower-triangular")
    gyro_C_gyro_i: Matrix3 = Field(description="C_gyro_i: rotation of the gyro triad from the IMU frame")
    gyro_A: Matrix3 = Field(description="A_gyro: gyro g-sensitivity, (rad/s)/(m/s^2)")
    accel_M: Matrix3 = Field(description="M_accel: accelerometer scale and misalignment, lower-triangular")
    states: dict[str, float] = Field(
        description="the 24 states as solved: M - I lower triangles (mg_*, ma_*), C_gyro_i as a rotation "
        "vector (cg_*, rad), A_gyro (ag_*)"
    )
    sigmas: dict[str, float] = Field(description="their one-sigma (jackknife-widened like every state)")
    prior_sigmas: dict[str, float] = Field(description="the weak prior's one-sigma about identity")
    min_information: float = Field(
        description="smallest eigenvalue of the data's prior-scaled information on the states (gate: at "
        "least 100)"
    )


class ImuEstimate(Document):
    """T_imu_cam and td_s with their covariance, and the nuisance states the solve estimated beside them."""

    T_imu_cam: Matrix4 = Field(description="4x4, maps camera-frame points into the IMU frame, metres")
    quaternion_wxyz: tuple[float, float, float, float] = Field(
        description="rotation of T_imu_cam (w, x, y, z)"
    )
    td_s: float = Field(description="time offset, seconds: " + TD_CONVENTION)
    td_held: bool = Field(description="true when td was held (not estimated), see td_held_reason")
    td_held_reason: str | None = Field(None, description="why td was held, in words")
    covariance: list[list[float]] = Field(description=COVARIANCE_LAYOUT)
    sigma_translation_mm: Vector3 = Field(description="one-sigma along IMU x, y, z, mm")
    sigma_rotation_deg: Vector3 = Field(description="one-sigma about IMU x, y, z, degrees")
    sigma_td_ms: float = Field(ge=0, description="one-sigma of td, ms (0 when held)")
    td_crlb_ms: float | None = Field(
        ge=0,
        description="td's Cramer-Rao bound with every other state known: sigma_px / sqrt(sum |u_dot|^2), ms",
    )
    sigma_inflation: dict[str, float] = Field(
        default_factory=dict,
        description="per state: the factor (at least 1) by which a delete-one-block jackknife widened its "
        "white-noise sigma; the sigmas above include it",
    )
    line_delay_s: float | None = Field(None, description="rolling-shutter line delay, s per row from c_y")
    sigma_line_delay_us: float | None = Field(None, description="its one-sigma, microseconds per row")
    gyro_bias_rad_s: Vector3 = Field(description="gyro bias, IMU frame, rad/s")
    accel_bias_m_s2: Vector3 = Field(description="accelerometer bias, IMU frame, m/s^2")
    gravity_board_m_s2: Vector3 = Field(description="gravity in the board frame, m/s^2")
    imu_model: ImuModelEstimate | None = Field(
        None,
        exclude_if=lambda model: model is None,
        description="the IMU's scale, misalignment and g-sensitivity when solved with that model; absent "
        "for Kalibr's 'calibrated' IMU (and in results stored before it existed: their hashes unchanged)",
    )

    @model_validator(mode="after")
    def _square(self) -> ImuEstimate:
        if len(self.covariance) != 7 or any(len(row) != 7 for row in self.covariance):
            raise ValueError("covariance must be 7x7 (" + COVARIANCE_LAYOUT + ")")
        return self


class ImuMetrics(Document):
    """Fit and k-fold held-out residuals of a solve."""

    frames: int = Field(ge=0, description="camera frames used")
    corners: int = Field(ge=0, description="corners used")
    corners_left_out: int = Field(
        ge=0, description="corners over 5 robust sigmas after the first solve, left out (blunders)"
    )
    imu_samples: int = Field(ge=0, description="IMU samples used")
    corner_rms_px: float = Field(ge=0, description="reprojection RMS, px")
    gyro_rms_rad_s: float = Field(ge=0, description="gyro residual RMS, rad/s")
    accel_rms_m_s2: float = Field(ge=0, description="accelerometer residual RMS, m/s^2")
    folds: int = Field(ge=0, description="k of the k-fold (0: none)")
    held_out_corner_rms_px: list[float] = Field(description="per fold: held-out reprojection RMS, px")
    held_out_gyro_rms_rad_s: list[float] = Field(description="per fold: held-out gyro RMS, rad/s")
    held_out_accel_rms_m_s2: list[float] = Field(description="per fold: held-out accelerometer RMS, m/s^2")
    iterations: int = Field(ge=0, description="LM iterations")
    converged: bool = Field(description="whether LM converged")


class ImuRowBin(Document):
    """One image-row bin of the row test."""

    row_px: float = Field(description="the bin's centre, image row (px, absolute)")
    time_residual_us: float | None = Field(
        description="speed-weighted mean residual along the motion over the speed, microseconds (none: empty)"
    )
    sigma_us: float | None = Field(description="its one-sigma, microseconds (none: empty)")
    corners: int = Field(ge=0, description="inlier corners in the bin that move")


class ImuRowTest(Document):
    """The row test on the solved residuals (core.imu.rows): a time offset is constant across image rows, a
    rolling shutter ramps with the row."""

    slope_us_per_row: float = Field(
        description="time residual against image row (from c_y): the line delay the solve left unexplained"
    )
    sigma_us_per_row: float = Field(
        ge=0, description="its one-sigma (the fit's, or a time-block jackknife's when larger)"
    )
    offset_us: float = Field(description="the constant part of the time residual, microseconds")
    principal_row_px: float = Field(
        description="c_y of the held intrinsics: the row the slope is counted from"
    )
    z: float = Field(ge=0, description="|slope| / sigma")
    significant: bool = Field(description="z over the threshold: rolling shutter suspected")
    line_delay_solved: bool = Field(description="true when the solve estimated a line delay already")
    corners: int = Field(ge=0, description="inlier corners that move, used by the fit")
    message: str = Field(description="the verdict in words, with the next action when significant")
    rows: list[ImuRowBin] = Field(description="the residual over image rows, binned (the report's plot)")


class ImuSeries(Document):
    """What the report plots over time, in equal bins (0.05 s, at most 240) over the solve's IMU span
    (none: an empty bin)."""

    t_s: list[float] = Field(description="bin centres, seconds from the first IMU sample (IMU clock)")
    gyro_rad_s: list[tuple[float | None, float | None, float | None]] = Field(
        description="mean gyro per bin with the solved bias removed, IMU x, y, z, rad/s"
    )
    camera_rate_rad_s: list[tuple[float | None, float | None, float | None]] = Field(
        description="mean board-derived camera rotation rate per bin, carried into the IMU frame by the "
        "solved rotation and placed at t_cam + td_s, rad/s"
    )
    corner_rms_px: list[float | None] = Field(description="inlier reprojection RMS per bin, px")
    gyro_rms_rad_s: list[float | None] = Field(description="gyro residual RMS per bin, rad/s")
    accel_rms_m_s2: list[float | None] = Field(description="accelerometer residual RMS per bin, m/s^2")


class ImuInput(Document):
    """One input file, pinned by hash."""

    role: Literal["imu", "camera", "corners", "images", "bag", "noise"] = Field(description="what it holds")
    path: str = Field(description="the file (or, for corners and images, the folder) as read, absolute")
    sha256: Sha256Hex = Field(
        description="its sha256; for a folder, sha256 of its files' 'NAME SHA256' lines sorted by name"
    )


class ImuEdgeResult(Document):
    """One camera-IMU solve of the edge ``parent_frame`` (the IMU) -> ``child_frame`` (a rig camera)."""

    schema_version: Literal[1] = Field(IMU_SCHEMA_VERSION, description="version of this document's schema")
    kind: Literal["imu"] = Field("imu", description="document kind")
    parent_frame: str = Field(
        pattern=FRAME_PATTERN, description="the IMU frame (a ROS name declared in the rig)"
    )
    child_frame: str = Field(pattern=SERIAL_PATTERN, description="the camera: a rig member's serial")
    status: Literal["accepted", "rejected"] = Field(description="accepted when every gate passed")
    camera: str = Field(description="SERIAL@VERSION of the stored calibration whose intrinsics were held")
    td_convention: TdConvention = Field(TD_CONVENTION, description="how td_s relates the two clocks")
    recording: str = Field(description="the recording folder as given")
    board: str | None = Field(
        None, description="NAME@REVISION of the registered board (--board): detected with or checked against"
    )
    estimate: ImuEstimate | None = Field(description="the estimate (none when refused before solving)")
    noise: ImuNoiseModel = Field(description="the IMU noise model used")
    metrics: ImuMetrics | None = Field(description="fit and held-out figures (none without an estimate)")
    gates: list[ImuGate] = Field(description="every gate, in order")
    inputs: list[ImuInput] = Field(description="every file read, with its sha256")
    created_at: UtcDatetime = Field(description="UTC time of the solve")
    row_test: ImuRowTest | None = Field(
        None,
        exclude_if=lambda test: test is None,
        description="the row test on the solved residuals; absent without an estimate and in results "
        "stored before it existed (their hashes unchanged)",
    )
    series: ImuSeries | None = Field(
        None,
        exclude_if=lambda series: series is None,
        description="rates and residuals over time for the report page; absent as row_test is",
    )
    ros_frames: RosFrames | None = ros_frames_field()
