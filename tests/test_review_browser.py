"""The review page in a real browser: Debian's chromium + chromedriver, driven by Selenium.

The page is opened from a file:// URL (no server). One test edits an association by keyboard
and mouse, saves it and feeds the CSV to ``map-compare --associate``; one loads a review of
2,000 landmarks per map and times the first paint and a filter change with
``performance.now()`` inside the page. Screenshots go to the test's tmp folder (and to
``$SLAMREL_ARTIFACTS`` when set, for CI to keep); they are checked to be non-blank.
Without chromium, chromedriver or selenium the tests skip — and fail under ``CI=true``.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from landmark_graph.maps import LandmarkMap
from slamrel.cli import main
from slamrel.formats.landmark_maps import write_map

# the full tier: a real browser (chromium under Selenium) takes seconds to start and to drive
pytestmark = pytest.mark.slow


def _missing(message: str) -> None:
    message += "; .ci/run installs chromium and chromium-driver, pip install '.[test]' selenium"
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(message)
    pytest.skip(message)


@pytest.fixture(scope="module")
def browser():
    """A headless Chromium under Selenium, with Debian's chromedriver (never downloaded)."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        _missing("selenium is not installed")
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    if chromium is None or driver is None:
        _missing(f"chromium ({chromium}) or chromedriver ({driver}) not found")
    opts = webdriver.ChromeOptions()
    opts.binary_location = chromium
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1400,900", "--no-first-run", "--disable-background-networking",
                "--disable-component-update", "--disable-sync"):  # fmt: skip
        opts.add_argument(arg)
    d = webdriver.Chrome(service=Service(driver), options=opts)
    d.set_script_timeout(30)
    yield d
    d.quit()


def _shot(d, path: Path, element=None) -> Path:
    """A screenshot of the page (or of one element), checked non-blank, also copied to
    $SLAMREL_ARTIFACTS."""
    import matplotlib.image as mpimg

    if element is None:
        d.save_screenshot(str(path))
    else:
        element.screenshot(str(path))
    img = mpimg.imread(path)[..., :3]
    ink = np.mean(np.any(img < 0.85, axis=-1))  # anything not (nearly) white
    colour = np.mean(img.max(axis=-1) - img.min(axis=-1) > 0.2)  # coloured pixels
    assert ink > 0.01 and colour > 0.001, (path, ink, colour)
    if os.environ.get("SLAMREL_ARTIFACTS"):
        out = Path(os.environ["SLAMREL_ARTIFACTS"])
        out.mkdir(parents=True, exist_ok=True)
        shutil.copy(path, out / path.name)
    return path


def _no_errors(d) -> None:
    """The page logged no error (an exception in a handler would show here)."""
    severe = [e["message"] for e in d.get_log("browser") if e["level"] == "SEVERE"]
    assert not severe, severe


def _open(d, page: Path) -> None:
    d.get(page.resolve().as_uri())
    assert d.execute_script("return !!window.slamrelReview"), d.get_log("browser")


def _maps(tmp_path: Path, rng) -> tuple[Path, Path]:
    """30 reference landmarks 0..29; the estimate (rotated, shifted, 3 cm noise) has 0..27 with
    5 and 6 swapped, and 100 placed 0.4 m from reference 28 (by id: 28 pairs, 2 missed —
    28 and 29 — and 1 spurious, 100)."""
    ref_xy = np.column_stack((np.arange(30) % 6 * 8.0, np.arange(30) // 6 * 8.0))
    ref_xy += rng.uniform(-2, 2, ref_xy.shape)
    a = 0.4
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    est_xy = (ref_xy - [5.0, 3.0]) @ rot + rng.normal(0, 0.03, ref_xy.shape)  # rot.T inverse
    est_xy[28] += [0.4, 0.0] @ rot
    ids = np.r_[np.arange(28), 100]
    ids[[5, 6]] = ids[[6, 5]]
    write_map(tmp_path / "est.csv", LandmarkMap(ids, est_xy[:29]))
    write_map(tmp_path / "ref.csv", LandmarkMap(np.arange(30), ref_xy))
    return tmp_path / "est.csv", tmp_path / "ref.csv"


def _click_landmark(d, side: str, landmark: int) -> None:
    from selenium.webdriver.common.action_chains import ActionChains

    canvas = d.find_element("id", "map")
    x, y = d.execute_script(f"return slamrelReview.screenOf('{side}', {landmark})")
    w, h = d.execute_script("return slamrelReview.canvasSize()")
    # Selenium 4 offsets are from the element's centre
    ActionChains(d).move_to_element_with_offset(
        canvas, int(round(x - w / 2)), int(round(y - h / 2))
    ).click().perform()


def _keys(d, keys: str) -> None:
    from selenium.webdriver.common.action_chains import ActionChains

    ActionChains(d).send_keys(keys).perform()


def _status(d) -> dict[tuple[int, int], str]:
    return {(p["estimate"], p["reference"]): p["status"]
            for p in d.execute_script("return slamrelReview.pairs()")}  # fmt: skip


def test_reject_draw_save_and_map_compare_reads_it(browser, tmp_path, rng, capsys):
    d = browser
    est, ref = _maps(tmp_path, rng)
    page = tmp_path / "review.html"
    assert main(["review", str(est), str(ref), "--associate", "id", "-o", str(page), "-q"]) == 0
    _open(d, page)
    d.find_element("tag name", "body").click()
    # keyboard: the most suspicious pair is one of the swapped ones; reject it, undo, redo
    _keys(d, "n")
    first = {k for k, s in _status(d).items()}
    sel = d.execute_script(
        "const p = slamrelReview.pairs(); return [p.length, document.getElementById('pair-info')"
        ".textContent]"
    )
    assert sel[0] == 28 and ("estimate 5 " in sel[1] or "estimate 6 " in sel[1]), sel
    _keys(d, "r")
    rejected = [k for k, s in _status(d).items() if s == "rejected"]
    assert len(rejected) == 1 and rejected[0] in {(5, 5), (6, 6)}, rejected
    _keys(d, "u")
    assert "rejected" not in _status(d).values()
    _keys(d, "r")  # undo selected the pair it restored
    assert [k for k, s in _status(d).items() if s == "rejected"] == rejected
    # the unmatched list proposes the correction: estimate 100 is 0.4 m from reference 28
    rows = [r.text.split() for r in d.find_elements("css selector", "#unmatched tbody tr")]
    assert rows[0][:2] == ["100", "28"] and abs(float(rows[0][2]) - 0.4) < 0.15, rows
    # mouse: draw the pair estimate 100 - reference 28 by clicking the two landmarks
    d.find_element("id", "fit").click()
    d.find_element("id", "draw").click()
    _click_landmark(d, "estimate", 100)
    _click_landmark(d, "reference", 28)
    status = _status(d)
    assert status.get((100, 28)) == "added", d.find_element("id", "status").text
    assert set(status) == first | {(100, 28)}
    _shot(d, tmp_path / "review_page.png")
    # save: the CSV appears in the page (and as a download link)
    d.find_element("id", "save").click()
    text = d.find_element("id", "csv-output").get_property("value")
    assert d.find_element("id", "download").get_attribute("href").startswith("blob:")
    saved = tmp_path / "association.csv"
    saved.write_text(text)
    # the oracle: by id 28 pairs, 2 missed (28, 29), 1 spurious (100); rejecting one pair and
    # drawing 100-28 leaves 28 pairs, missed {29, the rejected reference}, spurious {its estimate}
    out = tmp_path / "mc.json"
    rc = main(["map-compare", str(est), str(ref), "--associate", str(saved), "--json", str(out),
               "-q"])  # fmt: skip
    assert rc == 0, capsys.readouterr().err
    a = json.loads(out.read_text())["association"]
    e_rej, r_rej = rejected[0]
    assert (a["matched"], a["missed"], a["spurious"]) == (28, 2, 1)
    assert sorted(a["missed_ids"]) == sorted([r_rej, 29]) and a["spurious_ids"] == [e_rej]
    # continue the review: a fresh page loads the file back to the same state and the same CSV
    _open(d, page)
    d.find_element("id", "load").send_keys(str(saved))
    d.execute_script("return new Promise(r => setTimeout(r, 200))")
    assert _status(d) == status
    assert d.execute_script("return slamrelReview.csv()") == text
    _no_errors(d)


def test_pan_zoom_and_shift_click(browser, tmp_path, rng):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    d = browser
    est, ref = _maps(tmp_path, rng)
    page = tmp_path / "review.html"
    assert main(["review", str(est), str(ref), "-o", str(page), "-q"]) == 0
    _open(d, page)
    canvas = d.find_element("id", "map")

    def at(landmark):
        return np.array(d.execute_script(f"return slamrelReview.screenOf('reference', {landmark})"))

    a0, b0 = at(0), at(29)
    # drag: everything moves with the mouse
    ActionChains(d).move_to_element(canvas).click_and_hold().move_by_offset(60, 0).move_by_offset(
        0, 40
    ).release().perform()
    np.testing.assert_allclose(at(0) - a0, [60, 40], atol=1.5)
    # "+" zooms by 1.5 about the centre: distances on screen grow by 1.5
    d.find_element("tag name", "body").send_keys("+")
    assert np.linalg.norm(at(29) - at(0)) == pytest.approx(1.5 * np.linalg.norm(b0 - a0), rel=1e-6)
    # the wheel zooms about the cursor: the landmark under it stays put
    w, h = d.execute_script("return slamrelReview.canvasSize()")
    k = min(range(30), key=lambda k: np.linalg.norm(at(k) - [w / 2, h / 2]))  # on screen
    x, y = at(k)
    from selenium.webdriver.common.actions.wheel_input import ScrollOrigin

    origin = ScrollOrigin.from_element(canvas, int(round(x - w / 2)), int(round(y - h / 2)))
    ActionChains(d).scroll_from_origin(origin, 0, -100).perform()
    d.execute_script("return new Promise(r => requestAnimationFrame(() => r()))")
    np.testing.assert_allclose(at(k), [x, y], atol=1.5)
    assert np.linalg.norm(at(29) - at(0)) > 1.5 * np.linalg.norm(b0 - a0) * 1.1
    # Shift+click twice pairs without the draw button; Esc cancels a half-drawn pair
    d.find_element("id", "fit").click()
    for side, landmark in (("estimate", 100), ("reference", 28)):
        x, y = d.execute_script(f"return slamrelReview.screenOf('{side}', {landmark})")
        ActionChains(d).key_down(Keys.SHIFT).move_to_element_with_offset(
            canvas, int(round(x - w / 2)), int(round(y - h / 2))
        ).click().key_up(Keys.SHIFT).perform()
    assert _status(d).get((100, 28)) == "added"
    _keys(d, "d")
    _click_landmark(d, "estimate", 0)
    _keys(d, Keys.ESCAPE)
    _click_landmark(d, "reference", 29)  # a plain click now: selects, pairs nothing
    assert sum(s == "added" for s in _status(d).values()) == 1
    _no_errors(d)


def test_two_thousand_landmarks_paint_and_filter_within_a_second(browser, tmp_path, rng):
    d = browser
    n = 2000
    ref = LandmarkMap(np.arange(n), rng.uniform(0, 600, (n, 2)))
    est = LandmarkMap(np.arange(n), ref.xy + rng.normal(0, 0.3, (n, 2)))
    write_map(tmp_path / "est.csv", est)
    write_map(tmp_path / "ref.csv", ref)
    page = tmp_path / "review2000.html"
    assert main(["review", str(tmp_path / "est.csv"), str(tmp_path / "ref.csv"),
                 "--associate", "id", "-o", str(page), "-q"]) == 0  # fmt: skip
    _open(d, page)
    t = d.execute_script("return slamrelReview.timings")
    # ms since navigation start: parse + JSON + first drawing, and the first frame after it
    assert t["firstPaint"] < 1000 and t["firstFrame"] < 1000, t
    filter_ms = d.execute_async_script(
        """
        const done = arguments[arguments.length - 1];
        const el = document.getElementById("min-residual");
        const t0 = performance.now();
        el.value = "0.4";
        el.dispatchEvent(new Event("input"));
        // after the frame that shows the change
        requestAnimationFrame(() => setTimeout(() => done(performance.now() - t0), 0));
        """
    )
    assert filter_ms < 1000, filter_ms
    shown = d.execute_script("return slamrelReview.pairs().filter(p => p.residual >= 0.4).length")
    assert f"of {shown} pairs" in d.find_element("id", "list-note").text
    nav_ms = d.execute_async_script(
        """
        const done = arguments[arguments.length - 1];
        const t0 = performance.now();
        document.dispatchEvent(new KeyboardEvent("keydown", {key: "n"}));
        document.dispatchEvent(new KeyboardEvent("keydown", {key: "r"}));
        requestAnimationFrame(() => setTimeout(() => done(performance.now() - t0), 0));
        """
    )
    assert nav_ms < 1000, nav_ms
    assert [p["status"] for p in d.execute_script("return slamrelReview.pairs()")].count(
        "rejected"
    ) == 1
    _shot(d, tmp_path / "review_2000.png")
    _no_errors(d)
    print(
        f"review page, {n} landmarks per map: first paint {t['firstPaint']:.0f} ms, first "
        f"frame {t['firstFrame']:.0f} ms, render {t['lastRender']:.1f} ms; filter change "
        f"{filter_ms:.0f} ms; next+reject {nav_ms:.0f} ms"
    )


def test_report_opens_with_its_verdict_and_links_the_review(browser, tmp_path, quickstart_run):
    d = browser
    html = quickstart_run.html
    d.get(html.as_uri())
    verdict = d.find_element("id", "verdict")
    # the verdict is the first thing under the title, inside the first screen
    assert verdict.location["y"] < 200, verdict.location
    levels = [e.text for e in verdict.find_elements("css selector", "td .lamp")]
    assert levels and set(levels) <= {"green", "amber", "red", "info"}, levels
    assert "info" in levels  # the map accuracies: information lines, grey
    # each judgement is shown in its own colour (Chrome reports rgba)
    rgb = {
        "green": (26, 127, 55), "amber": (183, 121, 31), "red": (180, 35, 24),
        "info": (107, 114, 128),
    }  # fmt: skip
    for lamp in verdict.find_elements("css selector", ".lamp"):
        r, g, b = rgb[lamp.text]
        assert lamp.value_of_css_property("background-color") == f"rgba({r}, {g}, {b}, 1)"
    _shot(d, tmp_path / "report_verdict.png", verdict)
    toc = [a.get_attribute("href").rsplit("#", 1)[1] for a in d.find_elements(
        "css selector", "nav a")]  # fmt: skip
    assert toc and all(d.find_elements("id", t) for t in toc), toc
    link = d.find_element("css selector", 'a[href="review.html"]')
    link.click()
    assert d.execute_script("return !!window.slamrelReview"), d.current_url
    assert d.execute_script("return slamrelReview.pairs().length") > 0
