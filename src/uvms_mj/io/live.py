"""Live view: a run streamed to the Foxglove app over its WebSocket protocol (``uvms-mj run --live``).

:class:`LiveServer` is a WebSocket server of the official Foxglove SDK (``foxglove-sdk``, the
``[live]`` extra; imported only here, when a server is made) and a sink of the recorder
(:class:`uvms_mj.io.sinks.MessageSink`): given to :class:`~uvms_mj.io.writer.McapRecorder` as
``live=``, it gets the log's own channels (the same topics, schema names, schemas and JSON
messages, :mod:`uvms_mj.io.recorder`) and every message the log gets, with the same log times
(simulation time, ns from the run's start). Open it in Foxglove with "Open connection" ->
Foxglove WebSocket -> ``ws://127.0.0.1:8765``.

Pacing (``pace``): ``"realtime"`` sleeps at each sample until the wall-clock time since the first
sample reaches the simulation time since it (a run slower than real time is not slowed further);
``"fast"`` runs as fast as it can. Messages are sent at least every ``push_interval`` s of wall
time (the recorder encodes its pending samples then), so the app sees the run as it goes.

The server announces the simulation time (the SDK's ``time`` capability) at each push, so the
app's clock is the run's. The scene and the paths (messages outside the per-sample stream, which
the log sends once or now and then) are kept and sent again, with their log times, when a client
subscribes, every ``resend_period`` s of wall time while one is subscribed, and at :meth:`~LiveServer.close`,
so an app that connects during the run still draws the robot (a subscription can become active a
moment after the SDK reports it, foxglove/foxglove-sdk#533, and foxglove-sdk 0.30.3 can refuse a
subscription that arrives a moment after the channel's advertisement with "Unknown channel ID": a
client that subscribes again gets the scene with the periodic and final sends).
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any, Iterable, Mapping

__all__ = ["INSTALL_HINT", "PACES", "LiveServer", "LiveUnavailable"]

PACES = ("realtime", "fast")
_monotonic, _sleep = time.monotonic, time.sleep  # (module names: a test gives a fake clock)
INSTALL_HINT = "the live view needs foxglove-sdk: pip install 'uvms-mj[live]' (or: pip install foxglove-sdk)"


class LiveUnavailable(ImportError):
    """foxglove-sdk is not installed (the message says how to install it)."""


def _listener(subscribed: threading.Event, resend: threading.Event, active: list[int]) -> Any:
    """The SDK's ServerListener (its other callbacks: the protocol's defaults, which do nothing): a
    subscription sets the two events and counts in ``active[0]`` (called from the server's thread)."""
    from foxglove.websocket import ServerListener

    class _Listener(ServerListener):
        def on_subscribe(self, client: Any, channel: Any) -> None:  # noqa: ARG002
            active[0] += 1
            subscribed.set()
            resend.set()

        def on_unsubscribe(self, client: Any, channel: Any) -> None:  # noqa: ARG002
            active[0] -= 1

    return _Listener()


class LiveServer:
    """A Foxglove WebSocket server that streams the recorder's channels (see the module).

    Args:
        host: interface to listen on (default 127.0.0.1: this machine only; 0.0.0.0: every interface).
        port: TCP port (default 8765, Foxglove's default; 0: any free port, see :attr:`port`).
        pace: ``"realtime"`` (simulation time follows wall time) or ``"fast"`` (no waiting).
        wait: the longest wall-clock time [s] to wait, when the first message is sent (the channels
            are then advertised), for a client to subscribe to a channel (0: do not wait).
        push_interval: the longest wall-clock time [s] between sends (default 1/30 s: a display rate).
        linger: the wall-clock time [s] the server keeps sending at :meth:`close` while a client is
            subscribed (the SDK's ``stop`` drops the messages still queued: 200 messages stopped at once
            reached a local client 0, 127, 0 times of 3, after 0.3 s all 3 times; 0: stop at once).
        resend_period: the wall-clock time [s] between re-sends of the scene and paths while a client
            is subscribed (1 s: an app that connects mid-run draws the robot within a second).
        name: the server's name shown by the app.

    Raises:
        LiveUnavailable: foxglove-sdk is not installed.
        ValueError: a bad argument (named, with what is allowed).
        OSError / RuntimeError: the port cannot be opened (from the SDK).

    Use it as a context manager (or call :meth:`close`): the server stops at the end.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, pace: str = "realtime", *, wait: float = 0.0,
                 push_interval: float = 1 / 30, linger: float = 0.5, resend_period: float = 1.0,
                 name: str = "uvms-mj") -> None:
        if pace not in PACES:
            raise ValueError(f"pace = {pace!r}; allowed: {', '.join(PACES)}")
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise ValueError(f"port = {port!r}; allowed: an integer 0..65535 (0: any free port)")
        for key, value in (("wait", wait), ("push_interval", push_interval), ("linger", linger),
                           ("resend_period", resend_period)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{key} = {value!r} s; allowed: a finite number >= 0")
        try:
            import foxglove
            from foxglove.websocket import Capability
        except ImportError as exc:
            raise LiveUnavailable(INSTALL_HINT) from exc
        self._fg = foxglove
        self.host, self.pacing, self.wait, self.push_interval = host, pace, float(wait), float(push_interval)
        self.linger, self.resend_period = float(linger), float(resend_period)
        self._last_resend = -math.inf
        self._subscribed, self._resend, self._active = threading.Event(), threading.Event(), [0]
        self._context = foxglove.Context()  # its own: the run's channels only, never the global context's
        self._server = foxglove.start_server(name=name, host=host, port=port, capabilities=[Capability.Time],
                                             server_listener=_listener(self._subscribed, self._resend, self._active),
                                             context=self._context)
        self.port: int = self._server.port
        self._channels: dict[int, Any] = {}
        self._kept: dict[int, tuple[int, bytes]] = {}  # channel -> its last message outside the sample stream
        self._started = False
        self._anchor: tuple[float, float] | None = None  # (wall time, simulation time) of the first sample
        self._last_push = -math.inf
        self.closed = False

    @property
    def url(self) -> str:
        """The address to open in Foxglove (``ws://host:port``)."""
        return f"ws://{self.host}:{self.port}"

    # ------------------------------------------------------------ the sink (uvms_mj.io.sinks.MessageSink)

    def open_channel(self, channel_id: int, topic: str, message_encoding: str, schema_name: str,
                     schema_encoding: str, schema_data: bytes, metadata: Mapping[str, str]) -> None:
        schema = self._fg.Schema(name=schema_name, encoding=schema_encoding, data=schema_data) if schema_name else None
        self._channels[channel_id] = self._fg.Channel(topic, schema=schema, message_encoding=message_encoding,
                                                      context=self._context, metadata=dict(metadata))

    def add_message(self, channel_id: int, log_time: int, data: bytes) -> None:
        self._begin()
        self._kept[channel_id] = (log_time, data)
        self._channels[channel_id].log(data, log_time=log_time)

    def add_samples(self, samples: Iterable[tuple[Any, int, int]]) -> None:
        self._begin()
        if self._resend.is_set() or (self._active[0] > 0 and _monotonic() - self._last_resend >= self.resend_period):
            self._send_kept()
        channels = self._channels
        last = None
        for messages, log_time, _ in samples:
            for cid, data in messages:
                channels[cid].log(data, log_time=log_time)
            last = log_time
        if last is not None:
            self._server.broadcast_time(last)

    # ------------------------------------------------------------ pacing (called by the recorder per sample)

    def pace(self, t: float) -> bool:
        """At a sample of simulation time ``t`` [s]: wait as ``pace`` says; True when the pending
        samples are due to be sent (``push_interval`` s since the last send)."""
        now = _monotonic()
        if self._anchor is None:
            self._anchor = (now, t)
        elif self.pacing == "realtime":
            ahead = (t - self._anchor[1]) - (now - self._anchor[0])
            if ahead > 0:
                _sleep(ahead)
                now = _monotonic()
        if now - self._last_push >= self.push_interval or self._resend.is_set():
            self._last_push = now
            return True
        return False

    # ------------------------------------------------------------ internals

    def _begin(self) -> None:
        """Before the first message: wait up to ``wait`` s for a subscriber (the channels are advertised)."""
        if self._started:
            return
        self._started = True
        if self.wait > 0:
            self._subscribed.wait(self.wait)
            time.sleep(min(self.wait, 0.2))  # the app subscribes to its panels' channels one after another

    def _send_kept(self) -> None:
        self._resend.clear()
        self._last_resend = _monotonic()
        for cid, (log_time, data) in list(self._kept.items()):
            self._channels[cid].log(data, log_time=log_time)

    def close(self) -> None:
        """Stop the server (after ``linger`` s while a client is subscribed) and close its channels.
        Later calls do nothing."""
        if self.closed:
            return
        self.closed = True
        try:
            if self._active[0] > 0:
                self._send_kept()
                if self.linger > 0:
                    time.sleep(self.linger)
        finally:
            self._server.stop()
            for channel in self._channels.values():
                channel.close()

    def __enter__(self) -> "LiveServer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
