"""Job folders on disk: generated names only, atomic writes, deletion and retention."""

from __future__ import annotations

import re
import shutil
import uuid
from pathlib import Path

from converter.outputs import output_files

JOB_ID = re.compile(r"^[0-9a-f]{32}$")
REPORT = ("report.json", "application/json")  # every finished job's report, beside its output files


def result_files() -> dict[str, tuple[str, str]]:
    """Files a finished job may hold, by the kind name the API uses: (stored file name, media type)."""
    files = {key: (f"result{f.suffix}", f.media_type) for key, f in output_files().items()}
    return {**files, "report": REPORT}


def new_job_id() -> str:
    """A fresh random job id (32 hex digits); never derived from user input."""
    return uuid.uuid4().hex


def is_job_id(value: str) -> bool:
    """True when value has the shape of a job id."""
    return bool(JOB_ID.match(value or ""))


class Storage:
    """One folder per job under root: inputs (inputs/), outputs (out/), previews (out/preview-K.png)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    def job_dir(self, job_id: str) -> Path:
        """The folder of a job (not created)."""
        if not is_job_id(job_id):
            raise ValueError(f"not a job id: {job_id!r}")
        return self.root / job_id

    def inputs(self, job_id: str) -> Path:
        """The job's input folder, created on demand."""
        path = self.job_dir(job_id) / "inputs"
        path.mkdir(parents=True, exist_ok=True)
        return path

    def out(self, job_id: str) -> Path:
        """The job's output folder, created on demand."""
        path = self.job_dir(job_id) / "out"
        path.mkdir(parents=True, exist_ok=True)
        return path

    def result_path(self, job_id: str, kind: str) -> Path | None:
        """The file of a result kind if it exists, else None."""
        files = result_files()
        if kind not in files:
            return None
        path = self.job_dir(job_id) / "out" / files[kind][0]
        return path if path.is_file() else None

    def preview_path(self, job_id: str, frame: int) -> Path | None:
        """The 3D prerender PNG of a frame if it exists."""
        path = self.job_dir(job_id) / "out" / f"preview-{int(frame)}.png"
        return path if path.is_file() else None

    def available(self, job_id: str) -> list[str]:
        """The result kinds present on disk, in a fixed order."""
        return [k for k in result_files() if self.result_path(job_id, k)]

    def delete(self, job_id: str) -> None:
        """Remove a job's folder and everything in it (missing is fine)."""
        shutil.rmtree(self.job_dir(job_id), ignore_errors=True)

    def job_ids(self) -> list[str]:
        """Ids of every job folder on disk."""
        return sorted(p.name for p in self.root.iterdir() if p.is_dir() and is_job_id(p.name))

