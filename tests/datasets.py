"""Where the real photos (../shared/datasets, not made by us) are, for every test that reads them.

CI clones the repository with ``shared/`` beside it; a developer's checkout has it at /work/shared.
``CALIBCTL_TEST_DATASETS`` overrides both. Locally a missing folder skips the real-photo tests with
the reason; under CI (``CI`` set) it fails them, so real-data coverage can never vanish silently.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

_CANDIDATES = [
    Path(os.environ["CALIBCTL_TEST_DATASETS"]) if os.environ.get("CALIBCTL_TEST_DATASETS") else None,
    Path(__file__).resolve().parents[2] / "shared" / "datasets",
    Path("/work/shared/datasets"),
]
DATASETS = next((p for p in _CANDIDATES if p is not None and p.is_dir()), _CANDIDATES[1])
LEFT_RIGHT = DATASETS / "opencv-left-right"
UDACITY = DATASETS / "udacity-camcal"
BAKA_STEREO = DATASETS / "baka-stereo"
AVAILABLE = LEFT_RIGHT.is_dir() and UDACITY.is_dir() and BAKA_STEREO.is_dir()


def require_datasets() -> None:
    """Call at the top of a real-photo test or fixture."""
    if AVAILABLE:
        return
    message = f"real photos not found at {DATASETS} (set CALIBCTL_TEST_DATASETS)"
    if os.environ.get("CI"):
        pytest.fail(message)
    pytest.skip(message)


needs_datasets = pytest.mark.usefixtures("_require_datasets")


ACFR = DATASETS / "acfr-lidar-camera"


def require_acfr() -> None:
    """Call at the top of a test on the acfr camera + VLP-16 set (same rule as require_datasets)."""
    if ACFR.is_dir():
        return
    message = f"acfr-lidar-camera not found at {ACFR} (set CALIBCTL_TEST_DATASETS)"
    if os.environ.get("CI"):
        pytest.fail(message)
    pytest.skip(message)
