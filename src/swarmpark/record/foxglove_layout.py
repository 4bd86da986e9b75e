"""A Foxglove layout for a fleet: the 3D view of the map, skids, goals, boundaries, paths,
people and scans; the skids' speeds; the command, operator and alarm logs.

``docs/foxglove-layout.json`` is this layout for the skids ``s1``..``s6`` of the hangar
scenarios (``python -m swarmpark.record.foxglove_layout s1 s2 ... > layout.json`` makes one
for other ids). Import it in Foxglove with *Layouts -> Import from file*.
"""

from __future__ import annotations

import json
import sys

__all__ = ["fleet_layout"]

#: The 3D view's initial camera: top-down over the middle of a 30 x 20 m hangar.
CAMERA_TARGET_M = (15.0, 10.0, 0.0)
CAMERA_DISTANCE_M = 35.0


def fleet_layout(ids: list[str]) -> dict:
    """The layout (Foxglove's exported JSON format) for skids ``ids``."""
    topics = {
        "/map": {"visible": True, "colorMode": "map", "alpha": 0.9},
        "/world": {"visible": True},
        "/footprints": {"visible": True},
        "/goals": {"visible": True},
        "/boundary": {"visible": True},
        "/paths": {"visible": True},
        "/people": {"visible": True},
    }
    for rid in ids:
        topics[f"/{rid}/scan"] = {
            "visible": True,
            "pointSize": 2,
            "colorField": "range",
            "colorMode": "flat",
            "flatColor": "#ff5a5a",
        }
    plot_paths = [
        {
            "value": f"/{rid}/odom.twist.twist.linear.x",
            "enabled": True,
            "timestampMethod": "receiveTime",
        }
        for rid in ids
    ]
    return {
        "configById": {
            "3D!fleet": {
                "cameraState": {
                    "perspective": False,
                    "distance": CAMERA_DISTANCE_M,
                    "phi": 0.0,
                    "thetaOffset": 90.0,
                    "targetOffset": list(CAMERA_TARGET_M),
                    "target": [0.0, 0.0, 0.0],
                    "targetOrientation": [0.0, 0.0, 0.0, 1.0],
                    "fovy": 45.0,
                    "near": 0.5,
                    "far": 5000.0,
                },
                "followMode": "follow-none",
                "followTf": "map",
                "scene": {"transforms": {"showLabel": False, "axisScale": 0.5}},
                "transforms": {f"frame:{rid}/base_link": {"visible": True} for rid in ids},
                "topics": topics,
                "layers": {
                    "grid": {
                        "visible": True,
                        "layerId": "foxglove.Grid",
                        "size": 40,
                        "divisions": 40,
                    }
                },
            },
            "Plot!speeds": {"title": "Skid speeds (m/s)", "paths": plot_paths, "showLegend": True},
            "RawMessages!alarms": {"topicPath": "/swarmpark/alarms", "expansion": "all"},
            "RawMessages!commands": {"topicPath": "/swarmpark/commands", "expansion": "all"},
            "RawMessages!operator": {"topicPath": "/swarmpark/operator", "expansion": "all"},
        },
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": {"speed": 1},
        "layout": {
            "first": "3D!fleet",
            "second": {
                "first": "Plot!speeds",
                "second": {
                    "first": "RawMessages!alarms",
                    "second": {
                        "first": "RawMessages!commands",
                        "second": "RawMessages!operator",
                        "direction": "column",
                    },
                    "direction": "column",
                    "splitPercentage": 33,
                },
                "direction": "column",
                "splitPercentage": 30,
            },
            "direction": "row",
            "splitPercentage": 68,
        },
    }


def main(argv: list[str] | None = None) -> int:
    ids = list(sys.argv[1:] if argv is None else argv) or [f"s{k}" for k in range(1, 7)]
    sys.stdout.write(json.dumps(fleet_layout(ids), indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
