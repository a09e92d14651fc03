"""Field diagnostics on files a robot sends: residual buffers, wheel/VIO gauge logs, IMU and camera rates
(``triage``, ``gauge``, ``timeoffset``, the ``synth-*`` generators) and their plots. Never imports the
store or the artifacts.
"""
