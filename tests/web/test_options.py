"""One registry of output kinds and one set of option metadata: the CLI, the upload form and OpenAPI all offer them.

Expectations are derived from the ConversionOptions dataclass itself (its fields, defaults and metadata) and from
converter.outputs.OUTPUTS, never listed here, so a field or kind added in one place only makes these tests fail.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import MISSING, fields

import pytest
from lxml import html

from converter import outputs
from converter.cli import build_parser, main, options_from_args
from converter.convert import convert
from converter.errors import InputError
from converter.options import ConversionOptions
from converter.outputs import OutputFile, OutputKind
from web.conftest import glb_bytes, make_app

OTHER_FORM_FIELDS = {"csrf_token", "file", "cache"}  # upload controls that are not conversion options
OTHER_API_FIELDS = {"file", "sample", "cache"}
JSON_TYPES = {"bool": "boolean", "int": "integer", "float": "number", "str": "string"}


def expected_fields() -> list[dict]:
    """Name, default, choices, range and kind of every ConversionOptions field, read from the dataclass."""
    out = []
    for f in fields(ConversionOptions):
        meta = f.metadata["option"]
        assert f.default is not MISSING, f"{f.name} has no default"
        kinds = list(outputs.OUTPUTS) if meta.output_kinds else (list(meta.choices) if meta.choices else None)
        out.append({"name": f.name, "default": f.default, "choices": kinds, "min": meta.minimum,
                    "max": meta.maximum, "exclusive": meta.exclusive_minimum, "path": meta.path,
                    "form": meta.form, "bool": isinstance(f.default, bool), "type": str(f.type).split()[0]})
    return out


def cli_actions() -> dict:
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    return {a.dest: a for a in sub.choices["convert"]._actions}


@pytest.fixture
def web(tmp_path):
    app = make_app(tmp_path, "embedded")
    yield app.test_client()
    app.extensions["facesvg_queue"].close()


def upload_props(client) -> dict:
    doc = client.get("/api/v1/openapi.json").get_json()
    return doc["paths"]["/jobs"]["post"]["requestBody"]["content"]["multipart/form-data"]["schema"]["properties"]


def form_controls(client):
    page = html.fromstring(client.get("/").data)
    return page.get_element_by_id("upload-form")


def test_every_option_is_on_the_command_line_with_its_default_and_choices():
    actions = cli_actions()
    for e in expected_fields():
        a = actions[e["name"]]
        dashed = e["name"].replace("_", "-")
        flag = f"--no-{dashed}" if e["bool"] and e["default"] else f"--{dashed}"
        assert a.option_strings == [flag], e["name"]
        # A flag not given stays unset (so a --preset can fill it); its help says the default it takes then.
        assert a.default == argparse.SUPPRESS, e["name"]
        if not e["bool"] and e["default"] is not None:
            assert f"(default {e['default']})" in a.help, e["name"]
        assert (list(a.choices) if a.choices else None) == e["choices"], e["name"]
    # ... and the parser builds exactly those options back
    args = build_parser().parse_args(["convert", "x.glb"])
    assert not set(vars(args)) & {f.name for f in fields(ConversionOptions)}  # nothing given, nothing set
    assert options_from_args(args) == ConversionOptions()


def test_every_option_is_in_openapi_with_its_default_choices_and_range(web):
    props = upload_props(web)
    names = {e["name"] for e in expected_fields()}
    assert set(props) - names == OTHER_API_FIELDS  # nothing documented that is not an option or an upload
    for e in expected_fields():
        p = props[e["name"]]
        if e["path"]:
            assert p["format"] == "binary", e["name"]
            continue
        assert p.get("default") == e["default"], e["name"]
        assert p.get("enum") == e["choices"], e["name"]
        assert p.get("maximum") == e["max"], e["name"]
        assert p.get("exclusiveMinimum" if e["exclusive"] else "minimum") == e["min"], e["name"]
        assert p["type"] == JSON_TYPES[e["type"]], e["name"]


def test_every_option_is_in_the_upload_form_with_its_default_choices_and_range(web):
    form = form_controls(web)
    named = {el.get("name") for el in form.iter("input", "select")}
    expected = expected_fields()
    assert named - {e["name"] for e in expected} == OTHER_FORM_FIELDS
    for e in expected:
        controls = [el for el in form.iter("input", "select") if el.get("name") == e["name"]]
        if not e["form"]:
            assert controls == [], f"{e['name']} is marked form=False but the form offers it"
            continue
        assert controls, f"the form has no control for {e['name']}"
        el = controls[-1]
        if e["path"]:
            assert el.get("type") == "file", e["name"]
        elif e["choices"] is not None:
            assert el.tag == "select", e["name"]
            assert [o.get("value") for o in el.iter("option")] == e["choices"], e["name"]
            assert [o.get("value") for o in el.iter("option") if o.get("selected") is not None] == [e["default"]]
        elif e["bool"]:
            assert el.get("type") == "checkbox", e["name"]
            assert (el.get("checked") is not None) == e["default"], e["name"]
        elif e["type"] == "str":  # a name (a clip, a part or node): typed, with suggestions from the file
            assert el.get("type") == "text", e["name"]
            assert form.find(f".//datalist[@id='{el.get('list')}']") is not None, e["name"]
            assert el.get("value") == ("" if e["default"] is None else str(e["default"])), e["name"]
        else:
            assert el.get("type") == "number", e["name"]
            assert el.get("value") == ("" if e["default"] is None else str(e["default"])), e["name"]
            assert el.get("min") == (None if e["min"] is None else str(e["min"])), e["name"]
            assert el.get("max") == (None if e["max"] is None else str(e["max"])), e["name"]


def test_validation_follows_the_same_ranges_and_choices():
    for e in expected_fields():
        if e["choices"] is not None and e["name"] != "to":
            with pytest.raises(InputError, match="choose one of"):
                ConversionOptions(**{e["name"]: "no-such-choice"})
        if e["max"] is not None:
            with pytest.raises(InputError, match="must be"):
                ConversionOptions(**{e["name"]: e["max"] + 1})
            ConversionOptions(**{e["name"]: e["max"]})
        if e["min"] is not None:
            with pytest.raises(InputError, match="must be"):
                ConversionOptions(**{e["name"]: e["min"] - 1 if not e["exclusive"] else e["min"]})


def fake_writer(sheet, options, report, progress) -> bytes:
    """A stand-in writer of a JSON format (Rive-like): the frame count and the kept triangles as JSON."""
    return json.dumps({"frames": sheet.n_frames, "triangles": int(sheet.kept.sum())}).encode()


@pytest.fixture
def rive(monkeypatch):
    """An extra output kind, registered the way a new writer would be: one OutputKind entry."""
    kind = OutputKind("rive", "Rive animation", fake_writer,
                      (OutputFile("rive", "Rive (JSON)", ".json", "application/json", download_suffix=".rive.json"),))
    monkeypatch.setitem(outputs.OUTPUTS, "rive", kind)
    return kind


def test_an_extra_output_kind_is_offered_everywhere(rive, web, tmp_path):
    assert "rive" in cli_actions()["to"].choices
    assert upload_props(web)["to"]["enum"][-1] == "rive"
    doc = web.get("/api/v1/openapi.json").get_json()
    kinds = doc["paths"]["/jobs/{job_id}/result/{kind}"]["parameters"][1]["schema"]["enum"]
    assert "rive" in kinds
    to = form_controls(web).get_element_by_id("opt-to")
    assert {o.get("value"): o.text_content() for o in to.iter("option")}["rive"] == "Rive animation"
    # ... and it converts: the CLI names the file with the kind's extension and writes what its writer wrote.
    src = tmp_path / "cube.glb"
    src.write_bytes(glb_bytes())
    assert main(["convert", str(src), "--to", "rive", "--size", "64", "--no-occlusion", "-q"]) == 0
    svg = convert(src, ConversionOptions(size=64, occlusion=False))
    assert json.loads((tmp_path / "cube.json").read_bytes()) == {
        "frames": svg.report.counts["frames"], "triangles": svg.report.counts["triangles_kept"]}


def test_an_unknown_output_kind_is_refused_by_the_api(web):
    r = web.post("/api/v1/jobs", data={"to": "rive", "sample": "1"}, content_type="multipart/form-data")
    assert r.status_code == 400 and "unknown output kind 'rive'" in r.get_json()["error"]
