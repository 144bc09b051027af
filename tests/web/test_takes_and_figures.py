"""Issue 50 without a browser: a take is a first-class input named by the user's file, text options are text and
validated where the CLI validates them, the inspect endpoint lists what `facesvg info` lists, figures are in the
user's words, a Mobile job offers no mobile version, the ETA waits for a basis, and the mobile estimate is within
25 % of what the Mobile preset makes of the bundled sample."""

from __future__ import annotations

import io
import json
import time

import pytest

from conftest import SAMPLE
from converter.convert import convert
from converter.formats import captures
from converter.options import PRESETS, ConversionOptions
from web.conftest import SMALL, wait_job
from webapp.eta import MIN_BASIS_SECONDS, standing
from webapp.jobstore import DONE, QUEUED, RUNNING, Job, SQLiteStore
from webapp.messages import user_words, with_user_names
from webapp.presets import estimate_sizes

TAKE = json.dumps([{"time": k / 10, "blendshapes": {"jawOpen": k / 7}} for k in range(6)]).encode()
EMBEDDED = pytest.mark.parametrize("app", ["embedded"], indirect=True)


def post(client, **fields):
    data = {**SMALL, "end": "4", "file": (io.BytesIO(SAMPLE.read_bytes()), "my face.glb"), **fields}
    return client.post("/api/v1/jobs", data=data, content_type="multipart/form-data")


@EMBEDDED
def test_the_job_and_the_list_name_the_face_and_the_take(client):
    r = post(client, weights=(io.BytesIO(TAKE), "Monday take.json"))
    assert r.status_code == 202, r.get_json()
    job = wait_job(client, r.get_json()["id"], timeout=240)
    assert job["state"] == "done", job["error"]
    assert job["files"] == {"input": "my face.glb", "weights": "Monday take.json"}
    assert job["result"]["morph_targets"] > 0  # what the take drove
    page = client.get(job["links"]["page"]).get_data(as_text=True)
    assert '<strong id="input-take">Monday take.json</strong>' in page
    assert '<strong id="input-face">my face.glb</strong>' in page
    listing = client.get("/jobs").get_data(as_text=True)
    assert "Monday take.json" in listing and "my face.glb" in listing


@EMBEDDED
def test_a_refused_take_is_named_by_the_users_file_not_ours(client):
    r = post(client, weights=(io.BytesIO(b'{"hello": "world"}'), "notes from the shoot.json"))
    assert r.status_code == 400
    error = r.get_json()["error"]
    assert "“notes from the shoot.json”" in error and "weights.json" not in error, error
    assert captures.LAYOUTS[0].label in error  # and it names what it reads
    form = client.post("/jobs", data={"file": (io.BytesIO(SAMPLE.read_bytes()), "face.glb"),
                                      "weights": (io.BytesIO(b""), "empty take.csv")},
                       content_type="multipart/form-data")
    assert form.status_code == 400 and "empty take.csv" in form.get_data(as_text=True)


def test_a_converter_message_names_the_users_files():
    stored, names = {"input": "input.glb", "weights": "weights.csv"}, {"input": "a.glb", "weights": "take 1.csv"}
    message = "weights.csv has no frames; /srv/jobs/x/inputs/weights.csv was read with 'input.glb'."
    assert with_user_names(message, stored, names) == "“take 1.csv” has no frames; “take 1.csv” was read with “a.glb”."
    assert with_user_names("xweights.csv stays", stored, names) == "xweights.csv stays"


def test_command_line_flags_read_as_the_forms_words():
    text = user_words("framed the head (Wolf3D_Head); --frame-on NAME frames another part or node")
    assert "--" not in text and "NAME" not in text and "“Frame on part or node”" in text
    assert user_words("clips not played (choose with --animation NAME|INDEX|all).") == \
        "clips not played (choose with “Animation”)."


@EMBEDDED
def test_names_are_typed_and_checked_where_the_cli_checks_them(client):
    r = post(client, animation="smile_jaw_blink_brow", frame_on="head")
    assert r.status_code == 202, r.get_json()
    job = wait_job(client, r.get_json()["id"], timeout=240)
    assert job["state"] == "done", job["error"]
    assert job["options"]["animation"] == "smile_jaw_blink_brow" and job["options"]["frame_on"] == "head"
    bad = wait_job(client, post(client, animation="no such clip").get_json()["id"], timeout=240)
    assert bad["state"] == "failed" and "“Animation”" in bad["error"] and "--" not in bad["error"], bad["error"]
    assert "smile_jaw_blink_brow" in bad["error"]  # the clips it has
    bad = wait_job(client, post(client, frame_on="tail").get_json()["id"], timeout=240)
    assert bad["state"] == "failed" and "“Frame on part or node”" in bad["error"] and "head" in bad["error"]


@EMBEDDED
def test_inspect_lists_clips_parts_nodes_and_morph_targets_or_a_takes_layout(client):
    face = client.post("/api/v1/inspect", data={"file": (io.BytesIO(SAMPLE.read_bytes()), "face.glb")},
                       content_type="multipart/form-data").get_json()
    assert face["kind"] == "face" and face["morph_targets"] > 0
    assert [c["name"] for c in face["animations"]] == ["smile_jaw_blink_brow"]
    assert {"head", "skin"} <= set(face["frame_on"])
    assert face["driven_by"] == [layout.label for layout in captures.LAYOUTS]
    take = client.post("/api/v1/inspect", data={"file": (io.BytesIO(TAKE), "t.json")},
                       content_type="multipart/form-data").get_json()
    assert take["kind"] == "take" and take["frames"] == 6 and take["fps"] == pytest.approx(10)
    bad = client.post("/api/v1/inspect", data={"file": (io.BytesIO(b'{"a": 1}'), "odd.json"), "role": "face"},
                      content_type="multipart/form-data")
    assert bad.status_code == 400 and "odd.json" in bad.get_json()["error"]
    assert "input." not in bad.get_json()["error"]


def plant(queue, job_id: str, options: dict, result: dict, files: dict | None = None) -> None:
    now = time.time()
    queue.store.add(Job(id=job_id, state=DONE, stage="done", progress=1.0, filename="avatar.glb", kind="glb",
                        options=options, files=files or {"input": "input.glb"}, created=now - 5, started=now - 4,
                        finished=now, result=result))
    out = queue.storage.out(job_id)
    (out / "result.svg").write_bytes(b'<svg xmlns="http://www.w3.org/2000/svg" width="8" height="8"/>')


def svg_result(**extra) -> dict:
    report = {"counts": {"triangles": 4000, "triangles_kept": 2000, "frames": 1},
              "figures": {"playback_ms_4x": 12.04, "keys_per_path": 3.5, "budget_deviation_px": 35.83,
                          "within_tolerance": True, "tolerance_px": 0.5},
              "sizes": {}, "warnings": ["framed the head (Wolf3D_Head); --frame-on NAME frames another part or node"]}
    return {"report": report, "frames": 1, "fps": 30.0, "duration": 0.033, "size": 256, "preview_frames": [],
            "still": None, "outputs": {"svg": 400_000}, "media_type": "image/svg+xml", **extra}


@EMBEDDED
def test_a_face_alone_is_a_still_that_says_a_take_can_drive_it(app, client):
    q = app.extensions["facesvg_queue"]
    plant(q, "e" * 32, {"to": "svg", "shading": "flat", "size": 256}, svg_result(morph_targets=52))
    page = client.get("/jobs/" + "e" * 32).get_data(as_text=True)
    assert 'id="undriven"' in page and "52 morph targets" in page and captures.LAYOUTS[0].label in page
    assert "SVG still" in page and "Animated SVG result" not in page and 'id="play"' not in page
    # the figures in words, with units; no command-line flag in the warnings
    assert "Playback cost on a slow phone" in page and "12 ms a frame" in page and "playback_ms_4x" not in page
    assert "keys per path" not in page and "35.8 px" in page and "--frame-on" not in page


@EMBEDDED
def test_a_mobile_job_offers_no_mobile_version_and_others_an_estimate(app, client):
    q = app.extensions["facesvg_queue"]
    mobile = {"to": "svg", "shading": "flat", **PRESETS["mobile"].values}
    plant(q, "f" * 32, mobile, svg_result())
    page = client.get("/jobs/" + "f" * 32).get_data(as_text=True)
    assert 'id="estimate-mobile"' not in page and "Make a mobile version" not in page and 'id="made-mobile"' in page
    plant(q, "0" * 32, {"to": "svg", "shading": "flat", "size": 512, "preset": "mobile"}, svg_result())
    assert "Make a mobile version" not in client.get("/jobs/" + "0" * 32).get_data(as_text=True)
    plant(q, "1" * 32, {"to": "svg", "shading": "flat", "size": 512}, svg_result())
    page = client.get("/jobs/" + "1" * 32).get_data(as_text=True)
    assert 'id="estimate-mobile"' in page and "Make a mobile version" in page
    assert "about " in page.split('id="estimate-mobile"')[1].split("</p>")[0]  # the figure, at the fitted options
    plant(q, "2" * 32, {"to": "svg", "shading": "flat", "size": 96}, svg_result())
    page = client.get("/jobs/" + "2" * 32).get_data(as_text=True)
    estimate = page.split('id="estimate-mobile"')[1].split("</p>")[0]
    assert "Make a mobile version" in estimate and "KB" not in estimate  # no figure the model cannot vouch for


def test_the_eta_is_estimating_until_progress_was_measured_over_some_time(tmp_path):
    from types import SimpleNamespace

    store = SQLiteStore(tmp_path / "eta.sqlite3")
    now = time.time()
    store.add(Job(id="1" * 32, state=RUNNING, created=now - 1, started=now - 0.5, progress=0.2))
    store.add(Job(id="2" * 32, state=QUEUED, created=now))
    queue = SimpleNamespace(store=store, recent=store.recent, workers=1)
    early = standing(queue, store.get("1" * 32))
    assert early["eta_seconds"] is None and early["estimating"] is True  # 20 % in half a second: no basis yet
    queued = standing(queue, store.get("2" * 32))
    assert queued["eta_seconds"] is None and queued["estimating"] is True  # no job has finished here yet
    store.transition("1" * 32, (RUNNING,), progress_origin={"time": now - MIN_BASIS_SECONDS - 1, "progress": 0.1},
                     progress=0.5)
    later = standing(queue, store.get("1" * 32))
    done = (0.5 - 0.1) / 0.9  # of what was left at the origin, in MIN_BASIS_SECONDS + 1 s
    expected = (MIN_BASIS_SECONDS + 1) / done * (1 - done)
    assert later["estimating"] is False and later["eta_seconds"] == pytest.approx(expected, abs=0.2)
    store.close()


@pytest.mark.slow
def test_the_mobile_estimate_is_within_a_quarter_of_what_the_preset_makes_of_the_sample():
    made = {}
    for name, options in (("default", ConversionOptions()), ("mobile", ConversionOptions(preset="mobile"))):
        result = convert(SAMPLE, options)
        made[name] = (len(result.data), result.report.to_json())
    size, report = made["default"]
    job = Job(id="2" * 32, state=DONE, options={"to": "svg", "shading": "flat", "size": 512},
              result={"outputs": {"svg": size}, "report": report})
    (estimate,) = estimate_sizes(job)
    assert estimate["name"] == "mobile"
    assert abs(estimate["svg"] / made["mobile"][0] - 1) <= 0.25, (estimate, made["mobile"][0])


def test_triangle_budget_figures_read_in_words():
    from webapp.pages import figure_rows

    rows = {k: (label, text) for k, label, text in figure_rows(
        {"budget_coverage_kept_Wolf3D_Hair": 0.953, "budget_within_bound": False, "budget_bound_px": 5.0})}
    assert rows["budget_coverage_kept_Wolf3D_Hair"] == ("Pixels of Wolf3D_Hair still shown after the triangle budget",
                                                        "95.3 %")
    assert rows["budget_within_bound"][1] == "no" and rows["budget_bound_px"][1] == "5 px"
    assert not any("_" in label for label, _ in rows.values() if "Wolf3D" not in label)
