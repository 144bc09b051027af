"""Turn a submitted form (HTML or API) into a stored, checked, queued job."""

from __future__ import annotations

import shutil
from pathlib import Path

from werkzeug.datastructures import FileStorage, ImmutableMultiDict
from werkzeug.utils import secure_filename

from converter.errors import InputError
from converter.formats import captures
from converter.options import ConversionOptions, option_fields
from converter.outputs import output_kind
from webapp.jobstore import Job
from webapp.limits import check_options
from webapp.storage import new_job_id
from webapp.uploads import EXTRA_FIELDS, check_extra, check_main_input, stored_name

OPTION_FIELDS = tuple(spec.name for spec in option_fields() if not spec.meta.path)  # path options come as uploads
CONTROL_FIELDS = ("csrf_token", "sample", "file", *EXTRA_FIELDS)


def parse_options(form: ImmutableMultiDict, strict: bool) -> dict:
    """Scalar options from a form (the last value of each field wins, so a hidden 0 + checkbox 1 works)."""
    data = {}
    for key in form.keys():
        name = key.replace("-", "_")
        if name in OPTION_FIELDS:
            data[name] = form.getlist(key)[-1]
        elif strict and name not in CONTROL_FIELDS:
            raise InputError(f"unknown field {key!r}; see /api/v1/openapi.json for the accepted fields.")
    options = ConversionOptions.from_mapping(data)
    output_kind(options.to)  # an unknown kind is refused here, before anything is stored
    return {k: v for k, v in options.to_json().items() if k in OPTION_FIELDS}


def _present(upload: FileStorage | None) -> bool:
    return upload is not None and bool(upload.filename)


def create_job(queue, config, form: ImmutableMultiDict, files: ImmutableMultiDict, strict: bool = False,
               client: str = "") -> Job:
    """Validate options and uploads, store them under generated names, queue the job; InputError if bad."""
    options = parse_options(form, strict)
    check_options(options)
    use_sample = form.get("sample", "") in ("1", "true", "on", "yes")
    upload = files.get("file")
    if not use_sample and not _present(upload):
        raise InputError("choose an animation file to upload (glTF/GLB, a zip of OBJ frames, or OBJ + point "
                         "cache), or try the bundled sample.")
    kind = output_kind(options["to"])
    if not all(_present(files.get(name)) for name in kind.requires):
        raise InputError(f"the {kind.label} needs {kind.requires_text}; add them or choose another output.")
    storage = queue.storage
    job_id = new_job_id()
    inputs = storage.inputs(job_id)
    max_unzipped = int(config["FACESVG_MAX_UNZIPPED_MB"]) << 20
    try:
        if use_sample:
            sample = Path(config["FACESVG_SAMPLE"])
            if not sample.is_file():
                raise InputError("the bundled sample is missing from this installation; upload a file instead.")
            tmp = inputs / "upload.tmp"
            shutil.copyfile(sample, tmp)
            filename = sample.name
        else:
            tmp = inputs / "upload.tmp"
            upload.save(tmp)
            filename = upload.filename
        kind = check_main_input(tmp, max_unzipped)
        stored = {"input": stored_name("input", filename, kind)}
        names = {"input": display_name(filename)}
        tmp.rename(inputs / stored["input"])
        for role in EXTRA_FIELDS:
            extra = files.get(role)
            if not _present(extra):
                continue
            name = stored_name(role, extra.filename)
            extra.save(inputs / name)
            check_extra(inputs / name, "take" if role == "weights" else role, max_unzipped,
                        display_name(extra.filename))
            if role == "clone_target":
                check_main_input(inputs / name, max_unzipped)
            if role == "weights":
                check_take(inputs / name, display_name(extra.filename))
            stored[role] = name
            names[role] = display_name(extra.filename)
        if kind == "obj" and "cache" not in stored:
            raise InputError("an OBJ mesh needs its animation: add a PC2 or MDD point cache file.")
    except BaseException:
        storage.delete(job_id)
        raise
    job = Job(id=job_id, filename=display_name(filename), kind=kind, options=options, files=stored, names=names,
              client=client)
    queue.submit(job)
    return job


def check_take(path: Path, name: str) -> None:
    """InputError, naming the user's file, unless path holds a capture layout facesvg reads."""
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    if captures.detect(head) is None:
        captures.parse_capture(path.read_bytes(), f"“{name}”")  # raises the reader's words (empty, bad JSON, ...)


def display_name(filename: str) -> str:
    """The uploaded name trimmed for display (escaped by the templates; never used as a path)."""
    name = (filename or "upload").replace("\\", "/").rsplit("/", 1)[-1]
    return name[:120]


def download_stem(job: Job) -> str:
    """A safe file stem for downloads, from the uploaded name."""
    return secure_filename(Path(job.filename).stem)[:60] or "face"
