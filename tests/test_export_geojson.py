"""targets.geojson (the answers) and estimates.geojson (every method) against the rules of RFC 7946, and their
positions against closed-form geodesy."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from pipeline.answer import Answer, Verdict
from pipeline.report.exports import estimates_geojson, targets_geojson, write_estimates_geojson
from pipeline.results import GroupResult
from pipeline.solve.estimate import Estimate, Status
from support.synthetic import synthetic_observations

GEOMETRY_TYPES = {"Point", "MultiPoint", "LineString", "MultiLineString", "Polygon", "MultiPolygon",
                  "GeometryCollection"}

# ---- an RFC 7946 checker, written from the RFC's text --------------------------------------------------------


def _position_problems(p, where: str) -> list[str]:
    # 3.1.1: a position is an array of two or more numbers: longitude, latitude[, altitude] (WGS84, 4.)
    if not isinstance(p, list) or not 2 <= len(p) <= 3:
        return [f"{where}: a position must be [lon, lat] or [lon, lat, alt], got {p!r}"]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in p):
        return [f"{where}: position members must be finite numbers, got {p!r}"]
    out = []
    if not -180.0 <= p[0] <= 180.0:
        out.append(f"{where}: longitude {p[0]} out of [-180, 180]")
    if not -90.0 <= p[1] <= 90.0:
        out.append(f"{where}: latitude {p[1]} out of [-90, 90]")
    return out


def _signed_area(ring: list) -> float:
    x = np.array([p[0] for p in ring])
    y = np.array([p[1] for p in ring])
    return 0.5 * float(np.sum(x[:-1] * y[1:] - x[1:] * y[:-1]))


def _geometry_problems(g, where: str) -> list[str]:
    if g is None:
        return []  # 3.2: a Feature's geometry may be null
    if not isinstance(g, dict) or g.get("type") not in GEOMETRY_TYPES:
        return [f"{where}: not a GeoJSON geometry: {str(g)[:80]}"]
    if "crs" in g:
        return [f"{where}: 'crs' is not allowed (RFC 7946 4.)"]
    t = g["type"]
    if t == "GeometryCollection":
        return [p for i, sub in enumerate(g.get("geometries", [])) for p in _geometry_problems(sub, f"{where}[{i}]")]
    c = g.get("coordinates")
    if c is None:
        return [f"{where}: {t} without coordinates"]
    out = []
    if t == "Point":
        return _position_problems(c, where)
    lines = [c] if t in ("LineString", "MultiPoint") else c if t in ("MultiLineString", "Polygon") else [
        ring for poly in c for ring in poly]
    for k, line in enumerate(lines):
        if not isinstance(line, list):
            out.append(f"{where}: {t} part {k} is not an array")
            continue
        for j, p in enumerate(line):
            out += _position_problems(p, f"{where} part {k} position {j}")
        if t in ("LineString", "MultiLineString") and len(line) < 2:
            out.append(f"{where}: a LineString needs >= 2 positions (3.1.4)")
    if t in ("Polygon", "MultiPolygon"):
        polys = [c] if t == "Polygon" else c
        for poly in polys:
            for k, ring in enumerate(poly):
                if len(ring) < 4:
                    out.append(f"{where}: a linear ring needs >= 4 positions (3.1.6)")
                    continue
                if ring[0] != ring[-1]:
                    out.append(f"{where}: linear ring {k} is not closed (3.1.6)")
                area = _signed_area(ring)
                if k == 0 and area <= 0:
                    out.append(f"{where}: exterior ring is not counter-clockwise (3.1.6 right-hand rule)")
                if k > 0 and area >= 0:
                    out.append(f"{where}: hole {k} is not clockwise (3.1.6 right-hand rule)")
    return out


def rfc7946_problems(doc) -> list[str]:
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection":
        return ["top level must be a FeatureCollection"]
    if "crs" in doc:
        return ["'crs' is not allowed (RFC 7946 4.)"]
    feats = doc.get("features")
    if not isinstance(feats, list):
        return ["'features' must be an array (3.3)"]
    out = []
    for i, f in enumerate(feats):
        where = f"features[{i}]"
        if not isinstance(f, dict) or f.get("type") != "Feature":
            out.append(f"{where}: not a Feature")
            continue
        if "geometry" not in f or "properties" not in f:
            out.append(f"{where}: a Feature must have 'geometry' and 'properties' members (3.2)")
        if f.get("properties") is not None and not isinstance(f["properties"], dict):
            out.append(f"{where}: properties must be an object or null")
        if "crs" in f:
            out.append(f"{where}: 'crs' is not allowed")
        out += _geometry_problems(f.get("geometry"), where)
    return out


def strict_json(text: str):
    def bad(name):
        raise ValueError(f"non-standard JSON constant {name}")
    return json.loads(text, parse_constant=bad)


# ---- groups built by hand (no solver needed) ----------------------------------------------------------------

ORIGIN = (47.3977, 8.5456, 488.0)


def rotated_cov(a_m: float, b_m: float, azimuth_deg: float, up_m: float = 3.0) -> np.ndarray:
    """3x3 covariance whose horizontal 1-sigma ellipse has semi-axes a >= b, major axis at azimuth (cw from N)."""
    az = math.radians(azimuth_deg)
    major = np.array([math.sin(az), math.cos(az)])
    minor = np.array([math.cos(az), -math.sin(az)])
    cov = np.zeros((3, 3))
    cov[:2, :2] = a_m ** 2 * np.outer(major, major) + b_m ** 2 * np.outer(minor, minor)
    cov[2, 2] = up_m ** 2
    return cov


def hand_group(name="g1", truth=True, seed=3) -> GroupResult:
    obs, target = synthetic_observations(seed=seed, n_frames=12)
    est = {
        "vision": Estimate("vision", target + np.array([4.0, -3.0, 1.0]), 5, Status.CONVERGED),
        "ridge": Estimate("ridge", target + np.array([1.0, 2.0, -0.5]), 4, Status.CONVERGED),
        "mle": Estimate("mle", target + np.array([0.5, -1.0, 0.2]), 6, Status.CONVERGED,
                        covariance_m2=rotated_cov(4.0, 2.0, 30.0)),
        "range": Estimate("range", np.full(3, np.nan), 50, Status.DIVERGED),
    }
    return GroupResult(name=name, origin_lla=ORIGIN, observations=obs, estimates=est,
                       truth_m=target if truth else None, intersection_angle_deg=40.0)


@pytest.fixture(scope="module")
def doc(tmp_path_factory):
    path = tmp_path_factory.mktemp("geojson") / "estimates.geojson"
    write_estimates_geojson(path, [hand_group("g1"), hand_group("g2", truth=False, seed=4)])
    return strict_json(path.read_text())


def test_export_is_valid_rfc7946(doc):
    assert rfc7946_problems(doc) == []
    kinds = [f["properties"]["kind"] for f in doc["features"]]
    # per group: 3 finite estimates (range diverged: no feature), each with its ellipse (mle's own covariance, the
    # others' propagated through the method), a flight path, one line of sight per frame (12); the truth where known
    for g, truth in (("g1", 1), ("g2", 0)):
        k = [f["properties"]["kind"] for f in doc["features"] if f["properties"]["group"] == g]
        assert k.count("estimate") == 3
        assert k.count("error_ellipse") == 3
        assert k.count("flight_path") == 1
        assert k.count("line_of_sight") == 12
        assert k.count("truth") == truth
    assert set(kinds) == {"estimate", "error_ellipse", "flight_path", "line_of_sight", "truth"}


def test_checker_catches_violations(doc):
    """The checker is not vacuous: each broken copy is reported."""
    def broken(mutate):
        d = json.loads(json.dumps(doc))
        mutate(d)
        return rfc7946_problems(d)

    def first(d, kind):
        return next(f for f in d["features"] if f["properties"]["kind"] == kind)

    def swap_point(d):
        c = first(d, "estimate")["geometry"]["coordinates"]
        c[0], c[1] = c[1], c[0] + 100  # lat/lon order swapped (and off the globe)
    assert any("latitude" in p or "longitude" in p for p in broken(swap_point))

    def clockwise(d):
        first(d, "error_ellipse")["geometry"]["coordinates"][0].reverse()
    assert any("counter-clockwise" in p for p in broken(clockwise))

    def unclosed(d):
        first(d, "error_ellipse")["geometry"]["coordinates"][0].pop()
    assert any("not closed" in p for p in broken(unclosed))

    assert any("crs" in p for p in broken(lambda d: d.update(crs={"type": "name"})))

    def short_line(d):
        g = first(d, "flight_path")["geometry"]
        g["coordinates"] = g["coordinates"][:1]
    assert any(">= 2 positions" in p for p in broken(short_line))


def test_positions_match_closed_form_geodesy():
    """An estimate 1000 m East and one 1000 m North of the origin land where the WGS84 radii of curvature say."""
    obs, _ = synthetic_observations(seed=1, n_frames=4)
    east = Estimate("vision", np.array([1000.0, 0.0, 0.0]), 1, Status.CONVERGED)
    north = Estimate("mle", np.array([0.0, 1000.0, 0.0]), 1, Status.CONVERGED)
    # both taken as determined by the flight (the answer rule's verdicts), so both are exported as points
    verdicts = {m: Verdict(m, True) for m in ("vision", "mle")}
    r = GroupResult("geo", ORIGIN, obs, {"vision": east, "mle": north},
                    answer=Answer(True, "mle", north.position_m, None, "", 4, verdicts))
    doc = estimates_geojson([r])
    pts = {f["properties"]["method"]: f["geometry"]["coordinates"] for f in doc["features"]
           if f["properties"]["kind"] == "estimate"}
    a, f = 6378137.0, 1 / 298.257223563
    e2 = f * (2 - f)
    phi = math.radians(ORIGIN[0])
    N = a / math.sqrt(1 - e2 * math.sin(phi) ** 2)  # prime vertical radius
    M = a * (1 - e2) / (1 - e2 * math.sin(phi) ** 2) ** 1.5  # meridian radius
    lon_e, lat_e, alt_e = pts["vision"]
    # the origin is 488 m above the ellipsoid: the radii there are N + h0 and M + h0; positions are rounded to
    # 7 decimals (+-5e-8 deg)
    h0 = ORIGIN[2]
    assert lon_e == pytest.approx(ORIGIN[1] + math.degrees(1000.0 / ((N + h0) * math.cos(phi))), abs=6e-8)
    assert lat_e == pytest.approx(ORIGIN[0], abs=2e-6)
    # a point on the tangent plane 1 km away is d^2 / (2 R) above the ellipsoid
    assert alt_e == pytest.approx(ORIGIN[2] + 1000.0 ** 2 / (2 * N), abs=0.02)
    lon_n, lat_n, _ = pts["mle"]
    assert lat_n == pytest.approx(ORIGIN[0] + math.degrees(1000.0 / (M + h0)), abs=6e-8)
    assert lon_n == pytest.approx(ORIGIN[1], abs=1e-9)


def test_ellipse_polygon_shape_and_orientation(doc):
    """The 95 % ellipse of a covariance with 1-sigma axes 4 m x 2 m at azimuth 30 deg: semi-axes sqrt(5.991) times
    those, the major axis pointing 30 deg east of north."""
    f = next(f for f in doc["features"] if f["properties"]["kind"] == "error_ellipse"
             and f["properties"]["group"] == "g1" and f["properties"]["method"] == "mle")
    p = f["properties"]
    k = math.sqrt(5.991464547107979)
    assert p["confidence"] == 0.95
    assert p["semi_major_m"] == pytest.approx(4.0 * k, abs=1e-3)
    assert p["semi_minor_m"] == pytest.approx(2.0 * k, abs=1e-3)
    assert p["azimuth_deg"] == pytest.approx(30.0, abs=0.01)
    ring = np.array(f["geometry"]["coordinates"][0])
    centre = next(g for g in doc["features"] if g["properties"]["kind"] == "estimate"
                  and g["properties"]["group"] == "g1" and g["properties"]["method"] == "mle")
    lon0, lat0 = centre["geometry"]["coordinates"][:2]
    phi = math.radians(lat0)
    east = (ring[:, 0] - lon0) * math.radians(1) * 6378137.0 * math.cos(phi) / math.sqrt(
        1 - 0.00669438 * math.sin(phi) ** 2)
    north = (ring[:, 1] - lat0) * math.radians(1) * 6378137.0 * (1 - 0.00669438) / (
        1 - 0.00669438 * math.sin(phi) ** 2) ** 1.5
    dist = np.hypot(east, north)
    assert dist.max() == pytest.approx(4.0 * k, rel=0.01)
    assert dist.min() == pytest.approx(2.0 * k, rel=0.01)
    far = np.argmax(dist)
    az = math.degrees(math.atan2(east[far], north[far])) % 180.0
    assert az == pytest.approx(30.0, abs=3.0)


def test_lines_of_sight_pass_through_target_without_noise():
    """Noise-free observations: every line of sight's ray passes through the true target."""
    from pipeline.solve.observations import Sigma

    obs, target = synthetic_observations(seed=5, n_frames=8, sigma=Sigma(pixel_px=0.0, range_m=0.0,
                                                                         position_m=0.0, attitude_deg=0.0))
    from pipeline.report.geometry import lines_of_sight_m

    seg, idx = lines_of_sight_m(obs, None)
    assert list(idx) == list(range(8))
    for s in seg:
        d = (s[1] - s[0]) / np.linalg.norm(s[1] - s[0])
        off = (target - s[0]) - np.dot(target - s[0], d) * d
        assert np.linalg.norm(off) < 1e-6
        # as long as the (noise-free) range: it ends on the target
        assert np.linalg.norm(s[1] - target) < 1e-6


def test_the_answers_are_valid_rfc7946_one_point_per_located_target():
    """targets.geojson: a Point and its 95 % ellipse per located target, a null geometry (RFC 7946 3.2) with the
    reason for a target without an answer."""
    located = hand_group("g1")
    lost = hand_group("g2", seed=4)
    lost.estimates = {"range": lost.estimates["range"]}
    doc = strict_json(json.dumps(targets_geojson([located, lost])))
    assert rfc7946_problems(doc) == []
    kinds = [(f["properties"]["kind"], f["properties"]["name"], f["geometry"] and f["geometry"]["type"])
             for f in doc["features"]]
    assert kinds == [("target", "g1", "Point"), ("error_ellipse", "g1", "Polygon"), ("target", "g2", None)]
    assert doc["features"][0]["properties"]["method"] == "mle"
    assert doc["features"][2]["properties"]["status"] == "not_located"
