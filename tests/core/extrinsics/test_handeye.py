"""Hand-eye AX = XB against the seed's chapter 2: worked examples 1 and 2, the corridor, the table."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.extrinsics import handeye as he
from calibctl.core.extrinsics import handeye_gates as gates
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.handeye_refine import fit_handeye
from calibctl.core.extrinsics.motion_synth import synthesize_motions, synthesize_pose_log

R_Z90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
EXACT = 1e-12
X_3D = se3.transform(se3.rotation_from_rotvec([0.3, -0.5, 1.2]), [0.12, -0.05, 0.30])


def _motions(R_A, t_A, R_B, t_B) -> he.Motions:
    R_A = np.asarray(R_A, float)
    return he.Motions(
        R_A,
        np.asarray(t_A, float),
        np.asarray(R_B, float),
        np.asarray(t_B, float),
        tuple(f"m{i}" for i in range(len(R_A))),
    )


def _from_log(log) -> he.Motions:
    labels = tuple(str(i) for i in range(len(log.T_first)))
    if log.shape == "poses":
        return he.Motions.from_poses(log.T_first, log.T_second, labels)
    return he.Motions.from_transforms(log.T_first, log.T_second, labels)


def test_worked_example_1_procrustes_recovers_90_deg_about_z_from_two_motions():
    b = np.array([[0.0, 0.0, 0.40], [0.0, 0.55, 0.0]])  # 0.40 rad about z, 0.55 rad about y
    a = b @ R_Z90.T  # a_i = R_X b_i
    np.testing.assert_allclose(a, [[0, 0, 0.40], [-0.55, 0, 0]], atol=EXACT)
    M = a.T @ b
    np.testing.assert_allclose(M, [[0, -0.3025, 0], [0, 0, 0], [0, 0, 0.16]], atol=EXACT)
    R_X = he.solve_rotation_park(a, b)
    np.testing.assert_allclose(R_X, R_Z90, atol=EXACT)
    assert np.linalg.det(R_X) == pytest.approx(1.0, abs=EXACT)


def test_worked_example_1_det_guard_picks_the_rotation_not_the_equally_good_reflection():
    b = np.array([[0.0, 0.0, 0.40], [0.0, 0.55, 0.0]])
    a = b @ R_Z90.T
    U, s, Vt = np.linalg.svd(a.T @ b)
    assert s[2] == pytest.approx(0.0, abs=EXACT)  # the data say nothing about the third direction
    candidates = [U @ np.diag([1, 1, sign]) @ Vt for sign in (1.0, -1.0)]
    costs = [float(np.sum(a * (b @ Q.T))) for Q in candidates]
    assert costs[0] == pytest.approx(costs[1], abs=EXACT)  # same least-squares cost...
    dets = sorted(round(float(np.linalg.det(Q))) for Q in candidates)
    assert dets == [-1, 1]  # ...one is a reflection
    np.testing.assert_allclose(he.solve_rotation_park(a, b), R_Z90, atol=EXACT)


def _example_2() -> tuple[he.Motions, np.ndarray]:
    t_X = np.array([0.30, 0.10, 0.0])
    t_B = np.array([0.50, 0.00, 0.0])
    R_A = R_Z90 @ R_Z90 @ R_Z90.T  # R_X R_B R_X^T with R_B = 90 deg about z
    t_A = R_Z90 @ t_B + t_X - R_A @ t_X
    return _motions([R_A], [t_A], [R_Z90], [t_B]), t_X


def test_worked_example_2_planar_lever_arm_from_one_90_deg_turn():
    motions, t_X = _example_2()
    np.testing.assert_allclose(motions.t_A_m[0], [0.40, 0.30, 0.0], atol=EXACT)
    np.testing.assert_allclose(he.solve_translation(motions, R_Z90), t_X, atol=EXACT)


def test_worked_example_2_planar_motion_leaves_the_height_unobservable_and_the_gate_says_so():
    motions, _ = _example_2()
    gate = gates.lever_arm_gate(motions, gates.HandEyeThresholds())
    assert not gate.passed and gate.value == pytest.approx(0.0, abs=EXACT)
    assert gate.detail["weakest_direction_a"] in (
        ["+0.000", "+0.000", "+1.000"],
        ["+0.000", "+0.000", "-1.000"],
        ["-0.000", "-0.000", "+1.000"],
        ["-0.000", "-0.000", "-1.000"],
    )


def test_corridor_pure_translation_is_refused_not_answered():
    log = synthesize_motions(X_3D, 20, excitation="corridor", seed=3)
    results = {g.gate: g for g in gates.evaluate_handeye_gates(_from_log(log))}
    assert not results["lever-arm"].passed and results["lever-arm"].value < 0.05
    assert not results["rotation"].passed
    assert results["lever-arm"].message.startswith("lever arm unobservable: sigma_min")


def test_the_seed_message_for_two_deg_of_rotation_about_two_axes():
    R = [se3.rotation_from_rotvec(np.radians([2.0, 0, 0])), se3.rotation_from_rotvec(np.radians([0, 2.0, 0]))]
    gate = gates.lever_arm_gate(_motions(R, np.zeros((2, 3)), R, np.zeros((2, 3))), gates.HandEyeThresholds())
    assert not gate.passed
    assert gate.message == (
        "lever arm unobservable: sigma_min 0.035 (about 2 deg of rotation); "
        "rotate at least 30 deg about two non-parallel axes"
    )
    assert gate.hint == "rotate at least 30 deg about two non-parallel axes"


@pytest.mark.parametrize(
    ("theta_deg", "two_sin", "lever_arm_error_m"),
    [
        (2, 0.0349, 0.287),
        (5, 0.0872, 0.115),
        (10, 0.1743, 0.057),
        (30, 0.5176, 0.019),
        (45, 0.7654, 0.013),
        (90, 1.4142, 0.007),
    ],
)
def test_conditioning_table_from_the_error_propagation(theta_deg, two_sin, lever_arm_error_m):
    R_A = se3.rotation_from_rotvec([0, 0, np.radians(theta_deg)])[None]
    sigma_min, _ = gates.lever_arm_conditioning(R_A)
    sigma_m, directions = he.lever_arm_sigma_m(R_A, 0.01)
    assert round(2 * np.sin(np.radians(theta_deg) / 2), 4) == two_sin
    # the table's 3 decimals (its 2 deg row rounds 0.28649 via 0.28650, so allow one unit in the last place)
    np.testing.assert_allclose(sigma_m[:2], [lever_arm_error_m] * 2, atol=1e-3)  # in the plane
    np.testing.assert_allclose(sigma_m[:2], 0.01 / (2 * np.sin(np.radians(theta_deg) / 2)), rtol=1e-12)
    assert np.isinf(sigma_m[2]) and abs(directions[2, 2]) == pytest.approx(1.0)  # the height: never
    assert sigma_min == pytest.approx(0.0, abs=EXACT)


def test_conditioning_propagation_matches_monte_carlo_of_the_planar_solve():
    rng = np.random.default_rng(7)
    theta = np.radians(30.0)
    R_A = se3.rotation_from_rotvec([0, 0, theta])
    lhs = (R_A - np.eye(3))[:2, :2]
    errors = np.linalg.solve(lhs, rng.normal(0.0, 0.01, (2, 4000))).T  # 1 cm in the motion translation
    predicted = he.lever_arm_sigma_m(R_A[None], 0.01)[0][:2]
    np.testing.assert_allclose(errors.std(axis=0), predicted, rtol=0.05)


@pytest.mark.parametrize("method", he.METHODS)
def test_noise_free_3d_motions_recover_x_exactly(method):
    fit = fit_handeye(_from_log(synthesize_motions(X_3D, 6, seed=1)), method)
    np.testing.assert_allclose(fit.T_a_b, X_3D, atol=1e-9)


def test_park_and_tsai_closed_forms_agree_on_noisy_data_and_refine_to_one_answer():
    m = _from_log(synthesize_motions(X_3D, 15, noise_rotation_deg=0.1, noise_translation_m=0.003, seed=2))
    R_park, R_tsai = (
        he.solve_rotation_park(m.rotvec_A_rad, m.rotvec_B_rad),
        he.solve_rotation_tsai(m.rotvec_A_rad, m.rotvec_B_rad),
    )
    assert np.degrees(se3.rotation_angle_rad(R_park.T @ R_tsai)) < 0.2
    park, tsai = fit_handeye(m, "park"), fit_handeye(m, "tsai")
    np.testing.assert_allclose(park.T_a_b, tsai.T_a_b, atol=1e-8)
    assert np.degrees(se3.rotation_angle_rad(park.T_a_b[:3, :3].T @ X_3D[:3, :3])) < 0.3
    assert np.linalg.norm(park.T_a_b[:3, 3] - X_3D[:3, 3]) < 0.01


def test_unknown_method_is_refused():
    with pytest.raises(ValueError, match="unknown hand-eye method"):
        fit_handeye(_from_log(synthesize_motions(X_3D, 4)), "horaud")


def _z_scores(n_runs: int) -> np.ndarray:
    z = []
    for seed in range(n_runs):
        log = synthesize_motions(X_3D, 12, noise_rotation_deg=0.05, noise_translation_m=0.005, seed=seed)
        fit = fit_handeye(_from_log(log), "park")
        z.append((fit.T_a_b[:3, 3] - X_3D[:3, 3]) / fit.sigma_translation_m)
    return np.concatenate(z)


def test_reported_lever_arm_sigma_is_honest_over_seeded_3d_runs():
    z = _z_scores(60)  # 180 z values: standard error of the mean 0.075
    assert abs(z.mean()) <= 0.3
    assert 0.7 <= z.std() <= 1.5


def test_pose_logs_are_refined_on_poses_and_their_sigmas_are_honest_too():
    z_t, z_r = [], []
    for seed in range(40):
        log = synthesize_pose_log(X_3D, 20, noise_rotation_deg=0.05, noise_translation_m=0.002, seed=seed)
        fit = fit_handeye(_from_log(log))
        assert fit.model == "poses"
        z_t.append((fit.T_a_b[:3, 3] - X_3D[:3, 3]) / fit.sigma_translation_m)
        z_r.append(
            np.degrees(se3.rotvec_from_rotation(fit.T_a_b[:3, :3] @ X_3D[:3, :3].T)) / fit.sigma_rotation_deg
        )
    for z in (np.concatenate(z_t), np.concatenate(z_r)):  # 120 values each: standard error of the mean 0.09
        assert abs(z.mean()) <= 0.3
        assert 0.7 <= z.std() <= 1.5


def test_single_axis_motions_fail_the_rotation_gate_two_axes_pass():
    one_axis = synthesize_motions(X_3D, 10, excitation="planar", seed=4)
    assert not gates.rotation_gate(_from_log(one_axis), gates.HandEyeThresholds()).passed
    assert gates.rotation_gate(
        _from_log(synthesize_motions(X_3D, 10, seed=4)), gates.HandEyeThresholds()
    ).passed


def test_a_time_offset_is_named_by_the_angle_screen_and_a_synchronised_log_passes():
    late = synthesize_pose_log(X_3D, 30, time_offset_s=0.08, seed=5)
    on_time = synthesize_pose_log(X_3D, 30, seed=5)
    gate = gates.time_alignment_gate(_from_log(late), gates.HandEyeThresholds())
    assert not gate.passed and gate.message.startswith("time alignment:")
    assert gate.detail["mismatched_motions"]
    assert gates.time_alignment_gate(_from_log(on_time), gates.HandEyeThresholds()).passed


def test_pose_log_3d_passes_every_gate_and_recovers_x():
    log = synthesize_pose_log(X_3D, 30, noise_rotation_deg=0.02, noise_translation_m=0.001, seed=6)
    m = _from_log(log)
    assert all(g.passed for g in gates.evaluate_handeye_gates(m))
    fit = fit_handeye(m)
    assert np.linalg.norm(fit.T_a_b[:3, 3] - X_3D[:3, 3]) < 5 * np.linalg.norm(fit.sigma_translation_m)


def test_one_corrupted_motion_is_named_as_an_outlier():
    log = synthesize_motions(X_3D, 15, noise_rotation_deg=0.05, noise_translation_m=0.002, seed=8)
    log.T_first[6][:3, 3] += [0.0, 0.08, 0.0]
    fit = fit_handeye(_from_log(log))
    assert np.flatnonzero(gates.outlier_motions(fit)).tolist() == [6]


def test_thresholds_refuse_impossible_values():
    with pytest.raises(ValueError):
        gates.HandEyeThresholds(lever_arm_sigma_min=0.0)
    with pytest.raises(ValueError):
        gates.HandEyeThresholds(mismatch_fraction_max=1.0)
    with pytest.raises(ValueError):
        gates.HandEyeThresholds(rotation_residual_max_deg=-1.0)


def _scaled(log, scale_a: float, scale_b: float = 1.0) -> he.Motions:
    T_a, T_b = log.T_first.copy(), log.T_second.copy()
    T_a[:, :3, 3] *= scale_a
    T_b[:, :3, 3] *= scale_b
    return he.Motions.from_poses(T_a, T_b, tuple(str(i) for i in range(len(T_a))))


@pytest.mark.parametrize("noise_m", [0.002, 0.02])
def test_translation_scale_is_one_for_metric_logs_and_the_unit_factor_for_a_wrong_unit(noise_m):
    # The translation half with a free scale on a: 1 when both are in metres (noise moves it < 2 % on
    # these logs), 1/1000 when a is in mm, 100 when b is in cm: whatever lever arm the solve produced.
    log = synthesize_pose_log(X_3D, 30, noise_translation_m=noise_m, seed=3)
    for scale_a, scale_b, expected in ((1.0, 1.0, 1.0), (1000.0, 1.0, 1e-3), (1.0, 100.0, 100.0)):
        motions = _scaled(log, scale_a, scale_b)
        s, sigma = he.translation_scale(motions, fit_handeye(motions).T_a_b[:3, :3])
        assert s == pytest.approx(expected, rel=0.05) and sigma < 0.05 * expected


def test_translation_scale_gate_names_the_unit_and_the_sensor():
    log = synthesize_pose_log(X_3D, 30, seed=3)
    clean = _scaled(log, 1.0)
    gate = gates.translation_scale_gate(clean, fit_handeye(clean), ("lidar", "camera"))
    assert gate.passed and gate.value < 1.05 and gate.gate == "translation-scale"
    for scale_a, scale_b, sensor, unit in (
        (1000.0, 1.0, "lidar", "millimetres"),
        (1.0, 100.0, "camera", "centimetres"),
        (1 / 0.3048, 1.0, "lidar", "feet"),
    ):
        motions = _scaled(log, scale_a, scale_b)
        fit = fit_handeye(motions)
        gate = gates.translation_scale_gate(motions, fit, ("lidar", "camera"))
        assert not gate.passed and gate.reason == "translation_scale.unit"
        assert f"{sensor}'s translations look like {unit}, not metres" in gate.message
        assert gate.hint == f"convert {sensor}'s translations to metres"
    motions = _scaled(log, 2.0)  # no unit: a scale-free odometry, a wrong square size
    gate = gates.translation_scale_gate(motions, fit_handeye(motions), ("lidar", "camera"))
    assert (
        not gate.passed
        and gate.reason == "translation_scale.mismatch"
        and gate.value == pytest.approx(2.0, rel=0.05)
    )


def test_translation_scale_is_not_judged_when_a_never_translates():
    # a turns about its own origin in every motion: its translations (and their unit) carry nothing
    rotvecs = np.array([[0.6, 0.0, 0.0], [0.0, 0.7, 0.0], [0.0, 0.0, 0.8], [0.4, 0.4, 0.0]])
    R_A = np.array([se3.rotation_from_rotvec(v) for v in rotvecs])
    A = np.array([se3.transform(R, np.zeros(3)) for R in R_A])
    B = np.array([se3.invert(X_3D) @ T @ X_3D for T in A])
    motions = he.Motions.from_transforms(A, B, tuple(f"m{i}" for i in range(4)))
    s, sigma = he.translation_scale(motions, X_3D[:3, :3])
    assert sigma == np.inf
    assert gates.translation_scale_gate(motions, fit_handeye(motions)).passed


def test_a_camera_scale_off_by_a_typed_square_size_is_a_metric_gauge_verdict():
    # 23 mm typed for a 25 mm board scales every camera translation by 0.92: it used to pass (limit 1.25x)
    log = synthesize_pose_log(X_3D, 30, seed=3)
    typo = _scaled(log, 1.0, 0.92)
    gate = gates.translation_scale_gate(typo, fit_handeye(typo), ("base", "camera"))
    assert not gate.passed and gate.reason == "translation_scale.metric_gauge"
    assert "the metric gauge disagrees" in gate.message and "tolerance 1 %" in gate.message
    assert "calibctl check --reference-distance" in (gate.hint or "")
    assert gate.value == pytest.approx(1 / 0.92, rel=0.01)
    # within the station's tolerance it passes; a looser station tolerance lets 0.92 through
    near = _scaled(log, 1.0, 0.995)
    assert gates.translation_scale_gate(near, fit_handeye(near), ("base", "camera")).passed
    assert gates.translation_scale_gate(typo, fit_handeye(typo), ("base", "camera"), tolerance=0.1).passed


def test_a_translation_scale_tolerance_must_be_positive():
    with pytest.raises(ValueError):
        gates.HandEyeThresholds(translation_scale_tolerance=0.0)
