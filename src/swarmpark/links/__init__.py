"""Links to robot fleets: the :class:`RobotLink` protocol the supervisor talks through."""

from swarmpark.links.base import (
    FleetInfo,
    Inbox,
    Message,
    Odometry,
    PoseReport,
    RobotLink,
    Scan,
    Status,
    TrackedPeople,
    VelocityCommand,
)

__all__ = [
    "RobotLink",
    "FleetInfo",
    "Inbox",
    "Message",
    "Odometry",
    "PoseReport",
    "Scan",
    "Status",
    "TrackedPeople",
    "VelocityCommand",
]
