"""Camera-IMU calibration core (seed chapters 2-3): T_imu_cam and the time offset td as states.

May import ``core.board``, ``core.intrinsics``, ``core.extrinsics``, ``core.diagnostics.timeoffset``
(the rate cross-correlation), ``core.lm`` and ``core.gate``; pure numpy + OpenCV. Nothing in core
imports it (it sits on the top core level beside ``lidar``).

Conventions. w = the board frame; ``T_a_b`` (4, 4) maps points in b into a, so p_imu = R p_cam + t
with (R, t) = T_imu_cam. Time: ``t_imu = t_cam + td_s`` (a frame stamped t_cam on the camera clock was
seen at t_cam + td_s on the IMU clock); Kalibr's ``timeshift_cam_imu`` is the same number, and
Kalibr's ``T_cam_imu`` is ``ImuCameraSolution.T_cam_imu``. SI units inside (s, rad, m, px); sigmas
reported in deg, mm, ms. Rotation uncertainty is a left perturbation in the IMU frame:
R = Exp(d) R_hat, d ~ N(0, covariance_7[:3, :3]).

Inputs (``samples``; each raises an ``ImuInputError`` (ValueError) subclass naming the fix):
    ImuNoise(gyro_noise_density, accel_noise_density, gyro_random_walk, accel_random_walk,
             gravity_m_s2)                          Kalibr imu.yaml fields, continuous-time SI
    ImuSamples(t_s (n,), gyro_rad_s (n, 3), accel_m_s2 (n, 3), gyro_range_rad_s=None,
               accel_range_m_s2=None)                refuses stamps not strictly increasing
                                                     (StampOrderError), deg/s or g (ImuUnitError)
    CameraFrames(t_s (F,), object_points F x (N_f, 3) m, image_points F x (N_f, 2) px,
                 camera_matrix (3, 3), dist_coeffs (k,) OpenCV order, image_size (w, h))
    gaps(t_s) -> (k, 2) [start, end] s of intervals over 2.5 median periods

The plain approach (``plain``): board_track(frames) -> BoardTrack (PnP poses);
    plain_calibration(imu, frames) -> PlainResult(T_imu_cam, td_s, gyro_bias_rad_s,
    accel_bias_m_s2, gravity_w_m_s2, rate_ncc): rate cross-correlation, Kabsch on rates,
    twice-differentiated positions. The estimator's start and the benchmark's baseline.

The estimator (``solve``): solve_imu_camera(imu, frames, noise, SolveOptions(...)) ->
    ImuCameraSolution: T_imu_cam (4, 4), td_s, td_held, line_delay_s (s/row from c_y, or None),
    gyro_bias_rad_s (3,), accel_bias_m_s2 (3,), gravity_w_m_s2 (3,) board frame,
    covariance over state_names, covariance_7 (7, 7) over (rot 3 rad, trans 3 m, td s),
    sigma_rotation_deg (3,), sigma_translation_mm (3,), sigma_td_ms, td_crlb_ms (td's bound with
    every other state known: sigma_px / sqrt(sum |u_dot|^2), chapter 3), sigma_line_delay_us,
    corner/gyro/accel RMS, held_out (k-fold RMS per fold), residuals (per corner and IMU sample,
    with stamps and image rows: the report's plots), T_cam_imu, timeshift_cam_imu_s.

Gates (``gates``; ``core.gate.GateResult``, each with the next action in its hint):
    check_recording(imu, frames, solution) -> list[GateResult]: rotational excitation, td
    observability, the (td, yaw) correlation, saturation, IMU gaps, dropped frames.
    calibrate(imu, frames, noise, options) -> Calibration(solution, gates, held, verdict text):
    solve, gate, and on a high (td, rotation) correlation re-solve with td held (when the caller
    gave a value to hold) or refuse, naming which and why.
"""
