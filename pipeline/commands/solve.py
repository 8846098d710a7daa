"""`ridgeloc solve OBS.json [--method NAME ...|--method all] [--json]`: run estimators on an observations file
(docs/observations_format.md) and print their estimates.

With `--method all` (the default) every estimator that can runs; the others are listed with their status and
reason (e.g. range-only on a straight pass, anything with pixels on a file without them), and the command
succeeds when at least one solved. Named methods must all solve.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from pipeline.errors import RidgelocError, SolverError
from pipeline.solve_options import METHODS

HELP = "Locate the target in an observations file with one or more estimators (docs/solvers.md)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("observations", metavar="OBS.json", help="observations file (docs/observations_format.md)")
    parser.add_argument("--method", "-m", action="append", choices=(*METHODS, "all"), metavar="NAME",
                        help=f"estimator, repeatable: {', '.join(METHODS)} or all (default: all)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")


def _methods(chosen: list[str] | None) -> list[str]:
    if not chosen or "all" in chosen:
        return list(METHODS)
    return list(dict.fromkeys(chosen))


def _table(results: dict, failures: dict, truth, t_ns=None) -> str:
    from pipeline.solve import mle_outputs

    head = f"{'method':<11}{'x_m':>12}{'y_m':>12}{'z_m':>11}{'iter':>6}  {'status':<15}{'cond':>10}"
    if truth is not None:
        head += f"{'error_m':>10}"
    lines = [head]
    for name, d in results.items():
        x, y, z = d["position_m"]
        cond = "-" if d["condition_number"] is None else f"{d['condition_number']:.3g}"
        line = f"{name:<11}{x:12.3f}{y:12.3f}{z:11.3f}{d['iterations']:6d}  {d['status']:<15}{cond:>10}"
        if truth is not None:
            line += f"{d['error_m']:10.3f}"
        lines.append(line)
    for name, f in failures.items():
        lines.append(f"{name:<11}not solved ({f['status']}): {f['reason']}")
    notes = []
    if "los" in results and "oracle_error_m" in results["los"]:
        notes.append(f"los: median of {sum(p is not None for p in results['los']['points_m'])} frames; best "
                     f"single frame (oracle, needs the truth) {results['los']['oracle_error_m']:.3f} m")
    if "mle" in results:
        m = results["mle"]
        ax = m["ellipsoid"]["semi_axes_1sigma_m"]
        notes.append(f"mle: CEP50 {m['cep50_m']:.3f} m, CEP90 {m['cep90_m']:.3f} m (horizontal); 1-sigma "
                     f"ellipsoid semi-axes {ax[0]:.3f} {ax[1]:.3f} {ax[2]:.3f} m; robust {m['robust']}")
        notes += mle_outputs.notes(m, t_ns)
    if "ridge" in results and "k" in results["ridge"]:
        notes.append(f"ridge: last k = {results['ridge']['k']:.4g}")
    return "\n".join(lines + notes)


def _answer_line(a: dict) -> str:
    """The answer in one line (docs/outputs.md, "The answer")."""
    if a["status"] != "located":
        return f"answer: not located: {a['reason']}"
    x, y, z = a["position_m"]
    acc = "" if "ce90_m" not in a else f", CE90 {a['ce90_m']:.2f} m, LE90 {a['le90_m']:.2f} m"
    return f"answer: {a['method']} at ({x:.3f}, {y:.3f}, {z:.3f}) m{acc} ({a['reason']})"


def main(args) -> int:
    from pipeline.observation_file import load
    from pipeline.solve import solve, unsolved_status  # the CLI builds every command's parser: solve loads scipy

    obs = load(args.observations)
    results: dict = {}
    estimates: dict = {}
    failures: dict = {}
    every = not args.method or "all" in args.method
    for name in _methods(args.method):
        try:
            est = solve(name, obs)
        except RidgelocError as exc:
            failures[name] = {"status": unsolved_status(exc), "reason": str(exc)}
            continue
        results[name] = est.to_dict(obs.truth_m)
        estimates[name] = est
    from pipeline.answer import choose_answer

    # the answer in the file's own frame: an observations file has no geodetic origin, so no ground below it
    answer = choose_answer(obs, estimates, {m: f["reason"] for m, f in failures.items()}, None).summary()
    if args.json:
        doc: dict = {"answer": answer, "estimates": results}
        if failures:
            doc["unsolved"] = failures
        print(json.dumps(doc, indent=1, default=_json_default))
    else:
        print(_answer_line(answer) + "\n")
        print(_table(results, failures, obs.truth_m, obs.t_ns))
    sys.stdout.flush()
    if failures and (not every or not results):
        names = ", ".join(failures)
        if len(failures) == 1:
            raise SolverError(next(iter(failures.values()))["reason"], args.observations)
        raise SolverError(f"{len(failures)} estimators failed ({names}); see the output above",
                          args.observations)
    return 0


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
