"""The marking page of `ridgeloc mark`: one self-contained HTML file (frames inline as JPEG data URIs, plain
JavaScript, no network) that shows frames of a flight, or drone photos, lets the user click points, name them,
and download the marks CSV (`name,frame_or_image,x_px,y_px`, pipeline/targets.py) for the flight config's
`marks_file:` or `ridgeloc locate --marks` (photos: `frame_or_image` is the photo's path relative to the CSV).

A photo is shown as its stored pixels (the camera's, whatever EXIF Orientation says: pipeline.ingest.photo), scaled
down for the page where it is large; clicks are mapped to the photo's own pixels (its full width and height).

Pixel convention (as everywhere in ridgeloc): (0, 0) is the centre of the top-left pixel, so a click at
CSS offset (ox, oy) on an image drawn s times its natural size is the pixel (ox / s - 0.5, oy / s - 0.5).
"""

from __future__ import annotations

import base64
import json
from collections.abc import Mapping, Sequence
from html import escape

import cv2
import numpy as np

from pipeline.targets import MARKS_CSV_HEADER

_CSS = """
body { font: 14px system-ui, sans-serif; margin: 1em; color: #222; }
#wrap { position: relative; display: inline-block; border: 1px solid #888; cursor: crosshair; }
#frame { display: block; max-width: 100%; image-rendering: pixelated; }
#scroll { max-width: 100%; max-height: 80vh; overflow: auto; }
.centre { position: absolute; width: 15px; height: 15px; margin: -8px 0 0 -8px; pointer-events: none;
          background: linear-gradient(#0ff, #0ff) center / 1px 100% no-repeat,
                      linear-gradient(#0ff, #0ff) center / 100% 1px no-repeat; opacity: .8; }
.pin { position: absolute; width: 11px; height: 11px; margin: -6px 0 0 -6px; border: 2px solid #ff0;
       border-radius: 50%; box-shadow: 0 0 0 1px #000; pointer-events: none; }
.pin span { position: absolute; left: 12px; top: -6px; color: #ff0; font-weight: bold; text-shadow: 0 0 2px #000;
            white-space: nowrap; }
table { border-collapse: collapse; margin-top: .5em; } td, th { border: 1px solid #ccc; padding: 2px 6px; }
textarea { width: 40em; height: 8em; font: 12px monospace; }
"""

_JS = r"""
(function () {
  var FRAMES = %(frames)s;            // [{index, label, src, width, height}]: width, height of the frame itself
  var marks = %(marks)s;              // [{name, frame, x, y}]
  var PHOTOS = %(photos)s;            // one target in many photos: the next click keeps the last name
  var current = 0, lastName = '';
  var img = document.getElementById('frame'), wrap = document.getElementById('wrap');
  var sel = document.getElementById('frames'), nameBox = document.getElementById('name');
  var csvBox = document.getElementById('csv'), err = document.getElementById('error');
  FRAMES.forEach(function (f, i) {
    var o = document.createElement('option'); o.value = i; o.textContent = f.label; sel.appendChild(o);
  });
  function csvText() {
    var lines = [%(header)s];
    marks.forEach(function (m) { lines.push([m.name, m.frame, m.x.toFixed(2), m.y.toFixed(2)].join(',')); });
    return lines.join('\n') + '\n';
  }
  function draw() {
    var f = FRAMES[current];
    if (img.getAttribute('src') !== f.src) { img.src = f.src; }
    Array.prototype.slice.call(wrap.querySelectorAll('.pin, .centre')).forEach(function (p) { p.remove(); });
    var z = Number(zoomSel.value);  // 0: fit the page; else CSS pixels per image pixel
    img.style.maxWidth = z ? 'none' : '100%%';
    img.style.width = z ? (f.width * z) + 'px' : '';
    var s = img.clientWidth / f.width;
    var c = document.createElement('div'); c.className = 'centre';  // the image centre: where a laser points
    c.style.left = (f.width / 2 * s) + 'px'; c.style.top = (f.height / 2 * s) + 'px'; wrap.appendChild(c);
    marks.forEach(function (m) {
      if (m.frame !== f.index) { return; }
      var p = document.createElement('div'); p.className = 'pin';
      p.style.left = ((m.x + 0.5) * s) + 'px'; p.style.top = ((m.y + 0.5) * s) + 'px';
      var t = document.createElement('span'); t.textContent = m.name; p.appendChild(t); wrap.appendChild(p);
    });
    var rows = marks.map(function (m, i) {
      return '<tr><td>' + esc(m.name) + '</td><td>' + m.frame + '</td><td>' + m.x.toFixed(2) + '</td><td>' +
        m.y.toFixed(2) + '</td><td><button data-i="' + i + '">remove</button></td></tr>';
    });
    document.getElementById('list').innerHTML =
      '<tr><th>name</th><th>' + (PHOTOS ? 'photo' : 'frame') + '</th><th>x_px</th><th>y_px</th><th></th></tr>' +
      rows.join('');
    csvBox.value = csvText();
    document.body.setAttribute('data-marks', String(marks.length));
  }
  function esc(s) { return s.replace(/[&<>"]/g, function (c) { return '&#' + c.charCodeAt(0) + ';'; }); }
  function nextName() {
    var n = marks.length + 1;
    while (marks.some(function (m) { return m.name === 'T' + n; })) { n++; }
    return 'T' + n;
  }
  // A click: the image pixel under it (pixel centres at integers); the name from the box, else T<n>.
  window.ridgelocMark = function (x, y, name) {
    var f = FRAMES[current];
    var keep = PHOTOS && lastName && !marks.some(function (m) { return m.name === lastName && m.frame === f.index; });
    name = (name || '').trim() || (keep ? lastName : nextName());
    if (/[,\/\\:\n\r\t]|^\./.test(name)) {  // as pipeline.targets.check_name
      err.textContent = 'a name must not contain , / \\ : or a tab, nor start with a dot'; return false;
    }
    if (!(x >= -0.5 && y >= -0.5 && x <= f.width - 0.5 && y <= f.height - 0.5)) {  // as pipeline.targets.in_image
      err.textContent = 'outside the image'; return false;
    }
    if (marks.some(function (m) { return m.name === name && m.frame === f.index; })) {
      err.textContent = 'duplicate name ' + name + ' on ' + f.label; return false;
    }
    err.textContent = '';
    marks.push({name: name, frame: f.index, x: x, y: y}); nameBox.value = ''; lastName = name; draw(); return true;
  };
  img.addEventListener('click', function (ev) {
    var r = img.getBoundingClientRect(), f = FRAMES[current], s = r.width / f.width;
    window.ridgelocMark((ev.clientX - r.left) / s - 0.5, (ev.clientY - r.top) / s - 0.5, nameBox.value);
  });
  document.getElementById('list').addEventListener('click', function (ev) {
    var i = ev.target.getAttribute('data-i');
    if (i !== null) { marks.splice(Number(i), 1); draw(); }
  });
  sel.addEventListener('change', function () { current = Number(sel.value); draw(); });
  var zoomSel = document.getElementById('zoom');
  zoomSel.addEventListener('change', draw);
  img.addEventListener('load', draw);
  window.addEventListener('resize', draw);
  document.getElementById('save').addEventListener('click', function () {
    var a = document.createElement('a');
    a.href = 'data:text/csv;charset=utf-8,' + encodeURIComponent(csvText());
    a.download = %(csv_name)s; document.body.appendChild(a); a.click(); a.remove();
  });
  draw();
})();
"""


def jpeg_data_uri(image: np.ndarray, quality: int = 92) -> str:
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError("cannot encode the frame as JPEG")
    return "data:image/jpeg;base64," + base64.b64encode(buf.tobytes()).decode("ascii")


def mark_page(frames: Mapping[int | str, np.ndarray], title: str, marks: Sequence[dict] = (),
              csv_name: str = "marks.csv", sizes: Mapping[int | str, tuple[int, int]] | None = None) -> str:
    """The page: `frames` {frame index: image (gray or BGR)} of a video, or {photo path as the CSV names it:
    image} of photos (keys are str; one target is then marked in many photos under one name), `marks` already
    known ({name, frame, x, y}, frame the index or the photo's key). `sizes` {key: (width, height)} of an image
    shown scaled down: clicks are pixels of that size."""
    photos = any(isinstance(k, str) for k in frames)
    items = []
    for key, img in sorted(frames.items(), key=lambda kv: (str(kv[0]) if photos else kv[0])):
        w, h = (sizes or {}).get(key, (int(img.shape[1]), int(img.shape[0])))
        items.append({"index": key if photos else int(key), "label": str(key) if photos else f"frame {key}",
                      "src": jpeg_data_uri(img), "width": int(w), "height": int(h)})
    if not items:
        raise ValueError("no frame to mark")
    js = _JS % {"header": json.dumps(",".join(MARKS_CSV_HEADER)), "frames": json.dumps(items),
                "marks": json.dumps(list(marks)), "csv_name": json.dumps(csv_name),
                "photos": "true" if photos else "false"}
    what = "photo" if photos else "frame"
    how = ("Choose a photo, type the target's name (or leave it empty: T1, and the same name in the next photo) and "
           "click it; mark it in every photo that shows it. Then save the marks CSV beside this page and give it to "
           "<code>ridgeloc locate --marks</code> or a photo flight config's <code>marks_file:</code>." if photos else
           "Choose a frame, type a name (or leave it empty for T1, T2 ...) and click the point. A target may be "
           "marked in several frames under the same name. Then save the marks CSV and set <code>marks_file:</code> "
           "in the flight config to it.")
    return (f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{escape(title)}</title>"
            f"<style>{_CSS}</style></head><body><h1>{escape(title)}</h1>"
            f"<p>{how}</p>"
            f"<p><label>{what.capitalize()} <select id=\"frames\"></select></label> "
            "<label>Name <input id=\"name\" size=\"16\"></label> "
            "<label>Zoom <select id=\"zoom\"><option value=\"0\">fit</option><option value=\"1\">1x</option>"
            "<option value=\"2\">2x</option><option value=\"4\">4x</option><option value=\"8\">8x</option>"
            "</select></label> <span title=\"the image centre, where a laser points\">cyan cross: image centre "
            "(laser)</span> "
            f"<button id=\"save\">Save {escape(csv_name)}</button> <span id=\"error\" style=\"color:#b00\"></span></p>"
            "<div id=\"scroll\"><div id=\"wrap\"><img id=\"frame\" alt=\"frame\"></div></div>"
            "<table id=\"list\"></table>"
            f"<p>{escape(','.join(MARKS_CSV_HEADER))} (what Save writes):<br>"
            "<textarea id=\"csv\" readonly></textarea></p>"
            f"<script>{js}</script></body></html>\n")
