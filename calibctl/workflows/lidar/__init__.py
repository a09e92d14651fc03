"""Camera-LiDAR calibration at the station: scans and images in, T_lidar_cam with its one-sigma and a
verdict out.

``scans`` reads LiDAR sweeps (bounded) and pairs them with images by the last number in the file name;
``camera`` gives the lens (a ROS camera_info file, or a camera's active calibration in the store);
``lidar_solve`` runs segmentation, the camera poses, the gates and the solve (core.lidar) into a typed
result (``result_json`` its rounded JSON); ``rig_lidar`` makes it a rig edge's evidence (the ``edges`` room);
``lidar_run`` is the whole command in one call (check, solve, store, files);
``lidar_overlay`` draws the sweeps over the images through the solved T;
``lidar_synth`` writes a rendered set with known T. Sits above ``camera`` (it reads a camera's active
calibration) and beside ``handeye`` (neither imports the other), below ``rig``, above ``edges``.
"""
