"""report.html: it renders for the default design, byte for byte the same each time; it shows every file, the
key predictions and every spec key; it loads nothing from anywhere; it escapes what it is given; and it opens in
headless Chromium with no console errors and every picture decoded."""

from __future__ import annotations

import base64
import html as htmllib
import json
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import quote, unquote

import numpy as np
import pytest
from conftest import require_tool

from magfab import pcb
from magfab.errors import Finding, Severity
from magfab.export.cad import tessellate
from magfab.export.report import BENCH_FILES, render_report, section_loops
from magfab.pipeline import PARTS, Artifact

#: Files the build writes with or after the report: listed and linked by it (those the build does not
#: already list as artifacts are passed as extra_files).
LATER = (("report.html", "this page"), ("checklist.md", "fabrication checklist"),
         ("checklist.html", "the checklist with tick boxes"), ("bom.csv", "bill of materials"),
         ("manifest.json", "what made what"))

#: Test-only: appended to a copy of the report so Chromium records, in the DOM it dumps, every image that did
#: not decode and every resource the page fetched (the report itself has no scripts).
PROBE = """<script>
window.addEventListener('load', () => {
  const broken = [...document.images].filter(i => !i.complete || i.naturalWidth === 0)
    .map(i => (i.getAttribute('alt') || '') + ' ' + i.getAttribute('src').slice(0, 40));
  const loads = performance.getEntriesByType('resource').map(e => e.name.slice(0, 80));
  document.body.setAttribute('data-probe', JSON.stringify({images: document.images.length, broken, loads}));
});
</script>"""
CONSOLE_TROUBLE = ("Failed to load resource", "ERR_FILE_NOT_FOUND", "ERR_", "Uncaught", "Refused to", ":CONSOLE")


class Page(HTMLParser):
    """Tags, attributes and text of a page, as a browser's parser sees them."""

    def __init__(self, text: str) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict[str, str]]] = []
        self.text: list[str] = []
        self.styles: list[str] = []
        self._in_style = False
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, {k: v or "" for k, v in attrs}))
        self._in_style = tag == "style"

    def handle_endtag(self, tag):
        self._in_style = False

    def handle_data(self, data):
        (self.styles if self._in_style else self.text).append(data)

    def attr(self, name: str) -> list[str]:
        return [a[name] for _, a in self.tags if name in a]


@pytest.fixture(scope="module")
def inputs(default_build):
    r = default_build
    spec, design = r.spec, r.design
    meshes = {part.stem: tessellate(part.make(design), spec.mould.tessellation_tolerance_mm,
                                    spec.mould.angular_tolerance_deg) for part in PARTS}
    paths = {a.path for a in r.artifacts}
    calibration = json.loads(next(a.data for a in r.artifacts if a.path == "calibration/calibration.json"))
    return {"spec": spec, "design": design, "findings": list(r.findings), "artifacts": [a for a in r.artifacts
            if a.path != "report.html"], "prediction": r.prediction, "calibration": calibration, "meshes": meshes,
            "extra_files": [(p, d) for p, d in LATER if p not in paths or p == "report.html"],
            "board": pcb.board(design)}


@pytest.fixture(scope="module")
def report(inputs) -> bytes:
    return render_report(**inputs)


@pytest.fixture(scope="module")
def site(report, default_build, tmp_path_factory) -> Path:
    """A copy of the default build folder with this report in it: the page and every file it links."""
    out = tmp_path_factory.mktemp("report") / "magone"
    shutil.copytree(default_build.out_dir, out)
    (out / "report.html").write_bytes(report)
    return out


def test_report_is_deterministic(inputs, report):
    assert report.startswith(b"<!DOCTYPE html>") and report.rstrip().endswith(b"</html>")
    assert render_report(**inputs) == report


def test_report_lists_and_links_every_file(inputs, report, site):
    text = report.decode()
    listed = [a.path for a in inputs["artifacts"]] + [p for p, _ in inputs["extra_files"]]
    assert {"report.html", "checklist.md", "checklist.html", "bom.csv", "manifest.json"} <= set(listed)
    for path in listed:
        assert f'href="{quote(path, safe="/")}"' in text, path
        assert f"<code>{htmllib.escape(path)}</code>" in text, path
    for path, _ in BENCH_FILES:  # at the top of the page, as well as in the file table
        assert text.count(f'href="{path}"') >= 2, path
    page = Page(text)
    for href in page.attr("href"):
        if href.startswith("#"):
            assert any(a.get("id") == href[1:] for _, a in page.tags), f"no anchor for {href}"
        else:
            assert (site / unquote(href)).is_file(), f"link to a missing file: {href}"


def test_report_shows_the_key_figures_models_findings_and_spec(inputs, report):
    text = htmllib.unescape(" ".join(Page(report.decode()).text))
    design, data, cal = inputs["design"], inputs["prediction"].as_json(), inputs["calibration"]
    n, s = data["normal"], data["shear"]
    sens = "{0:.1f} – {1:.1f} G/N".format
    expected = [f"{design.d_rest_mm:.2f} mm", f"cover {design.cover_mm:.2f} mm", f"skin {design.skin_mm:.2f} mm",
                f"{data['field']['Bz_rest_G']:.1f} G", sens(*n["sensitivity_G_per_N"]), f"{n['resolution_mN']:.2f} mN",
                *inputs["prediction"].normal.range_parts(), sens(*s["sensitivity_G_per_N"]),
                f"{s['resolution_mN']:.2f} mN", f"{s['range_N']:.3f} N", f"{data['noise_G']['total_z_G']:.3f} G",
                cal["method"]]
    expected += [f"{1000 * cal['errors'][k]['rms_holdout']:.2f}" for k in ("Fz_N", "Fr_N")]
    expected += [m["model"] for m in data["models"].values()] + [m["detail"] for m in data["models"].values()]
    expected += [f.message for f in inputs["findings"]]
    for want in expected:
        assert want in text, want
    spec = inputs["spec"].model_dump(mode="json")
    for section, values in spec.items():
        if values is None:  # an optional section the spec leaves out ([array] for a single taxel)
            continue
        keys = values if isinstance(values, dict) else {section: values}
        if isinstance(values, dict):
            assert f"[{section}]" in text
        for key in keys:
            assert key in text, f"{section}.{key}"


def test_report_loads_nothing_from_anywhere(report):
    text = report.decode()
    page = Page(text)
    tags = {t for t, _ in page.tags}
    assert not tags & {"script", "link", "iframe", "object", "embed", "base", "frame", "audio", "video", "source"}
    assert not any(k.startswith("on") or k == "style" for _, a in page.tags for k in a)
    css = "".join(page.styles)
    assert "@import" not in css and "url(" not in css and "@font-face" not in css
    for value in page.attr("href") + page.attr("src"):
        assert not re.match(r"\s*([a-z][a-z0-9+.-]*:|//)", value, re.I) or value.startswith("data:image/"), value
        assert "http:" not in value and "https:" not in value
    sources = page.attr("src")
    assert len(sources) >= 1 + len(PARTS) + 1 + 4  # stack-up, parts, board, the prediction plots
    for src in sources:
        kind, _, b64 = src.partition(";base64,")
        data = base64.b64decode(b64, validate=True)
        if kind == "data:image/png":
            assert data.startswith(b"\x89PNG\r\n\x1a\n")
        else:
            assert kind == "data:image/svg+xml"
            root = ET.fromstring(data)  # well-formed, and nothing in it fetches anything
            assert root.tag.endswith("svg")
            for el in root.iter():
                for k, v in el.attrib.items():
                    if k.endswith("href"):
                        assert v.startswith(("#", "data:image/")), v
                    assert "url(http" not in v and "url(//" not in v


def test_report_escapes_what_it_is_given(inputs):
    hostile = "<script>alert(1)</script> & \"double\" 'single'"
    key = 'elastomer.material"><b id=pwn>'
    findings = inputs["findings"] + [Finding(Severity.WARNING, "hostile<code>", hostile, key)]
    odd = Artifact("notes/odd <name> & 'x'.txt", b"x", '<img src=x onerror="alert(2)">')
    html = render_report(**{**inputs, "findings": findings, "artifacts": inputs["artifacts"] + [odd]}).decode()
    page = Page(html)
    assert "<script" not in html and "<img src=x" not in html and "<b id=pwn>" not in html
    assert not any(t == "script" or "onerror" in a for t, a in page.tags)
    text = " ".join(page.text)
    for shown in (hostile, "hostile<code>", key, odd.path, odd.description):
        assert shown in text  # displayed literally
    assert 'href="notes/odd%20%3Cname%3E%20%26%20%27x%27.txt"' in html


def test_report_refuses_bad_file_lists_and_missing_meshes(inputs):
    with pytest.raises(ValueError, match="listed twice"):
        render_report(**{**inputs, "extra_files": [("design.json", "again")]})
    for bad in ("/etc/passwd", "../outside.txt", "a//b", "a\\b"):
        with pytest.raises(ValueError, match="relative POSIX path"):
            render_report(**{**inputs, "extra_files": [(bad, "x")]})
    with pytest.raises(ValueError, match="elastomer"):
        render_report(**{**inputs, "meshes": {k: v for k, v in inputs["meshes"].items() if k != "elastomer"}})


def test_section_of_the_elastomer_matches_its_profile(inputs):
    """The stack-up and the cut-away are drawn from mesh sections: the section through the axis spans the
    elastomer's diameter and height, and encloses twice the revolved profile's area (both halves)."""
    design = inputs["design"]
    loops = section_loops(inputs["meshes"]["elastomer"])
    pts = np.vstack(loops)
    assert np.ptp(pts[:, 0]) == pytest.approx(2 * design.elastomer_radius_mm, abs=0.02)
    assert np.ptp(pts[:, 1]) == pytest.approx(design.elastomer_height_mm, abs=0.02)
    area = sum(abs(0.5 * np.sum(lp[:, 0] * np.roll(lp[:, 1], -1) - np.roll(lp[:, 0], -1) * lp[:, 1])) for lp in loops)
    import math

    R, hb = design.elastomer_radius_mm, design.base_height_mm
    envelope = 2 * R * hb + 0.5 * math.pi * R * R  # hemisphere tip
    core = design.core_profile
    core_area = 2 * abs(0.5 * sum(a[0] * b[1] - b[0] * a[1] for a, b in zip(core, core[1:] + core[:1])))
    assert area == pytest.approx(envelope - core_area, rel=0.01)


def _chromium(*args: str, profile: Path) -> subprocess.CompletedProcess:
    exe = require_tool("chromium")
    return subprocess.run([exe, "--headless=new", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                           f"--user-data-dir={profile}", "--enable-logging=stderr", "--v=0", *args],
                          capture_output=True, text=True, timeout=120)


def _trouble(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if any(t in line for t in CONSOLE_TROUBLE)]


def _probe(page: Path, profile: Path) -> dict:
    probed = page.with_name("_probe_" + page.name)
    probed.write_text(page.read_text(encoding="utf-8").replace("</body>", PROBE + "</body>"), encoding="utf-8")
    run = _chromium("--dump-dom", probed.as_uri(), profile=profile)
    assert run.returncode == 0, run.stderr[-2000:]
    m = re.search(r'data-probe="([^"]*)"', run.stdout)
    assert m, "the probe did not run: " + run.stderr[-2000:]
    return json.loads(htmllib.unescape(m.group(1)))


def test_report_opens_in_chromium(site, tmp_path):
    import matplotlib.image as mpimg

    require_tool("chromium")
    page = site / "report.html"
    shot = tmp_path / "report.png"
    run = _chromium(f"--screenshot={shot}", "--window-size=1280,4000", page.as_uri(), profile=tmp_path / "profile")
    assert run.returncode == 0, run.stderr[-2000:]
    assert not _trouble(run.stderr), _trouble(run.stderr)
    image = mpimg.imread(shot)
    assert image.shape[:2] == (4000, 1280)
    colours = np.unique((image[:, :, :3] * 255).round().astype(np.uint8).reshape(-1, 3), axis=0)
    assert len(colours) > 200  # text, pictures, plots: not a blank or an error page
    assert (image[:, :, :3] < 0.5).mean() > 0.01  # and something dark on it

    probe = _probe(page, tmp_path / "profile")
    assert probe["images"] >= 1 + len(PARTS) + 1 + 4
    assert probe["broken"] == [] and probe["loads"] == []


def test_chromium_checks_catch_a_broken_page(tmp_path):
    """The same checks on a page with a missing image, an undecodable one and a script error all fail."""
    require_tool("chromium")
    page = tmp_path / "broken.html"
    page.write_text('<!DOCTYPE html><html><body><img alt="a" src="missing.png"><img alt="b" '
                    'src="data:image/png;base64,AAAA"><script>undefined_function();</script></body></html>')
    run = _chromium("--dump-dom", page.as_uri(), profile=tmp_path / "profile")
    assert any("Uncaught" in line for line in _trouble(run.stderr))
    probe = _probe(page, tmp_path / "profile")
    assert [b.split()[0] for b in probe["broken"]] == ["a", "b"]
