"""Settings: CLI flag > environment (CALIBCTL_*) > station file > default.

A station file is YAML (``--station-config FILE``, ``CALIBCTL_STATION_CONFIG``, or
``./calibctl-station.yaml`` when it exists) holding what one station overrides::

    station: line3-cam-bench
    db: postgresql+psycopg://calib@factory-db/calibctl
    image_retention_days: 30
    jobs: 8                                      # detection processes (default: the cores available)
    signing_key: /etc/calibctl/station-key.pem   # Ed25519, mode 0600: every record written is signed
    trusted_keys: /etc/calibctl/trusted-keys/    # public keys (*.pem) whose signatures are accepted
    gates: {observability_min: 1.0e-4, tilt_min_deg: 20}
    lint: {sigma_fx_max_px: 1.5}
"""

from __future__ import annotations

import getpass
import os
import socket
from collections.abc import Mapping
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from calibctl import bounded
from calibctl.errors import InputError, UsageError

DEFAULT_DB_URL = "sqlite:///calibctl.db"
DEFAULT_STATION_FILE = Path("calibctl-station.yaml")


class GateThresholds(BaseModel):
    """Capture-time gates (seed chapter 1: the capture rule and the sigma5/sigma1 gate)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    observability_min: float = Field(1e-4, gt=0, description="minimum sigma5/sigma1 of Zhang's V matrix")
    tilt_min_deg: float = Field(20.0, ge=0, description="a view counts as tilted from this angle")
    tilt_max_deg: float = Field(45.0, gt=0, description="above this the detector's accuracy collapses")
    tilt_directions_min: int = Field(
        3, ge=1, le=4, description="tilt directions at least 90 deg apart needed (at most 4 fit)"
    )
    min_views: int = Field(8, ge=3, le=100_000, description="fewest accepted views for a session to pass")
    projection_sigma_max_px: float = Field(
        5.0,
        gt=0,
        allow_inf_nan=False,
        description="the decisive gate: worst projection one-sigma over the region, pixels "
        "(core.capture.projection_gate)",
    )
    projection_region: str = Field(
        "auto",
        min_length=1,
        description="where the robot looks: auto (the image circle when one is known, else the "
        "image), image, circle, or a box U0,V0,U1,V1 in pixels",
    )


class LintThresholds(BaseModel):
    """Calibration lint (seed chapter 1: the three-line calibration lint)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    sigma_fx_max_px: float = Field(2.0, gt=0, description="one-sigma on fx above which fx is not observable")
    principal_point_max_frac: float = Field(0.1, gt=0, description="|cx - W/2| must be below this * W")
    outer_ring_ratio_max: float = Field(1.1, gt=0, description="held-out outer-ring RMS / fit outer-ring RMS")
    aspect_max_frac: float = Field(0.01, gt=0, description="|fx/fy - 1| above this is a warning")
    epipolar_max_px_at_720: float = Field(
        0.5, gt=0, description="rig: held-out epipolar RMS limit at 720 rows (scaled by rows / 720)"
    )
    loop_closure_max_mahalanobis: float = Field(
        4.48,
        gt=0,
        description="rig: loop residual limit, sqrt(chi2 6 dof 99.7%), under the loop's joint "
        "covariance (docs/verdicts.md: 1 of 216 clean rendered loops above it)",
    )


class HandEyeGates(BaseModel):
    """Hand-eye observability gates (seed chapter 2: the check nobody writes and everybody needs)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    lever_arm_sigma_min: float = Field(0.5, gt=0, description="minimum sigma_min of the stacked (R_A - I)")
    second_axis_min_deg: float = Field(
        10.0, gt=0, description="minimum rotation about a second axis (s2, deg)"
    )
    angle_mismatch_max_deg: float = Field(
        1.0, gt=0, description="|angle(A) - angle(B)| above this names a motion"
    )
    mismatch_fraction_max: float = Field(
        0.1, ge=0, lt=1, description="largest fraction of mismatched motions"
    )
    rotation_residual_max_deg: float = Field(
        1.0, gt=0, description="largest rotation residual RMS after the solve"
    )
    translation_scale_tolerance: float = Field(
        0.01,
        gt=0,
        lt=0.25,
        description="largest |s - 1| of the translation scale between the sensors (beyond its "
        "3 sigma): the metric gauge's tolerance, a fraction",
    )


class StationConfig(BaseModel):
    """The contents of a station file."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    station: str | None = None
    operator: str | None = None
    db: str | None = None
    signing_key: str | None = Field(
        None, description="private Ed25519 key file (0600) records are signed with"
    )
    trusted_keys: str | None = Field(
        None, description="folder of public keys (*.pem) whose signatures are trusted"
    )
    image_retention_days: int = Field(30, ge=0)
    jobs: int | None = Field(
        None, ge=1, description="detection workers (default: the cores this process may use)"
    )
    gates: GateThresholds = Field(default_factory=GateThresholds)
    lint: LintThresholds = Field(default_factory=LintThresholds)
    handeye: HandEyeGates = Field(default_factory=HandEyeGates)


class Settings(BaseModel):
    """Resolved settings for one invocation."""

    db_url: str
    station: str
    operator: str
    station_file: str | None
    signing_key: str | None = None
    trusted_keys: str | None = None
    image_retention_days: int
    jobs: int = Field(
        1, ge=1, description="detection workers: --jobs > CALIBCTL_JOBS > station file > cores available"
    )
    gates: GateThresholds
    lint: LintThresholds
    handeye: HandEyeGates = Field(default_factory=HandEyeGates)


def load_station_file(path: Path) -> StationConfig:
    raw = bounded.load_file(path, "read the station file") or {}
    if not isinstance(raw, dict):
        raise InputError(f"station file {path} must be a mapping, got {type(raw).__name__}")
    try:
        return StationConfig.model_validate(raw)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        raise InputError(f"station file {path}: {where}: {first['msg']}") from exc


def load_settings(
    db: str | None = None,
    station_config: Path | None = None,
    station: str | None = None,
    operator: str | None = None,
    env: Mapping[str, str] | None = None,
    jobs: int | None = None,
) -> Settings:
    """Resolve settings with the precedence CLI flag > environment > station file > default."""
    env = os.environ if env is None else env
    path = station_config or (
        Path(env["CALIBCTL_STATION_CONFIG"]) if env.get("CALIBCTL_STATION_CONFIG") else None
    )
    if path is None and DEFAULT_STATION_FILE.exists():
        path = DEFAULT_STATION_FILE
    file_cfg = load_station_file(path) if path is not None else StationConfig()
    return _checked(
        Settings(
            db_url=persistent_db_url(
                db if db is not None else env.get("CALIBCTL_DB") or file_cfg.db or DEFAULT_DB_URL
            ),
            station=station or env.get("CALIBCTL_STATION") or file_cfg.station or socket.gethostname(),
            operator=operator or env.get("CALIBCTL_OPERATOR") or file_cfg.operator or _login_name(),
            station_file=str(path) if path else None,
            signing_key=env.get("CALIBCTL_SIGNING_KEY") or file_cfg.signing_key,
            trusted_keys=env.get("CALIBCTL_TRUSTED_KEYS") or file_cfg.trusted_keys,
            image_retention_days=file_cfg.image_retention_days,
            jobs=_jobs(jobs, env.get("CALIBCTL_JOBS"), file_cfg.jobs),
            gates=file_cfg.gates,
            lint=file_cfg.lint,
            handeye=file_cfg.handeye,
        )
    )


def _jobs(flag: int | None, env_value: str | None, file_value: int | None) -> int:
    """Detection workers: ``--jobs`` > CALIBCTL_JOBS > the station file's ``jobs`` > the cores available."""
    if flag is not None:
        if flag < 1:
            raise UsageError(
                f"--jobs must be 1 or more, got {flag}", "leave it out to use every core available"
            )
        return flag
    if env_value:
        if not env_value.strip().isdigit() or int(env_value) < 1:
            raise UsageError(
                f"CALIBCTL_JOBS must be a whole number of 1 or more, got '{env_value}'",
                "unset it to use every core available",
            )
        return int(env_value)
    if file_value is not None:
        return file_value
    from calibctl.core.blas_threads import available_cores  # os only: no numpy or OpenCV is loaded

    return available_cores()


def _checked(settings: Settings) -> Settings:
    """Station and operator are written into every record: no control characters (PostgreSQL refuses NUL)."""
    bounded.check_text(settings.station, "the station (--station / CALIBCTL_STATION)", "its value")
    bounded.check_text(settings.operator, "the operator (--operator / CALIBCTL_OPERATOR)", "its value")
    return settings


def persistent_db_url(url: str) -> str:
    """``url`` unless it names no lasting store: an empty ``--db`` (it used to mean ./calibctl.db) or an
    in-memory SQLite database, which every calibctl process would create empty and throw away."""
    text = url.strip()
    if not text:
        raise UsageError(
            "--db is empty", "pass --db URL (sqlite:///PATH or postgresql://...), or leave it out"
        )
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "sqlite", "/" + text  # a bare path
    if scheme.startswith("sqlite"):
        target, _, query = rest.lstrip("/").partition("?")
        if target in ("", ":memory:") or "mode=memory" in query:
            raise UsageError(
                f"'{url}' is an in-memory database: every calibctl command would start from an empty "
                "store and keep nothing",
                "pass a file (sqlite:///PATH) or postgresql://...",
            )
    return text


def _login_name() -> str:
    try:
        return getpass.getuser()
    except Exception:  # no passwd entry in some containers
        return "unknown"
