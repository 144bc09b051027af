"""SAiD coefficient CSV: 32 lower-face ARKit columns, no time column, 60 fps; sniffing that steals no other CSV."""

import importlib

import numpy as np
import pytest

from converter.errors import InputError
from converter.formats.captures import said
from tests.formats.captures.layout_samples import others, read

FIXTURE = "said_coeffs.csv"
# yunik1004/SAiD data/ARKit_blendshapes.txt, typed from the repository
DOCUMENTED = ("jawForward jawLeft jawRight jawOpen mouthClose mouthFunnel mouthPucker mouthLeft mouthRight "
              "mouthSmileLeft mouthSmileRight mouthFrownLeft mouthFrownRight mouthDimpleLeft mouthDimpleRight "
              "mouthStretchLeft mouthStretchRight mouthRollLower mouthRollUpper mouthShrugLower mouthShrugUpper "
              "mouthPressLeft mouthPressRight mouthLowerDownLeft mouthLowerDownRight mouthUpperUpLeft "
              "mouthUpperUpRight cheekPuff cheekSquintLeft cheekSquintRight noseSneerLeft noseSneerRight").split()


def test_fixture():
    data = read(FIXTURE)
    assert said.LAYOUT.sniff(data)
    track = said.LAYOUT.parse(data, FIXTURE)
    assert track.source == "said-csv" and track.names == DOCUMENTED == list(said.SAID_NAMES)
    assert track.n_frames == 6 and track.fps == 60.0 and track.duration == pytest.approx(0.1)
    np.testing.assert_allclose(track.times, np.arange(6) / 60)
    np.testing.assert_allclose(track.values[:, 3], [0, 0.15, 0.3, 0.45, 0.6, 0.75], rtol=1e-6)  # jawOpen
    np.testing.assert_allclose(track.values[:, 6], [0, 0, 0, 0.4, 0.4, 0.4], rtol=1e-6)  # mouthPucker
    assert track.values.dtype == np.float32 and track.head is None


def test_any_subset_of_arkit_names_in_any_order():
    data = b"mouthPucker,jawOpen\r\n0.5,0.25\r\n0.0,1.0\r\n"
    assert said.sniff(data)
    track = said.parse(data, "two.csv")
    assert track.names == ["mouthPucker", "jawOpen"] and track.n_frames == 2
    np.testing.assert_allclose(track.values, [[0.5, 0.25], [0, 1]])


@pytest.mark.parametrize("header", [
    b"Timecode,BlendShapeCount,EyeBlinkLeft,JawOpen",  # Live Link Face
    b"time,jawOpen,mouthPucker",  # a time column: another layout
    b"JawOpen,MouthPucker",  # capitalised: not SAiD's spelling
    b"jawOpen,jawOpen",  # a name twice
    b"jawOpen",  # one column is too little to call it a layout
    b"jawOpen;mouthPucker",
])
def test_sniff_refuses_other_csv(header):
    assert not said.sniff(header + b"\n0.1,0.2\n")


def test_sniff_claims_only_said():
    assert not any(said.sniff(data) for data in others("said-csv").values())


def test_empty_and_header_only():
    with pytest.raises(InputError, match="empty"):
        said.parse(b"", "e.csv")
    with pytest.raises(InputError, match="has a header but no frames"):
        said.parse(b"jawOpen,mouthClose\n", "h.csv")


def test_truncated_row():
    data = read(FIXTURE)
    with pytest.raises(InputError, match=r"row 7 has 20 cells but the header has 32; the file is truncated"):
        said.parse(data[: data.rindex(b"\n", 0, len(data) - 1) + 1] + b"0.0," * 19 + b"0.0", "cut.csv")


def test_wrong_column_count():
    with pytest.raises(InputError, match=r"row 3 has 3 cells but the header has 2"):
        said.parse(b"jawOpen,mouthClose\n0.1,0.2\n0.1,0.2,0.3\n", "cols.csv")


def test_nan_and_text_cells():
    with pytest.raises(InputError, match=r"row 3, column mouthClose is NaN or infinite"):
        said.parse(b"jawOpen,mouthClose\n0.1,0.2\n0.1,nan\n", "nan.csv")
    with pytest.raises(InputError, match=r"row 2, column jawOpen: 'abc' is not a number"):
        said.parse(b"jawOpen,mouthClose\nabc,0.2\n", "text.csv")


def test_header_not_arkit():
    with pytest.raises(InputError, match=r"header cell 'time' is not an ARKit blendshape name"):
        said.parse(b"time,jawOpen\n0,0.1\n", "t.csv")


def test_registered():
    registry = importlib.import_module("converter.formats.captures")
    layouts = getattr(registry, "LAYOUTS", ())
    assert said.LAYOUT in (list(layouts.values()) if isinstance(layouts, dict) else list(layouts))
    assert registry.detect(read(FIXTURE)) == said.LAYOUT
