"""Where sensors sit relative to each other: SE(3) algebra, the rig (multi-camera) tree, its initialisation,
joint solve, metrics and held-out validation, board poses, and hand-eye (AX = XB) with its gates and
refinement. May import ``core.board`` and ``core.intrinsics``; never capture, check or synth.
"""
