"""What the capture layouts of this package share: decoding, checked numbers, frame limits and the take's rate.

The rate of a take is measured, never assumed from a timecode's base: the median spacing of its rows' times
(refined, see spacing_rate), snapped to a standard rate when within 1% (a 30 fps take written with 60 fps
timecodes is 30 fps).
"""

from __future__ import annotations

import json
import math

import numpy as np

from converter.errors import InputError
from converter.formats.captures.base import MAX_FRAMES

SNIFF_BYTES = 65536  # what sniff() looks at: the head of the file
# The nominal rates recorders run at. NTSC's 1000/1001 rates are left out on purpose: a phone's camera clock is
# neither (the shared Live Link Face take runs at 59.96 Hz against its timecode) and a take whose rows drift
# off the nominal grid is resampled by the drive step anyway, so the nominal rate is the one to report.
STANDARD_RATES: tuple[float, ...] = (
    10.0, 12.0, 15.0, 20.0, 24.0, 25.0, 30.0, 48.0, 50.0, 60.0, 72.0, 90.0, 100.0, 120.0, 144.0, 240.0,
)
SNAP_TOLERANCE = 0.01  # a measured rate within 1% of a standard one is that rate


def head(data: bytes) -> bytes:
    """The first SNIFF_BYTES of a file without a UTF-8 BOM and leading whitespace: what sniffers test."""
    return data[:SNIFF_BYTES].removeprefix(b"\xef\xbb\xbf").lstrip()


def text(data: bytes, name: str, what: str) -> str:
    """The bytes as UTF-8 text (a BOM dropped); InputError when empty or not text."""
    if not data.strip():
        raise InputError(f"{name} is empty; give the {what} the tool wrote.")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"{name} is not UTF-8 text, so it is not a {what}.") from None


def json_doc(data: bytes, name: str, what: str):
    """The bytes parsed as one JSON document; InputError naming the layout when they are not valid JSON."""
    try:
        return json.loads(text(data, name, what))
    except (json.JSONDecodeError, RecursionError) as exc:
        raise InputError(f"{name} is not valid JSON ({str(exc)[:60]}); the {what} is truncated or edited.") from None


def is_number(value) -> bool:
    """Whether a JSON value is a finite number (bools are not numbers here)."""
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)


def number(value, name: str, what: str, strings: bool = False) -> float:
    """A finite number as float (a numeric string too when strings); InputError naming `what` otherwise."""
    if strings and isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            pass
    if not is_number(value):
        raise InputError(f"{name}: {what} is {str(value)[:30]!r}, not a finite number.")
    return float(value)


def fps_value(value, name: str) -> float:
    """A frame rate a file states: a number in (0, 1000]."""
    fps = number(value, name, "the frame rate")
    if not 0 < fps <= 1000:
        raise InputError(f"{name}: the frame rate {value!r} is not a positive number of frames per second.")
    return fps


def frame_count(n: int, name: str) -> None:
    """InputError when a capture has no frames or more than facesvg takes."""
    if n < 1:
        raise InputError(f"{name} holds no frames.")
    if n > MAX_FRAMES:
        raise InputError(f"{name} has {n} frames, more than {MAX_FRAMES}; trim the capture.")


def is_float(s: object) -> bool:
    """Whether float(s) reads it (a cell, a key): the readers' test before they name a bad value."""
    try:
        float(s)  # type: ignore[arg-type]
        return True
    except (TypeError, ValueError):
        return False


def finite(values: np.ndarray, name: str, what: str) -> np.ndarray:
    """The array when every value is finite; InputError naming the first frame that is not."""
    bad = ~np.isfinite(values)
    if bad.any():
        k = int(np.argwhere(bad)[0][0])
        raise InputError(f"{name}: {what} of frame {k} is NaN or infinite; re-export the take.")
    return values


def increasing(times: np.ndarray, name: str, what: str = "frame times") -> np.ndarray:
    """Times (s) made relative to the first, after checking they are finite and strictly increasing."""
    times = np.asarray(times, np.float64)
    if not np.isfinite(times).all():
        raise InputError(f"{name}: the {what} hold NaN or infinite values.")
    if len(times) > 1 and np.any(np.diff(times) <= 0):
        k = int(np.argmax(np.diff(times) <= 0)) + 1
        raise InputError(f"{name}: frame {k} is not later than frame {k - 1}; the {what} must increase.")
    return times - times[0]


def snap_rate(rate: float) -> float:
    """The standard rate nearest to a measured one when within SNAP_TOLERANCE, else the measured rate."""
    best = min(STANDARD_RATES, key=lambda r: abs(rate - r))
    return best if abs(rate - best) <= SNAP_TOLERANCE * best else float(rate)


def spacing_rate(times: np.ndarray) -> float | None:
    """The rate the rows were recorded at, snapped; None for one row.

    The median spacing of the times, made exact by averaging the spacings within half of it (whole-millisecond
    stamps of a 30 fps take step 33 or 34 ms: the median alone says 30.3 fps); dropped rows' gaps are left out.
    """
    if len(times) < 2:
        return None
    steps = np.diff(times)
    median = float(np.median(steps))
    usual = steps[np.abs(steps - median) <= 0.5 * median]
    return snap_rate(1.0 / float(usual.mean()))
