"""The Lottie reference itself (tests/reference/lottie.py): lottie-web (svg, canvas) and ThorVG (dotlottie-web) draw
small hand-written Lottie documents where numpy's maths says, and the spec's schema tells valid from broken ones.

Nothing here uses our writer: each document is written out below, so the players and the expectations can
disagree, and the transform order and signs in lottie.py's docstring are the ones these tests verify.
"""

from __future__ import annotations

import copy
import io
import json
import zipfile
from collections.abc import Sequence

import numpy as np
import pytest

from tests.reference import lottie
from tests.svgrender import chromium_frame

ALPHA = 127  # a pixel belongs to a silhouette above this alpha
MIN_IOU = 0.95
LINEAR = {"o": {"x": [0], "y": [0]}, "i": {"x": [1], "y": [1]}}  # a keyframe's linear easing


@pytest.fixture(scope="module")
def players(browser):
    """The browser, once the Lottie packages are installed (skips locally without them, fails when CI is set)."""
    lottie.require()
    return browser


@pytest.fixture
def spec():
    """Skips (fails under CI) where the schema package is not installed."""
    lottie.require()


# --- Hand-written Lottie -------------------------------------------------------------------------------------------

def static(value) -> dict:
    """A property that does not animate."""
    return {"a": 0, "k": value}


def keyed(*keys: tuple[float, object], hold: bool = False) -> dict:
    """An animated property through (frame, value) keys, linear between them (held when hold)."""
    out = []
    for k, (t, value) in enumerate(keys):
        key = {"t": t, "s": value if isinstance(value, list) else [value]}
        if k < len(keys) - 1:
            key.update({"h": 1} if hold else LINEAR)
        out.append(key)
    return {"a": 1, "k": out}


def bezier(points) -> dict:
    """A closed polygon as a Lottie bezier (no tangents)."""
    pts = [[float(x), float(y)] for x, y in points]
    return {"c": True, "v": pts, "i": [[0.0, 0.0]] * len(pts), "o": [[0.0, 0.0]] * len(pts)}


def transform(**props) -> dict:
    """A group's `tr`: identity unless props set a, p, s, r, o, sk, sa."""
    tr = {"ty": "tr", "a": static([0, 0]), "p": static([0, 0]), "s": static([100, 100]), "r": static(0),
          "o": static(100), "sk": static(0), "sa": static(0)}
    tr.update(props)
    return tr


def fill(rgba, keyed_colour: dict | None = None) -> dict:
    return {"ty": "fl", "c": keyed_colour or static(list(rgba)), "o": static(100), "r": 1}


def stroke(rgba, width: float, cap: int = 2, join: int = 2) -> dict:
    return {"ty": "st", "c": static(list(rgba)), "o": static(100), "w": static(width), "lc": cap, "lj": join}


def document(groups: list[list[dict]], w: int, h: int, op: int = 60, ip: int = 0,
             layer_ks: dict | None = None) -> dict:
    """One shape layer holding one group per item list (each closed by its `tr`, identity unless given)."""
    shapes = [{"ty": "gr", "it": it if it[-1]["ty"] == "tr" else [*it, transform()]} for it in groups]
    ks = {"a": static([0, 0]), "p": static([0, 0]), "s": static([100, 100]), "r": static(0), "o": static(100)}
    ks.update(layer_ks or {})
    return {"v": "5.7.0", "fr": 30, "ip": ip, "op": op, "w": w, "h": h,
            "layers": [{"ty": 4, "ind": 1, "ip": ip, "op": op, "st": 0, "ks": ks, "shapes": shapes}]}


# --- numpy expectations --------------------------------------------------------------------------------------------

def _segment_distance(px: np.ndarray, py: np.ndarray, a, b) -> np.ndarray:
    ab = np.subtract(b, a, dtype=float)
    t = ((px - a[0]) * ab[0] + (py - a[1]) * ab[1]) / max(float(ab @ ab), 1e-12)
    t = np.clip(t, 0.0, 1.0)
    return np.hypot(px - (a[0] + t * ab[0]), py - (a[1] + t * ab[1]))


def _inside(px: np.ndarray, py: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd point in polygon."""
    out = np.zeros(px.shape, bool)
    for (x0, y0), (x1, y1) in zip(poly, np.roll(poly, -1, 0)):
        crosses = (y0 > py) != (y1 > py)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_at = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
        out ^= crosses & (px < x_at)
    return out


def expected_mask(polys: Sequence[np.ndarray], width: int, height: int, stroke_width: float = 0.0,
                  ss: int = 4) -> np.ndarray:
    """Pixels at least half covered by the polygons filled (union), plus a round-joined stroke of stroke_width
    centred on their edges, sampled ss x ss per pixel."""
    ys, xs = np.mgrid[0:height * ss, 0:width * ss]
    px, py = (xs + 0.5) / ss, (ys + 0.5) / ss
    covered = np.zeros(px.shape, bool)
    for poly in polys:
        poly = np.asarray(poly, float)
        covered |= _inside(px, py, poly)
        if stroke_width > 0:
            for a, b in zip(poly, np.roll(poly, -1, 0)):
                covered |= _segment_distance(px, py, a, b) <= stroke_width / 2
    return covered.reshape(height, ss, width, ss).mean(axis=(1, 3)) >= 0.5


def edge_distance(poly: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """(inside, distance to the nearest edge) at each pixel centre."""
    ys, xs = np.mgrid[0:height, 0:width]
    px, py = xs + 0.5, ys + 0.5
    dist = np.min([_segment_distance(px, py, a, b) for a, b in zip(poly, np.roll(poly, -1, 0))], axis=0)
    return _inside(px, py, np.asarray(poly, float)), dist


def iou(a: np.ndarray, b: np.ndarray) -> float:
    union = (a | b).sum()
    return float((a & b).sum() / union) if union else 1.0


def silhouette(rgba: np.ndarray) -> np.ndarray:
    return rgba[..., 3] > ALPHA


def apply(m: np.ndarray, pts) -> np.ndarray:
    pts = np.asarray(pts, float)
    return pts @ m[:2, :2].T + m[:2, 2]


def render_all(browser, doc, frames: Sequence[float]) -> dict[str, np.ndarray]:
    return {p: lottie.lottie_frames(doc, frames, p, browser=browser) for p in lottie.PLAYERS}


# --- A keyframed triangle, a held fill colour, a stroke ------------------------------------------------------------

TRI_A = np.array([[14.0, 12.0], [70.0, 20.0], [26.0, 66.0]])
TRI_B = np.array([[96.0, 50.0], [152.0, 58.0], [108.0, 104.0]])
KEY_END = 40  # the shape moves from TRI_A (frame 0) to TRI_B (frame 40), linearly
COLOURS = [(0, [1.0, 0.0, 0.0, 1.0]), (20, [0.0, 0.0, 1.0, 1.0]), (KEY_END, [0.0, 0.5, 0.0, 1.0])]  # held
STROKE_W = 3.0


def triangle_doc() -> dict:
    shape = {"ty": "sh", "ks": keyed((0, [bezier(TRI_A)]), (KEY_END, [bezier(TRI_B)]))}
    return document([[shape, stroke([0, 0, 0, 1], STROKE_W), fill(None, keyed(*COLOURS, hold=True))]], 168, 120)


def held_colour(frame: float) -> np.ndarray:
    """The fill's held colour at frame, 0..255 (the last key at or before it)."""
    return 255 * np.array([c for t, c in COLOURS if t <= frame][-1][:3])


@pytest.mark.browser
@pytest.mark.slow
def test_triangle_moves_linearly_with_held_fill_and_stroke(players):
    doc = triangle_doc()
    frames = [0, 12.5, 25, KEY_END, 55]  # the start, a sub-frame, mid-way, the last key, after it
    got = render_all(players, doc, frames)
    for f_i, frame in enumerate(frames):
        tri = TRI_A + min(frame / KEY_END, 1.0) * (TRI_B - TRI_A)
        want = expected_mask([tri], 168, 120, STROKE_W)
        bare = expected_mask([tri], 168, 120)  # without its stroke: the stroke must show
        inside, dist = edge_distance(tri, 168, 120)
        core = inside & (dist > STROKE_W / 2 + 1.5)
        on_edge = dist <= 0.4
        for player, shots in got.items():
            rgba = shots[f_i]
            score = iou(silhouette(rgba), want)
            assert score >= MIN_IOU, f"{player} frame {frame}: IoU {score:.3f} against the interpolated triangle"
            assert iou(silhouette(rgba), bare) < 0.9, f"{player} frame {frame}: the stroke did not widen it"
            colour = rgba[core][:, :3].astype(float)
            assert np.abs(colour - held_colour(frame)).max() <= 2, \
                f"{player} frame {frame}: fill {colour.mean(0)} is not the held {held_colour(frame)}"
            edge = rgba[on_edge]  # pixels on the stroke's centre line: covered by it (3 px wide, over the fill)
            assert np.abs(edge[:, :3].astype(float)).max() <= 2 and edge[:, 3].min() >= 253, \
                f"{player} frame {frame}: the stroke's centre line is not opaque black"


# --- A group's transform: order and signs --------------------------------------------------------------------------

L_SHAPE = np.array([[-20, -30], [0, -30], [0, 10], [30, 10], [30, 30], [-20, 30]], float)  # no symmetry
GROUP_ANCHOR = [5.0, -4.0]
GROUP_KEYS = {"p": ([60, 70], [130, 120]), "s": ([100, 100], [150, 70]), "r": (0, 50), "sk": (0, 25),
              "sa": (0, 35)}
LAYER = {"a": [100.0, 100.0], "p": [104.0, 97.0], "r": -8.0}  # a static layer transform above the group


def group_doc() -> dict:
    tr = transform(a=static(GROUP_ANCHOR), **{k: keyed((0, a), (KEY_END, b)) for k, (a, b) in GROUP_KEYS.items()})
    shapes = [{"ty": "sh", "ks": static(bezier(L_SHAPE))}, fill([0.2, 0.4, 0.8, 1]), tr]
    layer_ks = {"a": static(LAYER["a"]), "p": static(LAYER["p"]), "r": static(LAYER["r"])}
    return document([shapes], 220, 220, layer_ks=layer_ks)


def group_at(frame: float, sk_sign: float = 1.0, sa_sign: float = 1.0) -> np.ndarray:
    """The L shape's corners at frame by tr_matrix (signs flippable, for the negative control)."""
    t = min(frame / KEY_END, 1.0)
    v = {k: np.asarray(a, float) + t * (np.asarray(b, float) - np.asarray(a, float))
         for k, (a, b) in GROUP_KEYS.items()}
    group = lottie.tr_matrix(GROUP_ANCHOR, v["p"], v["s"], float(v["r"]), sk_sign * float(v["sk"]),
                             sa_sign * float(v["sa"]))
    layer = lottie.tr_matrix(LAYER["a"], LAYER["p"], r=LAYER["r"])
    return apply(layer @ group, L_SHAPE)


@pytest.mark.browser
@pytest.mark.slow
def test_group_transform_order_and_signs(players):
    frames = [0, 13.3, 27, KEY_END]
    got = render_all(players, group_doc(), frames)
    for f_i, frame in enumerate(frames):
        want = expected_mask([group_at(frame)], 220, 220)
        masks = {p: silhouette(shots[f_i]) for p, shots in got.items()}
        for player, mask in masks.items():
            score = iou(mask, want)
            assert score >= MIN_IOU, f"{player} frame {frame}: IoU {score:.3f} against tr_matrix"
        for a, b in (("lottie-svg", "lottie-canvas"), ("lottie-svg", "thorvg")):
            assert iou(masks[a], masks[b]) >= 0.97, f"frame {frame}: {a} and {b} disagree"
    # The signs matter: skew or its axis taken the other way round misses at the last key.
    for flipped in ({"sk_sign": -1.0}, {"sa_sign": -1.0}):
        wrong = expected_mask([group_at(KEY_END, **flipped)], 220, 220)
        assert iou(silhouette(got["thorvg"][-1]), wrong) < 0.9, f"{flipped} fits as well: the test cannot tell"


SVG_STACK = {"tx": 96.0, "ty": 84.0, "rotate": 35.0, "skewX": 20.0, "sx": 1.3, "sy": 0.7}


@pytest.mark.browser
@pytest.mark.slow
def test_svg_transform_stack_maps_to_lottie(players):
    """SVG's translate(tx ty) rotate(θ) skewX(φ) scale(sx sy) is the tr a=0, p=(tx, ty), r=θ, sk=-φ, sa=0,
    s=100(sx, sy): Chromium drawing the SVG and the three players drawing the tr cover the same pixels."""
    st = SVG_STACK
    d = "M" + " L".join(f"{x:g} {y:g}" for x, y in L_SHAPE) + " Z"
    svg = (f'<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200" viewBox="0 0 200 200">'
           f'<path d="{d}" fill="#3366cc" transform="translate({st["tx"]} {st["ty"]}) rotate({st["rotate"]}) '
           f'skewX({st["skewX"]}) scale({st["sx"]} {st["sy"]})"/></svg>').encode()
    ref = silhouette(chromium_frame(players, svg, 0.0, 200, 200))

    def doc(sk: float) -> dict:
        tr = transform(p=static([st["tx"], st["ty"]]), r=static(st["rotate"]), sk=static(sk),
                       s=static([100 * st["sx"], 100 * st["sy"]]))
        return document([[{"ty": "sh", "ks": static(bezier(L_SHAPE))}, fill([0.2, 0.4, 0.8, 1]), tr]], 200, 200)

    for player in lottie.PLAYERS:
        mapped = silhouette(lottie.lottie_frames(doc(-st["skewX"]), [0], player, browser=players)[0])
        assert iou(mapped, ref) >= 0.97, f"{player}: sk = -skewX does not draw the SVG's shape"
    same_sign = silhouette(lottie.lottie_frames(doc(st["skewX"]), [0], "thorvg", browser=players)[0])
    assert iou(same_sign, ref) < 0.9, "sk = +skewX fits as well: the test cannot tell the sign"
    m = lottie.tr_matrix(p=[st["tx"], st["ty"]], r=st["rotate"], sk=-st["skewX"], s=[100 * st["sx"], 100 * st["sy"]])
    assert iou(expected_mask([apply(m, L_SHAPE)], 200, 200), ref) >= 0.97


# --- Merged paths: several `sh`, one fill --------------------------------------------------------------------------

@pytest.mark.browser
@pytest.mark.slow
def test_two_paths_share_one_fill(players):
    one = np.array([[10, 10], [50, 14], [18, 52]], float)
    two = np.array([[60, 40], [92, 70], [56, 76]], float)
    doc = document([[{"ty": "sh", "ks": static(bezier(one))}, {"ty": "sh", "ks": static(bezier(two))},
                     fill([0.9, 0.6, 0.3, 1])]], 100, 90)
    got = render_all(players, doc, [0])
    for player, shots in got.items():
        mask = silhouette(shots[0])
        assert iou(mask, expected_mask([one, two], 100, 90)) >= MIN_IOU, player
        for tri in (one, two):
            own = expected_mask([tri], 100, 90)
            assert (mask & own).sum() >= 0.95 * own.sum(), f"{player}: a subpath is missing"


# --- A triangle collapsed to a point, with a thin stroke -----------------------------------------------------------

POINT_ROUND, POINT_BUTT = (20.3, 19.6), (60.3, 19.6)
DRAWS_A_DOT = {"lottie-svg": True, "lottie-canvas": False, "thorvg": False}  # round caps; butt caps: nothing


@pytest.mark.browser
@pytest.mark.slow
def test_collapsed_triangle_with_thin_round_stroke(players):
    """What each player draws for a closed path whose three vertices are equal, stroked 0.6 px: with round caps,
    lottie-web's svg (Chromium's SVG stroker) a dot, its canvas and ThorVG nothing; with butt caps none draws."""
    groups = [[{"ty": "sh", "ks": static(bezier([pt] * 3))}, stroke([0, 0, 0, 1], 0.6, cap=cap),
               fill([1, 0, 0, 1])] for pt, cap in ((POINT_ROUND, 2), (POINT_BUTT, 1))]
    got = render_all(players, document(groups, 80, 40, op=10), [0])
    for player, shots in got.items():
        alpha = shots[0][..., 3].astype(int)
        near_round = alpha[17:23, 18:23]
        near_butt = alpha[17:23, 58:63]
        assert alpha.sum() == near_round.sum() + near_butt.sum(), f"{player} drew away from the points"
        assert near_butt.max() == 0, f"{player} drew something for a butt-capped point"
        assert (near_round.max() >= 64) == DRAWS_A_DOT[player], \
            f"{player}: a dot is {DRAWS_A_DOT[player]} in lottie.py's findings, max alpha {near_round.max()}"


# --- dotLottie, and a composition that starts at ip > 0 ------------------------------------------------------------

def dotlottie(doc: dict, animation_id: str = "face") -> bytes:
    """A minimal dotLottie (zip: manifest.json + animations/<id>.json)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("manifest.json", json.dumps({"version": "1", "generator": "facesvg tests",
                                                 "animations": [{"id": animation_id}]}))
        zf.writestr(f"animations/{animation_id}.json", json.dumps(doc))
    return buf.getvalue()


@pytest.mark.browser
@pytest.mark.slow
def test_dotlottie_and_ip_offset(players):
    """Frames count from the composition (ip = 10 here) in every player, and a dotLottie of the document draws
    the same pixels as its JSON."""
    a = np.array([[6.3, 6.2], [40.1, 9.4], [9.6, 41.7]])
    b = a + [62.0, 3.5]
    doc = document([[{"ty": "sh", "ks": keyed((10, [bezier(a)]), (50, [bezier(b)]))}, fill([1, 0, 0, 1])]],
                   120, 50, op=70, ip=10)
    frames = [10, 30, 50, 69]
    for player in lottie.PLAYERS:
        plain = lottie.lottie_frames(doc, frames, player, browser=players)
        zipped = lottie.lottie_frames(dotlottie(doc), frames, player, browser=players)
        assert np.array_equal(plain, zipped), f"{player}: the dotLottie draws differently"
        for shot, frame in zip(plain, frames):
            tri = a + min((frame - 10) / 40, 1.0) * (b - a)
            assert iou(silhouette(shot), expected_mask([tri], 120, 50)) >= MIN_IOU, f"{player} frame {frame}"


def test_animation_of_reads_json_bytes_and_dotlottie():
    doc = document([[{"ty": "sh", "ks": static(bezier([[0, 0], [4, 0], [0, 4]]))}, fill([1, 0, 0, 1])]], 8, 8)
    assert lottie.animation_of(json.dumps(doc).encode()) == (doc, None)
    zipped = dotlottie(doc)
    assert lottie.animation_of(zipped) == (doc, zipped)
    empty = io.BytesIO()
    with zipfile.ZipFile(empty, "w") as zf:
        zf.writestr("manifest.json", "{}")
    for bad in (empty.getvalue(), b"PK\x03\x04" + b"\0" * 40):
        with pytest.raises(ValueError):
            lottie.animation_of(bad)


# --- The spec's schema ---------------------------------------------------------------------------------------------

def test_schema_accepts_the_hand_written_documents(spec):
    for doc in (triangle_doc(), group_doc(), document([[{"ty": "sh", "ks": static(bezier([[1, 1]] * 3))},
                                                        stroke([0, 0, 0, 1], 0.6)]], 8, 8)):
        assert lottie.schema_errors(doc) == []
        assert lottie.schema_errors(doc, strict=True) == []


def _broken(change) -> list[str]:
    doc = copy.deepcopy(triangle_doc())
    change(doc)
    return lottie.schema_errors(doc, strict=True)


def _shape(doc: dict, k: int) -> dict:
    return doc["layers"][0]["shapes"][0]["it"][k]


@pytest.mark.parametrize("change, where, what", [
    (lambda d: d.update(fr="30"), "fr", "not of type 'number'"),
    (lambda d: _shape(d, 0)["ks"]["k"][0]["s"][0].pop("v"), "layers/0/shapes/0/it/0/ks/k/0/s/0", "'v'"),
    (lambda d: _shape(d, 2)["c"]["k"][0].update(s=[1, 0]), "layers/0/shapes/0/it/2/c/k/0/s", "too short"),
    (lambda d: d["layers"][0].pop("ks"), "layers/0", "'ks' is a required property"),
    (lambda d: d.update(w=-1), "w", "minimum"),
    (lambda d: _shape(d, 1).update(ty="stroke"), "layers/0/shapes/0/it/1/ty", "not a shape type"),
], ids=["fr-string", "path-without-v", "colour-too-short", "layer-without-ks", "negative-width", "unknown-shape"])
def test_schema_reports_broken_documents(spec, change, where, what):
    errors = _broken(change)
    assert any(e.startswith(f"{where}: ") and what in e for e in errors), errors


def test_schema_itself_allows_unknown_types(spec):
    """The spec lets players skip unknown layer and shape types, so its schema passes them; strict reports them."""
    doc = copy.deepcopy(triangle_doc())
    _shape(doc, 1)["ty"] = "zz"
    doc["layers"][0]["ty"] = 99
    assert lottie.schema_errors(doc) == []
    assert sorted(lottie.schema_errors(doc, strict=True)) == [
        "layers/0/shapes/0/it/1/ty: 'zz' is not a shape type of the spec",
        "layers/0/ty: 99 is not a layer type of the spec"]
