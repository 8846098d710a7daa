"""Loopback TAK listeners for the tests, and reading what they received with TAK libraries ridgeloc did not write:
PyTAK's receiving worker splits an XML stream into events (`RXWorker.readcot`), takproto parses an event (XML
or TAK protocol version 1, mesh or stream) into a `TakMessage`.

Listeners bind 127.0.0.1 only, on a port the system picks, and keep what they receive in memory.
"""

from __future__ import annotations

import asyncio
import io
import socket
import ssl
import threading
import time
import warnings


def takproto():
    import takproto as tp

    return tp


def parse_event(data: bytes):
    """A TakMessage from one event: XML (with or without a declaration), or TAK protocol v1 with mesh (UDP) or
    stream framing (takproto)."""
    data = bytes(data).strip()
    if data[:1] == b"<":
        from takproto.functions import xml2message

        return xml2message(data)
    msg = takproto().parse_proto(bytearray(data))
    if msg is None:
        raise ValueError(f"not a TAK message: {data[:60]!r}")
    return msg


def split_xml_stream(data: bytes) -> list[bytes]:
    """The events of an XML CoT stream, split as PyTAK's receiver does (readuntil "</event>")."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import pytak

    async def read_all():
        reader = asyncio.StreamReader()
        reader.feed_data(data)
        reader.feed_eof()
        worker = pytak.RXWorker(asyncio.Queue(), {"TAK_PROTO": "0"}, reader)
        out = []
        while (event := await worker.readcot()) is not None:
            out.append(event.strip())
        return out

    return asyncio.run(read_all())


def split_proto_stream(data: bytes) -> list:
    """The TakMessages of a TAK protocol v1 stream (0xbf, varint length, message), read with takproto."""
    from takproto import delimited_protobuf
    from takproto.proto import TakMessage

    bio, out = io.BytesIO(data), []
    while (head := bio.read(1)) == b"\xbf":
        out.append(delimited_protobuf.read(bio, TakMessage))
    if head != b"":
        raise ValueError(f"not a TAK protocol stream at byte {bio.tell() - 1}: {head!r}")
    return out


class _Listener:
    """A socket on 127.0.0.1 served by a thread (`_run`) that keeps what arrives in `received`."""

    def __init__(self, sock: socket.socket):
        self.sock = sock
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.received: list[bytes] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        raise NotImplementedError

    def wait_for(self, n: int, timeout_s: float = 10.0) -> list[bytes]:
        """What has arrived once there are `n` items, or when `timeout_s` has passed."""
        t_end = time.monotonic() + timeout_s
        while len(self.received) < n and time.monotonic() < t_end:
            time.sleep(0.05)
        return list(self.received)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join(5)
        self.sock.close()


class UdpListener(_Listener):
    """Datagrams to 127.0.0.1:`port`, one item of `received` each."""

    def __init__(self):
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        super().__init__(sock)

    def _run(self):
        while not self._stop.is_set():
            try:
                self.received.append(self.sock.recv(65536))
            except TimeoutError:
                continue


class TcpListener(_Listener):
    """A stream server on 127.0.0.1:`port` (TLS when `ssl_context` is given): the bytes of each connection, one
    item of `received`, complete once the client has closed it. `handshake=False` accepts TCP connections and
    then says nothing (a server that never answers)."""

    def __init__(self, ssl_context: ssl.SSLContext | None = None, handshake: bool = True):
        super().__init__(socket.create_server(("127.0.0.1", 0)))
        self.ssl_context, self.handshake = ssl_context, handshake
        self.errors: list[str] = []

    def _run(self):
        held = []
        while not self._stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except TimeoutError:
                continue
            if not self.handshake:
                held.append(conn)
                continue
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()
        for c in held:
            c.close()

    def _serve(self, conn):
        try:
            if self.ssl_context is not None:
                conn.settimeout(10)
                conn = self.ssl_context.wrap_socket(conn, server_side=True)
            conn.settimeout(10)
            chunks = []
            while chunk := conn.recv(65536):
                chunks.append(chunk)
            self.received.append(b"".join(chunks))
        except (OSError, ssl.SSLError) as exc:
            self.errors.append(f"{type(exc).__name__}: {exc}")
        finally:
            conn.close()


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now (bound and released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def make_certificates(folder) -> dict:
    """A CA, a server certificate for 127.0.0.1 / localhost and a client certificate it signed, as PEM files in
    `folder`, and the client's certificate and key as a PKCS#12 file with the password "atakatak", as TAK servers
    hand them out (the `cryptography` package, which PyTAK's with-crypto extra installs); paths by name."""
    import datetime

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    now = datetime.datetime.now(datetime.timezone.utc)

    def name(cn):
        return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)])

    def cert(subject, key, issuer, issuer_key, *, ca=False, san=None, usage=None):
        b = (x509.CertificateBuilder().subject_name(name(subject)).issuer_name(name(issuer))
             .public_key(key.public_key()).serial_number(x509.random_serial_number())
             .not_valid_before(now - datetime.timedelta(days=1)).not_valid_after(now + datetime.timedelta(days=2))
             .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True))
        if san:
            b = b.add_extension(x509.SubjectAlternativeName(san), critical=False)
        if usage:
            b = b.add_extension(x509.ExtendedKeyUsage([usage]), critical=False)
        return b.sign(issuer_key, hashes.SHA256())

    import ipaddress

    ca_key, server_key, client_key = (ec.generate_private_key(ec.SECP256R1()) for _ in range(3))
    ca = cert("test TAK CA", ca_key, "test TAK CA", ca_key, ca=True)
    server = cert("localhost", server_key, "test TAK CA", ca_key,
                  san=[x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))],
                  usage=ExtendedKeyUsageOID.SERVER_AUTH)
    client = cert("ridgeloc test client", client_key, "test TAK CA", ca_key, usage=ExtendedKeyUsageOID.CLIENT_AUTH)
    from cryptography.hazmat.primitives.serialization import pkcs12

    paths = {"client_p12": folder / "client.p12"}
    paths["client_p12"].write_bytes(pkcs12.serialize_key_and_certificates(
        b"client", client_key, client, None, serialization.BestAvailableEncryption(b"atakatak")))
    for label, c, k in (("ca", ca, None), ("server", server, server_key), ("client", client, client_key)):
        paths[f"{label}_cert"] = folder / f"{label}.pem"
        paths[f"{label}_cert"].write_bytes(c.public_bytes(serialization.Encoding.PEM))
        if k is not None:
            paths[f"{label}_key"] = folder / f"{label}.key"
            paths[f"{label}_key"].write_bytes(k.private_bytes(serialization.Encoding.PEM,
                                                              serialization.PrivateFormat.PKCS8,
                                                              serialization.NoEncryption()))
    return paths


def atak_import(package: bytes) -> dict:
    """What ATAK's data package import does with `package` (zip bytes), by the rules of its MissionPackageExtractor
    and MissionPackageManifest (ATAK-CIV): the manifest at MANIFEST/manifest.xml, <MissionPackageManifest
    version="2">, a Configuration with `name` and `uid` parameters, each Content's zipEntry an entry of the zip,
    and a ".cot" entry imported as an event when it parses with a uid. Returns {"name", "uid", "events": {uid:
    TakMessage}, "entries": the zip's names}; AssertionError where ATAK would refuse the package or skip an
    entry."""
    import zipfile

    from defusedxml import ElementTree

    with zipfile.ZipFile(io.BytesIO(package)) as z:
        names = z.namelist()
        assert "MANIFEST/manifest.xml" in names, "no MANIFEST/manifest.xml"
        root = ElementTree.fromstring(z.read("MANIFEST/manifest.xml"))
        assert root.tag == "MissionPackageManifest" and root.get("version") == "2", root.tag
        params = {p.get("name"): p.get("value") for p in root.find("Configuration").findall("Parameter")}
        assert params.get("name") and params.get("uid"), params
        events = {}
        for content in root.find("Contents").findall("Content"):
            entry = content.get("zipEntry")
            assert entry in names, f"manifest lists {entry}, not in the zip"
            assert content.get("ignore", "false") == "false"
            assert entry.lower().endswith(".cot"), entry
            msg = parse_event(z.read(entry))
            uid = msg.cotEvent.uid
            assert uid, entry
            listed = {p.get("name"): p.get("value") for p in content.findall("Parameter")}
            assert listed.get("uid") in (None, uid), (entry, listed, uid)
            events[uid] = msg
    return {"name": params["name"], "uid": params["uid"], "events": events, "entries": names}


Z90 = 1.6448536269514722  # the standard normal's 90 % two-sided quantile


def ce90_by_integration(cov2) -> float:
    """Radius of the disc holding 90 % of a zero-mean 2-D Gaussian of covariance `cov2` (2, 2), integrated here
    (not with ridgeloc's code): P(r) = 1 / (2 pi sqrt|C|) * integral over theta of (1 - exp(-r^2 a / 2)) / a,
    a = u' C^-1 u, u the unit vector at theta (the density in polar coordinates, integrated along each ray)."""
    import math

    import numpy as np
    from scipy import integrate, optimize

    inv, det = np.linalg.inv(cov2), np.linalg.det(cov2)

    def a(theta):
        u = np.array([math.cos(theta), math.sin(theta)])
        return float(u @ inv @ u)

    def p(r):
        return integrate.quad(lambda t: (1 - math.exp(-r * r * a(t) / 2)) / a(t), 0, 2 * math.pi,
                              limit=200)[0] / (2 * math.pi * math.sqrt(det))

    return optimize.brentq(lambda r: p(r) - 0.9, 1e-9, 10 * math.sqrt(np.trace(cov2)), xtol=1e-9)


def compare_run_events(out) -> list[dict]:
    """Each event of OUT/cot/ beside what it was made from: targets.csv's row (by callsign = `name`) and the
    answer in OUT/<flight>/result.json (its ENU position converted here with pymap3d, CE90 integrated and LE90
    computed from its covariance). One dict per event: name, uid, status, and the differences d_* (deg, m)."""
    import csv
    import json
    import math
    from pathlib import Path

    import numpy as np
    import pymap3d

    out = Path(out)
    rows = {r["name"]: r for r in csv.DictReader((out / "targets.csv").open())}
    answers = {}
    for f in out.glob("*/result.json"):
        doc = json.loads(f.read_text())
        for r in doc.get("targets") or [doc]:
            if "answer" in r:
                name = r["name"] if r.get("target") is None else f"{r['name']}:{r['target']}"
                answers[name] = (r["answer"], r["origin_lla"])
    report = []
    for f in sorted((out / "cot").glob("*.cot")):
        e = parse_event(f.read_bytes()).cotEvent
        name = e.detail.contact.callsign
        row, (answer, origin) = rows[name], answers[name]
        lat, lon, h = pymap3d.enu2geodetic(*answer["position_m"], *origin)
        cov = np.asarray(answer["covariance_m2"])
        report.append({
            "name": name, "uid": e.uid, "status": row["status"], "answer_status": answer["status"],
            "d_lat_csv_deg": abs(e.lat - float(row["lat_deg"])), "d_lon_csv_deg": abs(e.lon - float(row["lon_deg"])),
            "d_hae_csv_m": abs(e.hae - float(row["alt_m"])), "d_lat_answer_deg": abs(e.lat - lat),
            "d_lon_answer_deg": abs(e.lon - lon), "d_hae_answer_m": abs(e.hae - h),
            "ce": e.ce, "ce90_m": ce90_by_integration(cov[:2, :2]), "le": e.le, "le90_m": Z90 * math.sqrt(cov[2, 2]),
            "sigma_h_m": math.sqrt(np.trace(cov[:2, :2]) / 2)})
    return report
