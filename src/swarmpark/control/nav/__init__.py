"""The default navigation stack: path follower, docking, collision monitor, avoidance."""

from swarmpark.control.nav.navigator import (
    Navigator,
    NavParams,
)

__all__ = [
    "NavParams",
    "Navigator",
]
