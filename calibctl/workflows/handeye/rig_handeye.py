"""Hand-eye edges in the rig tree: a gated hand-eye result becomes the rig's next version.

The choice (docs/conventions.md "Rig trees", docs/handeye.md): a rig version is the whole tree a
robot loads, so ``calibctl handeye ... --rig RIG`` stores the rig's next immutable version = the
active version's edges with this edge (``source: "hand-eye"``) added or replaced, and the sealed
hand-eye result as its evidence (``RigCalibration.handeye``). History, show, rollback and export are
then the rig's own, and a rollback moves camera and hand-eye edges together. A rejected result is
stored as a rejected version (never active) that carries *no* edge for that frame pair, so no
transform of it looks accepted. A rig re-solve carries the active version's hand-eye edges forward,
except one whose camera was re-calibrated since (it would be stale; named in the findings).

Concurrency: the new version (and a rig re-solve's, which carries the active hand-eye edges) is
written compare-and-set on the base version it was built from. When
another writer moved the rig's active version in between (another hand-eye edge, a re-solve, a
rollback), nothing is stored and the command exits 2 naming the newer version; it is never rebased
silently: the tree check, the stale-camera lint and the carried edges were judged against the base,
and the other change may be a rollback that the operator meant to keep out of the tree. Re-running
the command builds on the new active version.

The machinery (next version, carry forward, lint rules, compare-and-set, the edge export) is shared with
the camera-LiDAR edges of ``calibctl lidar solve --rig`` in the ``edges`` room, whose kind table holds the
hand-eye specifics (``edges.kinds.HANDEYE``); this module is the hand-eye side's entry to it.

Frames: a hand-eye edge joins a rig member camera or a frame declared with ``rig add --frame`` to
another frame of the rig; the combined edges must stay a tree (core.extrinsics.rig_tree.orient_tree).
"""

from __future__ import annotations

from collections.abc import Mapping

from calibctl.artifacts.handeye import HandEyeResult
from calibctl.artifacts.rig import RigCalibration
from calibctl.config import Settings
from calibctl.workflows.edges import versions
from calibctl.workflows.edges.kinds import HANDEYE, evidence_camera
from calibctl.workflows.edges.versions import StoredEdge

__all__ = ["StoredEdge", "check_target", "store_handeye", "with_handeye"]


def check_target(
    settings: Settings, rig_name: str, parent: str, child: str, serial: str | None = None
) -> None:
    """Before any solve (exit 2): the rig, its active version, the tree and the cameras (edges.versions)."""
    versions.check_target(settings, rig_name, parent, child, serial, HANDEYE)


def with_handeye(
    base: RigCalibration, result: HandEyeResult, active: Mapping[str, int | None], settings: Settings
) -> RigCalibration:
    """The next version: ``base`` with the edge of ``result`` added or replaced (rejected: removed)."""
    return versions.with_evidence(base, result, active, settings)


def store_handeye(settings: Settings, rig_name: str, result: HandEyeResult) -> StoredEdge:
    """Store ``result`` as the rig's next version; active only when accepted."""
    camera = evidence_camera(result)
    return versions.store_evidence(
        settings,
        rig_name,
        result,
        camera[0] if camera else None,
        lambda base, active: with_handeye(base, result, active, settings),
    )
