"""``leafsim accuracy`` and ``leafsim bench``: what accuracy costs, and how fast the kernels are."""

from __future__ import annotations

from pathlib import Path

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import check_output, not_an_input, output_target
from leafsim.commands.common import RESOLVED, emit, ready_kernels
from leafsim.measure.accuracy import GROUPS, markdown, study, write_report
from leafsim.measure.bench import main as bench_main


def cmd_accuracy(args):
    # the study sets its own parameters per row (its JSON lists each row's overrides)
    RESOLVED.update(species=args.species, seed=args.seed, config=args.config or "(shipped configs/leaves.json)",
                    quick=bool(args.quick))
    if args.out is not None and not args.out.strip():
        raise LeafsimError("--out '': expected a folder name for the report")
    out = Path(args.out) if args.out else None
    if out is not None and out.exists() and not out.is_dir():
        raise LeafsimError(f"--out {out}: exists and is not a folder")
    if out is not None and not out.parent.exists():
        raise LeafsimError(f"--out {out}: parent folder {out.parent} does not exist")
    if out is not None:
        check_output(out, "--out folder", folder=True)
        # the report's files, checked before the study (a read-only picture failed after it,
        # leaving the other two written)
        names = ("limit.json", "limit.md", "limit_front.png") if args.limit else ("accuracy.json", "accuracy.md", "accuracy_pareto.png")
        from leafsim.commands.common import species_inputs
        from leafsim.config.species import get_species

        inputs = species_inputs(get_species(args.species, args.config))  # (an unknown species says so here)
        for name in names:
            output_target(out / name, "report")
            not_an_input(out / name, inputs, "--out")  # a config kept as OUT/accuracy.json became the report
    if args.floor < 0:
        raise LeafsimError(f"--floor {args.floor}: expected a count ≥ 0")
    if args.limit:
        from leafsim.measure.limit import limit_study, markdown_limit, write_limit_report

        if args.groups is not None or args.floor or args.floor_reference:
            raise LeafsimError("--limit: measures its own settings against the limit; --groups, --floor and "
                               "--floor-reference are for the reference study (drop them or --limit)")
        if args.cache is not None:
            check_output(Path(args.cache), "--cache folder", folder=True)
        ready_kernels()
        report = limit_study(args.species, quick=args.quick, seed=args.seed, config=args.config, progress=not args.json,
                             cache=None if args.cache is None else Path(args.cache))
        if out is not None:
            report["files"] = write_limit_report(report, out)
        emit(args, report, markdown_limit(report))
        return
    if args.cache is not None:
        raise LeafsimError("--cache: only with --limit")
    groups = None if args.groups is None else [g.strip() for g in args.groups.split(",") if g.strip()]
    if groups is not None and (not groups or set(groups) - set(GROUPS)):
        raise LeafsimError(f"--groups {args.groups}: expected a comma list of {', '.join(sorted(GROUPS))}")
    ready_kernels()
    report = study(args.species, quick=args.quick, seed=args.seed, config=args.config, progress=not args.json,
                   floor=args.floor, floor_reference=args.floor_reference, groups=groups)
    if out is not None:
        report["files"] = write_report(report, out)
    emit(args, report, markdown(report))


def cmd_bench(args):
    ready_kernels()
    return bench_main(json_out=args.json, quick=args.quick)
