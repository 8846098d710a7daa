"""The scripts under scripts/ as modules (scripts/zoo.py, scripts/zoo_unseen.py), loaded once, and the zoo's
no-catastrophe rule on one flight."""

import importlib.util
import sys
from pathlib import Path

import numpy as np

from pipeline.errors import RidgelocError
from pipeline.solve import solve
from pipeline.solve_options import METHODS

SCRIPTS = Path(__file__).resolve().parents[2] / "scripts"


def script(name: str):
    """scripts/{name}.py as the module `name`, loaded once (scripts/ on sys.path while it loads, as when it is run:
    zoo_unseen imports zoo)."""
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, SCRIPTS / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module  # registered before running it: its dataclasses look their module up
        sys.path.insert(0, str(SCRIPTS))
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[name]
            raise
        finally:
            sys.path.remove(str(SCRIPTS))
    return sys.modules[name]


def zoo():
    return script("zoo")


def error_m(method: str, obs) -> float | None:
    """|solve(method, obs) - truth| m, or None where the method cannot solve the flight."""
    try:
        est = solve(method, obs)
    except RidgelocError:  # this method cannot solve this flight (too few ranges, degenerate geometry...)
        return None
    e = float(np.linalg.norm(est.position_m - obs.truth_m))
    return e if np.isfinite(e) else None


def catastrophe_bound(obs) -> tuple[float | None, float, int]:
    """(mle error m or None, bound m (scripts/zoo.py's `catastrophe`: 2 x median(the other methods' errors) + 5 m;
    NaN without others), how many others solved)."""
    errors = {m: e for m in METHODS if (e := error_m(m, obs)) is not None}
    _, bound, _ = zoo().catastrophe(errors)
    return errors.get("mle"), float("nan") if bound is None else bound, len(errors) - ("mle" in errors)
