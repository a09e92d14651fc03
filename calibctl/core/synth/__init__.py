"""Ground truth for tests, benchmarks and ``calibctl synth``: ray-cast pinhole and fisheye board renders,
scenes, rigs, and corner-level sessions without images. May import ``core.board`` and ``core.intrinsics``
(the fisheye projection); no product room imports it.
"""
