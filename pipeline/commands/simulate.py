"""`ridgeloc simulate [CONFIG]`: the paper's simulation experiment (Table 2, Figs. 4 and 5)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

HELP = "run the paper's simulation experiment (Table 2, Figs. 4-5) from a YAML config"

DEFAULT_CONFIG = "configs/simulation_table2.yaml"
DEFAULT_OUT = "out/simulation"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", nargs="?",
                        help=f"simulation config (YAML, see docs/simulation.md; default {DEFAULT_CONFIG}, or the "
                             "identical built-in defaults when run outside the repository)")
    parser.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                        help=f"output folder for table2.csv/.md, fig4.png, fig5.png, summary.json "
                             f"(default {DEFAULT_OUT})")
    parser.add_argument("--trials", type=int, metavar="N", help="override the config's trials per angle")
    parser.add_argument("--seed", type=int, help="override the config's random seed")
    parser.add_argument("--quiet", action="store_true", help="print only the wall time")


def main(args: argparse.Namespace) -> int:
    from pipeline.commands import output_folder
    from pipeline.errors import ConfigError
    from pipeline.simulate import SimulationConfig, run_simulation, write_outputs
    from pipeline.simulate.report import markdown_table

    t0, cpu0 = time.perf_counter(), time.process_time()
    output_folder(args.out, "--out")  # a file there is refused before the experiment runs
    source = args.config
    if source is None and not Path(DEFAULT_CONFIG).is_file():
        cfg, source = SimulationConfig(), "built-in defaults (= configs/simulation_table2.yaml)"
    else:
        source = source or DEFAULT_CONFIG
        cfg = SimulationConfig.load(source)
    changes = {k: getattr(args, k) for k in ("trials", "seed") if getattr(args, k) is not None}
    if changes:
        try:
            cfg = cfg.replace(**changes)
        except ConfigError as exc:
            raise ConfigError(f"command-line override: {exc}") from None
    say = (lambda _msg: None) if args.quiet else print
    say(f"simulation '{cfg.name}' from {source}: {len(cfg.angles_deg)} angles x {cfg.trials} trials x "
        f"{len(cfg.methods)} estimators")
    result = run_simulation(cfg, progress=say)
    written = write_outputs(result, args.out)
    if not args.quiet:
        print()
        print("median 3D error (m):")
        print("\n".join(markdown_table(result, "median_m", with_paper=True)))
        print()
        print("non-converged trials (%):")
        print("\n".join(markdown_table(result, "nonconverged_pct", with_paper=False)))
        print()
        print("solve time per method: " + ", ".join(
            f"{m} {s:.2f} s ({1e6 * s / result.solves():.0f} µs/problem)" for m, s in result.method_seconds.items()))
        print("wrote " + ", ".join(str(p) for p in written))
    print(f"wall time {time.perf_counter() - t0:.2f} s (experiment {result.wall_seconds:.2f} s; "
          f"CPU time of this process {time.process_time() - cpu0:.2f} s)")
    return 0
