"""Files a robot loads, written and read without the store: the export formats (JSON/YAML artifact, ROS
camera_info, OpenCV FileStorage), the trace header, and the rig's tf / URDF / Kalibr / stereo files.
Imports no other workflow room and never the store.
"""
