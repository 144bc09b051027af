"""The web app as a new user meets it, in headless Chromium at 1280 px and on a 390 px phone (issue 50): a face and
a take side by side and the job naming both, names typed with suggestions from the file, one player fitted to the
frame with the prerender following it, the API page within a phone's width, an ETA that says "estimating" first,
and a loading note until a large result has loaded."""

from __future__ import annotations

import json
import time

import pytest

from conftest import SAMPLE
from converter.outputs import OUTPUTS
from web.conftest import LiveServer, make_app

pytestmark = [pytest.mark.browser, pytest.mark.slow]

WIDTHS = {"desktop": (1280, 900), "phone": (390, 844)}
TAKE = json.dumps([{"time": k / 10, "blendshapes": {"jawOpen": k / 7, "eyeBlinkLeft": k / 8}}
                   for k in range(8)]).encode()
RECORD_ETA = """
document.addEventListener('DOMContentLoaded', () => {
  const el = document.getElementById('eta');
  if (!el) return;
  const log = () => {
    const seen = JSON.parse(sessionStorage.getItem('eta') || '[]');
    if (el.textContent.trim()) seen.push(el.textContent.trim());
    sessionStorage.setItem('eta', JSON.stringify(seen));
  };
  log();
  new MutationObserver(log).observe(el, {childList: true, characterData: true, subtree: true});
});
"""


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    if not SAMPLE.is_file():
        pytest.skip("the bundled sample is missing")
    s = LiveServer(make_app(tmp_path_factory.mktemp("newuser"), "embedded", FACESVG_EXECUTOR="thread",
                            FACESVG_WORKERS=1, FACESVG_PREVIEW_FRAMES=6, WTF_CSRF_ENABLED=True))
    yield s
    s.close()


@pytest.fixture(scope="module")
def take_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("take") / "my take.json"
    path.write_bytes(TAKE)
    return path


def new_page(browser, width: str):
    w, h = WIDTHS[width]
    return browser.new_context(viewport={"width": w, "height": h}).new_page()


def no_overflow(page) -> bool:
    """The page is no wider than the viewport (nothing scrolls sideways)."""
    return page.evaluate("document.documentElement.scrollWidth <= window.innerWidth")


def inside(inner: dict, outer: dict, slack: float = 1.0) -> bool:
    return (inner["x"] >= outer["x"] - slack and inner["y"] >= outer["y"] - slack
            and inner["x"] + inner["width"] <= outer["x"] + outer["width"] + slack
            and inner["y"] + inner["height"] <= outer["y"] + outer["height"] + slack)


def until(page, script: str, timeout: float = 30.0) -> None:
    """Evaluate script until it is true (page.wait_for_function evaluates strings, which the page's CSP forbids)."""
    end = time.monotonic() + timeout
    while not page.evaluate(script):
        assert time.monotonic() < end, f"never true: {script}"
        page.wait_for_timeout(100)


def wait_done(page, timeout: float = 240_000) -> None:
    page.wait_for_url("**/jobs/*")
    page.wait_for_selector("#player", timeout=timeout)
    assert page.text_content("#job-state") == "done"


def submit_small(page, **values) -> None:
    """Fill the few options that keep a conversion quick, then Convert."""
    page.fill("#opt-size", values.pop("size", "96"))
    page.click("details.more summary")
    page.uncheck("input[type=checkbox][name=occlusion]")
    for name, value in values.items():
        page.fill(f"#opt-{name}", value)
    page.click("#convert")


@pytest.mark.parametrize("width", list(WIDTHS))
def test_a_face_and_a_take_side_by_side_with_suggestions_and_the_job_names_both(browser, server, take_file, width,
                                                                               artifacts):
    page = new_page(browser, width)
    page.goto(server.url + "/")
    face, take = page.locator("#drop").bounding_box(), page.locator("#take-drop").bounding_box()
    vw = WIDTHS[width][0]
    assert face["x"] + face["width"] <= vw and take["x"] + take["width"] <= vw and no_overflow(page)
    if width == "desktop":  # side by side
        assert abs(face["y"] - take["y"]) < 2 and take["x"] >= face["x"] + face["width"]
    else:  # one above the other on a phone
        assert take["y"] >= face["y"] + face["height"]
    assert "A take" in page.text_content("#take-drop") and "Live Link Face" in page.text_content("#take-hint")

    page.set_input_files("#file", str(SAMPLE))
    page.set_input_files("#file-weights", str(take_file))
    until(page, "document.getElementById('face-info').textContent.includes('morph targets')")
    until(page, "document.getElementById('take-info').textContent.includes('frames')")
    assert "8 frames" in page.text_content("#take-info")
    clips = page.eval_on_selector_all("#suggest-animation option", "os => os.map(o => o.value)")
    parts = page.eval_on_selector_all("#suggest-frame_on option", "os => os.map(o => o.value)")
    assert "all" in clips and "smile_jaw_blink_brow" in clips, clips
    assert {"head", "skin"} <= set(parts), parts
    assert page.get_attribute("#opt-animation", "type") == "text"
    assert page.get_attribute("#opt-frame_on", "type") == "text"
    page.screenshot(path=str(artifacts / f"web_face_and_take_{width}.png"), full_page=True)

    submit_small(page, frame_on="head", end="6")
    page.wait_for_url("**/jobs/*")
    assert page.text_content("#input-face") == SAMPLE.name
    assert page.text_content("#input-take") == take_file.name
    wait_done(page)
    assert page.text_content("#input-take") == take_file.name and no_overflow(page)
    page.screenshot(path=str(artifacts / f"web_job_with_take_{width}.png"), full_page=True)
    assert "frame_on" not in page.text_content("#figures") and "--" not in page.text_content("main")
    page.goto(server.url + "/jobs")
    row = page.locator("table.jobs tbody tr").first.text_content()
    assert SAMPLE.name in row and take_file.name in row


def test_a_refused_take_is_named_by_the_users_file(browser, server, tmp_path):
    bad = tmp_path / "session notes.json"
    bad.write_text('{"hello": "world"}')
    page = new_page(browser, "desktop")
    page.goto(server.url + "/")
    page.set_input_files("#file-weights", str(bad))
    until(page, "document.getElementById('take-info').textContent.length > 0")
    assert "session notes.json" in page.text_content("#take-info")
    page.set_input_files("#file", str(SAMPLE))
    page.click("#convert")
    page.wait_for_selector("#form-error")
    error = page.text_content("#form-error")
    assert "“session notes.json”" in error and "weights.json" not in error, error


@pytest.fixture(scope="module")
def player_job(browser, server):
    """A finished player-output job's page address."""
    page = new_page(browser, "desktop")
    page.goto(server.url + "/")
    page.set_input_files("#file", str(SAMPLE))
    page.select_option("#opt-to", "player")
    submit_small(page, size="256", end="24")
    wait_done(page)
    yield page.url
    page.context.close()


@pytest.mark.parametrize("width", list(WIDTHS))
def test_one_player_fitted_to_the_frame_and_the_prerender_follows_it(browser, player_job, width, artifacts):
    page = new_page(browser, width)
    page.goto(player_job)
    assert page.locator("#play").count() == 0  # no second set of controls: the output's own player
    frame = page.frame_locator("#player-view")
    frame.locator("#facesvg-player[data-state=ready]").wait_for(timeout=60_000)
    page.wait_for_selector("#view-loading", state="hidden")
    iframe = page.locator("#player-view")
    iframe.scroll_into_view_if_needed()
    page.wait_for_timeout(300)  # the frame has been fitted to its player
    box = iframe.bounding_box()
    vw = WIDTHS[width][0]
    assert box["x"] >= 0 and box["x"] + box["width"] <= vw
    for control in ("#facesvg-canvas", "#facesvg-play", "#facesvg-scrub", "#facesvg-time"):
        inner = frame.locator(control).bounding_box()
        assert inner is not None and inside(inner, box), (control, inner, box)
    assert no_overflow(page)
    page.screenshot(path=str(artifacts / f"web_player_{width}.png"), full_page=True)
    # The prerender follows the player's clock: seek the player, the prerender shows that frame.
    fps = float(page.get_attribute("#player", "data-fps"))
    previews = json.loads(page.get_attribute("#player", "data-previews"))
    target = previews[len(previews) // 2]
    page.evaluate(f"document.getElementById('player-view').contentWindow.facesvgPlayer.seek({target / fps})")
    until(page, f"document.getElementById('player').dataset.followed === '{target}'")
    assert page.text_content("#prerender-label") == f"frame {target}"
    assert page.get_attribute("#prerender", "src").endswith(f"/preview/{target}")
    assert "KB" in page.text_content("#fig-html")  # the player's size is shown


def test_the_api_page_fits_a_phone_and_names_every_output(browser, server):
    page = new_page(browser, "phone")
    page.goto(server.url + "/docs/api")
    assert no_overflow(page), page.evaluate("document.documentElement.scrollWidth")
    outputs = page.text_content("#outputs")
    for kind in OUTPUTS.values():
        assert kind.name in outputs and kind.label in outputs
    assert "player" in outputs


def test_the_eta_says_estimating_until_it_has_a_basis(browser, tmp_path):
    s = LiveServer(make_app(tmp_path, "embedded", FACESVG_EXECUTOR="thread", FACESVG_WORKERS=1,
                            FACESVG_PREVIEW_FRAMES=4, WTF_CSRF_ENABLED=True))
    try:
        context = browser.new_context(viewport={"width": 390, "height": 844})
        context.add_init_script(RECORD_ETA)
        page = context.new_page()
        page.goto(s.url + "/")
        page.set_input_files("#file", str(SAMPLE))
        page.fill("#opt-size", "384")
        page.click("#convert")
        wait_done(page)
        seen = page.evaluate("JSON.parse(sessionStorage.getItem('eta') || '[]')")
        assert seen and "estimating" in seen[0], seen
        first_figure = next((i for i, t in enumerate(seen) if "Done in" in t), len(seen))
        assert all("estimating" in t for t in seen[:first_figure]), seen
    finally:
        s.close()


def test_a_large_result_says_loading_until_it_has_loaded(browser, server):
    page = new_page(browser, "desktop")
    page.goto(server.url + "/jobs")
    link = page.locator("table.jobs tbody tr td a").first
    if link.count() == 0:
        pytest.skip("no finished job in this module's server")
    held = []
    page.route("**/result/svg", lambda route: held.append(route))
    page.route("**/result/html", lambda route: held.append(route))
    link.click()
    page.wait_for_selector("#player")
    deadline = time.monotonic() + 10
    while not held and time.monotonic() < deadline:
        page.wait_for_timeout(100)
    assert held, "the result was not requested"
    assert page.is_visible("#view-loading") and "Loading" in page.text_content("#view-loading")
    for route in held:
        route.continue_()
    page.wait_for_selector("#view-loading", state="hidden", timeout=30_000)
