"""Live Link Face CSV (Epic's iOS app): ARKit weights per row, with the head and eye angles, timed by timecode.

Layout (the take's `<slate>_<take>.csv`, as the app writes it): a header `Timecode, BlendShapeCount`, the 52
ARKit weights with capitalised names (`EyeBlinkLeft` ... `TongueOut`), then `HeadYaw, HeadPitch, HeadRoll,
LeftEyeYaw, LeftEyePitch, LeftEyeRoll, RightEyeYaw, RightEyePitch, RightEyeRoll` (BlendShapeCount is 61: the
61 curves of Unreal's EARFaceBlendShape, in that enum's order). One row per captured frame.

Timing. `Timecode` is HH:MM:SS:FF.mmm: FF counts frames of the timecode's base rate (60 on current phones, the
smallest standard rate above every FF seen), .mmm the sub-frame fraction. The base is not the take's rate: a
take recorded at 30 fps still writes 60 fps timecodes and steps FF by 2 per row (a real 2 min 14 s take has
4,030 rows at 13:13:04:31, :33, :35 ...). So times are the timecodes as written (seconds + (FF + fraction) /
base), and the track's fps is the rate the rows were recorded at: the median spacing of those times, snapped
to a standard rate within 1% (`_util.spacing_rate`). The sub-frame creeps when the camera's clock is not the
timecode's (the shared MySlate_3 take runs at 59.96 Hz: +0.0006 frame per row, 0.2 frame over its 328 rows).

Angles: one unit is 180 degrees (pi radians), signed. Evidence:
- Epic's ARKit face code that makes these 61 curves (AppleARKitConversion.h, ToBlendShapeMap) divides the
  head's and each eye's FRotator yaw/pitch/roll (degrees) by 180: "Map the -180..180 range to -1..1".
- The real takes agree: the eyes' yaw difference (vergence) is a steady 0.063 to 0.072 units in three takes by
  two people (MySlate_3 here, alex_rom_3 and S07-001 of alexdjulin/LiveLinkFace-CSV-Retarget-For-Motionbuilder):
  11 to 13 degrees at pi per unit, i.e. eyes fixating 28 to 31 cm away, where the phone is. Radians (4 degrees,
  fixation ~0.9 m) or pi/2 per unit (6 degrees, ~0.6 m) do not fit a hand-held or head-rig phone.
- Importers disagree, so they are no evidence: polyvox_filament's bone drivers scale by pi/2 and Faceit reads
  the columns as radians; DMLiveLink maps -1..1 onto a calibrated angle range. facesvg's first reader took pi/2.
"""

from __future__ import annotations

import csv
import io
import math
import re

import numpy as np

from converter.errors import InputError
from converter.formats.captures import _util
from converter.formats.captures.base import DEFAULT_FPS, CaptureLayout, WeightTrack

NAME = "livelinkface-csv"
LLF_ANGLE_UNIT = math.pi  # radians per Live Link Face angle unit (-1..1 = -180..180 degrees)
LLF_HEAD = ("HeadYaw", "HeadPitch", "HeadRoll")
LLF_EYES = {side: tuple(f"{side}Eye{a}" for a in ("Yaw", "Pitch", "Roll")) for side in ("Left", "Right")}
TIMECODE = re.compile(r"^\s*(\d+):(\d+):(\d+)[:;.](\d+)(?:\.(\d+))?\s*$")
TIMECODE_BASES = (24, 25, 30, 48, 50, 60, 120, 240)
WHAT = "Live Link Face CSV"


def sniff(data: bytes) -> bool:
    """A CSV whose header starts with the Timecode column (BlendShapeCount is checked when parsing)."""
    first = _util.head(data).split(b"\n", 1)[0]
    return first.startswith(b"Timecode,") or first.startswith(b'"Timecode",')


def parse(data: bytes, name: str) -> WeightTrack:
    """Live Link Face's CSV: times and rate from the timecodes; 52 weights; head and eye angles in radians."""
    rows = [r for r in csv.reader(io.StringIO(_util.text(data, name, WHAT))) if any(c.strip() for c in r)]
    if not rows:
        raise InputError(f"{name} is empty; give the {WHAT} the app exports.")
    header = [c.strip() for c in rows[0]]
    if "Timecode" not in header or "BlendShapeCount" not in header:
        missing = " and ".join(c for c in ("Timecode", "BlendShapeCount") if c not in header)
        raise InputError(f"{name} is not a Live Link Face CSV (no {missing} column); give the CSV the app exports.")
    body = rows[1:]
    if not body:
        raise InputError(f"{name} has a header but no frames.")
    _util.frame_count(len(body), name)
    for k, r in enumerate(body):
        if len(r) != len(header):
            raise InputError(f"{name} row {k + 2} has {len(r)} cells but the header has {len(header)}; "
                             "the file is truncated or edited.")
    tc_col = header.index("Timecode")
    angle_cols = set(LLF_HEAD) | set(LLF_EYES["Left"]) | set(LLF_EYES["Right"])
    weight_cols = [i for i, c in enumerate(header) if c not in ("Timecode", "BlendShapeCount") and c not in angle_cols]
    if not weight_cols:
        raise InputError(f"{name} has no blendshape weight columns.")
    numeric = [i for i in range(len(header)) if i != tc_col]
    table = np.empty((len(body), len(header)), np.float64)
    for i in numeric:
        try:
            table[:, i] = [float(r[i]) for r in body]
        except ValueError:
            bad = next(k for k, r in enumerate(body) if not _util.is_float(r[i]))
            raise InputError(
                f"{name} row {bad + 2}, column {header[i]}: {body[bad][i][:30]!r} is not a number."
            ) from None
    if not np.isfinite(table[:, numeric]).all():
        k, j = np.argwhere(~np.isfinite(table[:, numeric]))[0]
        raise InputError(f"{name} row {k + 2}, column {header[numeric[j]]} is NaN or infinite; re-export the take.")
    times, base = timecode_times([r[tc_col] for r in body], name)
    fps = _util.spacing_rate(times) or float(base)

    def angles(cols: tuple[str, ...]) -> np.ndarray | None:
        if not all(c in header for c in cols):
            return None
        return (table[:, [header.index(c) for c in cols]] * LLF_ANGLE_UNIT).astype(np.float32)

    return WeightTrack([header[i] for i in weight_cols], times, table[:, weight_cols].astype(np.float32), fps,
                       body[0][tc_col].strip(), angles(LLF_HEAD), angles(LLF_EYES["Left"]), angles(LLF_EYES["Right"]),
                       NAME)


def timecode_times(cells: list[str], name: str) -> tuple[np.ndarray, int]:
    """Seconds from the first row of HH:MM:SS:FF[.fff] cells, and the timecode's base rate.

    The base is the smallest standard rate above every FF (a take shorter than a second is taken at the app's
    60); a row's time is its whole seconds plus (FF + fraction) / base.
    """
    parsed = np.empty((len(cells), 2), np.float64)
    for k, c in enumerate(cells):
        m = TIMECODE.match(c)
        if not m:
            raise InputError(f"{name} row {k + 2}: timecode {c[:30]!r} is not HH:MM:SS:FF.mmm.")
        h, mi, s, f = (int(m.group(i)) for i in range(1, 5))
        parsed[k] = (h * 3600 + mi * 60 + s, f + (float("0." + m.group(5)) if m.group(5) else 0.0))
    max_ff = int(parsed[:, 1].max())
    floor = max_ff + 1 if np.ptp(parsed[:, 0]) > 0 else max(max_ff + 1, int(DEFAULT_FPS))
    base = next((r for r in TIMECODE_BASES if r >= floor), floor)
    t = parsed[:, 0] + parsed[:, 1] / base
    if len(t) > 1 and np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0))
        raise InputError(f"{name} row {k + 3}: the timecode does not increase ({cells[k + 1].strip()} after "
                         f"{cells[k].strip()}); the take is edited or spans midnight.")
    return t - t[0], base



LAYOUT = CaptureLayout(
    NAME, "Live Link Face CSV", (".csv",), sniff, parse,
    "Epic Games' Live Link Face app (iOS): the take's CSV (Timecode, BlendShapeCount, 52 ARKit weights, 9 angles)",
)
