"""Reading files a user names: every failure becomes one InputError sentence."""

from __future__ import annotations

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
