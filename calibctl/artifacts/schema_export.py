"""Generate the committed JSON Schemas in ``schemas/`` from the pydantic models.

``make schemas`` runs this; tests/artifacts/test_schemas.py fails on any drift between the models
and the committed files, so a contract change is always a reviewed diff.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from pydantic import BaseModel

from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.check import CheckEvent
from calibctl.artifacts.events import ActivationEvent
from calibctl.artifacts.fleet import FleetEvent
from calibctl.artifacts.handeye import HandEyeResult
from calibctl.artifacts.health import HealthReport
from calibctl.artifacts.rig import RigActivation, RigCalibration, RigDefinition, RigSession
from calibctl.artifacts.session import CaptureSession
from calibctl.files import write_atomic

DOCUMENTS: dict[str, type[BaseModel]] = {
    "board-revision": BoardRevision,
    "check-event": CheckEvent,
    "capture-session": CaptureSession,
    "calibration": CalibrationArtifact,
    "activation-event": ActivationEvent,
    "handeye-result": HandEyeResult,
    "rig-definition": RigDefinition,
    "rig-session": RigSession,
    "rig-calibration": RigCalibration,
    "rig-activation": RigActivation,
    "fleet-event": FleetEvent,
    "health-report": HealthReport,
}


def schema_text(model: type[BaseModel]) -> str:
    schema = model.model_json_schema(mode="validation")
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    return json.dumps(schema, indent=2, sort_keys=True) + "\n"


def expected_files() -> dict[str, str]:
    """File name -> content for every schema calibctl publishes."""
    version = {
        "board-revision": 1,
        "capture-session": 1,
        "calibration": 1,
        "activation-event": 1,
        "handeye-result": 1,
        "rig-definition": 1,
        "rig-session": 1,
        "rig-calibration": 1,
        "rig-activation": 1,
        "check-event": 1,
        "fleet-event": 1,
        "health-report": 1,
    }
    return {f"{name}.v{version[name]}.schema.json": schema_text(model) for name, model in DOCUMENTS.items()}


def write(out_dir: Path) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, text in expected_files().items():
        path = out_dir / name
        write_atomic(path, text, force=True)
        written.append(path)
    return written


if __name__ == "__main__":
    for path in write(Path(sys.argv[1] if len(sys.argv) > 1 else "schemas")):
        print(path)
