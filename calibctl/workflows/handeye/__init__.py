"""Hand-eye (AX = XB) from motion logs and from a robot arm with a board, and hand-eye edges of a rig's
tree: log parsing, the solve workflow (``handeye_run``: the whole command in one call), storing edges
through the ``edges`` room (``rig_handeye``). May import camera (board poses), board, edges, store_admin,
exports and diagnostics (log readers); never rig or lidar.
"""
