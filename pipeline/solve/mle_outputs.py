"""The batched `mle` kernel's per-problem results as the JSON-ready extras of one `Estimate`: the fit checks
in words, the boresight bias and the rejected observations (frame, time, which residual, its size)."""

from __future__ import annotations

import numpy as np

from pipeline.solve import fit_checks
from pipeline.solve.estimate import finite_or_none as _f
from pipeline.solve.learned_tau import TAU_GRID_S
from pipeline.solve.observations import REAL_TIMES_NS

_ROWS = ("u", "v", "range")


def rejected_observations(ex: dict, t_ns: np.ndarray) -> list[dict]:
    """[{frame, t_ns, residual ("u" | "v" | "range"), value (px or m), sigmas}] of the rows at zero weight."""
    return [{"frame": int(i), "t_ns": int(t_ns[i]), "residual": _ROWS[k], "value": float(ex["residuals"][i, k]),
             "sigmas": float(ex["residual_sigmas"][i, k])} for i, k in zip(*np.nonzero(ex["rejected"]), strict=True)]


def fit_summary(ex: dict) -> dict:
    """The fit checks (`fit_checks`) as JSON values, with the message when the model does not fit."""
    block = [float(ex[f"batch_means_{g}"]) if ex.get(f"block_drift_{g}", False) else None for g in ("pixel", "range")]
    msg = fit_checks.describe(float(ex["chi2"]), float(ex["chi2_dof"]), float(ex["chi2_p"]),
                              float(ex["autocorrelation_pixel"]), float(ex["autocorrelation_range"]),
                              bool(ex["drift_pixel"]), bool(ex["drift_range"]), float(ex["covariance_inflation"]),
                              float(np.max(ex["robust_spread"])) if "robust_spread" in ex else 1.0, *block)
    return {"consistent": bool(ex["consistent"]), "chi2": _f(ex["chi2"]), "dof": _f(ex["chi2_dof"]),
            "p_value": _f(ex["chi2_p"]), "autocorrelation_pixel": _f(ex["autocorrelation_pixel"]),
            "autocorrelation_range": _f(ex["autocorrelation_range"]),
            **{k: _f(ex[k]) if k in ex else None for k in ("batch_means_pixel", "batch_means_range")},
            "covariance_inflation": _f(ex["covariance_inflation"]),
            "robust_spread": _f(np.max(ex["robust_spread"])) if "robust_spread" in ex else None, "message": msg}


#: a bias angle counts as determined by the flight when its posterior sigma is below this fraction of the
#: prior's (the flight told at least half of what is known about it)
DETERMINED_BELOW = 0.7


def boresight_bias(ex: dict) -> dict | None:
    """The estimated constant boresight bias (deg, about the camera's vertical axis: u, and its
    horizontal axis: v), its posterior and prior sigmas, whether the flight determined it, its correlation with the
    target (2, 3) and, where its size was learned, that size; None without a bias state."""
    if "bias_deg" not in ex or not np.isfinite(ex["bias_deg"]).all():  # no bias state (NaN: refitted without)
        return None
    bias, sd, prior = ex["bias_deg"], ex["bias_sigma_deg"], ex["bias_prior_deg"]
    out = {"u_deg": float(bias[0]), "v_deg": float(bias[1]), "u_sigma_deg": float(sd[0]),
           "v_sigma_deg": float(sd[1]), "u_prior_deg": float(prior[0]), "v_prior_deg": float(prior[1]),
           "u_determined": bool(sd[0] < DETERMINED_BELOW * prior[0]),
           "v_determined": bool(sd[1] < DETERMINED_BELOW * prior[1]),
           "correlation_with_target": [[_f(c) for c in row] for row in ex["bias_target_correlation"]]}
    if "bias_size_deg" in ex:
        out["size_deg"] = float(ex["bias_size_deg"])
    return out


def _bias_words(bias: dict) -> str:
    """The `boresight_bias` dict in words: each angle with its sigma, or that the flight did not determine it."""
    parts = []
    for k, axis in (("u", "about the camera's vertical axis"), ("v", "about its horizontal axis")):
        if bias[f"{k}_determined"]:
            parts.append(f"{bias[f'{k}_deg']:+.3f} +/- {bias[f'{k}_sigma_deg']:.3f} deg {axis} ({k})")
        else:
            parts.append(f"not determined by this flight {axis} ({k}: +/- {bias[f'{k}_sigma_deg']:.3f} deg, "
                         f"the prior's {bias[f'{k}_prior_deg']:.3f})")
    if "size_deg" in bias and (bias["u_determined"] or bias["v_determined"]):
        parts.append(f"the flight puts the constant part of the attitude error at about {bias['size_deg']:.2f} deg")
    return "; ".join(parts)


def _where(r: dict, t_ns: np.ndarray | None, video_frames) -> str:
    """Observation r["frame"] in words: its row, its video frame when known, its time from the first
    observation when the frames carry real timestamps (else the raw t_ns)."""
    i = r["frame"]
    where = [f"video frame {int(video_frames[i])}"] if video_frames is not None else []
    if t_ns is not None and t_ns.size > 1 and int(t_ns.max() - t_ns.min()) >= REAL_TIMES_NS:
        where.append(f"t = {(r['t_ns'] - int(t_ns.min())) / 1e9:.2f} s after the first observation")
    else:
        where.append(f"t_ns {r['t_ns']}")
    return f"observation {i} ({', '.join(where)})"


def notes(extras: dict, t_ns: np.ndarray | None = None, video_frames=None) -> list[str]:
    """The mle's fit message, boresight bias and rejected observations in words from `Estimate.extras`, for the
    console and the report; t_ns (n,) and video_frames (n,) (where known) say when a rejected one was taken."""
    if t_ns is not None:
        t_ns = np.asarray(t_ns, dtype=np.int64)
    out = []
    fit = extras.get("fit") or {}
    if fit.get("message"):
        out.append(f"mle: {fit['message']}")
    model = extras.get("error_model")
    if model:
        a_tau, p_tau = model["attitude_tau_s"], model["position_tau_s"]
        which = ("attitude and position errors" if a_tau is not None and p_tau is not None
                 else "attitude error" if a_tau is not None else "position (GNSS) error")
        out.append(f"mle: the residuals drift; the {which} drifting, correlation time learned from the flight: "
                   f"{a_tau if a_tau is not None else p_tau:g} s (Gauss-Markov, largest likelihood over 5-320 s), "
                   "generalized least squares")
        spread, own = model.get("models_spread_m"), model.get("model_sd_m")
        if spread is not None and own is not None and spread > own:
            out.append(f"mle: the flight does not pin down its error model: the answers of the likely drift models "
                       f"spread {spread:.1f} m (largest standard deviation), more than their own uncertainty "
                       f"({own:.1f} m, weighted average); the answer is their average and its covariance holds that "
                       "spread (laser ranges, or the errors' correlation times where known, would narrow it)")
    slip = extras.get("tracker_slip")
    if slip:
        out.append(f"mle: the pixels of observations {slip['first_observation']}-{slip['last_observation']} fit best "
                   "as a tracker slip (off by one constant offset there: likelier than a drift; any error constant "
                   "over those frames looks alike); fitted with that offset free: check the tracking there")
    bias = extras.get("boresight_bias")
    if bias:
        out.append(f"mle: boresight bias {_bias_words(bias)}")
    rejected = extras.get("rejected", [])
    pixel = {}  # frame -> {"u": entry, "v": entry}: a pixel is rejected whole, said once
    for r in rejected:
        if r["residual"] != "range":
            pixel.setdefault(r["frame"], {})[r["residual"]] = r
    for r in rejected:
        if r["residual"] == "range":
            out.append(f"mle: rejected the laser range of {_where(r, t_ns, video_frames)}: residual "
                       f"{r['value']:+.2f} m ({r['sigmas']:+.1f} sigma), zero weight")
        elif r["frame"] in pixel:
            uv = pixel.pop(r["frame"])
            if len(uv) == 2:
                size = float(np.hypot(uv["u"]["sigmas"], uv["v"]["sigmas"]))
                out.append(f"mle: rejected the pixel of {_where(r, t_ns, video_frames)}: residual "
                           f"({uv['u']['value']:+.2f}, {uv['v']['value']:+.2f}) px (u, v; {size:.1f} sigma), "
                           "zero weight")
            else:
                out.append(f"mle: rejected the pixel {r['residual']} of {_where(r, t_ns, video_frames)}: residual "
                           f"{r['value']:+.2f} px ({r['sigmas']:+.1f} sigma), zero weight")
    return out


def problem_extras(ex: dict, t_ns: np.ndarray) -> dict:
    """The JSON-ready extras of one problem's kernel extras ex: fit, rejected, boresight_bias, error_model (when
    learned) and tracker_slip (when the evidence chose one)."""
    out = {"fit": fit_summary(ex), "rejected": rejected_observations(ex, t_ns)}
    slip = ex.get("tracker_slip")
    if slip is not None and slip.any():  # absent (False) for a problem without one
        frames = np.flatnonzero(slip)
        out["tracker_slip"] = {"first_observation": int(frames[0]), "last_observation": int(frames[-1]),
                               "observations": int(frames.size)}
    bias = boresight_bias(ex)
    if bias is not None:
        out["boresight_bias"] = bias
    if "error_model_tau_s" in ex and np.isfinite(ex["error_model_tau_s"]):  # NaN: a problem without one
        out["error_model"] = {
            "attitude_tau_s": _f(ex["error_model_attitude_tau_s"]),
            "position_tau_s": _f(ex["error_model_position_tau_s"]),
            "attitude_deg": float(ex["error_model_attitude_deg"]), "chosen_by": "likelihood",
            "models_spread_m": _f(ex["error_model_spread_m"]), "model_sd_m": _f(ex["error_model_within_m"]),
            "log_likelihood": {f"{t:g}": _f(v) for t, v in zip(TAU_GRID_S, ex["error_model_log_likelihoods"],
                                                                 strict=True)}}
    return out
