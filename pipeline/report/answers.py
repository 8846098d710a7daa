"""Each target's one answer as the outputs write it: WGS84 position, MSL height, MGRS, CE90/LE90, the 95 % ellipse and
the target location error category (docs/outputs.md, "targets.csv").

- Heights: `alt_m` above the WGS84 ellipsoid, `alt_msl_m` above the EGM2008 geoid (pipeline.geometry.geoid).
- MGRS at 1 m precision from the `mgrs` package (GeoTrans, NGA's converter, wrapped by H. Butler; checked against
  GeographicLib's published values and pyproj's UTM in tests/test_answers.py).
- CE90: radius of the circle around the answer holding 90 % of the horizontal error (exact for the correlated 2-D
  Gaussian of the covariance), LE90: 1.6449 sigma of the height, CEP50 the 50 % circle.
- `tle_category`: the target location error category of JP 3-09.3 (Close Air Support) from CE90: CAT I up to 20 ft
  (6.1 m), II up to 50 ft (15.2 m), III up to 100 ft (30.5 m), IV up to 300 ft (91.4 m), V up to 1000 ft (304.8 m),
  VI beyond.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from pipeline.answer import Z90, Answer, choose_answer, unsolved_reasons
from pipeline.geometry.geoid import GEOID_MODEL_LONG, geoid_undulation_m
from pipeline.report.geometry import ALT_DATUM, geodetic_from_enu
from pipeline.report.labels import one_decimal
from pipeline.results import FlightResult, GroupFailure, GroupResult
from pipeline.solve.uncertainty import horizontal

ALT_MSL_DATUM = f"height above the {GEOID_MODEL_LONG}"
#: JP 3-09.3 target location error categories: (name, largest CE90 in metres), from the feet the publication gives
TLE_CATEGORIES = (("CAT I", 20 * 0.3048), ("CAT II", 50 * 0.3048), ("CAT III", 100 * 0.3048),
                  ("CAT IV", 300 * 0.3048), ("CAT V", 1000 * 0.3048), ("CAT VI", math.inf))

#: targets.csv's columns, in order: the answer first (docs/outputs.md describes each)
ANSWER_COLUMNS = (
    "name", "group", "target", "status", "lat_deg", "lon_deg", "alt_msl_m", "alt_m", "mgrs",
    "ce90_m", "le90_m", "tle_category", "method", "n_observations", "reason",
    "cep50_m", "ellipse95_semi_major_m", "ellipse95_semi_minor_m", "ellipse95_azimuth_deg", "sigma_up_m",
    "error_m", "error_horizontal_m", "error_up_m",
    "alt_datum", "alt_msl_datum", "geoid_undulation_m", "covariance_source",
)


def tle_category(ce90_m: float | None) -> str | None:
    """The JP 3-09.3 target location error category of a CE90 (m); None when it is not defined."""
    if ce90_m is None or not np.isfinite(ce90_m):
        return None
    return next(name for name, top in TLE_CATEGORIES if ce90_m <= top)


def mgrs_of(lat_deg: float, lon_deg: float) -> str:
    """The MGRS reference of a WGS84 point at 1 m precision, no spaces (e.g. 49SBU9399604341; zones 1-9 without
    the leading zero the package writes, as NGA's standard does), from the `mgrs` package."""
    import mgrs

    ref = mgrs.MGRS().toMGRS(float(lat_deg), float(lon_deg), MGRSPrecision=5)
    return ref[1:] if ref.startswith("0") else ref


def answer_of(r: GroupResult) -> Answer:
    """The result's answer: the one its run chose, or (a result saved before answers existed) chosen now from its
    estimates without the flight's DEM."""
    if r.answer is not None:
        return r.answer
    return choose_answer(r.observations, r.estimates, unsolved_reasons(r.settings.get("solve_failures")),
                         r.origin_lla)


def determined_estimates(r: GroupResult) -> dict:
    """method -> Estimate of the estimates that may be shown as points: finite, and (for the methods the answer
    rule judges) determined by the flight."""
    verdicts = answer_of(r).verdicts
    return {m: e for m, e in r.estimates.items()
            if np.isfinite(e.position_m).all() and (m not in verdicts or verdicts[m].determined)}


def shown_covariance(r: GroupResult, method: str) -> np.ndarray | None:
    """The covariance (3, 3) m^2 the outputs give a method's estimate: the one the answer rule judged it by (its
    own, or propagated through the method), else the estimator's own; None without one."""
    v = answer_of(r).verdicts.get(method)
    if v is not None and v.covariance_m2 is not None:
        return np.asarray(v.covariance_m2)
    e = r.estimates.get(method)
    return None if e is None or e.covariance_m2 is None else np.asarray(e.covariance_m2)


def answers_text(rows: list[dict]) -> str:
    """The answers as a plain-text table for the console: target, latitude, longitude, MSL height, MGRS, CE90,
    category, method; a target without an answer gets its reason on its line."""
    head = ("target", "latitude", "longitude", "MSL m", "MGRS", "CE90 m", "category", "method")
    lines = []
    for row in rows:
        if row["status"] == "located":
            ce90 = "-" if row["ce90_m"] is None else f"{row['ce90_m']:.1f}"
            lines.append((row["name"], f"{row['lat_deg']:.7f}", f"{row['lon_deg']:.7f}", one_decimal(row["alt_msl_m"]),
                          row["mgrs"], ce90, row["tle_category"] or "-", row["method"]))
        else:
            lines.append((row["name"], f"NOT LOCATED: {row['reason']}"))
    widths = [max([len(head[i]), *(len(ln[i]) for ln in lines if len(ln) == len(head))]) for i in range(len(head))]
    out = ["  ".join(h.ljust(w) for h, w in zip(head, widths, strict=True)).rstrip()]
    for ln in lines:
        if len(ln) == len(head):
            out.append("  ".join(v.ljust(w) if i in (0, 4, 6, 7) else v.rjust(w)
                                 for i, (v, w) in enumerate(zip(ln, widths, strict=True))).rstrip())
        else:
            out.append(f"{ln[0].ljust(widths[0])}  {ln[1]}")
    return "\n".join(out)


def _num(x, decimals: int = 3):
    if x is None:
        return None
    x = float(x)
    return round(x, decimals) if np.isfinite(x) else None


def answer_warnings(r: GroupResult) -> list[str]:
    """What a located answer is to be read with: its own warnings (`settings["answer_warnings"]`: accuracies the
    config leaves unstated), then the run's geometry warnings (its checks, about every point of the flight)."""
    return [*(r.settings.get("answer_warnings") or []), *(r.settings.get("geometry_warnings") or [])]


def answer_row(r: GroupResult) -> dict:
    """targets.csv's row of one target (keys ANSWER_COLUMNS; None where undefined)."""
    a = answer_of(r)
    row = dict.fromkeys(ANSWER_COLUMNS)
    row.update(name=r.label, group=r.name, target=r.target, status=a.status, method=a.method,
               n_observations=int(a.n_observations or r.n_observations), reason=a.reason, alt_datum=ALT_DATUM,
               alt_msl_datum=ALT_MSL_DATUM)
    if not a.located:
        return row
    warnings = answer_warnings(r)
    if warnings:
        row["reason"] = "; ".join([a.reason, *(f"warning: {w}" for w in warnings)])
    lat, lon, h = geodetic_from_enu(a.position_m, r.origin_lla)
    n_m = float(geoid_undulation_m(lat, lon))
    row.update(lat_deg=_num(lat, 8), lon_deg=_num(lon, 8), alt_m=_num(h), alt_msl_m=_num(h - n_m),
               geoid_undulation_m=_num(n_m), mgrs=mgrs_of(lat, lon), covariance_source=a.covariance_source or None)
    if a.covariance_m2 is not None and np.isfinite(a.covariance_m2).all():
        u = horizontal(np.asarray(a.covariance_m2))
        row.update(ce90_m=_num(u["cep90_m"]), cep50_m=_num(u["cep50_m"]), sigma_up_m=_num(u["sigma_up_m"]),
                   le90_m=_num(Z90 * u["sigma_up_m"]), tle_category=tle_category(u["cep90_m"]),
                   ellipse95_semi_major_m=_num(u["ellipse95_semi_major_m"]),
                   ellipse95_semi_minor_m=_num(u["ellipse95_semi_minor_m"]),
                   ellipse95_azimuth_deg=_num(u["ellipse95_azimuth_deg"], 2))
    if r.truth_m is not None:
        d = a.position_m - r.truth_m
        row.update(error_m=_num(np.linalg.norm(d)), error_horizontal_m=_num(np.hypot(d[0], d[1])),
                   error_up_m=_num(d[2]))
    return row


def _not_located_row(name: str, group: str, target: str | None, reason: str) -> dict:
    row = dict.fromkeys(ANSWER_COLUMNS)
    row.update(name=name, group=group, target=target, status="not_located", reason=reason, n_observations=0,
               alt_datum=ALT_DATUM, alt_msl_datum=ALT_MSL_DATUM)
    return row


def answer_rows(results, failures: Sequence[GroupFailure] = ()) -> list[dict]:
    """targets.csv's rows: one per target of every flight, in the run's order (a flight's located targets, then
    those it could not locate), then one per flight that failed as a whole (its targets unknown)."""
    rows = []
    for r in results:
        if isinstance(r, FlightResult):
            rows += [answer_row(t) for t in r.targets]
            rows += [_not_located_row(f"{r.name}:{f.target}", r.name, f.target, f.message) for f in r.failed]
        else:
            rows.append(answer_row(r))
    for f in failures:
        rows.append(_not_located_row(f.name, f.name, None, f"the flight failed: {f.message}"))
    return rows
