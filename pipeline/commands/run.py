"""`ridgeloc run [CONFIG] [-o OUTDIR]`: process flight groups end to end into reports and GIS exports."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from pipeline.commands import not_a_config, output_folder
from pipeline.commands.send import add_tak_arguments, check_send_args, cot_options, send_run_outputs
from pipeline.errors import InputError
from pipeline.flight_config import FlightConfig, load_run_config
from pipeline.report.labels import count

HELP = ("process flights (video or photos, telemetry, ranges) into one answer per target (WGS84, MGRS, CE90), a report "
        "comparing every method, GIS and TAK outputs")
DEFAULT_CONFIG = Path("configs/sample.yaml")
STAGES = ("ingest", "track", "sync", "solve")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", nargs="?", default=str(DEFAULT_CONFIG),
                        help="a run config listing flight configs under `groups:`, a manifest (YAML list of flight "
                             "configs), a folder of flights (every flight.yaml below it), one flight config, or a "
                             "MISB full-motion video (.ts with KLV metadata) "
                             f"(default: {DEFAULT_CONFIG} in the current folder: the sample flights of the source "
                             "checkout)")
    parser.add_argument("-o", "--outdir", default="out", help="output folder (default: out)")
    parser.add_argument("--workers", type=int, default=1, help="flights processed at once (default: 1)")
    parser.add_argument("--executor", choices=("local", "dask"), default="local",
                        help="local processes, or a Dask distributed cluster (needs the `dask` extra)")
    parser.add_argument("--scheduler", default=None,
                        help="Dask scheduler address, e.g. tcp://host:8786 (default: a local Dask cluster)")
    parser.add_argument("--force", action="store_true", help="redo flights whose outputs are already finished")
    parser.add_argument("--overwrite", action="store_true",
                        help="the output folder holds another run's results: replace them (else refused)")
    parser.add_argument("--no-figures", action="store_true", help="skip the per-group figures (faster)")
    parser.add_argument("--overlay", action="store_true",
                        help="also write overlay.mp4 per video flight: the observation frames with the tracked "
                             "target, the answer and its 95 %% ellipse, the laser spot (shown in report.html)")
    parser.add_argument("-q", "--quiet", action="store_true", help="print only the summary and errors")
    add_tak_arguments(parser)


def _resolve_config(arg: str) -> Path:
    """The config to run. With none given, configs/sample.yaml of the current folder: the sample flights are in
    the source checkout, not in the installed package (which makes no guess about where a checkout is)."""
    config = Path(arg)
    if arg == str(DEFAULT_CONFIG) and not config.exists():
        raise InputError(f"no config given and no {DEFAULT_CONFIG} here: name a run config, a flight config or a "
                         "folder of flights (the bundled sample flights: run from the source checkout)")
    return config


def _input_files(cfg: FlightConfig) -> list[Path]:
    """The files a flight's outputs depend on (for re-run skipping); folders (ROS 2 bags) contribute their files."""
    from pipeline.targets import flight_targets

    listed = [*cfg.files.telemetry, cfg.files.video, cfg.files.frames_csv, *cfg.files.photos, cfg.files.marks,
              cfg.truth_file, cfg.marks_file, cfg.terrain.dem if cfg.terrain is not None else None,
              *[m.template for t in flight_targets(cfg) for m in t.marks]]  # every target's template images
    files: list[Path] = []
    for f in listed:
        if f is None:
            continue
        p = Path(f)
        files.extend(sorted(q for q in p.rglob("*") if q.is_file()) if p.is_dir() else [p])
    return files


def group_summary(r, reused: bool = False) -> list[str]:
    """A finished group's console lines: observations, time and errors; then, indented, the logs' warnings (damage
    read past), the geometry warnings of its checks, the mle's words when its error model does not fit the flight,
    how many observations it rejected, and the methods that did not solve (the report has the details)."""
    from pipeline.report.exports import unsolved_methods

    errs = r.errors_m()
    shown = ", ".join(f"{m} {errs[m]:.2f} m" for m in ("ridge", "mle") if errs.get(m) is not None)
    state = "reused" if reused else f"{sum(r.timings_s.values()):.2f} s"
    lines = [f"{r.label}: {count(r.n_observations, 'observation')}, {state}" + (f", error {shown}" if shown else "")]
    lines += [f"  warning: {w}" for w in r.settings.get("input_warnings") or []]  # a truncated log, say
    lines += [f"  warning: {w}" for w in r.settings.get("geometry_warnings") or []]
    lines += [f"  warning: {w}" for w in r.settings.get("answer_warnings") or []]
    lines += [f"  {n}" for n in r.settings.get("notes") or [] if str(n).startswith("mle: the error model does not fit")]
    mle = r.estimates.get("mle")
    rejected = mle.extras.get("rejected") if mle is not None and isinstance(mle.extras, dict) else None
    if rejected:
        kinds = sorted({"range" if x["residual"] == "range" else "pixel" for x in rejected}, reverse=True)
        lines.append(f"  mle: {len(rejected)} {' and '.join(kinds)} residual(s) rejected as gross outliers (zero "
                     "weight; listed in the report and estimates.json)")
    unsolved = unsolved_methods(r)
    if unsolved:
        lines.append("  not solved: " + ", ".join(f"{m} ({status})" for m, (status, _) in unsolved.items()))
    return lines


def _failed_name(source: str) -> str:
    """The name a flight config that does not load is reported under: its file's stem, or for a flight.yaml (what
    `ridgeloc init` writes, one per flight folder) its folder's name, so that the failures of a folder of flights
    are told apart."""
    p = Path(source)
    if p.stem == "flight" and p.suffix.lower() in (".yaml", ".yml") and p.resolve().parent.name:
        return p.resolve().parent.name
    return p.stem


def main(args) -> int:
    output_folder(args.outdir)  # a file there is refused before any flight runs
    if args.scheduler is not None and args.executor != "dask":
        raise InputError("--scheduler names a Dask scheduler: give --executor dask too (it would be ignored)")
    cot = cot_options(args)  # a bad CoT type, stale time, URL or certificate is refused before any flight runs
    check_send_args(args, args.send)
    config = _resolve_config(args.config)
    try:
        entries = load_run_config(config)  # a malformed run config is refused before the heavy imports below
    except InputError as exc:
        raise not_a_config(config) or exc from None
    from pipeline import __version__
    from pipeline.batch import Job, job_digest, run_groups, summarize_failures
    from pipeline.report.outputs import write_run_outputs
    from pipeline.report.table4 import write_table4
    from pipeline.results import GroupFailure, group_files
    from pipeline.run import process_group

    config_failures: list[GroupFailure] = []
    loaded: list[tuple[str, FlightConfig]] = []
    for entry in entries:
        if entry.config is None:
            log = not_a_config(entry.source)  # a log listed as a flight config
            config_failures.append(GroupFailure(_failed_name(entry.source), entry.source, str(log or entry.error)))
        else:
            loaded.append((entry.source, entry.config))
    jobs = [Job(cfg.name, source, cfg) for source, cfg in loaded]
    from pipeline.report.outputs import claim_output_folder

    claim_output_folder(args.outdir, [j.name for j in jobs] + [f.name for f in config_failures], args.overwrite)
    # an overlay asked for is part of what a finished folder must hold
    digests = {cfg.name: job_digest({**cfg.to_dict(), **({"overlay": True} if args.overlay else {})},
                                    _input_files(cfg)) for _, cfg in loaded}
    results, failed, reused = run_groups(
        jobs, process_group, args.outdir, digests=digests, force=args.force, extra_files=group_files,
        figures=not args.no_figures, overlay=args.overlay, workers=args.workers, executor=args.executor,
        scheduler=args.scheduler,
        progress=not args.quiet, stages=STAGES)
    failures = config_failures + failed
    settings = {"config": str(config), "outdir": str(args.outdir), "workers": args.workers,
                "executor": args.executor, "ridgeloc": __version__, "reused": reused}
    t0 = time.perf_counter()
    if results:  # when every flight failed, no output at all (as for a flight config that does not load)
        write_run_outputs(args.outdir, results, failures, settings, figures=not args.no_figures, cot=cot)
        md, tab = write_table4(args.outdir, results, failures)
        t2 = time.perf_counter()
    from pipeline.results import per_target, target_failures

    for r in per_target(results):  # a summary per target of a flight with named targets
        lines = group_summary(r, reused=r.name in reused)
        if not args.quiet:
            print("\n".join(lines))
        else:  # -q still says when an mle's error model does not fit: never a silently overconfident ellipse
            for ln in lines[1:]:
                if ln.strip().startswith("mle: the error model does not fit"):
                    print(f"{r.label}: {ln.strip()}")
    not_located = target_failures(results)
    for name, f in not_located:  # the flight's other targets are in the outputs
        print(f"ridgeloc: {name}:{f.target}: not located: {f.message}", file=sys.stderr)
    for f in failures:  # one line each on stderr; the count and the names go to stdout with the rest of the summary
        print(f"ridgeloc: {f.name}: failed: {f.message}", file=sys.stderr)
    if results and not args.quiet:
        print(f"wrote {Path(args.outdir) / 'report.html'}, targets.csv/.geojson/.kml, cot/ and targets.zip (TAK), "
              f"estimates.csv/.geojson, {md} and {tab} in {t2 - t0:.2f} s")
    print(summarize_failures(failures, len(entries)).splitlines()[0])
    located = True
    if results:
        from pipeline.report.answers import answer_rows, answers_text

        rows = answer_rows(results, failures)
        located = all(row["status"] == "located" for row in rows)
        print("\n" + answers_text(rows))
    sent = send_run_outputs(args.outdir, args) if results and args.send else 0
    return 1 if failures or not_located or not located or sent else 0
