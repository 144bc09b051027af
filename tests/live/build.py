"""Datagrams built by the documented layouts (not by the parsers under test): Live Link Face, iFacialMocap, VMC;
and `facesvg live` run as a user runs it."""

from __future__ import annotations

import asyncio
import socket
import struct
import subprocess
import sys
import threading
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

import pytest
from pythonosc.osc_message_builder import OscMessageBuilder

from converter.live.packets import LLF_NAMES

ROOT = Path(__file__).resolve().parents[2]


def llf_string(text: str) -> bytes:
    """A Live Link string: big-endian int32 byte length, then UTF-8."""
    raw = text.encode()
    return struct.pack(">i", len(raw)) + raw


def llf_packet(curves: list[float], device: str = "5B1C6A2E-0D2F-4A4B-9C1E-3F0E7D1A2B3C", subject: str = "iPhone",
               frame: int = 1337, sub_frame: float = 0.25, rate: tuple[int, int] = (60, 1), version: int = 6) -> bytes:
    """A Live Link Face packet: version, device id, subject, frame time, curve count, big-endian float32 curves."""
    return (bytes([version]) + llf_string(device) + llf_string(subject)
            + struct.pack(">ifii", frame, sub_frame, *rate) + bytes([len(curves)])
            + struct.pack(f">{len(curves)}f", *curves))


def ifm_frame(weights: dict[str, int], head: tuple[float, ...], right: tuple[float, ...],
              left: tuple[float, ...]) -> bytes:
    """An iFacialMocap datagram: name-int items, then =head#rx,ry,rz,tx,ty,tz|rightEye#x,y,z|leftEye#x,y,z|."""
    items = [f"{k}-{v}" for k, v in weights.items()]
    items.append("=head#" + ",".join(str(v) for v in head))
    items.append("rightEye#" + ",".join(str(v) for v in right))
    items.append("leftEye#" + ",".join(str(v) for v in left))
    return ("|".join(items) + "|").encode()


def osc(address: str, *args) -> bytes:
    """One OSC message (strings as s, Python floats as f)."""
    m = OscMessageBuilder(address=address)
    for a in args:
        m.add_arg(a)
    return m.build().dgram


def osc_bundle(*messages: bytes) -> bytes:
    """An OSC bundle of built messages (as VMC performers send a frame): "#bundle", time tag 1 (immediately), then
    each element as a big-endian int32 size and its bytes."""
    return b"#bundle\x00" + struct.pack(">Q", 1) + b"".join(struct.pack(">i", len(m)) + m for m in messages)


def llf_curves(jaw: float, yaw: float = 0.0) -> list[float]:
    """61 curves: every weight 0.1 but JawOpen; head yaw in Live Link units."""
    c = [0.1] * 61
    c[LLF_NAMES.index("JawOpen")] = jaw
    c[52:] = [yaw, 0.0, 0.0, 0.01, 0.02, 0.0, 0.03, 0.04, 0.0]
    return c


def send(port: int, data: bytes) -> None:
    """One UDP datagram to 127.0.0.1:port."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(data, ("127.0.0.1", port))


def live_command(*args: str) -> subprocess.Popen:
    """`facesvg live` in a child process, its output as text."""
    return subprocess.Popen([sys.executable, "-m", "converter.cli", "live", *args], cwd=ROOT, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def read_lines(proc: subprocess.Popen, n: int, timeout: float = 60.0) -> list[str]:
    """n lines of the child's stdout, or a failure after timeout seconds."""
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stdout.readline() for _ in range(n)), daemon=True)
    reader.start()
    reader.join(timeout)
    if reader.is_alive():
        proc.kill()
        pytest.fail(f"facesvg live printed {lines} in {timeout} s")
    return lines


def run_async(scenario: Callable[[], Coroutine[Any, Any, Any]], timeout: float = 120.0) -> Any:
    """asyncio.run(scenario()) in a thread of its own (a session's Playwright keeps an event loop running in this
    one); its result, or its exception raised here; a failure after timeout seconds."""
    out: dict[str, Any] = {}

    def main() -> None:
        try:
            out["result"] = asyncio.run(scenario())
        except BaseException as exc:  # handed to the test's thread
            out["error"] = exc

    thread = threading.Thread(target=main, daemon=True)
    thread.start()
    thread.join(timeout)
    if thread.is_alive():
        pytest.fail(f"the scenario took more than {timeout} s")
    if "error" in out:
        raise out["error"]
    return out["result"]
