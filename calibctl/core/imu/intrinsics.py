"""The IMU's own intrinsics: Kalibr's IMU models as optional states of the camera-IMU solve.

``calibrated`` (the default): the IMU measures the body rate and specific force in one frame, in SI
units, up to a bias. ``scale-misalignment`` (Kalibr's ``IccScaledMisalignedImu``): with w and a the
IMU-frame body rate and specific force,

    gyro  = M_gyro (C_gyro_i w) + A_gyro (C_gyro_i a) + b_g
    accel = M_accel a + b_a

M_gyro and M_accel lower-triangular (scale on the diagonal, axis misalignment below it: the IMU frame
is the accelerometer triad's, its x axis the accelerometer's x, its y in the accelerometer's x-y
plane), C_gyro_i the gyro triad's rotation from the IMU frame, A_gyro the gyro's g-sensitivity
((rad/s)/(m/s^2)). Kalibr's size effect (accelerometer lever arms) is not modelled.

States: 24 deviations from identity, ``x`` in ``NAMES`` order: M_gyro - I (6, lower triangle row by
row), C_gyro_i as a rotation vector (3, rad), M_accel - I (6), A_gyro (9, row-major). Each has a weak
prior at zero (``PRIOR_SIGMAS``) so a short recording stays well posed; ``observability`` says whether
the data, not the prior, pinned them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibctl.core.extrinsics import se3

IMU_MODELS = ("calibrated", "scale-misalignment")
_TRI = ((0, 0), (1, 0), (1, 1), (2, 0), (2, 1), (2, 2))
_AXES = "xyz"
NAMES = (
    tuple(f"mg_{_AXES[i]}{_AXES[j]}" for i, j in _TRI)
    + tuple(f"cg_{a}" for a in _AXES)
    + tuple(f"ma_{_AXES[i]}{_AXES[j]}" for i, j in _TRI)
    + tuple(f"ag_{a}{b}" for a in _AXES for b in _AXES)
)
# Weak priors (one sigma about identity): 2 % scale / 0.02 rad misalignment (typical MEMS data sheets
# give under 1 %), 0.02 rad (1.1 deg) gyro-to-accelerometer rotation, 0.005 (rad/s)/(m/s^2) g-sensitivity
# (data sheets: under 0.1 deg/s/g = 1.8e-4).
PRIOR_SIGMAS = np.r_[np.full(6, 0.02), np.full(3, 0.02), np.full(6, 0.02), np.full(9, 0.005)]
# The data must pin every direction of the block this many times tighter (in information, prior-scaled)
# than the prior alone: 100 = the data's sigma at most a tenth of the prior's.
MIN_INFORMATION = 100.0


def matrices(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(24,) states -> M_gyro, C_gyro_i, A_gyro, M_accel, each (3, 3)."""
    M_g, M_a = np.eye(3), np.eye(3)
    for k, (i, j) in enumerate(_TRI):
        M_g[i, j] += x[k]
        M_a[i, j] += x[9 + k]
    return M_g, se3.rotation_from_rotvec(x[6:9]), x[15:24].reshape(3, 3), M_a


def measurement_map(x: np.ndarray) -> np.ndarray:
    """(6, 6) T with [gyro, accel] = T [w, a] (biases aside): [[M_g C, A_g C], [0, M_a]]."""
    M_g, C, A_g, M_a = matrices(x)
    T = np.zeros((6, 6))
    T[:3, :3], T[:3, 3:], T[3:, 3:] = M_g @ C, A_g @ C, M_a
    return T


def map_jacobians(x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """(24, 6, 6): d measurement_map / d x_k by central differences (exact for all but C_gyro_i)."""
    out = np.empty((x.size, 6, 6))
    for k in range(x.size):
        d = np.zeros(x.size)
        d[k] = h
        out[k] = (measurement_map(x + d) - measurement_map(x - d)) / (2 * h)
    return out


def observability(covariance: np.ndarray) -> float:
    """The smallest eigenvalue of the data's information on the 24 states (the marginal information,
    everything else integrated out, less the prior's), scaled by the prior sigmas: ``MIN_INFORMATION``
    or more when the recording, not the prior, pinned every direction. ``covariance``: (24, 24), the
    white-noise marginal covariance of the states with the prior in it."""
    info = np.linalg.inv(covariance) - np.diag(1.0 / PRIOR_SIGMAS**2)
    D = np.diag(PRIOR_SIGMAS)
    return float(np.linalg.eigvalsh(0.5 * (D @ info @ D + (D @ info @ D).T))[0])


@dataclass(frozen=True)
class ImuIntrinsics:
    """The solved IMU model: ``model`` (one of ``IMU_MODELS``), the states ``x`` (24,) in ``NAMES``
    order with their one-sigma ``sigma`` (24,) (jackknife-widened like every state), the matrices in
    Kalibr's meaning, and ``min_information`` (``observability``)."""

    model: str
    x: np.ndarray
    sigma: np.ndarray
    min_information: float

    @property
    def M_gyro(self) -> np.ndarray:
        return matrices(self.x)[0]

    @property
    def C_gyro_i(self) -> np.ndarray:
        return matrices(self.x)[1]

    @property
    def A_gyro(self) -> np.ndarray:
        return matrices(self.x)[2]

    @property
    def M_accel(self) -> np.ndarray:
        return matrices(self.x)[3]
