"""Every run leaves a record: MCAP files with ROS 2 messages, replay, a live Foxglove view.

- :mod:`~swarmpark.record.messages`: ROS 2 messages from arrays, CDR serialization.
- :mod:`~swarmpark.record.sinks`: an MCAP file (profile ``ros2``) or a Foxglove server.
- :mod:`~swarmpark.record.recorder`: the observer of the tick loop that writes the channels.
- :mod:`~swarmpark.record.reader`: a recording read back into arrays (replay, tests).
- :mod:`~swarmpark.record.audit`: the operator audit log (JSON lines) of the server.
- :mod:`~swarmpark.record.replay`: ``swarmpark replay``, the browser UI on a recording.
"""

from swarmpark.record.recorder import TOPICS, RecordConfig, Recorder

__all__ = ["Recorder", "RecordConfig", "TOPICS"]
