"""`ridgeloc send OUT --to URL`: send a finished run's targets (OUT/cot/*.cot) to TAK devices or a TAK server.

`run` and `locate` take the same options, with `--send URL`, to send when they finish (`add_tak_arguments`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pipeline.errors import InputError

HELP = "send a finished run's targets (Cursor on Target events) to TAK devices (multicast, UDP) or a TAK server"


def add_tak_arguments(parser: argparse.ArgumentParser, send_flag: bool = True) -> None:
    """The CoT and sending options. `send_flag` adds `--send URL` (run, locate) and the options that set how the
    events are written; without it, `--to URL` (send)."""
    from pipeline.tak import DEFAULT_TYPE, DEFAULT_URL

    g = parser.add_argument_group("TAK (docs/outputs.md, \"For TAK users\")")
    if send_flag:
        g.add_argument("--send", metavar="URL", default=None,
                       help=f"when finished, send the located targets to URL: {DEFAULT_URL} (the TAK multicast "
                            "group), udp://HOST:PORT, tcp://HOST:8087 or tls://HOST:8089")
    else:
        g.add_argument("--to", metavar="URL", default=DEFAULT_URL,
                       help=f"where to send: {DEFAULT_URL} (default: the TAK multicast group, which ATAK, iTAK and "
                            "WinTAK listen on), udp://HOST:PORT, tcp://HOST:8087 or tls://HOST:8089")
    g.add_argument("--cot-type", default=None, metavar="TYPE",
                   help="the events' CoT type (default " + (f"{DEFAULT_TYPE}: unknown affiliation, ground" if send_flag
                                                             else "as written") +
                        "; e.g. a-h-G hostile, a-n-G neutral, a-f-G friendly)")
    g.add_argument("--cot-stale", default=None, metavar="DURATION",
                   help="how long a marker stays valid after it is " + ("written" if send_flag else "sent")
                        + ": seconds, or 30m, 24h, 7d (default " + ("24h" if send_flag else "as written") + ")")
    g.add_argument("--ttl", type=int, default=1, help="multicast time to live: routers crossed + 1 (default 1)")
    g.add_argument("--cert", metavar="FILE", help="tls://: the client certificate the TAK server issued (PEM, or "
                                                  ".p12 with --cert-password)")
    g.add_argument("--key", metavar="FILE", help="tls://: the client certificate's private key (PEM)")
    g.add_argument("--cert-password", metavar="PASSWORD", help="tls://: the password of the .p12 or the key")
    g.add_argument("--ca", metavar="FILE", help="tls://: the CA that signed the server's certificate (PEM)")
    g.add_argument("--no-hostname-check", action="store_true",
                   help="tls://: accept a server certificate issued for another name (e.g. when connecting by IP)")
    g.add_argument("--insecure", action="store_true", help="tls://: do not verify the server's certificate")
    g.add_argument("--protobuf", action="store_true",
                   help="send TAK protocol version 1 (protobuf) instead of XML (docs/outputs.md says when)")
    g.add_argument("--timeout", type=float, default=10.0, metavar="S",
                   help="give up on a destination that does not answer within S seconds (default 10)")


def cot_options(args):
    """The CotOptions of `args` (run, locate): type and stale time, checked."""
    from pipeline.report.cot import CotOptions
    from pipeline.tak.cot import DEFAULT_STALE_S, DEFAULT_TYPE, check_type, parse_duration_s

    return CotOptions(check_type(args.cot_type or DEFAULT_TYPE),
                      DEFAULT_STALE_S if args.cot_stale is None else parse_duration_s(args.cot_stale))


def send_options(args):
    """The SendOptions of `args`."""
    from pipeline.tak.send import SendOptions

    return SendOptions(ttl=args.ttl, cert=args.cert, key=args.key, ca=args.ca, password=args.cert_password,
                       insecure=args.insecure, no_hostname_check=args.no_hostname_check, protobuf=args.protobuf,
                       timeout_s=args.timeout)


def check_send_args(args, url: str | None) -> None:
    """Refuse a bad URL or options before any work (InputError)."""
    from pipeline.tak.send import check_options, parse_destination

    if url is not None:
        check_options(parse_destination(url), send_options(args))
    elif any((args.cert, args.key, args.ca, args.cert_password, args.insecure, args.no_hostname_check,
              args.protobuf)):
        raise InputError("the certificate, --insecure and --protobuf options are for sending: give --send URL")


def event_files(path: Path) -> list[Path]:
    """The .cot files to send from `path`: a run folder (its cot/), a folder of .cot files, or one .cot file."""
    if path.is_file():
        return [path]
    if not path.is_dir():
        raise InputError("no such run folder or .cot file", path)
    folder = path / "cot" if (path / "cot").is_dir() else path
    files = sorted(folder.glob("*.cot"))
    if not files:
        raise InputError("no Cursor on Target events here (a run folder holds them in cot/: run `ridgeloc run -o "
                         "OUT` first; a run without located targets has none)", folder)
    return files


def load_events(files: list[Path], cot_type: str | None, stale: str | None) -> list[bytes]:
    """The events of `files`, re-stamped valid from now (time = start = now, stale = now + `stale`, default the
    validity they were written with) and, when given, of `cot_type`."""
    from datetime import datetime, timezone

    from pipeline.tak.cot import check_type, parse_duration_s, read_event_file, restamp, to_bytes

    stale_s = None if stale is None else parse_duration_s(stale)
    cot_type = None if cot_type is None else check_type(cot_type)
    now = datetime.now(timezone.utc)
    events = []
    for f in files:
        event = restamp(read_event_file(f), now, stale_s)
        if cot_type is not None:
            event.set("type", cot_type)
        events.append(to_bytes(event))
    return events


def send_files(files: list[Path], url: str, args, cot_type: str | None = None, stale: str | None = None) -> int:
    """Send the events of `files` (see `load_events`) to `url`; prints one line; returns the exit code (0 sent,
    1 not)."""
    return send_events_to(load_events(files, cot_type, stale), url, args)


def send_events_to(events: list[bytes], url: str, args) -> int:
    """Send `events` (XML) to `url` with the options of `args`; prints one line; returns the exit code (0 sent,
    1 not: the files on disk are never touched)."""
    from pipeline.tak.send import SendError, send_events

    if not events:
        print(f"ridgeloc: nothing to send to {url}: no target was located", file=sys.stderr)
        return 0
    try:
        dest = send_events(events, url, send_options(args))
    except SendError as exc:
        print(f"ridgeloc: error: {exc} (the files on disk are unchanged)", file=sys.stderr)
        return 1
    how = "protobuf" if args.protobuf else "XML"
    print(f"sent {len(events)} event(s) to {dest.url} ({dest.scheme.upper()}, {how})"
          + (f", multicast TTL {args.ttl}" if dest.multicast else ""))
    return 0


def send_run_outputs(outdir, args) -> int:
    """`--send URL` of run and locate: the run's fresh events (as written) to the URL; 0 when there is nothing
    located to send (the run's own exit code says so)."""
    return send_files(sorted((Path(outdir) / "cot").glob("*.cot")), args.send, args)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("outdir", metavar="OUT", help="a run folder (ridgeloc run/locate -o OUT: its cot/*.cot), a "
                                                      "folder of .cot files or one .cot file")
    add_tak_arguments(parser, send_flag=False)


def main(args) -> int:
    from pipeline.tak.cot import check_type, parse_duration_s

    if args.cot_stale is not None:  # a bad option is refused before anything is read
        parse_duration_s(args.cot_stale)
    if args.cot_type is not None:
        check_type(args.cot_type)
    check_send_args(args, args.to)
    return send_files(event_files(Path(args.outdir)), args.to, args, args.cot_type, args.cot_stale)
