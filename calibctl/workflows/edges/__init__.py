"""Evidence edges of a rig tree: what every sensor edge backed by its own solve shares.

A hand-eye edge (``flange -> camera``, evidence in ``RigCalibration.handeye``) and a camera-LiDAR edge
(``lidar -> camera``, evidence in ``RigCalibration.lidar``) join the rig's tree the same way: the rig's next
immutable version is the active one with this edge added or replaced, its evidence sealed inside it, written
compare-and-set on that base; a rejected result is stored as a rejected version carrying its evidence and no
edge; the other evidence edges are carried forward unless their camera was re-calibrated since (dropped and
named). Lint speaks per kind (``handeye-*``, ``lidar-*``, ``imu-*``). A camera-IMU edge (``imu -> camera``,
T_imu_cam, with the time offset td_s kept in its evidence, ``RigCalibration.imu``) is the third kind.

``kinds`` holds ONE table of edge kinds (``KINDS``): source, evidence field and type, frames, covariance
layout, lint rule prefix and loose-sigma thresholds, the command that re-runs it, and the few callables that
differ per kind (camera reference, tree edge with covariance, why no one-sigma, the tf export). ``tree``
turns a solved transform and its covariance into a tree edge; ``versions`` is the generic machinery (tree
check, lint, carry forward, next version, store) and ``export`` one edge's file; both iterate the table.

Adding a sensor (as the IMU was: camera-IMU with a time offset, edge ``imu -> camera``, T_imu_cam) needs:
1. one ``EdgeKind`` entry in ``kinds.KINDS`` (and its evidence type in ``kinds.Evidence``);
2. a field on ``RigCalibration`` holding its evidence (and its source in ``RigEdge.source``);
3. its own room (``workflows/imu``) that solves, builds the evidence and calls ``versions.store_evidence``.

Sits below ``lidar | handeye`` and ``rig`` (which import it) and imports only store_admin and exports.
"""
