"""Azure viseme blend shapes: 55-column FrameIndex/BlendShapes chunks at 60 fps, rolls in radians, bad input."""

import importlib
import json
import math

import numpy as np
import pytest

from converter.errors import InputError
from converter.formats.captures import azure
from tests.formats.captures.layout_samples import others, read

FIXTURE = "azure_visemes.jsonl"
# Microsoft Learn, "Get facial position with viseme", the order of BlendShapes (typed from the page's table)
DOCUMENTED = """eyeBlinkLeft eyeLookDownLeft eyeLookInLeft eyeLookOutLeft eyeLookUpLeft eyeSquintLeft eyeWideLeft
eyeBlinkRight eyeLookDownRight eyeLookInRight eyeLookOutRight eyeLookUpRight eyeSquintRight eyeWideRight jawForward
jawLeft jawRight jawOpen mouthClose mouthFunnel mouthPucker mouthLeft mouthRight mouthSmileLeft mouthSmileRight
mouthFrownLeft mouthFrownRight mouthDimpleLeft mouthDimpleRight mouthStretchLeft mouthStretchRight mouthRollLower
mouthRollUpper mouthShrugLower mouthShrugUpper mouthPressLeft mouthPressRight mouthLowerDownLeft mouthLowerDownRight
mouthUpperUpLeft mouthUpperUpRight browDownLeft browDownRight browInnerUp browOuterUpLeft browOuterUpRight cheekPuff
cheekSquintLeft cheekSquintRight noseSneerLeft noseSneerRight tongueOut headRoll leftEyeRoll rightEyeRoll""".split()


def chunks() -> list[dict]:
    return [json.loads(line) for line in read(FIXTURE).decode().splitlines()]


def test_column_order_is_the_documented_one():
    assert len(DOCUMENTED) == 55 and list(azure.COLUMNS) == DOCUMENTED


def test_fixture():
    data = read(FIXTURE)
    assert azure.LAYOUT.sniff(data)
    track = azure.LAYOUT.parse(data, FIXTURE)
    assert track.source == "azure-viseme-json" and track.names == DOCUMENTED[:52]
    assert track.n_frames == 5 and track.fps == 60.0 and track.duration == pytest.approx(5 / 60)
    np.testing.assert_allclose(track.times, np.arange(5) / 60)
    np.testing.assert_allclose(track.values[:, 17], [0, 0.1, 0.2, 0.3, 0.4], atol=1e-7)  # jawOpen
    np.testing.assert_allclose(track.values[:, 0], [0, 0.5, 0, 0, 0])  # eyeBlinkLeft
    # rolls: ARKit face-curve units (1 = 90 degrees) -> radians, about the forward axis only
    np.testing.assert_allclose(track.head, np.tile([0, 0, 0.1 * math.pi / 2], (5, 1)), rtol=1e-6)
    np.testing.assert_allclose(track.eye_left[:, 2], -0.05 * math.pi / 2, rtol=1e-6)
    np.testing.assert_allclose(track.eye_right[:, 2], 0.02 * math.pi / 2, rtol=1e-6)
    assert not track.eye_left[:, :2].any() and not track.head[:, :2].any()


def test_list_and_out_of_order_chunks():
    stream = azure.parse(read(FIXTURE), FIXTURE)
    swapped = azure.parse(json.dumps(chunks()[::-1]).encode(), "list.json")
    np.testing.assert_array_equal(swapped.values, stream.values)
    single = azure.parse(json.dumps(chunks()[0]).encode(), "one.json")
    assert single.n_frames == 3
    concatenated = azure.parse(b"".join(json.dumps(c).encode() for c in chunks()), "cat.json")  # no newlines
    assert concatenated.n_frames == 5


def test_sniff_claims_only_azure():
    assert not any(azure.sniff(data) for data in others("azure-viseme-json").values())


def test_missing_and_repeated_frames():
    first, second = chunks()
    second["FrameIndex"] = 4
    with pytest.raises(InputError, match="starts at frame 4 but the chunks before end at frame 3; frames are missing"):
        azure.parse(json.dumps([first, second]).encode(), "gap.json")
    second["FrameIndex"] = 1
    with pytest.raises(InputError, match="frames are repeated"):
        azure.parse(json.dumps([first, second]).encode(), "twice.json")


def test_wrong_column_count():
    first = chunks()[0]
    first["BlendShapes"][1] = first["BlendShapes"][1][:54]
    with pytest.raises(InputError, match=r"chunk 0 \(FrameIndex 0\) BlendShapes frame 1 has 54 values, expected 55"):
        azure.parse(json.dumps(first).encode(), "cols.json")


def test_nan():
    first = chunks()[0]
    first["BlendShapes"][2][17] = float("nan")
    with pytest.raises(InputError, match=r"frame 2, value 17 is NaN or infinite"):
        azure.parse(json.dumps(first).encode(), "nan.json")


def test_truncated_and_empty():
    data = read(FIXTURE)
    with pytest.raises(InputError, match="not valid JSON.*truncated"):
        azure.parse(data[: len(data) // 2 + 7], "cut.jsonl")
    with pytest.raises(InputError, match="empty"):
        azure.parse(b"\n", "e.json")
    with pytest.raises(InputError, match="every chunk's BlendShapes is empty"):
        azure.parse(b'{"FrameIndex": 0, "BlendShapes": []}', "none.json")


def test_not_a_chunk():
    with pytest.raises(InputError, match="chunk 1 is not an Azure viseme Animation object"):
        azure.parse(json.dumps([chunks()[0], {"FrameIndex": 3}]).encode(), "odd.json")
    with pytest.raises(InputError, match="FrameIndex -1"):
        azure.parse(b'{"FrameIndex": -1, "BlendShapes": [[0]]}', "neg.json")


def test_registered():
    registry = importlib.import_module("converter.formats.captures")
    layouts = getattr(registry, "LAYOUTS", ())
    assert azure.LAYOUT in (list(layouts.values()) if isinstance(layouts, dict) else list(layouts))
    assert registry.detect(read(FIXTURE)) == azure.LAYOUT
