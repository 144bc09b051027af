"""The occlusion pass: which triangles are ever seen, from one small integer-id render per frame.

One EGL context (converter.egl, Mesa), one program, one framebuffer (an R32UI id renderbuffer and a
depth renderbuffer, no multisampling), one vertex and one element buffer are made once and reused for every
frame; a frame costs a glBufferSubData of the clip-space vertices and one of the triangles it draws, one draw
and one glReadPixels of the ids (the depth is never read back). A compiled loop marks the ids' faces.

A frame draws only the triangles the SVG draws in it (front-facing, in the view: converter.extract.cull), as
the writers hide the others there: a triangle culled in a frame hides nothing in it (one with a corner behind
the eye would otherwise hide what is behind its near part). Fewer triangles also make a cheaper draw: on the
ICT head, 31k of 51k triangles a frame, the pass takes about 8 % less CPU.

The rule (issue 15.8), in two parts:

1. Pixel centres. A triangle that is front-facing and owns a pixel centre at the working resolution in some
   frame (nearest drawn face there, GL's rasterisation rule without multisampling) is kept, however small.
   Ids are exact integers, so no blend of two ids can stand for a third triangle or hide a small one.
2. Sub-pixel triangles. A front-facing, in-frustum triangle whose inscribed circle is narrower than a pixel
   diagonal (inradius < sqrt(2)/2 px, the only triangles that can miss every pixel centre) and that owns no
   pixel centre in a frame still shows in an anti-aliased SVG as a fraction of a pixel; dropping it leaves a
   light speckle where the surface has no other triangle. It is kept when it is not behind the visible
   surface at one of four probe points p inside it (its centroid, and each corner moved 10% toward the
   centroid, so that a triangle whose middle is covered but whose tip peeks out counts): the pixel holding p
   is empty, or the plane of that pixel's owner, evaluated at p, is not nearer than the triangle by more
   than the two planes can part over the distance d from p to the owner's pixel centre
   (2 |slope_t - slope_owner| d, plus float rounding). A triangle of the same surface passes (its plane and
   the owner's meet within d); one strictly behind another surface (an inner mouth behind the lips, an
   eyeball behind a closed lid) is farther by a gap and is dropped.
   Why not ids at a higher resolution: it only moves the limit (a triangle smaller than the finer pixel
   still slips) and on llvmpipe a 3x render costs ~4.5x the frame (measured 52 vs 11 ms CPU on the
   capture-like face). The probe rule errs on the safe side: where the owner is steep (lip and lid
   margins) it keeps hidden sub-pixel triangles just behind, which cost bytes, never a hole; what it can
   miss is a sub-pixel triangle covered at all four probes while a sliver of it peeks out (on the dense
   ICT head: 2-4 px of summed coverage per 100k-pixel frame, against ~550 px lost by the old pass).
"""

from __future__ import annotations

import ctypes
import os

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import numba
import numpy as np

from converter import isolated
from converter.camera import Camera
from converter.egl import EglContext, render_errors
from converter.errors import RenderError

INRADIUS_PX = 0.5 ** 0.5  # a triangle whose inscribed circle is this wide holds a pixel centre
SLACK = 2.0  # margin on the depth two planes of one surface can part by between the centroid and the pixel centre
DEPTH_EPS = 1e-6  # NDC depth below which two surfaces count as one (float rounding)
PROBE_IN = 0.1  # corner probes sit this far from each corner toward the centroid, inside the triangle

_VERTEX = """#version 410 core
layout(location = 0) in vec4 clip;
void main() { gl_Position = clip; }
"""
_FRAGMENT = """#version 410 core
layout(location = 0) out uint id;
void main() { id = uint(gl_PrimitiveID) + 1u; }
"""


def _gl():
    """PyOpenGL's GL module (callers turn its import errors into RenderError with egl.render_errors)."""
    from OpenGL import GL  # noqa: PLC0415 - imported late so the EGL platform variable is set first

    return GL


class IdRenderer:
    """A reusable id render target: render(clip, drawn) -> (H, W) uint32 ids, 0 = background, face f = f + 1."""

    def __init__(self, width: int, height: int, faces: np.ndarray, n_vertices: int):
        # Rasterised on this thread: a frame is small, and llvmpipe's helper threads cost ~20 % more CPU for the
        # same wall time here (capture-like face, 335 frames: 1.07 -> 0.87 s CPU, 0.85 s wall either way).
        self._context = EglContext(raster_threads=0)
        self.width, self.height, self.n_vertices = int(width), int(height), int(n_vertices)
        with render_errors(self.close):
            self.gl = _gl()
            self.faces = np.ascontiguousarray(faces, np.uint32)
            self._build(self.faces)

    def _build(self, faces: np.ndarray) -> None:
        gl = self.gl
        self.program = gl.glCreateProgram()
        for kind, src in ((gl.GL_VERTEX_SHADER, _VERTEX), (gl.GL_FRAGMENT_SHADER, _FRAGMENT)):
            sh = gl.glCreateShader(kind)
            gl.glShaderSource(sh, src)
            gl.glCompileShader(sh)
            if not gl.glGetShaderiv(sh, gl.GL_COMPILE_STATUS):
                raise RenderError(f"the GL driver rejected the id shader ({gl.glGetShaderInfoLog(sh).decode()}).")
            gl.glAttachShader(self.program, sh)
        gl.glLinkProgram(self.program)
        if not gl.glGetProgramiv(self.program, gl.GL_LINK_STATUS):
            raise RenderError(
                f"the GL driver rejected the id program ({gl.glGetProgramInfoLog(self.program).decode()})."
            )
        self.vao = gl.glGenVertexArrays(1)
        gl.glBindVertexArray(self.vao)
        self.vbo = gl.glGenBuffers(1)
        gl.glBindBuffer(gl.GL_ARRAY_BUFFER, self.vbo)
        gl.glBufferData(gl.GL_ARRAY_BUFFER, self.n_vertices * 16, None, gl.GL_DYNAMIC_DRAW)
        gl.glEnableVertexAttribArray(0)
        gl.glVertexAttribPointer(0, 4, gl.GL_FLOAT, gl.GL_FALSE, 16, ctypes.c_void_p(0))
        self.ebo = gl.glGenBuffers(1)
        gl.glBindBuffer(gl.GL_ELEMENT_ARRAY_BUFFER, self.ebo)
        gl.glBufferData(gl.GL_ELEMENT_ARRAY_BUFFER, faces.nbytes, faces, gl.GL_DYNAMIC_DRAW)
        self._drawn: np.ndarray | None = None  # the faces the element buffer holds (None: all, in order)
        self.fbo = gl.glGenFramebuffers(1)
        gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, self.fbo)
        self.rbo = gl.glGenRenderbuffers(2)
        for rb, fmt, att in ((self.rbo[0], gl.GL_R32UI, gl.GL_COLOR_ATTACHMENT0),
                             (self.rbo[1], gl.GL_DEPTH_COMPONENT32F, gl.GL_DEPTH_ATTACHMENT)):
            gl.glBindRenderbuffer(gl.GL_RENDERBUFFER, rb)
            gl.glRenderbufferStorage(gl.GL_RENDERBUFFER, fmt, self.width, self.height)
            gl.glFramebufferRenderbuffer(gl.GL_FRAMEBUFFER, att, gl.GL_RENDERBUFFER, rb)
        if gl.glCheckFramebufferStatus(gl.GL_FRAMEBUFFER) != gl.GL_FRAMEBUFFER_COMPLETE:
            raise RenderError("the GL driver cannot render to an integer id target (R32UI); update Mesa.")
        gl.glDrawBuffers(1, [gl.GL_COLOR_ATTACHMENT0])
        gl.glReadBuffer(gl.GL_COLOR_ATTACHMENT0)
        gl.glViewport(0, 0, self.width, self.height)
        gl.glEnable(gl.GL_DEPTH_TEST)
        gl.glDepthFunc(gl.GL_LESS)
        gl.glEnable(gl.GL_CULL_FACE)  # back faces are never drawn by the writers, so they hide nothing
        gl.glCullFace(gl.GL_BACK)
        gl.glFrontFace(gl.GL_CCW)
        gl.glDisable(gl.GL_MULTISAMPLE)
        gl.glUseProgram(self.program)
        self._clear_ids = np.zeros(4, np.uint32)

    def render(self, clip: np.ndarray, drawn: np.ndarray | None = None) -> np.ndarray:
        """(H, W) uint32 ids of one frame, row 0 at the top; clip is (V, 4) clip-space positions. drawn: the faces
        to draw (ascending ids; default all); the others hide nothing."""
        gl = self.gl
        gl.glBufferSubData(gl.GL_ARRAY_BUFFER, 0, np.ascontiguousarray(clip, np.float32))
        n = self._use(drawn)
        gl.glClearBufferuiv(gl.GL_COLOR, 0, self._clear_ids)
        gl.glClearBufferfv(gl.GL_DEPTH, 0, np.ones(1, np.float32))
        gl.glDrawElements(gl.GL_TRIANGLES, 3 * n, gl.GL_UNSIGNED_INT, ctypes.c_void_p(0))
        ids = gl.glReadPixels(0, 0, self.width, self.height, gl.GL_RED_INTEGER, gl.GL_UNSIGNED_INT)
        ids = np.frombuffer(ids, np.uint32).reshape(self.height, self.width)[::-1]
        if self._drawn is None:
            return ids
        out = np.empty(ids.shape, np.uint32)
        _face_ids(ids, self._drawn, out)  # the draw's primitive numbers -> face ids
        return out

    def _use(self, drawn: np.ndarray | None) -> int:
        """Put the faces drawn (None: all) into the element buffer; their count."""
        gl = self.gl
        if drawn is None:
            if self._drawn is not None:
                gl.glBufferSubData(gl.GL_ELEMENT_ARRAY_BUFFER, 0, self.faces)
                self._drawn = None
            return len(self.faces)
        self._drawn = np.asarray(drawn, np.int64)
        if len(self._drawn):
            gl.glBufferSubData(gl.GL_ELEMENT_ARRAY_BUFFER, 0, np.take(self.faces, self._drawn, axis=0))
        return len(self._drawn)

    def close(self) -> None:
        """Free the GL objects and the context."""
        self._context.close()

    def __enter__(self) -> IdRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def clip_coords(camera: Camera, frames: np.ndarray) -> np.ndarray:
    """(T, V, 4) float32 clip-space positions of (T, V, 3) world points: exactly what Camera.project divides."""
    m = camera.projection @ camera.view
    return (np.asarray(frames, np.float64) @ m[:, :3].T + m[:, 3]).astype(np.float32)


def ever_seen(frames: np.ndarray, faces: np.ndarray, camera: Camera, visible: np.ndarray,
              progress=None) -> np.ndarray:
    """Bool (F,): the triangles some frame shows by the module's rule; visible (T, F) is the culling. Run in a
    forked child where that is safe (converter.isolated): Mesa's memory leaves with it."""
    return isolated.run(_ever_seen, frames, faces, camera, visible, progress=progress, what="the occlusion pass")


def _ever_seen(frames: np.ndarray, faces: np.ndarray, camera: Camera, visible: np.ndarray,
               progress=None) -> np.ndarray:
    """ever_seen in this process."""
    t, f = frames.shape[0], faces.shape[0]
    kept = np.zeros(f, bool)
    faces64 = faces.astype(np.int64)
    with IdRenderer(camera.width, camera.height, faces, frames.shape[1]) as r:
        for k in range(t):
            clip = clip_coords(camera, frames[k])
            ids = r.render(clip, np.flatnonzero(visible[k]))
            _mark(ids, visible[k], kept)
            if np.any(visible[k] > kept):  # a front-facing triangle owns no pixel centre yet: rule 2
                w = clip[:, 3].astype(np.float64)
                xy = np.empty((clip.shape[0], 2))
                xy[:, 0] = (clip[:, 0] / w + 1) * 0.5 * camera.width
                xy[:, 1] = (1 - clip[:, 1] / w) * 0.5 * camera.height
                _subpixel(ids, xy, clip[:, 2] / w, faces64, visible[k], kept)
            if progress:
                progress((k + 1) / t)
    return kept


@numba.njit(cache=True, nogil=True)
def _face_ids(ids, drawn, out):
    """out = the face id (f + 1, 0 the background) of each of ids (H, W), a draw's primitive numbers + 1 over the
    faces drawn."""
    for i in range(ids.shape[0]):
        for j in range(ids.shape[1]):
            v = ids[i, j]
            out[i, j] = drawn[v - 1] + 1 if v > 0 else 0


@numba.njit(cache=True, nogil=True)
def _mark(ids, visible, kept):
    """kept[f] = True for each face f that owns a pixel of ids (H, W; f + 1, 0 the background) and is visible:
    one pass over the ids (marking a flag array through ids.astype(intp) cost 1 ms a 512 px frame)."""
    n = kept.shape[0]
    for i in range(ids.shape[0]):
        for j in range(ids.shape[1]):
            v = ids[i, j]
            if 0 < v <= n and visible[v - 1]:
                kept[v - 1] = True


@numba.njit(cache=True, nogil=True)
def _subpixel(ids, xy, z, faces, visible, kept):
    """Rule 2 of the module docstring, in place: kept[f] = True for each visible face f not yet kept whose
    inscribed circle is narrower than INRADIUS_PX and which is not behind the visible surface at one of its probe
    points. ids (H, W) as IdRenderer.render gives them; xy (V, 2) pixels with y down and z (V,) NDC depth of the
    same frame. Compiled: as numpy over each frame's few candidates it cost 0.4 ms a frame in call overhead. The
    arithmetic is numpy's, operation for operation (tests/core/test_occlusion.py keeps that version)."""
    owner = np.empty(3)
    for f in range(len(kept)):
        if kept[f] or not visible[f]:
            continue
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        e1x, e1y = xy[i1, 0] - xy[i0, 0], xy[i1, 1] - xy[i0, 1]
        e2x, e2y = xy[i2, 0] - xy[i0, 0], xy[i2, 1] - xy[i0, 1]
        ax, ay = xy[i1, 0] - xy[i2, 0], xy[i1, 1] - xy[i2, 1]
        perimeter = np.sqrt(ax * ax + ay * ay) + np.sqrt(e2x * e2x + e2y * e2y) + np.sqrt(e1x * e1x + e1y * e1y)
        if not abs(e1x * e2y - e1y * e2x) / max(perimeter, 1e-12) < INRADIUS_PX:  # inscribed circle's radius
            continue
        cx = (xy[i0, 0] + xy[i1, 0] + xy[i2, 0]) / 3
        cy = (xy[i0, 1] + xy[i1, 1] + xy[i2, 1]) / 3
        gx, gy = _slope(xy, z, i0, i1, i2)
        owner[0] = -1  # the owner whose slope owner[1:] holds: a sub-pixel triangle's probes mostly share one
        for probe in range(4):
            if probe == 0:
                px, py = cx, cy
            else:
                v = faces[f, probe - 1]
                px, py = PROBE_IN * cx + (1 - PROBE_IN) * xy[v, 0], PROBE_IN * cy + (1 - PROBE_IN) * xy[v, 1]
            if _in_front(ids, xy, z, faces, px, py, z[i0], xy[i0, 0], xy[i0, 1], gx, gy, owner):
                kept[f] = True
                break


@numba.njit(cache=True, nogil=True, inline="always")
def _slope(xy, z, i0, i1, i2):
    """The depth slope (per pixel x, y) of the triangle of vertices i0, i1, i2; 0 (or nan) when degenerate."""
    e1x, e1y = xy[i1, 0] - xy[i0, 0], xy[i1, 1] - xy[i0, 1]
    e2x, e2y = xy[i2, 0] - xy[i0, 0], xy[i2, 1] - xy[i0, 1]
    d1, d2 = z[i1] - z[i0], z[i2] - z[i0]
    det = e1x * e2y - e1y * e2x
    safe = det if abs(det) > 1e-12 else np.inf  # a degenerate triangle: no slope
    return (d1 * e2y - d2 * e1y) / safe, (d2 * e1x - d1 * e2x) / safe


@numba.njit(cache=True, nogil=True, inline="always")
def _in_front(ids, xy, z, faces, px, py, z0, x0, y0, gx, gy, cache) -> bool:
    """The plane (depth z0 at (x0, y0), slope (gx, gy)) is not behind the owner of the pixel holding (px, py).
    cache (3,): the last owner met and its slope, reused when the pixel has the same owner."""
    h, w = ids.shape
    col = min(max(np.int64(np.floor(px)), 0), w - 1)
    row = min(max(np.int64(np.floor(py)), 0), h - 1)
    owner = np.int64(ids[row, col]) - 1
    if owner < 0:
        return True
    o0, o1, o2 = faces[owner, 0], faces[owner, 1], faces[owner, 2]
    if cache[0] != owner:
        cache[1], cache[2] = _slope(xy, z, o0, o1, o2)
        cache[0] = owner
    ox, oy = cache[1], cache[2]
    z_t = z0 + ((px - x0) * gx + (py - y0) * gy)
    z_o = z[o0] + ((px - xy[o0, 0]) * ox + (py - xy[o0, 1]) * oy)
    reach = np.hypot(px - col - 0.5, py - row - 0.5)
    dx, dy = gx - ox, gy - oy
    tol = SLACK * np.sqrt(dx * dx + dy * dy) * reach + DEPTH_EPS
    return z_t <= z_o + tol
