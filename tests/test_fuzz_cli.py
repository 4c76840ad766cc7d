"""Generated scenes and command lines never crash the command line nor touch what is not theirs.

Property-based (Hypothesis), derandomised: every run draws the same 500 cases. For each case:
no traceback, an exit code among the documented ones, no file outside the command's output
changed, and nothing of the user's inside it lost (checksums before and after).

Three families, all in-process (``main`` called directly, ``SystemExit`` of the argument parser
caught): mutated scenes on every scene subcommand with ``--dry-run`` (the scene, argument,
time-grid, design-space and plan checks, without a solver); short real runs of the cheap
commands (a reduced simulation from a stored PROM, a PROM build served by the cache, mesh,
animate of one frame, cache list and clear) aimed at a sandbox of user files, toolkit outputs
and odd paths, with and without --force; and command lines of random tokens.
"""
import hashlib
import json
import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aquarom_fenics.cli import main
from aquarom_fenics.io.scene_sections import SECTIONS
from test_fuzz_scenes import to_toml

EXIT_CODES = {0, 1, 2, 3, 130, 143}
"""The documented exit codes: success, a failed check (``check``), bad input or OS error, a
solver stop, Ctrl-C, SIGTERM."""

FUZZ = dict(derandomize=True, database=None, deadline=None, print_blob=True,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                   HealthCheck.data_too_large])

BASE = {"mesh": {"level": 1}, "solver": {"duration": 0.2},
        "shapes": {"z_tail": {"bounds": [-0.2, 0.2]}, "y_thin": {"bounds": [-0.1, 0.1]}}}

SCENE_COMMANDS = ["mesh", "shapes", "simulate", "build", "compare", "optimize", "pareto", "basis", "check"]

ODD = st.one_of(
    st.integers(-3, 6), st.floats(allow_nan=True, allow_infinity=True), st.booleans(), st.text(max_size=6),
    st.sampled_from([1e-9, 1e-4, 1e300, -1e-300, 2 ** 70, "paper", "trust-region", "generalized-alpha", "",
                     [0.05, 0.4], [0.5], [], {}, {"bounds": [0.0, 0.0]}]),
    st.lists(st.floats(-1, 1), max_size=3))


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def checksums(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): digest(p) for p in sorted(folder.rglob("*")) if p.is_file()}


def run(argv: list[str], capsys) -> tuple[int, str]:
    """Exit code and stderr of ``aquarom ARGV``; any exception but the parser's SystemExit fails."""
    try:
        code = main(argv)
    except SystemExit as exit_:
        code = exit_.code
    error = capsys.readouterr().err
    assert "Traceback" not in error, (argv, error)
    assert code in EXIT_CODES, (argv, code, error)
    if code == 2 and not error.startswith("usage:"):
        # one error line; `warning:` lines before it (e.g. an --xi outside the bounds) are aside
        errors = [line for line in error.strip().splitlines() if not line.startswith("warning:")]
        assert len(errors) == 1, (argv, error)
    return code, error


# ---------------------------------------------------------------------- strategies
@st.composite
def scenes(draw) -> str:
    """TOML text of the base scene with 0 … 3 mutations, sometimes slipped at the byte level."""
    data = json.loads(json.dumps(BASE))
    for _ in range(draw(st.sampled_from([0, 0, 1, 1, 2, 3]))):
        section = draw(st.sampled_from([*SECTIONS, "shapes", "top", "constraints"]))
        if section == "top":
            data[draw(st.sampled_from(["name", "description", "extra"]))] = draw(ODD)
        elif section == "shapes":
            name = draw(st.sampled_from(["z_tail", "y_thin", "z_head", "nonsense"]))
            data["shapes"][name] = draw(st.one_of(ODD, st.fixed_dictionaries(
                {"bounds": st.lists(st.floats(-1, 1), max_size=3)}, optional={"start": ODD, "radius": ODD})))
        elif section == "constraints":
            data["constraints"] = [{"coefficients": {"z_tail": draw(ODD)}, "upper": draw(ODD)}]
        else:
            from dataclasses import fields

            known = {f.name: f.default for f in fields(SECTIONS[section])}
            key = draw(st.sampled_from(sorted(known) + ["unknown"]))
            default = known.get(key)
            plausible = (isinstance(default, (int, float)) and not isinstance(default, bool)
                         and section != "mesh" and draw(st.booleans()))
            value = type(default)(default * draw(st.sampled_from([0.5, 1, 2]))) if plausible else draw(ODD)
            data.setdefault(section, {})[key] = value
    text = to_toml(data)
    slip = draw(st.sampled_from(["none", "none", "none", "bom", "drop", "insert", "nest"]))
    position = draw(st.integers(0, max(len(text) - 1, 0)))
    if slip == "bom":
        text = "\ufeff" + text
    elif slip == "drop":
        text = text[:position] + text[position + 1:]
    elif slip == "insert":
        text = text[:position] + draw(st.sampled_from(["=", "[", "]", '"', "\n", "{", ",", "é"])) + text[position:]
    elif slip == "nest":
        depth = draw(st.integers(2, 3000))
        text += "deep = " + "[" * depth + "]" * depth + "\n"
    return text


def scene_arguments(command: str):
    """The options a scene subcommand takes, drawn with odd values among valid ones."""
    xi = st.lists(st.builds(lambda n, v: ["--xi", f"{n}={v}"], st.sampled_from(["z_tail", "y_thin", "bad", ""]),
                            st.sampled_from(["0.05", "-0.1", "0.01", "1e9", "nan", "x", "0", ""])), max_size=1)
    options = {"--level": st.sampled_from(["1", "1", "2", "0", "x"]), "--degree": st.sampled_from(["1", "2", "3"])}
    if command in ("simulate", "compare"):
        options["--model"] = st.sampled_from(["fom", "rom", "prom", "pod"] if command == "simulate" else ["rom", "prom"])
    if command == "optimize":
        options |= {"--method": st.sampled_from(["paper", "trust-region", "newton"]),
                    "--weight": st.sampled_from(["0.5", "2", "-1", "nan"]),
                    "--max-time": st.sampled_from(["10", "0", "-5", "inf"])}
    chosen = st.dictionaries(st.sampled_from(sorted(options)), st.none(), max_size=3)

    @st.composite
    def build(draw):
        argv = []
        for name in draw(chosen):
            argv += [name, draw(options[name])]
        if command in ("shapes", "simulate", "build", "compare"):
            for pair in draw(xi):
                argv += pair
        flags = ["--allow-large"] + (["--force"] if command not in ("mesh", "check") else [])
        flags += ["--resume"] if command == "optimize" else []
        flags += ["--no-progress"] if command in ("simulate", "compare") else []
        argv += draw(st.lists(st.sampled_from(flags), unique=True, max_size=2))
        return argv

    return build()


# ---------------------------------------------------------------------- the sandbox
@pytest.fixture(scope="module")
def template(tmp_path_factory):
    """A folder of user files, toolkit outputs and odd paths, and a PROM file and run to use."""
    root = tmp_path_factory.mktemp("fuzz")
    cache = root / "cache"
    patch = pytest.MonkeyPatch()
    patch.setenv("AQUAROM_CACHE", str(cache))
    scene = root / "base.toml"
    scene.write_text(to_toml(BASE))
    prom = root / "base-prom.npz"
    assert main(["build", str(scene), "--out", str(prom)]) == 0
    sandbox = root / "sandbox"
    assert main(["simulate", str(scene), "--model", "prom", "--prom", str(prom), "--out", str(sandbox / "run"),
                 "--no-progress"]) == 0
    (sandbox / "user").mkdir()
    (sandbox / "user" / "notes.txt").write_text("my notes")
    (sandbox / "user" / "data.csv").write_text("a,b\n1,2\n")
    shutil.copytree(sandbox / "run", sandbox / "mixed")
    (sandbox / "mixed" / "thesis.tex").write_text("\\chapter{mine}")
    (sandbox / "empty").mkdir()
    (sandbox / "clip.mp4").write_text("my film")
    (sandbox / "p.npz").write_text("my archive")
    shutil.copy(prom, sandbox / "prom.npz")
    yield {"root": root, "scene": scene, "prom": prom, "sandbox": sandbox, "cache": cache}
    patch.undo()


USER_FILES = ["user/notes.txt", "user/data.csv", "mixed/thesis.tex", "clip.mp4", "p.npz"]
TARGETS = ["user", "mixed", "run", "empty", "new", "new/a/b", "clip.mp4", "p.npz", "prom.npz", "user/notes.txt",
           "clip.mp4/below", "run/animation.mp4", "user/x.mp4", "mixed/y.npz", "."]


@pytest.fixture
def sandbox(template, tmp_path, monkeypatch):
    """A fresh copy of the template's sandbox for each test (the cases of one test share it)."""
    monkeypatch.setenv("AQUAROM_CACHE", str(template["cache"]))
    copy = tmp_path / "sandbox"
    shutil.copytree(template["sandbox"], copy)
    return copy


# ---------------------------------------------------------------------- family 1: scenes, every subcommand, dry runs
CASES = {"scenes": 300, "real runs": 120, "tokens": 80}
"""Cases drawn per family (500 in all)."""
drawn: list[str] = []


@settings(max_examples=CASES["scenes"], **FUZZ)
@given(text=scenes(), data=st.data())
def generated_scene_case(template, sandbox, capsys, text, data):
    drawn.append("scenes")
    command = data.draw(st.sampled_from(SCENE_COMMANDS))
    scene = sandbox.parent / "scene.toml"
    scene.write_text(text)
    target = data.draw(st.sampled_from(TARGETS))
    verbose = ["--verbose"] if data.draw(st.booleans()) else []
    argv = [*verbose, command, str(scene), *data.draw(scene_arguments(command)), "--dry-run"]
    if command not in ("mesh", "check"):
        argv += ["--out", str(sandbox / target)]
    before = checksums(sandbox)
    run(argv, capsys)
    assert checksums(sandbox) == before, argv          # a dry run writes nothing at all


# ---------------------------------------------------------------------- family 2: real cheap runs at the sandbox
def cheap_command(draw, template, sandbox: Path, target: Path) -> tuple[list[str], list[Path]]:
    """A command line that runs for real in well under a second, and the outputs it names."""
    kind = draw(st.sampled_from(["simulate", "build", "mesh", "animate", "animate", "cache"]))
    scene = str(template["scene"])
    force = ["--force"] if draw(st.booleans()) else []
    if kind == "simulate":
        xi = draw(st.sampled_from([[], ["--xi", "z_tail=0.05"], ["--xi", "z_tail=x"], ["--xi", "y_thin=9"]]))
        return ["simulate", scene, "--model", "prom", "--prom", str(template["prom"]), "--out", str(target),
                "--no-progress", *xi, *force], [target]
    if kind == "build":
        return ["build", scene, "--out", str(target), *force], [target]
    if kind == "mesh":
        return ["mesh", scene], []
    if kind == "animate":
        run_dir = sandbox / draw(st.sampled_from(["run", "mixed", "user", "missing"]))
        out = draw(st.sampled_from([None, target]))
        gif = draw(st.sampled_from([[], ["--gif", str(target.with_suffix(".gif"))]]))
        argv = ["animate", str(run_dir), "--stride", "1000", *force, *gif] + (["--out", str(out)] if out else [])
        return argv, [run_dir if out is None else target] + [Path(name) for name in gif[1:]]
    return ["cache", draw(st.sampled_from(["list", "clear"]))], []


@settings(max_examples=CASES["real runs"], **FUZZ)
@given(data=st.data())
def real_run_case(template, sandbox, capsys, data):
    drawn.append("real runs")
    target = sandbox / data.draw(st.sampled_from(TARGETS))
    argv, outputs = cheap_command(data.draw, template, sandbox, target)
    users = {name: digest(sandbox / name) for name in USER_FILES if (sandbox / name).is_file()}
    before = checksums(sandbox)
    code, error = run(argv, capsys)
    for name, checksum in users.items():
        assert (sandbox / name).is_file() and digest(sandbox / name) == checksum, (argv, name, error)
    after = checksums(sandbox)
    named = [output.resolve() for output in outputs]
    allowed = {path for output in named for path in (output, output.with_suffix(".gif"),
                                                     output.parent / "manifest.json")}

    def outside(name: str) -> bool:
        """Not an output (a folder and what is in it, or a file, its GIF and its folder's manifest)."""
        path = (sandbox / name).resolve()
        return not (path in allowed or any(output in path.parents or path.parent.name.startswith(output.name + ".new-")
                                           for output in named))

    changed = {name for name in set(before) | set(after) if before.get(name) != after.get(name)}
    assert not {name for name in changed if outside(name)}, (argv, code, error, changed)
    assert not [p for p in sandbox.rglob("*.aquarom-lock")], "a lock file outlived its run"
    if code != 3:
        assert not [p for p in sandbox.rglob("*.new-*")], (argv, error)
    shutil.rmtree(sandbox)                                   # the next case starts from the template again
    shutil.copytree(template["sandbox"], sandbox)


# ---------------------------------------------------------------------- family 3: random tokens
TOKENS = st.sampled_from(SCENE_COMMANDS + ["animate", "cache", "list", "clear", "nominal", "so1", "co", "--out",
                                           "--force", "--dry-run", "--xi", "z_tail=0.1", "--level", "1", "--model",
                                           "prom", "--kind", "fom", "--resume", "--fps", "0", "--stride", "-1",
                                           "--gif", "x.gif", "-v", "--help-me", "", "é", "--weight", "nan"])


@settings(max_examples=CASES["tokens"], **FUZZ)
@given(tokens=st.lists(TOKENS, min_size=0, max_size=6))
def random_tokens_case(template, sandbox, capsys, tokens):
    drawn.append("tokens")
    if "clear" in tokens:
        tokens = [token for token in tokens if token != "clear"]     # clearing is family 2's
    argv = [token for token in tokens if token not in ("--help-me",)]
    argv = argv if "--dry-run" in argv or not set(argv) & {"simulate", "compare", "optimize", "pareto", "build",
                                                             "shapes", "basis", "check"} else argv + ["--dry-run"]
    before = checksums(sandbox)
    run(argv, capsys)
    changed = {name for name, checksum in checksums(sandbox).items() if before.get(name) != checksum}
    assert not changed or {"mesh", "animate", "cache"} & set(argv), (argv, changed)
    for name in USER_FILES:
        assert (sandbox / name).is_file(), (argv, name)


@pytest.mark.parametrize("family, case", [("scenes", generated_scene_case), ("real runs", real_run_case),
                                          ("tokens", random_tokens_case)])
def test_generated_cases(family, case, template, sandbox, capsys, monkeypatch):
    """Every case of a family holds the properties; the family drew all its cases."""
    monkeypatch.chdir(sandbox)
    drawn.clear()
    case(template, sandbox, capsys)
    assert drawn.count(family) >= CASES[family]
