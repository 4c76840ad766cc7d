"""The virtual display: processes that start one at the same moment each get their own."""
import os
import shutil
import subprocess
import sys
import textwrap

import pytest

CHILD = textwrap.dedent("""\
    import os, sys, time
    from aquarom_fenics.viz.display import ensure_display
    sys.stdin.readline()                 # all children start their servers together
    ensure_display()
    print(os.environ["DISPLAY"], flush=True)
    time.sleep(2.0)                      # the servers overlap in time
    """)


@pytest.mark.skipif(shutil.which("Xvfb") is None, reason="needs Xvfb")
def test_processes_starting_at_once_get_distinct_displays(tmp_path):
    """Xvfb's ``-displayfd`` alone let two servers started together take one number (seen with 12
    processes); the start lock serialises the starts."""
    environment = {key: value for key, value in os.environ.items() if key != "DISPLAY"}
    children = [subprocess.Popen([sys.executable, "-c", CHILD], env=environment, cwd=tmp_path, text=True,
                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
                for _ in range(8)]
    for child in children:
        child.stdin.write("go\n")
        child.stdin.flush()
    displays = []
    for child in children:
        out, err = child.communicate(timeout=120)
        assert child.returncode == 0, err
        displays.append(out.strip())
    assert all(display.startswith(":") for display in displays)
    assert len(set(displays)) == len(displays), displays
