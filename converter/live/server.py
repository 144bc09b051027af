"""The `facesvg live` bridge: UDP listeners for the tracking apps and the WebSocket server puppet players connect to.

Each listener parses a datagram (`packets`) into frames and hands them to the `Hub`, which holds what the feeds have
set so far (every weight seen, the latest head and eye angles). Each connected player has its own sender, woken by
every frame: it sends the hub's state as it is when it gets to run, so a slow player skips to the newest state
instead of queueing frames, and no player is sent more messages than frames arrived. The state is whole (not only
the last frame's names), so a skipped frame loses nothing: a VMC sender that sends only changed weights still ends
at the right face. Network and clocks live here; `packets` is pure.
"""

from __future__ import annotations

import asyncio
import errno
import logging
import signal
import socket
from collections.abc import Callable
from dataclasses import dataclass

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed

from converter.errors import InputError
from converter.live.packets import (
    MAX_NAMES,
    LiveFrame,
    PacketError,
    VmcReader,
    message,
    parse_ifacialmocap,
    parse_livelink,
)
from converter.live.ports import Ports

Say = Callable[[str], None]
Parse = Callable[[bytes], tuple[list[LiveFrame], int]]
MAX_INCOMING = 4096  # bytes a player may send in one message (players send nothing; this bounds a stray client)
WILDCARDS = ("0.0.0.0", "::", "")


# (Ports field, label, parser factory): one UDP listener each, in this order.
SOURCES: tuple[tuple[str, str, Callable[[], Parse]], ...] = (
    ("llf", "Live Link Face", lambda: lambda data: ([parse_livelink(data)], 0)),
    ("ifm", "iFacialMocap", lambda: lambda data: ([parse_ifacialmocap(data)], 0)),
    ("vmc", "VMC (OSC)", lambda: VmcReader().feed),
)


@dataclass
class Counts:
    """Datagrams of one source: frames taken, and malformed packets (or OSC messages) skipped."""

    frames: int = 0
    malformed: int = 0


class Hub:
    """What the feeds have set so far, and a wake-up per connected player."""

    def __init__(self) -> None:
        self.weights: dict[str, float] = {}
        self.head: tuple[float, ...] | None = None
        self.eyes: tuple[float, ...] | None = None
        self.seq = 0  # frames published
        self.sent = 0  # messages sent, over every player
        self._text: tuple[int, str] = (-1, "")
        self._wakes: set[asyncio.Event] = set()

    def publish(self, frame: LiveFrame) -> None:
        """Take a frame into the state and wake every player's sender."""
        for name, value in frame.weights.items():
            if name in self.weights or len(self.weights) < MAX_NAMES:  # a stray sender's endless names are dropped
                self.weights[name] = value
        if frame.head is not None:
            self.head = frame.head
        if frame.eyes is not None:
            self.eyes = frame.eyes
        self.seq += 1
        for wake in self._wakes:
            wake.set()

    def text(self) -> str:
        """The state as the player's JSON message (encoded once per frame, whatever the number of players)."""
        if self._text[0] != self.seq:
            self._text = (self.seq, message(self.weights, self.head, self.eyes))
        return self._text[1]

    @property
    def players(self) -> int:
        """Players connected now."""
        return len(self._wakes)

    async def player(self, ws: ServerConnection) -> None:
        """Send one player the newest state after each frame until it leaves (what it sends is ignored)."""
        wake = asyncio.Event()
        closed = asyncio.ensure_future(ws.wait_closed())
        closed.add_done_callback(lambda _: wake.set())
        if self.seq:
            wake.set()  # a player joining mid-stream is sent the current state at once
        self._wakes.add(wake)
        sent = 0
        try:
            while True:
                await wake.wait()
                wake.clear()
                if closed.done():
                    return
                if self.seq != sent:
                    sent = self.seq
                    await ws.send(self.text())
                    self.sent += 1
        except ConnectionClosed:
            return
        finally:
            self._wakes.discard(wake)
            closed.cancel()


class _Listener(asyncio.DatagramProtocol):
    """One source's UDP socket: each datagram parsed, malformed ones counted and skipped."""

    def __init__(self, label: str, parse: Parse, hub: Hub, counts: Counts, say: Say) -> None:
        self.label, self.parse, self.hub, self.counts, self.say = label, parse, hub, counts, say

    def datagram_received(self, data: bytes, addr) -> None:
        """Parse, count, publish."""
        try:
            frames, bad = self.parse(data)
        except PacketError:
            self.counts.malformed += 1
            return
        self.counts.malformed += bad
        for frame in frames:
            if not self.counts.frames:
                who = f" ({frame.subject})" if frame.subject else ""
                self.say(f"facesvg live: {self.label} frames arriving from {addr[0]}{who}")
            self.counts.frames += 1
            self.hub.publish(frame)


def _quiet(_: str) -> None:
    """Say nothing."""


def _bind_error(exc: OSError, host: str, port: int, label: str, flag: str, kind: str) -> InputError:
    """The one sentence for a socket that would not bind."""
    if isinstance(exc, socket.gaierror) or exc.errno == errno.EADDRNOTAVAIL:
        return InputError(f"--host {host} is not an address of this machine; give 127.0.0.1, or 0.0.0.0 to listen on "
                          "every network interface.")
    if exc.errno == errno.EADDRINUSE:
        return InputError(f"{kind} port {port} ({label}) is already in use on {host}; stop what holds it or give "
                          f"{flag} another port.")
    if exc.errno == errno.EACCES:
        return InputError(f"{kind} port {port} ({label}) needs privileges on this system; give {flag} a port above "
                          "1023.")
    return InputError(f"cannot listen on {host} {kind} port {port} ({label}): {exc.strerror or exc}.")


class Bridge:
    """The UDP listeners and the WebSocket server on one host, started and closed together."""

    def __init__(self, host: str, ports: Ports, say: Say = _quiet) -> None:
        self.host, self.ports, self.say = host, ports, say
        self.hub = Hub()
        self.counts = {key: Counts() for key, _, _ in SOURCES}
        self.addresses: dict[str, tuple[str, int]] = {}
        self._transports: list[asyncio.BaseTransport] = []
        self._server: Server | None = None
        # websockets logs a stray client's failed handshake with its traceback; the bridge has nothing to add.
        self._log = logging.getLogger("facesvg.live")
        self._log.addHandler(logging.NullHandler())
        self._log.propagate = False

    async def start(self) -> None:
        """Bind every socket, or close those bound and raise an InputError saying which port would not bind."""
        loop = asyncio.get_running_loop()
        for key, label, parser in SOURCES:
            port = getattr(self.ports, key)
            listener = _Listener(label, parser(), self.hub, self.counts[key], self.say)
            try:
                transport, _ = await loop.create_datagram_endpoint(lambda li=listener: li, local_addr=(self.host, port))
            except OSError as exc:
                await self.close()
                raise _bind_error(exc, self.host, port, label, f"--{key}-port", "UDP") from None
            self._transports.append(transport)
            self.addresses[key] = transport.get_extra_info("sockname")[:2]
        try:
            self._server = await serve(self.hub.player, self.host, self.ports.ws, compression=None,
                                       max_size=MAX_INCOMING, logger=self._log)
        except OSError as exc:
            await self.close()
            raise _bind_error(exc, self.host, self.ports.ws, "players' WebSocket", "--ws-port", "TCP") from None
        self.addresses["ws"] = self._server.sockets[0].getsockname()[:2]

    @property
    def url(self) -> str:
        """The WebSocket address a player on this machine points at."""
        host, port = self.addresses["ws"]
        host = "127.0.0.1" if self.host in WILDCARDS else self.host
        return f"ws://{'[' + host + ']' if ':' in host else host}:{port}"

    async def close(self) -> None:
        """Close the listeners and the server (players are sent a close frame)."""
        for transport in self._transports:
            transport.close()
        self._transports = []
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
            self._server = None

    def summary(self) -> str:
        """Frames and malformed packets per source."""
        frames = sum(c.frames for c in self.counts.values())
        bad = sum(c.malformed for c in self.counts.values())
        per = ", ".join(f"{label} {self.counts[key].frames}" for key, label, _ in SOURCES)
        return f"{frames} frames ({per}), {bad} malformed packets skipped, {self.hub.sent} messages sent"

    def announce(self) -> None:
        """Say where the bridge listens and where to point the player."""
        listening = ", ".join(f"{label} on UDP {self.addresses[key][1]}" for key, label, _ in SOURCES)
        self.say(f"facesvg live: listening on {self.host}: {listening}")
        where = " (or this machine's network address)" if self.host in WILDCARDS else ""
        self.say(f"facesvg live: point the puppet at {self.url}{where}: face.html?live={self.url}, or its Live "
                 "field; Ctrl-C stops")


def run(host: str, ports: Ports, say: Say = print) -> Bridge:
    """Bridge until Ctrl-C or SIGTERM, then close every socket and say what arrived; the stopped Bridge."""
    bridge = Bridge(host, ports.check(), say)

    async def main() -> None:
        stop = asyncio.Event()
        asyncio.get_running_loop().add_signal_handler(signal.SIGTERM, stop.set)
        await bridge.start()
        bridge.announce()
        try:
            await stop.wait()
        finally:
            await bridge.close()

    try:
        asyncio.run(main())
    except KeyboardInterrupt:
        pass  # asyncio.run cancelled main, whose finally closed the sockets
    say(f"facesvg live: stopped; {bridge.summary()}")
    return bridge
