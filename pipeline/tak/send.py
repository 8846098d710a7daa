"""Sending CoT events to TAK devices and servers.

    udp://239.2.3.1:6969   the TAK SA multicast group (ATAK, iTAK and WinTAK listen on it), TTL 1 by default
    udp://HOST:PORT        one device or a server's UDP input
    tcp://HOST:8087        a TAK server's plain streaming input (TAK Server, FreeTAKServer)
    tls://HOST:8089        its TLS input, with the client certificate and key the server issued and its CA

The transports are PyTAK's (`pytak.protocol_factory`: the URL schemes, multicast TTL, TLS context from a PEM or
PKCS#12 client certificate, a CA file, hostname and verification switches); the TAK protocol's protobuf form
(version 1: "mesh" framing on UDP, "stream" framing on TCP/TLS) is takproto's `xml2proto`. On a stream, a TAK
ping (t-x-c-t) goes first and the events wait (at most `hello_wait_s`) for the server's first reply: TAK Server
answers the ping, FreeTAKServer greets a new client, and FreeTAKServer takes the first event of a connection as
the client's own presence (it drops it, and what arrives in the same read).

Every wait is bounded (`timeout_s` to connect, to hand each event to the network and to close): a destination
that cannot be reached is a `SendError` with one line, never a hang. UDP has no delivery receipt: a datagram
sent is not a datagram received.
"""

from __future__ import annotations

import asyncio
import configparser
import math
import socket
import ssl
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from urllib.parse import urlparse

from pipeline.errors import InputError, RidgelocError
from pipeline.tak import DEFAULT_URL
from pipeline.tak.cot import ping_event

__all__ = ["DEFAULT_URL", "Destination", "SendError", "SendOptions", "parse_destination", "send_events"]
DEFAULT_PORTS = {"udp": 6969, "tcp": 8087, "tls": 8089}
DEFAULT_TIMEOUT_S = 10.0
DEFAULT_HELLO_WAIT_S = 2.0


class SendError(RidgelocError):
    """The events could not be handed to a destination (unreachable, refused, timed out, TLS refused)."""


@dataclass(frozen=True)
class Destination:
    """A parsed destination URL: scheme (udp, tcp, tls), host, port."""

    url: str
    scheme: str
    host: str
    port: int

    @property
    def multicast(self) -> bool:
        import ipaddress

        try:
            return self.scheme == "udp" and ipaddress.ip_address(self.host).is_multicast
        except ValueError:
            return False

    @property
    def stream(self) -> bool:
        return self.scheme in ("tcp", "tls")


@dataclass(frozen=True)
class SendOptions:
    """How to send: multicast TTL (1-127, routers crossed + 1), TLS client certificate (PEM or .p12), its key
    and password, the server's CA (PEM), `insecure` (do not verify the server's certificate),
    `no_hostname_check`, `protobuf` (TAK protocol version 1 instead of XML), the bound on each wait (s) and the
    wait for a stream server's first reply (s)."""

    ttl: int = 1
    cert: str | None = None
    key: str | None = None
    ca: str | None = None
    password: str | None = None
    insecure: bool = False
    no_hostname_check: bool = False
    protobuf: bool = False
    timeout_s: float = DEFAULT_TIMEOUT_S
    hello_wait_s: float = DEFAULT_HELLO_WAIT_S


def parse_destination(url: str) -> Destination:
    """`url` as a Destination; InputError unless it is udp://, tcp:// or tls:// with a host (the port defaults
    to 6969, 8087 and 8089)."""
    usage = "udp://HOST:PORT (e.g. udp://239.2.3.1:6969, the TAK multicast group), tcp://HOST:8087 or tls://HOST:8089"
    p = urlparse(url or "")
    scheme = p.scheme.lower()
    if scheme not in DEFAULT_PORTS or not p.hostname or p.path not in ("", "/") or p.query:
        raise InputError(f"not a TAK destination: {url!r} (use {usage})")
    try:
        port = p.port or DEFAULT_PORTS[scheme]
    except ValueError:
        raise InputError(f"not a TAK destination: {url!r}: the port must be a number 1-65535") from None
    return Destination(url, scheme, p.hostname, port)


def check_options(dest: Destination, options: SendOptions) -> None:
    """InputError for options that do not fit the destination or name missing files (before any connection)."""
    if not (isinstance(options.ttl, int) and 1 <= options.ttl <= 127):
        raise InputError(f"--ttl must be 1-127 (PyTAK sets it as a signed byte), got {options.ttl}")
    for name in ("timeout_s", "hello_wait_s"):
        v = getattr(options, name)
        if not (v >= 0 and math.isfinite(v)):
            raise InputError(f"{name} must be a finite number >= 0, got {v}")
    tls_given = [f for f in ("cert", "key", "ca", "password") if getattr(options, f)]
    if dest.scheme != "tls" and (tls_given or options.insecure or options.no_hostname_check):
        raise InputError(f"certificates and TLS switches are for tls:// destinations, not {dest.url}")
    if dest.scheme == "tls" and not options.cert:
        raise InputError(f"{dest.url}: give the client certificate the TAK server issued with --cert (PEM, with "
                         "--key, or a .p12 with --cert-password) and its CA with --ca")
    for f in ("cert", "key", "ca"):
        path = getattr(options, f)
        if path and not Path(path).is_file():
            raise InputError("file not found", path)


def _pytak_config(dest: Destination, options: SendOptions) -> configparser.SectionProxy:
    scheme = "udp+wo" if dest.scheme == "udp" else dest.scheme  # write-only: PyTAK would bind a reader on PORT
    host = f"[{dest.host}]" if ":" in dest.host else dest.host
    values = {"COT_URL": f"{scheme}://{host}:{dest.port}", "PYTAK_MULTICAST_TTL": str(options.ttl)}
    if dest.scheme == "tls":
        values.update({k: v for k, v in (
            ("PYTAK_TLS_CLIENT_CERT", options.cert), ("PYTAK_TLS_CLIENT_KEY", options.key or options.cert),
            ("PYTAK_TLS_CLIENT_CAFILE", options.ca), ("PYTAK_TLS_CLIENT_PASSWORD", options.password),
            ("PYTAK_TLS_DONT_VERIFY", "1" if options.insecure else None),
            ("PYTAK_TLS_DONT_CHECK_HOSTNAME", "1" if options.no_hostname_check or options.insecure else None))
            if v})
    parser = configparser.ConfigParser(interpolation=None)
    parser.optionxform = str  # PyTAK's keys are upper case
    parser["ridgeloc"] = values
    return parser["ridgeloc"]


def _import_pytak():
    with warnings.catch_warnings():  # PyTAK warns at import about aiohttp, which only its HTTP transports need
        warnings.simplefilter("ignore")
        import pytak
    return pytak


def encode(xml: bytes, dest: Destination, protobuf: bool) -> bytes:
    """The bytes of one event on the wire: the XML itself, or TAK protocol version 1 (takproto): mesh framing on
    UDP, stream framing on TCP/TLS."""
    if not protobuf:
        return xml
    import takproto

    version = takproto.TAKProtoVer.STREAM if dest.stream else takproto.TAKProtoVer.MESH
    return bytes(takproto.xml2proto(xml, version))


async def _bounded(aw, timeout_s: float, what: str):
    try:
        return await asyncio.wait_for(aw, timeout_s)
    except asyncio.TimeoutError:
        raise TimeoutError(f"no answer within {timeout_s:g} s while {what}") from None


async def _send(payloads: Sequence[bytes], dest: Destination, options: SendOptions) -> None:
    pytak = _import_pytak()
    with warnings.catch_warnings():  # PyTAK warns when TLS checks are switched off; the user asked for it
        warnings.simplefilter("ignore")
        reader, writer = await _bounded(pytak.protocol_factory(_pytak_config(dest, options)), options.timeout_s,
                                        "connecting")
    if not dest.stream:
        try:
            for data in payloads:
                await _bounded(writer.send(data), options.timeout_s, "sending")
        finally:
            writer.close()
        return
    try:
        writer.write(encode(ping_event(datetime.now(timezone.utc)), dest, options.protobuf))
        await _bounded(writer.drain(), options.timeout_s, "sending")
        if options.hello_wait_s > 0:
            try:
                await asyncio.wait_for(reader.read(65536), options.hello_wait_s)
            except asyncio.TimeoutError:
                pass  # a server (or a plain listener) that says nothing: go on
        for data in payloads:
            writer.write(data)
            await _bounded(writer.drain(), options.timeout_s, "sending")
    finally:
        writer.close()
        try:
            await asyncio.wait_for(writer.wait_closed(), options.timeout_s)
        except (asyncio.TimeoutError, OSError, ssl.SSLError):
            pass


def _reason(exc: BaseException) -> str:
    if isinstance(exc.__cause__, ssl.SSLCertVerificationError):  # PyTAK's SyntaxError names its own settings
        exc = exc.__cause__
    if isinstance(exc, ConnectionRefusedError):
        return "connection refused (is the server running, and is this its port?)"
    if isinstance(exc, socket.gaierror):
        return f"unknown host ({exc.strerror or exc})"
    if isinstance(exc, ssl.SSLCertVerificationError):
        return (f"the server's certificate was not accepted: {exc.verify_message or exc} (give the CA that signed it "
                "with --ca; --no-hostname-check if it was issued for another name)")
    if isinstance(exc, ValueError) and exc.__cause__ is not None:  # PyTAK: the certificate or key did not load
        return f"{str(exc).splitlines()[0]}: {str(exc.__cause__).splitlines()[0]}"
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def send_events(events: Sequence[bytes], url: str, options: SendOptions | None = None) -> Destination:
    """Send CoT events (XML bytes, one event each) to `url`; returns the parsed destination. InputError for a
    bad URL or options, SendError (one line) when the destination cannot be reached or refuses them."""
    options = options or SendOptions()
    dest = parse_destination(url)
    check_options(dest, options)
    payloads = [encode(e, dest, options.protobuf) for e in events]
    try:
        asyncio.run(_send(payloads, dest, options))
    except (OSError, ssl.SSLError, SyntaxError, ValueError, EOFError, ConnectionError) as exc:
        raise SendError(f"cannot send to {dest.url}: {_reason(exc)}") from None
    return dest
