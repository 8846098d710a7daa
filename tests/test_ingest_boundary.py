"""The reader boundary (pipeline.ingest.boundary): one line naming the file for what a parser raises."""

from __future__ import annotations

import errno

import pytest

from pipeline.errors import InputError
from pipeline.ingest.boundary import reader_boundary


def test_an_io_error_names_the_side_file_it_was_about():
    with pytest.raises(InputError) as exc, reader_boundary("/data/flight.bag"):
        raise FileNotFoundError(errno.ENOENT, "No such file or directory", "/data/flight.bag/metadata.yaml")
    assert str(exc.value) == "/data/flight.bag: cannot read: No such file or directory (/data/flight.bag/metadata.yaml)"


def test_an_io_error_on_the_file_itself_is_said_once():
    with pytest.raises(InputError) as exc, reader_boundary("/data/log.tlog"):
        raise PermissionError(errno.EACCES, "Permission denied", "/data/log.tlog")
    assert str(exc.value) == "/data/log.tlog: cannot read: Permission denied"


def test_a_library_error_is_damage_naming_the_file():
    import json

    with pytest.raises(InputError) as exc, reader_boundary("/data/x.json", what="JSON"):
        json.loads("{")
    assert str(exc.value).startswith("/data/x.json: damaged JSON: JSONDecodeError Expecting property name")
