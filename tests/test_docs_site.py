"""The documentation site as a reader gets it: built with warnings as errors, every public name
and every command on a page of its own, nothing loaded from the network, and three pages
(the index, a gallery example, an API page) opened in a real headless Chromium (Debian's
chromium + chromium-driver, driven by selenium) with no console error and no broken local link.

The site is the one ``make docs`` built (``make test`` builds it before pytest); when it is
missing, the first test builds it (a few minutes).
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest
import triaxcal
from triaxcal.cli import build_parser

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
HTML = DOCS / "_build" / "html"

pytestmark = [pytest.mark.slow, pytest.mark.timeout(1200)]

#: The pages the browser opens: the front page, a gallery example on a real recording, an API
#: page.
PAGES = ["index.html", "auto_examples/plot_report_figure.html",
         "reference/api/generated/triaxcal.fit_ellipsoid.html"]


@pytest.fixture(scope="module")
def site() -> Path:
    if not (HTML / "index.html").is_file():
        subprocess.run([sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going",
                        "-q", str(DOCS), str(HTML)], check=True, cwd=ROOT)
    return HTML


def test_every_public_name_has_an_api_page(site):
    generated = site / "reference" / "api" / "generated"
    modules = {"sim": "triaxcal.sim.SimIMU", "rotations": None, "__version__": None}
    missing = []
    for name in triaxcal.__all__:
        if name in modules:
            continue
        if not (generated / f"triaxcal.{name}.html").is_file():
            missing.append(name)
    assert not missing, f"public names without an API page: {missing}"
    for name in triaxcal.sim.__all__:
        assert (generated / f"triaxcal.sim.{name}.html").is_file(), name
    assert "triaxcal.conventions.rotations" in (site / "reference/api/sim.html").read_text()


def test_every_command_and_option_is_in_the_cli_reference(site):
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert sub.choices, "no commands"
    for name, command in sub.choices.items():
        page = site / "reference" / "cli" / f"{name}.html"
        assert page.is_file(), f"no page for triaxcal {name}"
        text = page.read_text(encoding="utf-8")
        for action in command._actions:
            if action.help == argparse.SUPPRESS or isinstance(action, argparse._HelpAction):
                continue
            for option in action.option_strings:
                assert option in text, f"triaxcal {name} {option} is not on its page"


def test_no_page_loads_anything_from_the_network(site):
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        from triaxcal_docs import remote_assets
    finally:
        sys.path.remove(str(DOCS / "_ext"))
    assert remote_assets(site) == []
    pages = list(site.rglob("*.html"))
    assert len(pages) > 150
    # no math renderer from a CDN, no web fonts
    for page in pages:
        text = page.read_text(encoding="utf-8")
        assert "mathjax" not in text.lower(), page
        assert "fonts.googleapis" not in text, page


#: The methods are named for what they do and cited by their origin; the notes the project started
#: from are never called "seeds" where a user reads (the random seed of the simulator is fine).
_WRITE_UP = re.compile(r"seed's|seeds'|\bthe seeds?\b(?! of)|\bseed (?:methods?|write-ups?)",
                       re.I)


def test_no_page_calls_a_method_a_seed(site):
    said = []
    pages = [p for p in site.rglob("*.html") if "_modules" not in p.parts]  # not the source
    for page in [*pages, ROOT / "README.md"]:
        text = page.read_text(encoding="utf-8")
        text = re.sub(r"<script.*?</script>|<[^>]+>", " ", text, flags=re.S)
        said += [f"{page.name}: ...{text[max(0, m.start() - 40):m.end() + 20]}..."
                 for m in _WRITE_UP.finditer(text)]
    assert not said, said[:10]


def test_the_gallery_ran_and_drew_its_figures(site):
    pages = sorted((site / "auto_examples").glob("plot_*.html"))
    assert len(pages) >= 10
    for page in pages:
        text = page.read_text(encoding="utf-8")
        assert re.search(r'<img[^>]+src="[^"]*_images/sphx_glr_plot_', text), \
            f"{page.name} shows no figure"


# -- in a browser ------------------------------------------------------------------------------

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")
needs_browser = pytest.mark.skipif(
    CHROMIUM is None or CHROMEDRIVER is None,
    reason="needs Debian's chromium and chromium-driver (make deps installs them)")


@pytest.fixture(scope="module")
def driver():
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    opts = Options()
    opts.binary_location = CHROMIUM
    for a in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
              "--window-size=1280,1000", "--no-first-run", "--disable-extensions",
              "--disable-background-networking", "--disable-sync",
              "--disable-component-update", "--disable-default-apps"):
        opts.add_argument(a)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
    d = webdriver.Chrome(options=opts, service=Service(CHROMEDRIVER))
    try:
        d.set_page_load_timeout(120)
        yield d
    finally:
        d.quit()


_LINKS = """
return Array.from(document.querySelectorAll('a[href], link[href], script[src], img[src]'))
  .map(e => e.href || e.src);
"""


def _target_exists(url: str) -> str | None:
    """Why a local URL is broken, or None."""
    parts = urlsplit(url)
    path = Path(unquote(parts.path))
    if path.is_dir():
        path = path / "index.html"
    if not path.is_file():
        return f"{url}: no such file"
    if parts.fragment and path.suffix == ".html":
        text = path.read_text(encoding="utf-8")
        frag = re.escape(unquote(parts.fragment))
        if not re.search(rf'\b(?:id|name)="{frag}"', text):
            return f"{url}: no element with id {parts.fragment!r}"
    return None


@needs_browser
@pytest.mark.browser
@pytest.mark.parametrize("page", PAGES)
def test_page_opens_with_no_console_error_and_no_broken_local_link(site, driver, page):
    url = (site / page).as_uri()
    driver.get_log("browser")  # drop what an earlier page left
    driver.get_log("performance")
    driver.get(url)
    assert driver.execute_script("return document.readyState") == "complete"
    assert driver.find_element("css selector", "h1").text.strip()
    errors = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    assert not errors, errors
    links = driver.execute_script(_LINKS)
    local = [u for u in links if u.startswith("file:")]
    assert local, "the page has no local links at all"
    broken = sorted({why for u in local if (why := _target_exists(u))})
    assert not broken, broken
    remote_requests = [e["message"] for e in driver.get_log("performance")
                       if '"Network.requestWillBeSent"' in e["message"]
                       and re.search(r'"url":"https?://', e["message"])]
    assert not remote_requests, remote_requests[:3]
