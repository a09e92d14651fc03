"""One camera's use cases: capture (folders, videos, live), the pattern and distance checks at capture,
image circles, solve into a stored artifact, ``check`` against the active version, and the demo.
May import the rooms below it (report, lint, synth, board, store_admin, exports); never rig or handeye.
"""
