"""The default lens model's name, importable without numpy or OpenCV: the command line's option defaults use
it (``--help`` and the read commands import no OpenCV), the solves and every ``model=`` default below them
too."""

DEFAULT_MODEL = "k1k2"  # FIX_K3 | ZERO_TANGENT_DIST | FIX_ASPECT_RATIO (core.intrinsics.solution.MODELS)
