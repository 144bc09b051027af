"""The real pages in headless Chromium: drop the bundled sample, watch progress, play, download, phone width."""

from __future__ import annotations

import base64
import io

import numpy as np
import pytest
from lxml import etree
from PIL import Image

from converter.options import PRESETS
from web.conftest import LiveServer, make_app

pytestmark = [pytest.mark.browser, pytest.mark.slow]

RECORD_PROGRESS = """
document.addEventListener('DOMContentLoaded', () => {
  const el = document.getElementById('percent');
  if (!el) return;
  const log = () => {
    const seen = JSON.parse(sessionStorage.getItem('seen') || '[]');
    seen.push(parseInt(el.textContent, 10));
    sessionStorage.setItem('seen', JSON.stringify(seen));
  };
  log();
  new MutationObserver(log).observe(el, {childList: true, characterData: true, subtree: true});
});
"""


@pytest.fixture
def server(tmp_path, sample_file):
    s = LiveServer(make_app(tmp_path, "embedded", FACESVG_EXECUTOR="process", FACESVG_WORKERS=1,
                            FACESVG_SAMPLE=str(sample_file), FACESVG_PREVIEW_FRAMES=12,
                            WTF_CSRF_ENABLED=True))
    yield s
    s.close()


def small_options(page) -> None:
    """Keep the conversion quick: small size, a short frame range, no occlusion pass."""
    page.fill("#opt-size", "128")
    page.fill("#opt-yaw", "25")
    page.fill("#opt-pitch", "15")
    page.click("details.more summary")
    page.fill("#opt-end", "12")
    page.uncheck("input[type=checkbox][name=occlusion]")


def png(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"), np.int16)



def until(take, ok, timeout: float = 10.0):
    """Take screenshots until ok(image) or the timeout (slow machines paint late); returns the last one."""
    import time

    end = time.monotonic() + timeout
    img = take()
    while not ok(img) and time.monotonic() < end:
        time.sleep(0.2)
        img = take()
    return img


def moved(a, b) -> bool:
    """Two screenshots differ visibly: some pixels change by more than 40 levels over 0.2% of the view."""
    d = np.abs(a.astype(int) - b.astype(int)).max(axis=2)
    return bool(d.max() > 40 and (d > 40).mean() > 0.002)

def test_drop_sample_watch_progress_play_and_download(browser, server, sample_file, artifacts):
    context = browser.new_context(viewport={"width": 1280, "height": 900}, accept_downloads=True)
    context.add_init_script(RECORD_PROGRESS)
    page = context.new_page()
    page.goto(server.url + "/")
    page.screenshot(path=str(artifacts / "web_upload.png"), full_page=True)
    # Drag and drop the bundled sample onto the drop zone, as a person would.
    payload = base64.b64encode(sample_file.read_bytes()).decode()
    page.evaluate("""([name, b64]) => {
        const bytes = Uint8Array.from(atob(b64), c => c.charCodeAt(0));
        const dt = new DataTransfer();
        dt.items.add(new File([bytes], name, {type: 'model/gltf-binary'}));
        const drop = document.getElementById('drop');
        for (const type of ['dragenter', 'dragover', 'drop'])
          drop.dispatchEvent(new DragEvent(type, {dataTransfer: dt, bubbles: true, cancelable: true}));
    }""", [sample_file.name, payload])
    assert page.text_content("#file-name") == sample_file.name
    assert page.evaluate("document.getElementById('file').files.length") == 1
    small_options(page)
    page.click("#convert")
    page.wait_for_url("**/jobs/*")
    page.wait_for_selector("#player", timeout=180_000)
    seen = page.evaluate("JSON.parse(sessionStorage.getItem('seen') || '[]')")
    assert seen and seen[-1] == 100 and seen == sorted(seen), seen  # the bar moved forward to 100 %
    assert page.text_content("#job-state") == "done"
    assert int(page.text_content("#fig-triangles").split()[0]) > 0
    assert "KB" in page.text_content("#fig-svg")
    assert "Largest drawing error, measured" in page.text_content("#fidelity")  # the verifier's figures are shown
    page.wait_for_function("document.getElementById('svg-view').contentDocument?.documentElement?.tagName === 'svg'")
    page.screenshot(path=str(artifacts / "web_result.png"), full_page=True)

    # Play: the inline SVG shows different pictures at two times.
    view = page.locator("#svg-view")
    page.click("#play")
    assert page.get_attribute("#play", "aria-pressed") == "true"
    a = until(lambda: png(view.screenshot()), lambda img: (img < 200).any(axis=2).mean() > 0.01)  # painted
    b = until(lambda: png(view.screenshot()), lambda img: moved(a, img))
    assert moved(a, b), "the inline SVG did not change while playing"
    # Keyboard: pause with Enter on the focused button, then End on the slider seeks the last frame.
    page.focus("#play")
    page.keyboard.press("Enter")
    assert page.get_attribute("#play", "aria-pressed") == "false"
    page.focus("#frame-slider")
    page.keyboard.press("Home")
    first_src = page.get_attribute("#prerender", "src")
    assert first_src.endswith("/preview/0")
    page.keyboard.press("End")
    last = int(page.get_attribute("#frame-slider", "max"))
    assert page.input_value("#frame-slider") == str(last)
    assert page.text_content("#frame-label").startswith(f"frame {last} /")
    assert page.get_attribute("#prerender", "src").endswith(f"/preview/{last}")
    assert page.get_attribute("#prerender", "src") != first_src or last == 0
    t = page.evaluate("document.getElementById('svg-view').contentDocument.documentElement.getCurrentTime()")
    fps = float(page.get_attribute("#player", "data-fps"))
    assert abs(t - last / fps) < 1e-3
    page.screenshot(path=str(artifacts / "web_result_last_frame.png"))

    # Download the SVG and parse it.
    with page.expect_download() as info:
        page.click("#dl-svg")
    path = info.value.path()
    root = etree.parse(str(path)).getroot()
    assert root.tag == "{http://www.w3.org/2000/svg}svg"
    assert root.find(".//{*}metadata") is not None and root.findall(".//{*}animate")
    result_url = page.url

    # Phone width: nothing overflows sideways and the two views stack.
    phone = browser.new_context(viewport={"width": 390, "height": 844}, device_scale_factor=2, is_mobile=True,
                                has_touch=True)
    p = phone.new_page()
    for name, url in (("web_phone_upload.png", server.url + "/"), ("web_phone_result.png", result_url)):
        p.goto(url)
        assert p.evaluate("document.documentElement.scrollWidth") <= 390
        p.screenshot(path=str(artifacts / name), full_page=True)
    boxes = [p.locator("figure.view").nth(i).bounding_box() for i in range(2)]
    assert boxes[1]["y"] >= boxes[0]["y"] + boxes[0]["height"] - 1
    assert boxes[0]["width"] > 300
    phone.close()
    context.close()


def test_try_the_bundled_sample_is_one_click(browser, server, artifacts):
    page = browser.new_page(viewport={"width": 1024, "height": 800})
    page.goto(server.url + "/")
    small_options(page)
    page.click("#try-sample")
    page.wait_for_url("**/jobs/*")
    page.wait_for_selector("#player", timeout=180_000)
    assert page.text_content("#job-state") == "done"
    page.keyboard.press("Tab")
    assert page.evaluate("document.activeElement.className") == "skip"  # the first Tab offers the skip link
    page.goto(server.url + "/jobs")
    assert page.locator("table.jobs tbody tr").count() == 1
    page.screenshot(path=str(artifacts / "web_jobs.png"))
    page.close()


def test_preset_refill_delete_confirmation_and_same_origin_player(browser, server):
    """The mobile preset fills its fields, "Try again" refills the form, the pages raise no CSP violation,
    the fap2d player refuses a package from another origin, and deleting asks first."""
    import time

    from webapp.jobstore import Job

    q = server.app.extensions["facesvg_queue"]
    q.store.add(Job(id="f" * 32, state="failed", created=time.time(), message="broken; see --max-triangles.",
                    options={"size": 333, "shading": "gouraud", "max_triangles": 700}))
    page = browser.new_page(viewport={"width": 1024, "height": 800})
    violations = []
    page.on("console", lambda m: violations.append(m.text) if "Content Security Policy" in m.text else None)
    try:
        page.goto(server.url + "/")
        page.click("#preset-mobile")
        mobile = PRESETS["mobile"].values
        assert page.input_value("#opt-size") == str(mobile["size"])
        assert page.input_value("#opt-max_triangles") == str(mobile["max_triangles"])
        page.goto(server.url + "/jobs/" + "f" * 32)
        assert "“Triangle budget”" in page.text_content("#job-error")
        page.click("#try-again")
        assert page.input_value("#opt-size") == "333" and page.input_value("#opt-max_triangles") == "700"
        assert page.input_value("#opt-shading") == "gouraud"  # a select, refilled by the page script
        page.goto(server.url + "/jobs/" + "f" * 32)
        assert not page.is_visible("#delete-yes")  # one click shows the question, a second one deletes
        page.click("#delete-confirm summary")
        page.click("#delete-yes")
        page.wait_for_url(server.url + "/jobs")
        assert q.get("f" * 32) is None
        page.goto(server.url + "/static/fap2d.html?src=http://example.com/evil.zip")
        page.wait_for_function("() => document.getElementById('status').textContent.startsWith('Refused')")
        page.goto(server.url + "/static/fap2d.html?src=//example.com/evil.zip")
        page.wait_for_function("() => document.getElementById('status').textContent.startsWith('Refused')")
        page.goto(server.url + "/docs/api")
        assert page.is_visible("#createJob")
        assert violations == []
    finally:
        page.close()
