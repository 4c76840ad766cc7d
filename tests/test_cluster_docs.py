"""The cluster recipe (docs/user/cluster.rst, docs/user/slurm_dask.sbatch) cannot run here: its job
script, the Dask command lines, the aquarom command lines and the [cluster] snippet are parsed by
the programs that would read them."""
import os
import re
import shlex
import subprocess
import tomllib
from pathlib import Path

import pytest

from aquarom_fenics.cli.parser import build_parser
from aquarom_fenics.io.scene import scene_from_dict

REPOSITORY = Path(__file__).resolve().parents[1]
DOCS = REPOSITORY / "docs" / "user"
JOB_SCRIPT = DOCS / "slurm_dask.sbatch"
SLURM_ENVIRONMENT = {"SLURM_SUBMIT_DIR": "/shared/aquarom", "SLURM_JOB_ID": "4242", "SLURM_NTASKS": "128",
                     "TMPDIR": "/local/tmp"}


def script_commands() -> list[list[str]]:
    """The job script's command lines (continuations joined, commented commands uncommented,
    variables as a 4-node, 128-task allocation would set them), as argument lists."""
    text = JOB_SCRIPT.read_text().replace("\\\n", " ")
    variables = dict(SLURM_ENVIRONMENT)
    commands = []
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("# ") and re.match(r"# (\.venv/bin/aquarom|make) ", line):
            line = line[2:]
        if not line or line.startswith("#"):
            continue
        assignment = re.fullmatch(r'(\w+)=(.*)', line)
        if assignment:
            variables[assignment.group(1)] = expand(assignment.group(2).strip('"'), variables)
            continue
        commands.append(shlex.split(expand(line.rstrip("&").strip(), variables)))
    return commands


def expand(text: str, variables: dict) -> str:
    text = text.replace("$((SLURM_NTASKS - 1))", str(int(variables["SLURM_NTASKS"]) - 1))
    text = re.sub(r"\$\{(\w+):-[^}]*\}", lambda m: variables.get(m.group(1), ""), text)
    return re.sub(r"\$\{?(\w+)\}?", lambda m: variables.get(m.group(1), m.group(0)), text)


def after(command: list[str], marker: str) -> list[str]:
    return command[command.index(marker) + 1:]


def test_job_script_is_valid_bash_with_well_formed_sbatch_directives():
    subprocess.run(["bash", "-n", str(JOB_SCRIPT)], check=True)
    directives = [line for line in JOB_SCRIPT.read_text().splitlines() if line.startswith("#SBATCH")]
    assert len(directives) >= 5
    for line in directives:
        assert re.fullmatch(r"#SBATCH --[a-z-]+=\S+", line), line
    options = dict(line.split()[1].lstrip("-").split("=", 1) for line in directives)
    assert int(options["nodes"]) * int(options["ntasks-per-node"]) == int(SLURM_ENVIRONMENT["SLURM_NTASKS"])
    assert options["cpus-per-task"] == "1"


def test_scheduler_and_worker_command_lines_parse_with_dasks_own_options():
    from distributed.cli import dask_scheduler, dask_worker

    commands = script_commands()
    scheduler = next(c for c in commands if "distributed.cli.dask_scheduler" in c)
    worker = next(c for c in commands if "distributed.cli.dask_worker" in c)
    assert scheduler[0] == worker[0] == "srun" and "--exact" in scheduler and "--exact" in worker
    assert f"--ntasks={int(SLURM_ENVIRONMENT['SLURM_NTASKS']) - 1}" in worker
    scheduler_options = dask_scheduler.main.make_context("dask-scheduler",
                                                         after(scheduler, "distributed.cli.dask_scheduler")).params
    worker_options = dask_worker.main.make_context("dask-worker", after(worker, "distributed.cli.dask_worker")).params
    shared = "/shared/aquarom/results/dask-scheduler-4242.json"
    assert scheduler_options["scheduler_file"] == worker_options["scheduler_file"] == shared
    assert worker_options["nthreads"] == 1 and int(worker_options["n_workers"]) == 1 and worker_options["nanny"]
    assert worker_options["local_directory"] == "/local/tmp"


def test_aquarom_and_make_command_lines_of_the_script_parse():
    commands = script_commands()
    runs = [c for c in commands if c[0].endswith("aquarom")]
    assert {c[1] for c in runs} == {"sweep", "pareto"}
    for command in runs:
        args = build_parser().parse_args(command[1:])
        assert str(args.scheduler_file) == "/shared/aquarom/results/dask-scheduler-4242.json"
        assert args.connect_timeout == 300 and args.scheduler is None
    make = next(c for c in commands if c[0] == "make")
    assert make[1] == "validate" and make[2].startswith("SCHEDULER_FILE=")
    assert "$(SCHEDULER_FILE)" in (REPOSITORY / "Makefile").read_text()


def test_the_cluster_table_of_the_docs_loads_into_a_scene(tmp_path):
    page = (DOCS / "cluster.rst").read_text()
    [snippet] = re.findall(r"\.\. code-block:: toml\n\n((?:   .*\n)+)", page)
    table = tomllib.loads("\n".join(line[3:] for line in snippet.splitlines()))
    scene = scene_from_dict(table, source=str(tmp_path / "scene.toml"), base_dir=str(tmp_path))
    assert scene.cluster.scheduler_file == str(tmp_path / "dask-scheduler.json")
    assert scene.cluster.connect_timeout == 60.0
    assert scene.hash == scene_from_dict({}, source=str(tmp_path / "scene.toml")).hash   # not part of the study


def test_every_command_line_of_the_docs_pages_parses():
    for page in ("cluster.rst", "sweep.rst"):
        for line in re.findall(r"^   \$ (aquarom .*)$", (DOCS / page).read_text(), flags=re.M):
            words = shlex.split(line.split("#")[0])
            build_parser().parse_args([os.path.expanduser(word) for word in words[1:]])


@pytest.mark.parametrize("table, message", [
    ({"scheduler": "tcp://a:8786", "scheduler_file": "f.json"}, "not both"),
    ({"address": "tcp://a:8786"}, "unknown key [cluster] address"),
    ({"connect_timeout": 0}, "positive number of seconds"),
])
def test_a_bad_cluster_table_is_refused_in_one_line(table, message):
    from aquarom_fenics.errors import InputError

    with pytest.raises(InputError, match=re.escape(message)):
        scene_from_dict({"cluster": table}, source="scene.toml")
