"""A command writes its output and the named caches, nothing else: the user's home (gmsh's FLTK
preferences included), the temporary folder (Open MPI's session folder included) and the working
directory are as they were once it has ended."""
import os
import subprocess
import sys
from pathlib import Path

from aquarom_fenics.io.paths import forms_cache

from conftest import write_short_scene


def excluded_caches(forms: Path, xdg_cache: Path, toolkit_cache: Path) -> list[Path]:
    """The folders a command may write besides its output: the compiled forms' cache
    ($AQUAROM_JIT_CACHE), the user's cache folder ($XDG_CACHE_HOME: matplotlib's font list) and the
    toolkit's cache ($AQUAROM_CACHE)."""
    return [forms, xdg_cache, toolkit_cache]


def files_under(folder: Path, excluded: list[Path]) -> set[str]:
    """Every file and folder below ``folder``, relative to it, outside the ``excluded`` folders (a
    folder that vanishes while it is listed is skipped: another process may be removing it)."""
    found = set()
    for root, folders, files in os.walk(folder):
        folders[:] = [name for name in folders if Path(root, name) not in excluded]
        found.update(str(Path(root, name).relative_to(folder)) for name in folders + files)
    return found


def test_mesh_and_simulate_leave_home_temporary_folder_and_working_directory_as_they_were(tmp_path):
    home, temporary, here = tmp_path / "home", tmp_path / "tmp", tmp_path / "here"
    for folder in (home, temporary, here):
        folder.mkdir()
    (home / ".profile").write_text("# the user's own\n")
    forms = forms_cache()                       # the compiled forms are reused: the run stays short
    xdg_cache, toolkit_cache = tmp_path / "xdg-cache", tmp_path / "cache"
    excluded = excluded_caches(forms, xdg_cache, toolkit_cache)
    environment = dict(os.environ, HOME=str(home), TMPDIR=str(temporary), XDG_CACHE_HOME=str(xdg_cache),
                       AQUAROM_CACHE=str(toolkit_cache), AQUAROM_JIT_CACHE=str(forms))
    environment.pop("DISPLAY", None)
    scene = write_short_scene(tmp_path, duration=0.1)
    before = {folder: files_under(folder, excluded) for folder in (home, temporary, here)}
    aquarom = str(Path(sys.executable).with_name("aquarom"))
    for command in (["mesh", "fish"], ["simulate", scene, "--out", str(tmp_path / "run"), "--no-progress"]):
        with open(tmp_path / "said.txt", "w") as said:       # output to a file, as in a batch job:
            done = subprocess.run([aquarom, *command], cwd=here, env=environment, stdout=said,
                                  stderr=subprocess.STDOUT, timeout=300)   # Open MPI then leaves more
        assert done.returncode == 0, (tmp_path / "said.txt").read_text()
        for folder, files in before.items():
            assert files_under(folder, excluded) == files, f"aquarom {command[0]} changed {folder.name}/"
