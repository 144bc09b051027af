"""The bridge end to end on 127.0.0.1 (random free ports): UDP datagrams in, the player's JSON out over a WebSocket;
latest-wins for slow players; the `facesvg live` command's start, Ctrl-C and errors."""

from __future__ import annotations

import asyncio
import json
import math
import signal
import socket
import subprocess
import sys

import pytest
from websockets.asyncio.client import connect

from converter.live.packets import MAX_NAMES, LiveFrame
from converter.live.ports import Ports
from converter.live.server import Bridge, Hub

from .build import ROOT, ifm_frame, live_command, llf_curves, llf_packet, osc, osc_bundle, read_lines, run_async, send

ANY = Ports(0, 0, 0, 0)
WAIT = 10.0  # seconds any one await may take before the test fails


async def started() -> Bridge:
    """A bridge on 127.0.0.1, every port chosen free."""
    bridge = Bridge("127.0.0.1", ANY)
    await bridge.start()
    return bridge


SOURCES = {
    "llf": (llf_packet(llf_curves(0.75, 0.1)),
            lambda m: m["weights"]["JawOpen"] == 0.75 and m["head"][0] == pytest.approx(0.1 * math.pi, abs=1e-5)
            and m["eyes"] == pytest.approx([0.01 * math.pi, 0.02 * math.pi, 0.03 * math.pi, 0.04 * math.pi], abs=1e-5)),
    "ifm": (ifm_frame({"jawOpen": 75, "eyeBlink_L": 20}, (0.0, 10.0, 0.0, 0, 0, 0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
            lambda m: m["weights"] == {"jawOpen": 0.75, "eyeBlink_L": 0.2}
            and m["head"] == pytest.approx([-math.radians(10), 0.0, 0.0], abs=1e-5)),
    "vmc": (osc_bundle(osc("/VMC/Ext/Blend/Val", "JawOpen", 0.75), osc("/VMC/Ext/Blend/Apply")),
            lambda m: m == {"weights": {"JawOpen": 0.75}}),
}


@pytest.mark.parametrize("source", list(SOURCES))
def test_a_datagram_reaches_the_player_as_json_and_garbage_is_skipped(source):
    packet, check = SOURCES[source]

    async def scenario():
        bridge = await started()
        try:
            async with connect(bridge.url) as ws:
                port = bridge.addresses[source][1]
                send(port, b"\x00garbage\xff")
                send(port, packet)
                got = json.loads(await asyncio.wait_for(ws.recv(), WAIT))
                for _ in range(100):  # the counts are the listener's: the message may overtake the garbage's count
                    if bridge.counts[source].malformed:
                        break
                    await asyncio.sleep(0.01)
            return got, bridge.counts[source]
        finally:
            await bridge.close()

    got, counts = run_async(scenario)
    assert check(got), got
    assert (counts.frames, counts.malformed) == (1, 1)


def test_players_joining_later_get_the_state_and_every_player_gets_each_frame():
    async def scenario():
        bridge = await started()
        try:
            port = bridge.addresses["llf"][1]
            async with connect(bridge.url) as first:
                send(port, llf_packet(llf_curves(0.2)))
                a = json.loads(await asyncio.wait_for(first.recv(), WAIT))
                async with connect(bridge.url) as second:
                    b = json.loads(await asyncio.wait_for(second.recv(), WAIT))  # the current state, at once
                    send(port, llf_packet(llf_curves(0.6)))
                    c = [json.loads(await asyncio.wait_for(ws.recv(), WAIT)) for ws in (first, second)]
            return a, b, c
        finally:
            await bridge.close()

    a, b, c = run_async(scenario)
    assert a["weights"]["JawOpen"] == b["weights"]["JawOpen"] == pytest.approx(0.2)
    assert [m["weights"]["JawOpen"] for m in c] == [pytest.approx(0.6)] * 2


class GatedPlayer:
    """A player whose sends wait on a gate: a slow network."""

    def __init__(self) -> None:
        self.gate = asyncio.Event()
        self.sent: list[str] = []
        self.closed = asyncio.Event()

    async def send(self, text: str) -> None:
        await self.gate.wait()
        self.sent.append(text)

    async def wait_closed(self) -> None:
        await self.closed.wait()


def test_a_slow_player_is_sent_the_newest_state_not_a_backlog():
    async def scenario():
        hub, player = Hub(), GatedPlayer()
        task = asyncio.ensure_future(hub.player(player))
        await asyncio.sleep(0)
        hub.publish(LiveFrame({"jawOpen": 0.0, "browInnerUp": 0.5}))
        await asyncio.sleep(0)  # the sender takes the first frame and blocks in send
        for k in range(1, 100):  # frames pile up while it is blocked; VMC-like partial frames
            hub.publish(LiveFrame({"jawOpen": k / 100}, head=(k / 1000, 0.0, 0.0) if k == 50 else None))
        player.gate.set()
        for _ in range(50):
            await asyncio.sleep(0)
        player.closed.set()
        await asyncio.wait_for(task, WAIT)
        return hub, player

    hub, player = run_async(scenario)
    assert len(player.sent) == 2 and hub.sent == 2  # the first frame, then only the newest state
    last = json.loads(player.sent[-1])
    # partial frames merge: nothing a skipped frame set is lost
    assert last == {"weights": {"jawOpen": 0.99, "browInnerUp": 0.5}, "head": [0.05, 0.0, 0.0]}
    assert hub.players == 0


def test_a_player_that_stops_reading_holds_a_bounded_buffer_and_then_gets_the_latest():
    frames = 3000

    async def scenario():
        bridge = await started()
        port = bridge.addresses["llf"][1]
        raw = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        raw.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # a reader that falls behind at once
        raw.connect(bridge.addresses["ws"])
        raw.setblocking(False)
        try:
            async with connect(bridge.url, sock=raw, max_queue=1) as ws:
                for _ in range(200):
                    if bridge.hub.players:
                        break
                    await asyncio.sleep(0.01)
                conn = next(iter(bridge._server.connections))
                out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                buffered = 0
                for k in range(frames):
                    out.sendto(llf_packet(llf_curves(k / frames)), ("127.0.0.1", port))
                    if k % 20 == 19:
                        await asyncio.sleep(0.002)  # let the bridge read (UDP drops what overflows its buffer)
                        buffered = max(buffered, conn.transport.get_write_buffer_size())
                out.close()
                received = bridge.counts["llf"].frames
                sent_while_stalled = bridge.hub.sent
                final = bridge.hub.text()
                last = None
                for _ in range(frames + 2):  # now read: the messages in flight, then the newest state
                    last = await asyncio.wait_for(ws.recv(), WAIT)
                    if last == final:
                        break
            return received, sent_while_stalled, buffered, last == final, len(final)
        finally:
            await bridge.close()

    received, sent, buffered, got_final, size = run_async(scenario)
    print(f"received {received}, sent {sent}, buffered {buffered}, message {size} bytes")
    assert received > frames // 4  # most datagrams arrived
    assert sent < received  # frames that came while the player was stalled were not queued for it
    assert buffered <= 2 ** 15 + 2 * size  # websockets' write high-water mark and a message or two
    assert got_final


def test_ports_are_checked_before_binding():
    with pytest.raises(Exception, match="--llf-port and --vmc-port are both 5000"):
        Ports(5000, 6000, 5000, 0).check()


# The command, as a user runs it.

def test_the_command_says_where_to_point_the_player_and_stops_cleanly_on_ctrl_c():
    proc = live_command("--llf-port", "0", "--ifm-port", "0", "--vmc-port", "0", "--ws-port", "0")
    try:
        listening, point = read_lines(proc, 2)
        assert listening.startswith("facesvg live: listening on 127.0.0.1")
        assert "face.html?live=ws://127.0.0.1:" in point and "Ctrl-C" in point
        llf = int(listening.split("Live Link Face on UDP ")[1].split(",")[0])
        send(llf, b"nonsense")
        send(llf, llf_packet(llf_curves(0.5)))
        arriving = read_lines(proc, 1)[0]
        assert "Live Link Face frames arriving from 127.0.0.1 (iPhone)" in arriving
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert err == ""  # no traceback, no warning
    assert "facesvg live: stopped; 1 frames (Live Link Face 1, iFacialMocap 0, VMC (OSC) 0), 1 malformed" in out


def busy(kind: int) -> socket.socket:
    """A socket holding a free port of 127.0.0.1."""
    s = socket.socket(socket.AF_INET, kind)
    s.bind(("127.0.0.1", 0))
    if kind == socket.SOCK_STREAM:
        s.listen(1)
    return s


@pytest.mark.parametrize("flag", ["--vmc-port", "--ws-port"])
def test_a_busy_port_is_one_error_line_and_exit_2(flag):
    holder = busy(socket.SOCK_STREAM if flag == "--ws-port" else socket.SOCK_DGRAM)
    port = holder.getsockname()[1]
    ports = {"--llf-port": "0", "--ifm-port": "0", "--vmc-port": "0", "--ws-port": "0", flag: str(port)}
    try:
        proc = live_command(*(x for kv in ports.items() for x in kv))
        out, err = proc.communicate(timeout=60)
    finally:
        holder.close()
    assert proc.returncode == 2
    assert err.count("\n") == 1 and err.startswith("facesvg: error: ") and f"port {port}" in err and flag in err, err
    assert out == ""


@pytest.mark.parametrize("args, needle", [(["--llf-port", "70000"], "--llf-port 70000 is not a port number"),
                                          (["--ws-port", "web"], "--ws-port 'web' is not a port number"),
                                          (["--llf-port", "0", "--ifm-port", "0", "--vmc-port", "0", "--ws-port", "0",
                                            "--host", "192.0.2.1"], "--host 192.0.2.1 is not an address")])
def test_bad_ports_and_hosts_are_one_error_line_and_exit_2(args, needle):
    proc = live_command(*args)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 2 and err.count("\n") == 1 and err.startswith("facesvg: error: " + needle), err


def test_building_the_facesvg_parser_does_not_import_the_server():
    code = ("import sys, converter.cli; converter.cli.build_parser(); "
            "print(sorted(m for m in ('websockets', 'pythonosc', 'converter.live.server') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"  # every facesvg command builds the parser; only `live` needs websockets


def test_a_sender_of_endless_names_cannot_grow_the_state():
    hub = Hub()
    hub.publish(LiveFrame({f"w{k}": 0.5 for k in range(MAX_NAMES + 50)}))
    hub.publish(LiveFrame({"w0": 1.0, "new": 1.0}))
    assert len(hub.weights) == MAX_NAMES and hub.weights["w0"] == 1.0 and "new" not in hub.weights
