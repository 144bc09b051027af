"""An offscreen OpenGL 4.1 core context on EGL (Mesa here, no window), from PyOpenGL's EGL bindings alone, and
the RenderError that names what to install when EGL is missing.

The occlusion pass rendered its ids in this context until converter.raster replaced it; the tests' GL reference
for that rasteriser (tests/reference/gl_ids.py) still does. Before it, the pass used pyrender's EGL platform,
whose import brings pyrender's whole package (trimesh, its scene graph, its viewer), slow to load. The context is
made as pyrender makes it: the first EGL device when the driver enumerates devices (else the default
display), a pbuffer-capable RGB config, the desktop OpenGL API, no surface.
"""

from __future__ import annotations

import ctypes
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from converter.errors import RenderError

EGL_HELP = (
    "offscreen rendering needs Mesa EGL; install it with "
    "'apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1' and keep PYOPENGL_PLATFORM=egl"
)
_PLATFORM_DEVICE_EXT = 0x313F  # EGL_EXT_platform_device


def _egl():
    """PyOpenGL's EGL module with PyOpenGL's function loading switched to EGL (whatever PYOPENGL_PLATFORM said)."""
    import OpenGL.platform  # noqa: PLC0415 - imported late so the EGL platform variable is set first

    plugin = OpenGL.platform.PlatformPlugin.by_name("egl")
    if plugin is None:
        raise RenderError(f"{EGL_HELP} (PyOpenGL has no EGL platform).")
    platform_cls = plugin.load()
    if not isinstance(OpenGL.platform.PLATFORM, platform_cls):
        platform_cls().install(vars(OpenGL.platform))
        plugin.loaded = True
    from OpenGL import EGL  # noqa: PLC0415

    return EGL


def _extension(egl, name: str, restype, *argtypes):
    """An EGL extension function, or None when the driver lacks it."""
    address = egl.eglGetProcAddress(name)
    if not address:
        return None
    proto = ctypes.CFUNCTYPE(restype, *argtypes)
    return proto(address)


def _display(egl):
    """The first enumerated EGL device's display (what pyrender picks), else the default display."""
    query = _extension(egl, "eglQueryDevicesEXT", egl.EGLBoolean, egl.EGLint, ctypes.c_void_p,
                       ctypes.POINTER(egl.EGLint))
    platform_display = _extension(egl, "eglGetPlatformDisplayEXT", egl.EGLDisplay, egl.EGLenum, ctypes.c_void_p,
                                  ctypes.c_void_p)
    if query is not None and platform_display is not None:
        n = egl.EGLint()
        devices = (ctypes.c_void_p * 1)()
        if query(1, ctypes.cast(devices, ctypes.c_void_p), ctypes.byref(n)) and n.value >= 1:
            return platform_display(_PLATFORM_DEVICE_EXT, devices[0], None)
    saved = os.environ.pop("DISPLAY", None)  # never an X server's display: this context is offscreen
    try:
        return egl.eglGetDisplay(egl.EGL_DEFAULT_DISPLAY)
    finally:
        if saved is not None:
            os.environ["DISPLAY"] = saved


@contextmanager
def _raster_threads(n: int | None) -> Iterator[None]:
    """LP_NUM_THREADS=n for the block, when n is given and the environment does not already choose."""
    if n is None or "LP_NUM_THREADS" in os.environ:
        yield
        return
    os.environ["LP_NUM_THREADS"] = str(n)
    try:
        yield
    finally:
        del os.environ["LP_NUM_THREADS"]


@contextmanager
def render_errors(cleanup: Callable[[], None]) -> Iterator[None]:
    """Run the block; on any failure run cleanup() and raise a RenderError that names what to install."""
    try:
        yield
    except RenderError:
        cleanup()
        raise
    except Exception as exc:  # ImportError, PyOpenGL failing to find libEGL, a driver refusing a call
        cleanup()
        raise RenderError(f"{EGL_HELP} ({type(exc).__name__}: {exc}).") from None


class EglContext:
    """An OpenGL 4.1 core context, current on the calling thread from creation until close().

    raster_threads, when given, is llvmpipe's LP_NUM_THREADS for this display (unless the environment sets it):
    0 rasterises on the calling thread. Mesa reads it when the display is initialised."""

    def __init__(self, raster_threads: int | None = None) -> None:
        self._egl = self._display = self._context = None
        with render_errors(self.close):
            self._egl = egl = _egl()
            self._display = _display(egl)
            major, minor = egl.EGLint(), egl.EGLint()
            with _raster_threads(raster_threads):
                up = bool(self._display) and egl.eglInitialize(self._display, ctypes.byref(major), ctypes.byref(minor))
            if not up:
                raise RenderError(f"{EGL_HELP} (no EGL display could be initialised).")
            configs, count = (egl.EGLConfig * 1)(), egl.EGLint()
            attributes = (egl.EGLint * 13)(  # no depth: the id pass renders into its own framebuffer
                egl.EGL_SURFACE_TYPE, egl.EGL_PBUFFER_BIT, egl.EGL_RED_SIZE, 8, egl.EGL_GREEN_SIZE, 8,
                egl.EGL_BLUE_SIZE, 8, egl.EGL_RENDERABLE_TYPE, egl.EGL_OPENGL_BIT, egl.EGL_CONFORMANT,
                egl.EGL_OPENGL_BIT, egl.EGL_NONE)
            if not egl.eglChooseConfig(self._display, attributes, configs, 1, ctypes.byref(count)) or count.value < 1:
                raise RenderError(f"{EGL_HELP} (the EGL driver offers no desktop OpenGL configuration).")
            if not egl.eglBindAPI(egl.EGL_OPENGL_API):
                raise RenderError(f"{EGL_HELP} (the EGL driver cannot bind desktop OpenGL).")
            version = (egl.EGLint * 7)(
                egl.EGL_CONTEXT_MAJOR_VERSION, 4, egl.EGL_CONTEXT_MINOR_VERSION, 1,
                egl.EGL_CONTEXT_OPENGL_PROFILE_MASK, egl.EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, egl.EGL_NONE)
            self._context = egl.eglCreateContext(self._display, configs[0], egl.EGL_NO_CONTEXT, version)
            if not self._context:
                raise RenderError(f"{EGL_HELP} (the EGL driver could not create an OpenGL 4.1 context).")
            if not egl.eglMakeCurrent(self._display, egl.EGL_NO_SURFACE, egl.EGL_NO_SURFACE, self._context):
                raise RenderError(f"{EGL_HELP} (the OpenGL context could not be made current).")

    def close(self) -> None:
        """Release the context and the display (safe to call twice, or after a failed start)."""
        egl = self._egl
        try:
            if egl is not None and self._context:
                egl.eglMakeCurrent(self._display, egl.EGL_NO_SURFACE, egl.EGL_NO_SURFACE, egl.EGL_NO_CONTEXT)
                egl.eglDestroyContext(self._display, self._context)
            if egl is not None and self._display:
                egl.eglTerminate(self._display)
        except Exception:  # a context that never came up has nothing to free
            pass
        self._context = self._display = None
