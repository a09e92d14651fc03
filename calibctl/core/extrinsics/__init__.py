"""Extrinsics: rigid transforms between sensors (camera rigs; hand-eye)."""
