"""overlay.mp4 (issue 40): `ridgeloc run --overlay` and `ridgeloc overlay OUT/GROUP` write it per video flight,
its cost is a stage of the run, report.html shows it, and headless Chromium plays it from there."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

from pipeline.cli import main

ROOT = Path(__file__).resolve().parents[1]
CLIP = ROOT / ".." / "shared" / "fmv" / "aphill_klv_10s.ts"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--allow-file-access-from-files", "--autoplay-policy="
         "no-user-gesture-required", "--virtual-time-budget=60000")

# When the video can play: its duration, size and ready state; then seek into it and draw the frame on a canvas to
# count how many pixels are not black (a decoded frame, not an empty box).
_PROBE = """<script>
window.addEventListener('load', function () {
  var v = document.querySelector('video.overlay');
  if (!v) { document.body.setAttribute('data-probe', 'no-video'); return; }
  v.addEventListener('error', function () { document.body.setAttribute('data-probe', 'error:' + v.error.code); });
  v.addEventListener('loadeddata', function () {
    var d = v.duration;
    v.addEventListener('seeked', function () {
      var c = document.createElement('canvas'); c.width = v.videoWidth; c.height = v.videoHeight;
      var g = c.getContext('2d'); g.drawImage(v, 0, 0);
      var px = g.getImageData(0, 0, c.width, c.height).data, lit = 0;
      for (var i = 0; i < px.length; i += 4) { if (px[i] + px[i + 1] + px[i + 2] > 30) lit++; }
      document.body.setAttribute('data-probe', [d, v.videoWidth, v.videoHeight, v.readyState, lit,
                                                c.width * c.height].join(','));
    }, {once: true});
    v.currentTime = Math.min(d / 2, 3.0);
  });
  v.load();
});
</script>"""


def _probe(report: Path) -> list[float]:
    """The probe's figures; tried up to three times (the browser loads the media in real time beside its virtual
    clock: on a machine loaded by other jobs a first try can end before the video has loaded)."""
    page = report.with_name("probe.html")
    page.write_text(report.read_text().replace("</body>", _PROBE + "</body>"))
    for _ in range(3):
        with tempfile.TemporaryDirectory() as profile:
            out = subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={profile}", "--dump-dom", page.as_uri()],
                                 capture_output=True, text=True, timeout=180)
        m = re.search(r'data-probe="([^"]*)"', out.stdout)
        if m:
            break
    assert m, (out.stdout[-1500:], out.stderr[-1500:])
    assert "," in m.group(1), m.group(1)
    return [float(x) for x in m.group(1).split(",")]


def _read(mp4: Path) -> tuple[int, float, tuple[int, int], str]:
    import av

    with av.open(str(mp4)) as c:
        s = c.streams.video[0]
        n = sum(1 for _ in c.decode(s))
        return n, c.duration / 1e6, (s.codec_context.width, s.codec_context.height), s.codec_context.name


@pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium not installed (.ci/run installs it)")
def test_run_overlay_writes_an_mp4_that_plays_in_report_html(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", "configs/flights/fmv.yaml", "-o", str(out), "--overlay", "--no-figures", "-q"]) == 0
    mp4 = out / "fmv" / "overlay.mp4"
    tracking = json.loads((out / "fmv" / "tracking.json").read_text())
    n, duration_s, size, codec = _read(mp4)
    assert codec == "h264" and n == len(tracking["frame_index"]) and duration_s == pytest.approx(n * 0.5, abs=0.6)
    result = json.loads((out / "fmv" / "result.json").read_text())
    assert result["timings_s"]["overlay"] > 0 and result["settings"]["overlay"]["frames"] == n
    html = (out / "report.html").read_text()
    assert 'src="fmv/overlay.mp4"' in html
    d, w, h, ready, lit, total = _probe(out / "report.html")
    assert d == pytest.approx(duration_s, abs=0.6) and (w, h) == size and ready >= 2 and lit > 0.5 * total


def test_overlay_command_on_a_finished_kwiver_clip_and_its_drawing(tmp_path, capsys):
    """`ridgeloc overlay OUT/GROUP` after a run without it; the reticle is drawn where the tracker put the
    target (green on the frame, scaled), and report.html is rewritten to show the video."""
    if not CLIP.is_file():
        pytest.skip(f"{CLIP} absent (the shared read-only material is not beside this checkout)")
    out = tmp_path / "out"
    assert main(["run", str(CLIP), "-o", str(out), "--no-figures", "-q"]) == 0
    group = out / "aphill_klv_10s"
    assert not (group / "overlay.mp4").exists() and "overlay.mp4" not in (out / "report.html").read_text()
    capsys.readouterr()
    assert main(["overlay", str(group)]) == 0
    assert "overlay.mp4 (10 frames)" in capsys.readouterr().out
    n, _, size, _ = _read(group / "overlay.mp4")
    assert n == 10 and size == (360, 240)
    assert 'src="aphill_klv_10s/overlay.mp4"' in (out / "report.html").read_text()
    result = json.loads((group / "result.json").read_text())
    assert result["timings_s"]["overlay"] > 0

    import av

    tracking = json.loads((group / "tracking.json").read_text())
    k = next(i for i, p in enumerate(tracking["pixel_px"]) if p is not None)
    with av.open(str(group / "overlay.mp4")) as c:
        frame = [f.to_ndarray(format="bgr24") for f in c.decode(video=0)][k]
    x, y = (round(float(v)) for v in tracking["pixel_px"][k])
    ring = frame[max(y - 20, 0):y + 21, max(x - 20, 0):x + 21].astype(int)
    green = (ring[..., 1] > 150) & (ring[..., 0] < 120) & (ring[..., 2] < 120)
    assert green.sum() > 20  # the reticle around the tracked pixel


def test_overlay_refuses_a_folder_that_is_not_a_finished_flight(tmp_path, capsys):
    (tmp_path / "x").mkdir()
    assert main(["overlay", str(tmp_path / "x")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "x: not a finished flight folder" in err[0]
    assert not (tmp_path / "x" / "overlay.mp4").exists()
    assert main(["overlay", str(tmp_path / "nope")]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"ridgeloc: error: {tmp_path / 'nope'}: no such folder (give a flight's folder in a `ridgeloc run` output "
        "folder, OUT/FLIGHT)"]
    (tmp_path / "run.json").write_text(json.dumps({"groups": ["a", "b"]}))  # a run's folder, not a flight's
    assert main(["overlay", str(tmp_path)]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"ridgeloc: error: {tmp_path}: a run's output folder, not one of its flights: give a flight's folder, "
        f"{tmp_path / 'a'} or {tmp_path / 'b'}"]


def test_overlay_caption_range_is_the_frames_shot_whichever_target_kept_it():
    """Two targets on one frame: the first lies off the laser's axis, so its observation keeps no range (NaN); the
    caption's laser range is still the frame's shot, which the second target kept (the kwiver clip with a target
    marked beside the crosshair showed 'no laser range' on every frame)."""
    from types import SimpleNamespace

    import numpy as np

    from pipeline.report.overlay import OverlayTarget, frame_camera

    P = np.hstack([np.eye(3), np.zeros((3, 1))])
    tracking = {"frame_index": [0, 5], "used": [True, True]}

    def target(label, ranges):
        obs = SimpleNamespace(P=np.stack([P, P]), platform_m=np.zeros((2, 3)), range_m=np.array(ranges))
        return OverlayTarget(label, tracking, obs, None, None)

    off_axis, on_axis = target("car", [np.nan, np.nan]), target("truck", [1730.3, 1731.0])
    _, _, rng = frame_camera([off_axis, on_axis], 1)
    assert rng == pytest.approx(1731.0)
    P1, origin, rng = frame_camera([off_axis, target("gone", [np.nan, np.nan])], 0)
    assert P1 is not None and origin is not None and np.isnan(rng)


def test_a_klv_video_overlay_caption_gives_utc_from_the_packets_time_stamps():
    """A KLV video runs on its own "video" clock; its packets' time stamps (tag 2, UNIX microseconds) map the
    frames onto UTC, which the caption shows beside the time from the first observation."""
    from pathlib import Path

    import numpy as np

    from pipeline.ingest import read_flight
    from pipeline.report.overlay import _clock_text
    from pipeline.target_stage import unix_times_ns

    assert _clock_text(3_000_000_000, 0, 1_221_665_015_033_181_004) == "t +3.00 s (15:23:35.033 UTC)"
    assert _clock_text(3_000_000_000, 0) == "t +3.00 s"
    root = Path(__file__).resolve().parents[1]
    log = read_flight([root / "sample_data" / "fmv" / "flight.ts"])
    table = next(iter(log.klv_tables.values()))
    unix = unix_times_ns(log, table.t_ns[:5])
    assert unix is not None and np.abs(np.array(unix) - table.t_us[:5] * 1000).max() < 1_000_000  # within 1 ms
    assert unix_times_ns(read_flight([root / "sample_data" / "group1" / "flight.tlog"]), table.t_ns[:5]) is None


def test_the_caption_band_is_at_the_top_where_a_browsers_controls_do_not_cover_it():
    import numpy as np

    from pipeline.report.overlay import _caption

    img = np.full((240, 360, 3), 200, np.uint8)
    _caption(img, ["frame 3", "target: tracked", "legend"])
    assert img[:5].mean() < 100 and (img[-40:] == 200).all()
