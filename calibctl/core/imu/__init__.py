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
    ImuCameraSolution: T_imu_cam (4, 4), td_s, td_held, line_delay_s (s per row from c_y, or None),
    gyro_bias_rad_s (3,), accel_bias_m_s2 (3,) (+ *_drift per second with bias_drift; the walks'
    means with bias_walk), gravity_w_m_s2 (3,) board frame, covariance over state_names, covariance_7
    (7, 7) over (rot 3 rad, trans 3 m, td s; td's row and column zero when held), sigma_rotation_deg
    (3,), sigma_translation_mm (3,), sigma_td_ms, td_crlb_ms (td's bound with every other state known:
    sigma_px / sqrt(sum |u_dot|^2), chapter 3), sigma_line_delay_us, sigma_inflation (the
    delete-one-block jackknife's widening per state, >= 1), corner/gyro/accel RMS (corners over 5
    robust sigmas left out: n_outliers), held_out (k-fold RMS per fold), residuals (per corner and
    IMU sample, with stamps, image rows, the inlier mask, and the biases at every IMU sample: the
    report's plots), T_cam_imu, timeshift_cam_imu_s, plain (the PlainResult it started from), cpu_s.
    SolveOptions: knot_spacing_s (0.05), corner_sigma_px, fix_corner_sigma, fix_imu_sigma (the IMU at
    the noise file's densities, not raised to its residuals), estimate_line_delay, bias_drift,
    bias_walk (the biases as random walks weighted by the noise file's random-walk densities),
    hold_td_s, folds (3), jackknife_blocks (10), max_iterations, margin_s, imu_model ("calibrated" or
    "scale-misalignment": ``imu_intrinsics`` on the solution).
    solve_imu_cameras(imu, [frames, ...], noise, options, rig=None) -> [ImuCameraSolution, ...]:
    several cameras against ONE IMU trajectory, gravity and biases (each camera its own T_imu_cam,
    td, line delay); rig[k] = T_cam0_camk holds camera k through a pose the rig already knows.

The row test and the report's series (``rows``): row_test(solution, frames) -> RowTest
    (slope_s_per_row, sigma_s_per_row, offset_s, z, significant, message, per-row bins) or None;
    report_series(solution, imu, frames) -> ReportSeries (gyro and camera rate, residual RMS per time
    bin).

Gates (``gates``; ``core.gate.GateResult``, each with the next action in its hint):
    rotational_excitation(track), td_observability(frames, td_crlb_ms), td_rotation_correlation(
    covariance_7, td_held), saturation(imu), imu_gaps(imu), dropped_frames(frames),
    imu_model_observability(model, min_information), board_scale(BoardScale, square_mm),
    camera_fit(CameraFit).

The board's metric gauge and the camera's fit (``metric``): board_scale(imu, cameras, noise, options,
    tracks, solutions, rig) -> BoardScale(scale, sigma, inflation): one more solve with the board's
    true / registered size as a state (``SolveOptions.board_scale``; ``ImuCameraSolution.board_scale``);
    camera_fit(frames, track, solution) -> CameraFit: the corners' F ratio about the IMU's trajectory
    against their per-frame PnP poses; pnp_residuals(frames, track).

The IMU's own intrinsics (``intrinsics``): Kalibr's scale-misalignment model as 24 states about
    identity (NAMES, PRIOR_SIGMAS), matrices(x) -> M_gyro, C_gyro_i, A_gyro, M_accel,
    observability(covariance) -> the data's least prior-scaled information, ImuIntrinsics.
The one call (``calibrate``): calibrate(imu, frames, noise, options, fallback_td_s=None, square_mm=None) ->
    Calibration(solution | None, gates, held, held_reason; passed, failed): solve and gate; on a
    (td, rotation) degeneracy (the correlation gate, or a rate cross-correlation that cannot pin td)
    re-solve with td held at fallback_td_s and say so (held = "td"), or refuse (passed False,
    solution None when nothing could be solved). Raises ImuInputError subclasses on bad input.
    calibrate_cameras(imu, [frames, ...], noise, options, fallback_td_s=None, rig=None, square_mm=None)
    -> [Calibration, ...]: the same for a joint solve, each camera gated (a held td is held for all).
    Every solved verdict carries ``board_scale`` (square_mm: the registered edge it names) and
    ``camera_fit`` (``metric``).
"""
