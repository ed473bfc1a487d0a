"""The lab's HTML report in a real browser: headless Chromium renders it, every image decodes,
every inline SVG plot has a size, no console error, and a screenshot is saved.

The report is that of a table like the demo's (the anti-Helmholtz scene: a gradient whose
transverse components and the ring-down amplitude the published model leaves out), with the
selection on; and, for the plots of what the diagnosis names, that of a table whose truth holds
physics outside the catalog (tests/lab/outside_catalog.py, the moment's temperature coefficient:
the residual follows the temperature and B∥, and the search beyond the catalog finds B∥·T). A
small script appended to a copy of the page records, after the load event,
which images did not decode (``complete`` with ``naturalWidth`` 0) and the rendered size of each
inline SVG plot (a ``<figure>`` marked ``data-covariate`` or ``data-term``); Chromium's console goes to
its log (``--enable-logging=stderr``). The same check on a page with a broken image and a
console error must fail, so that it can. Chromium is Debian's ``chromium``, installed by
``make test`` when missing.
"""

import json
import re
import shutil
import subprocess

import numpy as np
import pytest

from lab.outside_catalog import CASES
from mows.lab import ProbeSet, analyse, write_report
from mows.lab.data import synthetic
from mows.lab.report.html_report import named_covariates
from mows.physics.field import UniformField, anti_helmholtz_pair
from mows.physics.probe import PAPER_PROBE

# One worker runs the whole module, so that its module fixture is computed once, not once per
# xdist worker.
pytestmark = pytest.mark.xdist_group("report_browser")

CHROMIUM = ("chromium", "--headless", "--no-sandbox", "--disable-gpu")
TIMEOUT_S = 180
CHECK = """<script>
window.addEventListener("load", () => {
  const images = Array.from(document.images);
  const failed = images.map((image, i) => image.complete && image.naturalWidth > 0 ? null : i)
    .filter((i) => i !== null);
  const figures = Array.from(document.querySelectorAll("figure[data-covariate], figure[data-term]")).map((f) => {
    const svg = f.querySelector("svg");
    const box = svg ? svg.getBoundingClientRect() : {width: 0, height: 0};
    return {kind: f.className, name: f.dataset.covariate || f.dataset.term, width: box.width, height: box.height};
  });
  const out = document.createElement("pre");
  out.id = "mows-image-check";
  out.textContent = JSON.stringify({images: images.length, failed: failed, figures: figures});
  document.body.appendChild(out);
});
</script>"""
BROKEN = (
    '<img src="data:image/png;base64,iVBORw0KGgoAAAAbroken" alt="broken"><script>console.error("deliberate");</script>'
    '<figure class="covariate" data-covariate="empty"><svg width="0" height="0"></svg></figure>'
)


def _chromium(*args):
    assert shutil.which(CHROMIUM[0]), "chromium not found: `make test` installs Debian's chromium"
    return subprocess.run(CHROMIUM + args, capture_output=True, text=True, timeout=TIMEOUT_S)


def render(path) -> tuple:
    """(image check {images, failed, figures}, console messages) of the page at ``path`` in Chromium."""
    checked = path.with_name(path.stem + "_checked.html")
    checked.write_text(path.read_text().replace("</body>", CHECK + "</body>"))
    done = _chromium("--enable-logging=stderr", "--v=0", "--virtual-time-budget=10000", "--dump-dom", checked.as_uri())
    found = re.search(r'<pre id="mows-image-check">([^<]*)</pre>', done.stdout)
    assert found, f"the page did not finish loading: {done.stderr[-2000:]}"
    console = [line for line in done.stderr.splitlines() if ":CONSOLE" in line]
    return json.loads(found.group(1)), console


@pytest.fixture(scope="module")
def report_page(tmp_path_factory):
    sweep = synthetic.rotation_sweeps(30.0, 2)
    theta0 = sweep.pop("theta0_deg")
    source = anti_helmholtz_pair((0, 0, 0), (1, 0, 0), 0.105, 100, 1.0) + UniformField((16e-6, 12e-6, -40e-6))
    table = synthetic.synthesize(
        PAPER_PROBE, source, theta0, np.random.default_rng(0), f_std_hz=3e-4, amplitude_deg=20.0, **sweep
    )
    report = analyse(table, ProbeSet.one(PAPER_PROBE), auto=True)
    return write_report(report, tmp_path_factory.mktemp("report") / "lab_report.html"), report


@pytest.fixture(scope="module")
def named_page(tmp_path_factory):
    """The report of a table whose residual follows covariates outside the catalog."""
    table, _ = CASES["moment_temperature"](0)
    report = analyse(table, ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False)
    return write_report(report, tmp_path_factory.mktemp("named") / "lab_report.html"), report


def drawn(figure) -> bool:
    return figure["width"] > 0 and figure["height"] > 0


def test_the_report_renders_with_every_image_decoded_and_no_console_error(report_page):
    path, report = report_page
    check, console = render(path)
    covariates = report.fit.table.covariates()
    # Fig. 3, Fig. 4, candidates, history as images; residuals against θ0 and each covariate as SVG.
    assert check["images"] == path.read_text().count("<img ") >= 4
    residuals = [f for f in check["figures"] if f["kind"] == "covariate"]
    assert sorted(f["name"] for f in residuals) == sorted(["θ0", *covariates])
    assert all(drawn(f) for f in check["figures"]), check["figures"]
    assert check["failed"] == []
    assert console == []
    shot = path.with_name("lab_report.png")
    done = _chromium("--window-size=1100,4000", f"--screenshot={shot}", path.as_uri())
    assert done.returncode == 0, done.stderr[-2000:]
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and shot.stat().st_size > 50_000


def test_the_check_fails_on_a_broken_image_and_a_console_error(report_page):
    path, _ = report_page
    broken = path.with_name("broken.html")
    broken.write_text(path.read_text().replace("<body>", "<body>" + BROKEN, 1))
    check, console = render(broken)
    assert check["failed"] == [0]
    assert [f["name"] for f in check["figures"] if not drawn(f)] == ["empty"]
    assert any('"deliberate"' in line for line in console)


def test_the_report_shows_separate_residual_axes_and_the_alias_groups(report_page):
    path, report = report_page
    text = path.read_text()
    assert report.groups and all(f"group {g.number}:" in text for g in report.groups)
    assert any(g.aliases for g in report.groups) and "alias: " in text


def test_the_report_plots_what_the_diagnosis_names_and_the_term_found(named_page):
    path, report = named_page
    named = named_covariates(report)
    assert {"temperature_k", "b_along_t"} <= set(named)  # the hidden term's covariates
    (term,) = report.discovery.terms
    assert term.name == "moment × temperature_k"  # the channel the truth acts in
    check, console = render(path)
    assert check["failed"] == [] and console == []
    residuals = [f["name"] for f in check["figures"] if f["kind"] == "covariate"]
    assert residuals[: 1 + len(named)] == ["θ0", *named]  # what the diagnosis names, first
    by_name = {(f["kind"], f["name"]): f for f in check["figures"]}
    assert all(drawn(by_name["covariate", name]) for name in named)
    assert drawn(by_name["term", term.name])
    assert path.read_text().count("<svg") == len(check["figures"]) == 2 + len(report.fit.table.covariates())
