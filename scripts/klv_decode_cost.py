"""What one MISB ST 0601 packet costs to decode: ridgeloc's `klv.decode_checked` (numpy checksum, then stanag4609's
`decode_uas_local_set` and the columns) against calling the library directly, on the same packets in one process
(docs/ingest.md, "MISB ST 0601 KLV").

    python scripts/klv_decode_cost.py [--packets 1000] [--rounds 5]

The packets are the synth FMV writer's (`pipeline.synth.writers.fmv.klv_packets`, as scripts/bench_ingest.py's
klv kind). The two sides alternate round by round, each decoding every packet once per round; printed: each
side's median, min and max over the rounds in ms a packet, and the median of the per-round ratio ours / library.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

from bench_ingest import gen_klv  # noqa: E402  (the bench's generator: the same packets as its klv kind)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--packets", type=int, default=1000)
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    import tempfile

    from stanag4609 import st0601

    from pipeline.ingest.klv import ST0601_KEY, decode_checked, scan_packets

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "packets.klv"
        gen_klv(path, args.packets)
        data = path.read_bytes()
    packets = scan_packets(data, ST0601_KEY, decode=lambda p: p)[0]  # the packets' bytes, undecoded
    assert len(packets) == args.packets and len(scan_packets(data)[0]) == args.packets

    def ours() -> None:
        for p in packets:
            decode_checked(p)

    def library() -> None:
        for p in packets:
            st0601.decode_uas_local_set(p, verify_checksum=True, require_version=False,
                                        field_decoding=st0601.FieldDecodingMode.PRESERVE)

    ours()  # imports and first-call costs out of the timing
    times: dict[str, list[float]] = {"ours (decode_checked)": [], "stanag4609 decode_uas_local_set": []}
    for _ in range(args.rounds):
        for name, fn in zip(times, (ours, library), strict=True):
            t0 = time.perf_counter()
            fn()
            times[name].append((time.perf_counter() - t0) / len(packets) * 1e3)
    for name, ms in times.items():
        print(f"{name:34s} median {statistics.median(ms):.3f} ms a packet (min {min(ms):.3f}, max {max(ms):.3f}; "
              f"{args.rounds} rounds of {len(packets)} packets)")
    ratio = statistics.median(a / b for a, b in zip(*times.values(), strict=True))
    print(f"ours / library, median of the rounds: {ratio:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
