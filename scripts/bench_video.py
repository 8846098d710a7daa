#!/usr/bin/env python
"""4K full-motion video at scale: generate a synthetic 3840x2160 30 fps H.264 + MISB ST 0601 KLV flight, then
time indexing against a bare PyAV demux, and the whole `ridgeloc run` on it, with its peak memory.

    nice -n 10 python scripts/bench_video.py --seconds 600          # the 10-minute flight of issue 13
    python scripts/bench_video.py --seconds 20 --workdir /tmp/bv     # a short one while developing

The flight: an arc 2 km above and 5 km from the target at 35 m/s, the camera (hfov 10 deg, 1-second GOP) kept on
the target with a slow pointing wander, one laser shot per second (range noise 1 m) in KLV tag 21, one KLV Local
Set per frame. Frames are a pre-rendered 4096 px ground texture (0.35 m/px, the synth's, grey) warped by each
frame's ground-plane homography, so generation costs one warp and one libx264 (ultrafast) encode per frame.
The flight config names only the .ts, with the target mark (the true pixel in the first observation frame) and
the true target for the error column.

Measures, in this one run: the imports every run loads before its first frame, bare demux (PyAV packets of every
stream, nothing kept), a bare PyAV decode of every frame (`for f in av.open(ts).decode(video=0)`, PyAV's default
threading: what the run is judged against), the decode floor of the answer (our reader, `VideoFrames.prefetch`,
decoding the observation frames and nothing else: each from the key frame before it), our index
(`pipeline.ingest.video.demux_index`, frames only) and our full ingest (`read_flight`: index + KLV decode), each in
a fresh subprocess; then `ridgeloc run FLIGHT.yaml` in a subprocess: wall time and peak RSS (that child's own, from
wait4), the run's stage times, the answer's errors and the tracked pixels' distance from the true target pixel.
Prints the ratios run / bare decode and run / the flight's length, the floor no run goes below (imports + ingest +
decode floor) against the bare decode, and the load average before and after; writes a JSON summary into the work
folder.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from fractions import Fraction
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

W, H, FPS = 3840, 2160, 30
HFOV_DEG = 10.0
TARGET_LLA = (34.30, 108.90, 420.0)
TEX_PX, TEX_RES_M = 4096, 0.35


def _look_at(cam_enu: np.ndarray) -> np.ndarray:
    """(n, 3, 3) R_enu_from_optical of cameras at cam_enu (n, 3) looking at the origin (no roll)."""
    z = -cam_enu / np.linalg.norm(cam_enu, axis=1, keepdims=True)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=-1)


def flight(seconds: float, seed: int = 4):
    """Frame times and true states: t_ns (n,), camera ENU (n, 3), R_enu_from_optical (n, 3, 3), velocity (n, 3)."""
    from scipy.spatial.transform import Rotation

    n = round(seconds * FPS)
    t_s = np.arange(n) / FPS
    height, slant, speed = 2000.0, 5000.0, 35.0
    radius = math.sqrt(slant ** 2 - height ** 2)
    az = math.radians(200.0) + speed * t_s / radius
    cam = np.column_stack([radius * np.sin(az), radius * np.cos(az), np.full(n, height)])
    vel = np.column_stack([speed * np.cos(az), -speed * np.sin(az), np.zeros(n)])
    R = _look_at(cam)
    # the gimbal's pointing wanders slowly about the target (a few pixels), as a tracking loop does
    rng = np.random.default_rng(seed)
    k = np.arange(n) / FPS
    wander = np.column_stack([np.sin(0.21 * k + rng.random() * 6) * 1.5e-4,
                              np.sin(0.17 * k + rng.random() * 6) * 1.5e-4, np.zeros(n)])
    R = R @ Rotation.from_rotvec(wander).as_matrix()
    t_ns = 1_715_000_000_000_000_000 + np.round(t_s * 1e9).astype(np.int64)
    return t_ns, cam, R, vel


def _K() -> np.ndarray:
    f = W / (2 * math.tan(math.radians(HFOV_DEG) / 2))
    return np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1.0]])


def _texture() -> np.ndarray:
    import cv2

    from pipeline.synth.render import TARGET_PATTERN_PX, ground_texture, target_pattern

    tex = cv2.cvtColor(ground_texture(7, TEX_PX, TEX_RES_M), cv2.COLOR_BGR2GRAY)
    size_px = round(36.0 / TEX_RES_M)  # a 36 m target at the texture's centre
    pat = cv2.resize(target_pattern(TARGET_PATTERN_PX), (size_px, size_px), interpolation=cv2.INTER_AREA)
    a = pat[..., 3:4]
    grey = cv2.cvtColor(pat[..., :3].astype(np.float32), cv2.COLOR_BGR2GRAY)[..., None]
    c0 = TEX_PX // 2 - size_px // 2
    roi = tex[c0:c0 + size_px, c0:c0 + size_px, None].astype(np.float32)
    tex[c0:c0 + size_px, c0:c0 + size_px] = np.clip(roi * (1 - a) + grey * a, 0, 255)[..., 0].astype(np.uint8)
    return tex


def _homography(K, R_enu_from_optical, cam) -> np.ndarray:
    """Image <- texture pixel homography of one frame (ground plane z = 0, texture row 0 north)."""
    Rco = R_enu_from_optical.T
    t = -Rco @ cam
    A = np.array([[TEX_RES_M, 0, -(TEX_PX / 2 - 0.5) * TEX_RES_M],
                  [0, -TEX_RES_M, (TEX_PX / 2 - 0.5) * TEX_RES_M], [0, 0, 1.0]])  # texture px -> E, N, 1
    return K @ np.column_stack([Rco[:, 0], Rco[:, 1], t]) @ A


def klv_values(t_ns, cam, R_enu_from_optical, vel, laser: dict[int, float]) -> list[dict]:
    from scipy.spatial.transform import Rotation

    from pipeline.geometry.frames import R_enu0_from_ned_at, lla_from_enu
    from pipeline.geometry.pose import R_OPTICAL_FROM_GIMBAL_DEFAULT

    lla = lla_from_enu(cam, TARGET_LLA)
    R_enu0_from_ned = R_enu0_from_ned_at(lla[:, 0], lla[:, 1], TARGET_LLA)
    heading = np.degrees(np.arctan2(vel[:, 0], vel[:, 1])) % 360.0  # ENU velocity: atan2(E, N)
    R_ned_from_body = Rotation.from_euler("Z", np.radians(heading)[:, None])
    R_ned_from_gimbal = np.swapaxes(R_enu0_from_ned, -1, -2) @ R_enu_from_optical @ R_OPTICAL_FROM_GIMBAL_DEFAULT
    aer = (R_ned_from_body.inv() * Rotation.from_matrix(R_ned_from_gimbal)).as_euler("ZYX", degrees=True)
    out = []
    for i, t in enumerate(t_ns.tolist()):
        v = {2: t // 1000, 65: 19, 5: float(heading[i]), 6: 0.0, 7: 0.0, 13: float(lla[i, 0]), 14: float(lla[i, 1]),
             75: float(lla[i, 2]), 16: HFOV_DEG, 17: float(np.degrees(2 * np.arctan(H / W * np.tan(np.radians(
                 HFOV_DEG / 2))))), 18: float(aer[i, 0] % 360), 19: float(aer[i, 1]), 20: float(aer[i, 2] % 360)}
        if t in laser:
            v[21] = laser[t]
        out.append(v)
    return out


def generate(folder: Path, seconds: float) -> Path:
    import av
    import cv2
    from stanag4609 import st0601

    folder.mkdir(parents=True, exist_ok=True)
    ts = folder / "flight.ts"
    t_ns, cam, R, vel = flight(seconds)
    n = len(t_ns)
    rng = np.random.default_rng(11)
    shots = np.arange(15, n, FPS)  # one laser shot per second, mid-GOP
    laser = {int(t_ns[i]): float(np.linalg.norm(cam[i]) + rng.normal(0, 1.0)) for i in shots}
    values = klv_values(t_ns, cam, R, vel, laser)
    K = _K()
    tex = _texture()
    t0 = time.perf_counter()
    tb = Fraction(1, 90000)
    with av.open(str(ts), "w", format="mpegts") as out:
        vs = out.add_stream("libx264", rate=FPS)
        vs.width, vs.height, vs.pix_fmt = W, H, "yuv420p"
        vs.codec_context.time_base = vs.time_base = tb
        vs.options = {"preset": "ultrafast", "crf": "28", "g": str(FPS)}
        ds = out.add_data_stream(codec_name="klv")
        for i in range(n):
            img = cv2.warpPerspective(tex, _homography(K, R[i], cam[i]), (W, H), flags=cv2.INTER_LINEAR,
                                      borderMode=cv2.BORDER_REFLECT)
            pts = round(Fraction(int(t_ns[i] - t_ns[0]), 10**9) / tb)
            pkt = av.Packet(st0601.encode_uas_local_set(values[i]))
            pkt.stream, pkt.pts, pkt.dts, pkt.time_base = ds, pts, pts, tb
            out.mux(pkt)
            frame = av.VideoFrame.from_ndarray(img, format="gray")
            frame.pts, frame.time_base = pts, tb
            out.mux(vs.encode(frame))
            if i % (10 * FPS) == 0:
                print(f"  frame {i}/{n}, {time.perf_counter() - t0:.0f} s", flush=True)
        out.mux(vs.encode(None))
    gen_s = time.perf_counter() - t0
    # the mark: the true target pixel in the first observation frame
    i0 = int(shots[0])
    x = K @ (R[i0].T @ (-cam[i0]))
    mark = [round(float(x[0] / x[2]), 2), round(float(x[1] / x[2]), 2)]
    cfg = {"name": f"bench4k_{int(seconds)}s", "files": {"telemetry": [ts.name]},
           "target": {"frame_index": i0, "pixel": mark},
           "truth": {"lat_deg": TARGET_LLA[0], "lon_deg": TARGET_LLA[1], "alt_m": TARGET_LLA[2]},
           "sigma": {"pixel_px": 0.5, "range_m": 1.0, "position_m": 0.5, "attitude_deg": 0.05}}
    import yaml

    (folder / "flight.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    (folder / "generate.json").write_text(json.dumps({"seconds": seconds, "frames": n, "generate_s": gen_s,
                                                      "bytes": ts.stat().st_size}))
    print(f"generated {n} frames, {ts.stat().st_size / 1e6:.0f} MB in {gen_s:.0f} s", flush=True)
    return folder / "flight.yaml"


# Each child imports first, then times its work alone (wall and CPU seconds), and prints them as JSON.
_TIMER = "import json,sys,time\n_t0,_c0=time.perf_counter(),time.process_time()\n{work}\n" \
         "print(json.dumps([time.perf_counter()-_t0,time.process_time()-_c0]))"
def loop(folder: Path, times: int) -> Path:
    """A longer flight from the generated one: its packets copied `times` times (no re-encoding) with the video
    and KLV timestamps shifted by the loop's span and each KLV packet's tag 2 re-stamped (stanag4609
    update_uas_local_set, checksum recomputed). The video content and the flight path repeat; sizes, frame count,
    GOP structure and per-frame KLV are those of a `times`-times longer recording."""
    import av
    import yaml
    from stanag4609 import st0601

    src = folder / "flight.ts"
    dst = folder / f"flight_x{times}.ts"
    gen = json.loads((folder / "generate.json").read_text())
    span_ticks = gen["frames"] * (90000 // FPS)
    span_us = gen["frames"] * 1_000_000 // FPS
    with av.open(str(dst), "w", format="mpegts") as out:
        vs = ds = None
        for k in range(times):
            with av.open(str(src)) as inp:
                if vs is None:
                    vs = out.add_stream_from_template(inp.streams.video[0])
                    ds = out.add_data_stream(codec_name="klv")
                for pkt in inp.demux():
                    if pkt.size == 0:
                        continue
                    if pkt.stream.type == "video":
                        pkt.stream = vs
                        pkt.pts += k * span_ticks
                        pkt.dts += k * span_ticks
                        out.mux(pkt)
                    else:
                        ls = st0601.decode_uas_local_set(bytes(pkt))
                        new = av.Packet(st0601.update_uas_local_set(
                            ls, {2: ls.misp_timestamp_microseconds + k * span_us}))
                        new.stream, new.time_base = ds, pkt.time_base
                        new.pts = new.dts = pkt.pts + k * span_ticks
                        out.mux(new)
    cfg = yaml.safe_load((folder / "flight.yaml").read_text())
    cfg["name"] = f"{cfg['name']}_x{times}"
    cfg["files"]["telemetry"] = [dst.name]
    path = folder / f"flight_x{times}.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


# what every run imports before its first frame (the interpreter's own start is not counted)
RUN_IMPORTS = ("pipeline.commands.run", "pipeline.run", "pipeline.report.outputs", "pipeline.report.html",
               "pipeline.report.figures", "pipeline.report.cot", "stanag4609.st0601", "folium", "cv2", "av")

CHILD = {
    "imports (modules a run loads)": ("", "\n".join(f"import {m}" for m in RUN_IMPORTS)),
    "bare demux": ("import av", "c=av.open(sys.argv[1])\nfor p in c.demux():\n    pass"),
    "bare decode (every frame)": ("import av", "c=av.open(sys.argv[1])\nfor f in c.decode(video=0):\n    pass"),
    "decode floor (observation frames)": (
        "from pipeline.ingest.video import VideoFrames",
        "v=VideoFrames(sys.argv[1], gray=True)\nw=[int(i) for i in sys.argv[2].split(',')]\nv.prefetch(w)\n"
        "for i in w:\n    v[i]\nv.close()"),
    "index": ("from pipeline.ingest.video import demux_index", "demux_index(sys.argv[1])"),
    "ingest (index + KLV)": ("from pipeline.ingest import read_flight\nimport stanag4609.st0601",
                             "read_flight([sys.argv[1]])"),
}


def _spawn(cmd: list[str]) -> tuple[str, float, float]:
    """Run cmd: (its stdout, its own CPU s and peak RSS MiB from wait4). Raises when it fails."""
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    out = proc.stdout.read()
    _, status, ru = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise subprocess.CalledProcessError(proc.returncode, cmd)
    return out, ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024.0


def _child(imports: str, work: str, path: Path, *args: str) -> tuple[float, float, float]:
    """(wall s, CPU s) of `work` after `imports` in a fresh process, and its peak RSS (MiB)."""
    code = imports + "\n" + _TIMER.format(work=work)
    out, _, peak = _spawn([sys.executable, "-c", code, str(path), *args])
    wall, cpu = json.loads(out.strip().splitlines()[-1])
    return wall, cpu, peak


def pixel_errors(tracking: dict, seconds_generated: float) -> np.ndarray:
    """Distances (px) of the tracked pixels from the true target pixel of their frames (a looped flight's frame
    i shows frame i mod n of the generated one)."""
    _, cam, R, _ = flight(seconds_generated)
    K = _K()
    out = []
    for i, px in zip(tracking["frame_index"], tracking["pixel_px"], strict=True):
        if px is None:
            continue
        j = i % len(cam)
        x = K @ (R[j].T @ (-cam[j]))
        out.append(math.hypot(px[0] - x[0] / x[2], px[1] - x[1] / x[2]))
    return np.array(out)


def yaml_files(cfg: Path) -> str:
    import yaml

    return yaml.safe_load(cfg.read_text())["files"]["telemetry"][0]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=600.0)
    ap.add_argument("--workdir", default=None, help="where the flight is written (default: a temp folder)")
    ap.add_argument("--reuse", action="store_true", help="reuse a flight already generated in --workdir")
    ap.add_argument("--loop", type=int, default=1,
                    help="benchmark the generated flight copied this many times end to end (see loop())")
    ap.add_argument("--max-detect-px", type=int, default=None,
                    help="run with this tracking.max_detect_px (default: the config's default)")
    args = ap.parse_args(argv)
    folder = Path(args.workdir or f"/tmp/ridgeloc_bench_video_{int(args.seconds)}s")
    load0 = os.getloadavg()
    print(f"load average before: {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}", flush=True)
    cfg = folder / "flight.yaml"
    if not (args.reuse and cfg.is_file()):
        cfg = generate(folder, args.seconds)
    if args.loop > 1:
        t = time.perf_counter()
        cfg = loop(folder, args.loop)
        print(f"looped x{args.loop} in {time.perf_counter() - t:.0f} s", flush=True)
    if args.max_detect_px is not None:  # the same flight with another SIFT resolution, in a config of its own
        import yaml

        doc = yaml.safe_load(cfg.read_text())
        doc["name"] = f"{doc['name']}_sift{args.max_detect_px}"
        doc["tracking"] = {**(doc.get("tracking") or {}), "max_detect_px": args.max_detect_px}
        cfg = cfg.with_name(f"{cfg.stem}_sift{args.max_detect_px}.yaml")
        cfg.write_text(yaml.safe_dump(doc, sort_keys=False))
    ts = folder / yaml_files(cfg)
    results = {"seconds": args.seconds * args.loop, "loop": args.loop, "load_before": load0,
               "mbytes": ts.stat().st_size / 1e6}
    # the observation frames, found in a child (a child's peak RSS counts its parent's pages before exec)
    wanted = subprocess.run([sys.executable, "-c", "import sys\nfrom pipeline.flight import Flight\n"
                             "from pipeline.flight_config import load_run_config\n"
                             "with Flight.open(load_run_config(sys.argv[1])[0].config) as f:\n"
                             "    print(','.join(str(i) for i in f.require_plan().frame_index.tolist()))", str(cfg)],
                            check=True, cwd=ROOT, capture_output=True, text=True).stdout.strip()
    for name, (imports, work) in CHILD.items():  # separate processes, each with its own peak RSS
        wall, cpu, peak = _child(imports, work, ts, wanted)
        results[name] = {"s": wall, "cpu_s": cpu, "peak_mib": peak}
        print(f"{name}: {wall:.2f} s wall, {cpu:.2f} s CPU, peak RSS {peak:.0f} MiB", flush=True)
    out = folder / f"run_{cfg.stem}"  # one output folder per flight (a run folder holds one run's flights)
    t = time.perf_counter()
    _, cpu, peak = _spawn([sys.executable, "-m", "pipeline", "run", str(cfg), "-o", str(out), "--force", "--overwrite",
                           "-q"])
    wall = time.perf_counter() - t
    results["ridgeloc run"] = {"s": wall, "cpu_s": cpu, "peak_mib": peak}
    import yaml

    group = out / yaml.safe_load(cfg.read_text())["name"]  # this flight's folder (a --loop run shares `out`)
    name = [group] if group.is_dir() else []
    res = json.loads((name[0] / "result.json").read_text()) if name else {}
    est = json.loads((name[0] / "estimates.json").read_text())["estimates"] if name else {}
    tracking = json.loads((name[0] / "tracking.json").read_text()) if name else None
    results["errors_m"] = {m: e.get("error_m") for m, e in est.items()}
    results["timings_s"] = res.get("timings_s")
    results["cpu_s"] = (res.get("settings") or {}).get("cpu_s")
    results["frames_decoded"] = (res.get("settings") or {}).get("frames_decoded")
    results["n_observations"] = len(tracking["frame_index"]) if tracking else None
    gen = json.loads((folder / "generate.json").read_text())
    px = pixel_errors(tracking, gen["seconds"]) if tracking else np.zeros(0)
    results["pixel_error_px"] = {"tracked": int(px.size), "median": float(np.median(px)) if px.size else None,
                                 "p95": float(np.percentile(px, 95)) if px.size else None}
    per_minute = [float(np.median(px[k:k + 60])) for k in range(0, px.size, 60)]  # one observation a second
    results["pixel_error_px"]["median_per_minute"] = [round(v, 3) for v in per_minute]
    results["load_after"] = os.getloadavg()
    bare = results["bare decode (every frame)"]["s"]
    floor = results["decode floor (observation frames)"]["s"]
    print(f"ridgeloc run: {wall:.1f} s wall, {cpu:.1f} s CPU, peak RSS {peak:.0f} MiB")
    print(f"run / bare decode of every frame = {wall / bare:.2f} (wall); decode floor / bare decode = "
          f"{floor / bare:.2f}; run / flight length = {wall / results['seconds']:.3f}")
    fixed = sum(results[k]["s"] for k in ("imports (modules a run loads)", "ingest (index + KLV)",
                                          "decode floor (observation frames)"))
    print(f"imports + ingest + decode floor = {fixed:.2f} s = {fixed / bare:.2f} of the bare decode (a run's floor "
          "before any tracking, solving or report)")
    print(f"index / bare demux = {results['index']['s'] / results['bare demux']['s']:.2f} (wall)")
    print(f"frames decoded by the run: {results['frames_decoded']} for {results['n_observations']} observations")
    print(f"stages wall s: {results['timings_s']}")
    print(f"stages CPU s: {results['cpu_s']}")
    print(f"errors m: {results['errors_m']}")
    print(f"tracked pixel - true pixel: {results['pixel_error_px']}")
    print(f"load average after: {' '.join(f'{v:.2f}' for v in results['load_after'])}")
    (folder / f"bench_video_x{args.loop}.json").write_text(json.dumps(results, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
