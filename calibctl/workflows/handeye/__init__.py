"""Hand-eye (AX = XB) from motion logs and from a robot arm with a board, and hand-eye edges of a rig's
tree: log parsing, the solve workflow, storing edges. May import camera (board poses), board,
store_admin, exports and diagnostics (log readers); never rig.
"""
