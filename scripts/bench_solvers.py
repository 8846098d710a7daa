"""Benchmark the estimators on the paper's geometry (10 frames, 5 km slant range, 2 km height, paper noise).

Reports, in one run:
  * batched throughput (problems per second) of `solve_batch()` for every method on B problems: the speed that
    matters (a simulation, a batch of flights);
  * median microseconds per `solve()` call for every method (one problem, the CLI path: the same kernels on a
    batch of one; a flight solves each method once, so this only has to stay small against a flight's run);
  * scipy.optimize.least_squares on the same weighted problem as `mle` (robust off, and Huber): the largest
    difference from `mle`;
  * GTSAM (optional extra `gtsam`) as the accuracy cross-check and a batched-throughput comparison: a factor
    graph of projection factors from fixed cameras (TriangulationFactorCal3_S2) and range factors
    (RangeFactor3, Point3 to Point3, to platform points pinned by tight priors), Levenberg-Marquardt; the
    largest difference from `mle` without robust loss, and problems per second solving one graph per problem
    (GTSAM has no batched mode) against `solve_batch('mle', robust=None)` in the same run.

    python scripts/bench_solvers.py [--problems 40] [--batch 8000] [--gamma 30]
    python scripts/bench_solvers.py --against COMMIT[,COMMIT...] [--batch 0]   (before / after, interleaved)
    python scripts/bench_solvers.py --scale [--sizes 300,600,1200,1800,18000] [--timeout 600] [--memory-gb 4]
                                    [--attitude-unstated]
    OPENBLAS_NUM_THREADS=1 python scripts/bench_solvers.py --profile [--batch 8000] [--top 35]

`--profile`: the batched mle on the paper's problems (issue 19's throughput): problems/s of CPU (best of 3) and a
cProfile of one solve_batch("mle") call, sorted by cumulative time.

`--scale` (issue 19): `solve("mle", obs)` on one long continuous-video flight per size (scripts/zoo.py's
generator: an orbit at 20 m/s, 5 km slant, 2 km height, fx 4,000 px, every frame at 30 Hz with a pixel, the laser
at 1 Hz, attitude and GNSS errors drifting (Gauss-Markov, tau 20 s and 120 s), the sigma without correlation
times), each in its own child process: wall and CPU seconds of the solve, the child's peak RSS (max RSS from
wait4) and its RSS before the solve, the error; a case still running after --timeout seconds is killed and
reported as "did not finish in T s". Then the time ratio of the largest to the smallest size that finished
against the ratio of their sizes, and the batched mle on the paper's problems (problems/s, best of 3).
"""

from __future__ import annotations

import argparse
import cProfile
import dataclasses
import itertools
import os
import pstats
import statistics
import sys
import time
import timeit
from pathlib import Path

import numpy as np
import scipy.linalg
from scipy.optimize import least_squares

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # this checkout's pipeline; test support (support.scenes)

from pipeline.geometry.camera import project  # noqa: E402
from pipeline.solve import METHODS, solve, solve_batch  # noqa: E402
from pipeline.solve.mle import HUBER_C, base_variances  # noqa: E402
from pipeline.solve.stacked import Stacked  # noqa: E402
from support.scenes import paper_batch, paper_problem  # noqa: E402


def _time_calls(fn, items, repeats: int) -> tuple[float, float]:
    """Median wall-clock and median CPU seconds per call of fn(item) over `repeats` passes through items
    (after one warm-up pass). CPU time (time.process_time) is what the call cost this process; on a loaded
    machine wall-clock time also counts waiting for a core."""
    for it in items:
        fn(it)
    wall, cpu = [], []
    for _ in range(repeats):
        for it in items:
            c, t = time.process_time(), time.perf_counter()
            fn(it)
            wall.append(time.perf_counter() - t)
            cpu.append(time.process_time() - c)
    return statistics.median(wall), statistics.median(cpu)


def _fmt(pair) -> str:
    return f"{pair[0] * 1e6:8.1f} us wall {pair[1] * 1e6:8.1f} us cpu"


def _ratio(ours, theirs) -> str:
    """Ratios of CPU and of wall times (ours / theirs), measured in the same run."""
    return f"{ours[1] / theirs[1]:.2f} cpu, {ours[0] / theirs[0]:.2f} wall"


def _sigmas(obs, x0):
    var = base_variances(Stacked.from_observations(obs), x0[None], obs.sigma)[0]
    sd = np.sqrt(var)
    return sd[:2 * obs.n].reshape(obs.n, 2), sd[2 * obs.n:]


def _scipy_mle(obs, robust: bool):
    x0 = solve("dlt", obs).position_m
    sd_px, sd_r = _sigmas(obs, x0)

    def f(x):
        pix = (obs.pixel - project(obs.P, np.broadcast_to(x, (obs.n, 3)))) / sd_px
        return np.r_[pix.reshape(-1), (obs.range_m - np.linalg.norm(x - obs.platform_m, axis=1)) / sd_r]

    if robust:
        return least_squares(f, x0, loss="huber", f_scale=HUBER_C, method="trf", xtol=1e-12).x
    return least_squares(f, x0, method="lm", xtol=1e-12).x


def _gtsam_setup(obs):
    """Cameras and noise models built once per problem (like the DLT start, outside the timed part)."""
    import gtsam

    x0 = solve("dlt", obs).position_m
    sd_px, sd_r = _sigmas(obs, x0)
    cams = []
    for P in obs.P:
        K, R = scipy.linalg.rq(P[:, :3])
        D = np.diag(np.sign(np.diag(K)))  # make K's diagonal positive
        K, R = K @ D, D @ R
        if np.linalg.det(R) < 0:
            R = -R
        K = K / K[2, 2]
        C = -np.linalg.solve(P[:, :3], P[:, 3])
        cal = gtsam.Cal3_S2(K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2])
        cams.append(gtsam.PinholeCameraCal3_S2(gtsam.Pose3(gtsam.Rot3(R.T), C), cal))
    return x0, sd_px, sd_r, cams


def _gtsam_solve(obs, setup):
    import gtsam

    x0, sd_px, sd_r, cams = setup
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    X = 0
    values.insertPoint3(X, x0)
    pin = gtsam.noiseModel.Isotropic.Sigma(3, 1e-6)
    for i in range(obs.n):
        if obs.has_pixel[i]:
            noise = gtsam.noiseModel.Diagonal.Sigmas(sd_px[i])
            graph.add(gtsam.TriangulationFactorCal3_S2(cams[i], obs.pixel[i], noise, X))
        if obs.has_range[i]:
            key = 1 + i
            graph.add(gtsam.PriorFactorPoint3(key, obs.platform_m[i], pin))
            values.insertPoint3(key, obs.platform_m[i])
            graph.add(gtsam.RangeFactor3(X, key, float(obs.range_m[i]),
                                          gtsam.noiseModel.Isotropic.Sigma(1, float(sd_r[i]))))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-12)
    result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    return result.atPoint3(X)


def _calibration_us() -> float:
    """Microseconds of one trivial numpy call (a 30-element multiply): the per-call overhead every figure
    here scales with (about 0.3 us on an idle desktop core)."""
    a = np.ones(30)
    best = min(timeit.repeat(lambda: a * 2.0, number=2000, repeat=5)) / 2000
    return best * 1e6


def _import_baseline(commit: str, workdir: str, name: str = "baseline_pipeline"):
    """The solvers of another commit, importable next to this checkout's: `git archive` of its pipeline/ into
    workdir, renamed to the package `name` (its imports rewritten), and the problem generator on its types (its
    pipeline/solve/scenes.py, or this checkout's tests/support/scenes.py for commits after the move)."""
    import importlib
    import re
    import subprocess
    import sys
    import tarfile
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    tar_path = Path(workdir) / f"{name}.tar"
    with open(tar_path, "wb") as fh:
        subprocess.run(["git", "-C", str(repo), "archive", commit, "pipeline"], stdout=fh, check=True)
    with tarfile.open(tar_path) as tar:
        tar.extractall(workdir, filter="data")
    src = Path(workdir) / "pipeline"
    dst = src.rename(Path(workdir) / name)
    if not (dst / "solve" / "scenes.py").exists():
        (dst / "solve" / "scenes.py").write_text((repo / "tests" / "support" / "scenes.py").read_text())
    for f in dst.rglob("*.py"):
        text = f.read_text()
        text = re.sub(r"\bfrom pipeline([. ])", rf"from {name}\1", text)
        text = re.sub(r"\bimport pipeline\b", f"import {name}", text)
        text = re.sub(r"\bpipeline\.([a-z_]+)", rf"{name}.\1", text)
        f.write_text(text)
    if workdir not in sys.path:
        sys.path.insert(0, workdir)
    return importlib.import_module(f"{name}.solve"), importlib.import_module(f"{name}.solve.scenes")


def _tm(fn):
    """(wall, cpu) seconds of one call of fn()."""
    c, t = time.process_time(), time.perf_counter()
    fn()
    return time.perf_counter() - t, time.process_time() - c


def _simulate_wall_s(module: str, workdir: str, pythonpath: str) -> float:
    """Wall seconds of `python -m MODULE simulate` (the default experiment) in a child process."""
    import subprocess
    import sys

    env = {**os.environ, "PYTHONPATH": pythonpath}
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", module, "simulate", "--quiet", "--out", workdir], check=True, env=env,
                   stdout=subprocess.DEVNULL)
    return time.perf_counter() - t


def _compare(commits: list[str], problems: int, batch_size: int, gamma: float, simulate_rounds: int) -> None:
    """This checkout against the solvers of other commits, in one process and one run, interleaved so that the
    machine's load affects all alike: batched throughput (alternating calls, best of 3), then solve() per call
    (every problem solved by each in turn, the order rotating from problem to problem: the first of a round
    runs on colder caches), then `ridgeloc simulate` wall time (alternating child processes)."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        olds = [_import_baseline(c, tmp, f"baseline{k}_pipeline") for k, c in enumerate(commits)]
        head = "".join(f"{c[:12]:>22}" for c in commits) + f"{'now':>22}" + "".join(f"{'now / ' + c[:7]:>16}"
                                                                                       for c in commits)
        n_runs = len(olds) + 1
        if batch_size > 0:
            print(f"\nbatched, solve_batch() on B = {batch_size} problems: problems per second, CPU (wall)")
            print(f"  {'method':<16}{head}   (CPU ratio)")
            batches = [scenes.paper_batch(batch_size, gamma_deg=gamma, seed=123) for _, scenes in olds]
            batches.append(paper_batch(batch_size, gamma_deg=gamma, seed=123))
            fns = [mod.solve_batch for mod, _ in olds] + [solve_batch]
            for k in range(n_runs):  # warm-up
                fns[k]("mle", batches[k])
            for m in METHODS:
                best = [(np.inf, np.inf)] * n_runs
                for _ in range(3):
                    for k in range(n_runs):
                        w, c = _tm(lambda m=m, k=k: fns[k](m, batches[k]))
                        best[k] = (min(best[k][0], w), min(best[k][1], c))
                print(f"  {m:<16}" + "".join(f"{batch_size / c:11.0f} ({batch_size / w:7.0f})" for w, c in best) +
                      "".join(f"{b[1] / best[-1][1]:15.2f}x" for b in best[:-1]))

        probs = [paper_problem(gamma_deg=gamma, seed=s) for s in range(problems)]
        runs = [(mod.solve, [scenes.paper_problem(gamma_deg=gamma, seed=s) for s in range(problems)])
                for mod, scenes in olds] + [(solve, probs)]

        def med(ts, k):
            return statistics.median(x[k] for x in ts) * 1e6

        print("\nsolve() on one problem: median per call, CPU us (wall)")
        print(f"  {'method':<16}{head}   (CPU ratio)")
        corr = {**dataclasses.asdict(probs[0].sigma), "attitude_tau_s": 20.0, "position_tau_s": 60.0}
        for m, kw in [(m, {}) for m in METHODS] + [("mle", {"robust": None}), ("mle", {"sigma": corr})]:
            for fn, ps in runs:  # warm-up
                for p in ps:
                    fn(m, p, **kw)
            times: list[list] = [[] for _ in runs]
            for _ in range(1 if m in ("fusion", "ridge") else 3):
                for i in range(problems):
                    for j in range(n_runs):
                        k = (i + j) % n_runs
                        fn, ps = runs[k]
                        times[k].append(_tm(lambda fn=fn, p=ps[i], m=m, kw=kw: fn(m, p, **kw)))
            label = m + (" robust=None" if "robust" in kw else " correlated" if kw else "")
            print(f"  {label:<16}" + "".join(f"{med(t, 1):11.1f} ({med(t, 0):7.1f})" for t in times) +
                  "".join(f"{med(times[-1], 1) / med(t, 1):15.2f}x" for t in times[:-1]))

        if simulate_rounds > 0:
            repo = str(Path(__file__).resolve().parents[1])
            contestants = [(f"baseline{k}_pipeline", tmp) for k in range(len(olds))] + [("pipeline", repo)]
            walls: list[list[float]] = [[] for _ in contestants]
            for _ in range(simulate_rounds):
                for k, (module, path) in enumerate(contestants):
                    walls[k].append(_simulate_wall_s(module, os.path.join(tmp, f"sim{k}"), path))
            print(f"\n`ridgeloc simulate` (default experiment), wall seconds, median of {simulate_rounds} "
                  "alternating runs")
            print("  " + "".join(f"{c[:12]:>14}" for c in commits) + f"{'now':>14}")
            print("  " + "".join(f"{statistics.median(w):14.2f}" for w in walls))


def _gtsam_batch(probs, setups) -> tuple[float, float]:
    """(wall, cpu) seconds to solve every problem by its own GTSAM graph (GTSAM has no batched mode)."""
    return _tm(lambda: [_gtsam_solve(o, setups[id(o)]) for o in probs])


def scale_flight(n: int):
    """The scale benchmark's flight of n observations: n / 30 s of video at 30 Hz on an orbit at 20 m/s (5 km
    slant, 2 km height: 10 s cover 2.5 deg of azimuth, 10 minutes 150 deg), a range per second; told an attitude
    sigma of 0.1 deg (`--attitude-unstated`: none, and the learned drift model weighs ATTITUDE_GRID_DEG too: 70
    models, not 14)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import zoo

    slant, height, speed = 5000.0, 2000.0, 20.0
    horiz2 = slant ** 2 - height ** 2
    azimuth = speed * (n / 30.0) / np.sqrt(horiz2)
    gamma = np.degrees(np.arccos((height ** 2 + horiz2 * np.cos(azimuth)) / slant ** 2))
    return zoo.make_flight(np.random.default_rng([19, 1]), f"scale{n}", "drift", "arc", gamma_deg=gamma,
                           slant_m=slant, height_m=height, fx=4000.0, image=(1280, 720), fps=30.0, n_obs=n,
                           stride=1, speed_mps=speed, pixel_sigma_px=0.7, pixel_stated=True,
                           told=zoo.Sigma(range_m=3.0, position_m=3.0, attitude_deg=0.1), occlusion_s=0.0,
                           laser_keep=1.0, path="arc")


def _scale_child(n: int, attitude_unstated: bool) -> None:
    """In a child process: one solve("mle") on the n-observation flight; prints a JSON line."""
    import json
    import resource

    f = scale_flight(n)
    sigma = dataclasses.replace(f.obs.sigma, attitude_deg=None) if attitude_unstated else f.obs.sigma
    obs = dataclasses.replace(f.obs, truth_m=None, sigma=sigma)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    c, t = time.process_time(), time.perf_counter()
    est = solve("mle", obs)
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    err = float(np.linalg.norm(est.position_m - f.obs.truth_m))
    print(json.dumps({"n": obs.n, "pixels": int(obs.has_pixel.sum()), "ranges": int(obs.has_range.sum()),
                      "wall_s": wall, "cpu_s": cpu, "rss_before_kb": rss0, "error_m": err,
                      "status": est.status.name.lower(),
                      "iterations": int(est.iterations)}), flush=True)


def _run_scale_case(n: int, timeout_s: float, memory_gb: float, attitude_unstated: bool) -> dict:
    """_scale_child(n) in a child process: its JSON, plus its peak RSS (kB); {'n', 'timeout'} when killed,
    {'n', 'failed'} when it failed (e.g. out of memory: its address space is limited to memory_gb, so that a
    dense n x n path cannot take the shared machine's memory)."""
    import json
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    repo = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": repo}
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as errf:
        import resource

        limit = int(memory_gb * 2**30)
        p = subprocess.Popen([sys.executable, __file__, "--scale-child", str(n)]
                             + (["--attitude-unstated"] if attitude_unstated else []), stdout=out, env=env, cwd=repo,
                             stderr=errf,
                             preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (limit, limit)))
        t0 = time.perf_counter()
        while True:
            pid, status, ru = os.wait4(p.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - t0 > timeout_s:
                p.kill()
                os.wait4(p.pid, 0)
                return {"n": n, "timeout": timeout_s}
            time.sleep(0.2)
        p.returncode = os.waitstatus_to_exitcode(status)
        errf.seek(0)
        err = errf.read().strip().splitlines()
        out.seek(0)
        text = out.read().strip().splitlines()
    if p.returncode != 0 or not text:
        why = err[-1][:160] if err else ""
        if "MemoryError" in why or "Unable to allocate" in why:
            why = f"out of memory: over the {memory_gb:g} GB address-space limit ({why})"
        return {"n": n, "failed": f"exit {p.returncode}: {why}"}
    row = json.loads(text[-1])
    row["rss_peak_kb"] = ru.ru_maxrss
    return row


def _scale(sizes: list[int], timeout_s: float, batch_size: int, memory_gb: float, attitude_unstated: bool) -> None:
    print(f"\nscale: solve('mle') on one continuous-video flight per size (30 Hz, a pixel per frame, a range per "
          f"second, drifting attitude and GNSS errors, no correlation times"
          f"{', no attitude sigma stated' if attitude_unstated else ''}), each in a child process, "
          f"timeout {timeout_s:g} s, address space limited to {memory_gb:g} GB")
    print(f"  {'observations':>12} {'ranges':>7} {'wall s':>9} {'cpu s':>9} {'peak RSS MB':>12} "
          f"{'RSS before MB':>14} {'error m':>9}  status")
    done = []
    for n in sizes:
        r = _run_scale_case(n, timeout_s, memory_gb, attitude_unstated)
        if "timeout" in r:
            print(f"  {n:>12}  did not finish in {timeout_s:g} s", flush=True)
            continue
        if "failed" in r:
            print(f"  {n:>12}  failed ({r['failed']})", flush=True)
            continue
        done.append(r)
        print(f"  {r['n']:>12} {r['ranges']:>7} {r['wall_s']:9.2f} {r['cpu_s']:9.2f} {r['rss_peak_kb'] / 1024:12.0f} "
              f"{r['rss_before_kb'] / 1024:14.0f} {r['error_m']:9.2f}  {r['status']}, {r['iterations']} iterations",
              flush=True)
    for a, b in itertools.pairwise(done):  # consecutive sizes: the 18,000 / 1,800 <= 12
        print(f"  time ratio {b['n']} / {a['n']} observations: {b['wall_s'] / a['wall_s']:.1f} wall, "
              f"{b['cpu_s'] / a['cpu_s']:.1f} cpu (size ratio {b['n'] / a['n']:.1f}); peak RSS ratio "
              f"{b['rss_peak_kb'] / a['rss_peak_kb']:.2f}")
    if batch_size > 0:
        batch = paper_batch(batch_size, seed=123)
        solve_batch("mle", paper_batch(8, seed=1))
        best = (np.inf, np.inf)
        for _ in range(3):
            w, c = _tm(lambda: solve_batch("mle", batch))
            best = (min(best[0], w), min(best[1], c))
        print(f"\nbatched mle, paper's problems (10 frames, 30 deg), B = {batch_size}, best of 3: "
              f"{batch_size / best[1]:.0f} problems/s CPU ({batch_size / best[0]:.0f} wall)")


def _profile(batch_size: int, gamma: float, top: int) -> None:
    """Problems/s of CPU of solve_batch("mle") on paper problems (best of 3) and a cProfile of one call."""
    b = paper_batch(batch_size, 10, gamma, seed=1)
    solve_batch("mle", b)  # warm-up
    times = []
    for _ in range(3):
        t = time.process_time()
        solve_batch("mle", b)
        times.append(time.process_time() - t)
    print(f"{batch_size / min(times):.0f} problems/s CPU (best of 3), load average {os.getloadavg()[0]:.1f}")
    prof = cProfile.Profile()
    prof.runcall(solve_batch, "mle", b)
    pstats.Stats(prof).sort_stats("cumulative").print_stats(top)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", type=int, default=40, help="distinct problems for the single-solve timings")
    ap.add_argument("--batch", type=int, default=8000, help="problems per batched call")
    ap.add_argument("--gamma", type=float, default=30.0, help="intersection angle, degrees")
    ap.add_argument("--against", metavar="COMMIT[,COMMIT...]", help="instead: time this checkout against the "
                    "solvers of other git commits, interleaved in one run (e.g. --against 146e541); "
                    "--batch 0 skips the batched part")
    ap.add_argument("--simulate-rounds", type=int, default=3, help="with --against: alternating runs of "
                    "`ridgeloc simulate` per commit (0 skips them)")
    ap.add_argument("--scale", action="store_true", help="instead: the scale cases (issue 19, above)")
    ap.add_argument("--sizes", default="300,600,1200,1800,18000", help="with --scale: observations per case")
    ap.add_argument("--timeout", type=float, default=600.0, help="with --scale: seconds per case")
    ap.add_argument("--memory-gb", type=float, default=4.0, help="with --scale: address-space limit per case")
    ap.add_argument("--profile", action="store_true", help="instead: profile the batched mle (above)")
    ap.add_argument("--top", type=int, default=35, help="with --profile: functions listed")
    ap.add_argument("--attitude-unstated", action="store_true", help="with --scale: the flight's sigma states no "
                    "attitude sigma (the learned drift model's 70 candidates)")
    ap.add_argument("--scale-child", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.profile:
        _profile(args.batch, args.gamma, args.top)
        return 0
    if args.scale_child:
        _scale_child(args.scale_child, args.attitude_unstated)
        return 0
    if args.scale:
        print(f"machine: {os.cpu_count()} cpus, load average {os.getloadavg()[0]:.1f}, one trivial numpy call "
              f"{_calibration_us():.2f} us")
        _scale([int(x) for x in args.sizes.split(",")], args.timeout, args.batch, args.memory_gb,
               args.attitude_unstated)
        return 0
    print(f"geometry: 10 frames, 5 km slant range, 2 km height, intersection {args.gamma:g} deg, paper noise")
    print(f"machine: {os.cpu_count()} cpus, load average {os.getloadavg()[0]:.1f}, one trivial numpy call "
          f"{_calibration_us():.2f} us")
    if args.against:
        _compare(args.against.split(","), args.problems, args.batch, args.gamma, args.simulate_rounds)
        return 0
    probs = [paper_problem(gamma_deg=args.gamma, seed=s) for s in range(args.problems)]

    print(f"\nbatched, solve_batch() on B = {args.batch} problems (after a warm-up call)")
    batch = paper_batch(args.batch, gamma_deg=args.gamma, seed=123)
    solve_batch("mle", paper_batch(8, gamma_deg=args.gamma, seed=1))
    for m in METHODS:
        c, t = time.process_time(), time.perf_counter()
        be = solve_batch(m, batch)
        dt, dc = time.perf_counter() - t, time.process_time() - c
        err = np.nanmedian(be.errors_m(batch.truth_m))
        conv = be.converged.mean() * 100
        print(f"  {m:<11}{args.batch / dt:9.0f} /s wall {args.batch / dc:9.0f} /s cpu ({dc / args.batch * 1e6:6.1f} us "
              f"cpu per problem)   median error {err:7.2f} m, converged {conv:5.1f} %, median iterations "
              f"{np.median(be.iterations):g}")

    print("\none problem, solve(): median per call (all of solve: checks, start value, result)")
    for m in METHODS:
        repeats = 1 if m in ("fusion", "ridge") else 3
        pair = _time_calls(lambda o, m=m: solve(m, o), probs, repeats)
        it = np.median([solve(m, o).iterations for o in probs])
        print(f"  {m:<16}{_fmt(pair)}   (median iterations {it:g})")
    pair = _time_calls(lambda o: solve("mle", o, robust=None), probs, 3)
    print(f"  {'mle robust=None':<16}{_fmt(pair)}")
    corr = dataclasses.replace(probs[0].sigma, attitude_tau_s=20.0, position_tau_s=60.0)
    pair = _time_calls(lambda o: solve("mle", o, sigma=corr), probs, 3)
    print(f"  {'mle correlated':<16}{_fmt(pair)}   (attitude_tau_s 20, position_tau_s 60: generalized least squares)")

    mle_plain = {id(o): solve("mle", o, robust=None).position_m for o in probs}
    mle_huber = {id(o): solve("mle", o).position_m for o in probs}
    print("\nscipy.optimize.least_squares on the same weighted problem (same DLT start, same sigmas)")
    for robust in (False, True):
        ref = mle_huber if robust else mle_plain
        diff = max(np.abs(_scipy_mle(o, robust) - ref[id(o)]).max() for o in probs)
        print(f"  {'huber' if robust else 'no robust loss':<16}max |scipy - mle| {diff:.1e} m")

    try:
        import gtsam  # noqa: F401
    except ImportError:
        print("\nGTSAM: not installed (pip install 'ridgeloc[gtsam]'), skipped")
        return 0
    setups = {id(o): _gtsam_setup(o) for o in probs}
    diff = max(np.abs(_gtsam_solve(o, setups[id(o)]) - mle_plain[id(o)]).max() for o in probs)
    print("\nGTSAM factor graph: TriangulationFactorCal3_S2 (fixed cameras) + RangeFactor3 to pinned platform "
          "points, Levenberg-Marquardt from the DLT start, same sigmas")
    print(f"  accuracy: max |gtsam - mle(robust=None)| {diff:.1e} m over {len(probs)} problems")
    # throughput on the same problems: GTSAM one graph per problem (cameras, sigmas and start prepared outside
    # the timing), ridgeloc one solve_batch call (everything included); alternating, best of 3
    gb = paper_batch(min(args.batch, 500), gamma_deg=args.gamma, seed=7)
    gprobs = [gb.problem(b) for b in range(gb.size)]
    gsetups = {id(o): _gtsam_setup(o) for o in gprobs}
    g_best, r_best = (np.inf, np.inf), (np.inf, np.inf)
    for _ in range(3):
        w, c = _gtsam_batch(gprobs, gsetups)
        g_best = (min(g_best[0], w), min(g_best[1], c))
        w, c = _tm(lambda: solve_batch("mle", gb, robust=None))
        r_best = (min(r_best[0], w), min(r_best[1], c))
    B = gb.size
    print(f"  throughput on {B} problems, problems per second CPU (wall): GTSAM graph + LM {B / g_best[1]:.0f} "
          f"({B / g_best[0]:.0f}); solve_batch('mle', robust=None) {B / r_best[1]:.0f} ({B / r_best[0]:.0f}); "
          f"ratio {g_best[1] / r_best[1]:.1f}x CPU, {g_best[0] / r_best[0]:.1f}x wall")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
