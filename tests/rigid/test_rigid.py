"""Rigid-motion factoring: fits, decomposition, ordering, and the composed error bound (numpy evaluation)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from converter import verify
from converter.encode import freeknots, groups, overlap, parallel, robust_affine
from converter.encode import keys as keyframes
from converter.encode import order as order_mod
from converter.encode.budget import ErrorBudget
from converter.extract import extract, fit_camera
from converter.writers.svg_transforms import CLOSE, group_open
from tests.rigid.synth import captured_head
from tests.rigid.synth import grid as synth_grid


def _random_affine(rng, t):
    params = np.column_stack([rng.uniform(-50, 50, (t, 2)), rng.uniform(-170, 170, t), rng.uniform(-30, 30, t),
                              rng.uniform(0.5, 2, t), rng.uniform(0.5, 2, t)])
    return params, groups.compose(params, np.zeros(2))


def test_decompose_inverts_compose():
    rng = np.random.default_rng(0)
    params, mats = _random_affine(rng, 50)
    back = groups.decompose(mats, np.zeros(2))
    assert np.allclose(groups.compose(back, np.zeros(2)), mats, atol=1e-9)
    assert np.allclose(back[:, 3:], params[:, 3:], atol=1e-9)  # skew and scales come back exactly


def test_svg_stack_order_is_translate_rotate_skew_scale():
    # translate(tx ty) rotate(a) skewX(k) scale(sx sy) written out by hand for one point.
    p = np.array([[10.0, -4.0, 30.0, 20.0, 1.2, 0.8]])  # tx ty angle skew sx sy
    m = groups.compose(p, np.zeros(2))[0]
    a = math.radians(30.0)
    x, y = 2.0, 3.0
    x, y = 1.2 * x, 0.8 * y  # scale
    x = x + math.tan(math.radians(20.0)) * y  # skewX(20)
    x, y = math.cos(a) * x - math.sin(a) * y, math.sin(a) * x + math.cos(a) * y
    assert np.allclose(m @ [2.0, 3.0, 1.0], [x + 10.0, y - 4.0])


def test_fit_affine_is_robust_to_local_motion():
    rng = np.random.default_rng(1)
    ref = rng.uniform(-100, 100, (400, 2))
    _, mats = _random_affine(rng, 5)
    xy = np.einsum("tij,nj->tni", mats[:, :, :2], ref) + mats[:, None, :, 2]
    xy[:, :40] += rng.uniform(5, 20, (5, 40, 2))  # a tenth of the points move on their own (a mouth)
    fit = robust_affine.fit_affine(ref, xy)
    assert np.abs(robust_affine.fit_affine(ref, xy[:, ::-1], np.arange(399, -1, -1)) - fit).max() < 1e-9
    assert np.abs(fit - mats).max() < 0.05 * np.abs(mats).max()
    pred = np.einsum("tij,nj->tni", fit[:, :, :2], ref) + fit[:, None, :, 2]
    assert np.linalg.norm(pred - xy, axis=-1)[:, 40:].max() < 0.5


def test_reorder_keeps_every_overlapping_pair_and_merges_runs():
    rng = np.random.default_rng(2)
    p = 300
    band = rng.integers(0, 3, p)
    pairs = np.unique(np.sort(rng.integers(0, p, (400, 2)), axis=1), axis=0)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    order = groups.reorder(band, pairs)
    assert sorted(order.tolist()) == list(range(p))
    pos = np.empty(p, int)
    pos[order] = np.arange(p)
    assert (pos[pairs[:, 0]] < pos[pairs[:, 1]]).all()
    def runs(b):
        return int((np.diff(b) != 0).sum()) + 1

    assert runs(band[order]) < runs(band) / 3


def test_reorder_releases_long_and_short_successor_rows_alike(monkeypatch):
    # Dense pairs (rows of ~20 successors): released with numpy past order.SHORT_ROW, one by one below it; the
    # same order either way, and every pair kept.
    rng = np.random.default_rng(5)
    p = 80
    band = rng.integers(0, 4, p)
    pairs = np.unique(np.sort(rng.integers(0, p, (1600, 2)), axis=1), axis=0)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    assert np.bincount(pairs[:, 0]).max() > 20
    orders = []
    for short in (0, 10**9):
        monkeypatch.setattr(order_mod, "SHORT_ROW", short)
        orders.append(groups.reorder(band, pairs))
    assert orders[0].tolist() == orders[1].tolist()
    pos = np.empty(p, int)
    pos[orders[0]] = np.arange(p)
    assert sorted(orders[0].tolist()) == list(range(p)) and (pos[pairs[:, 0]] < pos[pairs[:, 1]]).all()


def test_overlap_pairs_finds_touching_and_not_far_triangles():
    tri = np.array([[0, 0], [10, 0], [0, 10]], float)
    xy = np.stack([tri, tri + [10.2, 0], tri + [100, 100]])[None].reshape(1, 3, 3, 2)
    pairs = overlap.overlap_pairs(xy, np.ones((1, 3), bool))
    assert pairs.tolist() == [[0, 1]]
    hidden = overlap.overlap_pairs(xy, np.array([[True, False, True]]))
    assert hidden.tolist() == []


def test_overlap_pairs_drops_boxes_that_meet_when_the_triangles_do_not():
    # Two thin triangles along a diagonal: their boxes overlap, the triangles stay 1 px apart in every frame.
    a = np.array([[0, 0], [20, 20], [0, 2]], float)
    b = a + [1.5, -1.5]
    frames = np.stack([np.stack([a + k, b + k]) for k in range(6)])  # (6, 2, 3, 2), moving together
    assert overlap.overlap_pairs(frames, np.ones((6, 2), bool)).tolist() == []
    # ... but one frame where they cross is enough to keep the pair.
    frames[4, 1] = frames[4, 0] + [1, 0]
    assert overlap.overlap_pairs(frames, np.ones((6, 2), bool)).tolist() == [[0, 1]]
    # ... unless that frame does not draw one of them.
    act = np.ones((6, 2), bool)
    act[4, 1] = False
    assert overlap.overlap_pairs(frames, act).tolist() == []


def test_apart_is_a_separating_axis_test():
    t = np.array([[0, 0], [4, 0], [0, 4]], float)
    assert overlap.apart(t, t + [5, 0], 0.5) and not overlap.apart(t, t + [4.2, 0], 0.5)  # 1 px vs 0.2 px apart
    assert not overlap.apart(t, t + [1, 1], 0.0)  # overlapping
    assert overlap.apart(t, t[::-1] + [6, 6], 0.5)  # winding does not matter


@pytest.fixture(scope="module")
def sheet():
    anim = captured_head(n_frames=60)
    return extract(anim, fit_camera(anim, 256), occlusion=False)


def _plan(sheet, tol, **kw):
    tris = sheet.order
    act = sheet.visible[:, tris]
    t, p = act.shape
    track = sheet.xy[:, sheet.faces[tris]].reshape(t, p, 6).astype(np.float64)
    scale = max(1, math.ceil(1 / (math.sqrt(2) * 0.25 * tol)))
    tb, fe = 0.03 * tol, 1e-3
    rg = tol - math.sqrt(0.5) / scale - tb - fe
    budget = ErrorBudget(tol, scale, math.sqrt(0.5) / scale, tb, fe, rg)
    costs = groups.Costs(lambda m: len(group_open(m, t, "2.4s")), len(CLOSE), 24)
    plan = groups.plan(sheet.xy, sheet.faces, sheet.part_ids, 0, tris, act, budget, costs, **kw)
    return plan, act, track, scale, rg


@pytest.mark.parametrize("tol", [0.25, 0.5])
def test_composed_error_within_tolerance(sheet, tol):
    plan, act, track, scale, _ = _plan(sheet, tol)
    act = act[:, plan.order]
    keys = freeknots.point_keys(plan.track.take(slice(None)), act, plan.radius)
    q = np.rint(keys.values * scale) / scale  # what the file holds (integer viewBox units)
    played = keyframes.interpolate(keyframes.Keys(keys.mask, q, keys.first_active))
    err = np.linalg.norm((groups.compose_tracks(plan, played) - track[:, plan.order]).reshape(*act.shape, 3, 2),
                         axis=-1)
    assert plan.stats["groups"] >= 1 and plan.stats["grouped_paths"] > 0.25 * act.shape[1]
    assert err.max(axis=-1)[act].max() <= tol * (1 - 0.03)  # keyTimes rounding keeps its own share
    assert plan.stats["keys_rigid"] < 0.75 * plan.stats["keys_global"]


def test_groups_are_disjoint_runs_of_one_band(sheet):
    plan, *_ = _plan(sheet, 0.25)
    runs = plan.groups.tolist()
    assert runs and all(a < b <= c for (a, b), (c, _) in zip(runs, runs[1:] + [(10 ** 9, 0)]))
    grouped = np.zeros(len(plan.band), bool)
    for a, b in runs:
        grouped[a:b] = True
        assert len(set(plan.band[a:b].tolist())) == 1
    assert ((plan.band >= 0) == grouped).all()


def test_group_markup_plays_the_matrices_in_the_verifier(sheet):
    plan, *_ = _plan(sheet, 0.25)
    b = int(plan.band[plan.groups[0, 0]])
    motion = plan.motions[b]
    t = motion.matrices.shape[0]
    scale = 7
    text = group_open(groups.band_motion(*_params(motion), scale=scale, kt_decimals=4), t, "2.4s")
    svg = (f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {256 * scale} {256 * scale}" width="256" '
           f'height="256"><metadata id="facesvg">{{"frames": {t}, "fps": 25, "viewport": [256, 256]}}</metadata>'
           f'{text}<path id="f0" d="M{scale} 0L0 {scale}L0 0z"/></g></svg>').encode()
    ev = verify.evaluate(svg)
    replay = groups.band_motion(*_params(motion), scale=scale, kt_decimals=4).matrices
    want = np.einsum("tij,vj->tvi", replay[:, :, :2], np.array([[1.0, 0], [0, 1], [0, 0]])) + replay[:, None, :, 2]
    assert np.abs(ev.xy[:, 0] - want).max() < 1e-6


def _params(motion):
    params = groups.decompose(motion.matrices, np.zeros(2))
    return params, motion.centroid, 50.0, 0.025


def test_local_radius_shrinks_with_gain():
    r = ErrorBudget.split(0.25, 512).local_keys(np.array([1.0, 2.0]))
    assert r[1] < r[0] / 1.9
    assert (r > 0).all()


def test_pair_set_is_a_set():
    # Against Python's set: duplicates within and across batches, growth from a 2-slot table (every insert
    # collides and probes, every other one rehashes), every bit of a tile's word (the top one is the sign bit),
    # pairs within one tile and across far tiles.
    rng = np.random.default_rng(5)
    n = 5003
    pairs, want = overlap.PairSet(n, bits=1), set()
    tile = overlap.TILE
    corner = [(a, b) for a in range(tile) for b in range(tile, 2 * tile)]  # all 64 bits of tile (0, 1)
    for size in (1, 3, 50, 400, 2000):
        a = np.concatenate([rng.integers(0, 40, size), rng.integers(0, n, size)])
        b = np.concatenate([rng.integers(0, 40, size), rng.integers(0, n, size)])
        a, b = np.minimum(a, b), np.maximum(a, b)
        keep = a < b
        a, b = a[keep], b[keep]
        if size == 50:
            a = np.concatenate([a, [p[0] for p in corner]])
            b = np.concatenate([b, [p[1] for p in corner]])
        assert pairs.has(a, b).tolist() == [(x, y) in want for x, y in zip(a.tolist(), b.tolist())]
        pairs.add(a, b)
        want |= set(zip(a.tolist(), b.tolist()))
        assert pairs.count == len(want) and 2 * pairs.used <= len(pairs.table)
    assert set(corner) <= want
    got = pairs.pairs()
    assert got.tolist() == [list(w) for w in sorted(want)]
    assert pairs.has(got[:, 0], got[:, 1]).all()
    perm = rng.permutation(n)  # renamed: each pair (smaller, larger) of the new names, sorted
    assert pairs.pairs(perm).tolist() == sorted(sorted([int(perm[x]), int(perm[y])]) for x, y in want)
    absent = np.array([(x, y) for x in range(0, n, 97) for y in range(x + 1, n, 89) if (x, y) not in want])
    assert len(absent) > 1000 and not pairs.has(absent[:, 0], absent[:, 1]).any()


def test_pair_set_keeps_a_rows_neighbouring_tiles_in_one_line():
    # Tiles 4q..4q+3 (one row's) start at 4 consecutive slots of one 64-byte line, in every table size; the
    # groups spread over the table.
    for bits in (2, 3, 12, 22):
        shift = 64 - bits
        slots = [[int(overlap._slot(np.int64(4 * q + k), shift)) for k in range(4)] for q in range(0, 4000, 7)]
        assert all(s[0] % 4 == 0 and s == list(range(s[0], s[0] + 4)) for s in slots)
        groups = min(len(slots), 2 ** bits // 4)
        assert groups // 4 <= len({s[0] for s in slots}) <= groups
    assert [int(overlap._slot(np.int64(c), 63)) for c in range(4)] == [0, 1, 0, 1]  # 2 slots: the low bit
    for slots in (2, 4096, 1 << 16):
        table = overlap._table(slots)
        assert table.shape == (slots, 2) and table.ctypes.data % 64 == 0 and (table == overlap.EMPTY).all()


def test_screen_order_numbers_neighbours_near():
    # A 64 x 64 grid of points, shuffled: along the Z-order curve consecutive numbers are mostly 1 px apart (in
    # the shuffled order, ~30 px); non-finite points come last.
    rng = np.random.default_rng(2)
    grid = np.stack(np.meshgrid(np.arange(64.0), np.arange(64.0)), -1).reshape(-1, 2)
    pts = np.concatenate([rng.permutation(grid), [[np.nan, 3.0], [np.inf, np.inf]]])
    order = overlap.screen_order(pts + 100.25)
    assert sorted(order.tolist()) == list(range(len(pts))) and order[-2:].tolist() == [4096, 4097]
    step = np.abs(np.diff(pts[order[:-2]], axis=0)).sum(axis=1)
    assert np.median(step) == 1 and step.mean() < 2.5


@pytest.mark.parametrize(("grows", "bands", "threads"), [(False, 2, 2), (True, 2, 1), (False, 7, 3), (False, 2, 4)])
def test_overlap_pairs_match_every_pair_tested_by_brute_force(monkeypatch, grows, bands, threads):
    # Random small triangles over a few blocks of frames, some hidden, in bands: the grid candidates (a cell's
    # boxes grouped by band, only pairs across its bands looked at), their per-cell reporting, the cells shared
    # among threads (a slice of the entries each: a cell across two slices is read once) and the dedupe across
    # blocks (a PairSet, starting at 2 slots when it grows) against testing every pair.
    if grows:
        monkeypatch.setattr(overlap, "PAIRSET_BITS", 1)
    monkeypatch.setattr(parallel, "THREADS", threads)
    rng = np.random.default_rng(11)
    t, p = 20, 60
    centre = rng.uniform(0, 60, (1, p, 1, 2)) + np.cumsum(rng.normal(0, 1.0, (t, p, 1, 2)), axis=0)
    xy = centre + rng.uniform(-4, 4, (t, p, 3, 2))
    active = rng.random((t, p)) > 0.3
    band = rng.integers(0, bands, p)
    got = {tuple(e) for e in overlap.overlap_pairs(xy, active, block=8, margin=0.5, band=band).tolist()}
    want = set()
    lo, hi = xy.min(axis=2), xy.max(axis=2)
    for i in range(p):
        for j in range(i + 1, p):
            if band[i] == band[j]:
                continue
            both = active[:, i] & active[:, j]
            near = both & ((np.maximum(lo[:, i], lo[:, j]) <= np.minimum(hi[:, i], hi[:, j]) + 0.5).all(axis=1))
            if (near & ~overlap.apart(xy[:, i], xy[:, j], 0.5)).any():
                want.add((i, j))
    assert len(want) > 20 and got == want
    for block in (3, 16):  # the blocks only gather candidates: any size finds the same pairs
        other = overlap.overlap_pairs(xy, active, block=block, margin=0.5, band=band)
        assert {tuple(e) for e in other.tolist()} == want
    # The same paths given as vertex ids into a shared (T, V, 2) array (the planner's form): the same pairs.
    verts = xy.reshape(t, p * 3, 2)
    corners = np.arange(p * 3).reshape(p, 3)
    shared = overlap.overlap_pairs(verts, active, block=8, margin=0.5, band=band, corners=corners)
    assert {tuple(e) for e in shared.tolist()} == want


def test_candidates_of_slices_of_the_entries_are_those_of_all_of_them():
    # Each cell is read by the call whose slice holds its first entry: cut anywhere, two calls give the one call's
    # pairs, in its order (none lost, none twice), whichever buffer size they start with.
    rng = np.random.default_rng(5)
    lo = rng.uniform(0, 40, (80, 2)).astype(np.float32)
    hi = lo + rng.uniform(0.5, 6, (80, 2)).astype(np.float32)
    cells = overlap._cell_lists(lo, hi, 4.0, rng.integers(0, 3, 80))
    found = overlap.PairSet(80)
    idx = np.arange(80)
    n = len(cells[0])

    def pairs(first, last, k=4):
        buf, m = overlap._candidates(*cells, idx, found.table, found.shift, found.tiles, np.empty((k, 2), np.int64),
                                     first, last)
        return buf[:m].tolist()

    whole = pairs(0, n)
    assert len(whole) > 20 and len(set(map(tuple, whole))) == len(whole)
    assert (np.diff(cells[0]) == 0).sum() > 20  # cells of several entries, which most cuts fall inside
    for cut in range(n + 1):
        assert pairs(0, cut, 1) + pairs(cut, n, 64) == whole


def test_overlap_pairs_with_a_drift_taken_off_are_the_same_pairs():
    # A head's translation per frame taken off before the candidate search moves every box of a frame alike: the
    # same pairs, whatever the drift (the true one, a wrong one, a huge one), also far from the origin where the
    # float32 differences round (the boxes grow by that rounding).
    rng = np.random.default_rng(12)
    t, p = 24, 80
    walk = 3000.0 + np.cumsum(rng.normal(0, 4.0, (t, 2)), axis=0)  # a fast head, far out: float32 ulp ~ 2e-4 px
    centre = rng.uniform(0, 45, (1, p, 1, 2)) + np.cumsum(rng.normal(0, 0.3, (t, p, 1, 2)), axis=0)
    xy = (walk[:, None, None] + centre + rng.uniform(-4, 4, (1, p, 3, 2))).astype(np.float32)
    active = rng.random((t, p)) > 0.2
    band = rng.integers(0, 3, p)
    verts, corners = xy.reshape(t, p * 3, 2), np.arange(p * 3).reshape(p, 3)
    plain = overlap.overlap_pairs(verts, active, margin=0.5, band=band, corners=corners)
    assert len(plain) > 50
    for drift in (walk, walk + rng.normal(0, 3.0, (t, 2)), np.full((t, 2), -1e6)):
        got = overlap.overlap_pairs(verts, active, margin=0.5, band=band, corners=corners, drift=drift)
        assert np.array_equal(got, plain)
    # The translation taken off, the paths barely move: blocks of more frames find them.
    assert overlap.block_frames(verts, corners, walk) > overlap.block_frames(verts, corners) == 2


def test_overlap_blocks_follow_how_far_a_triangle_moves_for_its_size():
    # 6 px triangles moving 0.5 px a frame: a block of 12 frames; ten times the speed: 2 (the least); still: 32.
    rng = np.random.default_rng(2)
    tri = rng.uniform(0, 200, (40, 1, 2)) + np.array([[0, 0], [6, 0], [0, 6]])  # (P, 3, 2), 6 px boxes
    for speed, want in ((0.5, 12), (5.0, 2), (0.0, 32)):
        xy = tri[None] + speed * np.arange(30)[:, None, None, None] * np.array([1.0, 0.0])
        assert overlap.block_frames(xy) == want
        verts = xy.reshape(30, -1, 2)  # the same as vertex ids into a shared array
        assert overlap.block_frames(verts, np.arange(120).reshape(40, 3)) == want
    moving = tri[None] + 5.0 * np.arange(30)[:, None, None, None] * np.array([1.0, 0.0])
    assert overlap.block_frames(moving, drift=5.0 * np.arange(30)[:, None] * np.array([1.0, 0.0])) == 32
    assert overlap.block_frames(np.full((5, 3, 3, 2), np.nan)) == 32
    assert overlap.block_frames(np.zeros((1, 0, 3, 2))) == 2


def test_plan_in_blocks_of_runs_is_the_plan_in_one(sheet, monkeypatch):
    """The plan works band-local tracks and keys out a block of runs at a time (memory): blocks of a few paths
    decide the same groups, tracks and keys as one block of every path."""
    whole, *_ = _plan(sheet, 0.25)
    monkeypatch.setattr(freeknots, "BLOCK_TRACKS", 5)
    asked: list[int] = []  # ... and a run longer than a block has its band-local tracks worked a block at a time
    band_local = groups.Layout.band_local
    monkeypatch.setattr(groups.Layout, "band_local", lambda lay, sel: asked.append(len(sel)) or band_local(lay, sel))
    small, *_ = _plan(sheet, 0.25)
    assert whole.stats["groups"] >= 2 and len(groups._run_blocks([(a, b) for a, b in whole.groups.tolist()], 5)) > 1
    assert max(b - a for a, b in whole.groups.tolist()) > 5 and max(asked) <= 5
    assert np.array_equal(whole.groups, small.groups) and whole.stats == small.stats
    assert np.array_equal(whole.track.take(slice(None)), small.track.take(slice(None)))
    assert np.array_equal(whole.radius, small.radius)
    assert all(np.array_equal(a, b) for a, b in zip(whole.timeline, small.timeline))


def test_plan_timeline_holds_its_tracks_within_radius(sheet):
    """The plan's keys (folded with the hidden frames, worked out a block of paths at a time from packed square
    keys and vertex-shared tracks) play every path within its radius of its track wherever it is drawn, and
    collapse it wherever it is hidden."""
    plan, act, *_ = _plan(sheet, 0.25)
    act = act[:, plan.order]
    tl, track = plan.timeline, plan.track.take(slice(None)).astype(np.float64)
    t, p = act.shape
    bounds = np.searchsorted(tl.path, np.arange(p + 1))
    assert plan.stats["groups"] >= 1 and np.all(np.diff(bounds) >= 2)
    worst, over = 0.0, 0.0
    for j in range(p):
        h, v = tl.half[bounds[j]:bounds[j + 1]], tl.values[bounds[j]:bounds[j + 1]].astype(np.float64)
        played = np.stack([np.interp(2 * np.arange(t), h, v[:, c]) for c in range(6)], axis=1)  # (T, 6)
        err = np.linalg.norm((played - track[:, j]).reshape(t, 3, 2), axis=-1).max(axis=1)
        worst = max(worst, float((err / plan.radius[j])[act[:, j]].max(initial=0.0)))
        over = max(over, float((err - plan.radius[j])[act[:, j]].max(initial=0.0)))
        pts = played[~act[:, j]].reshape(-1, 3, 2)
        assert np.allclose(pts, pts[:, :1], atol=1e-4)  # hidden: the three corners at one point
    assert worst > 0.5 and over <= 1e-4  # float32 key values: the budget's float_err (1e-3 px here) covers them


def test_head_local_rows_are_the_paths_vertices_in_the_order_they_first_use_them(sheet):
    """The layout keeps head-local px for the paths' own vertices only, numbered along the paths' order: each path's
    track is, bit for bit, its corners' head-frame px (float64, cast to float32) as worked out for every vertex."""
    tris = sheet.order[::2]  # half the paths: some vertices belong to none of them
    act = sheet.visible[:, tris]
    budget = ErrorBudget(0.25, 6, math.sqrt(0.5) / 6, 0.0075, 1e-3, 0.1)
    lay = groups.layout(sheet.xy, sheet.faces, sheet.part_ids, 0, tris, act, budget)
    head = lay.head
    inv = np.linalg.inv(head.matrices[:, :, :2])
    in_head = sheet.xy.astype(np.float64) - head.matrices[:, None, :, 2]
    for sl in groups.blocks(len(in_head), groups.FRAME_BLOCK):  # as layout works them (one matrix product a block)
        in_head[sl] = groups.apply_linear(inv[sl], in_head[sl], out=np.empty_like(in_head[sl]))
    corners = sheet.faces[tris[lay.order]]
    t, p = act.shape
    want = np.take(in_head, corners, axis=1).astype(np.float32).reshape(t, p, 6)
    assert np.array_equal(lay.head_local.take(slice(None)), want)
    rows = lay.head_local.corners.ravel()
    used = len(np.unique(corners))
    assert lay.head_local.verts.shape[1] == used < sheet.xy.shape[1]
    firsts = rows[np.sort(np.unique(rows, return_index=True)[1])]
    assert firsts.tolist() == list(range(used))  # row r is the r-th vertex the paths meet


@pytest.mark.parametrize("stop", [(0.0, 0.0), (groups.STOP_SLACK, groups.STOP_SHARE)])
def test_head_local_keys_stopped_early_make_the_plan_in_full(sheet, monkeypatch, stop):
    """Head-local keys stop early on runs that may pay (lower bounds decide them; the others' stopped paths are
    redone): the same groups, stats, tracks and timeline as every head-local track worked out in full. The tight
    stop (0, 0) leaves runs its bounds cannot decide, so the redoing is exercised too."""
    monkeypatch.setattr(groups, "STOP_SLACK", 1e9)  # never reached: every track in full
    full, *_ = _plan(sheet, 0.25)
    monkeypatch.setattr(groups, "STOP_SLACK", stop[0])
    monkeypatch.setattr(groups, "STOP_SHARE", stop[1])
    calls = []
    real = freeknots.shape_keys

    def spy(xy, active, radius, deg, limit=None, **kw):
        k, gave_up = real(xy, active, radius, deg, limit, **kw)
        calls.append((limit is not None, int(gave_up.sum())))
        return k, gave_up

    redone = []
    replace = keyframes.replace
    monkeypatch.setattr(freeknots, "shape_keys", spy)
    monkeypatch.setattr(keyframes, "replace", lambda base, cols, new: redone.append(len(cols)) or
                        replace(base, cols, new))
    early, *_ = _plan(sheet, 0.25)
    assert full.stats["groups"] >= 2 and sum(g for lim, g in calls if lim) > 0
    if stop == (0.0, 0.0):
        assert sum(redone) > 0
    assert np.array_equal(full.groups, early.groups) and full.stats == early.stats
    assert np.array_equal(full.track.take(slice(None)), early.track.take(slice(None)))
    assert all(np.array_equal(a, b) for a, b in zip(full.timeline, early.timeline))


def test_replace_and_emptied_put_tracks_in_place():
    rng = np.random.default_rng(4)
    mask = rng.random((9, 6)) < 0.4
    mask[0] = True
    keys = keyframes.Keys(mask, rng.normal(size=(9, 6, 2)).astype(np.float32), np.zeros(6, np.int64))
    other = keyframes.Keys(~mask, rng.normal(size=(9, 6, 2)).astype(np.float32), np.zeros(6, np.int64))
    cols = np.array([1, 4, 5])
    part = keyframes.Keys(other.mask[:, cols], other.values[:, cols], other.first_active[cols])
    mixed = keyframes.replace(keyframes.pack(keys), cols, keyframes.pack(part))
    want = keys._replace(mask=keys.mask.copy(), values=keys.values.copy())
    want.mask[:, cols], want.values[:, cols] = other.mask[:, cols], other.values[:, cols]
    got = mixed.unpack(0, 6)
    assert np.array_equal(got.mask, want.mask)
    assert np.array_equal(got.values[got.mask], want.values[want.mask])
    bare = keyframes.emptied(mixed, cols).unpack(0, 6)  # those tracks hold no keys, the others are unchanged
    assert not bare.mask[:, cols].any() and not bare.values[:, cols].any()
    rest = np.setdiff1d(np.arange(6), cols)
    assert np.array_equal(bare.mask[:, rest], want.mask[:, rest])
    assert np.array_equal(bare.values[:, rest], got.values[:, rest])
    assert keyframes.emptied(mixed, cols[:0]) is mixed


def test_run_blocks_keep_order_and_size():
    runs = [(0, 3), (3, 4), (4, 10), (10, 12), (12, 13)]
    blocks = groups._run_blocks(runs, 4)
    assert [r for b in blocks for r in b] == runs
    assert blocks == [[(0, 3), (3, 4)], [(4, 10)], [(10, 12), (12, 13)]]


def test_motion_clusters_peak_memory_follows_the_tracks():
    # A 1,225-vertex sheet waving non-rigidly over 1,000 frames: the head is cut into clusters, and the traced
    # peak stays within 1.4x the tracks' own size: the features (the residuals, worked out a block of frames at a
    # time), or before them the residuals' lengths at half that, and a block of frames. The residuals (T, n, 2)
    # held while their lengths were taken, then their transposed copy as features, took it to 2.0x (the peak of
    # the ICT head x 4,000, 7.98 GB); a temporary of the residuals' size on top (|res - mean| in one go) to 2.4x.
    # The first call is not traced: it loads kernels.
    import tracemalloc

    _, faces = synth_grid(35, 0.0, 1.0, 0.0)
    u, v = np.meshgrid(np.linspace(-100, 100, 35), np.linspace(-100, 100, 35))
    ref = np.stack([u, v], -1).reshape(-1, 2)
    k = np.arange(1000)[:, None]
    xy = ref[None] + np.stack([10 * np.sin(k / 20 + ref[None, :, 1] / 40), 6 * np.cos(k / 15 + ref[None, :, 0] / 30)],
                              -1)
    xy[..., 0] += 20 * np.sin(k / 30)
    band = np.zeros(len(faces), np.int64)
    first = groups.motion_clusters(band, faces, xy, 0, groups.HEAD_CLUSTERS)
    tracemalloc.start()
    try:
        label = groups.motion_clusters(band, faces, xy, 0, groups.HEAD_CLUSTERS)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(np.unique(label)) == groups.HEAD_CLUSTERS and np.array_equal(label, first)
    assert peak < 1.4 * xy.nbytes


def test_overlap_pairs_of_no_frames_or_one_path_are_none():
    corners = np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4]])
    xy = np.zeros((0, 5, 2), np.float32)
    assert overlap.overlap_pairs(xy, np.zeros((0, 3), bool), corners=corners).shape == (0, 2)
    assert overlap.overlap_pairs(np.zeros((3, 1, 3, 2)), np.ones((3, 1), bool)).shape == (0, 2)
    one = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 4.0], [4.0, 4.0], [8.0, 0.0]], np.float32)[None].repeat(2, 0)
    assert overlap.overlap_pairs(one, np.ones((2, 3), bool), corners=corners).tolist() == [[0, 1], [0, 2], [1, 2]]
