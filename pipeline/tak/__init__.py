"""Targets into TAK (ATAK, iTAK, WinTAK, TAK Server, FreeTAKServer): Cursor on Target events, data packages,
sending.

Modules:
    cot: one located target -> a CoT 2.0 event (XML bytes); stable uids; stale times; re-stamping for a send.
    package: a TAK data package (zip with MANIFEST/manifest.xml) of events.
    send: events to udp://, tcp:// or tls:// destinations through PyTAK (protobuf through takproto on request).

What the events hold, and why (ce/le as CE90/LE90, the type, how, stale): docs/outputs.md, "For TAK users".
"""

#: the TAK SA multicast group and port ATAK, iTAK and WinTAK listen on: where `ridgeloc send` sends by default
DEFAULT_URL = "udp://239.2.3.1:6969"
#: the default CoT type of a target: an atom of unknown affiliation on the ground
DEFAULT_TYPE = "a-u-G"
#: how long a target's event stays valid by default (s)
DEFAULT_STALE_S = 24 * 3600.0
