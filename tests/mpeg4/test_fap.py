"""FAP stream reading/writing on the eight Xface streams and every variant of the format; strict errors."""

from __future__ import annotations

import re

import numpy as np
import pytest

from converter.errors import InputError
from converter.mpeg4.fap import FapStream, read_fap, write_fap

STREAMS = ("anger", "beg", "disgust", "fear", "happy-for", "hate", "joy", "pride")


@pytest.fixture(scope="module")
def xface(small_data):
    return small_data / "mpeg4" / "xface"


@pytest.mark.parametrize("name", STREAMS)
def test_xface_stream_parses_and_round_trips(xface, name):
    text = (xface / f"{name}.fap").read_text()
    header = text.splitlines()[0].split()
    s = read_fap(xface / f"{name}.fap")
    assert s.fps == float(header[-2]) == 25.0
    assert s.n_frames == int(header[-1])
    assert s.name == " ".join(header[1:-2])
    # values line k holds exactly the set mask bits of mask line k
    lines = text.splitlines()[1:]
    for t in (0, s.n_frames // 2, s.n_frames - 1):
        bits = [b == "1" for b in lines[2 * t].split()]
        vals = [float(x) for x in lines[2 * t + 1].split()[1:]]
        assert list(s.mask[t]) == bits[:68]
        np.testing.assert_array_equal(s.values[t][s.mask[t]], vals)
        assert not s.values[t][~s.mask[t]].any()
    assert 40 <= s.mask.any(0).sum() <= 51
    again = read_fap(write_fap(s))
    np.testing.assert_array_equal(again.values, s.values)
    np.testing.assert_array_equal(again.mask, s.mask)
    assert (again.name, again.fps, again.extra) == (s.name, s.fps, s.extra)
    assert write_fap(again) == write_fap(s)


def _stream_text(n_frames=3, first=0, version="2.1", sep=" ", width=68, fap12=None):
    """A small stream: FAPs 3 and 19 set, plus FAP 1/2 with the given value counts."""
    head = f"{version} my test stream {25} {n_frames}"
    rows = [head]
    for t in range(n_frames):
        bits = ["0"] * width
        vals = []
        for k in fap12 or {}:
            bits[k - 1] = "1"
        if fap12:
            for k in sorted(fap12):
                vals += [str(k * 10 + i) for i in range(fap12[k])]
        bits[2] = bits[18] = "1"
        vals += [str(100 + t), str(-5 * t)]
        rows.append(sep.join(bits))
        rows.append(sep.join([str(first + t)] + vals))
    return "\n".join(rows) + "\n"


@pytest.mark.parametrize("kwargs", [
    {}, {"first": 1}, {"version": "2.0"}, {"sep": "\t"}, {"width": 69},
    {"fap12": {1: 1}}, {"fap12": {1: 4}}, {"fap12": {2: 6}}, {"fap12": {1: 4, 2: 6}}, {"fap12": {1: 1, 2: 1}},
    {"fap12": {1: 4, 2: 1}}, {"fap12": {1: 1, 2: 6}},
])
def test_variants_parse_and_round_trip(kwargs):
    text = "# a comment\n# another one\n" + _stream_text(**kwargs)
    s = read_fap(text)
    assert s.name == "my test stream" and s.n_frames == 3
    np.testing.assert_array_equal(s.values[:, 2], [100, 101, 102])
    np.testing.assert_array_equal(s.values[:, 18], [0, -5, -10])
    assert s.extra["first_frame"] == kwargs.get("first", 0)
    assert s.extra["version"] == kwargs.get("version", "2.1")
    for k, count in (kwargs.get("fap12") or {}).items():
        assert s.mask[:, k - 1].all()
        assert s.values[0, k - 1] == k * 10  # the first of its values
        if count > 1:
            assert s.extra[f"fap{k}"][0] == tuple(float(k * 10 + i) for i in range(count))
    again = read_fap(write_fap(s))
    np.testing.assert_array_equal(again.values, s.values)
    np.testing.assert_array_equal(again.mask, s.mask)
    assert again.extra == s.extra
    # the low-level view never carries FAP 1-2
    assert not s.low_level()[:, :2].any()


def _replace_line(text: str, lineno: int, new: str) -> str:
    lines = text.splitlines()
    lines[lineno - 1] = new
    return "\n".join(lines) + "\n"


GOOD = "# comment\n" + _stream_text()  # header on line 2, masks on 3/5/7, values on 4/6/8

MALFORMED = [
    ("bad version", _replace_line(GOOD, 2, "3.0 name 25 3"), 2, "version"),
    ("fps not a number", _replace_line(GOOD, 2, "2.1 name abc 3"), 2, "frame rate"),
    ("frames not an integer", _replace_line(GOOD, 2, "2.1 name 25 3.5"), 2, "number of frames"),
    ("short header", _replace_line(GOOD, 2, "2.1 25"), 2, "header"),
    ("mask with a 2", _replace_line(GOOD, 5, "0 0 2" + " 0" * 65), 5, "mask"),
    ("mask too short", _replace_line(GOOD, 3, "0 0 1"), 3, "mask"),
    ("too few values", _replace_line(GOOD, 6, "1 101"), 6, "values"),
    ("too many values", _replace_line(GOOD, 8, "2 102 -10 7"), 8, "values"),
    ("value not a number", _replace_line(GOOD, 6, "1 101 x"), 6, "FAP value"),
    ("frame number skips", _replace_line(GOOD, 8, "5 102 -10"), 8, "frame number 2"),
    ("first frame 7", _replace_line(GOOD, 4, "7 100 0"), 4, "first frame"),
    ("frame number text", _replace_line(GOOD, 4, "a 100 0"), 4, "frame number"),
    ("missing last frame", "\n".join(GOOD.splitlines()[:-2]) + "\n", 6, "3 frames"),
]


@pytest.mark.parametrize("label,text,lineno,word", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_line_is_named(label, text, lineno, word):
    with pytest.raises(InputError) as err:
        read_fap(text)
    msg = str(err.value)
    assert re.search(rf"\bline {lineno}\b", msg), msg
    assert word in msg and "expected" in msg


def test_empty_and_missing(tmp_path):
    with pytest.raises(InputError, match="empty"):
        read_fap("# only a comment\n\n")
    with pytest.raises(InputError, match="does not exist"):
        read_fap(tmp_path / "nope.fap")


def test_writer_is_deterministic_and_compact():
    v = np.zeros((2, 68))
    m = np.zeros((2, 68), bool)
    v[1, 2], m[:, 2] = 12.5, True
    s = FapStream("a  b", 30.0, v, m)
    text = write_fap(s)
    assert text == write_fap(s)
    assert text.splitlines()[0] == "2.1 a b 30 2"
    assert text.splitlines()[4] == "1 12.5"
