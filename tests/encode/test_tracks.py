"""The encoder's compact stores: vertex-shared tracks (encode.tracks), packed keys (keys.Packed) and timelines
folded a block of paths at a time (collapse.fold_blocks, take_paths). Each is checked against the dense form it
replaces."""

import numpy as np
import pytest

from converter.encode import collapse, freeknots
from converter.encode import keys as keyframes
from converter.encode.groups import local_tracks
from converter.encode.tracks import Tracks, blocks, first_use


def _face(seed: int, t: int = 30, v: int = 40, p: int = 60):
    rng = np.random.default_rng(seed)
    verts = (np.cumsum(rng.normal(0, 0.7, (t, v, 2)), axis=0) + rng.uniform(0, 300, (1, v, 2))).astype(np.float32)
    corners = rng.integers(0, v, (p, 3))
    active = rng.random((t, p)) > 0.25
    return verts, corners, active


@pytest.mark.parametrize("seed", [0, 1])
def test_tracks_give_the_dense_array(seed):
    verts, corners, _ = _face(seed)
    dense = np.take(verts, corners, axis=1).reshape(verts.shape[0], len(corners), 6)
    tr = Tracks(verts, corners)
    assert tr.shape == dense.shape
    idx = np.array([5, 0, 59, 5])
    assert np.array_equal(tr.take(idx), dense[:, idx]) and tr.take(idx).dtype == np.float32
    assert np.array_equal(tr.take(slice(10, 20)), dense[:, 10:20])
    order = np.random.default_rng(seed).permutation(len(corners))
    assert np.array_equal(tr.reorder(order).take(slice(None)), dense[:, order])
    assert [(s.start, s.stop) for s in blocks(10, 4)] == [(0, 4), (4, 8), (8, 10)] and blocks(0, 4) == []
    assert Tracks.screen(verts, corners).verts is verts  # the Sheet's float32 xy: read where it lies
    wide = Tracks.screen(verts.astype(np.float64), corners)
    assert wide.verts.dtype == np.float32 and np.array_equal(wide.take(idx), dense[:, idx])


def test_vertex_local_tracks_are_the_corners_bits():
    """A band's local px worked out once per vertex are, bit for bit, what each corner gets on its own (the plan
    stores the former and its keys were decided on the latter)."""
    verts, corners, _ = _face(3, t=50, v=300, p=500)
    rng = np.random.default_rng(3)
    mats = np.zeros((50, 2, 3))
    mats[:, :, :2] = np.eye(2) + rng.normal(0, 0.05, (50, 2, 2))
    mats[:, :, 2] = rng.normal(0, 20, (50, 2))
    per_corner = local_tracks(np.take(verts, corners, axis=1), mats)
    u, inv = np.unique(corners, return_inverse=True)
    per_vertex = local_tracks(np.take(verts, u, axis=1)[:, :, None, :], mats)[:, :, 0]
    assert np.array_equal(np.take(per_vertex, inv.reshape(corners.shape), axis=1), per_corner)


@pytest.mark.parametrize("seed", [0, 1])
def test_packed_keys_unpack_to_the_dense_keys(seed):
    verts, corners, active = _face(seed)
    dense = freeknots.point_keys(Tracks(verts, corners).take(slice(None)), active, 0.4)
    packed = keyframes.pack(dense)
    assert len(packed.values) == dense.mask.sum() < dense.mask.size
    assert np.array_equal(np.diff(packed.start), dense.mask.sum(axis=0))

    def same(k: keyframes.Keys, a: int, b: int) -> bool:
        m = dense.mask[:, a:b]
        return (np.array_equal(k.mask, m) and np.array_equal(k.values[m], dense.values[:, a:b][m])
                and np.array_equal(k.first_active, dense.first_active[a:b]))

    assert same(packed.unpack(0, 60), 0, 60) and same(packed.unpack(13, 14), 13, 14)
    assert same(packed.unpack(7, 41), 7, 41) and packed.unpack(20, 20).mask.shape == (31, 0)
    joined = keyframes.join([packed.part(0, 7), packed.part(7, 41), packed.part(41, 60)])
    assert all(np.array_equal(x, y) for x, y in zip(joined, packed))


@pytest.mark.parametrize("size", [1, 7, 1000])
def test_fold_in_blocks_is_the_fold_of_all(size):
    verts, corners, active = _face(2)
    keys = freeknots.point_keys(Tracks(verts, corners).take(slice(None)), active, 0.3)
    whole = collapse.fold(keys, active)
    asked = []

    def keys_of(a: int, b: int) -> keyframes.Keys:
        asked.append((a, b))
        return keyframes.Keys(keys.mask[:, a:b], keys.values[:, a:b], keys.first_active[a:b])

    blocked = collapse.fold_blocks(active, keys_of, size)
    assert all(np.array_equal(x, y) for x, y in zip(whole, blocked))
    assert asked == [(a, min(a + size, 60)) for a in range(0, 60, size)]


def test_take_paths_reorders_a_timeline():
    verts, corners, active = _face(4)
    keys = freeknots.point_keys(Tracks(verts, corners).take(slice(None)), active, 0.3)
    order = np.random.default_rng(4).permutation(60)[:45]
    moved = collapse.take_paths(collapse.fold(keys, active), order)
    direct = collapse.fold(keyframes.Keys(keys.mask[:, order], keys.values[:, order], keys.first_active[order]),
                           active[:, order])
    assert all(np.array_equal(x, y) for x, y in zip(moved, direct))


def test_first_use_lists_each_value_once_where_it_first_occurs():
    ids = np.array([[7, 2, 7], [3, 2, 9], [0, 9, 3]])
    assert first_use(ids, 12).tolist() == [7, 2, 3, 9, 0]
    rng = np.random.default_rng(2)
    ids = rng.integers(0, 500, (300, 3))
    got = first_use(ids, 500)
    flat = ids.ravel().tolist()
    assert got.tolist() == sorted(set(flat), key=flat.index)
    assert first_use(np.zeros((0, 3), np.int64), 5).tolist() == []
