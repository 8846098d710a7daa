"""`ridgeloc send` to a real TAK server: FreeTAKServer 2.2.1 (PyPI), started here on 127.0.0.1, relays the events
to another connected client, which reads them back with PyTAK's receiver and takproto.

FreeTAKServer lives in a virtualenv of its own (its pins, e.g. protobuf 3 and cryptography 36, clash with ours):
`.ci/run` installs it where it is missing, at $RIDGELOC_FTS_VENV (default ~/.cache/ridgeloc/freetakserver-2.2.1).
Without it the test is skipped, except in CI (CI set), where it fails. docs/outputs.md, "Tested against".
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from datetime import datetime, timedelta, timezone
from pathlib import Path

import pytest

from pipeline.report.cot import write_cot_outputs
from pipeline.tak.cot import cot_time
from support.synthetic import synthetic_group
from support.tak import free_port, parse_event, split_xml_stream

ROOT = Path(__file__).resolve().parents[1]
FTS_VENV = Path(os.environ.get("RIDGELOC_FTS_VENV", Path.home() / ".cache/ridgeloc/freetakserver-2.2.1"))
LAUNCHER = ROOT / "tests" / "support" / "fts_launch.py"
START_TIMEOUT_S = 180.0


def _fts_python() -> Path:
    python = FTS_VENV / "bin" / "python"
    ok = python.is_file() and subprocess.run([python, "-c", "import FreeTAKServer"], capture_output=True,
                                             timeout=120).returncode == 0
    if not ok:
        reason = f"FreeTAKServer is not installed in {FTS_VENV} (.ci/run installs it)"
        if os.environ.get("CI"):
            pytest.fail(reason)
        pytest.skip(reason)
    return python


@pytest.fixture(scope="module")
def fts(tmp_path_factory):
    """A running FreeTAKServer: (its TCP CoT port, its log file)."""
    python = _fts_python()
    folder = tmp_path_factory.mktemp("fts")
    ports = {k: free_port() for k in ("cot", "ssl_cot", "api", "dp", "ssl_dp", "fed", "rp_sub", "rp_pub",
                                      "rp_srv", "im_pull", "im_pub")}
    env = {**os.environ, "FTS_FIRST_START": "false", "FTS_PERSISTENCE_PATH": str(folder),
           "FTS_CONFIG_PATH": str(folder / "FTSConfig.yaml"), "FTS_DB_PATH": str(folder / "fts.db"),
           "FTS_LOGFILE_PATH": str(folder / "logs"), "FTS_DATAPACKAGE_PATH": str(folder / "dp"),
           "FTS_EXCHECK_PATH": str(folder / "excheck"), "FTS_EXCHECK_TEMPLATE_PATH": str(folder / "excheck/t"),
           "FTS_EXCHECK_CHECKLIST_PATH": str(folder / "excheck/c"), "FTS_CLIENT_PACKAGES_PATH": str(folder / "cp"),
           "FTS_CERTS_PATH": str(folder / "certs"), "FTS_COT_PORT": str(ports["cot"]),
           "FTS_SSLCOT_PORT": str(ports["ssl_cot"]), "FTS_API_PORT": str(ports["api"]),
           "FTS_FED_PORT": str(ports["fed"]), "FTS_API_ADDRESS": "127.0.0.1", "FTS_DP_ADDRESS": "127.0.0.1",
           "FTS_USER_ADDRESS": "127.0.0.1", "FTS_ROUTING_PROXY_SUBSCRIBE_PORT": str(ports["rp_sub"]),
           "FTS_ROUTING_PROXY_PUBLISHER_PORT": str(ports["rp_pub"]),
           "FTS_ROUTING_PROXY_SERVER_PORT": str(ports["rp_srv"]),
           "FTS_INTEGRATION_MANAGER_PULLER_PORT": str(ports["im_pull"]),
           "FTS_INTEGRATION_MANAGER_PUBLISHER_PORT": str(ports["im_pub"])}
    certs = folder / "certs"
    for sub in ("logs", "dp", "excheck/t", "excheck/c", "cp", "certs"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    env.update({"FTS_SERVER_KEYDIR": str(certs / "server.key"), "FTS_SERVER_PEMDIR": str(certs / "server.pem"),
                "FTS_TESTCLIENT_PEMDIR": str(certs / "server.pem"), "FTS_TESTCLIENT_KEYDIR": str(certs / "server.key"),
                "FTS_UNENCRYPTED_KEYDIR": str(certs / "server.key.unencrypted"),
                "FTS_SERVER_P12DIR": str(certs / "server.p12"), "FTS_CADIR": str(certs / "ca.pem"),
                "FTS_CAKEYDIR": str(certs / "ca.key"), "FTS_FEDERATION_CERTDIR": str(certs / "server.pem"),
                "FTS_FEDERATION_KEYDIR": str(certs / "server.key"), "FTS_CRLDIR": str(certs / "FTS_CRL.json")})
    args = ["-CoTIP", "127.0.0.1", "-CoTPort", ports["cot"], "-SSLCoTIP", "127.0.0.1", "-SSLCoTPort",
            ports["ssl_cot"], "-DataPackageIP", "127.0.0.1", "-DataPackagePort", ports["dp"], "-SSLDataPackageIP",
            "127.0.0.1", "-SSLDataPackagePort", ports["ssl_dp"], "-RestAPIIP", "127.0.0.1", "-RestAPIPort",
            ports["api"]]
    log = folder / "fts.log"
    with open(log, "wb") as out:
        proc = subprocess.Popen([python, LAUNCHER, folder, *map(str, args)], env=env, stdout=out,
                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        t_end = time.monotonic() + START_TIMEOUT_S
        while True:
            if proc.poll() is not None:
                pytest.fail(f"FreeTAKServer exited ({proc.returncode}): {log.read_text()[-2000:]}")
            try:
                socket.create_connection(("127.0.0.1", ports["cot"]), timeout=1).close()
                break
            except OSError:
                if time.monotonic() > t_end:
                    pytest.fail(f"FreeTAKServer did not listen within {START_TIMEOUT_S:.0f} s: "
                                f"{log.read_text()[-2000:]}")
                time.sleep(0.5)
        yield ports["cot"], log
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(15)


def _presence(uid: str, callsign: str) -> bytes:
    now = datetime.now(timezone.utc)
    return (f'<?xml version="1.0" encoding="UTF-8"?><event version="2.0" uid="{uid}" type="a-f-G-U-C" how="m-g" '
            f'time="{cot_time(now)}" start="{cot_time(now)}" stale="{cot_time(now + timedelta(minutes=5))}">'
            f'<point lat="34.3" lon="108.7" hae="400" ce="10" le="10"/><detail><contact callsign="{callsign}"/>'
            '</detail></event>').encode()


def _read_until(sock: socket.socket, done, timeout_s: float) -> bytes:
    data, t_end = b"", time.monotonic() + timeout_s
    sock.settimeout(0.5)
    while not done(data) and time.monotonic() < t_end:
        try:
            chunk = sock.recv(65536)
        except TimeoutError:
            continue
        if not chunk:
            break
        data += chunk
    return data


def test_freetakserver_relays_every_event_to_a_connected_device(fts, tmp_path):
    port, log = fts
    results = [synthetic_group(f"flight{i}", seed=i) for i in range(3)]
    entries = write_cot_outputs(tmp_path / "out", results)
    files = sorted((tmp_path / "out" / "cot").glob("*.cot"))
    assert len(files) == len(entries) == 3
    sent = {e.cotEvent.uid: e.cotEvent for e in (parse_event(f.read_bytes()) for f in files)}
    before = {f: f.read_bytes() for f in files}

    # a device (an ATAK stand-in) connects and announces itself; the server greets it
    device = socket.create_connection(("127.0.0.1", port), timeout=10)
    try:
        device.sendall(_presence("test-device", "device"))
        greeting = _read_until(device, lambda d: b"</event>" in d, 30)
        assert b"</event>" in greeting, f"FreeTAKServer did not greet the device: {log.read_text()[-2000:]}"

        r = subprocess.run([sys.executable, "-m", "pipeline", "send", str(tmp_path / "out"), "--to",
                            f"tcp://127.0.0.1:{port}", "--timeout", "20"], capture_output=True, text=True,
                           timeout=120, cwd=ROOT)
        assert r.returncode == 0, r.stderr
        assert f"sent 3 event(s) to tcp://127.0.0.1:{port}" in r.stdout

        data = _read_until(device, lambda d: all(uid.encode() in d for uid in sent), 60)
    finally:
        device.close()
    received = {}
    for xml in split_xml_stream(data):
        e = parse_event(xml).cotEvent
        if e.uid in sent:
            received[e.uid] = e
    assert set(received) == set(sent), f"relayed {sorted(received)} of {sorted(sent)}: {log.read_text()[-1500:]}"
    for uid, e in received.items():
        s = sent[uid]
        assert (e.type, e.how) == (s.type, s.how) == ("a-u-G", "m-f")
        assert (e.lat, e.lon, e.hae, e.ce, e.le) == pytest.approx((s.lat, s.lon, s.hae, s.ce, s.le), abs=1e-9)
        assert e.detail.contact.callsign == s.detail.contact.callsign
    assert {f: f.read_bytes() for f in files} == before
