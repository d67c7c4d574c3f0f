"""Every report of a quick run of the S1 studies, opened in headless Chromium as a reader would open it:
the page loads without a console error, every image decodes, and every paper table carries the
publication's column. CI installs Debian's chromium; elsewhere the test is skipped, saying why."""

from __future__ import annotations

import json
import os
import shutil

import numpy as np
import pytest

from softtip.published import tables_of
from softtip._core.systems import is_own, owner, studies
from softtip.studies.reproduce import reproduce_study, write_index

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def _browser():
    reason = None
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        reason = "playwright is not installed (pip install -e '.[test]')"
    if CHROMIUM is None:
        reason = "Debian's chromium is not installed (apt-get install chromium)"
    if reason is not None:
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI must check the reports in a browser: {reason}")
        pytest.skip(reason)
    return sync_playwright


def own_studies() -> dict:
    """softtip's own studies (the coarse protocols below are written for its designs), not those of a system
    installed beside it."""
    return {name: study for name, study in studies().items() if is_own(owner("study", name))}


@pytest.fixture(scope="module")
def reports(tmp_path_factory, coarse_protocol):
    """Every study's report from a quick run on coarse meshes and few conditions: the reports' structure,
    not the studies' figures."""
    directory = tmp_path_factory.mktemp("reports")
    for name, study in own_studies().items():
        design = "rectangular" if name in ("hysteresis", "grasp-positions", "contact-states", "inverter") else "cylindrical-D"
        path = coarse_protocol(study.protocol, design, fewer=True)
        reproduce_study(name, quick=True, protocol_path=path).write(directory)
    write_index(directory)
    return directory


@pytest.mark.slow
def test_every_report_renders_in_chromium_with_its_published_columns(reports):
    sync_playwright = _browser()
    pages = {name: reports / f"{name}.html" for name in own_studies()}
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        try:
            page = browser.new_page()
            problems: list[str] = []
            page.on("console", lambda m: problems.append(m.text) if m.type in ("error", "warning") else None)
            page.on("pageerror", lambda e: problems.append(str(e)))
            page.on("request", lambda r: problems.append(f"fetched {r.url}") if not r.url.startswith(
                ("file:", "data:")) else None)  # self-contained: nothing from the network
            for name, path in {**pages, "index": reports / "index.html"}.items():
                problems.clear()
                page.goto(path.as_uri())
                images = page.evaluate("Array.from(document.images).map(i => i.complete && i.naturalWidth > 0)")
                assert problems == [], (name, problems)
                assert all(images), (name, images)
                if name == "index":
                    links = page.evaluate("Array.from(document.querySelectorAll('a')).map(a => a.getAttribute('href'))")
                    assert sorted(links) == sorted(f"{n}.html" for n in own_studies())
                    continue
                assert images, name  # every study report has its figures
                titles = page.evaluate("Array.from(document.querySelectorAll('.paper-table h3')).map(h => h.textContent)")
                for table in tables_of(name):
                    assert table.title in titles, (name, table.title)
                    published = page.evaluate(
                        "t => { const h = Array.from(document.querySelectorAll('.paper-table h3'))"
                        ".find(h => h.textContent === t); return h.parentElement.querySelectorAll("
                        "'.published').length }", table.title)
                    assert published > 0, (name, table.title)
        finally:
            browser.close()


@pytest.mark.slow
def test_each_report_json_puts_results_beside_the_published_figures(reports):
    for name in own_studies():
        entry = json.loads((reports / f"{name}.json").read_text())
        assert entry["study"] == name and entry["report"] == f"{name}.html"
        for comparison in entry["comparisons"]:
            assert comparison["verdict"] in ("within", "outside", "better", "fitted")
            if comparison["difference"] is not None:  # a number, or the middle of a range "a–b"
                published = float(np.mean([float(v) for v in comparison["published"].split("–")]))
                assert comparison["difference"] == pytest.approx(comparison["softtip"] - published, abs=1e-5)
        # a study that follows published tables compares at least one of their cells
        assert bool(entry["comparisons"]) == bool(tables_of(name)), name
        # every setting that is not the publication's procedure is listed with both values
        for difference in entry["procedure_differences"]:
            assert difference["setting"].startswith("parameters.") and difference["softtip"] != difference["published"]
    # a smoke run's trials are cut below the published counts: marked
    pushing = json.loads((reports / "pushing.json").read_text())["procedure_differences"]
    assert {"setting": "parameters.calibration_trials", "softtip": 2, "published": 10.0} in [
        {key: d[key] for key in ("setting", "softtip", "published")} for d in pushing]
