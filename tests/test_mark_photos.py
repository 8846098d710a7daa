"""`ridgeloc mark` on drone photos (issue 41): the same offline page as for video, one target marked in several
photos under one name, clicks on a photo shown scaled down giving the photo's own pixels, and the marks CSV that
`ridgeloc locate --marks` and a photo flight config's marks_file: read."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from test_mark_page import needs_chromium, page_result

from pipeline.cli import main as cli_main
from pipeline.report.mark_page import mark_page
from pipeline.targets import read_marks_csv
from support.maker_photos import write_maker_photo

# click photo a.jpg (drawn at its natural 150 px width, half its 300 px) at CSS (11, 21), then b.jpg at (40, 41)
# with the name box empty: the same target, so the same name
_CLICKS = """<script>
window.addEventListener('load', function () { setTimeout(function () {
  var img = document.getElementById('frame');
  document.getElementById('wrap').style.cssText += 'position: fixed; left: 0; top: 0;';
  function click(x, y) {
    var r = img.getBoundingClientRect();
    img.dispatchEvent(new MouseEvent('click', {bubbles: true, clientX: r.left + x, clientY: r.top + y}));
  }
  click(11, 21);
  var sel = document.getElementById('frames'); sel.value = '1'; sel.dispatchEvent(new Event('change'));
  setTimeout(function () {
    click(40, 41);
    document.body.setAttribute('data-result', JSON.stringify({csv: document.getElementById('csv').value,
      labels: Array.prototype.map.call(sel.options, function (o) { return o.textContent; })}));
  }, 300);
}, 500); });
</script>"""


@needs_chromium
def test_clicks_on_scaled_photos_are_their_own_pixels_under_one_name(tmp_path):
    rng = np.random.default_rng(4)
    images = {"a.jpg": rng.integers(0, 255, (100, 150, 3), dtype=np.uint8),
              "b.jpg": rng.integers(0, 255, (100, 150, 3), dtype=np.uint8)}
    page = tmp_path / "marks.html"
    page.write_text(mark_page(images, "photos", sizes={"a.jpg": (300, 200), "b.jpg": (300, 200)})
                    .replace("</body>", _CLICKS + "</body>"))
    result = page_result(page)
    assert result["labels"] == ["a.jpg", "b.jpg"]
    # CSS (11, 21) on an image drawn at half its size: pixel (11 / 0.5 - 0.5, 21 / 0.5 - 0.5)
    assert result["csv"] == "name,frame_or_image,x_px,y_px\nT1,a.jpg,21.50,41.50\nT1,b.jpg,79.50,81.50\n"


def test_mark_of_a_photo_folder_and_the_csv_locate_reads(tmp_path, capsys):
    folder = tmp_path / "photos"
    folder.mkdir()
    for k, lon in enumerate((7.4997, 7.5003)):
        write_maker_photo(folder / f"P{k}.jpg", "parrot", yaw=0.0, pitch=-60.0, lon=lon, size=(640, 480),
                          model="test camera")
    assert cli_main(["mark", str(folder)]) == 0
    assert "wrote " in capsys.readouterr().out
    html = (folder / "marks.html").read_text()
    assert '"index": "P0.jpg"' in html and '"width": 640' in html and html.count("data:image/jpeg") == 2
    # the CSV the page saves beside itself (two marks of one target): read as marks_file: and by locate --marks
    csv = folder / "marks.csv"
    csv.write_text("name,frame_or_image,x_px,y_px\ncairn,P0.jpg,400.0,150.0\ncairn,P1.jpg,240.0,150.0\n")
    (target,) = read_marks_csv(csv)
    assert [m.template for m in target.marks] == [str((folder / f"P{k}.jpg").resolve()) for k in (0, 1)]
    cli_main(["locate", str(folder), "--marks", str(csv), "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert np.isfinite(doc["estimates"]["dlt"]["lat_deg"])
    # the name typed on the page names the answer, as `ridgeloc run` of a flight config with that marks_file: does
    assert (doc["answer"]["name"], doc["answer"]["group"], doc["answer"]["target"]) == ("photos:cairn", "photos",
                                                                                         "cairn")


def test_mark_of_a_photo_flight_config_shows_its_known_marks(tmp_path, capsys):
    from pathlib import Path

    config = Path(__file__).resolve().parents[1] / "configs" / "flights" / "h20_laser.yaml"
    assert cli_main(["mark", str(config), "-o", str(tmp_path / "marks.html")]) == 0
    html = (tmp_path / "marks.html").read_text()
    assert html.count("data:image/jpeg") == 5
    marks = json.loads(re.search(r"var marks = (\[.*?\]);", html).group(1))
    assert {m["name"] for m in marks} >= {"cairn", "gate"}
    assert all(m["frame"].endswith(".JPG") for m in marks)


def test_mark_refuses_a_mix_of_configs_and_photos(tmp_path, capsys):
    photo = write_maker_photo(tmp_path / "p.jpg", "parrot")
    config = tmp_path / "f.yaml"
    config.write_text("name: x\n")
    assert cli_main(["mark", str(config), str(photo)]) != 0
    assert "give one flight config, or drone photos" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli_main(["mark"])


def test_mark_of_a_folder_without_photos_says_it_has_none(tmp_path, capsys):
    """`ridgeloc mark FOLDER` takes a photo folder: one without photos is told so (it said only "a folder, not a
    flight config", as if mark took no folders), and no page is written."""
    folder = tmp_path / "empty"
    folder.mkdir()
    assert cli_main(["mark", str(folder)]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"ridgeloc: error: {folder}: no drone photos (.jpg, .jpeg files) here, and a folder is not a flight config: "
        f"`ridgeloc init {folder}` writes one from a flight's files"]
    assert list(folder.iterdir()) == []
