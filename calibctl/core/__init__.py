"""The numbers: pure numpy and OpenCV, no store, no artifacts, no CLI (import-linter enforces it).

One room per capability, each importing only the rooms below it (docs/architecture.md):
``board`` <- ``intrinsics`` <- ``capture``, ``extrinsics`` <- ``check``, ``synth``; ``diagnostics`` stands
alone. ``blas_threads`` (thread limits), ``gate`` (the verdict type) and ``lm`` (the Levenberg-Marquardt
solver of the fisheye, rig and board-pose fits) are shared by every room.
"""
