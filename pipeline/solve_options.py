"""The estimators' names and options as data: one table that a config validates against at load.

`METHODS` is the one list of estimator names (docs/solvers.md). `OPTIONS[method]` lists the keyword options
`solve(method, obs, **options)` accepts, each an `Option` (name, type, bounds, default, meaning), as
docs/solvers.md and `pipeline.solve.methods` state them. `options_schema()` turns the table into a typed
dataclass per method (every field defaulting to `UNSET`, "not given": `solve` applies its own default), which
`pipeline.config_schema.load_dataclass` validates, so a flight config's `solve.options.mle.robst` is refused
at load with "did you mean 'robust'" instead of failing as a diverged method after ingest and tracking.
`given_options` turns a validated schema back into `{method: {option: value}}` with the given keys only.
`solve` keeps its own checks (it is called from code as well as from configs).

It sits in the config layer, beside `pipeline.flight_config` which imports it, and imports no pipeline module:
importing `pipeline.solve` costs about 2.5 s (scipy.stats), which would break "a config mistake is refused in
the first second". `pipeline.solve.methods` takes METHODS from here.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import annotated_types
import pydantic

from pipeline.config_schema import NonNegative, Positive

METHODS = ("dlt", "vision", "range", "los", "fusion-raw", "fusion", "ridge", "mle")
Method = Literal["dlt", "vision", "range", "los", "fusion-raw", "fusion", "ridge", "mle"]


class _Unset:
    """The default of an option that was not given (None is a value: `robust: null` is the squared loss)."""

    def __repr__(self) -> str:
        return "UNSET"

    def __copy__(self):
        return self  # pydantic copies a default: UNSET stays the one marker

    def __deepcopy__(self, memo):
        return self


UNSET: Any = _Unset()



@dataclass(frozen=True)
class SigmaOption:
    """The mle's `sigma` option: sensor sigmas and correlation times overriding the observations' (all >= 0)."""

    pixel_px: NonNegative | None = None
    range_m: NonNegative | None = None
    position_m: NonNegative | None = None
    attitude_deg: NonNegative | None = None
    attitude_tau_s: NonNegative | None = None
    position_tau_s: NonNegative | None = None


@dataclass(frozen=True)
class Option:
    """One keyword option: `type` is what a config may give (bounds as annotated_types), `default` what `solve`
    uses when it is not given (a description where it depends on the data)."""

    name: str
    type: Any
    default: Any
    meaning: str


_COMMON = (
    Option("tol_m", Positive, 1e-4, "stop when ||dX|| <= tol_m (the paper's threshold)"),
    Option("max_iterations", Annotated[int, annotated_types.Ge(1)], 50, "iteration limit"),
    Option("initial_m", tuple[float, float, float], None, "start value (E, N, U metres), replaces the method's"),
)

OPTIONS: dict[str, tuple[Option, ...]] = {
    "dlt": (),
    "los": (),
    "vision": _COMMON,
    "range": _COMMON,
    "fusion-raw": _COMMON,
    "fusion": _COMMON,
    "ridge": (*_COMMON,
              Option("hkb", Literal["paper", "textbook"], "paper", "Hoerl-Kennard-Baldwin variant"),
              Option("k", NonNegative, None, "a fixed ridge parameter (0 is exactly fusion)")),
    "mle": (*_COMMON,
            Option("robust", Literal["redescending", "huber", "cauchy"] | None, "redescending",
                   "the loss (null: squared)"),
            Option("sigma", SigmaOption, None, "sensor sigmas overriding the flight's `sigma`"),
            Option("estimate_variance_components", bool, "on when the pixel or range sigma is unknown",
                   "estimate the pixel and range sigmas from the data"),
            Option("bias_prior_deg", NonNegative, "learned from the flight",
                   "prior sigma of a constant boresight bias (0: no bias)")),
}


# Options `solve` takes that a config's `solve.options` cannot state: a Python value built from another part of the
# flight config (terrain: the DEM's height function from `terrain:`, docs/terrain.md).
NOT_IN_CONFIG: dict[str, frozenset[str]] = {"mle": frozenset({"terrain"})}
#: where a config states what a NOT_IN_CONFIG option is built from
NOT_IN_CONFIG_WHERE = {
    "terrain": "give the DEM as the flight config's top-level `terrain: {dem: DEM.tif, vertical_sigma_m: ...}`"}


def not_in_config_problem(doc) -> str | None:
    """'solve.options.METHOD.NAME: ...' for a parsed flight config that states a NOT_IN_CONFIG option, else None."""
    options = (doc.get("solve") or {}).get("options") if isinstance(doc, dict) and isinstance(doc.get("solve"),
                                                                                              dict) else None
    for method, names in NOT_IN_CONFIG.items():
        given = options.get(method) if isinstance(options, dict) else None
        for name in sorted(names & set(given if isinstance(given, dict) else ())):
            return f"solve.options.{method}.{name}: not an option of solve.options ({NOT_IN_CONFIG_WHERE[name]})"
    return None


def _schema_name(method: str) -> str:
    return "".join(p.capitalize() for p in method.split("-")) + "Options"


@dataclass(frozen=True)
class _Base:
    def given(self) -> dict:
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, _Unset):
                continue
            out[f.name] = {k: x for k, x in dataclasses.asdict(v).items() if x is not None} \
                if dataclasses.is_dataclass(v) else v
        return out


def _method_schema(method: str) -> type:
    fields = [(o.name, o.type, dataclasses.field(default=UNSET)) for o in OPTIONS[method]]
    return dataclasses.make_dataclass(_schema_name(method), fields, bases=(_Base,), frozen=True,
                                      namespace={"__module__": __name__})


METHOD_SCHEMAS: dict[str, type] = {m: _method_schema(m) for m in METHODS}
SolveOptions = dataclasses.make_dataclass(  # a field per method, named as in a config (fusion-raw: an alias)
    "SolveOptions", [(m.replace("-", "_"), Annotated[METHOD_SCHEMAS[m] | None, pydantic.Field(alias=m)],
                      dataclasses.field(default=None)) for m in METHODS],
    frozen=True, namespace={"__module__": __name__})
SolveOptions.__doc__ = "A flight config's `solve.options`: per method, the options of OPTIONS[method]."
for _schema in (*METHOD_SCHEMAS.values(), SolveOptions):
    globals()[_schema.__name__] = _schema  # importable by name (pickling, get_type_hints)


def given_options(options) -> dict[str, dict]:
    """{method: {option: value}} of a validated SolveOptions, the given options only (a dict passes through)."""
    if isinstance(options, dict):
        return options
    given = {m: getattr(options, m.replace("-", "_")) for m in METHODS}
    return {m: o.given() for m, o in given.items() if o is not None}
