"""The web form and API take an ARKit weight capture that drives the uploaded face's morph targets."""

from __future__ import annotations

import io
import json

import pytest

from conftest import SAMPLE
from web.conftest import wait_job


@pytest.mark.parametrize("app", ["embedded"], indirect=True)
def test_weights_upload_drives_the_face(client):
    capture = json.dumps([{"time": k / 10, "blendshapes": {"jawOpen": k / 7, "eyeBlinkLeft": 0.5, "noseSneerLeft": 1}}
                          for k in range(8)]).encode()
    r = client.post("/api/v1/jobs", data={
        "file": (io.BytesIO(SAMPLE.read_bytes()), "face.glb"), "size": "96", "occlusion": "0",
        "weights": (io.BytesIO(capture), "take.json"),
    }, content_type="multipart/form-data")
    assert r.status_code == 202, r.get_json()
    job = wait_job(client, r.get_json()["id"], timeout=240)
    assert job["state"] == "done", job["error"]
    counts = job["result"]["report"]["counts"]
    assert counts["weights_matched"] == 2 and counts["weights_unmatched"] == 1 and counts["frames"] == 8
    assert any("noseSneerLeft" in w for w in job["result"]["report"]["warnings"])


@pytest.mark.parametrize("app", ["embedded"], indirect=True)
def test_upload_form_offers_the_weights_field(client):
    html = client.get("/").get_data(as_text=True)
    assert 'name="weights"' in html and 'type="file"' in html
