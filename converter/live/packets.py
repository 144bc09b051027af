"""One datagram of a face-tracking app as a `LiveFrame`, and a frame as the puppet player's JSON message.

Live Link Face (Epic's iOS app, UDP, default port 11111): the Live Link packet as Unreal's Apple ARKit Live Link
source reads it, observed the same by LLV (think-biq/LLV) and PyLiveLinkFace; every number is big-endian:
  uint8 packet version (6), int32 length + UTF-8 device id, int32 length + UTF-8 subject name,
  frame time: int32 frame number, float32 sub-frame, int32 rate numerator, int32 rate denominator,
  uint8 curve count (61), then that many float32: the 52 ARKit weights, head yaw, pitch, roll, left eye yaw,
  pitch, roll, right eye yaw, pitch, roll.
The weights are named as the app's CSV names its columns (`LLF_NAMES`; blender_livelinkface names streamed slots
the same way), the angles in the CSV's unit (one unit is 180 degrees: `livelinkface.LLF_ANGLE_UNIT`).

iFacialMocap (iOS, UDP port 49983): one frame of the text layout `formats.captures.ifacialmocap` reads, a datagram
a frame; that module's parser reads it.

VMC protocol (OSC over UDP, port 39539): `/VMC/Ext/Blend/Val` (name, value) sets a weight, `/VMC/Ext/Blend/Apply`
ends a frame; `/VMC/Ext/Bone/Pos` ("Head", position, rotation quaternion) gives the head's local rotation, in
Unity's left-handed axes (VRM's glTF axes with x mirrored), carried by the next Apply's frame.

A malformed datagram raises `PacketError`; the server counts and skips it.
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass

import numpy as np
from pythonosc.osc_packet import OscPacket, ParseError

from converter.errors import InputError
from converter.formats.captures import arkit, ifacialmocap
from converter.formats.captures.livelinkface import LLF_ANGLE_UNIT

LLF_CURVES = 61  # Unreal's EARFaceBlendShape: 52 weights and 9 angles
LLF_WEIGHTS = len(arkit.NAMES)


def _csv_names() -> tuple[str, ...]:
    """The 52 weight names of a packet's slots, as the app's CSV heads its columns: ARKit's names capitalised, in
    EARFaceBlendShape's order but for JawRight/JawLeft and MouthRight/MouthLeft, which the app's CSV (the real take
    in tests/data/captures) lists the other way round. A streamed take then drives the puppet as its CSV does."""
    names = [n[0].upper() + n[1:] for n in arkit.NAMES]
    for a, b in (("JawLeft", "JawRight"), ("MouthLeft", "MouthRight")):
        i, j = names.index(a), names.index(b)
        names[i], names[j] = names[j], names[i]
    return tuple(names)


LLF_NAMES = _csv_names()
_LLF_TIME = struct.Struct(">ifii")
_INT32 = struct.Struct(">i")
VMC_BLEND = "/VMC/Ext/Blend/Val"
VMC_APPLY = "/VMC/Ext/Blend/Apply"
VMC_BONE = "/VMC/Ext/Bone/Pos"
MAX_NAMES = 1024  # distinct weight names a feed may set (ARKit has 52, VRM's presets fewer): bounds a stray sender


class PacketError(ValueError):
    """A datagram that is not a frame of the layout its port expects."""


@dataclass(frozen=True)
class LiveFrame:
    """One tracked frame: weights by name; head (yaw, pitch, roll) and eyes (left yaw, pitch, right yaw, pitch) in
    radians as the puppet turns them, None when the packet carries none; `subject` names the sender where known."""

    weights: dict[str, float]
    head: tuple[float, float, float] | None = None
    eyes: tuple[float, float, float, float] | None = None
    subject: str = ""


def message(weights: dict[str, float], head: tuple[float, ...] | None, eyes: tuple[float, ...] | None) -> str:
    """The player's JSON message: {"weights": {name: w}, "head": [yaw, pitch, roll], "eyes": [ly, lp, ry, rp]}."""
    out: dict[str, object] = {"weights": {k: round(float(v), 5) for k, v in weights.items()}}
    if head is not None:
        out["head"] = [round(float(v), 6) for v in head]
    if eyes is not None:
        out["eyes"] = [round(float(v), 6) for v in eyes]
    return json.dumps(out, separators=(",", ":"))


def _string(data: bytes, at: int) -> tuple[str, int]:
    """A Live Link int32-length-prefixed UTF-8 string at `at`, and the offset after it."""
    if at + 4 > len(data):
        raise PacketError("the packet ends inside a string's length")
    (n,) = _INT32.unpack_from(data, at)
    at += 4
    if n < 0 or at + n > len(data):
        raise PacketError(f"a string length of {n} runs past the packet's end")
    try:
        return data[at:at + n].decode("utf-8"), at + n
    except UnicodeDecodeError:
        raise PacketError("a string is not UTF-8") from None


def parse_livelink(data: bytes) -> LiveFrame:
    """A Live Link Face packet: the ARKit weights (named as the app's CSV names them), head and eye angles in
    radians."""
    if not data:
        raise PacketError("an empty packet")
    device, at = _string(data, 1)
    subject, at = _string(data, at)
    if at + _LLF_TIME.size + 1 > len(data):
        raise PacketError("the packet ends before its frame time and curve count")
    _, _, numerator, denominator = _LLF_TIME.unpack_from(data, at)
    at += _LLF_TIME.size
    count = data[at]
    at += 1
    if count > LLF_CURVES:
        raise PacketError(f"{count} curves, more than Live Link Face's {LLF_CURVES}")
    if len(data) != at + 4 * count:
        raise PacketError(f"{len(data)} bytes where {count} curves make {at + 4 * count}")
    if denominator <= 0 or numerator <= 0:
        raise PacketError(f"a frame rate of {numerator}/{denominator}")
    values = struct.unpack_from(f">{count}f", data, at)
    if not all(math.isfinite(v) for v in values):
        raise PacketError("a curve is NaN or infinite")
    weights = dict(zip(LLF_NAMES, values[:LLF_WEIGHTS]))
    head = eyes = None
    if count >= LLF_WEIGHTS + 3:
        yaw, pitch, roll = (v * LLF_ANGLE_UNIT for v in values[LLF_WEIGHTS:LLF_WEIGHTS + 3])
        head = (yaw, pitch, roll)
    if count >= LLF_CURVES:
        ly, lp, _, ry, rp, _ = (v * LLF_ANGLE_UNIT for v in values[LLF_WEIGHTS + 3:LLF_CURVES])
        eyes = (ly, lp, ry, rp)
    return LiveFrame(weights, head, eyes, subject or device)


def parse_ifacialmocap(data: bytes) -> LiveFrame:
    """An iFacialMocap datagram (its last frame when it holds several lines): weights, head and eyes in radians."""
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # a huge number becomes inf, refused below
            track = ifacialmocap.parse(data, "the iFacialMocap packet")
    except InputError as exc:
        raise PacketError(str(exc)) from None
    rows = [a[-1] for a in (track.values, track.head, track.eye_left, track.eye_right) if a is not None]
    if not all(np.isfinite(r).all() for r in rows):  # the reader checks its float64 degrees, not their float32 radians
        raise PacketError("a value is too large for a float32")
    weights = dict(zip(track.names, track.values[-1].tolist()))
    head = eyes = None
    if track.head is not None:
        yaw, pitch, roll = track.head[-1].tolist()
        head = (yaw, pitch, roll)
    if track.eye_left is not None and track.eye_right is not None:
        (ly, lp), (ry, rp) = track.eye_left[-1, :2].tolist(), track.eye_right[-1, :2].tolist()
        eyes = (ly, lp, ry, rp)
    return LiveFrame(weights, head, eyes)


def unity_head_angles(qx: float, qy: float, qz: float, qw: float) -> tuple[float, float, float]:
    """(yaw, pitch, roll) radians of a Unity rotation quaternion, turned into glTF's axes (x mirrored) and split as
    the puppet composes its head turn, R = Ry(yaw) Rx(pitch) Rz(roll)."""
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    if not (n > 1e-9 and math.isfinite(n)):
        raise PacketError("a zero or non-finite rotation quaternion")
    # Mirroring x keeps the rotation's x component and flips its y and z (a mirror reverses the turn's sense).
    x, y, z, w = qx / n, -qy / n, -qz / n, qw / n
    r02 = 2 * (x * z + w * y)
    r12 = 2 * (y * z - w * x)
    r22 = 1 - 2 * (x * x + y * y)
    r10 = 2 * (x * y + w * z)
    r11 = 1 - 2 * (x * x + z * z)
    pitch = math.asin(max(-1.0, min(1.0, -r12)))
    return math.atan2(r02, r22), pitch, math.atan2(r10, r11)


class VmcReader:
    """VMC protocol datagrams (OSC messages or bundles) to frames: weights gathered until each Blend/Apply."""

    def __init__(self) -> None:
        self.pending: dict[str, float] = {}
        self.head: tuple[float, float, float] | None = None

    def feed(self, data: bytes) -> tuple[list[LiveFrame], int]:
        """The frames one datagram completes, and how many of its messages were malformed (and skipped)."""
        try:
            messages = [m.message for m in OscPacket(data).messages]
        except (ParseError, ValueError, IndexError, TypeError, OverflowError, struct.error) as exc:
            raise PacketError(f"not an OSC packet ({exc})") from None
        frames, bad = [], 0
        for m in messages:
            try:
                frame = self._message(m.address, list(m.params))
            except PacketError:
                bad += 1
                continue
            if frame is not None:
                frames.append(frame)
        return frames, bad

    def _message(self, address: str, params: list) -> LiveFrame | None:
        """Apply one message; the frame it ends, if it is an Apply."""
        if address == VMC_BLEND:
            if len(params) != 2 or not isinstance(params[0], str) or not _finite(params[1]):
                raise PacketError("Blend/Val takes a name and a number")
            if len(self.pending) >= MAX_NAMES and params[0] not in self.pending:
                raise PacketError(f"more than {MAX_NAMES} weight names in one frame")
            self.pending[params[0]] = float(params[1])
        elif address == VMC_APPLY:
            frame = LiveFrame(self.pending, self.head)
            self.pending, self.head = {}, None
            return frame
        elif address == VMC_BONE:
            if len(params) != 8 or not isinstance(params[0], str) or not all(_finite(v) for v in params[1:]):
                raise PacketError("Bone/Pos takes a name, a position and a quaternion")
            if params[0] == "Head":
                self.head = unity_head_angles(*(float(v) for v in params[4:8]))
        return None


def _finite(value) -> bool:
    """A real number (OSC int or float), finite."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
