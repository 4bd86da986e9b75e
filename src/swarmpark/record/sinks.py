"""Where recorded messages go: an MCAP file (profile ``ros2``) or a live Foxglove server.

A sink takes messages already serialized as CDR, so a tick's messages are encoded once
and written to every sink. Both sinks declare ``ros2msg`` schemas and ``cdr`` encoding:
``ros2 bag play``, Foxglove and RViz (through a bag) read them as ROS 2 messages.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

from swarmpark.record.messages import msgdef

__all__ = ["Sink", "McapSink", "FoxgloveSink"]

LIBRARY = "swarmpark"


class Sink(Protocol):
    def channel(self, topic: str, typename: str) -> int: ...

    def write(self, channel: int, t_ns: int, data: bytes) -> None: ...

    def metadata(self, name: str, data: dict[str, str]) -> None: ...

    def active(self) -> bool:
        """Whether anything reads the messages now (else the recorder skips the samples)."""
        ...

    def close(self) -> None: ...


class McapSink:
    """An MCAP file with ROS 2 message types (``profile: ros2``), zstd-compressed chunks.

    Parameters
    ----------
    path
        File to write (its directory is created).
    chunk_size
        Bytes per chunk before it is compressed and written: larger chunks compress better,
        smaller ones lose less if the process is killed.
    """

    def __init__(self, path: str | Path, *, chunk_size: int = 1 << 20) -> None:
        from mcap.writer import Writer

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = open(self.path, "wb")  # noqa: SIM115 (closed in close())
        self._w = Writer(self._f, chunk_size=chunk_size)
        self._w.start(profile="ros2", library=LIBRARY)
        self._schemas: dict[str, int] = {}
        self._seq: dict[int, int] = {}
        self.closed = False

    def channel(self, topic: str, typename: str) -> int:
        sid = self._schemas.get(typename)
        if sid is None:
            sid = self._w.register_schema(
                name=typename, encoding="ros2msg", data=msgdef(typename).encode()
            )
            self._schemas[typename] = sid
        cid = self._w.register_channel(topic=topic, message_encoding="cdr", schema_id=sid)
        self._seq[cid] = 0
        return cid

    def write(self, channel: int, t_ns: int, data: bytes) -> None:
        seq = self._seq[channel] = self._seq[channel] + 1
        self._w.add_message(channel, log_time=t_ns, data=data, publish_time=t_ns, sequence=seq)

    def metadata(self, name: str, data: dict[str, str]) -> None:
        self._w.add_metadata(name, data)

    def active(self) -> bool:
        return not self.closed

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._w.finish()
            self._f.close()


class FoxgloveSink:
    """Live channels on a Foxglove WebSocket server (``foxglove.sdk.v1``).

    Messages are logged only while a client subscribes (the SDK drops them otherwise), so an
    idle server costs one check per message. The server runs on the SDK's own threads; the
    tick only hands it bytes.

    Parameters
    ----------
    host, port
        Address to bind (127.0.0.1 by default: nothing leaves the machine). Port 0 picks a
        free port (see :attr:`port`).
    """

    def __init__(self, *, host: str = "127.0.0.1", port: int = 8765, name: str = "swarmpark"):
        import foxglove

        self._foxglove = foxglove
        self._ctx = foxglove.Context()
        #: Set (from the server's thread) when a client subscribes: the recorder then
        #: re-sends the latched topics (a plain bool: reading it needs no lock).
        self.subscribed = False
        sink = self

        class _Listener(foxglove.ServerListener):
            def on_subscribe(self, client, channel) -> None:
                sink.subscribed = True

        self.server = foxglove.start_server(
            name=name, host=host, port=port, context=self._ctx, server_listener=_Listener()
        )
        self.port = self.server.port
        self._channels: list = []
        self._by_topic: dict[str, int] = {}
        self.closed = False

    def channel(self, topic: str, typename: str) -> int:
        if topic in self._by_topic:  # a reset re-declares the same channels
            return self._by_topic[topic]
        fg = self._foxglove
        schema = fg.Schema(name=typename, encoding="ros2msg", data=msgdef(typename).encode())
        ch = fg.Channel(topic, schema=schema, message_encoding="cdr", context=self._ctx)
        self._channels.append(ch)
        self._by_topic[topic] = len(self._channels) - 1
        return self._by_topic[topic]

    def write(self, channel: int, t_ns: int, data: bytes) -> None:
        ch = self._channels[channel]
        if ch.has_sinks():
            ch.log(data, log_time=t_ns)

    def metadata(self, name: str, data: dict[str, str]) -> None:
        """Foxglove's live protocol has no metadata records: nothing to send."""

    def active(self) -> bool:
        """A client subscribes to at least one channel."""
        return any(ch.has_sinks() for ch in self._channels)

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            for ch in self._channels:
                ch.close()
            self.server.stop()
