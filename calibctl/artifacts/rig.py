"""Camera rigs: the registry entry, a synchronised capture, and the immutable, versioned rig calibration.

A rig calibration stores its extrinsics as a tree of named frames with one root (``edges``: parent ->
child with ``T_parent_child`` and a 6x6 covariance), never as a set of pairs, so every pairwise
transform is derived and consistent. An edge's ``source`` says what produced it ("rig-solve" today;
a hand-eye edge such as ``flange -> cam0`` is ``"hand-eye"``, with its evidence in ``handeye``; a camera-LiDAR
edge ``lidar -> cam0`` is ``"lidar-board"``, with its evidence in ``lidar``; a camera-IMU edge
``imu -> cam0`` is ``"camera-imu"``, with its evidence (T_imu_cam and td_s) in ``imu``). Each member is
pinned by serial, version and content_sha256 of the camera calibration the solve used, so
``rig-stale-member`` can tell when a member was re-calibrated after the rig solve.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from calibctl.artifacts.calibration import Provenance, RecordSignature
from calibctl.artifacts.common import (
    CURRENT_HASH,
    LEGACY_HASH,
    SERIAL_PATTERN,
    Document,
    HashAlgorithm,
    Sha256Hex,
    UtcDatetime,
    content_hash,
)
from calibctl.artifacts.handeye import FRAME_PATTERN, HandEyeResult
from calibctl.artifacts.imu import ImuEdgeResult
from calibctl.artifacts.lidar import LidarEdgeResult
from calibctl.artifacts.lint import Finding

RIG_SCHEMA_VERSION: Literal[1] = 1
RIG_NAME_PATTERN = SERIAL_PATTERN
UNSEALED = "0" * 64

Matrix4 = tuple[tuple[float, float, float, float], ...]


class DesignBaseline(Document):
    """What the mechanical design says the distance between two cameras is."""

    a: str = Field(pattern=SERIAL_PATTERN, description="first camera serial")
    b: str = Field(pattern=SERIAL_PATTERN, description="second camera serial")
    baseline_mm: float = Field(gt=0, description="design distance between the optical centres, mm")
    tolerance_mm: float = Field(ge=0, description="allowed deviation, mm")


class RigDefinition(Document):
    """A registered rig: which cameras, which one is the root, the design values lint compares against."""

    schema_version: Literal[1] = Field(RIG_SCHEMA_VERSION, description="version of this document's schema")
    name: str = Field(pattern=RIG_NAME_PATTERN, description="rig name (letters, digits, . _ : -)")
    cameras: list[str] = Field(
        min_length=1,
        description="member camera serials; frame names of the tree (one camera: the root of its sensor "
        "edges)",
    )
    root: str = Field(description="the tree's root camera")
    design_baselines: list[DesignBaseline] = Field(default_factory=list, description="design distances")
    frames: list[Annotated[str, Field(pattern=FRAME_PATTERN)]] = Field(
        default_factory=list,
        exclude_if=lambda frames: not frames,
        description="non-camera frames (flange, imu, lidar) that hand-eye edges may join to the tree",
    )
    created_at: UtcDatetime = Field(description="UTC time of registration")
    created_by: str = Field(description="who registered it")
    station: str = Field(description="where")

    @model_validator(mode="after")
    def _members(self) -> RigDefinition:
        if len(set(self.cameras)) != len(self.cameras):
            raise ValueError("a camera is listed twice")
        if self.root not in self.cameras:
            raise ValueError(f"root {self.root} is not a member")
        clash = sorted(set(self.frames) & set(self.cameras)) or [
            f for i, f in enumerate(self.frames) if f in self.frames[:i]
        ]
        if clash:
            raise ValueError(f"frame {clash[0]} is listed twice (frames and cameras share one name space)")
        for d in self.design_baselines:
            if d.a not in self.cameras or d.b not in self.cameras or d.a == d.b:
                raise ValueError(f"design baseline {d.a}:{d.b} does not name two different members")
        return self


class RigFrame(Document):
    """One synchronised frame: its key and the image each camera contributed (absent: no photo)."""

    key: int = Field(ge=0, description="the frame key (last number of the file names)")
    images: dict[str, str] = Field(description="camera serial -> image name in that camera's capture session")


class UnmatchedImage(Document):
    camera: str = Field(description="camera serial")
    name: str = Field(description="image name")
    reason: Literal[
        "no-frame-key", "duplicate-frame-key", "no-partner", "outside-time-tolerance", "no-timestamp"
    ] = Field(
        description="why it is unmatched (paired by time: no other camera's image within the tolerance, or "
        "none listed in the timestamps file)"
    )


class RigGate(Document):
    """A rig-level capture gate."""

    gate: Literal["rig-connected", "metric-gauge"] = Field(description="which gate")
    passed: bool = Field(description="true when satisfied (metric-gauge: no failed gauge, or overridden)")
    value: float = Field(
        description="rig-connected: shared views of the weakest linking pair (or of the best pair across a "
        "split); metric-gauge: |ratio - 1| of the board revision's failed gauge"
    )
    threshold: float = Field(description="rig-connected: views a linking pair needs; metric-gauge: 0.01")
    message: str = Field(description="the verdict in words")
    hint: str | None = Field(None, description="what the operator should do next, naming the pair")


class RigSession(Document):
    """A rig capture: one capture session per camera (their own gates) and how their images pair up."""

    schema_version: Literal[1] = Field(RIG_SCHEMA_VERSION, description="version of this document's schema")
    rig_session_id: str = Field(pattern=r"^[0-9a-f]{12}$", description="12 hex digits")
    rig: str = Field(pattern=RIG_NAME_PATTERN, description="rig name")
    camera_sessions: dict[str, str] = Field(description="camera serial -> its capture session id")
    frames: list[RigFrame] = Field(description="synchronised frames, by key")
    unmatched: list[UnmatchedImage] = Field(default_factory=list, description="images that pair with nothing")
    shared_views: dict[str, int] = Field(description="'A-B' -> frames in which both cameras saw the board")
    gates: list[RigGate] = Field(description="rig-level gates")
    status: Literal["accepted", "rejected"] = Field(
        description="accepted when every camera's and the rig's gates pass"
    )
    created_at: UtcDatetime = Field(description="UTC")
    station: str = Field(description="station id")
    operator: str = Field(description="who")


class RigMember(Document):
    """The camera calibration a rig solve used for one member (intrinsics as used, refined or not)."""

    serial: str = Field(pattern=SERIAL_PATTERN, description="camera serial")
    version: int = Field(ge=1, description="its calibration version")
    content_sha256: Sha256Hex = Field(description="that calibration's content hash")
    image_size: tuple[int, int] = Field(description="[W, H] pixels")
    camera_matrix: tuple[
        tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]
    ] = Field(description="K used by the rig solve, px")
    dist_coeffs: list[float] = Field(description="distortion used, OpenCV order")
    refined: bool = Field(description="true when the rig solve refined these intrinsics")
    lens: Literal["pinhole", "fisheye"] = Field(
        "pinhole",
        exclude_if=lambda lens: lens == "pinhole",
        description="pinhole (OpenCV's distortion order) or fisheye (equidistant Kannala-Brandt, "
        "dist_coeffs k1..k4); "
        "written only for fisheye, so older documents and their hashes are unchanged",
    )


class RigEdge(Document):
    """One parent -> child transform of the tree."""

    parent: str = Field(description="parent frame")
    child: str = Field(description="child frame")
    T_parent_child: Matrix4 = Field(
        description="4x4 transform mapping child-frame points into the parent frame, metres"
    )
    covariance: list[list[float]] = Field(
        description="6x6 covariance of (rvec rad, tvec m) of T_parent_child"
    )
    translation_mm: float = Field(ge=0, description="|t|, mm")
    sigma_translation_mm: float = Field(ge=0, description="one-sigma of |t|, mm")
    rotation_deg: float = Field(ge=0, description="rotation angle, degrees")
    sigma_rotation_deg: float = Field(
        ge=0, description="one-sigma of the rotation on its least certain axis, degrees"
    )
    source: Literal["rig-solve", "hand-eye", "lidar-board", "camera-imu"] = Field(
        "rig-solve", description="what produced this edge"
    )


class RigPair(Document):
    """Derived numbers of one camera pair (a before b in the rig's camera order)."""

    a: str = Field(description="first camera")
    b: str = Field(description="second camera")
    baseline_mm: float = Field(ge=0, description="distance of the optical centres, mm")
    sigma_baseline_mm: float = Field(ge=0, description="one-sigma, mm")
    rotation_deg: float = Field(ge=0, description="relative rotation, degrees")
    sigma_rotation_deg: float = Field(ge=0, description="one-sigma, degrees")
    shared_views: int = Field(ge=0, description="frames both cameras saw the board in")
    epipolar_rms_px: float | None = Field(None, ge=0, description="held-out epipolar error RMS, px")
    epipolar_max_px: float | None = Field(None, ge=0, description="held-out epipolar error max, px")
    rectified_rms_px: float | None = Field(
        None, ge=0, description="held-out rectified cross-epipolar disparity RMS, px"
    )
    rectified_max_px: float | None = Field(None, ge=0, description="its max, px")


class RigLoop(Document):
    """Residual of independently solved pairs composed around one cycle of cameras."""

    cycle: list[str] = Field(min_length=3, description="cameras around the cycle")
    rotation_deg: float = Field(ge=0, description="residual rotation, degrees")
    translation_mm: float = Field(ge=0, description="residual translation, mm")
    sigma_rotation_deg: float = Field(ge=0, description="expected residual rotation (one-sigma), degrees")
    sigma_translation_mm: float = Field(ge=0, description="expected residual translation (one-sigma), mm")
    mahalanobis: float = Field(ge=0, description="sqrt(r^T C^-1 r) of the 6-vector residual")


class RigCalibration(Document):
    """One immutable version of a rig's extrinsics."""

    schema_version: Literal[1] = Field(RIG_SCHEMA_VERSION, description="version of this document's schema")
    rig: str = Field(pattern=RIG_NAME_PATTERN, description="rig name")
    version: int = Field(ge=1, description="1, 2, 3, ... per rig, allocated by the store")
    status: Literal["accepted", "rejected"] = Field(description="accepted when rig lint passed")
    root: str = Field(description="root frame of the tree")
    members: list[RigMember] = Field(
        min_length=1, description="the camera calibrations used (one: a one-camera rig, pinned)"
    )
    edges: list[RigEdge] = Field(description="the tree, parents before children")
    pairs: list[RigPair] = Field(description="every camera pair, derived from the tree")
    loops: list[RigLoop] = Field(default_factory=list, description="loop closure (3+ cameras)")
    fit_rms_px: dict[str, float] = Field(description="camera serial -> fit RMS, px")
    held_out_rms_px: dict[str, float] = Field(description="camera serial -> k-fold held-out RMS, px")
    held_out_folds: int = Field(ge=0, description="folds of the held-out validation")
    solver: str = Field(description="cv2.stereoCalibrateExtended or calibctl joint LM")
    refine_intrinsics: bool = Field(description="whether the members' intrinsics were refined")
    gates: list[RigGate] = Field(default_factory=list, description="rig gates of the capture")
    lint: list[Finding] = Field(
        default_factory=list, description="rig lint findings at the time of the solve"
    )
    handeye: list[HandEyeResult] = Field(
        default_factory=list,
        exclude_if=lambda results: not results,
        description="evidence of every hand-eye edge of this version (source 'hand-eye'), and for a version "
        "rejected by a hand-eye gate, the rejected result (it adds no edge)",
    )
    lidar: list[LidarEdgeResult] = Field(
        default_factory=list,
        exclude_if=lambda results: not results,
        description="evidence of every camera-LiDAR edge of this version (source 'lidar-board'), and for a "
        "version "
        "rejected by a LiDAR gate, the rejected result (it adds no edge); absent when empty, so older "
        "versions and their hashes are unchanged",
    )
    imu: list[ImuEdgeResult] = Field(
        default_factory=list,
        exclude_if=lambda results: not results,
        description="evidence of every camera-IMU edge of this version (source 'camera-imu': T_imu_cam "
        "and td_s), and for a version rejected by an IMU gate, the rejected result (it adds no edge); "
        "absent when empty, so older versions and their hashes are unchanged",
    )
    provenance: Provenance = Field(description="how, where, when and from what it was made")
    content_hash_algorithm: HashAlgorithm = Field(
        LEGACY_HASH,
        exclude_if=lambda algorithm: algorithm == LEGACY_HASH,
        description="how content_sha256 is computed: sha256-rfc8785 = sha256 of the RFC 8785 (JCS) form of "
        "every "
        "other field, this one included; absent = sha256-python-json, the versions written before it",
    )
    content_sha256: Sha256Hex = Field(
        description="sha256 of the canonical JSON of every other field but signature"
    )
    signature: RecordSignature | None = Field(
        None,
        exclude_if=lambda seal: seal is None,
        description="the writing store's signature of this version's record, when it had a key (absent: "
        "unsigned); not hashed, and absent from the stored document (the store keeps it in the row's "
        "columns)",
    )

    @property
    def ref(self) -> str:
        return f"{self.rig}@{self.version}"

    def computed_sha256(self) -> str:
        """The hash under the version's own ``content_hash_algorithm`` (old versions keep theirs)."""
        return content_hash(self, {"content_sha256", "signature"}, self.content_hash_algorithm)

    def sealed(self) -> RigCalibration:
        """An unsigned copy hashed with the current algorithm (RFC 8785); the store signs what it writes."""
        current = self.model_copy(update={"content_hash_algorithm": CURRENT_HASH, "signature": None})
        return current.model_copy(update={"content_sha256": current.computed_sha256()})


class RigActivation(Document):
    """One move of a rig's active version. Never updated, never deleted."""

    event_id: int = Field(ge=1, description="store-assigned, increasing")
    rig: str = Field(description="rig name")
    version: int = Field(ge=1, description="the version that became active")
    previous_version: int | None = Field(None, description="the version active before, if any")
    kind: Literal["activate", "rollback"] = Field(description="activate after a solve, or rollback")
    actor: str = Field(description="who did it")
    station: str = Field(description="where")
    at: UtcDatetime = Field(description="UTC")
    reason: str = Field(min_length=1, description="why")
