"""Errors a user can cause, and failures of the machine they run on."""


class FacesvgError(Exception):
    """Base class of every error facesvg raises on purpose."""


class InputError(FacesvgError):
    """The user's input or options are wrong; the message says what and what to do."""


class RenderError(FacesvgError):
    """Offscreen rendering is unavailable or failed; the message names what to install."""
