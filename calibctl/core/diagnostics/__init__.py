"""Field diagnostics, pure numpy: residual triage, metric-gauge watchdog, camera-IMU time offset.

student_t   Student t CDF / quantile without scipy
regression  OLS with honest standard errors, per-keyframe aggregation, collinearity checks
triage      which calibration parameter moved, from a residual buffer (seed chapters 4-5)
gauge       windowed wheel/VIO distance ratio (seed chapter 0)
timeoffset  normalised cross-correlation of angular rates, jackknife sigma, drift (seed chapter 3)
faults      the fault injector: synthetic residual buffers, odometry and rate logs
"""
