"""The ``railpaper`` command: list, run, check, compare, sweep, bands, build, track, bench,
register, evidence, compile.

Every user error ends in one line on stderr (``railpaper: error: ...``) and exit status 2;
no traceback.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import sys
from pathlib import Path

import yaml

EXIT_USER_ERROR = 2


class _Parser(argparse.ArgumentParser):
    """argparse with usage errors as one line (``railpaper: error: run: ...``) and exit 2."""

    def error(self, message: str):
        command = self.prog.split(" ", 1)[1] + ": " if " " in self.prog else ""
        self.exit(EXIT_USER_ERROR, f"railpaper: error: {command}{message} (see --help)\n")


class Interrupted(KeyboardInterrupt):
    """SIGTERM, turned into the KeyboardInterrupt path (staging removed, outputs kept)."""


def _raise_interrupted(signum, frame):  # noqa: ARG001 - signal handler signature
    raise Interrupted(signum)


def interruption(exc: BaseException) -> KeyboardInterrupt | None:
    """The KeyboardInterrupt (SIGINT, or SIGTERM as :class:`Interrupted`) that ``exc`` was raised
    while handling, if any: a signal that lands inside a library's locking (dask's
    ``as_completed`` releasing its condition) can come out as that library's own error."""
    while exc is not None:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        exc = exc.__context__
    return None


def _report_interrupt(args, exc: KeyboardInterrupt) -> int:
    """One line and exit 128 + signal for an interrupted command."""
    signum = exc.args[0] if isinstance(exc, Interrupted) else signal.SIGINT
    kept = (f"finished samples kept in {args.out / 'results.csv'}; the same command resumes"
            if args.func is cmd_sweep else "previous outputs left untouched")
    print(f"railpaper: error: interrupted by {signal.Signals(signum).name}; {kept}",
          file=sys.stderr)
    return 128 + signum


class _Loader(yaml.SafeLoader):
    """YAML, plus floats without a dot (``1e-4``, ``2E3``) that YAML 1.1 reads as strings."""


_Loader.add_implicit_resolver("tag:yaml.org,2002:float",
                              re.compile(r"^[-+]?[0-9]+[eE][-+]?[0-9]+$"), list("-+0123456789"))


def _parse_value(text: str):
    """A ``-p NAME VALUE`` value, parsed as YAML (so ``'[80, 140]'`` is a list)."""
    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError:
        return text


def cmd_list(args) -> int:
    from railpaper.experiments import available_chapters, load_chapter
    for name in available_chapters():
        spec = load_chapter(name).SPEC
        source = f"paper {spec.paper}" if spec.paper else "no paper: a study of our own"
        print(f"{name}: {spec.title}  [{source}]")
        if spec.quick_sizes:
            print(f"  --quick: {spec.quick_sizes}")
        for p in spec.parameters:
            quick = "" if p.quick is None else f" (quick: {p.quick!r})"
            print(f"  {p.name} = {p.default!r}{quick}  [{p.type}]  {p.meaning}")
    return 0


def cmd_run(args) -> int:
    from railpaper.pipeline.chapters import chapter_spec, resolve_parameters, run_chapter
    from railpaper.pipeline.evidence_store import records_on
    overrides = {}
    spec = chapter_spec(args.chapter)
    for name, value in args.parameter or []:
        spec.parameter(name)                                  # unknown name: one line, exit 2
        overrides[name] = _parse_value(value)
    resolve_parameters(args.chapter, overrides, args.quick)   # wrong type / value: before a kernel
    with records_on(args.workers, args.scheduler, args.store):
        out = run_chapter(args.chapter, overrides, args.quick, args.out,
                          progress=sys.stderr.isatty())       # no progress bar in logs
    print(f"railpaper: chapter {args.chapter} written to {out}")
    return 0


def cmd_check(args) -> int:
    from railpaper.pipeline.chapters import book_chapters, chapter_spec
    from railpaper.pipeline.check import check_chapter, format_rows
    chapters = args.chapters or book_chapters()
    if args.out is not None and len(chapters) != 1:
        raise ValueError("check --out DIR needs exactly one chapter name")
    rows = []
    for name in chapters:
        chapter_spec(name)
        rows += check_chapter(name, args.out if len(chapters) == 1 else None)
    print(format_rows(rows))
    failed = [r for r in rows if r.status.startswith("FAIL")]
    if failed:
        print(f"railpaper: {len(failed)} metric(s) out of tolerance", file=sys.stderr)
        return 1
    return 0


def cmd_register(args) -> int:
    from railpaper.pipeline.decisive import register_chapter
    for chapter in args.chapters:
        sizes, revised = register_chapter(chapter)
        for key, size in sizes.items():
            print(f"{key}: {'no sample' if size is None else f'{size} records'}")
        if revised:
            print(f"railpaper: {len(revised)} row(s) of {chapter} revised (the previous "
                  f"declarations are kept in the registry): {', '.join(revised)}")
    return 0


def cmd_evidence(args) -> int:
    from railpaper.pipeline.chapters import paper_chapters
    from railpaper.pipeline.decisive import run_decisive
    from railpaper.pipeline.sweep import close_client, make_client
    if not args.decisive:
        raise ValueError("evidence needs --decisive (every ledger row at its registered size)")
    chapters = args.chapters or paper_chapters()
    client = cluster = None
    if args.workers or args.scheduler:
        client, cluster = make_client(args.scheduler, args.workers)
    try:
        done = run_decisive(chapters, client=client, workers=args.workers or 1,
                            progress=lambda line: print(line, file=sys.stderr, flush=True))
    finally:
        if client is not None:
            close_client(client, cluster)
    for item in done:
        state = "; ".join(part for part in (f"{item.size} records" if item.size else "",
                                             item.skipped) if part)
        print(f"{item.chapter} {item.study}: {state}")
    return 0


def cmd_compile(args) -> int:
    from railpaper.pipeline.chapters import paper_chapters
    from railpaper.pipeline.kernels import compile_kernels
    if args.jobs < 1:
        raise ValueError(f"compile: --jobs must be >= 1, got {args.jobs}")
    say = (lambda line: print(line, file=sys.stderr, flush=True)) if args.verbose else None
    seconds = compile_kernels(paper_chapters(), args.jobs, progress=say)
    print(f"railpaper: numba kernels compiled into their cache in {seconds:.0f} s")
    return 0


def cmd_compare(args) -> int:
    from railpaper.pipeline.compare import compare_runs, format_comparison
    if args.out is not None and (args.out.suffix != ".csv" or not args.out.parent.is_dir()):
        raise ValueError(f"compare --out {args.out}: expected a .csv file in an existing directory")
    result = compare_runs(args.run_a, args.run_b)
    print(format_comparison(result, args.run_a, args.run_b))
    if args.out is not None:
        result["metrics"].to_csv(args.out, index=False, float_format="%.17g")
        print(f"railpaper: every metric of both runs written to {args.out}")
    return 0


def _validate_sweep(chapter: str, grid: dict, fixed: dict, quick: bool) -> None:
    """Every grid combination through the chapter's checks, before any worker starts (a sample
    failing at run time is recorded in results.csv; a non-physical input is the user's error)."""
    import itertools

    from railpaper.pipeline.chapters import resolve_parameters
    lists = [v if isinstance(v, list) else [v] for v in grid.values()]
    for values in itertools.product(*lists):
        resolve_parameters(chapter, dict(fixed, **dict(zip(grid, values))), quick)


def cmd_sweep(args) -> int:
    from railpaper.pipeline.sweep import parse_grid_option, run_sweep
    grid = dict(parse_grid_option(text, _parse_value) for text in args.grid or [])
    fixed = {name: _parse_value(value) for name, value in args.parameter or []}
    _validate_sweep(args.chapter, grid, fixed, args.quick)
    frame = run_sweep(args.chapter, grid, args.seeds, args.out, fixed=fixed, quick=args.quick,
                      workers=args.workers, scheduler=args.scheduler)
    failed = int((frame.status != "ok").sum())
    print(f"railpaper: sweep of {args.chapter}: {len(frame) - failed} ok, {failed} failed; "
          f"{args.out / 'results.csv'}, {args.out / 'summary.csv'}")
    return 1 if failed else 0


def cmd_bands(args) -> int:
    from railpaper.pipeline.bands import compute_bands, refloor, write_bands
    from railpaper.pipeline.chapters import chapter_spec
    chapter_spec(args.chapter)
    if args.stride < 1:
        raise ValueError(f"--stride must be >= 1, got {args.stride}")
    if args.out is not None and (not args.out.parent.is_dir() or args.out.is_dir()):
        raise ValueError(f"bands --out {args.out}: no such directory to write into, or a directory")
    bands = (refloor(args.chapter, args.quick) if args.refloor else
             compute_bands(args.chapter, args.quick, args.batches, args.stride, args.work))
    target = write_bands(args.chapter, args.quick, bands, None if args.write else args.out)
    print(f"railpaper: {len(bands)} {'quick' if args.quick else 'full'} bands of {args.chapter} "
          f"written to {target}")
    return 0


def cmd_build(args) -> int:
    from railpaper.pipeline.book import build_book
    from railpaper.pipeline.evidence_store import records_on
    if args.jobs < 1:
        raise ValueError(f"--jobs must be >= 1, got {args.jobs}")
    with records_on(args.workers, args.scheduler, args.store):
        html = build_book(args.quick, args.book_dir, progress=sys.stderr.isatty(), jobs=args.jobs)
    print(f"railpaper: book built at {html / 'index.html'}")
    return 0


def cmd_bench(args) -> int:
    from railpaper.bench.report import run_bench
    if args.scaling:
        from railpaper.pipeline.chapters import book_chapters
        from railpaper.pipeline.scaling import run_scaling
        payload = run_scaling(book_chapters(), alternations=args.alternations)
        if args.out:
            args.out.write_text(json.dumps(payload, indent=1) + "\n")
            print(f"railpaper: scaling benchmark written to {args.out}")
        return 0
    if args.out is not None:                      # refuse before a minute of benchmarking
        if args.out.suffix != ".json":
            raise ValueError(f"bench --out {args.out}: expected a .json file name")
        folder = args.out.parent
        if not folder.is_dir() or not os.access(folder, os.W_OK | os.X_OK) or args.out.is_dir():
            raise ValueError(f"bench --out {args.out}: cannot write there (no such writable "
                             "directory, or a directory of that name)")
    run_bench(args.quick, args.out)
    if args.out:
        print(f"railpaper: benchmark written to {args.out} (plot beside it)")
    return 0


def cmd_track(args) -> int:
    from railpaper import track
    if args.list:
        for name, description, components in track.list_spectra():
            print(f"{name:12s} {description}  components: {', '.join(components)}")
        return 0
    if not args.spectrum or not args.output:
        raise ValueError("track needs --spectrum and -o FILE (or --list)")
    distance, profile = track.synthesize_profile(
        args.spectrum, args.component, args.length_m, args.dx_m, args.seed,
        wavelength_min_m=args.wavelength_min_m, wavelength_max_m=args.wavelength_max_m,
        method=args.method)
    frame = track.profile_frame(distance, profile)
    output = Path(args.output)
    if not output.parent.is_dir() or output.is_dir():
        raise ValueError(f"track -o {output}: no such directory to write into, or a directory")
    tmp = output.with_name(f".{output.name}.tmp")
    frame.to_csv(tmp, index=False, float_format="%.17g")
    tmp.replace(output)
    print(f"railpaper: {len(frame)} samples of {args.spectrum} {args.component} written to {output}")
    return 0


def _records_arguments(p) -> None:
    """``--workers``, ``--scheduler`` and ``--store`` of ``run`` and ``build``."""
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="K",
                       help="compute the Monte Carlo records on K local single-threaded worker "
                       "processes (one dask LocalCluster, shared by the chapters of a build)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="compute them on an existing dask cluster, e.g. tcp://host:8786")
    p.add_argument("--store", type=Path, metavar="DIR",
                   help="keep every record's row in this evidence store and reuse the rows it "
                   "holds (only missing seeds are computed)")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="railpaper", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("list", help="chapters with their parameters, defaults and meaning")
    p.set_defaults(func=cmd_list)

    p = sub.add_parser("run", help="execute one chapter notebook with papermill")
    p.add_argument("chapter")
    p.add_argument("-p", "--parameter", nargs=2, action="append", metavar=("NAME", "VALUE"),
                   help="set a chapter parameter; VALUE is YAML (e.g. -p speeds_kmh '[80, 140]')")
    p.add_argument("--quick", action="store_true", help="the chapter's quick sizes (CI)")
    p.add_argument("--out", type=Path, help="output directory (default: the book's chapter folder)")
    _records_arguments(p)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("check", help="metrics.json against the CI tolerances")
    p.add_argument("chapters", nargs="*")
    p.add_argument("--out", type=Path, help="run directory to check (one chapter only)")
    p.set_defaults(func=cmd_check)

    p = sub.add_parser("register", help="fix the declared claims' sample sizes by power and "
                       "record their fingerprints (data/claims_registry.json)")
    p.add_argument("chapters", nargs="+")
    p.set_defaults(func=cmd_register)

    p = sub.add_parser("evidence", help="compute the stored decisive evidence (data/evidence)")
    p.add_argument("--decisive", action="store_true",
                   help="every declared row's study at its registered size")
    p.add_argument("chapters", nargs="*", help="default: every paper chapter")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="K", help="K local worker processes")
    where.add_argument("--scheduler", metavar="ADDRESS", help="an existing dask cluster")
    p.set_defaults(func=cmd_evidence)

    p = sub.add_parser("compile", help="compile the numba kernels into their on-disk cache once "
                       "(make test does this): one record of every study")
    p.add_argument("--jobs", type=int, default=2, help="processes (default 2)")
    p.add_argument("--verbose", action="store_true", help="one line per study compiled")
    p.set_defaults(func=cmd_compile)

    p = sub.add_parser("compare", help="two runs of a chapter side by side: parameters, metrics, "
                       "verdicts")
    p.add_argument("run_a", type=Path, help="output directory of run A (holds metrics.json)")
    p.add_argument("run_b", type=Path, help="output directory of run B")
    p.add_argument("--out", type=Path, help="write every metric of both runs to this CSV")
    p.set_defaults(func=cmd_compare)

    p = sub.add_parser("sweep", help="Monte Carlo sweep: grid values x seeds on dask workers")
    p.add_argument("chapter")
    p.add_argument("--grid", action="append", metavar="NAME=V1,V2,...",
                   help="values of one parameter, each YAML (e.g. speeds_kmh=[60],[100])")
    p.add_argument("-p", "--parameter", nargs=2, action="append", metavar=("NAME", "VALUE"),
                   help="a parameter fixed for every sample; VALUE is YAML")
    p.add_argument("--seeds", required=True, help="START:STOP (0:50 = seeds 0..49) or 0,3,7")
    p.add_argument("--out", type=Path, required=True, help="directory of results.csv, summary.csv")
    p.add_argument("--quick", action="store_true", help="the chapter's quick sizes")
    p.add_argument("--workers", type=int, help="local worker processes (default: all cores)")
    p.add_argument("--scheduler", help="dask scheduler address, e.g. tcp://host:8786")
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser("bands", help="CI tolerance bands of a chapter from disjoint seed batches")
    p.add_argument("chapter")
    p.add_argument("--quick", action="store_true", help="bands of the quick sizes")
    p.add_argument("--batches", type=int, default=10, help="chapter runs (default 10)")
    p.add_argument("--stride", type=int, default=1000,
                   help="batch k runs with seed = k * stride (default 1000)")
    p.add_argument("--work", type=Path, help="where the batch runs go (default runs/bands-...); "
                   "finished batches there are reused")
    p.add_argument("--refloor", action="store_true",
                   help="run no batch: widen the stored bands to their rounding floor "
                   "(±max(1e-9, 1e-9·|value|), capped at rule thresholds)")
    target = p.add_mutually_exclusive_group(required=True)
    target.add_argument("--out", type=Path, help="write a tolerances file here")
    target.add_argument("--write", action="store_true",
                        help="replace this mode's bands in data/<chapter>/tolerances.toml")
    p.set_defaults(func=cmd_bands)

    p = sub.add_parser("build", help="run every chapter, then build the book strictly")
    p.add_argument("--quick", action="store_true")
    p.add_argument("--book-dir", type=Path, help=argparse.SUPPRESS)
    p.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1),
                   help="chapters run at once, one core each (default: 2, or 1 on one core)")
    _records_arguments(p)
    p.set_defaults(func=cmd_build)

    p = sub.add_parser("bench", help="RBPF engine benchmark on paper 003's lateral model")
    p.add_argument("--quick", action="store_true",
                   help="fewer steps and alternations, same N (about half a minute)")
    p.add_argument("--out", type=Path, help="write the results as JSON (and a PNG plot beside)")
    p.add_argument("--scaling", action="store_true",
                   help="instead: each chapter's Monte Carlo records on 1 and 2 dask workers, "
                   "alternated, on about 5 %% of its decisive evidence")
    p.add_argument("--alternations", type=int, default=3, help="--scaling: 1/2-worker pairs")
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser("track", help="export a synthetic track irregularity profile as CSV")
    p.add_argument("--list", action="store_true", help="name the spectra and components")
    p.add_argument("--spectrum")
    p.add_argument("--component", default="vertical")
    p.add_argument("--length-m", type=float, default=2000.0)
    p.add_argument("--dx-m", type=float, default=0.25)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--wavelength-min-m", type=float)
    p.add_argument("--wavelength-max-m", type=float)
    p.add_argument("--method", choices=("harmonic", "ifft"), default="ifft")
    p.add_argument("-o", "--output")
    p.set_defaults(func=cmd_track)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status."""
    from railpaper.data import DataError
    from railpaper.experiments.base import ParameterError
    from railpaper.pipeline.chapters import PipelineError

    args = build_parser().parse_args(argv)
    previous_handler = signal.signal(signal.SIGTERM, _raise_interrupted)
    try:
        return args.func(args)
    except (ParameterError, DataError, PipelineError, ValueError, OSError) as exc:
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"railpaper: error: {message}", file=sys.stderr)
        return EXIT_USER_ERROR
    except MemoryError:
        print("railpaper: error: out of memory; use smaller sizes", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt as exc:
        return _report_interrupt(args, exc)
    except RuntimeError as exc:
        interrupt = interruption(exc)
        if interrupt is None:
            raise
        return _report_interrupt(args, interrupt)
    finally:
        signal.signal(signal.SIGTERM, previous_handler)


if __name__ == "__main__":
    sys.exit(main())
