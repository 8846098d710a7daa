"""The Brighton pose-chain check (docs/ingest.md, "Brighton check"): marks points seen in three consecutive
photos of ../shared/photos/brighton and triangulates each from the first pair and from the second pair.

Marking: SIFT (OpenCV) on the photos at half size, matches kept where the best match is < 0.6 x the second best
in both consecutive pairs, chained over three photos; per triple the two chains with the most distinctive
matches (smallest worse ratio) are kept: a rule that does not look at the triangulation. Pixels are printed in the
files' frame (full size) for tests/test_photo_brighton.py.

    python scripts/photo_brighton_check.py [--folder ../shared/photos/brighton]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def triangulate(views, idx, px_file) -> np.ndarray:
    from pipeline.solve import solve
    from pipeline.solve.observations import Observations

    obs = Observations(P=views.P[idx], pixel=views.pinhole_pixels(px_file, idx), platform_m=views.camera_m[idx],
                       range_m=np.full(len(idx), np.nan))
    return solve("dlt", obs).position_m


def main() -> int:
    import cv2

    from pipeline.ingest.photo import read_photos
    from pipeline.ingest.photo_views import photo_views

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--folder", default="../shared/photos/brighton")
    args = ap.parse_args()
    photos, bad = read_photos([args.folder])
    if bad or len(photos) != 6:
        print(f"expected six readable photos, got {len(photos)}; bad: {bad}", file=sys.stderr)
        return 1
    views = photo_views(photos, rotation_deg=180)
    scale = 0.5
    imgs = [cv2.resize(cv2.imread(p.path, cv2.IMREAD_GRAYSCALE), None, fx=scale, fy=scale) for p in photos]
    sift = cv2.SIFT_create(4000)
    feats = [sift.detectAndCompute(im, None) for im in imgs]
    matcher = cv2.BFMatcher()

    def matches(a, b):
        out = {}
        for m in matcher.knnMatch(feats[a][1], feats[b][1], k=2):
            if len(m) == 2 and m[0].distance < 0.6 * m[1].distance:
                out[m[0].queryIdx] = (m[0].trainIdx, m[0].distance / m[1].distance)
        return out

    print("photos  pixel_a  pixel_b  pixel_c  |A-B| m  |A-C| m  depth_A m")
    for i in range(len(photos) - 2):
        m01, m12 = matches(i, i + 1), matches(i + 1, i + 2)
        chains = sorted(((max(r1, m12[b][1]), a, b, m12[b][0]) for a, (b, r1) in m01.items() if b in m12))
        for _, a, b, c in chains[:2]:
            px = np.array([feats[i][0][a].pt, feats[i + 1][0][b].pt, feats[i + 2][0][c].pt]) / scale
            A = triangulate(views, [i, i + 1], px[:2])
            B = triangulate(views, [i + 1, i + 2], px[1:])
            C = triangulate(views, [i, i + 2], px[[0, 2]])
            print(f"{i},{i + 1},{i + 2}  " + "  ".join(f"({u:.1f}, {v:.1f})" for u, v in px)
                  + f"  {np.linalg.norm(A - B):.2f}  {np.linalg.norm(A - C):.2f}  {A[2] - views.camera_m[i, 2]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
