"""The calibration target as geometry: board specs (chessboard, ChArUco, AprilGrid), model points, the desk
gauge of the square size against a span measurement, and ``BoardView`` (corners matched to model points),
the unit every other core room consumes. Imports numpy and OpenCV only; no other core room.
"""
