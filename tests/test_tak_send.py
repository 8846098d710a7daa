"""`ridgeloc send OUT --to URL` to loopback listeners that read what arrives with TAK libraries ridgeloc did not
write (PyTAK's receiver splits a stream, takproto parses XML and protobuf): UDP, TCP, TLS with a client
certificate, protobuf; and what happens when the destination cannot be reached (one line, a non-zero exit
within the bound, the files untouched)."""

from __future__ import annotations

import hashlib
import ssl
import sys
import time
from pathlib import Path

import pytest

from pipeline.cli import main as cli_main
from pipeline.report.cot import write_cot_outputs
from pipeline.tak.send import SendOptions, parse_destination
from support.synthetic import synthetic_group
from support.tak import (
    TcpListener,
    UdpListener,
    atak_import,
    make_certificates,
    parse_event,
    split_proto_stream,
    split_xml_stream,
)


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    """A run folder with three events in cot/."""
    folder = tmp_path_factory.mktemp("send") / "out"
    write_cot_outputs(folder, [synthetic_group(f"flight{i}", seed=i) for i in range(3)])
    return folder


def _files(out: Path) -> dict:
    return {f.name: hashlib.sha256(f.read_bytes()).hexdigest() for f in sorted(out.rglob("*")) if f.is_file()}


def _written(out: Path) -> dict:
    """uid -> CotEvent of the files."""
    return {e.uid: e for e in (parse_event(f.read_bytes()).cotEvent for f in (out / "cot").glob("*.cot"))}


def _same_targets(got: dict, out: Path) -> None:
    written = _written(out)
    assert set(got) == set(written)
    for uid, e in got.items():
        w = written[uid]
        assert (e.type, e.how, e.detail.contact.callsign) == (w.type, w.how, w.detail.contact.callsign)
        assert (e.lat, e.lon, e.hae, e.ce, e.le) == (w.lat, w.lon, w.hae, w.ce, w.le)
        assert e.startTime > w.startTime  # re-stamped when sent
        assert e.staleTime - e.startTime == w.staleTime - w.startTime  # for the validity written


def test_udp_delivers_every_event(out, capsys):
    with UdpListener() as listener:
        assert cli_main(["send", str(out), "--to", f"udp://127.0.0.1:{listener.port}"]) == 0
        received = listener.wait_for(3)
    _same_targets({e.uid: e for e in (parse_event(d).cotEvent for d in received)}, out)
    assert capsys.readouterr().out.strip() == f"sent 3 event(s) to udp://127.0.0.1:{listener.port} (UDP, XML)"


def test_tcp_delivers_every_event_after_a_tak_ping(out):
    before = _files(out)
    with TcpListener() as listener:
        assert cli_main(["send", str(out / "cot"), "--to", f"tcp://127.0.0.1:{listener.port}"]) == 0
        (stream,) = listener.wait_for(1)
    events = [parse_event(x).cotEvent for x in split_xml_stream(stream)]
    assert events[0].type == "t-x-c-t"  # TAK's ping first: a server answers it, no device shows it
    _same_targets({e.uid: e for e in events[1:]}, out)
    assert _files(out) == before


def test_protobuf_on_udp_and_tcp(out):
    with UdpListener() as udp, TcpListener() as tcp:
        assert cli_main(["send", str(out), "--protobuf", "--to", f"udp://127.0.0.1:{udp.port}"]) == 0
        assert cli_main(["send", str(out), "--protobuf", "--to", f"tcp://127.0.0.1:{tcp.port}"]) == 0
        datagrams = udp.wait_for(3)
        (stream,) = tcp.wait_for(1)
    assert all(d[:3] == b"\xbf\x01\xbf" for d in datagrams)  # TAK protocol v1, mesh framing
    _same_targets({e.uid: e for e in (parse_event(d).cotEvent for d in datagrams)}, out)
    messages = split_proto_stream(stream)  # stream framing: 0xbf, length, message
    assert messages[0].cotEvent.type == "t-x-c-t"
    _same_targets({m.cotEvent.uid: m.cotEvent for m in messages[1:]}, out)


def test_tls_with_a_client_certificate_the_server_requires(out, tmp_path):
    certs = make_certificates(tmp_path)
    server = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    server.load_cert_chain(certs["server_cert"], certs["server_key"])
    server.load_verify_locations(certs["ca_cert"])
    server.verify_mode = ssl.CERT_REQUIRED  # as a TAK server's 8089: no client certificate, no connection
    with TcpListener(ssl_context=server) as listener:
        url = f"tls://127.0.0.1:{listener.port}"
        assert cli_main(["send", str(out), "--to", url, "--cert", str(certs["client_cert"]), "--key",
                         str(certs["client_key"]), "--ca", str(certs["ca_cert"])]) == 0
        (stream,) = listener.wait_for(1)
    _same_targets({e.uid: e for e in (parse_event(x).cotEvent for x in split_xml_stream(stream)[1:])}, out)


def test_tls_with_a_pkcs12_client_certificate(out, tmp_path):
    certs = make_certificates(tmp_path)
    server = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    server.load_cert_chain(certs["server_cert"], certs["server_key"])
    server.load_verify_locations(certs["ca_cert"])
    server.verify_mode = ssl.CERT_REQUIRED
    with TcpListener(ssl_context=server) as listener:
        assert cli_main(["send", str(out), "--to", f"tls://127.0.0.1:{listener.port}", "--cert",
                         str(certs["client_p12"]), "--cert-password", "atakatak", "--ca", str(certs["ca_cert"])]) == 0
        (stream,) = listener.wait_for(1)
    _same_targets({e.uid: e for e in (parse_event(x).cotEvent for x in split_xml_stream(stream)[1:])}, out)


def test_tls_refuses_a_server_its_ca_did_not_sign(out, tmp_path, capsys):
    certs = make_certificates(tmp_path)
    (tmp_path / "other").mkdir()
    other = make_certificates(tmp_path / "other")  # another CA's server
    server = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    server.load_cert_chain(other["server_cert"], other["server_key"])
    with TcpListener(ssl_context=server) as listener:
        code = cli_main(["send", str(out), "--to", f"tls://127.0.0.1:{listener.port}", "--cert",
                         str(certs["client_cert"]), "--key", str(certs["client_key"]), "--ca", str(certs["ca_cert"])])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1 and "certificate" in err[0], err


def test_an_unreachable_server_is_one_line_and_a_non_zero_exit(out, capsys):
    before = _files(out)
    with TcpListener() as listener:
        port = listener.port  # closed when the block ends: nothing listens there afterwards
    t0 = time.monotonic()
    assert cli_main(["send", str(out), "--to", f"tcp://127.0.0.1:{port}", "--timeout", "3"]) == 1
    assert time.monotonic() - t0 < 3
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"ridgeloc: error: cannot send to tcp://127.0.0.1:{port}: connection refused (is the server "
                   "running, and is this its port?) (the files on disk are unchanged)"]
    assert _files(out) == before


def test_a_server_that_never_answers_is_given_up_after_the_timeout(out, capsys, tmp_path):
    certs = make_certificates(tmp_path)
    with TcpListener(handshake=False) as listener:  # accepts the connection, never starts TLS
        t0 = time.monotonic()
        code = cli_main(["send", str(out), "--to", f"tls://127.0.0.1:{listener.port}", "--timeout", "2",
                         "--cert", str(certs["client_cert"]), "--key", str(certs["client_key"]), "--insecure"])
        elapsed = time.monotonic() - t0
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and 2 <= elapsed < 8, elapsed
    assert len(err) == 1 and "no answer within 2 s while connecting" in err[0], err


@pytest.mark.parametrize("argv, message", [
    (["--to", "http://example.org"], "not a TAK destination"),
    (["--to", "udp://"], "not a TAK destination"),
    (["--to", "tcp://127.0.0.1:99999"], "the port must be a number"),
    (["--to", "tls://127.0.0.1:8089"], "give the client certificate"),
    (["--to", "udp://127.0.0.1:9", "--cert", "c.pem"], "are for tls:// destinations"),
    (["--to", "tls://127.0.0.1:8089", "--cert", "missing.pem"], "missing.pem: file not found"),
    (["--to", "udp://239.2.3.1:6969", "--ttl", "300"], "--ttl must be 1-127"),
])
def test_bad_destinations_and_options_are_refused_before_sending(out, argv, message, capsys):
    assert cli_main(["send", str(out), *argv]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_a_folder_without_events_is_refused(tmp_path, capsys):
    assert cli_main(["send", str(tmp_path), "--to", "udp://127.0.0.1:9"]) == 1
    assert "no Cursor on Target events here" in capsys.readouterr().err


def test_the_default_destination_is_the_tak_multicast_group():
    d = parse_destination("udp://239.2.3.1:6969")
    assert d.multicast and not d.stream and (d.host, d.port) == ("239.2.3.1", 6969)
    assert parse_destination("tcp://tak.example.org").port == 8087
    assert parse_destination("tls://[::1]").port == 8089 and not parse_destination("udp://10.0.0.5:4242").multicast
    assert SendOptions().ttl == 1


def test_send_is_a_command_of_the_cli():
    import subprocess

    r = subprocess.run([sys.executable, "-m", "pipeline", "send", "--help"], capture_output=True, text=True,
                       cwd=Path(__file__).resolve().parents[1])
    assert r.returncode == 0 and "239.2.3.1:6969" in r.stdout


def test_locate_writes_its_target_for_tak_and_sends_it(tmp_path):
    photos = Path(__file__).resolve().parents[1] / "sample_data" / "photos" / "h20_laser"
    with UdpListener() as listener:
        assert cli_main(["locate", str(photos), "-o", str(tmp_path / "out"), "--send",
                         f"udp://127.0.0.1:{listener.port}", "--cot-type", "a-h-G"]) == 0
        assert cli_main(["locate", str(photos), "--name", "spot", "--send", f"udp://127.0.0.1:{listener.port}"]) == 0
        received = listener.wait_for(2)
    (written,) = (tmp_path / "out" / "cot").glob("*.cot")
    e = parse_event(written.read_bytes()).cotEvent
    assert (written.name, e.detail.contact.callsign, e.type) == ("h20_laser.cot", "h20_laser", "a-h-G")
    got = [parse_event(d).cotEvent for d in received]
    assert [g.detail.contact.callsign for g in got] == ["h20_laser", "spot"]  # without -o: sent, nothing written
    assert got[0].uid == e.uid and got[1].uid != e.uid
    assert set(atak_import((tmp_path / "out" / "targets.zip").read_bytes())["events"]) == {e.uid}


def test_locate_refuses_a_name_the_tak_events_take_before_any_work(tmp_path, capsys):
    assert cli_main(["locate", str(tmp_path / "no-such-photo.jpg"), "--name", "cot", "-o", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["ridgeloc: error: the name 'cot' is taken by the run's TAK events (OUTDIR/cot/, targets.zip): "
                   "give the flight another name"]
