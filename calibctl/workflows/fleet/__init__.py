"""The fleet (issue 25 item 2, first step): robots (named units carrying camera serials and rigs), which
calibration version each one runs, and ``fleet status``. The top workflow room: rollouts will gate on
``compare`` (diff) and the field checks, so it may import every room below it.
"""
