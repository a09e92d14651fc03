"""Camera-LiDAR extrinsics from a board both sensors see: scans in, T_lidar_cam with its covariance out.

What this room owns (docs/lidar.md): parsing LiDAR sweeps (``pcd``: PCD v0.7 ascii / binary /
binary_compressed, plain N x 3/4 arrays), finding the board in a sweep inside a station box
(``segment``: RANSAC plane, least squares, outline from ring end points, dimension error, per-scan
outcome), the board plane in the camera (``target``), the solve (``solve``: closed form from plane
normals and distances, then joint least squares with the camera poses as nuisance parameters), its
checks (``validation``: k-fold held-out, range offset from board sizes, acfr's roll/pitch/yaw), the
gates (``gates``) and a camera + VLP-16-like ring LiDAR renderer with known T (``render``).

Frames: ``T_lidar_cam`` maps camera-frame points into the LiDAR frame, ``p_lidar = R p_cam + t``
(the convention of acfr/cam_lidar_calibration's published numbers). Units: metres inside, mm in reports.

May import: ``core.board``, ``core.intrinsics``, ``core.extrinsics``, ``core.gate`` (top layer of core).
"""
