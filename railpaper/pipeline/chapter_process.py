"""Several chapters at once, each in a process of its own: how ``railpaper build`` fills the
machine's cores.

A chapter runs on one core (its kernel pins numba and OpenBLAS to one thread, so its metrics are
the same bits however many run beside it); :func:`run_chapters` keeps ``jobs`` of them running,
longest first, each as ``python -m railpaper.pipeline.chapter_process NAME OUT [--quick]`` — that
is :func:`railpaper.pipeline.chapters.run_chapter` with its staging directory, so a failed or
interrupted chapter leaves its previous output untouched.  Its own output goes to a log beside
its folder; one line per chapter reports start, end and wall time.  If a chapter fails, the others
are stopped (SIGTERM: each removes its staging directory) and the error names the log.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

from railpaper.pipeline.chapters import PipelineError, ensure_kernel, run_chapter

#: Chapters by their default run's wall time on one core, longest first (measured 2026-12-05 in
#: a two-job build: 332 s, about 300 s, 105 s, 70 s, 25 s); a chapter not listed starts last.
LONGEST_FIRST = ("rbpf-parameter-estimation", "quasi-gaussian-rbpf", "suspension-fault-detection",
                 "reduced-order-observer", "partial-state-observer")


def _log_path(out: Path) -> Path:
    return out.parent / f".{out.name}.build.log"


def run_chapters(names: list[str], quick: bool, out_dirs: dict[str, Path], jobs: int = 2,
                 say=lambda line: print(line, file=sys.stderr, flush=True)) -> None:
    """Run ``names`` (each into ``out_dirs[name]``), at most ``jobs`` at a time."""
    ensure_kernel()                                   # once, before the children look for it
    order = sorted(names, key=lambda n: LONGEST_FIRST.index(n) if n in LONGEST_FIRST
                   else len(LONGEST_FIRST))
    running: dict[str, tuple[subprocess.Popen, float, object]] = {}
    t0 = time.monotonic()
    try:
        while order or running:
            while order and len(running) < jobs:
                name = order.pop(0)
                out = Path(out_dirs[name])
                out.parent.mkdir(parents=True, exist_ok=True)
                log = open(_log_path(out), "w")
                command = [sys.executable, "-m", "railpaper.pipeline.chapter_process", name,
                           str(out)] + (["--quick"] if quick else [])
                # a chapter's records run in its own process unless the build was given
                # --workers or --scheduler (evidence_store.records_on): then on those workers
                running[name] = (subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT),
                                 time.monotonic(), log)
                say(f"railpaper: running chapter {name}{' (quick)' if quick else ''} "
                    f"({len(running)} running)")
            time.sleep(0.2)
            for name, (process, started, log) in list(running.items()):
                if process.poll() is None:
                    continue
                log.close()
                del running[name]
                if process.returncode != 0:
                    raise PipelineError(f"chapter '{name}' failed (exit {process.returncode}); "
                                        f"its log: {_log_path(Path(out_dirs[name]))}")
                say(f"railpaper: chapter {name} done in {time.monotonic() - started:.0f} s "
                    f"({time.monotonic() - t0:.0f} s since the first started)")
    finally:
        for process, _, log in running.values():       # an error or an interrupt: stop the rest
            process.terminate()
        for process, _, log in running.values():
            process.wait()
            log.close()


def main(argv: list[str] | None = None) -> int:
    """One chapter in this process (see the module docstring); SIGTERM takes the interrupt
    path, so the staging directory goes and the previous output stays."""
    args = sys.argv[1:] if argv is None else argv
    quick = "--quick" in args
    name, out = [a for a in args if a != "--quick"]

    def interrupted(signum, frame):  # noqa: ARG001 - signal handler signature
        raise KeyboardInterrupt(signum)
    signal.signal(signal.SIGTERM, interrupted)
    try:
        run_chapter(name, {}, quick, out, progress=False, page=False)
    except KeyboardInterrupt:
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
