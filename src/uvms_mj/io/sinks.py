"""Where the recorder's messages go: one writer interface, several sinks.

:class:`~uvms_mj.io.writer.McapRecorder` defines every channel (topic, schema name, schema
encoding and data, message encoding, metadata) and encodes every message once; it writes them
through an object with the MCAP writer's methods (``register_schema``, ``register_channel``,
``add_message``, ``add_samples``). Without a second sink that object is the MCAP writer itself
(:class:`~uvms_mj.io.mcap_writer.LeanWriter`); with one (the live WebSocket server,
:class:`uvms_mj.io.live.LiveServer`) it is a :class:`Tee`, which gives the file and each further
sink the same channels and the same bytes, so that no channel or schema is defined twice.

A further sink (:class:`MessageSink`) gets each channel once, by the file's channel id, before
any message on it, and the messages in the order they are written to the file.
"""

from __future__ import annotations

from typing import Any, Iterable, Mapping, Protocol, Sequence

__all__ = ["MessageSink", "Tee"]

Sample = tuple[Sequence[tuple[int, bytes]], int, int]  # ((channel id, data), ...), log time [ns], sequence


class MessageSink(Protocol):
    """A receiver of the recorder's channels and messages besides the MCAP file."""

    def open_channel(self, channel_id: int, topic: str, message_encoding: str, schema_name: str,
                     schema_encoding: str, schema_data: bytes, metadata: Mapping[str, str]) -> None:
        """A new channel (``channel_id``: the file's id of it, used by the messages below)."""

    def add_message(self, channel_id: int, log_time: int, data: bytes) -> None:
        """One message outside the per-sample stream (the scene, the paths); ``log_time`` in ns."""

    def add_samples(self, samples: Iterable[Sample]) -> None:
        """The messages of control samples, in order (each sample's messages share its log time)."""


class Tee:
    """The MCAP writer ``primary`` (whose channel and schema ids the recorder keeps) and the
    further ``sinks``, written together; every other attribute (``start``, ``flush``,
    ``add_metadata``, ``finish``...) is the primary's."""

    def __init__(self, primary: Any, *sinks: MessageSink) -> None:
        self._primary = primary
        self._sinks = sinks
        self._schemas: dict[int, tuple[str, str, bytes]] = {}

    def __getattr__(self, name: str) -> Any:
        return getattr(self._primary, name)

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        sid = self._primary.register_schema(name=name, encoding=encoding, data=data)
        self._schemas[sid] = (name, encoding, bytes(data))
        return sid

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: Mapping[str, str] | None = None) -> int:
        cid = self._primary.register_channel(topic=topic, message_encoding=message_encoding, schema_id=schema_id,
                                             metadata=dict(metadata or {}))
        name, encoding, data = self._schemas.get(schema_id, ("", "", b""))
        for sink in self._sinks:
            sink.open_channel(cid, topic, message_encoding, name, encoding, data, dict(metadata or {}))
        return cid

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0) -> None:
        self._primary.add_message(channel_id, log_time, data, publish_time, sequence)
        for sink in self._sinks:
            sink.add_message(channel_id, log_time, data)

    def add_samples(self, samples: list[Sample]) -> None:
        self._primary.add_samples(samples)
        for sink in self._sinks:
            sink.add_samples(samples)
