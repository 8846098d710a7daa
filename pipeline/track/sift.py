"""Carry the operator's target mark from frame to frame: SIFT features, ratio-test matching, RANSAC homography
through key frames, then sub-pixel refinement against the ORIGINAL mark.

For each frame (processed outward from the mark frame, forward and backward in time):
1. SIFT features are matched to the current key frame (Lowe's ratio test) and a homography H_cur_from_key is
   fitted with RANSAC; the ground at kilometres of range is close to a plane, so one homography maps it. On large
   frames the features are those of a window around the target (where it was last found, and around it in the
   key frame: `tracking.detect_window_px`), the whole frames' only when the windows give too few matches.
2. The mark's pixel is predicted through the chain H_cur_from_mark = H_cur_from_key @ H_key_from_mark.
3. The mark image is warped into the current frame by H_cur_from_mark and the patch around the target is
   located in the current frame by normalised cross-correlation in a small window, with a parabolic fit of the
   peak for the sub-pixel position. The template always comes from the mark frame, so errors of the chain shift
   only the prediction, not the answer; and the chain is re-anchored on the position found (H_cur_from_mark moved
   by the refinement's offset from the prediction), so those shifts do not add up over a long flight either.
4. Quality: inlier count and ratio, RANSAC reprojection RMS, peak correlation. Below thresholds the frame is
   flagged lost (pixel NaN), never guessed. A failed frame is retried against the mark frame itself
   (re-acquisition) and through intermediate frames (stepping stones) when the caller offers them; with a
   `ViewCache` that shares matches (a flight's named targets), not where the key frame's homography holds: it
   then puts the target outside the image (it has left the view) or inside but not found there (covered, washed
   out: too low a correlation or contrast), and stones, which only change the homography, would cost decoding and
   SIFT for the same view of it.
   (Without one, as for a flight's single `target:`, they are tried there too: every match draws from one random
   stream, so skipping one would shift every later frame's matches.)
5. The current frame becomes the key frame when its inliers fall below a fraction of the key's first match, or
   after a re-acquisition, so later frames match a recent view.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from pipeline.errors import InputError
from pipeline.flight_config import TrackerSettings


@dataclass
class _View:
    """A decoded frame and its features: of the whole frame (found on first use, `SiftTracker.features`), or of a
    window of it (`window` (x0, y0, x1, y1) full-resolution pixels, `SiftTracker.window_view`)."""

    index: int
    image: np.ndarray  # grayscale uint8
    keypoints_px: np.ndarray | None = None  # (k, 2) full-resolution pixels; None until found
    descriptors: np.ndarray | None = None  # (k, 128) float32
    window: tuple[int, int, int, int] | None = None


@dataclass
class _Key:
    view: _View
    H_key_from_mark: np.ndarray
    first_inliers: int | None = None
    centre_px: np.ndarray | None = None  # the target's pixel in the key frame (its feature window's centre)
    window: _View | None = None  # the key frame's features around centre_px, found on first use


@dataclass
class FrameTrack:
    """One frame's tracking outcome."""

    frame_index: int
    pixel_px: tuple[float, float] = (float("nan"), float("nan"))
    lost: bool = True
    inliers: int = 0
    inlier_ratio: float = 0.0
    reproj_px: float = float("nan")
    correlation: float = float("nan")
    contrast: float = float("nan")
    keyframe: bool = False
    via: str = ""  # "mark" (the mark frame), "key", "reacquired", "bridge", or why it was lost
    predicted_px: tuple[float, float] = (float("nan"), float("nan"))  # where the homography puts the mark, if any


@dataclass
class TrackResult:
    """Tracking of m frames, in the order asked: frame_index (m,), pixel_px (m, 2) image pixels (distorted, as
    seen) or NaN when lost, lost (m,) bool, and per-frame quality."""

    frames: list[FrameTrack] = field(default_factory=list)

    @property
    def frame_index(self) -> np.ndarray:
        return np.array([f.frame_index for f in self.frames], dtype=np.int64)

    @property
    def pixel_px(self) -> np.ndarray:
        return np.array([f.pixel_px for f in self.frames], dtype=np.float64).reshape(-1, 2)

    @property
    def predicted_px(self) -> np.ndarray:
        """(m, 2) where the homography chain puts the mark, also in lost frames (NaN where no homography)."""
        return np.array([f.predicted_px for f in self.frames], dtype=np.float64).reshape(-1, 2)

    @property
    def lost(self) -> np.ndarray:
        return np.array([f.lost for f in self.frames], dtype=bool)

    def to_dict(self) -> dict:
        """Per-frame columns, JSON-serialisable (NaN -> None)."""
        def clean(v):
            return None if isinstance(v, float) and not np.isfinite(v) else v

        cols = ("frame_index", "lost", "inliers", "inlier_ratio", "reproj_px", "correlation", "contrast", "keyframe",
                "via")
        out = {c: [clean(getattr(f, c)) for f in self.frames] for c in cols}
        out["pixel_px"] = [None if f.lost else [float(f.pixel_px[0]), float(f.pixel_px[1])] for f in self.frames]
        out["predicted_px"] = [None if not np.isfinite(f.predicted_px).all() else [float(v) for v in f.predicted_px]
                               for f in self.frames]
        return out


class ViewCache:
    """Decoded frames' features shared by every target of a flight: each frame is decoded and its SIFT features
    computed once, whatever the number of targets tracked through it. Holds (grayscale image, keypoints,
    descriptors) per frame until dropped with the cache, up to `max_bytes`: past it, further frames are not kept
    (a later target decodes them again), so memory does not grow with the flight's length. Not evicting keeps
    the first frames for every later pass over the same frames in the same order (an LRU would keep none).

    share_matches: also keep each frame pair's homography (matching and RANSAC), so that targets tracked
    through the same key frames match each pair once. Each pair is then matched with FLANN's random trees seeded
    by the pair itself, so a target's track does not depend on which targets were tracked before it (without
    it, as for a flight's single `target:`, the seed is set once per track, as before many targets)."""

    def __init__(self, share_matches: bool = False, max_bytes: int = 192 * 2**20):
        self.views: dict[int, _View] = {}
        self.pairs: dict[tuple[int, int], tuple] | None = {} if share_matches else None
        self.max_bytes = max_bytes
        self.bytes = 0

    def get(self, tracker: SiftTracker, decode: Callable[[Sequence[int]], dict[int, np.ndarray]],
            indices: Sequence[int]) -> dict[int, _View]:
        """{index: view} of the frames among `indices` that decode, decoding only those not kept before."""
        out = {int(i): self.views[int(i)] for i in indices if int(i) in self.views}
        missing = [int(i) for i in indices if int(i) not in self.views]
        if missing:
            for i, img in decode(missing).items():
                v = out[int(i)] = tracker.view(int(i), img)
                size = v.image.nbytes + tracker.s.n_features * (128 * 4 + 2 * 4)  # the image and its features
                if self.bytes + size <= self.max_bytes:
                    self.views[int(i)] = v
                    self.bytes += size
        return {int(i): out[int(i)] for i in indices if int(i) in out}


def to_gray(image: np.ndarray) -> np.ndarray:
    if image.ndim == 2:
        return image
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def _subpixel_peak(r: np.ndarray) -> tuple[float, float, float]:
    """(x, y, value) of the maximum of a correlation surface, refined by a parabola through its neighbours."""
    _, peak, _, (x, y) = cv2.minMaxLoc(r)
    dx = dy = 0.0
    if 0 < x < r.shape[1] - 1:
        a, b, c = r[y, x - 1], r[y, x], r[y, x + 1]
        den = a - 2 * b + c
        dx = 0.5 * (a - c) / den if den < 0 else 0.0
    if 0 < y < r.shape[0] - 1:
        a, b, c = r[y - 1, x], r[y, x], r[y + 1, x]
        den = a - 2 * b + c
        dy = 0.5 * (a - c) / den if den < 0 else 0.0
    return x + float(np.clip(dx, -0.5, 0.5)), y + float(np.clip(dy, -0.5, 0.5)), float(peak)


class SiftTracker:
    """Track one marked ground point through chosen frames of a flight (see the module docstring)."""

    def __init__(self, settings: TrackerSettings | None = None):
        self._pairs: dict | None = None  # a ViewCache's shared homographies during track(), when it shares them
        self._available: tuple = (None, [])  # the last `available` given to track() and its frames sorted
        self._last_window: tuple | None = None  # the last window view found (`_window_of`)
        self.s = settings or TrackerSettings()
        self._sift = cv2.SIFT_create(nfeatures=self.s.n_features)
        self._matcher = cv2.FlannBasedMatcher({"algorithm": 1, "trees": 4}, {"checks": 48})

    # ---- features and matching ---------------------------------------------------------------------------

    def view(self, index: int, image: np.ndarray) -> _View:
        """A decoded frame (grayscale); its features are found when first needed (`features`, `window_view`)."""
        return _View(int(index), to_gray(image))

    def _detect(self, image: np.ndarray, f: float) -> tuple[np.ndarray, np.ndarray | None]:
        """SIFT keypoints (k, 2) in `image`'s own pixels and descriptors, found on it resized by f."""
        small = image if f == 1.0 else cv2.resize(image, None, fx=f, fy=f, interpolation=cv2.INTER_AREA)
        kp, desc = self._sift.detectAndCompute(small, None)
        # keypoints back to full-resolution pixel coordinates (pixel centres at integers in both)
        pts = ((np.array([k.pt for k in kp], dtype=np.float32).reshape(-1, 2) + 0.5) / f - 0.5).astype(np.float32)
        return pts, desc

    def _whole_scale(self, view: _View) -> float:
        return min(self.s.detect_scale, self.s.max_detect_px / max(view.image.shape))

    def features(self, view: _View) -> _View:
        """The view with its whole-frame features, found (once) on a reduced copy: `detect_scale`, and no more than
        `max_detect_px` on the long side, so SIFT's cost does not grow with the video's resolution (the refinement
        stays full-res)."""
        if view.keypoints_px is None:
            view.keypoints_px, view.descriptors = self._detect(view.image, self._whole_scale(view))
        return view

    def windowed(self, view: _View) -> bool:
        """Whether features are found in a window around the target (`tracking.detect_window_px` square, reduced
        by `detect_scale`) rather than on the whole reduced frame: when the window has at most half the pixels
        SIFT would see on the whole frame, and no other target shares this frame's matches."""
        w, f = self.s.detect_window_px, self.s.detect_scale
        h, wid = view.image.shape[:2]
        whole = self._whole_scale(view) ** 2 * h * wid
        return self._pairs is None and w > 0 and (w * f) ** 2 <= 0.5 * whole and w < min(h, wid)

    def window_view(self, view: _View, centre_px: np.ndarray) -> _View:
        """Features of the `detect_window_px` square of `view` centred on centre_px (moved inside the image),
        found on it reduced by `detect_scale`, in full-frame pixels."""
        w = self.s.detect_window_px
        h, wid = view.image.shape[:2]
        x0 = int(np.clip(round(float(centre_px[0]) - w / 2), 0, wid - w))
        y0 = int(np.clip(round(float(centre_px[1]) - w / 2), 0, h - w))
        pts, desc = self._detect(view.image[y0:y0 + w, x0:x0 + w], self.s.detect_scale)
        return _View(view.index, view.image, pts + np.float32([x0, y0]), desc, (x0, y0, x0 + w, y0 + w))

    def homography(self, src: _View, dst: _View) -> tuple[np.ndarray | None, int, float, float]:
        """H_dst_from_src by ratio-test matches and RANSAC: (H or None, inliers, inlier ratio, RMS reprojection
        px of the inliers)."""
        if self._pairs is None or src.index < 0 or dst.index < 0 or src.window or dst.window:
            return self._homography(src, dst)
        key = (src.index, dst.index)
        if key not in self._pairs:
            cv2.setRNGSeed((0x5EED + 7919 * key[0] + 104729 * key[1]) & 0x7FFFFFFF)  # the pair's own seed
            self._pairs[key] = self._homography(src, dst)
        return self._pairs[key]

    def _homography(self, src: _View, dst: _View) -> tuple[np.ndarray | None, int, float, float]:
        if src.descriptors is None or dst.descriptors is None or len(src.descriptors) < 4 or len(dst.descriptors) < 4:
            return None, 0, 0.0, float("nan")
        pairs = self._matcher.knnMatch(src.descriptors, dst.descriptors, k=2)
        good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < self.s.ratio * p[1].distance]
        if len(good) < max(4, self.s.min_inliers):
            return None, len(good), 0.0, float("nan")
        a = src.keypoints_px[[m.queryIdx for m in good]]
        b = dst.keypoints_px[[m.trainIdx for m in good]]
        H, mask = cv2.findHomography(a, b, cv2.RANSAC, self.s.ransac_reproj_px, maxIters=2000, confidence=0.999)
        if H is None or not np.isfinite(H).all():
            return None, 0, 0.0, float("nan")
        inl = mask.ravel().astype(bool)
        if not inl.any():
            return None, 0, 0.0, float("nan")
        proj = cv2.perspectiveTransform(a[inl].reshape(-1, 1, 2).astype(np.float64), H).reshape(-1, 2)
        rms = float(np.sqrt(np.mean(np.sum((proj - b[inl]) ** 2, axis=1))))
        return H, int(inl.sum()), float(inl.mean()), rms

    # ---- refinement against the mark ---------------------------------------------------------------------

    def refine(self, mark: _View, mark_px: np.ndarray, cur: _View, H_cur_from_mark: np.ndarray
               ) -> tuple[np.ndarray, float, float]:
        """Sub-pixel target position in `cur` near the prediction H_cur_from_mark(mark_px), the peak normalised
        correlation of the mark's warped patch there, and the contrast ratio std(found patch) / std(mark patch).
        Correlation ignores gain and offset, so a target washed out by cloud or haze still correlates; the
        contrast ratio tells it apart."""
        h, s = self.s.patch_half_px, self.s.search_half_px
        pred = cv2.perspectiveTransform(mark_px.reshape(1, 1, 2).astype(np.float64), H_cur_from_mark).reshape(2)
        # Warp only the neighbourhood: translate so the prediction lands at the patch centre.
        T = np.array([[1.0, 0.0, h - pred[0]], [0.0, 1.0, h - pred[1]], [0.0, 0.0, 1.0]])
        templ = cv2.warpPerspective(mark.image, T @ H_cur_from_mark, (2 * h + 1, 2 * h + 1), flags=cv2.INTER_LINEAR,
                                    borderMode=cv2.BORDER_REPLICATE)
        size = 2 * (h + s) + 1
        window = cv2.getRectSubPix(cur.image, (size, size), (float(pred[0]), float(pred[1])))
        if float(templ.std()) < 1e-3 or float(window.std()) < 1e-3:
            return pred, float("nan"), 0.0
        r = cv2.matchTemplate(window.astype(np.float32), templ.astype(np.float32), cv2.TM_CCOEFF_NORMED)
        x, y, peak = _subpixel_peak(r)
        px = pred + np.array([x - s, y - s])
        found = cv2.getRectSubPix(cur.image, (2 * h + 1, 2 * h + 1), (float(px[0]), float(px[1])))
        return px, peak, float(found.std()) / float(templ.std())

    # ---- the tracking loop -------------------------------------------------------------------------------

    def _in_image(self, px: np.ndarray, view: _View) -> bool:
        m = self.s.patch_half_px
        hgt, wid = view.image.shape[:2]
        return bool(np.isfinite(px).all() and m <= px[0] < wid - m and m <= px[1] < hgt - m)

    def _attempt(self, key: _Key, mark: _View, mark_px: np.ndarray, cur: _View, via: str,
                 centre_px: np.ndarray | None = None) -> tuple[FrameTrack, np.ndarray | None]:
        """Match `cur` to the key frame and refine the target against the mark: (the frame's track, H_cur_from_mark
        or None when lost). `centre_px`: where the target is expected in `cur`; where features are found in
        windows (`windowed`), those around it and around the target in the key frame are matched first, the
        whole frames only when the windows give too few matches."""
        if centre_px is not None and self.windowed(cur):
            if key.window is None:
                c = key.centre_px if key.centre_px is not None else cv2.perspectiveTransform(
                    mark_px.reshape(1, 1, 2).astype(np.float64), key.H_key_from_mark).reshape(2)
                key.window = self.window_view(key.view, c)
            ft, H = self._match(key.window, key.H_key_from_mark, mark, mark_px, self._window_of(cur, centre_px), via)
            if ft.via != "too few matches":
                return ft, H
        return self._match(self.features(key.view), key.H_key_from_mark, mark, mark_px, self.features(cur), via)

    def _window_of(self, cur: _View, centre_px: np.ndarray) -> _View:
        """`window_view(cur, centre_px)`, kept for the next attempt on the same frame and centre."""
        memo = (cur.index, id(cur.image), float(centre_px[0]), float(centre_px[1]))
        if self._last_window is None or self._last_window[0] != memo:
            self._last_window = (memo, self.window_view(cur, centre_px))
        return self._last_window[1]

    def _match(self, key_view: _View, H_key_from_mark: np.ndarray, mark: _View, mark_px: np.ndarray, cur: _View,
               via: str) -> tuple[FrameTrack, np.ndarray | None]:
        H, inl, ratio, rms = self.homography(key_view, cur)
        ft = FrameTrack(cur.index, inliers=inl, inlier_ratio=ratio, reproj_px=rms)
        if H is None or inl < self.s.min_inliers or ratio < self.s.min_inlier_ratio:
            ft.via = "too few matches"
            return ft, None
        H_cur_from_mark = H @ H_key_from_mark
        pred = cv2.perspectiveTransform(mark_px.reshape(1, 1, 2).astype(np.float64), H_cur_from_mark).reshape(2)
        ft.predicted_px = (float(pred[0]), float(pred[1]))
        if not self._in_image(pred, cur):
            ft.via = "out of image"
            return ft, None
        px, corr, contrast = self.refine(mark, mark_px, cur, H_cur_from_mark)
        ft.correlation = corr
        ft.contrast = contrast
        if not np.isfinite(corr) or corr < self.s.min_correlation or not self._in_image(px, cur):
            ft.via = "low correlation"
            return ft, None
        if not self.s.min_contrast_ratio <= contrast <= 1.0 / self.s.min_contrast_ratio:
            ft.via = "low contrast"
            return ft, None
        ft.pixel_px = (float(px[0]), float(px[1]))
        ft.lost = False
        ft.via = via
        return ft, self._reanchor(H_cur_from_mark, pred, px)

    @staticmethod
    def _reanchor(H_cur_from_mark: np.ndarray, predicted_px: np.ndarray, found_px: np.ndarray) -> np.ndarray:
        """H_cur_from_mark moved so that it maps the mark to where the target was found: a key frame made from
        this frame predicts the next ones from the refined position, so the chain's drift does not add up from
        key frame to key frame (its local shape, which warps the template, is unchanged)."""
        d = np.asarray(found_px, dtype=np.float64) - np.asarray(predicted_px, dtype=np.float64)
        return np.array([[1.0, 0.0, d[0]], [0.0, 1.0, d[1]], [0.0, 0.0, 1.0]]) @ H_cur_from_mark

    def track(self, decode: Callable[[Sequence[int]], dict[int, np.ndarray]], mark_index: int,
              mark_px: Sequence[float], wanted: Sequence[int], available: Sequence[int] | None = None,
              cache: ViewCache | None = None) -> TrackResult:
        """Track the point marked at `mark_px` (image pixel) in frame `mark_index` through the `wanted` frames.

        `decode(indices)` returns {index: image} (BGR or gray) for frame numbers; `available` lists every frame
        number that could be decoded, from which stepping stones are taken when a wanted frame cannot be matched
        directly (given again as the same list, unchanged, for another target: it is sorted once). `cache`:
        frames' features shared with other targets' tracks (each frame decoded once); without it only the mark and
        key frames are kept (memory stays flat). Returns the wanted frames' tracks in the order of `wanted`."""
        cv2.setRNGSeed(0x5EED)  # FLANN's randomised trees draw from OpenCV's RNG: same input, same answer
        self._pairs = cache.pairs if cache is not None else None
        try:
            return self._track(decode, mark_index, mark_px, wanted, available, cache)
        finally:
            self._pairs, self._last_window = None, None

    def _track(self, decode, mark_index, mark_px, wanted, available, cache) -> TrackResult:
        if cache is not None:
            def decode_views(indices):
                return cache.get(self, decode, indices)
        else:
            def decode_views(indices):
                return {i: self.view(i, img) for i, img in decode(indices).items()}
        wanted = [int(i) for i in wanted]
        mark_index = int(mark_index)
        p0 = np.asarray(mark_px, dtype=np.float64)
        forward = sorted(i for i in set(wanted) if i > mark_index)
        backward = sorted((i for i in set(wanted) if i < mark_index), reverse=True)
        prefetch = getattr(decode, "prefetch", None)  # a reader that decodes ahead is told the order of the loop
        if prefetch is not None:
            prefetch([i for i in [mark_index, *forward, *backward] if cache is None or i not in cache.views])
        got0 = decode_views([mark_index])  # the others one at a time as the loop reaches them
        if mark_index not in got0:
            raise InputError(f"the target's mark frame {mark_index} cannot be decoded")
        mark = got0[mark_index]
        if not self._in_image(p0, mark):
            raise InputError(f"the target mark {p0.tolist()} is not inside frame {mark_index} "
                             f"({mark.image.shape[1]}x{mark.image.shape[0]} px) with a {self.s.patch_half_px} px "
                             "margin")
        def enough(v: _View) -> bool:
            return v.descriptors is not None and len(v.descriptors) >= self.s.min_inliers

        mark_window = self.window_view(mark, p0) if self.windowed(mark) else None
        if not (mark_window is not None and enough(mark_window)) and not enough(self.features(mark)):
            raise InputError(f"the target's mark frame {mark_index} has too few SIFT features to track")

        mark_features = mark_window if mark_window is not None and enough(mark_window) else mark

        def mark_key() -> _Key:
            return _Key(mark, np.eye(3), centre_px=p0, window=mark_window)

        views: dict[int, _View] = {mark_index: mark}
        p0_t = (float(p0[0]), float(p0[1]))
        out: dict[int, FrameTrack] = {mark_index: FrameTrack(
            mark_index, pixel_px=p0_t, lost=False, inliers=len(mark_features.keypoints_px), inlier_ratio=1.0,
            reproj_px=0.0, correlation=1.0, contrast=1.0, keyframe=True, via="mark", predicted_px=p0_t)}
        if available is None:
            avail = []
        elif available is self._available[0]:  # a flight's frame index, sorted once for all its targets
            avail = self._available[1]
        else:
            avail = sorted(set(int(i) for i in available))
            self._available = (available, avail)
        for seq in (forward, backward):
            direction = 1 if seq is forward else -1
            key = mark_key()
            centre = p0  # where the target is expected next: where it was last found
            for idx in seq:
                for j in [j for j in views if j not in (mark_index, key.view.index)]:
                    del views[j]  # only the mark and the key frame are needed from here on
                if idx not in views:
                    got = decode_views([idx])
                    if idx not in got:
                        out[idx] = FrameTrack(idx, via="not decodable")
                        continue
                    views[idx] = got[idx]
                cur = views[idx]
                ft, H = self._attempt(key, mark, p0, cur, "key", centre)
                if H is None and key.view is not mark:  # re-acquisition against the mark itself
                    ft2, H = self._attempt(mark_key(), mark, p0, cur, "reacquired", centre)
                    ft = ft2 if H is not None else ft
                # the key frame's homography held: the target left the view, or is in view but not found (covered,
                # washed out); stones would give the same view of it (see the module docstring, 4.)
                held = ft.via in ("out of image", "low correlation", "low contrast") and self._pairs is not None
                if H is None and not held:
                    ft, H = self._bridge(decode_views, key, mark, p0, cur, avail, direction, views, ft, centre)
                out[idx] = ft
                if H is None:
                    continue
                centre = np.array(ft.pixel_px)
                if key.first_inliers is None and ft.via == "key":
                    key.first_inliers = ft.inliers
                floor = self.s.keyframe_inlier_fraction * (key.first_inliers or 0)
                weak = key.first_inliers is not None and ft.inliers < floor
                if weak or ft.via in ("reacquired", "bridge"):
                    key = _Key(cur, H, centre_px=centre)
                    ft.keyframe = True
        return TrackResult([out[i] if i in out else FrameTrack(i, via="not tracked") for i in wanted])

    def _bridge(self, decode_views, key: _Key, mark: _View, p0: np.ndarray, cur: _View, avail: list[int],
                direction: int, views: dict[int, _View], failed: FrameTrack, centre_px: np.ndarray | None = None
                ) -> tuple[FrameTrack, np.ndarray | None]:
        """Try intermediate frames between the key frame and `cur` as stepping stones (nearest to the key first,
        at most `neighbours` of them); `decode_views(indices)` -> {index: view}."""
        lo, hi = sorted((key.view.index, cur.index))
        between = avail[bisect.bisect_right(avail, lo):bisect.bisect_left(avail, hi)]  # avail: sorted, unique
        if not between or self.s.neighbours <= 0:
            return failed, None
        between.sort(key=lambda i: abs(i - key.view.index))
        step = max(1, len(between) // (self.s.neighbours + 1))
        stones = between[step - 1::step][: self.s.neighbours] or between[:1]
        images = decode_views([i for i in stones if i not in views])
        k = key
        for i in stones:
            if i not in views:
                if i not in images:
                    continue
                views[i] = images[i]
            ft, H = self._attempt(k, mark, p0, views[i], "bridge", centre_px)
            if H is not None:
                k = _Key(views[i], H, centre_px=np.array(ft.pixel_px))
        if k is key:
            return failed, None
        ft, H = self._attempt(k, mark, p0, cur, "bridge", centre_px)
        return (ft, H) if H is not None else (failed, None)

    # ---- marking by a template image ---------------------------------------------------------------------

    def acquire(self, template: np.ndarray, template_px: Sequence[float] | None,
                decode: Callable[[Sequence[int]], dict[int, np.ndarray]], candidates: Sequence[int]
                ) -> tuple[int, tuple[float, float]]:
        """Find a template image (a view of the target area; the target at `template_px`, default its centre)
        in the first of `candidates` frames where it matches: returns (frame index, image pixel) to use as the
        mark. Raises InputError when no candidate frame matches."""
        cv2.setRNGSeed(0x5EED)
        tview = self.view(-1, template)
        hgt, wid = tview.image.shape[:2]
        tp = np.asarray(template_px if template_px is not None else ((wid - 1) / 2, (hgt - 1) / 2), dtype=np.float64)
        for start in range(0, len(candidates), 8):
            chunk = [int(i) for i in candidates[start:start + 8]]
            images = decode(chunk)
            for idx in chunk:
                if idx not in images:
                    continue
                cur = self.view(idx, images[idx])
                ft, _ = self._attempt(_Key(tview, np.eye(3)), tview, tp, cur, "template")
                if not ft.lost:
                    return idx, ft.pixel_px
        raise InputError("the target template matches none of the observation frames")
