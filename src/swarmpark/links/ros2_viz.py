"""What the operator UI shows, as RViz2 markers (``visualization_msgs/MarkerArray``).

Namespaces: ``footprints`` (each skid's rectangle, coloured by its state; a faulted skid is
red), ``goals`` (arrows), ``boundary`` (the parking boundaries of the park groups) and
``paths`` (the planned paths). Every array starts with a DELETEALL so markers of skids that
lost their goal or path disappear.
"""

from __future__ import annotations

import numpy as np

from swarmpark.core.geometry import body_corners, footprint_corners
from swarmpark.links import ros2_msgs as rm

__all__ = ["markers", "STATE_COLOURS"]

#: Marker colours (r, g, b) of the robot states of the snapshot.
STATE_COLOURS = {
    "idle": (0.6, 0.6, 0.6),
    "moving": (0.1, 0.5, 1.0),
    "parked": (0.1, 0.8, 0.2),
    "stopped": (1.0, 0.6, 0.0),
    "estopped": (1.0, 0.0, 0.0),
    "teleop": (0.8, 0.2, 0.8),
    "stuck": (1.0, 0.9, 0.0),
}
FAULT_COLOUR = (1.0, 0.0, 0.0)


def _marker(stamp, frame, ns, mid, kind, points, rgb, width=0.04, pose=(0.0, 0.0, 0.0)):
    m = rm.msg
    return m("visualization_msgs/msg/Marker")(
        header=rm.header(stamp, frame),
        ns=ns,
        id=int(mid),
        type=kind,
        action=0,
        pose=rm.pose_msg(pose),
        scale=m("geometry_msgs/msg/Vector3")(
            x=width * 2 if kind == 0 else width, y=width / 2, z=width / 2
        ),
        color=m("std_msgs/msg/ColorRGBA")(r=rgb[0], g=rgb[1], b=rgb[2], a=1.0),
        lifetime=m("builtin_interfaces/msg/Duration")(sec=0, nanosec=0),
        frame_locked=False,
        points=[m("geometry_msgs/msg/Point")(x=float(x), y=float(y), z=0.0) for x, y in points],
        colors=[],
        texture_resource="",
        texture=m("sensor_msgs/msg/CompressedImage")(
            header=rm.header(0.0, ""), format="", data=np.zeros(0, np.uint8)
        ),
        uv_coordinates=[],
        text="",
        mesh_resource="",
        mesh_file=m("visualization_msgs/msg/MeshFile")(filename="", data=np.zeros(0, np.uint8)),
        mesh_use_embedded_materials=False,
    )


def markers(sup, stamp: float, frame: str = "map"):
    """The ``MarkerArray`` of a supervisor's state at ``stamp`` (epoch seconds)."""
    line, arrow = 4, 0
    out = [_marker(stamp, frame, "", 0, 0, [], (0, 0, 0))]
    out[0].action = 3  # DELETEALL
    poses = sup.poses_known
    known = np.isfinite(poses[:, 0])
    corners = footprint_corners(np.nan_to_num(poses), body_corners(list(sup.info.footprints)))
    faults = sup.health.fault_names() if getattr(sup, "health", None) is not None else {}
    for i, mode in enumerate(sup.modes()):
        if not known[i]:
            continue
        rgb = FAULT_COLOUR if sup.ids[i] in faults else STATE_COLOURS.get(mode, (1, 1, 1))
        ring = np.vstack([corners[i], corners[i][:1]])
        out.append(_marker(stamp, frame, "footprints", i, line, ring, rgb))
        if sup.has_goal[i]:
            g = sup.goals[i]
            out.append(
                _marker(stamp, frame, "goals", i, arrow, [], (0.1, 0.8, 0.2), 0.3, pose=tuple(g))
            )
    for k, grp in enumerate(getattr(sup, "groups", [])):
        xy = np.asarray(grp.boundary.exterior.coords)
        out.append(_marker(stamp, frame, "boundary", k, line, xy, (1.0, 1.0, 1.0), 0.05))
    paths = getattr(sup.controller, "paths", None)
    if callable(paths):
        paths = paths()
    for i, p in enumerate(paths or []):
        if p is not None and len(p) > 1:
            out.append(
                _marker(stamp, frame, "paths", i, line, np.asarray(p)[:, :2], (0.3, 0.7, 1.0), 0.02)
            )
    return rm.msg("visualization_msgs/msg/MarkerArray")(markers=out)
