"""A run whose filter bank cannot fit in memory is refused before it starts (one line, exit 2).

The estimate (:func:`railpaper.experiments.base.particle_bank_bytes`) is checked against what the
filters really take: the peak resident memory of a fresh process running them (VmHWM of
``/proc/self/status``), at a large and a small N.
"""

import json
import subprocess
import sys
import textwrap
import time

import pytest
from conftest import REPO, railpaper_cli

from railpaper.experiments.base import (
    ParameterError,
    available_memory_bytes,
    check_banks,
    particle_bank_bytes,
)


@pytest.mark.parametrize("chapter, args, name", [
    ("quasi-gaussian-rbpf", ["-p", "n_particles", "1e9"], "n_particles"),
    ("quasi-gaussian-rbpf", ["-p", "grid_size", "1000000"], "grid_size"),
    ("quasi-gaussian-rbpf", ["-p", "timing_particles", "[100, 3e9]"], "timing_particles"),
    ("rbpf-parameter-estimation", ["-p", "n_particles", "1e9"], "n_particles"),
    ("rbpf-parameter-estimation", ["-p", "toy_particles", "1e10"], "toy_particles"),
])
def test_too_large_a_bank_is_refused_at_once(chapter, args, name, tmp_path):
    start = time.perf_counter()
    result = railpaper_cli("run", chapter, "--quick", *args, "--out", str(tmp_path / "out"),
                           timeout=120)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("railpaper: error:"), result.stderr
    assert f"parameter '{name}'" in lines[0] and "available (MemAvailable)" in lines[0]
    assert " TB " in lines[0] or " GB " in lines[0]
    assert time.perf_counter() - start < 60 and not (tmp_path / "out").exists()


def test_meminfo_is_read_and_the_check_names_the_numbers(tmp_path):
    meminfo = tmp_path / "meminfo"
    meminfo.write_text("MemTotal:       24683652 kB\nMemFree:  100 kB\n"
                       "MemAvailable:   24061128 kB\n")
    assert available_memory_bytes(meminfo) == 24061128 * 1024
    assert available_memory_bytes(tmp_path / "missing") is None
    meminfo.write_text("MemTotal: 1 kB\n")
    assert available_memory_bytes(meminfo) is None
    assert particle_bank_bytes(1000, 16, 373, copies=10) == 8.0 * 1000 * (2720 + 373 + 64)
    bank = [("n_particles", 10 ** 6, 10 ** 6, 16, 373, "the lateral RBPF")]
    check_banks(bank, available=int(26e9))                    # 25.3 GB needed: fits
    with pytest.raises(ParameterError) as err:
        check_banks(bank, available=int(10e9))
    assert str(err.value) == ("parameter 'n_particles' = 1000000 needs ≈ 25.3 GB for the lateral "
                              "RBPF (1000000 filters of 16 states), but this machine has 10 GB "
                              "available (MemAvailable): at most 395945 filters fit")
    check_banks([("n_particles", 0, 0, 16, 373, "not run")], available=1)


PEAK = textwrap.dedent("""
    import json, sys
    import numpy as np
    from railpaper.engine import QuasiGaussianRBPF, RaoBlackwellisedPF, run_filter
    from railpaper.models.linear_toys import paper004_system, simulate_paper004
    kind, N = sys.argv[1], int(sys.argv[2])
    rng = np.random.default_rng(0)
    system = paper004_system(1e-3, 1e-3)
    y = simulate_paper004(-0.7, 1.5, 1e-3, 1e-3, 0.05, 8, rng).y
    theta = np.column_stack([rng.uniform(-1, 0.4, N), rng.uniform(1, 2.8, N)])
    open('/proc/self/clear_refs', 'w').write('5')       # peak of the filter, not the imports
    if kind == 'qgrbpf':
        f = QuasiGaussianRBPF(system, theta, np.zeros(2), 0.0025 * np.eye(2), rng)
    else:
        f = RaoBlackwellisedPF(system, theta, np.zeros(2), 0.0025 * np.eye(2), rng,
                               scheme=kind, delta=0.98, ess_fraction=0.8)
    run_filter(f, y)
    status = open('/proc/self/status').read()
    print(int(status.split('VmHWM:')[1].split()[0]) * 1024)
""")


def peak_bytes(kind: str, N: int) -> int:
    out = subprocess.run([sys.executable, "-c", PEAK, kind, str(N)], capture_output=True,
                         text=True, check=True, cwd=REPO, timeout=120)
    return int(out.stdout.split()[-1])


@pytest.mark.skipif(available_memory_bytes() is None, reason="needs /proc/meminfo")
@pytest.mark.parametrize("kind", ["paper", "working", "qgrbpf"])
def test_the_estimate_covers_what_the_filters_take(kind):
    """Peak RSS at N = 100 000 minus at N = 100 (the 2-state toy of chapter 004) is at most the
    estimate, and not a small fraction of it (the estimate is not a blanket refusal)."""
    N = 100_000
    used = peak_bytes(kind, N) - peak_bytes(kind, 100)
    estimate = particle_bank_bytes(N, 2, 6)
    assert 0.25 * estimate < used <= estimate, json.dumps(dict(used=used, estimate=estimate))
