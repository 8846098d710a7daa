"""Per-format message/topic mappings: package defaults (mappings/<format>.yaml) merged with a user override.

An override is a dict keyed by format (`{"ros": {"position": {"topic": "/my/fix"}}}`), e.g. the `ingest:`
section of a flight config. Dicts merge key by key, any other value replaces the default; a key that is not
in the defaults is rejected (ConfigError) so that a typo never silently falls back to a default.
"""

from __future__ import annotations

import copy
import difflib
from functools import cache
from importlib import resources

import yaml

from pipeline.errors import ConfigError
from pipeline.ingest.rangefinder import rename_deprecated_range_keys

FORMATS = ("tlog", "dataflash", "ulog", "ros", "mcap", "video", "srt", "klv")


@cache
def _defaults(fmt: str) -> dict:
    text = resources.files("pipeline.ingest").joinpath("mappings", f"{fmt}.yaml").read_text()
    return yaml.safe_load(text)


def default_mapping(fmt: str) -> dict:
    """A fresh copy of the package defaults for `fmt`."""
    if fmt not in FORMATS:
        raise ConfigError(f"unknown log format {fmt!r} (known: {', '.join(FORMATS)})")
    return copy.deepcopy(_defaults(fmt))


def _merge(base: dict, override: dict, where: str) -> dict:
    if not isinstance(override, dict):
        raise ConfigError(f"mapping.{where}: expected a mapping, got {type(override).__name__}")
    out = dict(base)
    for key, val in override.items():
        if key not in base:
            near = difflib.get_close_matches(str(key), list(map(str, base)), n=1)
            hint = f"did you mean {near[0]!r}? " if near else ""
            raise ConfigError(f"mapping.{where}: unknown key {key!r} ({hint}known: {', '.join(map(str, base))})")
        if isinstance(base[key], dict):
            out[key] = _merge(base[key], val, f"{where}.{key}")
        else:
            out[key] = val
    return out


def check_override(override: dict | None) -> None:
    """Validate a whole override (all formats) without reading anything: raises ConfigError on unknown keys."""
    for fmt in (override or {}):
        mapping_for(fmt, override)


def mapping_for(fmt: str, override: dict | None = None) -> dict:
    """Defaults of `fmt` with `override[fmt]` merged over them."""
    if override is not None and not isinstance(override, dict):
        raise ConfigError(f"mapping: expected a mapping keyed by format, got {type(override).__name__}")
    for key in override or {}:
        if key not in FORMATS:
            raise ConfigError(f"mapping: unknown format {key!r} (known: {', '.join(FORMATS)})")
    base = default_mapping(fmt)
    if override and override.get(fmt) is not None:
        return _merge(base, rename_deprecated_range_keys(fmt, override[fmt]), fmt)
    return base
