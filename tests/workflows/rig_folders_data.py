"""A rendered 2-camera rig (75 mm) shared by the rig workflow and CLI tests, rendered once per process."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from calibctl.workflows.synth.synth_rig import run_synth_rig

_CACHE: dict[str, Path] = {}


def rendered_rig(factory: pytest.TempPathFactory) -> Path:
    """OUT of ``calibctl synth --rig 2 --views 8 --baseline-mm 75 --seed 7`` (do not write into it)."""
    if "rig2" not in _CACHE:
        out = factory.mktemp("rig") / "rig2"
        run_synth_rig(out, 2, seed=7, frames=8, baseline_mm=75.0)
        _CACHE["rig2"] = out
    return _CACHE["rig2"]


def rig_sources(rig: Path, cam1: Path | None = None) -> list[str]:
    """The ``--source CAM0=DIR --source CAM1=DIR`` options of a rendered rig (CAM1's folder ``cam1`` where
    given)."""
    return ["--source", f"CAM0={rig / 'CAM0'}", "--source", f"CAM1={rig / 'CAM1' if cam1 is None else cam1}"]


def true_baseline_mm(out: Path) -> float:
    truth = json.loads((out / "rig_truth.json").read_text())
    return float(np.linalg.norm(np.array(truth["cameras"][1]["T_root_cam"])[:3, 3]) * 1e3)


def split_pairs(src: Path, dst: Path, pattern_left: str, pattern_right: str) -> tuple[Path, Path]:
    """Copy a flat folder of left*/right* photos into dst/left and dst/right."""
    left, right = dst / "left", dst / "right"
    left.mkdir(parents=True)
    right.mkdir(parents=True)
    for p in src.glob(pattern_left):
        shutil.copy(p, left / p.name)
    for p in src.glob(pattern_right):
        shutil.copy(p, right / p.name)
    return left, right
