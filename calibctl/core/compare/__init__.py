"""``calibctl diff``: is one calibration different from another beyond their uncertainties?

lens             a stored lens as numbers (K, distortion, its intrinsic covariance), projection and
                 unprojection with the Jacobians the comparison needs (pinhole and fisheye)
projection_diff  the projection difference over the imager, with and without the implied rotation
                 (mrcal's show-projection-diff), its expected spread from both covariances, the
                 chi-square test that decides "same within noise"
chi2             chi-square survival function and quantile without scipy
rig_diff         two rig versions: baseline and rotation change per camera pair with sigma, and the
                 predicted depth-error change at a few ranges

May import ``core.intrinsics`` and ``core.extrinsics``; nothing imports it but workflows.
"""
