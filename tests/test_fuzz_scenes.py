"""Mutated shipped scenes never crash the command line: exit 0, 2 or 3, no traceback.

Seeded and bounded: every run mutates the same scenes the same way, and the CLI validates them
through `--dry-run` (scene loader, argument checks, time grid, design space, plan) without
running a solver.
"""
import copy
import json
import math
import random
import time
import tomllib

from aquarom_fenics.cli import main
from aquarom_fenics.io.scene import SCENES_DIR

SEED = 2026
SCENES = 300
TIME_BUDGET = 60.0     # s, for all of them
ODD_VALUES = [-1, 0, 1, 3, 0.5, -0.5, 1e300, -1e-300, 2 ** 70, math.nan, math.inf, -math.inf, True, False,
              "text", "paper", "", [], [1.0], [1.0, 2.0, 3.0], [0.5, -0.5], {}, {"bounds": [0.0, 0.0]}]
COMMANDS = [["simulate"], ["simulate", "--model", "prom"], ["simulate", "--model", "rom"], ["build"],
            ["compare"], ["optimize"], ["optimize", "--method", "trust-region"], ["pareto"], ["shapes"]]


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{json.dumps(key)} = {toml_value(item)}" for key, item in value.items()) + " }"
    return str(value)


def to_toml(data: dict) -> str:
    """TOML text of a scene dictionary: scalars, [tables] and [[arrays of tables]]."""
    lines = [f"{json.dumps(key)} = {toml_value(value)}" for key, value in data.items()
             if not isinstance(value, dict) and not (isinstance(value, list) and value and
                                                     all(isinstance(item, dict) for item in value))]
    for key, value in data.items():
        if isinstance(value, dict):
            lines.append(f"[{json.dumps(key)}]")
            lines += [f"{json.dumps(name)} = {toml_value(item)}" for name, item in value.items()]
        elif isinstance(value, list) and value and all(isinstance(item, dict) for item in value):
            for item in value:
                lines.append(f"[[{json.dumps(key)}]]")
                lines += [f"{json.dumps(name)} = {toml_value(entry)}" for name, entry in item.items()]
    return "\n".join(lines) + "\n"


def leaves(data, path=()):
    """Paths to every value in nested tables and lists."""
    items = data.items() if isinstance(data, dict) else enumerate(data) if isinstance(data, list) else ()
    for key, value in items:
        yield path + (key,)
        yield from leaves(value, path + (key,))


def container(data, path):
    for key in path[:-1]:
        data = data[key]
    return data


def odd_value(rng: random.Random):
    """A fresh copy of one of ODD_VALUES: the lists among them are mutated later, and a shared one
    put into itself would make a cyclic scene (no TOML has one)."""
    return copy.deepcopy(rng.choice(ODD_VALUES))


def mutate(data: dict, rng: random.Random) -> dict:
    """One to three structural mutations: delete, replace with an odd value, scale, add a key."""
    for _ in range(rng.randint(1, 3)):
        paths = list(leaves(data))
        kind = rng.choice(["delete", "replace", "scale", "add"])
        if not paths or kind == "add":
            target = rng.choice([data] + [v for v in data.values() if isinstance(v, dict)])
            target[rng.choice(["extra", "level", "bounds", "weights", "z_tail", "method"])] = odd_value(rng)
            continue
        path = rng.choice(paths)
        parent = container(data, path)
        if kind == "delete":
            del parent[path[-1]]
        elif kind == "replace":
            parent[path[-1]] = odd_value(rng)
        elif isinstance(parent[path[-1]], (int, float)) and not isinstance(parent[path[-1]], bool):
            parent[path[-1]] = parent[path[-1]] * rng.choice([-10, -1, 0, 1e-6, 1e6])
    return data


def corrupt_text(text: str, rng: random.Random) -> str:
    """A byte-level slip: a character dropped, or a stray one inserted."""
    position = rng.randrange(len(text))
    if rng.random() < 0.5:
        return text[:position] + text[position + 1:]
    return text[:position] + rng.choice(["=", "[", "]", '"', "\n", "{", ",", "é"]) + text[position:]


def arguments(scene: dict, rng: random.Random) -> list[str]:
    command = list(rng.choice(COMMANDS))
    shapes = list(scene.get("shapes", {})) if isinstance(scene.get("shapes"), dict) else []
    for _ in range(rng.randint(0, 2)):
        name = rng.choice(shapes + ["z_tail", "nonsense"])
        command += ["--xi", f"{name}={rng.choice(['0.05', '-0.1', '1e9', 'nan', 'x', '0'])}"]
    if rng.random() < 0.3:
        command += ["--level", str(rng.randint(1, 5))]
    return command


def test_mutated_shipped_scenes_exit_0_2_or_3_without_traceback(tmp_path, capsys):
    rng = random.Random(SEED)
    shipped = sorted(SCENES_DIR.glob("*.toml"))
    originals = {path.stem: tomllib.loads(path.read_text()) for path in shipped}
    (tmp_path / "meshes").symlink_to(SCENES_DIR.parent / "meshes")    # the fish scenes' ../meshes/ files, as shipped
    (tmp_path / "scenes").mkdir()
    started = time.perf_counter()
    codes = []
    for number in range(SCENES):
        name = rng.choice(sorted(originals))
        data = mutate(json.loads(json.dumps(originals[name])), rng)
        text = to_toml(data)
        if rng.random() < 0.25:
            text = corrupt_text(text, rng)
        scene = tmp_path / "scenes" / f"{number:03d}-{name}.toml"
        scene.write_text(text)
        command = arguments(data, rng)
        argv = [command[0], str(scene), *command[1:], "--dry-run", "--out", str(tmp_path / "out")]
        try:
            code = main(argv)
        except SystemExit as exit_:       # argparse refusing an argument
            code = exit_.code
        captured = capsys.readouterr()
        assert code in (0, 2, 3), (argv, text, captured.err)
        assert "Traceback" not in captured.err, (argv, text, captured.err)
        if code == 2 and not captured.err.startswith("usage:"):
            assert len(captured.err.strip().splitlines()) == 1, (argv, text, captured.err)
        codes.append(code)
    elapsed = time.perf_counter() - started
    assert elapsed < TIME_BUDGET, f"{SCENES} mutated scenes took {elapsed:.1f} s"
    assert not (tmp_path / "out").exists()
    # the mutations reach both sides: some scenes stay valid, many are refused
    assert codes.count(0) >= 10 and codes.count(2) >= 100, {c: codes.count(c) for c in set(codes)}
