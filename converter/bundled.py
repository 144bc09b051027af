"""Files shipped with facesvg: the bundled sample face, the web UI's templates and static files.

A checkout keeps them in top-level folders (samples/, templates/, static/); the wheel's build hook (setup.py)
copies them into the packages (converter/samples/, webapp/templates/, webapp/static/), so an installed facesvg
finds them as package resources.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

CHECKOUT = Path(__file__).resolve().parents[1]


def asset_dir(package: str, name: str) -> Path:
    """Folder `name` shipped inside `package` (installed wheel), else the checkout's top-level folder `name`."""
    shipped = resources.files(package) / name
    if shipped.is_dir():
        return Path(str(shipped))
    return CHECKOUT / name


def sample_path() -> Path:
    """The bundled sample face (glTF binary, ICT FaceKit derived, MIT)."""
    return asset_dir("converter", "samples") / "face.glb"
