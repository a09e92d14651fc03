"""The calibration report page of one stored camera version: what it draws (``report_data``), gathering
it from the store (``report``), and the HTML/SVG writers. May import board and store_admin; never
camera, rig or handeye (the rig page lives in ``workflows.rig`` and reuses the writers).
"""
