"""Rendered synthetic sessions shared by the capture tests: each scenario is rendered once per process.

``rendered(tmp_path_factory, scenario)`` returns the folder ``calibctl synth`` wrote (seeded, so the
same files every run). Tests must not write into it: copy it first.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from calibctl.workflows.synth import run_synth

SEED = 1
SIZES = {"video": (320, 240)}  # the video path only needs frames; 320x240 renders in 2/3 of the time
_CACHE: dict[str, Path] = {}


def rendered(factory: pytest.TempPathFactory, scenario: str) -> Path:
    """The folder of a rendered scenario (12 views at 640x480; the video: 8 key poses at 320x240)."""
    if scenario not in _CACHE:
        out = factory.mktemp(f"synth-{scenario}") / scenario
        run_synth(out, scenario, seed=SEED, image_size=SIZES.get(scenario, (640, 480)))
        _CACHE[scenario] = out
    return _CACHE[scenario]
