"""A process under mpirun that runs the compiled kernels writes its own output on stdout and nothing after it."""
import os
import subprocess
import sys

import pytest

pytest.importorskip("numba")

SCRIPT = """
import numpy as np
from aquarom_fenics.dynamics import reduced_kernel
from aquarom_fenics.fem import pair_kernel

reduced_kernel.warm_up()
arguments = pair_kernel.synthetic()
m, n = arguments[0].shape[3:]
pair_kernel.whitened_pair_products(*arguments, np.empty((m * (m + 1) // 2, 6, n)))
print("last line")
"""


@pytest.mark.mpi
def test_a_rank_that_ran_the_compiled_kernels_ends_stdout_with_its_last_line(tmp_path):
    import shutil

    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not installed")
    script = tmp_path / "kernels.py"
    script.write_text(SCRIPT)
    environment = {key: value for key, value in os.environ.items() if key != "NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING"}
    completed = subprocess.run(["mpirun", "-n", "1", sys.executable, str(script)], capture_output=True, text=True,
                               timeout=300, env=environment)
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout == "last line\n"
