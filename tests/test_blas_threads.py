"""The suite's processes do their linear algebra on one thread (tests/conftest.py): with three
workers on two cores a second BLAS thread only spins, and burns CPU the other workers need.
The nodes a test starts inherit the setting."""

import json
import subprocess
import sys

import threadpoolctl

THREADS = """
import json, numpy, scipy.linalg, sklearn.linear_model, threadpoolctl
print(json.dumps([pool["num_threads"] for pool in threadpoolctl.threadpool_info()]))
"""


def test_a_worker_and_the_processes_it_starts_use_one_blas_thread():
    import numpy  # noqa: F401  (OpenBLAS loaded, as in any test)

    assert {pool["num_threads"] for pool in threadpoolctl.threadpool_info()} == {1}
    child = subprocess.run([sys.executable, "-c", THREADS], capture_output=True, text=True, check=True)
    pools = json.loads(child.stdout)
    assert len(pools) == 3 and set(pools) == {1}  # numpy's and scipy's OpenBLAS, scikit-learn's OpenMP
