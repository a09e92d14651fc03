"""Extrinsics: rigid transforms between sensors (SE(3) helpers, hand-eye AX = XB)."""
