"""The puppet's tables reproduce the projected 3D face (blendshapes.drive, the same camera), not themselves."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from converter import blendshapes
from converter.extract import fit_camera, unit_face_normals, unit_vertex_normals
from converter.formats.captures.base import WeightTrack
from converter.lighting import lambert
from converter.puppet import pose, shade
from converter.puppet.model import MORPH_WEIGHTS, Z_LEVELS, build

QUANT_PX = 0.1  # the brief's bound at a keyform: quantisation (step <= 1/64 px) and float32 rounding
BETWEEN_PX = 0.25  # between a morph's keyforms: piecewise linear in the weight (measured: < 0.03 px)
COMBINED_PX = 1.0  # several targets at once under a head turn: 2D displacements add (measured ~0.2 px)


def truth(face, puppet, names, values, head=None, eye_left=None):
    """(V, 2) px of the 3D face driven by one frame and projected with the puppet's camera, puppet vertices."""
    track = WeightTrack(list(names), np.zeros(1), np.asarray([values], np.float32), 30.0,
                        head=None if head is None else np.asarray([head], np.float32),
                        eye_left=None if eye_left is None else np.asarray([eye_left], np.float32))
    anim = blendshapes.drive(face, track)
    xy, z, _ = puppet.camera.project(anim.frames[0][puppet.source_vertices])
    return xy, z


def z_tol(puppet) -> float:
    """One depth step: the face's depth range over Z_LEVELS (a table keeps depth changes to half of it)."""
    return float(np.ptp(puppet.z)) / Z_LEVELS


def weights_of(puppet, **named):
    w = np.zeros(len(puppet.morphs))
    for k, p in enumerate(puppet.morphs):
        w[k] = named.get(p.name, 0.0)
    return w


def test_every_morph_is_exact_at_its_keyforms(face, puppet):
    nonlinear = 0
    for p in puppet.morphs:
        nonlinear += len(p.axes[0]) > 2
        for w in p.axes[0]:
            want, want_z = truth(face, puppet, [p.name], [w])
            got, got_z = pose(puppet, weights_of(puppet, **{p.name: w}))
            assert np.abs(got - want).max() <= QUANT_PX, (p.name, w)
            assert np.abs(got_z - want_z).max() <= z_tol(puppet), (p.name, w)
    assert nonlinear >= 1  # jawOpen moves in depth: its projection needs the chapter's intervals
    assert any(len(p.axes[0]) == 2 for p in puppet.morphs)  # browInnerUp lifts in a plane: one interval


def test_morphs_between_keyforms_are_close(face, puppet):
    for p in puppet.morphs:
        for w in (0.1, 0.4, 0.6, 0.9):
            want, _ = truth(face, puppet, [p.name], [w])
            got, _ = pose(puppet, weights_of(puppet, **{p.name: w}))
            assert np.abs(got - want).max() <= BETWEEN_PX, (p.name, w)


def test_jaw_keyforms_are_needed(face, puppet):
    """With only jawOpen's end keyforms the middle is off by more than the tolerance: the intervals are real."""
    jaw = next(p for p in puppet.morphs if p.name == "jawOpen")
    assert list(jaw.axes[0]) == list(MORPH_WEIGHTS)
    want, _ = truth(face, puppet, ["jawOpen"], [0.5])
    full, _ = truth(face, puppet, ["jawOpen"], [1.0])
    rest = puppet.xy.astype(np.float64)
    linear = rest + 0.5 * (full - rest)
    assert np.abs(linear - want).max() > 0.1


@pytest.mark.parametrize("yaw,pitch,roll", [(-30, 0, 0), (13, -22, 0), (20, 20, 0.3), (0, 0, -0.5), (37, 5, 0.2)])
def test_head_turns_are_exact_at_any_angle(face, puppet, yaw, pitch, roll):
    head = (math.radians(yaw), math.radians(pitch), roll)
    want, want_z = truth(face, puppet, ["jawOpen"], [0.0], head=head)
    got, got_z = pose(puppet, weights_of(puppet), head=head)
    assert np.abs(got - want).max() <= QUANT_PX
    assert np.abs(got_z - want_z).max() <= z_tol(puppet)
    assert np.abs(got - puppet.xy).max() > 10  # it did turn


@pytest.mark.parametrize("name,w", [("jawOpen", 1.0), ("jawOpen", 0.5), ("mouthSmileLeft", 1.0)])
def test_a_target_turns_with_the_head(face, puppet, name, w):
    head = (math.radians(18), math.radians(-12), 0.25)
    want, _ = truth(face, puppet, [name], [w], head=head)
    got, _ = pose(puppet, weights_of(puppet, **{name: w}), head=head)
    assert np.abs(got - want).max() <= QUANT_PX
    rest, _ = pose(puppet, weights_of(puppet), head=head)
    assert np.abs(got - rest).max() > 5  # the target showed


def test_several_targets_under_a_turn_are_close(face, puppet):
    head = (math.radians(-15), math.radians(10), -0.1)
    named = {"jawOpen": 0.8, "mouthSmileLeft": 0.6, "browInnerUp": 0.3, "eyeBlinkLeft": 0.9}
    want, _ = truth(face, puppet, list(named), list(named.values()), head=head)
    got, _ = pose(puppet, weights_of(puppet, **named), head=head)
    assert np.abs(got - want).max() <= COMBINED_PX


@pytest.mark.parametrize("yaw,pitch", [(20, 0), (-13, 10), (30, -25)])
def test_left_eye_turns_exactly(face, puppet, yaw, pitch):
    eye = (math.radians(yaw), math.radians(pitch), 0.0)
    want, _ = truth(face, puppet, ["jawOpen"], [0.0], eye_left=eye)
    got, _ = pose(puppet, weights_of(puppet), eyes=(eye[0], eye[1], 0.0, 0.0))
    assert np.abs(got - want).max() <= QUANT_PX
    assert np.abs(got - puppet.xy).max() > 1  # the eye moved
    head = (0.2, -0.1, 0.1)
    want, _ = truth(face, puppet, ["eyeBlinkLeft"], [0.5], head=head, eye_left=eye)
    got, _ = pose(puppet, weights_of(puppet, eyeBlinkLeft=0.5), head=head, eyes=(eye[0], eye[1], 0.0, 0.0))
    assert np.abs(got - want).max() <= QUANT_PX


def test_only_moving_vertices_are_stored(puppet):
    brow = next(p for p in puppet.morphs if p.name == "browInnerUp")
    assert 0 < len(brow.table.vertices) < len(puppet.xy) / 4
    assert len(puppet.eyes) == 2 and all(0 < len(e) < len(puppet.xy) / 8 for e in puppet.eyes)
    assert all(p.table.xy.dtype == np.int16 for p in puppet.morphs)


def test_back_of_the_head_is_dropped_and_the_jaw_keeps_what_it_shows(face, puppet):
    assert len(puppet.triangles) < len(face.faces)
    puppet = build(face, puppet.camera, budget=False)  # the full mesh's triangles (test_budget checks the budget's)
    # every triangle front-facing at the neutral pose is kept
    xy, _, _ = puppet.camera.project(face.base)
    tri = xy[face.faces]
    u, v = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    area = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    kept = set(map(int, puppet.source_vertices[puppet.triangles].min(axis=1)))
    front = np.flatnonzero(area < 0)
    assert {int(face.faces[f].min()) for f in front} <= kept


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-2.0, 3.0, allow_nan=False), min_size=4, max_size=4),
       st.tuples(*(st.floats(-1.5, 1.5) for _ in range(3))), st.tuples(*(st.floats(-1.0, 1.0) for _ in range(4))))
def test_random_weights_give_finite_vertices(puppet, weights, head, eyes):
    xy, z = pose(puppet, np.array(weights), head=head, eyes=eyes)
    assert np.isfinite(xy).all() and np.isfinite(z).all()


@pytest.mark.parametrize("gouraud", [False, True])
def test_shade_relights_the_turned_head_as_the_prerender_lights_it(face, gouraud):
    """The stored rest normals turned by the head and lit (model.shade, what the player does) match lambert on the
    turned 3D face's own normals within the int8 normals' rounding; at rest they give back the baked colours."""
    from_face = build(face, fit_camera(face.still(30.0), 256), gouraud=gouraud, budget=False)
    assert np.abs(shade(from_face).astype(int) - from_face.colors).max() <= 2
    head = (math.radians(20), math.radians(-15), 0.2)
    r = blendshapes.rotations(np.array([head]))[0]
    turned = (face.base.astype(np.float64) @ r.T)[None].astype(np.float32)
    if gouraud:
        normals = unit_vertex_normals(turned, face.faces)[0][from_face.source_vertices]
        base = face.still(1.0).face_base_colors()[from_face.source_vertices]
    else:
        kept = [np.flatnonzero((np.sort(face.faces, 1) == np.sort(from_face.source_vertices[t])).all(1))[0]
                for t in from_face.triangles]
        normals = unit_face_normals(turned, face.faces)[0][kept]
        base = face.still(1.0).triangle_colors()[kept]
    want = np.rint(lambert(normals, base, from_face.camera.view) * 255)
    got = shade(from_face, head).astype(int)
    assert np.abs(got - want).max() <= 3
    assert np.abs(got - from_face.colors).max() > 10  # the turn changes the light: the rest colours would not do
