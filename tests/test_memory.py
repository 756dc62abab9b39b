"""keep_freed_memory: a paper-scheme filter's steps stop faulting in fresh pages.

Run in a fresh process (the setting is per process, and the test workers have made filters
already): the same filter's steps before and after the call, minor page faults counted by the
kernel (``getrusage``).  Before: hundreds per step at N = 1000 on glibc; after: none.
"""

import platform
import subprocess
import sys

import pytest

SCRIPT = """
import resource
import numpy as np
import railpaper.memory as memory
from railpaper.bench.rbpf_engine import lateral_problem, make_filter

memory._state["applied"] = False          # as if the C library had no mallopt: nothing set
prob = lateral_problem(120)
filt = make_filter(prob, "rbpf-paper", 1000)

def faults_per_step(k0, k1):
    r0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for k in range(k0, k1):
        filt.step(prob["y"][k], prob["u"][k])
    return (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - r0) / (k1 - k0)

faults_per_step(0, 10)
before = faults_per_step(10, 40)
memory._state["applied"] = None
assert memory.keep_freed_memory()
faults_per_step(40, 50)
print(before, faults_per_step(50, 80))
"""


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc",
                    reason="mallopt's thresholds are glibc's")
def test_filter_steps_fault_in_no_pages_once_freed_memory_is_kept():
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True,
                         check=True, timeout=300)
    before, after = map(float, out.stdout.split())
    assert before > 100, before             # the effect exists where the test runs
    assert after < 5, after
