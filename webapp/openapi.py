"""The OpenAPI 3.1 document of /api/v1 (kept next to the routes; a test checks that both match)."""

from __future__ import annotations

from converter.options import OptionField, option_fields
from converter.outputs import OUTPUTS, choices, required_by
from webapp.storage import result_files

UPLOAD_FIELDS = {
    "file": "the animation: glTF/GLB, a zip of numbered OBJ frames, or an OBJ mesh (with 'cache')",
    "cache": "PC2 or MDD point cache for an OBJ mesh",
}
JSON_TYPES = {bool: "boolean", int: "integer", float: "number", str: "string"}


def _file_description(spec: OptionField) -> str:
    needed = required_by(spec.name)
    return spec.meta.help + (f" (required with to={' or '.join(needed)})" if needed else "")


def _option_property(spec: OptionField) -> dict:
    """The JSON schema of one scalar option, from its metadata."""
    prop = {"type": JSON_TYPES[spec.type], "description": spec.meta.help}
    if spec.default is not None:
        prop["default"] = spec.default
    kinds = choices(spec)
    if kinds:
        prop["enum"] = list(kinds)
    meta = spec.meta
    if meta.minimum is not None:
        prop["exclusiveMinimum" if meta.exclusive_minimum else "minimum"] = meta.minimum
    if meta.maximum is not None:
        prop["maximum"] = meta.maximum
    return prop


def _option_schema() -> dict:
    return {spec.name: _option_property(spec) for spec in option_fields() if not spec.meta.path}


def _error(description: str) -> dict:
    return {"description": description,
            "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}}


def _job_response(description: str) -> dict:
    return {"description": description,
            "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Job"}}}}


TOO_LARGE = ("the request body is larger than the server's upload limit (FACESVG_MAX_UPLOAD_MB, 100 MB unless set); "
             "the error names the limit. A body up to as much again over it (FACESVG_DRAIN_MB) is still read and "
             "discarded so a client that sends it whole before reading gets this answer; a longer declared body is "
             "refused as soon as its headers arrive, and such a client may see the connection closed instead")


JOB_ID = {"name": "job_id", "in": "path", "required": True, "schema": {"type": "string", "pattern": "^[0-9a-f]{32}$"}}


def openapi_document() -> dict:
    """The whole OpenAPI document."""
    files = {**UPLOAD_FIELDS, **{spec.name: _file_description(spec) for spec in option_fields() if spec.meta.path}}
    upload_props = {k: {"type": "string", "format": "binary", "description": v} for k, v in files.items()}
    upload_props["sample"] = {"type": "string", "enum": ["1"], "description": "convert the bundled sample instead"}
    upload_props.update(_option_schema())
    return {
        "openapi": "3.1.0",
        "info": {"title": "facesvg API", "version": "1",
                 "description": "Convert 3D facial animation to "
                                + ", ".join(f"{k.label} (to={k.name})" for k in OUTPUTS.values())
                                + ". Jobs run "
                                "in the background; poll GET /jobs/{job_id} until state is done or failed. "
                                "DELETE cancels a queued job, removes a finished one, and asks a running one to "
                                "stop (202; it is removed when its worker reaches the next progress step)."},
        "servers": [{"url": "/api/v1"}],
        "paths": {
            "/health": {"get": {"summary": "Liveness and queue backend", "operationId": "health",
                                "responses": {"200": {"description": "the server is up"}}}},
            "/openapi.json": {"get": {"summary": "This document", "operationId": "openapi",
                                      "responses": {"200": {"description": "OpenAPI document"}}}},
            "/jobs": {
                "get": {"summary": "Recent jobs, newest first", "operationId": "listJobs",
                        "parameters": [{"name": "limit", "in": "query", "schema": {"type": "integer",
                                                                                     "minimum": 1, "maximum": 500}}],
                        "responses": {"200": {"description": "jobs", "content": {"application/json": {"schema": {
                            "type": "object", "properties": {"jobs": {"type": "array", "items": {
                                "$ref": "#/components/schemas/Job"}}}}}}},
                            "400": _error("bad limit")}},
                "post": {"summary": "Submit a conversion job", "operationId": "createJob",
                         "requestBody": {"required": True, "content": {"multipart/form-data": {"schema": {
                             "type": "object", "properties": upload_props}}}},
                         "responses": {"202": _job_response("queued; Location names the job"),
                                       "400": _error("bad input or options (message says what to fix)"),
                                       "401": _error("API keys are on and none (or a wrong one) was sent"),
                                       "403": _error("sent by a page of another web site"),
                                       "413": _error(TOO_LARGE),
                                       "429": _error("too many submissions from this client; see Retry-After"),
                                       "503": _error("the queue is full; see Retry-After")}},
            },
            "/jobs/{job_id}": {
                "parameters": [JOB_ID],
                "get": {"summary": "State, stage, progress and error of a job", "operationId": "getJob",
                        "responses": {"200": _job_response("the job"), "404": _error("no such job")}},
                "delete": {"summary": "Cancel (queued), delete (finished) or stop (running) a job",
                           "operationId": "deleteJob",
                           "responses": {"204": {"description": "cancelled or deleted"},
                                         "202": {"description": "running; it stops at its next progress step"},
                                         "404": _error("no such job")}},
            },
            "/inspect": {
                "post": {"summary": "Describe a face (clips, parts and nodes, morph targets) or a take (its capture "
                                    "layout) without converting it", "operationId": "inspectUpload",
                         "requestBody": {"required": True, "content": {"multipart/form-data": {"schema": {
                             "type": "object", "properties": {"file": {
                                 "type": "string", "format": "binary",
                                 "description": "a face (as the file field of POST /jobs) or a take (as weights)"},
                                 "role": {"type": "string", "enum": ["face", "take"],
                                          "description": "read the file as this (default: by its content)"}},
                             "required": ["file"]}}}},
                         "responses": {"200": {"description": "kind (face or take); a face's animations (index, "
                                                              "name), frame_on (parts and nodes), morph_targets; a "
                                                              "take's layout, frames, fps; driven_by (the layouts)"},
                                       "400": _error("no file, or a file facesvg cannot read"),
                                       "413": _error(TOO_LARGE)}},
            },
            "/jobs/{job_id}/result": {
                "parameters": [JOB_ID],
                "get": {"summary": "The main output (SVG, or the fap2d package)", "operationId": "getResult",
                        "parameters": [{"name": "download", "in": "query", "schema": {"type": "string"}}],
                        "responses": {"200": {"description": "the file", "content": {
                            media: {} for media in dict.fromkeys(k.files[0].media_type for k in OUTPUTS.values())}},
                            "404": _error("no such job"), "409": _error("the job is not done")}},
            },
            "/jobs/{job_id}/result/{kind}": {
                "parameters": [JOB_ID, {"name": "kind", "in": "path", "required": True,
                                        "schema": {"type": "string", "enum": list(result_files())}}],
                "get": {"summary": "One output by kind", "operationId": "getResultKind",
                        "parameters": [{"name": "download", "in": "query", "schema": {"type": "string"}}],
                        "responses": {"200": {"description": "the file (the report as strict JSON: a figure that "
                                                              "could not be measured is null)"},
                                      "404": _error("no such job or kind"), "409": _error("the job is not done"),
                                      "500": _error("the job's stored report is damaged")}},
            },
            "/jobs/{job_id}/preview/{frame}": {
                "parameters": [JOB_ID, {"name": "frame", "in": "path", "required": True,
                                        "schema": {"type": "integer", "minimum": 0}}],
                "get": {"summary": "3D prerender PNG of a frame listed in result.preview_frames",
                        "operationId": "getPreview",
                        "responses": {"200": {"description": "PNG", "content": {"image/png": {}}},
                                      "404": _error("no such job or frame"), "409": _error("not done")}},
            },
        },
        "components": {"securitySchemes": {"apiKey": {
            "type": "http", "scheme": "bearer",
            "description": "When the server sets FACESVG_API_KEYS, send a key as 'Authorization: Bearer KEY' (or "
                           "'X-API-Key: KEY'); each key then sees and deletes only its own jobs. Requests a "
                           "browser sends from another web site are refused (403)."}},
            "schemas": {
            "Error": {"type": "object", "properties": {"error": {"type": "string"}, "status": {"type": "integer"}}},
            "Job": {"type": "object", "properties": {
                "id": {"type": "string"},
                "state": {"type": "string", "enum": ["queued", "running", "done", "failed", "cancelling",
                                                     "cancelled"]},
                "stage": {"type": "string"}, "progress": {"type": "number"}, "percent": {"type": "integer"},
                "error": {"type": ["string", "null"]}, "filename": {"type": "string"},
                "files": {"type": "object", "description": "the user's file name of each upload by field: input "
                                                           "(the face), weights (the take), ..."},
                "input_kind": {"type": "string"}, "options": {"type": "object", "properties": _option_schema()},
                "created": {"type": "number"}, "started": {"type": ["number", "null"]},
                "finished": {"type": ["number", "null"]},
                "queue_position": {"type": ["integer", "null"],
                                   "description": "1 for the next job to start; null unless queued"},
                "eta_seconds": {"type": ["number", "null"],
                                "description": "estimated seconds until done, from the stage progress and recent "
                                               "jobs; null when finished or while estimating"},
                "estimating": {"type": "boolean",
                               "description": "true while an active job's ETA has no basis yet (too little "
                                              "progress measured, or no job has finished on this server)"},
                "result": {"type": "object", "description": "report, frames, fps, duration, preview_frames, "
                                                            "outputs (bytes per kind)"},
                "links": {"type": "object"}}},
        }},
    }
