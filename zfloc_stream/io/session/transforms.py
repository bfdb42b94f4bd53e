"""The session log's frame tree (/tf, foxglove.FrameTransforms), written with each pose so
Foxglove's 3D panel draws the floorplan and the poses (`map`), the BEV (`odom`) and the
scans or images (`laser` / `camera`) in one scene:

    map -> odom -> base_link -> laser | camera,   map -> floorplan (identity)

The transforms are frame_tree.py's (its docstring says how a non-unit scale is handled).
`floorplan` is the map frame's name in logs written before REP 105 naming: an identity
child of `map`, so a layout made for such a log still finds its display frame. Display
only: the reader does not read /tf back (a replay recomputes it from the pose).
"""

from __future__ import annotations

import numpy as np
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms

from ...geometry import frame_tree as F
from ...estimate import Estimate
from . import schemas as S


def _transform(ns: int, parent: str, child: str, T: np.ndarray) -> FrameTransform:
    msg = FrameTransform(timestamp=S.to_stamp(ns), parent_frame_id=parent, child_frame_id=child)
    msg.translation.x, msg.translation.y, msg.translation.z = (float(v) for v in T[:3, 3])
    q = S.quaternion_from_matrix(T[:3, :3])
    msg.rotation.x, msg.rotation.y, msg.rotation.z, msg.rotation.w = (float(v) for v in q)
    return msg


def frame_transforms_msg(estimate: Estimate, sensor: tuple[str, str, np.ndarray] | None, ns: int) -> FrameTransforms | None:
    """The frame tree at a frame with a pose; None without one (no alignment: `odom` is
    not placed on the map). sensor: (frame id, heading axis, T_odom_sensor) of the frame
    as logged, for base_link -> sensor; None leaves the sensor out."""
    if estimate.pose is None or estimate.alignment is None or not np.isfinite(estimate.pose).all():
        return None
    pose, alignment = estimate.pose, estimate.alignment
    msg = FrameTransforms()
    msg.transforms.append(_transform(ns, F.MAP, F.LEGACY_MAP, np.eye(4)))
    msg.transforms.append(_transform(ns, F.MAP, F.ODOM, F.planar_matrix(*F.map_to_odom(pose, alignment))))
    msg.transforms.append(_transform(ns, F.ODOM, F.BASE_LINK, F.planar_matrix(*F.odom_to_base(pose, alignment))))
    if sensor is not None:
        frame_id, axis, T_odom_sensor = sensor
        msg.transforms.append(_transform(ns, F.BASE_LINK, frame_id, F.base_to_sensor(T_odom_sensor, axis)))
    return msg
