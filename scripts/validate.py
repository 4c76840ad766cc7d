"""`make validate`: validation studies of the FOM, ROM and PROM, stress tests and results/REPORT.md.

Studies (SPEC §11 "Validation studies", the validation issue):
  a       FOM vs ROM (default and the source's basis) vs PROM(3, 5, 8 parameters) on the mesh levels
          × actuation stiffnesses at the shipped degree (2; levels 1–3): errors of distance and tail amplitude, build and solve times;
          heat maps of the distance error over (cells, tail amplitude).
  b       cost against size: build (basis / tensors / rest) and solve time against cells, fitted
          power-law exponents (over every case of a; solve times are the minimum of 3 repeats).
  c       run time against error on the reference case: basis variants, time steps, Taylor order;
          one Pareto plot.
  d       time-step convergence on the shipped scenes' mesh: successive-difference ratios of head x,
          tail y (FOM, ROM) and of the PROM sensitivities at h = 0.02 … 0.0025, for the default
          scheme and Newmark; the default scheme continued to 0.00125 (FOM) and 0.0003125 (ROM,
          PROM); also written as <out>/time_convergence.json.
  e       MPI: the FOM with mpirun -n 1 and -n 2 at the shipped degree on levels 2 and 3 (21k, 40k dofs):
          speed-up, agreement.
  stress  numerical stability: 2×–5× actuation stiffness, h up to 0.1 s, Newmark α_N = 0, E/5, the PROM
          on the finest mesh; Newton iterations and the energy balance per case.
  mesh_convergence
          the nominal FOM for degree 1 on levels 1–5 and degree 2 on levels 1–3: distance, tail
          amplitude, first frequency, static peak-muscle tail deflection, wall time; Richardson
          reference per quantity (observed order, error estimate) and the cheapest (degree, level)
          within 3% of the reference distance (`aquarom_fenics.verification.convergence`).
  fish_mesh_convergence
          the same for the shipped fish (scenes/fish.toml, degree 2) on its shipped meshes
          meshes/fish_l1.msh … fish_l4.msh (levels 1–3 with --quick); checks: the reference distance's
          estimated error and the finest level's error against it, each within 1 % (the reference:
          Richardson's, or without an observed order the finest level with the three finest levels'
          spread as its error).
  calibration
          `aquarom calibrate` on synthetic FOM swims of the nominal fish (2 s, 240 Hz, noise 0.3 mm) at
          parameters away from the scene's: cases (E, k), (E, α), (k, drag factor), (E, k, thrust factor);
          each fitted value's error and 95 % interval, and the interval's coverage over 20 noise draws
          for (E, k) (not cached: every run fits again).

The studies, the case cache and the report live in `aquarom_fenics.verification.validation`;
this script parses the command line.

Every case is cached in <out>/cases/<kind>-<key>.json (key: scene hash + model settings +
software versions), so a rerun computes only what is missing; each study writes <out>/<study>.json,
figures go to <out>/, and the report to results/REPORT.md (--report-only rewrites figures and
report from what is cached).

    .venv/bin/python scripts/validate.py --jobs 2        # everything, missing cases in 2 workers
    .venv/bin/python scripts/validate.py --quick         # levels 1–2, 0.4 s horizon (≈ 1–2 min)
    .venv/bin/python scripts/validate.py --only a,b      # selected studies
    .venv/bin/python scripts/validate.py --report-only   # figures and REPORT.md from the cache
    .venv/bin/python scripts/validate.py --scheduler tcp://host:8786   # missing cases on a Dask cluster
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from aquarom_fenics.errors import InputError
from aquarom_fenics.parallel import choose_cluster
from aquarom_fenics.verification.validation.figures import make_figures
from aquarom_fenics.verification.validation.report import write_report
from aquarom_fenics.verification.validation.settings import FULL, QUICK
from aquarom_fenics.verification.validation.suite import STUDIES, run

REPOSITORY = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="levels 1–2, three stiffnesses, 0.4 s horizon (smoke run)")
    parser.add_argument("--only", help=f"comma-separated studies among {', '.join(STUDIES)} (default all)")
    parser.add_argument("--out", type=Path, help="results folder (default results/validation, "
                                                 "results/validation-quick with --quick)")
    parser.add_argument("--report", type=Path, help="report file (default results/REPORT.md, <out>/REPORT.md with --quick)")
    parser.add_argument("--report-only", action="store_true", help="rewrite figures and report from the cached results")
    parser.add_argument("--recompute-failed", action="store_true", help="recompute cached cases that did not complete")
    parser.add_argument("--time-limit", type=float, help="seconds per case (default 1800, 300 with --quick)")
    parser.add_argument("--jobs", type=int, default=1,
                        help="compute the missing cases in this many worker processes first (the MPI study e "
                             "always runs alone afterwards); timings are then taken with that many cases at once")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="compute the missing cases on the workers of this Dask scheduler (tcp://host:8786); "
                             "the results folder must be on a file system the workers share")
    parser.add_argument("--scheduler-file", type=Path, metavar="FILE",
                        help="as --scheduler, the address read from `dask scheduler --scheduler-file FILE`")
    args = parser.parse_args(argv)
    settings = QUICK if args.quick else FULL
    out = args.out or REPOSITORY / "results" / ("validation-quick" if args.quick else "validation")
    report_path = args.report or (out / "REPORT.md" if args.quick else REPOSITORY / "results" / "REPORT.md")
    if args.report_only:
        make_figures(out)
        write_report(out, report_path)
        print(f"wrote {report_path}")
        return 0
    studies = STUDIES
    if args.only:
        studies = tuple(name.strip() for name in args.only.split(",") if name.strip())
        unknown = [name for name in studies if name not in STUDIES]
        if unknown:
            parser.error(f"--only: unknown studies {', '.join(unknown)}; valid: {', '.join(STUDIES)}")
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    try:
        cluster = choose_cluster(args.scheduler, args.scheduler_file)
        run(settings, out, report_path, studies, args.recompute_failed, args.time_limit, jobs=args.jobs,
            cluster=cluster)
    except InputError as error:
        print(f"validate: error: {error}", file=sys.stderr)
        return InputError.exit_code
    return 0


if __name__ == "__main__":
    sys.exit(main())
