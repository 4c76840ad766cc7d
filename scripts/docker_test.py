"""`make docker-test`: the Docker image builds from the repository, passes the test suite, runs the
demo and reproduces the host's results.

Needs the `docker` command, a running Docker daemon and a `debian:bookworm` base image
(docker/README.md makes one with debootstrap where the registry cannot be reached); without one
of them it prints one line and exits 2. Writes results/bench/docker.json: build time, sizes of
the build context and the image, test counts, demo time, what the image's FFCx cache saves, the
nominal FOM distance (2 MPI ranks, the scene's own mesh) and the SO1 optimum (level 1) in the
container next to the same runs on the host. Exit 1 when a check fails (the JSON is written).
"""
import argparse
import itertools
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

from aquarom_fenics.io.persistence import write_json_atomic

REPOSITORY = Path(__file__).resolve().parents[1]
IMAGE = "aquarom-fenicsx"
BASE_IMAGE = "debian:bookworm"
AGREEMENT = 1e-10          # relative, container against host
CONTEXT_LIMIT = 10e6       # bytes
RUN_LIMIT = 3600           # s, any one run; a container is killed after it
RUN_NUMBERS = itertools.count(1)
NOT_ROOT = (65534, 65534)  # uid, gid the container runs as when docker-test is run by root


class Missing(Exception):
    """Something docker-test needs is not there (exit 2)."""


def docker(*arguments: str, check: bool = True, timeout: float | None = None) -> subprocess.CompletedProcess:
    """Run `docker ARGUMENTS`, output captured; a failure ends the study with docker's message."""
    completed = subprocess.run(["docker", *arguments], capture_output=True, text=True, timeout=timeout)
    if check and completed.returncode != 0:
        raise RuntimeError(f"docker {' '.join(arguments[:3])} … failed ({completed.returncode}):\n"
                           f"{completed.stdout[-3000:]}\n{completed.stderr[-3000:]}")
    return completed


def require_docker() -> None:
    if shutil.which("docker") is None:
        raise Missing("needs the `docker` command (Debian: apt-get install docker.io)")
    if docker("info", check=False).returncode != 0:
        raise Missing("no Docker daemon answers (start one: dockerd, or systemctl start docker)")
    if docker("image", "inspect", BASE_IMAGE, check=False).returncode != 0:
        raise Missing(f"needs the base image {BASE_IMAGE} (docker pull {BASE_IMAGE}, or build it "
                      f"with debootstrap as docker/README.md shows)")


def timed(function, *arguments):
    """(result, wall seconds) of function(*arguments)."""
    started = time.perf_counter()
    result = function(*arguments)
    return result, time.perf_counter() - started


def git_head() -> str:
    answer = subprocess.run(["git", "-C", str(REPOSITORY), "rev-parse", "HEAD"], capture_output=True, text=True)
    return answer.stdout.strip() or "unknown"


def build_image(reuse_layers: bool) -> dict:
    """docker build with the legacy builder, whose log states the size of the context it sends."""
    options = [] if reuse_layers else ["--no-cache"]
    started = time.perf_counter()
    completed = subprocess.run(
        ["docker", "build", *options, "-f", "docker/Dockerfile", "--build-arg", f"AQUAROM_GIT_COMMIT={git_head()}",
         "-t", IMAGE, "."], cwd=REPOSITORY, capture_output=True, text=True, env=os.environ | {"DOCKER_BUILDKIT": "0"})
    seconds = time.perf_counter() - started
    if completed.returncode != 0:
        raise RuntimeError(f"docker build failed:\n{completed.stdout[-3000:]}\n{completed.stderr[-3000:]}")
    context = re.search(r"Sending build context to Docker daemon\s+([\d.]+)\s*([kMG]?B)", completed.stdout)
    units = {"B": 1, "kB": 1e3, "MB": 1e6, "GB": 1e9}
    image_bytes = int(docker("image", "inspect", "-f", "{{.Size}}", IMAGE).stdout)
    return {"seconds": round(seconds, 1), "layers_reused": reuse_layers,
            "context_bytes": round(float(context[1]) * units[context[2]]) if context else None,
            "image_bytes": image_bytes, "image_gb": round(image_bytes / 1e9, 2)}


def pytest_counts(output: str) -> dict:
    """{'passed': n, 'failed': m, ...} from pytest's last summary line ("335 passed, 2 skipped in …")."""
    lines = [line for line in output.splitlines() if re.search(r"\d+ (passed|failed|error)", line)]
    if not lines:
        raise RuntimeError(f"make test in the container printed no pytest summary:\n{output[-3000:]}")
    summary = lines[-1]
    return {word: int(number) for number, word in re.findall(r"(\d+) (passed|failed|errors?|skipped|xfailed|xpassed)",
                                                             summary)} | {"summary": summary.strip("= ")}


FRESH = {"HOME": "/tmp/empty-home", "AQUAROM_JIT_CACHE": "/tmp/empty-jit-cache"}
"""A container's environment with nothing compiled yet (the image's forms are in /home/aquarom/.cache)."""


def in_container(*arguments: str, entrypoint: str | None = None, user: str | None = None,
                 mount: Path | None = None, environment: dict | None = None,
                 check: bool = True) -> subprocess.CompletedProcess:
    """`docker run --rm IMAGE ARGUMENTS`; `mount` is seen as /results in the container.

    A run longer than RUN_LIMIT is killed and ends the study.
    """
    name = f"aquarom-docker-test-{os.getpid()}-{next(RUN_NUMBERS)}"
    options = ["--rm", "--name", name]
    if entrypoint:
        options += ["--entrypoint", entrypoint]
    if user:
        options += ["--user", user]
    if mount:
        options += ["-v", f"{Path(mount).resolve()}:/results"]
    for name, value in (environment or {}).items():
        options += ["-e", f"{name}={value}"]
    try:
        return docker("run", *options, IMAGE, *arguments, check=check, timeout=RUN_LIMIT)
    except subprocess.TimeoutExpired:
        docker("kill", name, check=False)
        raise RuntimeError(f"docker run {' '.join(arguments[:4])} … took more than {RUN_LIMIT} s; stopped")



def summary(folder: Path) -> dict:
    return json.loads((folder / "summary.json").read_text())


def relative_difference(a: float, b: float) -> float:
    return abs(a - b) / max(abs(a), abs(b))


def nominal_fom(host: Path, container: Path, user: str) -> dict:
    """`mpirun -n 2 aquarom simulate nominal` (the scene's mesh) in the container and on the host."""
    run = ["simulate", "nominal", "--no-progress"]
    completed, container_seconds = timed(lambda: in_container("-n", "2", "aquarom", *run, "--out", "/results/nominal-fom",
                                                              entrypoint="mpirun", user=user, mount=container))
    subprocess.run(["mpirun", "-n", "2", str(REPOSITORY / ".venv/bin/aquarom"), *run, "--out", str(host / "nominal-fom")],
                   check=True, capture_output=True, timeout=RUN_LIMIT, env=os.environ | {"OMPI_ALLOW_RUN_AS_ROOT": "1",
                                                                        "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"})
    inside, outside = summary(container / "nominal-fom"), summary(host / "nominal-fom")
    return {"command": "mpirun -n 2 aquarom simulate nominal", "mpi_ranks": 2,
            "mesh_level": inside["scene_values"]["mesh"]["level"], "cells": inside["cells"],
            "container_distance": inside["distance"], "host_distance": outside["distance"],
            "relative_difference": relative_difference(inside["distance"], outside["distance"]),
            "container_seconds": round(container_seconds, 1),
            "single_copy_warnings": completed.stdout.count("Read -1") + completed.stderr.count("Read -1")}


def so1_optimum(host: Path, container: Path, user: str) -> dict:
    """`aquarom optimize so1 --level 1` in the container (as `user`, not root) and on the host."""
    run = ["optimize", "so1", "--level", "1"]
    in_container(*run, "--out", "/results/so1", user=user, mount=container)
    subprocess.run([str(REPOSITORY / ".venv/bin/aquarom"), *run, "--out", str(host / "so1")], check=True,
                   capture_output=True, timeout=RUN_LIMIT)
    inside, outside = summary(container / "so1"), summary(host / "so1")
    differences = [relative_difference(inside["optimum"][name], outside["optimum"][name]) for name in inside["optimum"]]
    differences.append(relative_difference(inside["fom_check"]["optimal_distance"],
                                           outside["fom_check"]["optimal_distance"]))
    owners = {f"{path.stat().st_uid}:{path.stat().st_gid}" for path in (container / "so1").rglob("*")}
    return {"command": f"docker run --user {user} -v FOLDER:/results {IMAGE} optimize so1 --level 1 --out /results/so1",
            "container_optimum": inside["optimum"], "host_optimum": outside["optimum"],
            "container_fom_optimal_distance": inside["fom_check"]["optimal_distance"],
            "host_fom_optimal_distance": outside["fom_check"]["optimal_distance"],
            "iterations": [inside["iterations"], outside["iterations"]],
            "max_relative_difference": max(differences),
            "outputs_owned_by_container_user": owners == {user}}


def ffcx_cache_saving() -> dict:
    """Wall time of `aquarom simulate nominal --level 1` with the image's compiled forms and with none."""
    run = ["simulate", "nominal", "--level", "1", "--no-progress", "--out", "/tmp/nominal"]
    _, warm = timed(in_container, *run)
    _, cold = timed(lambda: in_container(*run, environment=FRESH))
    size = in_container("-sb", "/home/aquarom/.cache/fenics", entrypoint="du").stdout.split()[0]
    return {"command": "aquarom simulate nominal --level 1", "with_image_cache_seconds": round(warm, 1),
            "empty_cache_seconds": round(cold, 1), "saved_seconds": round(cold - warm, 1),
            "cache_bytes": int(size)}


def main() -> int:
    """Exit 0 when every check passes, 1 when one fails or a docker step breaks, 2 when docker is missing."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "bench" / "docker.json")
    parser.add_argument("--reuse-layers", action="store_true", help="let docker build reuse cached layers")
    args = parser.parse_args()
    try:
        require_docker()
    except Missing as missing:
        print(f"docker-test: {missing}", file=sys.stderr)
        return 2
    try:
        report = study(args.reuse_layers)
    except (RuntimeError, subprocess.CalledProcessError, subprocess.TimeoutExpired) as error:
        print(f"docker-test: {error}", file=sys.stderr)
        return 1
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out, report)
    failed = [name for name, passed in report["checks"].items() if not passed]
    print(f"docker-test: {'FAILED ' + ', '.join(failed) if failed else 'all checks pass'}; {args.out}")
    return 1 if failed else 0


def study(reuse_layers: bool) -> dict:
    """Build, test, demo, then the container's results against the host's."""
    work = REPOSITORY / "results" / "docker" / time.strftime("%Y%m%dT%H%M%S")   # fresh: no --force under MPI
    host, container = work / "host", work / "container"
    for folder in (host, container):
        folder.mkdir(parents=True, exist_ok=True)
    uid, gid = (os.getuid(), os.getgid()) if os.getuid() != 0 else NOT_ROOT
    os.chown(container, uid, gid)         # the container writes as the folder's owner, never as root
    user = f"{uid}:{gid}"
    print("docker-test: building the image", flush=True)
    report = {"image": IMAGE, "base_image": BASE_IMAGE, "build": build_image(reuse_layers), "host_cores": os.cpu_count()}
    print("docker-test: make test in the container, on an empty HOME and folder of compiled forms (as CI)", flush=True)
    tests, seconds = timed(lambda: in_container("-c", 'mkdir -p "$HOME" && make test', entrypoint="bash",
                                                 check=False, environment=FRESH).stdout)
    (container.parent / "make-test.log").write_text(tests)      # what failed, when something did
    report["tests"] = pytest_counts(tests) | {"seconds": round(seconds, 1)}
    print("docker-test: make demo in the container", flush=True)
    _, seconds = timed(lambda: in_container("demo", "OUT=/tmp/demo", entrypoint="make"))
    report["demo_seconds"] = round(seconds, 1)
    print("docker-test: nominal FOM, SO1 optimum and FFCx cache, container against host", flush=True)
    report["nominal_fom"] = nominal_fom(host, container, user)
    report["so1_optimize"] = so1_optimum(host, container, user)
    report["ffcx_cache"] = ffcx_cache_saving()
    report["checks"] = {
        "context_under_10_mb": report["build"]["context_bytes"] is not None
                               and report["build"]["context_bytes"] < CONTEXT_LIMIT,
        "no_failed_tests": report["tests"].get("failed", 0) == 0 and "error" not in report["tests"]
                           and "errors" not in report["tests"],
        "nominal_distance_agrees": report["nominal_fom"]["relative_difference"] <= AGREEMENT,
        "so1_optimum_agrees": report["so1_optimize"]["max_relative_difference"] <= AGREEMENT,
        "so1_outputs_owned_by_container_user": report["so1_optimize"]["outputs_owned_by_container_user"],
        "no_single_copy_warnings": report["nominal_fom"]["single_copy_warnings"] == 0}
    return report


if __name__ == "__main__":
    sys.exit(main())
