"""Sensor logs (MCAP with hanzo.fusion.v1 messages, docs/sensor-logs.md) from Python.

    from hanzo.fusion import read_log, LogWriter, replay
    for record in read_log("sensors.mcap"):          # LogRecord(topic, log_time_ns, message)
        print(record.topic, record.message.time_s)
    with LogWriter("mine.mcap") as log:               # messages of hanzo.fusion.messages
        log.write("/imu", imu_message)
    session = replay("sensors.mcap", "fusion.yaml", "calibration.yaml")   # the whole pipeline over a log
"""

from __future__ import annotations

from typing import Iterator, Optional

from hanzo.fusion import _fusion
from hanzo.fusion.messages import LogRecord, Message

__all__ = ["read_log", "LogWriter", "replay"]


def read_log(path: str, on_error: str = "raise") -> Iterator[LogRecord]:
    """Every message of a sensor log in log-time order, as LogRecord(topic, log_time_ns, message).

    Messages are hanzo.fusion.messages dataclasses (PoseEstimate for logged poses); channels of
    other schemas (the Foxglove mirrors) are skipped. A message that does not decode raises
    ValueError naming topic and time (on_error="raise"), or is left out (on_error="skip").
    A file that is no MCAP, or is missing, raises ValueError when the iteration starts.
    """
    if on_error not in ("raise", "skip"):
        raise ValueError(f"on_error: expected 'raise' or 'skip', got '{on_error}'")
    reader = _fusion.LogReader(path)
    while True:
        try:
            record = reader.next()
        except ValueError:
            if on_error == "raise":
                raise
            continue
        if record is None:
            return
        yield LogRecord(*record)


class LogWriter:
    """Writes a sensor log that `hanzo-fusion run`, `replay` and the server read.

    compression: "zstd" (default), "lz4" or "none" per chunk; image_compression: "none", "png"
    (lossless) or "jpeg"; foxglove_channels: also write the Foxglove mirror channels so the log
    opens in Foxglove Studio. write() validates each message (ValueError naming topic and field;
    nothing is written then). Use as a context manager or call close(): an unclosed file stays
    readable up to its last complete chunk.
    """

    def __init__(self, path: str, compression: str = "zstd", image_compression: str = "none", foxglove_channels: bool = True):
        self._writer = _fusion.LogWriter(path, compression, image_compression, foxglove_channels)

    def write(self, topic: str, message: Message, sensor_name: str = "") -> None:
        self._writer.write(topic, message, sensor_name)

    def close(self) -> None:
        self._writer.close()

    def __enter__(self) -> "LogWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def replay(log: str, config: str, calibration: Optional[str] = None, threads: int = 1, allow_partial: bool = False) -> _fusion.Session:
    """The whole pipeline (as `hanzo-fusion run`) over a sensor log: returns the Session after the
    last message, to read poses(), optimized_trajectory(), map_points() and summary() from.
    Raises ValueError for a configuration, calibration or log that cannot be read, and for a log
    read only in part (corrupted chunks, truncated) unless allow_partial."""
    session = _fusion.Session(config, calibration, threads)
    session.replay(log, allow_partial)
    return session
