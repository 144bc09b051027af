"""Rhubarb Lip Sync mouth cues (JSON and TSV): the shape table, sampling with linear cross-fades, bad input."""

import importlib
import json

import numpy as np
import pytest

from converter.errors import InputError
from converter.formats.captures import rhubarb
from converter.formats.captures.arkit import NAME_SET
from tests.formats.captures.layout_samples import others, read

JSON, TSV = "rhubarb_hi.json", "rhubarb_hi.tsv"
# README 'Hi': X 0-0.05, D 0.05-0.27, C 0.27-0.31, B 0.31-0.43, X 0.43-0.47
CUES = [(0.0, 0.05, "X"), (0.05, 0.27, "D"), (0.27, 0.31, "C"), (0.31, 0.43, "B"), (0.43, 0.47, "X")]


def step(t: float, name: str) -> float:
    """The table's weight of the cue holding at t (no fade)."""
    shape = next(s for a, b, s in CUES if a <= t < b)
    return rhubarb.SHAPES[shape].get(name, 0.0)


def test_json_hi():
    data = read(JSON)
    assert rhubarb.LAYOUT.sniff(data)
    track = rhubarb.LAYOUT.parse(data, JSON)
    assert track.source == "rhubarb" and track.fps == 60.0
    assert track.n_frames == 29  # frames k / 60 for k / 60 < 0.47 s
    assert track.times[-1] < 0.47 <= track.duration
    assert set(track.names) <= NAME_SET and "jawOpen" in track.names
    assert 0 <= track.values.min() and track.values.max() <= 1
    jaw = track.values[:, track.names.index("jawOpen")]
    # away from the cue changes (farther than half a cross-fade) each frame is its cue's table row exactly
    for k, t in enumerate(track.times):
        if min(abs(t - b) for _, b, _ in CUES) > rhubarb.CROSSFADE / 2 + 1e-9 and t > rhubarb.CROSSFADE / 2:
            for j, n in enumerate(track.names):
                assert track.values[k, j] == pytest.approx(step(t, n), abs=1e-6)
    # X -> D at 0.05 s is a linear ramp over CROSSFADE centred on the change
    d_jaw = rhubarb.SHAPES["D"]["jawOpen"]
    for k in (2, 3, 4):  # 0.033, 0.050, 0.067 s
        t = k / 60
        expected = d_jaw * np.clip((t - (0.05 - rhubarb.CROSSFADE / 2)) / rhubarb.CROSSFADE, 0, 1)
        assert jaw[k] == pytest.approx(expected, abs=1e-6)
    assert jaw[3] == pytest.approx(d_jaw / 2, abs=1e-6)  # halfway at the change itself
    assert jaw[0] == 0 and jaw[-1] == 0  # closed at rest before and after


def test_tsv_equals_json():
    assert rhubarb.sniff(read(TSV))
    a = rhubarb.parse(read(JSON), JSON)
    b = rhubarb.parse(read(TSV), TSV)
    assert a.names == b.names and a.n_frames == b.n_frames
    np.testing.assert_allclose(a.values, b.values, atol=1e-7)


def test_rate_from_the_file():
    doc = json.loads(read(JSON))
    doc["metadata"]["fps"] = 30
    track = rhubarb.parse(json.dumps(doc).encode(), "30.json")
    assert track.fps == 30.0 and track.n_frames == 15
    np.testing.assert_allclose(track.times, np.arange(15) / 30)


def test_gap_holds_rest_and_late_start():
    doc = {"mouthCues": [{"start": 0.2, "end": 0.4, "value": "D"}, {"start": 0.6, "end": 0.8, "value": "F"}]}
    track = rhubarb.parse(json.dumps(doc).encode(), "gap.json")
    jaw = track.values[:, track.names.index("jawOpen")]
    pucker = track.values[:, track.names.index("mouthPucker")]
    t = track.times
    assert np.all(jaw[t < 0.17] == 0)  # before the first cue: rest
    assert np.all(jaw[(t > 0.43) & (t < 0.57)] == 0) and np.all(pucker[(t > 0.43) & (t < 0.57)] == 0)  # the gap
    assert pucker[np.argmin(np.abs(t - 0.7))] == pytest.approx(rhubarb.SHAPES["F"]["mouthPucker"])


def test_shape_table():
    assert set(rhubarb.SHAPES) == set("ABCDEFGHX") and rhubarb.SHAPES["X"] == {}
    for shape, weights in rhubarb.SHAPES.items():
        assert set(weights) <= NAME_SET, shape
        assert all(0 < w <= 1 for w in weights.values()), shape
        for name in weights:  # sided shapes come in pairs
            for a, b in (("Left", "Right"), ("Right", "Left")):
                if name.endswith(a):
                    assert weights[name[: -len(a)] + b] == weights[name]
    jaw = {s: w.get("jawOpen", 0.0) for s, w in rhubarb.SHAPES.items()}
    assert jaw["A"] == 0 and max(jaw, key=jaw.get) == "D"  # A closed, D the widest
    assert jaw["E"] <= jaw["C"] <= jaw["H"] < jaw["D"]  # README: E no wider than C; H between C and D
    assert max(rhubarb.SHAPES, key=lambda s: rhubarb.SHAPES[s].get("mouthPucker", 0)) == "F"
    assert max(rhubarb.SHAPES, key=lambda s: rhubarb.SHAPES[s].get("mouthRollLower", 0)) == "G"


def test_sniff_claims_only_rhubarb():
    assert not any(rhubarb.sniff(data) for data in others("rhubarb").values())
    assert not rhubarb.sniff(b"0.00\tX\n0.05\tQ\n") and not rhubarb.sniff(b"0.5,1\n")


@pytest.mark.parametrize(("data", "message"), [
    (b"", "empty"),
    (b'{"metadata": {}, "mouthCues": []}', "mouthCues is empty"),
    (b'{"metadata": {}, "mouthCues": [{"start": 0, "end": 0.1, "value": "Q"}]}', "mouth shape 'Q'"),
    (b'{"mouthCues": [{"start": 0, "value": "A"}]}', "mouth cue 0 needs start, end and value"),
    (b'{"mouthCues": [{"start": 0.2, "end": 0.1, "value": "A"}]}', r"cue 0 ends \(0.1 s\) before it starts"),
    (b'{"mouthCues": [{"start": 0, "end": 0.3, "value": "A"}, {"start": 0.2, "end": 0.4, "value": "B"}]}',
     "cue 1 starts at 0.2 s, before cue 0 ends"),
    (b'{"mouthCues": [{"start": 0, "end": NaN, "value": "A"}]}', "mouth cue 0 end is 'nan', not a finite number"),
    (b'{"mouthCues": [{"start": 0, "end": 0.1, "value": "A"}', "not valid JSON"),
    (b'{"mouthCues": 3}', "needs a mouthCues list"),
    (b"0.00\tX\n0.05\tD extra\n", r"line 2: '0.05\\tD extra' is not `seconds<TAB>shape`"),
    (b"0.00\tX\nnan\tD\n0.3\tX\n", "line 2: the time is NaN or infinite"),
    (b"0.00\tX\n0.30\tD\n0.10\tX\n", r"cue 1 ends \(0.1 s\) before it starts"),
    (b"0.00\tX\nabc\tD\n", "line 2: 'abc' is not a time"),
])
def test_bad_input(data, message):
    with pytest.raises(InputError, match=message):
        rhubarb.parse(data, "bad")


def test_truncated_tsv_still_reads_what_is_there():
    # a TSV cut after a line is a shorter recording (its last line is taken as the end), not an error
    track = rhubarb.parse(b"0.00\tX\n0.05\tD\n0.27\tC\n", "cut.tsv")
    assert track.n_frames == 17 and track.duration == pytest.approx(17 / 60)


def test_registered():
    registry = importlib.import_module("converter.formats.captures")
    layouts = getattr(registry, "LAYOUTS", ())
    assert rhubarb.LAYOUT in (list(layouts.values()) if isinstance(layouts, dict) else list(layouts))
    assert registry.detect(read(JSON)) == rhubarb.LAYOUT and registry.detect(read(TSV)) == rhubarb.LAYOUT
