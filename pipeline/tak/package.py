"""A TAK data package (ATAK's "Mission Package" format, version 2, which iTAK and WinTAK import too): a zip with
MANIFEST/manifest.xml and the events.

    MANIFEST/manifest.xml
    <event uid>/<name>.cot          one per event

    <MissionPackageManifest version="2">
      <Configuration>
        <Parameter name="uid" value="<package uid>"/>
        <Parameter name="name" value="<name>"/>
        <Parameter name="onReceiveImport" value="true"/>
        <Parameter name="onReceiveDelete" value="false"/>
      </Configuration>
      <Contents>
        <Content ignore="false" zipEntry="<event uid>/<name>.cot">
          <Parameter name="uid" value="<event uid>"/>
          <Parameter name="name" value="<callsign>"/>
        </Content> ...
      </Contents>
    </MissionPackageManifest>

What ATAK requires to import one (its MissionPackageExtractor and MissionPackageManifest, ATAK-CIV): the
manifest at that path, version 2, a Configuration with at least a `name` and a `uid`, and each Content's
`zipEntry` naming an entry of the zip; an entry ending in ".cot" that parses as an event with a uid is
imported as a map item. The package uid is derived from the events' uids, so importing the package of a
re-run replaces the earlier one.
"""

from __future__ import annotations

import io
import uuid
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass

from pipeline.tak.cot import UID_NAMESPACE, XML_DECLARATION

MANIFEST_PATH = "MANIFEST/manifest.xml"


@dataclass(frozen=True)
class PackageEntry:
    """One event of a package: its uid, the callsign shown for it, its file name (`<name>.cot`) and XML bytes."""

    uid: str
    callsign: str
    file_name: str
    xml: bytes

    @property
    def zip_entry(self) -> str:
        return f"{self.uid}/{self.file_name}"


def package_uid(event_uids: Sequence[str]) -> str:
    """The package's uid: a uuid5 of its events' uids (in any order)."""
    return str(uuid.uuid5(UID_NAMESPACE, "data-package:" + "\n".join(sorted(event_uids))))


def manifest_xml(entries: Sequence[PackageEntry], name: str) -> bytes:
    """MANIFEST/manifest.xml of a package of `entries` named `name`."""
    root = ET.Element("MissionPackageManifest", {"version": "2"})
    config = ET.SubElement(root, "Configuration")
    for key, value in (("uid", package_uid([e.uid for e in entries])), ("name", name),
                       ("onReceiveImport", "true"), ("onReceiveDelete", "false")):
        ET.SubElement(config, "Parameter", {"name": key, "value": value})
    contents = ET.SubElement(root, "Contents")
    for e in entries:
        content = ET.SubElement(contents, "Content", {"ignore": "false", "zipEntry": e.zip_entry})
        ET.SubElement(content, "Parameter", {"name": "uid", "value": e.uid})
        ET.SubElement(content, "Parameter", {"name": "name", "value": e.callsign})
    ET.indent(root)
    return (XML_DECLARATION + ET.tostring(root, encoding="unicode") + "\n").encode("utf-8")


def data_package(entries: Sequence[PackageEntry], name: str) -> bytes:
    """The zip bytes of a data package of `entries` (deflated; entries dated 1980-01-01, so the same events give
    the same bytes)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for path, data in ((MANIFEST_PATH, manifest_xml(entries, name)), *((e.zip_entry, e.xml) for e in entries)):
            info = zipfile.ZipInfo(path, date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            z.writestr(info, data)
    return buf.getvalue()
