"""Recording a served session: one MCAP file per scenario run, and a live Foxglove view.

The server's session starts a new supervisor when the operator loads or resets a scenario;
:class:`LiveRecording` (an observer of the session) then closes the file of the previous run
(with its result) and opens the next one in the record directory, named by the wall-clock
time it began and the scenario. The Foxglove server stays up across runs.
"""

from __future__ import annotations

import datetime as _dt
import re
from pathlib import Path

from swarmpark.record.recorder import RecordConfig, Recorder
from swarmpark.record.sinks import FoxgloveSink, McapSink

__all__ = ["LiveRecording"]


class LiveRecording:
    """Observer of a served session: records to ``directory`` and/or streams to Foxglove.

    Parameters
    ----------
    directory
        Where the ``.mcap`` files go (``None``: no files).
    foxglove_port
        Serve the channels to Foxglove on this port (``None``: no live view; 0: any free
        port, see :attr:`foxglove_port`).
    foxglove_host
        Address the Foxglove server binds (loopback by default).
    config
        Sampling rates of the recorder.
    """

    def __init__(
        self,
        *,
        directory: str | Path | None = None,
        foxglove_port: int | None = None,
        foxglove_host: str = "127.0.0.1",
        config: RecordConfig | None = None,
    ) -> None:
        if directory is None and foxglove_port is None:
            raise ValueError("LiveRecording: give a directory, a Foxglove port, or both")
        self.directory = Path(directory) if directory is not None else None
        self.config = config or RecordConfig()
        self.fox = (
            FoxgloveSink(host=foxglove_host, port=foxglove_port)
            if foxglove_port is not None
            else None
        )
        self.foxglove_port = self.fox.port if self.fox is not None else None
        self.rec: Recorder | None = None
        self.files: list[Path] = []

    def _next_file(self, scenario: str) -> Path:
        stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%SZ")
        safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", scenario) or "run"
        path = self.directory / f"{stamp}-{safe}.mcap"
        k = 1
        while path.exists() or path in self.files:
            k += 1
            path = self.directory / f"{stamp}-{safe}-{k}.mcap"
        return path

    # ------------------------------------------------------------------ observer

    def on_start(self, sup) -> None:
        sinks, owned = [], []
        if self.directory is not None:
            path = self._next_file(sup.world.scenario.name)
            mcap = McapSink(path)
            self.files.append(path)
            sinks.append(mcap)
            owned.append(mcap)
        if self.fox is not None:
            sinks.append(self.fox)
        self.rec = Recorder(sinks, self.config, owned=owned, meta={"served": "true"})
        self.rec.on_start(sup)

    def on_tick(self, sup) -> None:
        if self.rec is None:
            return
        self.rec.on_tick(sup)
        if self.fox is not None and self.fox.subscribed:
            self.fox.subscribed = False
            self.rec.republish(self.fox)

    def on_command(self, entry: dict) -> None:
        if self.rec is not None:
            self.rec.on_command(entry)

    def on_alarm(self, entry: dict) -> None:
        if self.rec is not None:
            self.rec.on_alarm(entry)

    def on_end(self, sup, result: dict | None = None) -> None:
        if self.rec is not None:
            self.rec.on_end(sup, result)
            self.rec = None

    def close(self) -> None:
        if self.fox is not None:
            self.fox.close()
