"""`ridgeloc overlay OUT/GROUP`: write overlay.mp4 for a finished video flight of a run (issue 40)."""

from __future__ import annotations

import argparse

HELP = "write overlay.mp4 for a finished video flight of a run (OUT/GROUP): the observation frames with the " \
       "tracked target, the answer and its 95 % ellipse, the laser spot; report.html then shows it"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", metavar="OUT/GROUP", help="a flight's folder in a `ridgeloc run` output folder")


def _not_a_flight(folder):
    """The one-line error for a folder that is not a finished flight: missing, a run's output folder (naming its
    flights' folders), or anything else."""
    import json

    from pipeline.errors import InputError

    if not folder.is_dir():
        return InputError("no such folder (give a flight's folder in a `ridgeloc run` output folder, OUT/FLIGHT)",
                          folder)
    try:
        groups = [str(folder / g) for g in json.loads((folder / "run.json").read_text()).get("groups", [])]
    except (OSError, ValueError, AttributeError, TypeError):
        groups = []
    if groups:
        more = f" (and {len(groups) - 3} more)" if len(groups) > 3 else ""
        return InputError(f"a run's output folder, not one of its flights: give a flight's folder, "
                          f"{' or '.join(groups[:3])}{more}", folder)
    return InputError("not a finished flight folder of a `ridgeloc run` (no result.json and .done)", folder)


def main(args) -> int:
    import json
    import os
    import time
    from pathlib import Path

    from pipeline.errors import InputError
    from pipeline.report.outputs import RESULT_FILE, add_overlay, load_finished_group, write_run_outputs
    from pipeline.report.store import save_group_result
    from pipeline.results import GroupFailure

    folder = Path(args.folder)
    outdir, name = folder.resolve().parent, folder.resolve().name
    result = load_finished_group(outdir, name)
    if result is None:
        raise _not_a_flight(folder)
    t0 = time.perf_counter()
    made = add_overlay(outdir, result)
    if not made:
        raise InputError("not a video flight: there are no frames to draw on", folder)
    for name_, tmp in made.items():
        os.replace(tmp, folder / name_)
    save_group_result(folder / RESULT_FILE, result)
    line = f"wrote {folder / 'overlay.mp4'} ({result.settings['overlay']['frames']} frames) in " \
           f"{time.perf_counter() - t0:.2f} s"
    run_file = outdir / "run.json"
    if run_file.is_file():  # the run's report.html now shows it
        doc = json.loads(run_file.read_text())
        results = [r for r in (load_finished_group(outdir, g) for g in doc.get("groups", [])) if r is not None]
        failures = [GroupFailure(f["name"], f.get("source", ""), f["message"], f.get("traceback", ""))
                    for f in doc.get("failures", [])]
        paths = write_run_outputs(outdir, results, failures, doc.get("settings") or {})
        line += f"; updated {paths['html']}"
    print(line)
    return 0
