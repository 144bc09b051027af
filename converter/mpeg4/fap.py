"""MPEG-4 .fap text streams: FapStream, a strict reader for every variant seen in the wild, and a writer.

Format (one header, then a mask line and a value line per frame):
    # comment lines anywhere
    2.1 <name, may contain spaces> <fps> <number of frames>
    <68 (or 69) mask values 0/1 for FAP 1..68>
    <frame number> <one value per set mask bit, in FAP order; FAP 1 may carry 4 values, FAP 2 six>
Version 2.0 or 2.1, frames numbered from 0 or 1, spaces or tabs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from converter.errors import InputError
from converter.mpeg4.standard import N_FAPS
from converter.userfiles import read_bytes

VERSIONS = ("2.0", "2.1")
FAP1_VALUES = 4  # viseme_select1, viseme_select2, viseme_blend, viseme_def
FAP2_VALUES = 6  # expression_select1, intensity1, expression_select2, intensity2, init_face, expression_def


@dataclass(eq=False)
class FapStream:
    """A FAP animation: values (T, 68) in FAPU units (0 where not set), mask (T, 68), fps and name.

    extra holds what the values array cannot: "version", "first_frame" (0 or 1), "mask_width" (68/69),
    "loa" (level of articulation, from a "# loa: <level>" comment),
    and "fap1"/"fap2": {frame index: tuple of the several values} when a writer gave FAP 1-2 several values.
    """

    name: str
    fps: float
    values: np.ndarray
    mask: np.ndarray
    extra: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.values = np.asarray(self.values, dtype=np.float64).reshape(-1, N_FAPS)
        self.mask = np.asarray(self.mask, dtype=bool).reshape(-1, N_FAPS)
        if self.values.shape != self.mask.shape:
            raise InputError("FAP values and mask have different shapes; give one mask row per frame.")

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.values.shape[0])

    def low_level(self) -> np.ndarray:
        """Values with unset FAPs and FAP 1-2 zeroed: what the deformation engine consumes, (T, 68)."""
        v = np.where(self.mask, self.values, 0.0)
        v[:, :2] = 0.0
        return v


def _number(tok: str, lineno: int, what: str) -> float:
    try:
        x = float(tok)
    except ValueError:
        raise InputError(f"FAP line {lineno}: expected {what}, got {tok[:20]!r}.") from None
    if not np.isfinite(x):
        raise InputError(f"FAP line {lineno}: expected {what}, got {tok[:20]!r}.")
    return x


def _integer(tok: str, lineno: int, what: str) -> int:
    try:
        return int(tok)
    except ValueError:
        raise InputError(f"FAP line {lineno}: expected {what} (an integer), got {tok[:20]!r}.") from None


def read_fap(source: str | Path) -> FapStream:
    """Parse a .fap file (a path, or the text itself when it contains a newline); InputError names the line."""
    if isinstance(source, Path) or ("\n" not in source and len(source) < 4096):
        path = Path(source)
        raw = read_bytes(path, "FAP file")
        text = raw.decode("utf-8", errors="replace")
    else:
        text = source
    lines = [(n, ln.split()) for n, ln in enumerate(text.splitlines(), 1)]
    loa = next((toks[2] for _, toks in lines if len(toks) == 3 and toks[:2] == ["#", "loa:"]), None)
    lines = [(n, toks) for n, toks in lines if toks and not toks[0].startswith("#")]
    if not lines:
        raise InputError("the FAP file is empty; expected a header line like '2.1 name 25 100'.")

    n, head = lines[0]
    if head[0] not in VERSIONS:
        raise InputError(f"FAP line {n}: expected a header starting with version 2.0 or 2.1, got {head[0][:20]!r}.")
    if len(head) < 3:
        raise InputError(f"FAP line {n}: expected a header 'version name fps frames', got {len(head)} fields.")
    fps = _number(head[-2], n, "the frame rate")
    if not 0 < fps <= 1000:
        raise InputError(f"FAP line {n}: expected a frame rate between 0 and 1000, got {head[-2]}.")
    n_frames = _integer(head[-1], n, "the number of frames")
    if n_frames < 1:
        raise InputError(f"FAP line {n}: expected at least one frame, got {n_frames}.")
    name = " ".join(head[1:-2])
    body = lines[1:]
    if len(body) != 2 * n_frames:
        last = body[-1][0] if body else n
        raise InputError(
            f"FAP line {last}: expected {n_frames} frames (a mask line and a value line each) as the header says, "
            f"found {len(body)} data lines."
        )

    values = np.zeros((n_frames, N_FAPS))
    mask = np.zeros((n_frames, N_FAPS), bool)
    fap1: dict[int, tuple] = {}
    fap2: dict[int, tuple] = {}
    mask_width = None
    first_frame = None
    for t in range(n_frames):
        (mn, mtoks), (vn, vtoks) = body[2 * t], body[2 * t + 1]
        if len(mtoks) not in (N_FAPS, N_FAPS + 1) or any(tok not in ("0", "1") for tok in mtoks):
            bad = next((tok for tok in mtoks if tok not in ("0", "1")), None)
            got = f"{bad[:20]!r}" if bad is not None else f"{len(mtoks)} values"
            raise InputError(f"FAP line {mn}: expected a mask of 68 or 69 values 0/1, got {got}.")
        mask_width = mask_width or len(mtoks)
        bits = np.array([tok == "1" for tok in mtoks[:N_FAPS]])
        frame_no = _integer(vtoks[0], vn, "a frame number")
        if first_frame is None:
            if frame_no not in (0, 1):
                raise InputError(f"FAP line {vn}: expected the first frame number to be 0 or 1, got {frame_no}.")
            first_frame = frame_no
        if frame_no != first_frame + t:
            raise InputError(f"FAP line {vn}: expected frame number {first_frame + t}, got {frame_no}.")
        nums = [_number(tok, vn, "a FAP value") for tok in vtoks[1:]]
        low = int(bits[2:].sum())
        extra_n = len(nums) - low
        options = [
            (a, b) for a in ((1, FAP1_VALUES) if bits[0] else (0,)) for b in ((1, FAP2_VALUES) if bits[1] else (0,))
        ]
        fit = [(a, b) for a, b in options if a + b == extra_n]
        if not fit:
            want = " or ".join(str(low + a + b) for a, b in options)
            raise InputError(f"FAP line {vn}: expected {want} values after the frame number for the mask on line {mn}, "
                             f"got {len(nums)}.")
        a, b = fit[0]
        if a:
            values[t, 0] = nums[0]
            if a > 1:
                fap1[t] = tuple(nums[:a])
        if b:
            values[t, 1] = nums[a]
            if b > 1:
                fap2[t] = tuple(nums[a:a + b])
        values[t, np.flatnonzero(bits[2:]) + 2] = nums[a + b:]
        mask[t] = bits
    extra = {"version": head[0], "first_frame": first_frame, "mask_width": mask_width}
    if fap1:
        extra["fap1"] = fap1
    if fap2:
        extra["fap2"] = fap2
    if loa:
        extra["loa"] = loa
    return FapStream(name, fps, values, mask, extra)


def _fmt(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else repr(float(x))


def write_fap(stream: FapStream) -> str:
    """The stream as .fap text (same version, naming and frame numbering as it was read with)."""
    version = stream.extra.get("version", "2.1")
    first = int(stream.extra.get("first_frame", 0))
    width = int(stream.extra.get("mask_width", N_FAPS))
    fap1, fap2 = stream.extra.get("fap1", {}), stream.extra.get("fap2", {})
    name = " ".join(stream.name.split()) or "fap"
    out = [f"# loa: {stream.extra['loa']}"] if stream.extra.get("loa") else []
    out.append(f"{version} {name} {_fmt(stream.fps)} {stream.n_frames}")
    for t in range(stream.n_frames):
        bits = stream.mask[t]
        out.append(" ".join("1" if b else "0" for b in bits) + (" 0" if width > N_FAPS else ""))
        nums: list[float] = []
        if bits[0]:
            nums += list(fap1.get(t, (stream.values[t, 0],)))
        if bits[1]:
            nums += list(fap2.get(t, (stream.values[t, 1],)))
        nums += list(stream.values[t, np.flatnonzero(bits[2:]) + 2])
        out.append(" ".join([str(first + t)] + [_fmt(x) for x in nums]))
    return "\n".join(out) + "\n"
