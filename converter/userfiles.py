"""Files a user names: reading them (every failure becomes one InputError sentence), hashing, atomic writes."""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

from converter.errors import InputError


def read_bytes(path: str | Path, what: str = "", missing_hint: str = "") -> bytes:
    """The file's bytes; InputError saying what is wrong (missing, a folder, unreadable) otherwise."""
    path = Path(path)
    label = f"{what} {path}".strip()
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{label} does not exist{missing_hint}.") from None
    except IsADirectoryError:
        raise InputError(f"{label} is a folder; give a file.") from None
    except OSError as exc:
        raise InputError(f"cannot read {label}: {exc.strerror}.") from None


def check_output(path: str | Path) -> Path:
    """The output path, after checking it can be written: not a folder, its folder exists."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"output {path} is a folder; give a file name.")
    if not path.parent.exists():
        raise InputError(f"the output folder {path.parent} does not exist.")
    return path


def file_sha256(path: str | Path) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def write_atomic(path: str | Path, data: bytes) -> None:
    """Write bytes to path through a temporary file in the same folder and a rename: never half-written."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent or ".")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the file the usual permissions
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
