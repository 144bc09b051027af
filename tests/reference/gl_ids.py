"""The GL id render the occlusion pass used before converter.raster: the tests' independent reference for it.

One EGL context (converter.egl, Mesa's llvmpipe), an R32UI id renderbuffer and a depth renderbuffer without
multisampling, one vertex and one element buffer reused for every frame: render(clip, drawn) gives the ids of
the faces drawn, as GL rasterises them.
"""

from __future__ import annotations

import ctypes
import os

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import numba
import numpy as np

from converter.camera import Camera
from converter.egl import EglContext, render_errors
from converter.errors import RenderError

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
    from OpenGL import GL

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


@numba.njit(cache=True, nogil=True)
def _face_ids(ids, drawn, out):
    """out = the face id (f + 1, 0 the background) of each of ids (H, W), a draw's primitive numbers + 1 over the
    faces drawn."""
    for i in range(ids.shape[0]):
        for j in range(ids.shape[1]):
            v = ids[i, j]
            out[i, j] = drawn[v - 1] + 1 if v > 0 else 0


