"""pipeline.config_schema: YAML rules (strict scalars, lists -> tuples) and one-line messages naming file and key."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import pytest

from pipeline.config_schema import load_dataclass, read_yaml, to_plain
from pipeline.errors import ConfigError


@dataclass(frozen=True)
class Lens:
    focal_mm: float = 35.0
    count: int = 1
    coeffs: tuple[float, ...] = ()
    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        if self.focal_mm <= 0:
            raise ValueError("'focal_mm' must be positive")


@dataclass(frozen=True)
class Site:
    lat_deg: float
    lon_deg: float


@dataclass(frozen=True)
class Rig:
    name: str = "rig"
    enabled: bool = True
    lens: Lens = field(default_factory=Lens)
    lenses: tuple[Lens, ...] = ()
    site: Site | str = "auto"
    mode: str = "a"
    extra: dict[str, object] = field(default_factory=dict)

    def __post_init__(self):
        if self.mode == "explode":
            raise ConfigError("'mode' explode is not allowed")


def _error(doc, **kw) -> str:
    with pytest.raises(ConfigError) as info:
        load_dataclass(Rig, doc, source="cfg/rig.yaml", **kw)
    return str(info.value)


def test_values_are_typed_ints_stay_ints_lists_become_tuples():
    rig = load_dataclass(Rig, {"lens": {"focal_mm": 50, "count": 3, "coeffs": [1, 2.5], "offset_m": [0, 1, 2]},
                               "lenses": [{"count": 2}], "site": {"lat_deg": 1, "lon_deg": 2}, "extra": {"k": [1]}})
    assert rig.lens == Lens(focal_mm=50.0, count=3, coeffs=(1.0, 2.5), offset_m=(0.0, 1.0, 2.0))
    assert type(rig.lens.focal_mm) is float and type(rig.lens.count) is int and type(rig.lens.coeffs[0]) is float
    assert rig.lenses == (Lens(count=2),) and rig.site == Site(1.0, 2.0) and rig.extra == {"k": [1]}
    assert load_dataclass(Rig, {}) == Rig()


def test_unknown_key_names_the_file_and_suggests_the_key_with_its_unit():
    assert _error({"lens": {"focal": 50}}) == "cfg/rig.yaml: lens.focal: unknown key (did you mean 'focal_mm'?)"
    assert _error({"colour": "red"}) == ("cfg/rig.yaml: colour: unknown key "
                                         "(known: name, enabled, lens, lenses, site, mode, extra)")
    assert _error({"lens": {"a": 1, "b": 2}}) == ("cfg/rig.yaml: lens.a, lens.b: unknown keys "
                                                  "(known: focal_mm, count, coeffs, offset_m)")
    assert _error({"lens": {"focal": 1}}, style="quoted") == ("cfg/rig.yaml: unknown key(s) lens.focal "
                                                              "(did you mean 'focal_mm'?)")


def test_wrong_types_are_named_with_the_nested_key_path():
    assert _error({"lens": {"count": "three"}}) == ("cfg/rig.yaml: lens.count: must be a plain number "
                                                    "(the unit is in the key's name), got 'three'")
    assert _error({"lens": {"count": "3"}}) == "cfg/rig.yaml: lens.count: must be an integer, got str '3'"
    assert _error({"name": 5}) == "cfg/rig.yaml: name: must be a string, got int 5"
    assert _error({"lens": 5}) == "cfg/rig.yaml: lens: must be a mapping of keys, got int 5"
    assert _error({"lens": {"coeffs": 1.0}}) == "cfg/rig.yaml: lens.coeffs: must be a list, got float 1.0"
    assert _error({"lens": {"count": "x"}}, style="quoted") == (
        "cfg/rig.yaml: 'lens.count' must be an integer, got str 'x'")  # no unit hint in this style
    assert _error([1, 2], style="quoted") == "cfg/rig.yaml: the top level must be a mapping of keys, got list [1, 2]"


def test_list_indices_in_the_key_path():
    assert _error({"lens": {"coeffs": [1.0, "a"]}}, style="quoted").endswith(
        "'lens.coeffs[1]' must be a finite number, got str 'a'")
    assert _error({"lenses": [{}, {"count": 1.5}]}) == (
        "cfg/rig.yaml: lenses[1].count: must be an integer, got float 1.5")
    assert _error({"lens": {"offset_m": [1, 2]}}) == "cfg/rig.yaml: lens.offset_m: must have 3 elements, got 2"
    assert _error({"lens": {"offset_m": [1, 2, 3, 4]}}) == "cfg/rig.yaml: lens.offset_m: must have 3 elements, got 4"


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_non_finite_floats_are_rejected(value):
    assert _error({"lens": {"focal_mm": value}}) == (
        f"cfg/rig.yaml: lens.focal_mm: must be a finite number, got float {value!r}")


def test_bools_are_not_numbers_and_numbers_are_not_bools():
    assert _error({"lens": {"count": True}}) == "cfg/rig.yaml: lens.count: must be an integer, got bool True"
    assert _error({"lens": {"focal_mm": False}}) == (
        "cfg/rig.yaml: lens.focal_mm: must be a finite number, got bool False")
    assert _error({"enabled": 1}) == "cfg/rig.yaml: enabled: must be true or false, got int 1"


def test_integral_floats_only_where_asked():
    assert _error({"lens": {"count": 2.0}}) == "cfg/rig.yaml: lens.count: must be an integer, got float 2.0"
    rig = load_dataclass(Rig, {"lens": {"count": 2.0}}, integral_floats=True)
    assert rig.lens.count == 2 and type(rig.lens.count) is int
    assert "must be an integer, got float 2.5" in _error({"lens": {"count": 2.5}}, integral_floats=True)


def test_checks_of_the_dataclasses_and_unions():
    assert _error({"lens": {"focal_mm": -1}}) == "cfg/rig.yaml: lens: 'focal_mm' must be positive"
    assert _error({"site": {"lat_deg": 1}}) == "cfg/rig.yaml: site.lon_deg: is required"
    assert _error({"site": 3}) == "cfg/rig.yaml: site: must be a mapping of keys, got int 3"  # the first member's error
    assert _error({"site": {"lat_deg": 1, "lon_deg": 2, "zz": 3}}) == (
        "cfg/rig.yaml: site.zz: unknown key (known: lat_deg, lon_deg)")
    assert _error({"mode": "explode"}) == "cfg/rig.yaml: 'mode' explode is not allowed"  # ConfigError, file added
    assert _error({"extra": {1: "x"}}) == "cfg/rig.yaml: extra: has a key that is not a string: 1"


def test_without_a_source_the_message_has_no_file():
    with pytest.raises(ConfigError, match=r"^lens\.count: must be an integer, got str '3'$") as info:
        load_dataclass(Rig, {"lens": {"count": "3"}})
    assert info.value.path is None


def test_to_plain_reads_back():
    rig = Rig(lens=Lens(coeffs=(1.0, 2.0)), lenses=(Lens(count=4),), site=Site(3.0, 4.0))
    plain = to_plain(rig)
    assert plain["lens"]["coeffs"] == [1.0, 2.0] and plain["lenses"][0]["count"] == 4
    assert load_dataclass(Rig, plain) == rig


def test_read_yaml_errors_are_one_line_naming_the_file(tmp_path):
    with pytest.raises(ConfigError, match="config file not found"):
        read_yaml(tmp_path / "none.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: 1\nb: [2,\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml: not valid YAML at line 3 column 1: ") as info:
        read_yaml(bad)
    assert "\n" not in str(info.value)
    (tmp_path / "empty.yaml").write_text("")
    assert read_yaml(tmp_path / "empty.yaml") is None
