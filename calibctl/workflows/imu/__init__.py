"""Camera-IMU calibration: a recording in, T_imu_cam and the time offset td_s with their one-sigma, the
gates and a verdict out; with ``--rig`` the rig's next version with the edge ``imu -> camera``.

``recording`` reads the IMU log, the per-frame corners and the IMU noise model (bounded; stamps in ns;
units checked); ``imu_solve`` pins the camera's active stored calibration, runs core.imu's solve and
gates, builds the edge's evidence (``RigCalibration.imu``) at full precision and stores it through the
``edges`` room (``run_imu`` is the whole command in one call); ``imu_synth`` writes a rendered
recording with its truth; ``imu_report`` draws an edge's section of ``calibctl report --rig`` from its
stored evidence. Beside ``lidar | handeye`` (imports neither), below ``rig``, above ``edges``.
"""
