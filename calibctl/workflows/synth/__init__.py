"""``calibctl synth``: synthetic sessions written to disk (camera folders, videos, rig folders) with their
truth. Never opens the store.
"""
