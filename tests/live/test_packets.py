"""The live packet parsers on datagrams built by the documented layouts, the real iFacialMocap frame, and garbage."""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from converter.blendshapes import rotations
from converter.formats.captures import ifacialmocap, livelinkface
from converter.live.packets import (
    LLF_NAMES,
    MAX_NAMES,
    LiveFrame,
    PacketError,
    VmcReader,
    message,
    parse_ifacialmocap,
    parse_livelink,
    unity_head_angles,
)

from .build import ifm_frame, llf_packet, osc, osc_bundle

CAPTURES = Path(__file__).resolve().parents[1] / "data" / "captures"
LLF_CSV = CAPTURES / "livelinkface_myslate3_cut.csv"
F32 = 1e-6


def curves(seed: int = 0) -> list[float]:
    """61 Live Link curves: 52 weights in 0..1, then 9 angles within +-0.2 units (+-36 degrees)."""
    rng = np.random.default_rng(seed)
    return [float(v) for v in np.r_[rng.uniform(0, 1, 52), rng.uniform(-0.2, 0.2, 9)].astype(np.float32)]


def test_llf_names_are_the_apps_csv_columns():
    header = LLF_CSV.read_text().splitlines()[0].split(",")
    assert list(LLF_NAMES) == header[2:54]


def test_llf_packet_gives_the_weights_and_angles_in_radians():
    c = curves()
    frame = parse_livelink(llf_packet(c, subject="Ana's iPhone"))
    assert frame.subject == "Ana's iPhone"
    assert list(frame.weights) == list(LLF_NAMES)
    assert np.allclose(list(frame.weights.values()), c[:52], atol=F32)
    assert np.allclose(frame.head, np.array(c[52:55]) * math.pi, atol=F32)  # one unit is 180 degrees
    assert np.allclose(frame.eyes, np.array([c[55], c[56], c[58], c[59]]) * math.pi, atol=F32)


def test_llf_packet_reads_as_the_same_take_written_as_csv():
    """The streamed frame and the CSV row the app would write for it read the same weights, head and eyes."""
    header = LLF_CSV.read_text().splitlines()[0]
    c = curves(3)
    csv = f"{header}\n00:00:01:00.000,61,{','.join(f'{v:.9f}' for v in c)}\n".encode()
    track = livelinkface.parse(csv, "one.csv")
    frame = parse_livelink(llf_packet(c))
    assert dict(zip(track.names, track.values[0].tolist())) == pytest.approx(frame.weights, abs=F32)
    assert np.allclose(track.head[0], frame.head, atol=1e-5)
    assert np.allclose([*track.eye_left[0, :2], *track.eye_right[0, :2]], frame.eyes, atol=1e-5)


def test_llf_packet_of_52_curves_has_no_angles():
    frame = parse_livelink(llf_packet(curves()[:52]))
    assert len(frame.weights) == 52 and frame.head is None and frame.eyes is None


def test_llf_truncated_padded_or_wrong_packets_are_packet_errors():
    good = llf_packet(curves())
    for n in range(len(good)):
        with pytest.raises(PacketError):
            parse_livelink(good[:n])
    bad = [
        good + b"\x00",  # a trailing byte
        llf_packet(curves() + [0.0]),  # 62 curves
        llf_packet(curves()[:60] + [float("nan")]),
        llf_packet(curves(), rate=(60, 0)),
        bytes([6]) + struct.pack(">i", -1) + good[5:],  # a negative string length
        bytes([6]) + struct.pack(">i", 10_000) + good[5:],  # a string longer than the packet
        llf_packet(curves(), subject="x").replace(b"x", b"\xff"),  # not UTF-8
    ]
    for packet in bad:
        with pytest.raises(PacketError):
            parse_livelink(packet)


def test_ifm_real_frame_reads_as_the_capture_reader_reads_it():
    data = (CAPTURES / "ifacialmocap_frame.txt").read_bytes()
    track = ifacialmocap.parse(data, "frame")
    frame = parse_ifacialmocap(data)
    assert frame.weights == dict(zip(track.names, track.values[0].tolist()))
    assert frame.weights["jawOpen"] == pytest.approx(0.12)
    assert frame.head == tuple(track.head[0].tolist())
    assert frame.eyes == (*track.eye_left[0, :2].tolist(), *track.eye_right[0, :2].tolist())
    extra = parse_ifacialmocap((CAPTURES / "ifacialmocap_frame_extra_key.txt").read_bytes())
    assert "hapihapi" not in extra.weights and extra.weights


def test_ifm_built_frame_units_and_axes():
    data = ifm_frame({"jawOpen": 40, "eyeBlink_L": 100, "mouthSmile_R": 7}, (10.0, -20.0, 5.0, 0.1, 0.2, 0.3),
                     (3.0, -4.0, 0.0), (3.0, 6.0, 0.0))
    frame = parse_ifacialmocap(data)
    assert frame.weights == pytest.approx({"jawOpen": 0.4, "eyeBlink_L": 1.0, "mouthSmile_R": 0.07})
    d = math.pi / 180
    # head (yaw, pitch, roll) = -(ry, rx, rz); each eye (yaw, pitch) = (y, x): the layout's pitch-yaw-roll items
    assert frame.head == pytest.approx((20 * d, -10 * d, -5 * d), abs=1e-6)
    assert frame.eyes == pytest.approx((6 * d, 3 * d, -4 * d, 3 * d), abs=1e-6)


def reject(constant: str):
    """json.loads hook: NaN and Infinity are not JSON (the player's JSON.parse refuses them)."""
    raise AssertionError(f"{constant} in a message")


@pytest.mark.parametrize("data", [b"", b"\xff\xfe\x00", b"hello", b"|||", b"=head#1,2|", llf_packet(curves()),
                                  b"jawOpen-10|=head#1,2,x,4,5,6|",
                                  b"jawOpen-1" + b"0" * 400 + b"|", b"jawOpen-1|=head#1e41,0,0,0,0,0|"])
def test_ifm_garbage_is_a_packet_error(data):
    with pytest.raises(PacketError):
        parse_ifacialmocap(data)


def test_vmc_weights_make_a_frame_at_each_apply():
    reader = VmcReader()
    frames, bad = reader.feed(osc_bundle(osc("/VMC/Ext/Blend/Val", "JawOpen", 0.25),
                                         osc("/VMC/Ext/Blend/Val", "Blink_L", 1.0),
                                         osc("/VMC/Ext/Root/Pos", "root", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
                                         osc("/VMC/Ext/Blend/Apply")))
    assert bad == 0 and len(frames) == 1
    assert frames[0].weights == {"JawOpen": 0.25, "Blink_L": 1.0} and frames[0].head is None
    # values spread over datagrams wait for the Apply; an Apply starts the next frame afresh
    assert reader.feed(osc("/VMC/Ext/Blend/Val", "A", 0.5)) == ([], 0)
    frames, _ = reader.feed(osc("/VMC/Ext/Blend/Apply"))
    assert [f.weights for f in frames] == [{"A": 0.5}]
    frames, _ = reader.feed(osc_bundle(osc("/VMC/Ext/Blend/Apply"), osc("/VMC/Ext/Blend/Val", "E", 0.1),
                                       osc("/VMC/Ext/Blend/Apply")))
    assert [f.weights for f in frames] == [{}, {"E": pytest.approx(0.1)}]


def test_vmc_malformed_messages_are_counted_and_skipped():
    reader = VmcReader()
    frames, bad = reader.feed(osc_bundle(osc("/VMC/Ext/Blend/Val", "A"), osc("/VMC/Ext/Blend/Val", 3, 0.5),
                                         osc("/VMC/Ext/Blend/Val", "B", "x"),
                                         osc("/VMC/Ext/Bone/Pos", "Head", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
                                         osc("/VMC/Ext/Blend/Val", "C", 0.75), osc("/VMC/Ext/Blend/Apply")))
    assert bad == 4
    assert [f.weights for f in frames] == [{"C": 0.75}] and frames[0].head is None
    for data in (b"", b"\x00\x01\x02", b"#bundle\x00", b"/VMC/Ext/Blend/Val\x00\x00,sf", llf_packet(curves())):
        with pytest.raises(PacketError):
            reader.feed(data)


@pytest.mark.parametrize("ypr", [(0.3, 0.0, 0.0), (0.0, -0.4, 0.0), (0.0, 0.0, 0.5), (0.35, -0.25, 0.15),
                                 (-1.0, 0.6, -0.8)])
def test_vmc_head_quaternion_gives_the_puppets_angles(ypr):
    """A Unity rotation whose glTF (x-mirrored) form is Ry Rx Rz(ypr) reads back as ypr, carried by the Apply."""
    mirror = np.diag([-1.0, 1.0, 1.0])
    unity = mirror @ rotations(np.array([ypr]))[0] @ mirror
    qx, qy, qz, qw = Rotation.from_matrix(unity).as_quat()
    frames, bad = VmcReader().feed(osc_bundle(osc("/VMC/Ext/Bone/Pos", "Head", 0.0, 1.5, 0.0, qx, qy, qz, qw),
                                              osc("/VMC/Ext/Blend/Apply")))
    assert bad == 0 and frames[0].head == pytest.approx(ypr, abs=1e-6)


def test_a_unity_turn_to_the_avatars_right_is_a_negative_yaw():
    """Unity's y turn takes +z towards +x; with x mirrored into glTF's axes that is towards -x: Ry of minus it."""
    t = 0.4
    yaw, pitch, roll = unity_head_angles(0.0, math.sin(t / 2), 0.0, math.cos(t / 2))
    assert (yaw, pitch, roll) == pytest.approx((-t, 0.0, 0.0), abs=1e-9)
    with pytest.raises(PacketError):
        unity_head_angles(0.0, 0.0, 0.0, 0.0)


def test_message_is_the_players_json():
    text = message({"jawOpen": 0.123456789}, (0.1, -0.2, 0.3), None)
    assert json.loads(text) == {"weights": {"jawOpen": 0.12346}, "head": [0.1, -0.2, 0.3]}
    assert "eyes" in json.loads(message({}, None, (1, 2, 3, 4)))


def test_no_garbage_escapes_as_anything_but_a_packet_error():
    """Random datagrams and random byte flips of good ones: each parses or raises PacketError, nothing else."""
    rng = np.random.default_rng(52)
    good = [llf_packet(curves()), (CAPTURES / "ifacialmocap_frame.txt").read_bytes(),
            osc_bundle(osc("/VMC/Ext/Blend/Val", "A", 0.5), osc("/VMC/Ext/Blend/Apply"))]
    parsers = [parse_livelink, parse_ifacialmocap, VmcReader().feed]
    outcomes = {"parsed": 0, "rejected": 0}
    for k in range(600):
        if k % 2:
            data = rng.integers(0, 256, int(rng.integers(0, 400)), dtype=np.uint8).tobytes()
        else:
            data = bytearray(good[k % 3])
            for i in rng.integers(0, len(data), int(rng.integers(1, 4))):
                data[i] = int(rng.integers(0, 256))
            data = bytes(data)
        for parse in parsers:
            try:
                out = parse(data)
            except PacketError:
                outcomes["rejected"] += 1
                continue
            outcomes["parsed"] += 1
            frames = out[0] if isinstance(out, tuple) else [out]
            for f in frames:
                assert isinstance(f, LiveFrame)
                json.loads(message(f.weights, f.head, f.eyes), parse_constant=reject)  # no NaN: the player's JSON
    assert outcomes["parsed"] > 0 and outcomes["rejected"] > 0


def test_vmc_names_past_the_bound_are_skipped():
    messages = [osc("/VMC/Ext/Blend/Val", f"w{k}", 0.5) for k in range(MAX_NAMES + 3)]
    frames, bad = VmcReader().feed(osc_bundle(*messages, osc("/VMC/Ext/Blend/Apply")))
    assert bad == 3 and len(frames[0].weights) == MAX_NAMES
