"""The verifier: evaluate an animated SVG's SMIL at every frame time and compare with the exact projection.

A player file (``--to player``, recognised by content) is decoded by converter.writers.player instead and
compared the same way, and a Lottie file (``--to lottie``, ``--to dotlottie``) by converter.writers.lottie.

It reads the SVG with lxml, takes the camera, frame rate and options from ``<metadata id="facesvg">``,
re-loads the input (converter.formats.load plus the same 3D stages: frame range, triangle budget, ...),
projects every frame with the metadata camera and measures, for every vertex of every path drawn at frame k
(t = k / fps), its distance in output pixels from the exact projection, and for every triangle in the file
the frames where it is drawn although culled or hidden although visible.

A triangle collapsed to one point (the bounded encoding's way to hide it) counts as hidden, unless the exact
triangle is visible and lies within the tolerance of that point (a triangle below the tolerance may be keyed
to a point; it is then measured like any drawn one).
SMIL support: <animate> of ``d``, ``class``, ``visibility`` and ``display`` with values, keyTimes (or even
spacing), calcMode linear or discrete, dur, repeatCount; a static ``transform`` on the path and its ancestors and
<animateTransform> (translate, scale, rotate, matrix-free forms) on ancestor groups; viewBox scaling.
"""

from __future__ import annotations

import gzip
import json
import math
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numba
import numpy as np
from lxml import etree

from converter.arrays import lengths
from converter.camera import Camera
from converter.convert import load, prepare
from converter.encode.groups import apply_linear
from converter.errors import InputError
from converter.extract import cull
from converter.options import ConversionOptions, Report
from converter.writers import lottie, player

SVG_NS = "{http://www.w3.org/2000/svg}"
NO_PATHS = "the SVG has no triangle paths (id f<number>); only facesvg output can be verified."
BLOCK_BYTES = 1 << 25  # paths measured at once: about this many bytes of their (T, n, 3, 2) float64 positions
FRAME_BLOCK = 256  # frames projected at once
_TOKEN = re.compile(r"[MmLlZzHhVv]|[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_VALUE_TOKEN = re.compile(";|" + _TOKEN.pattern)  # an animate's values: their tokens and where each value ends
_SEMI, _M, _L, _H, _V, _Z = (ord(c) for c in ";MLHVZ")
_CODES = frozenset(";MmLlHhVvZz")
_POW10 = np.array([float(10 ** k) for k in range(16)])  # exact doubles
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


@dataclass
class Verification:
    """What the verifier measured."""

    max_px: float
    mean_px: float
    vertex_frames: int  # drawn vertex-frames measured
    visibility_mismatches: int  # (triangle, frame) pairs drawn/hidden wrongly
    mismatch_frames: int  # frames with at least one visibility mismatch
    tolerance: float
    frames: int
    paths: int  # triangles drawn (a merged path draws several)
    triangles: int
    dropped_visible: int  # front-facing triangles absent from the file (never seen: occlusion pass)
    worst: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """Within the stated tolerance and no visibility mismatch."""
        return self.max_px <= self.tolerance and self.visibility_mismatches == 0

    def summary(self) -> str:
        """One line for the CLI."""
        return (f"max {self.max_px:.4f} px, mean {self.mean_px:.4f} px over {self.vertex_frames} drawn vertex-frames "
                f"({self.paths} triangles, {self.frames} frames); visibility mismatches {self.visibility_mismatches} "
                f"in {self.mismatch_frames} frames; tolerance {self.tolerance:g} px: {'OK' if self.ok else 'FAIL'}")


@dataclass
class Evaluated:
    """The SVG evaluated at every frame: per path the triangle, vertex positions (T, 3, 2) px and shown (T,)."""

    meta: dict
    triangles: np.ndarray  # int (P,)
    xy: np.ndarray  # float64 (T, P, 3, 2) in viewport pixels
    shown: np.ndarray  # bool (T, P)
    collapsed: np.ndarray | None = None  # bool (T, P): hidden by being a point (else by class/display/visibility)


def read_svg(data: bytes) -> etree._Element:
    """Parse SVG or SVGZ bytes; InputError when it is not XML."""
    if data[:2] == b"\x1f\x8b":
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError):
            raise InputError("the .svgz file is not valid gzip; regenerate it.") from None
    parser = etree.XMLParser(resolve_entities=False, huge_tree=True, no_network=True)
    try:
        return etree.fromstring(data, parser)
    except etree.XMLSyntaxError as exc:
        raise InputError(f"the SVG is not well-formed XML ({exc}); regenerate it.") from None


def metadata_of(root: etree._Element) -> dict:
    """The facesvg metadata JSON of a parsed SVG."""
    node = root.find(f".//{SVG_NS}metadata[@id='facesvg']")
    if node is None or not (node.text or "").strip():
        raise InputError("the SVG has no <metadata id=\"facesvg\">; only facesvg output can be verified.")
    try:
        return json.loads(node.text)
    except json.JSONDecodeError:
        raise InputError("the facesvg metadata is not valid JSON; the file is corrupt.") from None


def _seconds(text: str | None) -> float:
    if not text:
        raise InputError("an <animate> has no dur; the file is corrupt.")
    text = text.strip()
    try:
        if text.endswith("ms"):
            return float(text[:-2]) / 1000
        if text.endswith("s"):
            return float(text[:-1])
        if text.endswith("min"):
            return float(text[:-3]) * 60
        return float(text)
    except ValueError:
        raise InputError(f"dur {text!r} is not a clock value; the file is corrupt.") from None


def _phase(anim: etree._Element, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Simple-duration fraction u (T,) of an animation at document times, and whether it is active."""
    if anim.get("begin", "0").strip() not in ("0", "0s"):
        raise InputError("only animations that begin at 0 can be verified.")
    dur = _seconds(anim.get("dur"))
    rc = anim.get("repeatCount")
    total = math.inf if rc == "indefinite" or anim.get("repeatDur") == "indefinite" else dur * float(rc or 1)
    u = np.mod(times, dur) / dur
    done = times >= total
    if anim.get("fill") == "freeze":
        u = np.where(done, 1.0, u)
        return u, np.ones_like(done)
    return u, ~done


def _key_index(anim: etree._Element, n: int, u: np.ndarray, discrete: bool) -> tuple[np.ndarray, np.ndarray]:
    """Segment index (T,) and fraction (T,) of u among the values' key times."""
    kt_text = anim.get("keyTimes")
    if kt_text:
        kt = np.array([float(x) for x in kt_text.split(";")])
        if len(kt) != n:
            raise InputError("keyTimes and values differ in length; the file is corrupt.")
    elif discrete:
        kt = np.arange(n) / n
    else:
        kt = np.linspace(0.0, 1.0, n) if n > 1 else np.zeros(1)
    i = np.clip(np.searchsorted(kt, u, side="right") - 1, 0, n - 1)
    if discrete or n == 1:
        return i, np.zeros_like(u)
    i = np.minimum(i, n - 2)
    span = kt[i + 1] - kt[i]
    frac = np.clip((u - kt[i]) / np.where(span > 0, span, 1), 0, 1)
    return i, frac


def _triangles_of_d(d: str) -> list[float]:
    """The first three absolute vertices of each subpath of a path made of M/L/H/V/Z commands (relative or
    absolute), flattened: 6 numbers per triangle (a merged path holds several, converter.encode.merge)."""
    return _d_rows(d, values=False)[0].tolist()


def _d_rows(text: str, values: bool = True) -> np.ndarray:
    """(K, 6 n): _triangles_of_d of each value of an animate's values (split at ';', blank ones left out), or with
    values False of text as one path's d. A compiled scanner finds the tokens as _TOKEN does and reads the numbers
    (those float() would not read to the same bits by a division are read by float()), and a compiled loop reads
    the paths: per value in Python, with the regular expression, they were most of the verifier's time."""
    blank = np.array([not v.strip() for v in text.split(";")]) if values else np.zeros(1, bool)
    if text.isascii():
        raw = np.frombuffer(text.encode("ascii"), np.uint8)
        code, nums, spans = np.empty(len(raw), np.int64), np.empty(len(raw)), np.empty((len(raw), 3), np.int64)
        n, slow = _tokens(raw, values, code, nums, spans)
        code, nums = code[:n], nums[:n]
        for at, a, b in spans[:slow].tolist():  # an exponent, or more digits than a double holds exactly
            nums[at] = float(raw[a:b].tobytes())
    else:  # _TOKEN's \d also takes other scripts' digits, which float() reads too
        tokens = (_VALUE_TOKEN if values else _TOKEN).findall(text)
        code = np.array([ord(t) if t in _CODES else 0 for t in tokens], np.int64)
        nums = np.array([0.0 if t in _CODES else float(t) for t in tokens])
        n = len(tokens)
    out = np.empty(2 * n)  # a triangle is 3 points of one number at least each (H, V): 6 numbers from 3 tokens
    ends = np.zeros(len(blank), np.int64)
    err = np.zeros(2, np.int64)
    _read_paths(code, nums, blank, out, ends, err)
    if err[0] == 1:
        raise InputError("a path has fewer than 3 vertices; the file is corrupt.")
    if err[0] == 2:
        cmd = chr(err[1]) if err[1] else ""
        raise InputError(f"path command {cmd!r} is not a triangle; only M/L/H/V/Z paths can be verified.")
    widths = np.diff(ends, prepend=0)[~blank]
    if len(widths) == 0:
        return np.zeros((0, 0))
    if (widths != widths[0]).any():
        raise InputError("the values of a d animation hold different numbers of triangles; the file is corrupt.")
    return out[:ends[-1]].reshape(len(widths), widths[0])


@numba.njit(cache=True, nogil=True)
def _tokens(raw, values, code, nums, spans):  # pragma: no cover - compiled
    """_TOKEN's matches in the bytes raw, left to right (and each ';' when values): per token its code (the
    command's or ';''s character, 0 for a number) and number. A number of at most 15 digits and no exponent is
    its digits over a power of ten (both exact, so one correctly rounded division: float()'s bits); the others
    are listed in spans (token, start, end) for float(). Returns (tokens, slow numbers)."""
    n, slow, i, size = 0, 0, 0, len(raw)
    while i < size:
        c = raw[i]
        if c == 77 or c == 109 or c == 76 or c == 108 or c == 90 or c == 122 or c == 72 or c == 104 \
                or c == 86 or c == 118 or (values and c == 59):  # MmLlZzHhVv ;
            code[n] = c
            n += 1
            i += 1
            continue
        j = i + 1 if c == 43 or c == 45 else i  # a sign
        digits, frac, mant = 0, 0, 0
        while j < size and 48 <= raw[j] <= 57:
            mant = mant * 10 + (raw[j] - 48) if digits < 18 else mant
            digits += 1
            j += 1
        if j < size and raw[j] == 46 and (digits or (j + 1 < size and 48 <= raw[j + 1] <= 57)):  # '.'
            j += 1
            while j < size and 48 <= raw[j] <= 57:
                mant = mant * 10 + (raw[j] - 48) if digits < 18 else mant
                digits += 1
                frac += 1
                j += 1
        if digits == 0:  # no number here: the character is skipped
            i += 1
            continue
        exp = False
        if j < size and (raw[j] == 101 or raw[j] == 69):  # an exponent only with a digit after its sign
            k = j + 1 + (1 if j + 1 < size and (raw[j + 1] == 43 or raw[j + 1] == 45) else 0)
            if k < size and 48 <= raw[k] <= 57:
                exp = True
                j = k
                while j < size and 48 <= raw[j] <= 57:
                    j += 1
        code[n] = 0
        if exp or digits > 15:
            spans[slow, 0], spans[slow, 1], spans[slow, 2] = n, i, j
            slow += 1
            nums[n] = 0.0
        else:
            v = np.float64(mant) / _POW10[frac]
            nums[n] = -v if c == 45 else v
        n += 1
        i = j
    return n, slow


@numba.njit(cache=True, nogil=True, inline="always")
def _close(out, m, px, py, npts) -> int:  # pragma: no cover - compiled
    """A subpath's first triangle (px, py: its first 3 of npts vertices) into out at m: the next m (m itself for
    an empty subpath), -1 for one of fewer than 3 vertices. (out holds 2 numbers a token: a triangle is 3 points of
    one number at least each, H or V.)"""
    if npts == 0:
        return m
    if npts < 3:
        return -1
    for k in range(3):
        out[m + 2 * k], out[m + 2 * k + 1] = px[k], py[k]
    return m + 6


@numba.njit(cache=True, nogil=True)
def _read_paths(code, nums, blank, out, ends, err) -> None:  # pragma: no cover - compiled
    """_d_rows' loop over the tokens (code: a command's or ';''s character, 0 for a number nums[i]): the
    triangles of value v into out, ending at ends[v]; err (kind, character) at the first error (1: fewer than 3
    vertices, 2: not an M/L/H/V command), as _triangles_of_d raised them value by value."""
    i, m, n = 0, 0, len(code)
    px = np.empty(3)
    py = np.empty(3)
    for v in range(len(blank)):
        begin = m
        cmd, have, first_num = 0, 0, 0.0  # the command, numbers of its pair read (0 or 1), the first of them
        x = y = sx = sy = 0.0
        npts = 0
        while i < n and code[i] != _SEMI:
            c = code[i]
            i += 1
            closing = False
            if c != 0:
                cmd, have = c, 0
                closing = c == _Z or c == _Z + 32
            else:
                up = cmd - 32 if cmd >= 97 else cmd
                rel = cmd >= 97
                if up == _M or up == _L:
                    if have == 0:
                        first_num, have = nums[i - 1], 1
                        continue
                    have = 0
                    if up == _M:  # a moveto closes the subpath before it
                        m, npts = _close(out, m, px, py, npts), 0
                        if m < 0:
                            err[0] = 1
                            return
                    if rel:
                        x, y = x + first_num, y + nums[i - 1]
                    else:
                        x, y = first_num, nums[i - 1]
                    if up == _M:
                        sx, sy = x, y
                        cmd = _L + 32 if rel else _L  # further pairs after M are implicit linetos
                elif up == _H or up == _V:
                    if up == _H:
                        x = x + nums[i - 1] if rel else nums[i - 1]
                    else:
                        y = y + nums[i - 1] if rel else nums[i - 1]
                else:
                    err[0], err[1] = 2, cmd
                    return
                if npts < 3:
                    px[npts], py[npts] = x, y
                npts += 1
                continue
            if closing:
                m, npts = _close(out, m, px, py, npts), 0
                if m < 0:
                    err[0] = 1
                    return
                x, y = sx, sy  # after a closepath the current point is the subpath's start
        i += 1  # past the ';'
        if not blank[v]:
            m = _close(out, m, px, py, npts)
            if m <= begin:  # fewer than 3 vertices in the last subpath, or no triangle at all
                err[0] = 1
                return
        ends[v] = m


def _hidden_classes(root: etree._Element) -> set[str]:
    names: set[str] = set()
    for style in root.iter(f"{SVG_NS}style"):
        for m in re.finditer(r"\.([\w-]+)\s*\{([^}]*)\}", style.text or ""):
            body = m.group(2).replace(" ", "")
            if "visibility:hidden" in body or "display:none" in body:
                names.add(m.group(1))
    return names


def _hidden_value(attr: str, value: str, hidden_classes: set[str]) -> bool:
    if attr == "class":
        return bool(set(value.split()) & hidden_classes)
    if attr == "visibility":
        return value.strip() in ("hidden", "collapse")
    return value.strip() == "none"  # display


def _shown(el: etree._Element, times: np.ndarray, hidden_classes: set[str]) -> np.ndarray:
    """Bool (T,): the element is not hidden by its class, visibility or display (static or animated)."""
    hidden = np.zeros(len(times), bool)
    for attr in ("class", "visibility", "display"):
        base = _hidden_value(attr, el.get(attr, ""), hidden_classes)
        state = np.full(len(times), base)
        for anim in el.findall(f"{SVG_NS}animate[@attributeName='{attr}']"):
            values = anim.get("values", "").split(";")
            u, on = _phase(anim, times)
            i, _ = _key_index(anim, len(values), u, discrete=True)  # strings never interpolate
            flags = np.array([_hidden_value(attr, v, hidden_classes) for v in values])
            state = np.where(on, flags[i], state)
        hidden |= state
    return ~hidden


def _path_xy(el: etree._Element, times: np.ndarray) -> np.ndarray:
    """(T, 6 n) vertex coordinates of a path's d of n triangles, animated or not, in user units."""
    base = el.get("d")
    if base:
        out = np.tile(np.array(_triangles_of_d(base), np.float64), (len(times), 1))
    else:
        out = np.full((len(times), 6), np.nan)
    for anim in el.findall(f"{SVG_NS}animate[@attributeName='d']"):
        mode = anim.get("calcMode", "linear")
        if mode not in ("linear", "discrete"):
            raise InputError(f"calcMode {mode!r} on d cannot be verified; use linear or discrete.")
        values = _d_rows(anim.get("values", ""))
        if len(values) == 0:
            raise InputError("an <animate> of d has no values; the file is corrupt.")
        if values.shape[1] != out.shape[1]:
            raise InputError("the values of a d animation hold different numbers of triangles; the file is corrupt.")
        u, on = _phase(anim, times)
        i, frac = _key_index(anim, len(values), u, discrete=mode == "discrete")
        j = np.minimum(i + 1, len(values) - 1)
        val = values[i] + frac[:, None] * (values[j] - values[i])
        out = np.where(on[:, None], val, out)
    return out


def _parse_transform(text: str) -> np.ndarray:
    """A 3x3 matrix for an SVG transform list."""
    m = np.eye(3)
    for name, args in re.findall(r"(\w+)\s*\(([^)]*)\)", text or ""):
        a = [float(x) for x in _NUMBER.findall(args)]
        m = m @ _transform_matrix(name, a)
    return m


def _transform_matrix(name: str, a: list[float]) -> np.ndarray:
    """The 3x3 matrix of one SVG transform function name(a...)."""
    if name == "rotate" and len(a) == 3:  # about the point (a[1], a[2])
        return (_transform_matrix("translate", a[1:]) @ _transform_matrix("rotate", a[:1])
                @ _transform_matrix("translate", [-a[1], -a[2]]))
    return _transform_stack(name, np.array([a], np.float64).reshape(1, len(a)))[0]


def _transform_stack(kind: str, rows: np.ndarray) -> np.ndarray:
    """The matrices (T, 3, 3) of the transform function kind with the arguments of each row of rows (T, w): an
    animateTransform's values a frame each, built as arrays (a matrix a frame in Python was most of the verifier's
    time on a long capture's groups), the angles through math's functions."""
    t, w = rows.shape
    known = {"matrix": 6, "translate": 0, "scale": 0, "rotate": 0, "skewX": 0, "skewY": 0}  # kind: width it needs
    if kind not in known or w == 0 or known[kind] not in (0, w):
        raise InputError(f"transform {kind}({rows[0].tolist() if t else []}) cannot be verified.")
    if kind == "rotate" and w == 3:
        return np.stack([_transform_matrix(kind, row) for row in rows.tolist()])
    out = np.zeros((t, 3, 3))
    out[:, 0, 0] = out[:, 1, 1] = out[:, 2, 2] = 1.0
    if kind == "matrix":
        out[:, 0, :], out[:, 1, :] = rows[:, [0, 2, 4]], rows[:, [1, 3, 5]]
    elif kind == "translate":
        out[:, 0, 2] = rows[:, 0]
        if w > 1:
            out[:, 1, 2] = rows[:, 1]
    elif kind == "scale":
        out[:, 0, 0], out[:, 1, 1] = rows[:, 0], rows[:, 1 if w > 1 else 0]
    elif kind == "rotate":
        r = [math.radians(a) for a in rows[:, 0].tolist()]
        c, sn = np.array([math.cos(a) for a in r]), np.array([math.sin(a) for a in r])
        out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = c, -sn, sn, c
    else:
        tan = np.array([math.tan(math.radians(a)) for a in rows[:, 0].tolist()])
        out[:, (0, 1)[kind == "skewY"], (1, 0)[kind == "skewY"]] = tan
    return out


def _group_matrices(g: etree._Element, times: np.ndarray) -> np.ndarray:
    """(T, 3, 3) transform of one element: static transform, then animateTransform (replace or sum)."""
    base = _parse_transform(g.get("transform", ""))
    out = np.broadcast_to(base, (len(times), 3, 3)).copy()
    anims = g.findall(f"{SVG_NS}animateTransform")
    if not anims:
        return out
    acc = None
    for anim in anims:
        kind = anim.get("type", "translate")
        values = [[float(x) for x in _NUMBER.findall(v)] for v in anim.get("values", "").split(";") if v.strip()]
        mode = anim.get("calcMode", "linear")
        u, on = _phase(anim, times)
        i, frac = _key_index(anim, len(values), u, discrete=mode == "discrete")
        width = max(len(v) for v in values)
        vals = np.array([v + [0.0] * (width - len(v)) if kind != "scale" or len(v) > 1 else v * 2 for v in values])
        j = np.minimum(i + 1, len(values) - 1)
        cur = vals[i] + frac[:, None] * (vals[j] - vals[i])
        mats = _transform_stack(kind, cur)
        mats = np.where(on[:, None, None], mats, np.eye(3))
        if anim.get("additive") == "sum" and acc is not None:
            acc = acc @ mats
        elif anim.get("additive") == "sum":
            acc = out @ mats
        else:
            acc = mats
    return acc


def evaluate(data: bytes) -> Evaluated:
    """Evaluate every triangle path of a facesvg SVG (or player file) at the frame times k / fps."""
    if player.is_player(data):  # the player's block decoded by its own reader
        d = player.decode(data)
        return Evaluated(d.meta, d.triangles, d.path_xy(), d.shown)
    if lottie.is_lottie(data):  # Lottie JSON or a dotLottie zip, evaluated by its writer's reader
        d = lottie.decode(data)
        return Evaluated(d.meta, d.triangles, d.xy, d.shown, d.collapsed)
    root = read_svg(data)
    meta = metadata_of(root)
    parts = list(_svg_paths(root, meta, _svg_times(meta)))
    if not parts:
        raise InputError(NO_PATHS)
    return Evaluated(meta, *_joined(parts))


def _svg_times(meta: dict) -> np.ndarray:
    """The frame times k / fps (s) of a facesvg SVG's metadata."""
    try:
        n_frames, fps = int(meta["frames"]), float(meta["fps"])
        _width, _height = meta["viewport"]
    except (KeyError, TypeError, ValueError):
        raise InputError("the facesvg metadata lacks frames, fps or viewport; the file is corrupt.") from None
    return np.arange(n_frames) / fps


def _svg_paths(root: etree._Element, meta: dict,
               times: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Per triangle path of a parsed facesvg SVG, in document order: its triangle ids (n,), their positions
    (T, n, 3, 2) in viewport px at times, and where each is shown and where collapsed to a point (T, n)."""
    width, height = meta["viewport"]
    vb = [float(x) for x in _NUMBER.findall(root.get("viewBox", f"0 0 {width} {height}"))]
    sx, sy = width / vb[2], height / vb[3]
    view = np.array([[sx, 0, -vb[0] * sx], [0, sy, -vb[1] * sy], [0, 0, 1]])
    hidden_classes = _hidden_classes(root)
    group_cache: dict[etree._Element, tuple[np.ndarray, np.ndarray]] = {}  # keyed by element: id() of a freed
    # lxml proxy is reused by the next one, which handed nested groups another group's transform
    chains: dict[etree._Element | None, tuple[np.ndarray, np.ndarray]] = {}  # by a path's nearest group: the
    # view's map times its groups' maps, and where they are all shown
    listed = [int(i) for i in meta.get("triangle_order", [])]
    at = 0  # a path of n triangles draws the next n of the metadata's triangle_order
    for el in root.iter(f"{SVG_NS}path"):
        m = re.fullmatch(r"f(\d+)[a-z]?", el.get("id", ""))
        if not m:
            continue
        flat = _path_xy(el, times)
        n = flat.shape[1] // 6
        if n > 1 and (listed[at:at + 1] != [int(m.group(1))] or len(listed) < at + n):
            raise InputError(f"path {el.get('id')} holds {n} triangles the metadata's triangle_order does not "
                             "list; the file is corrupt.")
        ids = listed[at:at + n] if n > 1 else [int(m.group(1))]
        at += n
        xy = flat.reshape(len(times), n, 3, 2)
        point = (xy == xy[:, :, :1]).all(axis=(2, 3))  # (T, n)
        nearest = next(el.iterancestors(f"{SVG_NS}g"), None)
        if nearest not in chains:  # the paths of a group share its chain of maps (per path: 13 of 80 s, 3,000 frames)
            mat, shown = np.broadcast_to(view, (len(times), 3, 3)), np.ones(len(times), bool)
            for anc in reversed(list(el.iterancestors(f"{SVG_NS}g"))):
                if anc not in group_cache:
                    group_cache[anc] = (_group_matrices(anc, times), _shown(anc, times, hidden_classes))
                gm, gv = group_cache[anc]
                mat = mat @ gm
                shown = shown & gv
            chains[nearest] = (mat, shown)
        mat, shown = chains[nearest]
        vis = _shown(el, times, hidden_classes) & shown
        own = el.get("transform")
        if own:
            mat = mat @ _parse_transform(own)
        xy = apply_linear(mat[:, :2, :2], xy) + mat[:, None, None, :2, 2]
        yield np.array(ids, np.int64), xy, vis[:, None] & ~point, vis[:, None] & point


def _corners_aligned(xy: np.ndarray, exact: np.ndarray, shown: np.ndarray) -> np.ndarray:
    """xy (T, n, 3, 2) with each path's corners cyclically rotated to fit exact's where it is shown largest (the
    turn is plain there, beyond the tolerance): a path may start at any corner (the flat writer starts an open
    path after the edge its stroke leaves out)."""
    size = np.where(shown, lengths(exact - np.roll(exact, 1, axis=2)).min(axis=2), -1.0)
    first = np.argmax(np.nan_to_num(size, nan=-1.0), axis=0)  # (n,)
    cols = np.arange(xy.shape[1])
    at, want = xy[first, cols], exact[first, cols]  # (n, 3, 2)
    err = np.stack([lengths(np.roll(at, -r, axis=1) - want).max(axis=1) for r in range(3)])
    turn = np.argmin(np.where(np.isnan(err), np.inf, err), axis=0)
    if not turn.any():
        return xy
    idx = (np.arange(3)[None] + turn[:, None]) % 3  # (n, 3)
    return np.take_along_axis(xy, np.broadcast_to(idx[None, :, :, None], xy.shape), axis=2)


class _Tally:
    """compare's figures, gathered a block of paths at a time: the (T, P, 3, 2) positions of every path at once
    were most of a long job's memory (8k triangles x 3,000 frames: 5 GB of the web job's 5.1 GB peak)."""

    def __init__(self, exact_xy: np.ndarray, expected_visible: np.ndarray, faces: np.ndarray, tolerance: float):
        self.exact, self.expected, self.faces, self.tolerance = exact_xy, expected_visible, faces, tolerance
        self.drawn_tri = np.zeros((exact_xy.shape[0], len(faces)), bool)
        self.tris: list[np.ndarray] = []
        self.paths, self.count, self.total = 0, 0, 0.0
        self.best: tuple[float, int, int, int] | None = None  # (px, -frame, -path, -vertex): argmax's first

    def add(self, tris: np.ndarray, xy: np.ndarray, shown: np.ndarray, collapsed: np.ndarray | None) -> None:
        """The next paths: triangle ids tris (n,), positions xy (T, n, 3, 2), shown and collapsed (T, n)."""
        if tris.max() >= len(self.faces):
            raise InputError("the SVG names triangles the input does not have; pass the input it was made from.")
        exact = np.take(self.exact, self.faces[tris], axis=1)
        dist = lengths(_corners_aligned(xy, exact, shown) - exact)  # (T, n, 3)
        dist = np.where(np.isnan(dist), np.inf, dist)
        if collapsed is not None:  # a visible triangle smaller than the tolerance may be drawn as its point
            small = collapsed & np.take(self.expected, tris, axis=1) & (dist <= self.tolerance).all(axis=-1)
            shown = shown | small
        drawn = np.broadcast_to(shown[..., None], dist.shape)
        d = dist[drawn]
        if d.size:
            self.count += d.size
            self.total += float(d.sum())
            k, p, v = np.unravel_index(np.argmax(np.where(drawn, dist, -1)), dist.shape)
            best = (float(dist[k, p, v]), -int(k), -(self.paths + int(p)), -int(v))
            if self.best is None or best > self.best:
                self.best = best
                self.worst = {"frame": int(k), "triangle": int(tris[p]), "vertex": int(v), "px": best[0]}
        np.logical_or.at(self.drawn_tri.T, tris, shown.T)
        self.tris.append(tris)
        self.paths += len(tris)

    def result(self) -> Verification:
        """The Verification of every path added."""
        tri_ids = np.unique(np.concatenate(self.tris))
        wrong = np.take(self.drawn_tri, tri_ids, axis=1) != np.take(self.expected, tri_ids, axis=1)
        absent = np.ones(len(self.faces), bool)
        absent[tri_ids] = False
        return Verification(
            max_px=self.best[0] if self.count else 0.0,
            mean_px=self.total / self.count if self.count else 0.0,
            vertex_frames=self.count,
            visibility_mismatches=int(wrong.sum()),
            mismatch_frames=int(wrong.any(axis=1).sum()),
            tolerance=float(self.tolerance),
            frames=self.exact.shape[0],
            paths=self.paths,
            triangles=len(tri_ids),
            dropped_visible=int((self.expected[:, absent].any(axis=0)).sum()),
            worst=self.worst if self.count else {},
        )


def compare(ev: Evaluated, exact_xy: np.ndarray, expected_visible: np.ndarray, faces: np.ndarray,
            tolerance: float) -> Verification:
    """Deviation of every drawn vertex from exact_xy (T, V, 2) and visibility against expected (T, F)."""
    t = ev.xy.shape[0]
    if exact_xy.shape[0] != t:
        raise InputError(f"the SVG has {t} frames but the input gives {exact_xy.shape[0]}; pass the same input.")
    tally = _Tally(exact_xy, expected_visible, faces, tolerance)
    tally.add(ev.triangles, ev.xy, ev.shown, ev.collapsed)
    return tally.result()


def exact_projection(anim, camera: Camera, frames: slice = slice(None)) -> tuple[np.ndarray, np.ndarray]:
    """Pixel xy (T, V, 2) float64 and culled visibility (T, F) of anim's frames with camera, projected a block of
    frames at a time (all at once, the float64 copies of a long capture took GBs)."""
    src = anim.frames[frames]
    t = src.shape[0]
    xy = np.empty((t, src.shape[1], 2))
    visible = np.empty((t, len(anim.faces)), bool)
    for a in range(0, t, FRAME_BLOCK):
        sl = slice(a, min(a + FRAME_BLOCK, t))
        bxy, ndc_z, w = camera.project(src[sl])
        xy[sl] = bxy
        visible[sl] = cull(bxy, ndc_z, w, anim.faces, camera.width, camera.height)
    return xy, visible


def verify_animation(data: bytes, anim, tolerance: float | None = None) -> Verification:
    """Verify SVG bytes against an already prepared FaceAnimation (the exact 3D the SVG should show); an SVG's
    paths are evaluated and measured a block at a time."""
    if player.is_player(data) or lottie.is_lottie(data):
        ev = evaluate(data)
        meta, n_frames, parts = ev.meta, ev.xy.shape[0], iter([(ev.triangles, ev.xy, ev.shown, ev.collapsed)])
    else:
        root = read_svg(data)
        meta = metadata_of(root)
        times = _svg_times(meta)
        n_frames, parts = len(times), _blocks(_svg_paths(root, meta, times), len(times))
    camera = Camera.from_json(meta["camera"])
    tol = tolerance if tolerance is not None else float(meta.get("options", {}).get("tolerance", 0.25))
    encoding = meta.get("encoding", {})
    frames = slice(None)
    if encoding.get("mode") == "still":  # a still (--frame K) shows frame K only
        k = int(encoding.get("frame", 0))
        if not 0 <= k < anim.n_frames or n_frames != anim.n_frames:
            raise InputError("the still's frame is not in the input; pass the input it was made from.")
        frames = slice(k, k + 1)
    elif anim.n_frames != n_frames:
        raise InputError(f"the SVG has {n_frames} frames but the input gives {anim.n_frames}; pass the same input.")
    tally = _Tally(*exact_projection(anim, camera, frames), anim.faces, tol)
    for tris, xy, shown, collapsed in parts:
        tally.add(tris, xy[frames], shown[frames], None if collapsed is None else collapsed[frames])
    if not tally.paths:
        raise InputError(NO_PATHS)
    return tally.result()


def _blocks(paths: Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
            n_frames: int) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """_svg_paths' paths joined into blocks of about BLOCK_BYTES of positions."""
    size = max(1, BLOCK_BYTES // max(48 * n_frames, 1))  # triangles a block
    part: list = []
    n = 0
    for path in paths:
        part.append(path)
        n += len(path[0])
        if n >= size:
            yield _joined(part)
            part, n = [], 0
    if part:
        yield _joined(part)


def _joined(part: list) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Consecutive paths of _svg_paths as one (ids, positions, shown, collapsed)."""
    tris, xys, shown, points = zip(*part)
    return (np.concatenate(tris), np.concatenate(xys, axis=1), np.concatenate(shown, axis=1),
            np.concatenate(points, axis=1))


def verify_file(svg_path: str | Path, input_path: str | Path, cache: str | Path | None = None,
                tolerance: float | None = None) -> Verification:
    """Verify an SVG (or player file) written by facesvg against the input it was converted from."""
    try:
        data = Path(svg_path).read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read {svg_path}: {exc.strerror}.") from None
    if player.is_player(data):
        meta = player.decode(data).meta
    elif lottie.is_lottie(data):
        meta = lottie.metadata(data)
    else:
        meta = metadata_of(read_svg(data))
    opts = meta.get("options", {})
    options = ConversionOptions.from_mapping({k: v for k, v in opts.items() if not isinstance(v, (dict, list))})
    anim = load(input_path, options, cache)  # with the options' --weights capture, when it was driven by one
    anim = prepare(anim, options, Report())
    return verify_animation(data, anim, tolerance)


def register_cli(subparsers) -> None:
    """Add `facesvg verify OUT.svg INPUT [--cache FILE] [--tolerance PX] [--json]`."""
    p = subparsers.add_parser("verify", help="check an SVG against the exact projection of its input")
    p.add_argument("svg", help="the SVG (or .svgz, player .html, Lottie .json or .lottie) written by facesvg convert")
    p.add_argument("input", help="the input animation it was converted from")
    p.add_argument("--cache", help="PC2 or MDD point cache for an OBJ input")
    p.add_argument("--tolerance", type=float, help="px bound to check (default: the SVG's stated tolerance)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(func=_cmd_verify)


def _cmd_verify(args) -> int:
    result = verify_file(args.svg, args.input, cache=args.cache, tolerance=args.tolerance)
    if args.json:
        print(json.dumps({**result.__dict__, "ok": result.ok}, sort_keys=True))
    else:
        print(f"{args.svg}: {result.summary()}")
    return 0 if result.ok else 1
