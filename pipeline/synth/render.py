"""Rendering video frames from the TRUE camera: a procedural ground texture and the target, seen through the
ground-to-image homography, the lens distortion, haze and sensor noise.

The ground is the z = 0 plane of the target's ENU frame. For every output pixel (supersampled), the lens model
gives its ideal pinhole pixel (cv2.undistortPoints), the inverse ground-to-image homography H^-1 = (K [r1 r2 t])^-1
gives the ground point it sees, and cv2.remap samples the texture there; the supersampled frame is reduced with
INTER_AREA (anti-aliasing). The target (a bright square with a dark cross, the paper's Fig. 6) is a separate
high-resolution pattern composited the same way, so it stays sharp however coarse the ground texture is.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import cv2
import numpy as np

TARGET_PATTERN_PX = 64  # target pattern resolution (pixels across the square), pre-filtered
TEXTURE_VERSION = 1  # bump when make_ground_texture changes, so cached textures are not reused


def _cache_dir() -> Path | None:
    d = os.environ.get("RIDGELOC_CACHE_DIR")
    if d == "":
        return None  # caching disabled
    return Path(d) if d else Path.home() / ".cache" / "ridgeloc"


@functools.lru_cache(maxsize=2)
def ground_texture(seed: int, size_px: int, res_m: float) -> np.ndarray:
    """(size_px, size_px, 3) uint8 BGR texture of res_m metres per pixel (see make_ground_texture), kept in
    memory and in a lossless PNG under ~/.cache/ridgeloc (or $RIDGELOC_CACHE_DIR; empty disables) because it
    takes seconds to make and every flight of a scene shares it. The cache holds exactly what
    make_ground_texture returns, so it never changes a result."""
    cache = _cache_dir()
    path = None if cache is None else cache / f"ground_texture_v{TEXTURE_VERSION}_{seed}_{size_px}_{res_m:g}.png"
    if path is not None and path.is_file():
        img = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if img is not None and img.shape == (size_px, size_px, 3):
            return img
    img = make_ground_texture(seed, size_px, res_m)
    if path is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f".tmp-{os.getpid()}-{path.name}")
            if cv2.imwrite(str(tmp), img):
                os.replace(tmp, path)
        except OSError:
            pass  # a read-only home is fine: the texture is just made again next time
    return img


def make_ground_texture(seed: int, size_px: int, res_m: float) -> np.ndarray:
    """(size_px, size_px, 3) uint8 BGR texture of res_m metres per pixel, centred on the target, row 0 north.

    Farmland parcels (crop rows, mottled soil) in blocks of different orientation, hedges along parcel edges,
    roads, villages of buildings with shadows, tree clumps, and value noise at several scales; deterministic in
    `seed`."""
    rng = np.random.default_rng([seed, 1001])
    n = size_px

    def value_noise(cells: int) -> np.ndarray:
        g = rng.random((cells + 1, cells + 1), dtype=np.float32)
        return cv2.resize(g, (n, n), interpolation=cv2.INTER_CUBIC)

    # blocks of parcels: the Voronoi cells of a few seeds (labels of the nearest seed pixel, OpenCV)
    n_blocks = max(8, int((n * res_m / 900.0) ** 2))
    seeds = np.minimum((rng.random((n_blocks, 2)) * n).astype(np.int64), n - 1)
    mask = np.ones((n, n), np.uint8)
    mask[seeds[:, 1], seeds[:, 0]] = 0
    _, labels = cv2.distanceTransformWithLabels(mask, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    lut = np.zeros(labels.max() + 1, np.uint8)
    lut[labels[seeds[:, 1], seeds[:, 0]]] = np.arange(n_blocks) % 256
    block = lut[labels]
    del labels, mask
    theta = rng.uniform(0, np.pi, n_blocks).astype(np.float32)
    width_u = (rng.uniform(60, 220, n_blocks) / res_m).astype(np.float32)
    width_v = (rng.uniform(120, 400, n_blocks) / res_m).astype(np.float32)

    xx = np.arange(n, dtype=np.float32)[None, :]
    yy = np.arange(n, dtype=np.float32)[:, None]
    c, s = np.cos(theta)[block], np.sin(theta)[block]
    u = xx * c + yy * s
    v = -xx * s + yy * c
    del c, s
    fu = u / width_u[block]
    fv = v / width_v[block]
    iu, iv = np.floor(fu).astype(np.int64), np.floor(fv).astype(np.int64)
    parcel = (iu * 73856093 ^ iv * 19349663 ^ block.astype(np.int64) * 83492791) % 4093
    edge = np.minimum(np.minimum(fu - iu, 1 - (fu - iu)) * width_u[block],
                      np.minimum(fv - iv, 1 - (fv - iv)) * width_v[block])  # distance to parcel edge, px
    del fu, fv, iu, iv

    palette = np.array([[70, 125, 80], [55, 140, 95], [90, 160, 150], [80, 170, 195], [75, 115, 140],
                        [100, 135, 160], [60, 105, 70], [120, 150, 170], [50, 95, 60]], dtype=np.float32)
    n_parcels = 4093
    colour = (palette[rng.integers(0, len(palette), n_parcels)]
              * rng.uniform(0.8, 1.2, (n_parcels, 1))).astype(np.float32)
    period = (rng.uniform(4.0, 12.0, n_parcels) / res_m).astype(np.float32)
    row_amp = np.where(rng.random(n_parcels) < 0.55, rng.uniform(0.08, 0.22, n_parcels), 0.0).astype(np.float32)
    along_u = rng.random(n_parcels) < 0.5
    coord = np.where(along_u[parcel], u, v)
    shade = 1.0 + row_amp[parcel] * np.sin(2 * np.pi * coord / period[parcel])
    del coord, u, v
    img = colour[parcel] * shade[..., None]
    del shade
    # hedges (dark) or field tracks (light) along parcel edges
    line = np.clip(1.6 - edge, 0, 1)[..., None]
    kind = (parcel % 4 == 0)[..., None]
    line_colour = np.where(kind, np.float32([35, 60, 40]), np.float32([150, 170, 180]))
    img = img * (1 - 0.7 * line) + 0.7 * line * line_colour
    del line, kind, line_colour
    del edge, parcel, block

    lum = (0.45 * value_noise(6) + 0.25 * value_noise(24) + 0.15 * value_noise(96) + 0.1 * value_noise(384)
           + 0.05 * value_noise(n // 3))
    img *= (0.7 + 0.6 * lum)[..., None]
    del lum

    # tree clumps
    for _ in range(int(60 * (n / 4096) ** 2)):
        cxy = rng.random(2) * n
        for p in cxy + rng.normal(0, 25 / res_m, (40, 2)):
            r = int(max(1, rng.uniform(2.0, 5.0) / res_m))
            cv2.circle(img, (int(p[0]), int(p[1])), r, (35, 60, 40), -1, cv2.LINE_AA)
    # roads: long gently curving polylines
    for _ in range(int(14 * n / 4096)):
        a = rng.uniform(0, 2 * np.pi)
        p0 = rng.random(2) * n
        pts = [p0]
        for _ in range(30):
            a += rng.normal(0, 0.08)
            pts.append(pts[-1] + (n / 25) * np.array([np.cos(a), np.sin(a)]))
        pts = np.round(np.array(pts)).astype(np.int32)
        w = int(max(2, rng.uniform(5, 9) / res_m))
        cv2.polylines(img, [pts], False, (150, 150, 145), w + 2, cv2.LINE_AA)
        cv2.polylines(img, [pts], False, (95, 95, 98), w, cv2.LINE_AA)
    # villages: buildings with shadows (sun from the south-east: shadows fall north-west)
    shadow = np.array([-6.0, -5.0]) / res_m
    roofs = np.array([[70, 80, 170], [150, 150, 150], [200, 200, 205], [140, 110, 90], [90, 100, 120]], np.float32)
    for _ in range(int(40 * (n / 4096) ** 2)):
        centre = rng.random(2) * n
        ang = rng.uniform(0, np.pi)
        for _ in range(rng.integers(15, 80)):
            c0 = centre + rng.normal(0, 70 / res_m, 2)
            wl = rng.uniform(8, 30, 2) / res_m
            ca, sa = np.cos(ang), np.sin(ang)
            corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * wl / 2
            corners = corners @ np.array([[ca, sa], [-sa, ca]]) + c0
            cv2.fillPoly(img, [np.round((corners + shadow) * 16).astype(np.int32)], (35, 40, 45), cv2.LINE_AA, 4)
            roof = roofs[rng.integers(0, len(roofs))].tolist()
            cv2.fillPoly(img, [np.round(corners * 16).astype(np.int32)], roof, cv2.LINE_AA, 4)
    img += rng.normal(0, 4.0, img.shape[:2]).astype(np.float32)[..., None]
    img = cv2.GaussianBlur(img, (0, 0), 0.6)
    return np.clip(img, 0, 255).astype(np.uint8)


@functools.lru_cache(maxsize=2)
def target_pattern(px: int = TARGET_PATTERN_PX) -> np.ndarray:
    """(px + 2m, px + 2m, 4) float32 BGRA: a white square with a black cross (arms 1/5 of the side, as a
    surveyor's panel), with an m-pixel transparent margin so edges blend; alpha 1 on the square."""
    hi = 16 * px
    pat = np.full((hi, hi), 235.0, np.float32)
    arm = hi // 5
    lo, up = (hi - arm) // 2, (hi + arm) // 2
    pat[lo:up, :] = 25.0
    pat[:, lo:up] = 25.0
    small = cv2.resize(pat, (px, px), interpolation=cv2.INTER_AREA)
    m = 2
    out = np.zeros((px + 2 * m, px + 2 * m, 4), np.float32)
    out[m:-m, m:-m, :3] = small[..., None]
    out[m:-m, m:-m, 3] = 1.0
    return out


class Renderer:
    """Renders frames of one camera over one ground texture. K (3, 3), dist (5,), size (w, h) px."""

    def __init__(self, K: np.ndarray, dist, size_px: tuple[int, int], texture: np.ndarray, texture_res_m: float,
                 target_size_m: float, supersample: int = 2, haze_km: float = 16.0, extra_targets=()):
        """extra_targets: (east_m, north_m, size_m, contrast) of further panels on the ground."""
        self.K = K
        self.extra_targets = tuple(extra_targets)
        self.w, self.h = size_px
        self.tex = texture
        self.res = texture_res_m
        self.target_size_m = target_size_m
        self.ss = supersample
        self.haze_m = haze_km * 1000.0
        ws, hs = self.w * supersample, self.h * supersample
        us = (np.arange(ws, dtype=np.float64) + 0.5) / supersample - 0.5
        vs = (np.arange(hs, dtype=np.float64) + 0.5) / supersample - 0.5
        grid = np.stack(np.meshgrid(us, vs), axis=-1).reshape(-1, 1, 2)
        d = np.asarray(dist, dtype=np.float64)
        if d.any():
            norm = cv2.undistortPoints(grid, K, d, None, None, None,
                                       (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-9))
        else:
            norm = cv2.undistortPoints(grid, K, d)
        # ideal normalised rays (x, y, 1) of every supersampled output pixel
        self.ray_x = norm[:, 0, 0].reshape(vs.size, us.size).astype(np.float32)
        self.ray_y = norm[:, 0, 1].reshape(vs.size, us.size).astype(np.float32)
        uo, vo = np.meshgrid(np.arange(self.w) - K[0, 2], np.arange(self.h) - K[1, 2])
        r = np.hypot(uo / self.w, vo / self.h)
        self.vignette = (1.0 - 0.35 * r ** 2).astype(np.float32)[..., None]
        self.shape_ss = (hs, ws)

    def ground_points(self, R_cam_from_enu: np.ndarray, centre_enu: np.ndarray, zoom: float = 1.0
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Ground E, N metres seen by every supersampled pixel (rows, cols) via H^-1 (NaN where the ray misses
        the ground), and the distance to that point (m)."""
        x, y = self.ray_x, self.ray_y
        if zoom != 1.0:  # focal lengths times zoom about the same principal point: rays shrink by 1 / zoom
            x, y = x / np.float32(zoom), y / np.float32(zoom)
        centre_enu = np.asarray(centre_enu, dtype=np.float64)
        t = -R_cam_from_enu @ centre_enu
        H = np.column_stack([R_cam_from_enu[:, 0], R_cam_from_enu[:, 1], t])  # normalised image <- ground (E, N, 1)
        Hi = np.linalg.inv(H)
        g = [np.float32(Hi[i, 0]) * x + np.float32(Hi[i, 1]) * y + np.float32(Hi[i, 2]) for i in range(3)]
        R = R_cam_from_enu
        up = np.float32(R[0, 2]) * x + np.float32(R[1, 2]) * y + np.float32(R[2, 2])  # world z of each ray (R^T ray)
        hits = up * centre_enu[2] < 0  # the ray descends towards the ground
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.where(hits, g[0] / g[2], np.nan)
            n = np.where(hits, g[1] / g[2], np.nan)
        dist_m = np.sqrt((e - centre_enu[0]) ** 2 + (n - centre_enu[1]) ** 2 + centre_enu[2] ** 2)
        return e, n, np.where(hits, dist_m, np.inf)

    def render(self, R_cam_from_enu: np.ndarray, centre_enu: np.ndarray, rng: np.random.Generator,
               pixel_noise_dn: float = 1.5, cloud_at_px: tuple[float, float] | None = None,
               zoom: float = 1.0, more_clouds_px=()) -> np.ndarray:
        """(h, w, 3) uint8 BGR frame of a camera at centre_enu (3,) with rotation R_cam_from_enu (3, 3); `zoom`
        multiplies the focal lengths (a distortion-free camera only)."""
        e, n, dist_m = self.ground_points(R_cam_from_enu, centre_enu, zoom)
        n_tex = self.tex.shape[0]
        mx = np.nan_to_num(e / self.res + (n_tex / 2 - 0.5), nan=-1e6).astype(np.float32)
        my = np.nan_to_num(-n / self.res + (n_tex / 2 - 0.5), nan=-1e6).astype(np.float32)
        img = cv2.remap(self.tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)
        self._composite_target(img, e, n)
        for east_m, north_m, size_m, contrast in self.extra_targets:
            self._composite_target(img, e - east_m, n - north_m, size_m, contrast)
        out = cv2.resize(img, (self.w, self.h), interpolation=cv2.INTER_AREA).astype(np.float32)
        # smooth effects at output resolution: haze with distance, vignetting, cloud, sensor noise
        d = cv2.resize(np.minimum(dist_m, 1e7).astype(np.float32), (self.w, self.h), interpolation=cv2.INTER_AREA)
        haze = (1.0 - np.exp(-d / self.haze_m))[..., None]
        out = out * (1 - haze) + haze * np.array([205, 195, 185], np.float32)
        out *= self.vignette
        if cloud_at_px is not None:
            out = _cloud(out, cloud_at_px, rng)
        for at in more_clouds_px:  # clouds over other targets
            out = _cloud(out, at, rng)
        if pixel_noise_dn > 0:
            out += rng.normal(0, pixel_noise_dn, out.shape).astype(np.float32)
        return np.clip(np.rint(out), 0, 255).astype(np.uint8)

    def _composite_target(self, img: np.ndarray, e: np.ndarray, n: np.ndarray, size_m: float | None = None,
                          contrast: float = 1.0) -> None:
        """Blend the target pattern (centred at e = n = 0, `size_m` across, default the main target's; its grey
        levels scaled towards mid-grey by `contrast`) into the supersampled frame `img` (in place)."""
        size_m = self.target_size_m if size_m is None else size_m
        half = size_m / 2 + 2 * self.res
        near = (np.abs(e) < half) & (np.abs(n) < half)
        if not near.any():
            return
        rows, cols = np.flatnonzero(near.any(axis=1)), np.flatnonzero(near.any(axis=0))
        r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
        pat = target_pattern()
        if contrast != 1.0:
            pat = pat.copy()
            pat[..., :3] = 130.0 + contrast * (pat[..., :3] - 130.0)
        scale = TARGET_PATTERN_PX / size_m
        tx = (e[r0:r1, c0:c1] * scale + (pat.shape[1] / 2 - 0.5)).astype(np.float32)
        ty = (-n[r0:r1, c0:c1] * scale + (pat.shape[0] / 2 - 0.5)).astype(np.float32)
        tgt = cv2.remap(pat, tx, ty, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0, 0))
        a = tgt[..., 3:4]
        roi = img[r0:r1, c0:c1].astype(np.float32)
        img[r0:r1, c0:c1] = np.clip(np.rint(roi * (1 - a) + tgt[..., :3] * a), 0, 255).astype(np.uint8)


def _cloud(img: np.ndarray, at_px: tuple[float, float], rng: np.random.Generator) -> np.ndarray:
    """A ragged cloud patch (~90 px across) centred near `at_px`, hiding the target."""
    h, w = img.shape[:2]
    noise = sum(a * cv2.resize(rng.random((c, int(c * w / h))).astype(np.float32), (w, h),
                               interpolation=cv2.INTER_CUBIC) for c, a in ((6, 0.6), (20, 0.3), (60, 0.1)))
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    r = np.hypot(xx - at_px[0], yy - at_px[1]) / 90.0
    alpha = np.clip(2.2 * (1.0 - r) + 1.5 * (noise - 0.5), 0, 0.96)[..., None]
    alpha = cv2.GaussianBlur(alpha, (0, 0), 2.0)[..., None]
    shade = (215 + 30 * noise)[..., None]
    return img * (1 - alpha) + alpha * shade * np.array([1.0, 0.99, 0.97], np.float32)
