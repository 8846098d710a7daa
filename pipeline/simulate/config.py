"""The simulation experiment's configuration: typed defaults, loaded from YAML, unknown keys rejected.

Every choice the paper leaves open (section 3.1) is a key here; docs/simulation.md says what each default is
and why. Defaults reproduce the paper's setup: 2 km height, 5 km slant distance, 10 observations, intersection
angles 10..80 deg, noise 5 m / 2.5 m / 0.2 deg / 0.1 px, 1000 trials.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Annotated, Literal

from annotated_types import Ge, Gt, MinLen

from pipeline.config_schema import NonNegative, Positive, load_dataclass, read_yaml, to_plain
from pipeline.errors import ConfigError
from pipeline.solve_options import METHODS, Method


@dataclass(frozen=True)
class GeometryConfig:
    """Flight path and viewing geometry. The target is at the world origin (ENU metres, z up).

    path: "arc" = the platform circles the target at constant height and slant distance (every frame at the
        nominal observation angle); "straight" = a straight level line whose midpoint is at the nominal slant
        distance, perpendicular to the horizontal line of sight there (end frames are farther away).
    n_observations: frames per trial, evenly spaced along the path between the first and last line of sight.
    """

    path: Literal["arc", "straight"] = "arc"
    n_observations: Annotated[int, Ge(2)] = 10
    height_m: Positive = 2000.0
    slant_distance_m: Positive = 5000.0


@dataclass(frozen=True)
class CameraConfig:
    """Pinhole camera without distortion, principal point at the image centre.

    pointing_jitter_deg: std (per axis) of how far the true optical axis misses the target, so the true
        pixel is not always the principal point (0 = the target locked at the centre, as in the paper).
    """

    image_width_px: Annotated[int, Gt(0)] = 600
    image_height_px: Annotated[int, Gt(0)] = 400
    focal_length_px: Positive = 1000.0
    pointing_jitter_deg: NonNegative = 0.0


@dataclass(frozen=True)
class NoiseConfig:
    """Zero-mean normal noise, standard deviations.

    platform_position_m: per axis, on the platform (camera centre = laser origin) position the estimators see.
    range_m: on the laser range, which is measured from the true platform position.
    attitude_deg: per axis, a small rotation composed with the true camera attitude the estimators see.
    attitude_model: "independent" = a fresh error per frame; "accumulating" = a random walk, frame i's error is
        the sum of i independent steps of attitude_deg each; "constant" = one error shared by all frames (bias).
    pixel_px: per axis, on the target pixel, which is projected through the true camera.
    """

    platform_position_m: NonNegative = 5.0
    range_m: NonNegative = 2.5
    attitude_deg: NonNegative = 0.2
    attitude_model: Literal["independent", "accumulating", "constant"] = "independent"
    pixel_px: NonNegative = 0.1


@dataclass(frozen=True)
class SolverConfig:
    """Options passed to every estimator (pipeline.solve.solve_batch).

    tol_m: the paper's iteration threshold ||dX|| (0.0001 in section 3.1).
    max_iterations: iteration limit; a trial that reaches it counts as non-converged.
    ridge_hkb: Hoerl-Kennard-Baldwin variant for the ridge estimator, "paper" (Eqs. 44-45 as printed) or
        "textbook".
    mle_sigma: "given" = the MLE is told the true noise standard deviations of this config; "estimated" = it
        is told nothing and must estimate them (variance components) from the data.
    mle_robust: the MLE's loss; "none" = plain weighted least squares, the maximum-likelihood estimator for the
        Gaussian noise simulated here; "huber" / "cauchy" = the robust losses meant for real data with outliers.
    """

    tol_m: Positive = 1e-4
    max_iterations: Annotated[int, Ge(1)] = 100
    ridge_hkb: Literal["paper", "textbook"] = "paper"
    mle_sigma: Literal["given", "estimated"] = "given"
    mle_robust: Literal["none", "huber", "cauchy"] = "none"


@dataclass(frozen=True)
class SimulationConfig:
    """The whole experiment; `name` labels the outputs (defaults to the config file's stem)."""

    name: str = "table2"
    description: str = ""
    seed: Annotated[int, Ge(0)] = 20240601
    trials: Annotated[int, Ge(1)] = 1000
    angles_deg: Annotated[tuple[float, ...], MinLen(1)] = (10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0)
    methods: Annotated[tuple[Method, ...], MinLen(1)] = METHODS
    geometry: GeometryConfig = field(default_factory=GeometryConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)

    def __post_init__(self):
        _check_config(self)

    @classmethod
    def from_dict(cls, doc: dict | None, path: str | PathLike | None = None) -> SimulationConfig:
        doc = {} if doc is None else doc
        if isinstance(doc, dict) and "name" not in doc and path is not None:
            doc = {**doc, "name": Path(path).stem.removeprefix("simulation_")}
        return load_dataclass(cls, doc, source=path, style="quoted")

    @classmethod
    def load(cls, path: str | PathLike) -> SimulationConfig:
        return cls.from_dict(read_yaml(path), path)

    def replace(self, **changes) -> SimulationConfig:
        """A copy with `changes`, validated as a YAML config is (ConfigError: `'trials' must be >= 1, got 0`)."""
        return type(self).from_dict(dataclasses.replace(self, **changes).to_dict())

    def to_dict(self) -> dict:
        return to_plain(self)


def _check_config(cfg: SimulationConfig) -> None:
    """What the field annotations cannot say: no duplicates, a reachable geometry."""
    g = cfg.geometry
    for name in ("angles_deg", "methods"):
        values = list(getattr(cfg, name))
        if len(set(values)) != len(values):
            raise ConfigError(f"'{name}' has duplicates: {values}")
    if not g.height_m < g.slant_distance_m:
        raise ConfigError(f"'geometry.height_m' ({g.height_m}) must be below 'geometry.slant_distance_m' "
                          f"({g.slant_distance_m})")
    max_angle = max_intersection_angle_deg(g)
    too_wide = [a for a in cfg.angles_deg if not 0 < a < max_angle]
    if too_wide:
        raise ConfigError(f"'angles_deg' {too_wide} not reachable: the {g.path} path at this height and slant distance "
                          f"allows intersection angles in (0, {max_angle:.1f}) deg")


def max_intersection_angle_deg(g: GeometryConfig) -> float:
    """Largest intersection angle the path can produce (arc: half a circle; straight: approaching 180 deg)."""
    if g.path == "straight":
        return 180.0
    r2 = g.slant_distance_m ** 2 - g.height_m ** 2
    return math.degrees(math.acos((g.height_m ** 2 - r2) / g.slant_distance_m ** 2))
