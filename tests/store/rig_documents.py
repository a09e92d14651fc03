"""Small valid rig documents for store tests (deterministic)."""

from __future__ import annotations

import numpy as np

from calibctl.artifacts.calibration import Provenance
from calibctl.artifacts.rig import (
    UNSEALED,
    DesignBaseline,
    RigCalibration,
    RigDefinition,
    RigEdge,
    RigFrame,
    RigGate,
    RigMember,
    RigPair,
    RigSession,
)
from tests.artifacts.factories import FIXED_TIME

RIG = "STEREO-1"


def rig_definition(name: str = RIG) -> RigDefinition:
    return RigDefinition(
        name=name,
        cameras=["CAM-0001", "CAM-0002"],
        root="CAM-0001",
        design_baselines=[DesignBaseline(a="CAM-0001", b="CAM-0002", baseline_mm=75.0, tolerance_mm=0.5)],
        created_at=FIXED_TIME,
        created_by="op",
        station="st1",
    )


def rig_session(rig_session_id: str = "fedcba987654", status: str = "accepted") -> RigSession:
    gate = RigGate(gate="rig-connected", passed=status == "accepted", value=12, threshold=5, message="ok")
    return RigSession(
        rig_session_id=rig_session_id,
        rig=RIG,
        camera_sessions={"CAM-0001": "0123456789ab", "CAM-0002": "0123456789ac"},
        frames=[RigFrame(key=1, images={"CAM-0001": "left01.png", "CAM-0002": "right01.png"})],
        shared_views={"CAM-0001-CAM-0002": 1},
        gates=[gate],
        status=status,  # type: ignore[arg-type]
        created_at=FIXED_TIME,
        station="st1",
        operator="op",
    )


def rig_calibration(status: str = "accepted", baseline_m: float = 0.075) -> RigCalibration:
    T = np.eye(4)
    T[0, 3] = baseline_m
    member = {
        "image_size": (640, 480),
        "camera_matrix": ((800.0, 0.0, 320.0), (0.0, 800.0, 240.0), (0.0, 0.0, 1.0)),
        "dist_coeffs": [-0.28, 0.09, 0.0, 0.0, 0.0],
        "refined": False,
    }
    return RigCalibration(
        rig=RIG,
        version=1,
        status=status,
        root="CAM-0001",  # type: ignore[arg-type]
        members=[
            RigMember(serial="CAM-0001", version=1, content_sha256="ab" * 32, **member),  # type: ignore[arg-type]
            RigMember(serial="CAM-0002", version=1, content_sha256="cd" * 32, **member),
        ],  # type: ignore[arg-type]
        edges=[
            RigEdge(
                parent="CAM-0001",
                child="CAM-0002",
                T_parent_child=tuple(map(tuple, T.tolist())),
                covariance=(np.eye(6) * 1e-9).tolist(),
                translation_mm=baseline_m * 1e3,
                sigma_translation_mm=0.03,
                rotation_deg=0.0,
                sigma_rotation_deg=0.002,
            )
        ],
        pairs=[
            RigPair(
                a="CAM-0001",
                b="CAM-0002",
                baseline_mm=baseline_m * 1e3,
                sigma_baseline_mm=0.03,
                rotation_deg=0.0,
                sigma_rotation_deg=0.002,
                shared_views=12,
                epipolar_rms_px=0.05,
                epipolar_max_px=0.2,
                rectified_rms_px=0.05,
                rectified_max_px=0.2,
            )
        ],
        fit_rms_px={"CAM-0001": 0.04, "CAM-0002": 0.04},
        held_out_rms_px={"CAM-0001": 0.05, "CAM-0002": 0.05},
        held_out_folds=5,
        solver="cv2.stereoCalibrateExtended",
        refine_intrinsics=False,
        provenance=Provenance(
            calibctl_version="0.1.0",
            opencv_version="5.0.0",
            station="st1",
            operator="op",
            created_at=FIXED_TIME,
            session_id="fedcba987654",
        ),
        content_sha256=UNSEALED,
    )
