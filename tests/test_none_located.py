"""A flight none of whose targets could be located: one line naming the config once, then each target's reason."""

from types import SimpleNamespace

from pipeline.errors import InputError, none_located


def test_the_config_is_named_once():
    path = "/data/f1/flight.yaml"
    failed = [SimpleNamespace(target="T1", message=f"{path}: inconsistent geometry: the lines of sight ..."),
              SimpleNamespace(target="T2", message="other.csv: T2 is marked in no frame")]
    exc = none_located(failed, path)
    assert isinstance(exc, InputError)
    assert str(exc) == (f"{path}: no target could be located: T1: inconsistent geometry: the lines of sight ...; "
                        "T2: other.csv: T2 is marked in no frame")
    assert str(exc).count(path) == 1
