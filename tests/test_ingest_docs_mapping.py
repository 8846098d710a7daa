"""The documented default mappings are the shipped ones; every mapping key is accepted and typos are not."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.errors import ConfigError
from pipeline.ingest.mapping import FORMATS, check_override, default_mapping, mapping_for

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("fmt", FORMATS)
def test_docs_show_each_default_mapping(fmt):
    text = (REPO / "pipeline" / "ingest" / "mappings" / f"{fmt}.yaml").read_text().rstrip()
    assert text in (REPO / "docs" / "ingest.md").read_text()
    assert default_mapping(fmt)  # parses


def test_override_merges_and_rejects():
    m = mapping_for("ros", {"ros": {"position": {"topic": "/x"}}})
    assert m["position"]["topic"] == "/x" and m["position"]["by_type"] is True
    assert default_mapping("ros")["position"]["topic"] == "/uav/gps/fix"  # defaults untouched
    with pytest.raises(ConfigError, match=r"ros\.position: unknown key 'topc'"):
        check_override({"ros": {"position": {"topc": "/x"}}})
    with pytest.raises(ConfigError, match="expected a mapping"):
        check_override({"ros": {"position": "/x"}})
    with pytest.raises(ConfigError, match="unknown format 'ros3'"):
        check_override({"ros3": {}})
