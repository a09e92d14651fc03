"""The fleet: robots (named units carrying camera serials and rigs), which calibration version each one
runs, ``fleet status``, rollouts, and the health reports robots send (``fleet ingest``, ``fleet trends``).
The top workflow room: rollouts gate on ``compare`` (diff) and the field checks, so it may import every
room below it.
"""
