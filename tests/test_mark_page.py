"""`ridgeloc mark` (issue 21): the offline marking page, driven in headless Chromium: clicks on the frame become
marks at the clicked image pixels, named, listed and written as the marks CSV that pipeline.targets reads."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tempfile
from html import unescape
from pathlib import Path

import numpy as np
import pytest

from pipeline.report.mark_page import mark_page
from pipeline.targets import in_image, read_marks_csv

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None, reason="headless Chromium not installed (Debian: apt-get install chromium; .ci/run installs it)")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync", "--hide-scrollbars",
         "--virtual-time-budget=8000", "--window-size=1400,1000")

# After load: click the image at CSS offsets (11, 21) and (251, 101) from its corner (drawn at its natural size: the
# image pixels (10.5, 20.5) and (250.5, 100.5), pixel centres at integers), the second named "mast", then a
# duplicate, then a click on frame 7. MouseEvent coordinates are whole CSS pixels: the image's corner is too.
_CLICKS = """<script>
window.addEventListener('load', function () { setTimeout(function () {
  var img = document.getElementById('frame');
  document.getElementById('wrap').style.cssText += 'position: fixed; left: 0; top: 0;';  // a whole-pixel corner
  function click(x, y) {
    var r = img.getBoundingClientRect();
    img.dispatchEvent(new MouseEvent('click', {bubbles: true, clientX: r.left + x, clientY: r.top + y}));
  }
  click(11, 21);
  document.getElementById('name').value = 'mast'; click(251, 101);
  document.getElementById('name').value = 'mast'; click(30, 30);
  var dup = document.getElementById('error').textContent;
  document.getElementById('name').value = '.hidden'; click(60, 60);
  var dot = document.getElementById('error').textContent;
  var edge = [window.ridgelocMark(299.6, 10, 'e1'), window.ridgelocMark(10, -0.6, 'e2')];  // just off the image
  var sel = document.getElementById('frames'); sel.value = '1'; sel.dispatchEvent(new Event('change'));
  setTimeout(function () {
    document.getElementById('name').value = 'mast'; click(40, 41);
    var r = img.getBoundingClientRect();
    document.body.setAttribute('data-result', JSON.stringify({csv: document.getElementById('csv').value, dup: dup,
      dot: dot, edge: edge, corner: [r.left, r.top],
      pins: document.querySelectorAll('.pin').length, img: img.naturalWidth + 'x' + img.naturalHeight,
      css: img.clientWidth}));
  }, 300);
}, 500); });
</script>"""


def _frames() -> dict[int, np.ndarray]:
    rng = np.random.default_rng(3)
    return {4: rng.integers(0, 255, (120, 300, 3), dtype=np.uint8), 7: rng.integers(0, 255, (120, 300), np.uint8)}


def test_the_page_is_self_contained():
    html = mark_page(_frames(), "t", [{"name": "A", "frame": 4, "x": 1.0, "y": 2.0}])
    assert "data:image/jpeg;base64," in html and html.count("data:image/jpeg") == 2
    assert not re.search(r"""(src|href)=["']https?://""", html)  # nothing from the network


def page_result(page: Path) -> dict:
    """The JSON a page's test script leaves in body[data-result], after headless Chromium ran it."""
    import json

    with tempfile.TemporaryDirectory() as profile:
        out = subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={profile}", "--dump-dom", page.as_uri()],
                             capture_output=True, text=True, timeout=180)
    m = re.search(r'data-result="([^"]*)"', out.stdout)
    assert m, (out.stdout[-1500:], out.stderr[-1500:])
    return json.loads(unescape(m.group(1)))


@needs_chromium
def test_clicks_become_the_marks_csv(tmp_path):
    page = tmp_path / "marks.html"
    page.write_text(mark_page(_frames(), "test").replace("</body>", _CLICKS + "</body>"))
    res = page_result(page)
    assert res["img"] == "300x120" and res["css"] == 300  # drawn at natural size: offsets are pixels + 0.5
    assert all(float(v).is_integer() for v in res["corner"])
    assert res["dup"].startswith("duplicate name mast on frame 4")
    assert res["dot"].startswith("a name must not")  # as targets.check_name: a run would refuse it
    assert res["edge"] == [in_image(299.6, 10, 300, 120), in_image(10, -0.6, 300, 120)] == [False, False]
    assert res["pins"] == 1  # frame 7 shows its own mark only
    assert res["csv"] == ("name,frame_or_image,x_px,y_px\nT1,4,10.50,20.50\nmast,4,250.50,100.50\n"
                          "mast,7,39.50,40.50\n")
    (tmp_path / "marks.csv").write_text(res["csv"])
    targets = read_marks_csv(tmp_path / "marks.csv")  # what the page saves is what a flight reads
    assert [(t.name, [(m.frame_index, m.pixel) for m in t.marks]) for t in targets] == [
        ("T1", [(4, (10.5, 20.5))]), ("mast", [(4, (250.5, 100.5)), (7, (39.5, 40.5))])]


def test_mark_command_writes_the_page_of_a_flight(tmp_path):
    out = tmp_path / "m.html"
    r = subprocess.run([sys.executable, "-m", "pipeline", "mark", str(ROOT / "configs" / "flights" /
                        "three_targets.yaml"), "-o", str(out), "--max-frames", "3"], cwd=ROOT, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    html = out.read_text()
    assert html.count("data:image/jpeg") == 3  # frames 4 (the marks' frame), and three spread observation frames
    for name in ("panel", "small_grey", "far_north"):  # the config's marks, to edit
        assert f'"name": "{name}"' in html


def test_mark_refuses_a_folder_or_a_file_in_the_pages_way_before_reading_the_flight(tmp_path, capsys, monkeypatch):
    from pipeline.cli import main
    from pipeline.flight import Flight

    def no_flight(*args, **kwargs):
        raise AssertionError("the flight was read before the output path was checked")

    monkeypatch.setattr(Flight, "open", no_flight)
    config = str(ROOT / "configs" / "flights" / "group1.yaml")
    afile = tmp_path / "afile"
    afile.write_text("keep me")
    for out, problem in ((tmp_path, f"is a folder: name the file to write, e.g. {tmp_path / 'marks.html'}"),
                         (afile / "m.html", f"cannot write: {afile} is not a folder")):
        assert main(["mark", config, "-o", str(out)]) == 1
        assert capsys.readouterr().err.splitlines() == [f"ridgeloc: error: {out}: {problem}"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"] and afile.read_text() == "keep me"


def test_mark_shows_a_colour_video_in_colour(tmp_path):
    """The real KWIVER clip is in colour (a pink car beside a grey one): the page shows its frames in colour, not
    the tracker's grayscale, so the person marking can tell the targets apart by it."""
    import base64

    import cv2

    from pipeline.cli import main

    clip = ROOT / ".." / "shared" / "fmv" / "aphill_short.ts"
    if not clip.is_file():
        pytest.skip(f"{clip} absent (the shared read-only material is not beside this checkout)")
    (tmp_path / "flight.yaml").write_text(f"name: clip\nfiles: {{telemetry: [{clip.resolve()}]}}\n"
                                          "altitude: {geoid_separation_m: auto}\n")
    assert main(["mark", str(tmp_path / "flight.yaml"), "--max-frames", "2"]) == 0
    html = (tmp_path / "marks.html").read_text()
    jpegs = re.findall(r"data:image/jpeg;base64,([A-Za-z0-9+/=]+)", html)
    assert len(jpegs) == 2
    img = cv2.imdecode(np.frombuffer(base64.b64decode(jpegs[0]), np.uint8), cv2.IMREAD_UNCHANGED)
    assert img.ndim == 3 and img.shape == (480, 720, 3)
    saturation = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)[..., 1]
    assert np.percentile(saturation, 99) > 80  # a gray page has none


_ZOOM = """<script>
window.addEventListener('load', function () { setTimeout(function () {
  var img = document.getElementById('frame');
  document.getElementById('wrap').style.cssText += 'position: fixed; left: 0; top: 0;';
  var zoom = document.getElementById('zoom'); zoom.value = '4'; zoom.dispatchEvent(new Event('change'));
  var r = img.getBoundingClientRect();
  img.dispatchEvent(new MouseEvent('click', {bubbles: true, clientX: r.left + 42, clientY: r.top + 82}));
  var c = document.querySelector('.centre');
  document.body.setAttribute('data-result', JSON.stringify({csv: document.getElementById('csv').value,
    css: img.clientWidth, centre: [c.style.left, c.style.top]}));
}, 500); });
</script>"""


@needs_chromium
def test_zoomed_clicks_are_the_same_image_pixels_and_the_centre_is_shown(tmp_path):
    """A 13 x 5 px target needs a zoom: at 4x a click 42, 82 CSS px from the corner is the image pixel (10, 20);
    the image centre (where a laser points) is marked at (w/2, h/2) in pixel-edge terms."""
    page = tmp_path / "marks.html"
    page.write_text(mark_page(_frames(), "test").replace("</body>", _ZOOM + "</body>"))
    res = page_result(page)
    assert res["css"] == 1200 and res["centre"] == ["600px", "240px"]
    assert res["csv"] == "name,frame_or_image,x_px,y_px\nT1,4,10.00,20.00\n"


def test_mark_takes_a_clip_alone_as_run_and_check_do(tmp_path, capsys, monkeypatch):
    """`ridgeloc mark clip.ts` (no config): the page goes into the current folder (a clip's folder may be a
    read-only archive) and says how the marks reach a run: a flight config for the clip with marks_file."""
    from pipeline.cli import main

    clip = ROOT / ".." / "shared" / "fmv" / "aphill_short.ts"
    if not clip.is_file():
        pytest.skip(f"{clip} absent (the shared read-only material is not beside this checkout)")
    monkeypatch.chdir(tmp_path)
    assert main(["mark", str(clip), "--max-frames", "2"]) == 0
    out = capsys.readouterr().out
    assert (tmp_path / "marks.html").is_file() and "marks_file: marks.csv" in out
    # init of the clip, not of its folder (the shared folder holds two clips, which init would read as one flight)
    assert f"`ridgeloc init {clip.resolve()} -o flight.yaml`" in out
    assert len(re.findall(r"data:image/jpeg;base64,", (tmp_path / "marks.html").read_text())) == 2
