"""From images to an accepted capture: board detection, per-image outcomes, frame selection for video and
live sources, the image circle of a circular fisheye, board-extent probing, per-view tilt, the capture
gates that say what to do next, and the one-camera (two-camera split) test. May import ``core.board`` and
``core.intrinsics`` (tilt and the one-camera test fit a lens); never extrinsics, check or synth.
"""
