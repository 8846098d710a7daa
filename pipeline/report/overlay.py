"""overlay.mp4: a video flight's observation frames with what ridgeloc saw and answered drawn on them, so a user
sees whether the tracker followed the right thing (issue 40).

Per planned observation frame (every one, tracked, lost or dropped), in the order of the flight, held
`HOLD_S` seconds each: the source frame scaled to at most `MAX_WIDTH_PX` wide (browsers), and for every target
  - its tracked pixel with a reticle in the target's colour, or, where it was lost, a red cross at the pixel the
    homography predicted (when there was one) and why it was lost;
  - its answer (`pipeline.answer`: the one answer per target, or none) projected back into the frame with the
    frame's projection matrix, and the answer's 95 % ellipse: the 3-D covariance pushed through the projection's
    Jacobian (chi-square 2 dof, 95 %);
  - the laser's spot: the point on the rangefinder's axis (the image centre's ray from the rangefinder) at the
    target's distance (the answer's, else the measured range), projected into the frame;
and a caption with the frame number, its time (from the first observation, and UTC when the clock is UNIX time)
and the laser range. Frames are decoded again here (only the observation frames, `VideoFrames.prefetch`),
drawn with OpenCV and encoded with PyAV: H.264 (libx264, yuv420p, even size) in MP4 with the index at the front
(`movflags=+faststart`), which Chromium, Firefox and VLC play. Cost: one decode of each observation frame and one
small encode; `ridgeloc run --overlay` books it as the "overlay" stage.

Only observation frames carry a measurement: the frames between them are not drawn (a reticle there would be a
guess).
"""

from __future__ import annotations

import datetime
import math
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from pipeline.geometry.lens import distort_pixels
from pipeline.geometry.rays import camera_rays_m
from pipeline.results import FlightResult, GroupResult, per_target

OVERLAY_FILE = "overlay.mp4"
MAX_WIDTH_PX = 1280
HOLD_S = 0.5
CHI2_2_95 = 5.991464547107979  # chi-square, 2 degrees of freedom, 95 %
COLOURS_BGR = ((60, 220, 60), (255, 200, 0), (255, 80, 255), (0, 220, 255), (255, 140, 60))
LOST_BGR = (40, 40, 235)
ANSWER_BGR = (0, 165, 255)
LASER_BGR = (40, 40, 255)


@dataclass
class OverlayTarget:
    """What is drawn for one target: its label, tracking columns (tracking.json), observations (the used frames'
    P, range, laser origin) and its answer: ENU position (3,) m and covariance (3, 3) m^2, or None for none."""

    label: str
    tracking: dict
    observations: object
    position_m: np.ndarray | None
    covariance_m2: np.ndarray | None


def overlay_targets(result: GroupResult | FlightResult) -> list[OverlayTarget]:
    """The located targets of a run's result, each with its answer (`pipeline.report.answers.answer_of`)."""
    from pipeline.report.answers import answer_of

    out = []
    for r in per_target([result]):
        a = answer_of(r)
        out.append(OverlayTarget(r.target or "target", r.tracking or {}, r.observations,
                                 a.position_m if a.located else None, a.covariance_m2 if a.located else None))
    return out


def video_of(settings: dict) -> Path | None:
    """The video a flight's frames came from: `files.video`, else a telemetry file that is a video (MISB FMV)."""
    from pipeline.ingest.video import VIDEO_SUFFIXES

    files = (settings or {}).get("files") or {}
    if files.get("video"):
        return Path(files["video"])
    for f in files.get("telemetry") or []:
        if Path(f).suffix.lower() in VIDEO_SUFFIXES:
            return Path(f)
    return None


def _project(P: np.ndarray, X: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(pixel (2,), Jacobian d pixel / d X (2, 3)) of ENU point X through the 3x4 camera P; None behind it."""
    x = P @ np.append(X, 1.0)
    if not np.isfinite(x).all() or x[2] <= 0:
        return None, None
    uv = x[:2] / x[2]
    J = (P[:2, :3] - uv[:, None] * P[2, :3][None, :]) / x[2]
    return uv, J


def _ellipse(cov_px: np.ndarray) -> tuple[tuple[float, float], float] | None:
    """((semi-axis a, b) px, angle deg) of the 95 % ellipse of a 2x2 pixel covariance."""
    if not np.isfinite(cov_px).all():
        return None
    w, v = np.linalg.eigh(0.5 * (cov_px + cov_px.T))
    w = np.clip(w, 0.0, None)
    return (math.sqrt(w[1] * CHI2_2_95), math.sqrt(w[0] * CHI2_2_95)), math.degrees(math.atan2(v[1, 1], v[0, 1]))


def _clock_text(t_ns: int, t0_ns: int, unix_ns: int | None = None) -> str:
    """'t +S s' from the first observation, with the UTC time where the clock is UNIX time or `unix_ns` (the
    frame's time mapped onto UNIX time, a KLV video's packet time stamps) gives it."""
    text = f"t +{(t_ns - t0_ns) / 1e9:.2f} s"
    if unix_ns is None and t_ns > 10**17:  # a UNIX clock: show the UTC time too
        unix_ns = t_ns
    if unix_ns is not None:
        utc = datetime.datetime.fromtimestamp(unix_ns / 1e9, datetime.timezone.utc)
        text += f" ({utc:%H:%M:%S.%f}"[:-3] + " UTC)"
    return text


class _Canvas:
    """A scaled frame to draw on in source-frame pixel coordinates (sub-pixel, OpenCV's shift)."""

    SHIFT = 4

    def __init__(self, image: np.ndarray, scale: float):
        self.img, self.s = image, scale

    def _p(self, px) -> tuple[int, int]:
        k = self.s * (1 << self.SHIFT)
        return int(np.rint((px[0] + 0.5) * k - 0.5 * (1 << self.SHIFT))), \
            int(np.rint((px[1] + 0.5) * k - 0.5 * (1 << self.SHIFT)))

    def inside(self, px) -> bool:
        h, w = self.img.shape[:2]
        return bool(np.isfinite(px).all() and -w < px[0] * self.s < 2 * w and -h < px[1] * self.s < 2 * h)

    def reticle(self, px, colour, r: int = 14) -> None:
        import cv2

        if not self.inside(px):
            return
        c = self._p(px)
        one = 1 << self.SHIFT
        cv2.circle(self.img, c, r * one, colour, 2, cv2.LINE_AA, self.SHIFT)
        for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            cv2.line(self.img, (c[0] + dx * (r // 3) * one, c[1] + dy * (r // 3) * one),
                     (c[0] + dx * (r + 6) * one, c[1] + dy * (r + 6) * one), colour, 2, cv2.LINE_AA, self.SHIFT)

    def cross(self, px, colour, r: int = 10) -> None:
        import cv2

        if not self.inside(px):
            return
        c, one = self._p(px), 1 << self.SHIFT
        for dx, dy in ((1, 1), (1, -1)):
            cv2.line(self.img, (c[0] - dx * r * one, c[1] - dy * r * one), (c[0] + dx * r * one, c[1] + dy * r * one),
                     colour, 2, cv2.LINE_AA, self.SHIFT)

    def dot(self, px, colour, r: int = 4) -> None:
        import cv2

        if self.inside(px):
            cv2.circle(self.img, self._p(px), r << self.SHIFT, colour, -1, cv2.LINE_AA, self.SHIFT)

    def ellipse(self, px, axes_px, angle_deg, colour) -> None:
        import cv2

        if not self.inside(px):
            return
        one = 1 << self.SHIFT
        ax = (max(int(np.rint(axes_px[0] * self.s * one)), one), max(int(np.rint(axes_px[1] * self.s * one)), one))
        cv2.ellipse(self.img, self._p(px), ax, angle_deg, 0, 360, colour, 2, cv2.LINE_AA, self.SHIFT)

    def text(self, px, text: str, colour) -> None:
        import cv2

        if not self.inside(px):
            return
        x, y = int(px[0] * self.s) + 18, int(px[1] * self.s) - 12
        cv2.putText(self.img, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(self.img, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX, 0.5, colour, 1, cv2.LINE_AA)


def _caption(img: np.ndarray, lines: Sequence[str]) -> None:
    """White lines on a darkened band at the top (a browser's video controls cover the bottom while the mouse is
    over the video), the font scaled so a 640 px wide line fits the frame."""
    import cv2

    scale = min(0.5, img.shape[1] / 1280.0)
    step = int(np.ceil(40 * scale))
    h = step * len(lines) + step // 2
    band = img[:h]
    band[:] = (band * 0.35).astype(np.uint8)
    for k, line in enumerate(lines):
        cv2.putText(img, line, (6, step * (k + 1)), cv2.FONT_HERSHEY_SIMPLEX, scale,
                    (255, 255, 255), 1, cv2.LINE_AA)


def frame_camera(targets: Sequence[OverlayTarget], k: int) -> tuple[np.ndarray | None, np.ndarray | None, float]:
    """(P (3, 4), laser origin (3,) m, laser range m or NaN) of the planned frame `k`: every target's observations
    of a frame share its camera (a target dropped there borrows another's); the range is the frame's shot, which a
    target off the laser's axis does not keep (its range is NaN), so it comes from any target that kept it."""
    P = origin = None
    rng = math.nan
    for t in targets:
        used = t.tracking.get("used") or [True] * len(t.tracking["frame_index"])
        if not used[k]:
            continue
        j = int(sum(1 for u in used[:k] if u))  # the frame's row in this target's observations
        if P is None:
            P, origin = t.observations.P[j], t.observations.platform_m[j]
        if not np.isfinite(rng):
            rng = float(t.observations.range_m[j])
    return P, origin, rng


def draw_frame(image: np.ndarray, scale: float, k: int, targets: Sequence[OverlayTarget], camera: dict,
               t0_ns: int) -> np.ndarray:
    """One overlay frame: `image` the scaled source frame (BGR, drawn on in place), `k` the row of the planned
    frames (tracking columns), `camera` the resolved camera (cx_px, cy_px, K, dist) for the laser axis and the
    lens. Returns the image."""
    canvas = _Canvas(image, scale)
    first = targets[0].tracking
    frame = first["frame_index"][k]
    t_ns = (first.get("t_ns") or [t0_ns] * len(first["frame_index"]))[k]
    unix_ns = (first.get("unix_t_ns") or [None] * len(first["frame_index"]))[k]
    K = np.array([[camera["fx_px"], 0, camera["cx_px"]], [0, camera["fy_px"], camera["cy_px"]], [0, 0, 1.0]])
    dist = np.asarray(camera.get("dist") or [0.0] * 5, dtype=np.float64)
    lens = bool(np.any(dist != 0))

    def seen(px):  # an ideal pinhole pixel -> where the lens put it
        return distort_pixels(px[None], K, dist)[0] if lens else px

    P, origin, rng = frame_camera(targets, k)
    range_text = f"laser range {rng:.1f} m" if np.isfinite(rng) else "no laser range"
    status = []
    for n, t in enumerate(targets):
        colour = COLOURS_BGR[n % len(COLOURS_BGR)]
        tr = t.tracking
        px = tr["pixel_px"][k]
        if px is not None:
            canvas.reticle(np.asarray(px, dtype=float), colour)
            canvas.text(np.asarray(px, dtype=float), t.label, colour)
            status.append(f"{t.label}: tracked ({tr['via'][k]})")
        else:
            pred = (tr.get("predicted_px") or [None] * len(tr["frame_index"]))[k]
            if pred is not None:
                canvas.cross(np.asarray(pred, dtype=float), LOST_BGR)
                canvas.text(np.asarray(pred, dtype=float), f"{t.label}: LOST", LOST_BGR)
            status.append(f"{t.label}: LOST ({tr['via'][k]})")
        if P is None:
            continue
        if t.position_m is not None:
            uv, J = _project(P, np.asarray(t.position_m, dtype=float))
            if uv is not None:
                canvas.dot(seen(uv), ANSWER_BGR, 3)
                if t.covariance_m2 is not None:
                    e = _ellipse(J @ np.asarray(t.covariance_m2, dtype=float) @ J.T)
                    if e is not None:
                        canvas.ellipse(seen(uv), *e, ANSWER_BGR)
        # the laser's spot: the rangefinder's axis (the image centre's ray) at the target's distance
        dist_m = float(np.linalg.norm(np.asarray(t.position_m) - origin)) if t.position_m is not None else rng
        if np.isfinite(dist_m):
            _, axis = camera_rays_m(P[None], np.array([[camera["cx_px"], camera["cy_px"]]]))
            uv, _ = _project(P, origin + dist_m * axis[0])
            if uv is not None:
                canvas.dot(seen(uv), LASER_BGR, 4)
    _caption(image, [f"frame {frame}   {_clock_text(int(t_ns), t0_ns, unix_ns)}   {range_text}", "   ".join(status),
                     "reticle: tracked   red x: lost   orange: answer + 95 % ellipse   red dot: laser"])
    return image


def write_overlay(result: GroupResult | FlightResult, path, video: Path | None = None) -> dict:
    """Render the overlay of a video flight's result into `path` (MP4). Returns {"frames", "seconds", "width",
    "height"}. Raises InputError when the flight has no video or the video cannot be read."""
    import av
    import cv2

    from pipeline.errors import InputError
    from pipeline.ingest.video import VideoFrames

    first = per_target([result])[0]
    video = video or video_of(first.settings)
    if video is None or not Path(video).is_file():
        raise InputError(f"no video to draw the overlay on ({video or 'the flight names none'})")
    targets = overlay_targets(result)
    frames = [int(i) for i in targets[0].tracking.get("frame_index") or []]
    if not frames:
        raise InputError("the flight has no observation frame to draw", path=video)
    camera = first.settings.get("camera_resolved") or {}
    t0 = int((targets[0].tracking.get("t_ns") or [0])[0])
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with VideoFrames(video) as src:
        src.prefetch(frames)
        h0, w0 = src.index.frames.height_px, src.index.frames.width_px
        scale = min(1.0, MAX_WIDTH_PX / w0)
        w, h = 2 * int(np.rint(w0 * scale / 2)), 2 * int(np.rint(h0 * scale / 2))
        with av.open(str(tmp), "w", format="mp4", options={"movflags": "+faststart"}) as out:
            st = out.add_stream("libx264", rate=Fraction(1) / Fraction(HOLD_S).limit_denominator(1000))
            st.width, st.height, st.pix_fmt = w, h, "yuv420p"
            st.options = {"crf": "23", "preset": "veryfast"}
            for k, i in enumerate(frames):
                img = cv2.resize(src[i], (w, h), interpolation=cv2.INTER_AREA)
                draw_frame(img, w / w0, k, targets, camera, t0)
                vf = av.VideoFrame.from_ndarray(img, format="bgr24")
                vf.pts = k
                out.mux(st.encode(vf))
            out.mux(st.encode(None))
    tmp.replace(path)
    return {"frames": len(frames), "seconds": len(frames) * HOLD_S, "width": w, "height": h}
