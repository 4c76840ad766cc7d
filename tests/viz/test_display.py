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


BLOCKED = textwrap.dedent("""\
    import os, subprocess, time
    from aquarom_fenics.viz.display import display_number, ensure_display
    taken = display_number(os.getpid(), 0)
    other = subprocess.Popen(["Xvfb", f":{taken}", "-screen", "0", "64x64x24", "-nolisten", "tcp"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1.0)                      # the other server holds this process's first number
    try:
        ensure_display()
        print(os.environ["DISPLAY"], taken, display_number(os.getpid(), 1))
    finally:
        other.terminate()
        other.wait()
    """)


@pytest.mark.skipif(shutil.which("Xvfb") is None, reason="needs Xvfb")
def test_a_display_number_held_by_another_server_is_passed_over(tmp_path):
    environment = {key: value for key, value in os.environ.items() if key != "DISPLAY"}
    finished = subprocess.run([sys.executable, "-c", BLOCKED], env=environment, cwd=tmp_path, capture_output=True,
                              text=True, timeout=120)
    assert finished.returncode == 0, finished.stderr
    display, taken, second = finished.stdout.split()
    assert display == f":{second}" != f":{taken}"
