"""Camera rigs: ``capture --rig`` / ``solve --rig``, ``rig solve-folders``, the rig lint, the rig report
page and rig rollback. The top workflow room: may import handeye, camera and everything below.
"""
