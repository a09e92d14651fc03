"""``calibctl check``: re-test a stored calibration on fresh views without re-solving it (the stored model's
own residual definition, the delta-model test of focal and principal point). May import
``core.intrinsics`` and ``core.extrinsics`` (SE(3) helpers); nothing imports it but workflows.
"""
