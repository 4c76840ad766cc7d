"""Scene files: shipped studies (SPEC §11), defaults (SPEC §2, §6), hashing, and bad input
reported by the command line as one line with exit code 2."""
import dataclasses
import itertools
import json
import math
import textwrap
import tomllib
from pathlib import Path

import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.errors import InputError
from aquarom_fenics.io.scene import (
    SCENES_DIR,
    ActuationSection,
    CooptimizationSection,
    FluidSection,
    MaterialSection,
    RegionsSection,
    Scene,
    SolverSection,
    scene_from_dict,
)
from aquarom_fenics.io.command_values import parse_xi_assignments

COARSE = "[mesh]\nlevel = 1\n"


def write_scene(directory: Path, text: str, name: str = "scene.toml") -> Path:
    """Write a scene file (text dedented) and return its path."""
    path = Path(directory) / name
    path.write_text(textwrap.dedent(text))
    return path


def write_box_inp(path: Path, counts=(9, 3, 3), size=(0.20, 0.04, 0.10)) -> Path:
    """An Abaqus C3D4 mesh of the box x ∈ [-L, 0], y ∈ [-W/2, W/2], z ∈ [-H/2, H/2] on a
    structured grid of counts = (n_x, n_y, n_z) nodes, each hexahedron split into the six
    tetrahedra of its Kuhn triangulation (conforming between neighbours). Odd n_y and n_z put
    nodes on the body axis y = z = 0; even ones avoid it."""
    n_x, n_y, n_z = counts
    length, width, height = size
    axes = (
        [-length + length * i / (n_x - 1) for i in range(n_x)],
        [-width / 2 + width * j / (n_y - 1) for j in range(n_y)],
        [-height / 2 + height * k / (n_z - 1) for k in range(n_z)],
    )

    def label(i, j, k):
        return 1 + i + n_x * (j + n_y * k)

    lines = ["*Heading", "structured box", "*Node"]
    for k, j, i in itertools.product(range(n_z), range(n_y), range(n_x)):
        lines.append(f"{label(i, j, k)}, {axes[0][i]:.12g}, {axes[1][j]:.12g}, {axes[2][k]:.12g}")
    lines.append("*Element, type=C3D4, elset=body")
    number = 0
    for i, j, k in itertools.product(range(n_x - 1), range(n_y - 1), range(n_z - 1)):
        for order in itertools.permutations(range(3)):
            corner = [i, j, k]
            vertices = [label(*corner)]
            for axis in order:
                corner[axis] += 1
                vertices.append(label(*corner))
            number += 1
            lines.append(f"{number}, " + ", ".join(map(str, vertices)))
    path.write_text("\n".join(lines) + "\n")
    return path


def run_cli(argv, capfd):
    """(exit code, stdout, stderr) of ``aquarom argv``."""
    code = main([str(arg) for arg in argv])
    out, err = capfd.readouterr()
    return code, out, err


def assert_one_line_error(code, out, err, command, *names):
    assert code == 2, (code, out, err)
    assert "Traceback" not in out + err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert len(err.strip().splitlines()) == 1, err
    assert lines[0].startswith(f"aquarom {command}: error: "), lines[0]
    for name in names:
        assert name in lines[0], (name, lines[0])


# ---------------------------------------------------------------------------------------------
# Shipped scenes (SPEC §11)

SO1 = {"z_tail": (-0.5, 0.5), "z_head": (-0.5, 0.5), "y_thin": (-0.15, 0.15)}
SO2 = {"z_tail": (-0.5, 0.5), "z_head": (-0.5, 0.5), "y_lin_long_tail": (-0.4, 0.4),
       "y_head": (-0.5, 0.5), "y_ellipse": (-0.5, 0.5)}
SO3 = {"z_tail": (-0.5, 0.5), "z_head": (-0.5, 0.5), "y_lin_long_tail": (-0.3, 0.3),
       "y_head": (-0.4, 0.4), "y_ellipse": (-0.4, 0.4), "z_small": (-0.25, 0.25),
       "z_notch": (-0.25, 0.25), "xz_concave_tail": (-0.01, 0.2)}
SO7 = {"z_tail": (-0.5, 0.5), "z_head": (-0.5, 0.5), "y_thin": (-0.15, 0.15),
       "y_fin": (-0.02, 0.3), "y_notch": (-0.3, 0.3)}
SO8 = {"z_tail": (-0.5, 0.5), "z_head": (-0.5, 0.5), "y_thin": (-0.15, 0.15),
       "y_lin_long_tail": (-0.4, 0.4), "y_head": (-0.4, 0.4)}
SO9 = {"z_tail": (-0.5, 0.5), "z_head": (-0.5, 0.5), "z_tail_step": (-0.5, 0.5),
       "z_tail_lin": (-0.5, 0.5), "y_lin_long_tail": (-0.4, 0.4), "y_ellipse": (-0.4, 0.4)}

DEFAULT_MESH = tuple(json.loads((Path(__file__).resolve().parents[2] / "docs" / "data" / "validation"
                                  / "mesh_convergence.json").read_text())["default"][key] for key in ("level", "degree"))
"""(level, degree) the mesh-convergence study chose: the cheapest mesh within 3 % of the converged distance
(its committed snapshot docs/data/validation/mesh_convergence.json)."""
FINE_MESH = (4, 1)         # SO4–SO6: SO1–SO3 on the 16k-cell level (SPEC §11)
STUDIES = {
    "so1": (SO1, DEFAULT_MESH), "so2": (SO2, DEFAULT_MESH), "so3": (SO3, DEFAULT_MESH),
    "so4": (SO1, FINE_MESH), "so5": (SO2, FINE_MESH), "so6": (SO3, FINE_MESH),
    "so7": (SO7, DEFAULT_MESH), "so8": (SO8, DEFAULT_MESH), "so9": (SO9, DEFAULT_MESH),
    "co": (SO2, DEFAULT_MESH),
}
SHIPPED = sorted(path.stem for path in SCENES_DIR.glob("*.toml"))
PARETO_WEIGHTS = (0.2, 0.3, 0.4, 0.5, 0.7, 0.9, 0.98)


def test_every_study_of_spec_is_shipped():
    assert set(STUDIES) | {"nominal"} <= set(SHIPPED)


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scene_loads_by_name_and_by_path(name):
    by_name = Scene.load(name)
    by_path = Scene.load(SCENES_DIR / f"{name}.toml")
    assert by_name.name == name
    assert by_name == by_path
    assert by_name.hash == by_path.hash
    assert by_name.description
    # the block, or a mesh shipped beside the scenes (the fish, meshes/fish.toml)
    assert by_name.mesh_file is None or by_name.mesh_file.parent == SCENES_DIR.resolve().parent / "meshes"
    assert by_name.mesh_file is None or by_name.mesh_file.is_file()
    assert all(shape.start == 0.0 for shape in by_name.shapes)


@pytest.mark.parametrize("name", sorted(STUDIES))
def test_shipped_study_matches_spec(name):
    shapes, mesh = STUDIES[name]
    scene = Scene.load(name)
    assert (scene.mesh.level, scene.mesh.degree) == mesh
    assert scene.shape_names == list(shapes)
    assert {shape.name: (shape.lower, shape.upper) for shape in scene.shapes} == shapes
    assert scene.cooptimization.enabled == (name == "co")
    if name != "so9":
        assert scene.constraints == ()


def test_so9_limits_the_sum_of_the_tail_heights():
    (constraint,) = Scene.load("so9").constraints
    assert dict(constraint.coefficients) == {"z_tail": 1.0, "z_tail_step": 1.0, "z_tail_lin": 1.0}
    assert (constraint.lower, constraint.upper) == (-0.8, 0.8)


def test_co_sweeps_the_weights_of_spec_with_the_amplitude_as_parameter():
    scene = Scene.load("co")
    assert scene.cooptimization.enabled
    assert scene.cooptimization.weights == PARETO_WEIGHTS
    assert scene.cooptimization.amplitude_bounds == (0.05, 0.4)
    assert scene.actuation.amplitude == 0.2


def test_defaults_are_the_values_of_spec():
    scene = Scene()
    assert scene.mesh.level == 3
    assert (scene.mesh.length, scene.mesh.width, scene.mesh.height) == (0.20, 0.04, 0.10)
    material = scene.material
    assert material.young_modulus == 260e3
    assert material.poisson_ratio == 0.4
    assert material.density == 1070.0
    assert material.head_stiffness_factor == 100.0
    assert material.rayleigh_alpha == 3.1
    assert material.rayleigh_beta == 6.3e-6
    assert material.mass == "consistent"
    assert scene.regions.head_fraction == 0.35
    assert scene.regions.muscle_range == (-0.95, -0.35)
    assert scene.actuation.stiffness == 6e4
    assert scene.actuation.amplitude == 0.2
    assert scene.actuation.frequency == 1.0
    assert scene.fluid.density == 1000.0
    assert scene.fluid.thrust and scene.fluid.drag
    solver = scene.solver
    assert solver.time_step == 0.02
    assert solver.duration == 2.0
    assert solver.integrator == "generalized-alpha"
    assert solver.rho_infinity == SolverSection().rho_infinity and 0 <= solver.rho_infinity <= 1   # docs/theory/time-scheme.md
    assert solver.newmark_alpha == 0.02   # SPEC §6: 0.005, raised for stability (docs/theory/time-scheme.md, scene.py)
    assert solver.min_time_step == 1e-3
    assert scene.fluid.spine_force == "source"
    assert solver.tolerance == 1e-6
    assert solver.max_iterations == 30
    assert scene.n_steps == 100
    assert scene.cooptimization.weights == PARETO_WEIGHTS
    assert scene.cooptimization.amplitude_bounds == (0.05, 0.4)
    assert scene.shapes == () and scene.constraints == ()


def test_empty_file_gives_the_defaults_and_nominal_spells_them_out(tmp_path):
    empty = Scene.load(write_scene(tmp_path, ""))
    nominal = Scene.load("nominal")
    for scene in (empty, nominal):
        assert scene.material == MaterialSection()
        assert scene.regions == RegionsSection()
        assert scene.actuation == ActuationSection()
        assert scene.fluid == FluidSection()
        assert scene.solver == SolverSection()
        assert scene.cooptimization == CooptimizationSection()
    assert empty.name == "scene"
    assert (nominal.mesh.level, nominal.mesh.degree) == DEFAULT_MESH and nominal.shapes == ()
    assert (empty.mesh.level, empty.mesh.degree) == (3, 1)


# ---------------------------------------------------------------------------------------------
# Hash and replace

PLAIN = """\
name = "study"

[mesh]
level = 1

[solver]
time_step = 0.01
duration = 0.5

[material]
young_modulus = 260e3

[shapes]
y_thin = { bounds = [-0.15, 0.15] }
z_tail = { bounds = [-0.5, 0.5], start = 0.1 }
"""

REFORMATTED = """\
# the same study, written differently
material.young_modulus = 260000
solver = { duration = 5e-1, time_step = 1e-2, tolerance = 1e-6 }
name = 'study'

[shapes.y_thin]
bounds = [-0.15,
          0.15]

[shapes.z_tail]
start = 0.1
bounds = [ -0.5, 0.5 ]

[mesh]
level = 1
length = 0.2
"""


def test_hash_is_stable_and_ignores_formatting(tmp_path):
    first = Scene.load(write_scene(tmp_path, PLAIN, "a.toml"))
    again = Scene.load(write_scene(tmp_path, PLAIN, "a.toml"))
    other = Scene.load(write_scene(tmp_path, REFORMATTED, "b.toml"))
    assert len(first.hash) == 16 and int(first.hash, 16) >= 0
    assert first.hash == first.hash == again.hash
    assert other.hash == first.hash
    assert Scene.load("so1").hash == Scene.load("so1").hash
    so1 = Scene.load("so1")
    hashed = so1.hash      # made once per scene: a changed copy is hashed anew
    assert so1.replace("optimizer", method="trust-region").hash != hashed == so1.hash


def test_hash_follows_the_order_of_the_shapes(tmp_path):
    first = Scene.load(write_scene(tmp_path, PLAIN, "a.toml"))
    y_thin = "y_thin = { bounds = [-0.15, 0.15] }\n"
    swapped = Scene.load(write_scene(tmp_path, PLAIN.replace(y_thin, "") + y_thin, "b.toml"))
    assert swapped.shape_names == ["z_tail", "y_thin"] == first.shape_names[::-1]
    assert swapped.hash != first.hash


@pytest.mark.parametrize("old, new", [
    ("time_step = 0.01", "time_step = 0.005"),
    ("young_modulus = 260e3", "young_modulus = 261e3"),
    ("level = 1", "level = 2"),
    ("start = 0.1", "start = 0.0"),
    ("bounds = [-0.15, 0.15]", "bounds = [-0.15, 0.14]"),
    ('name = "study"', 'name = "other"'),
])
def test_hash_changes_with_any_value(tmp_path, old, new):
    assert PLAIN.count(old) == 1
    first = Scene.load(write_scene(tmp_path, PLAIN, "a.toml"))
    changed = Scene.load(write_scene(tmp_path, PLAIN.replace(old, new), "b.toml"))
    assert changed.hash != first.hash


def test_a_key_added_later_keeps_the_hash_of_the_scenes_before_it_at_its_legacy_value():
    """[fluid] spine_rule came after scenes were hashed (their caches, checkpoints and studies): at the
    rule they computed with ("rear"), written out or not, the hash is the one without the key; the new
    default ("trapezoid") and any other value change it."""
    from aquarom_fenics.io.scene_sections import FluidSection, ReductionSection, legacy_values

    assert legacy_values(FluidSection) == {"spine_rule": "rear", "thrust_factor": 1.0, "drag_factor": 1.0}
    scene = Scene.load("co")
    assert scene.fluid.spine_rule == "trapezoid"
    rear = scene.replace("fluid", spine_rule="rear")
    data = rear.to_dict()
    for key in ("spine_rule", "thrust_factor", "drag_factor"):
        del data["fluid"][key]
    data["actuation"]["start_ramp"] = 0.0          # "auto" is hashed as the τ it gives: the pair's 0
    data["reduction"]["vibration_modes"] = 1       # "auto" is hashed as the mode count it gives: the pair's 1
    for section, key in (("mesh", "axis"), ("mesh", "head_end"), ("regions", "head"), ("regions", "muscles"),
                         ("regions", "muscle_pairs"), ("material", "law"),
                         ("cooptimization", "effort"), ("optimizer", "screen"),
                         ("optimizer", "atlas"), ("optimizer", "expand_ratio"),
                         ("optimizer", "expand_factor")):   # later keys at their legacy values
        del data[section][key]
    for key, legacy in legacy_values(ReductionSection).items():    # the CO scene sets some of them
        if data["reduction"][key] == legacy:
            del data["reduction"][key]
    assert rear.hash == rear._digest(data)
    assert scene.hash != rear.hash and scene.fom_hash != rear.fom_hash
    assert 'spine_rule = "rear"' in rear.to_toml()          # a written scene still names it
    assert Scene.load("co").hash == scene.hash


def test_the_region_axis_and_head_end_keys_keep_the_hashes_of_the_scenes_before_them():
    """[regions] head, muscles and [mesh] axis, head_end came after scenes were hashed: at the block's
    names, "x" and "+x" or not given (""), written out or not, the hash is the one without them; other
    values change it."""
    from aquarom_fenics.io.scene_sections import LegacyValues, MeshSection, RegionsSection, legacy_values

    assert legacy_values(RegionsSection) == {"head": "head", "muscles": ("left_muscle", "right_muscle"),
                                             "muscle_pairs": 1}
    assert legacy_values(MeshSection) == {"axis": "x", "head_end": LegacyValues(("", "+x"))}
    scene = Scene.load("nominal")
    data = scene.to_dict()
    for section, key in (("mesh", "axis"), ("mesh", "head_end"), ("regions", "head"), ("regions", "muscles"),
                         ("regions", "muscle_pairs"), ("material", "law"), ("reduction", "stroke_amplitude"),
                         ("reduction", "validity_change"), ("reduction", "stroke_sensitivities"),
                         ("reduction", "atlas_scale"), ("reduction", "atlas_change"), ("reduction", "atlas_check"),
                         ("fluid", "thrust_factor"), ("fluid", "drag_factor"),
                         ("cooptimization", "effort"), ("optimizer", "screen"),
                         ("optimizer", "atlas"), ("optimizer", "expand_ratio"),
                         ("optimizer", "expand_factor")):   # later keys at their legacy values
        del data[section][key]
    data["actuation"]["start_ramp"] = 0.0          # "auto" is hashed as the τ it gives: the pair's 0
    data["reduction"]["vibration_modes"] = 1       # "auto" is hashed as the mode count it gives: the pair's 1
    assert scene.hash == scene._digest(data)
    written = scene_from_dict(tomllib.loads(scene.to_toml()), source=scene.source, base_dir=scene.base_dir)
    assert written.hash == scene.hash and written.regions.muscles == ("left_muscle", "right_muscle")
    assert scene.mesh.head_end == "+x" and scene.replace("mesh", head_end="").hash == scene.hash
    for section, values in (("regions", {"head": "nose"}), ("regions", {"muscles": ["right_muscle", "left_muscle"]}),
                            ("mesh", {"head_end": "-x"}), ("mesh", {"axis": "y", "head_end": "+y"})):
        changed = scene.replace(section, **values)
        assert changed.hash != scene.hash and changed.fom_hash != scene.fom_hash


def test_the_material_law_is_checked_and_svk_keeps_the_hash_of_the_scenes_before_it():
    """[material] law came after scenes were hashed: "svk", written out or not, leaves the hash as it was."""
    from aquarom_fenics.io.scene_sections import MaterialSection, legacy_values

    assert legacy_values(MaterialSection) == {"law": "svk"}
    scene = Scene.load("nominal")
    assert scene.material.law == "svk" and scene.replace("material", law="svk").hash == scene.hash
    neo_hookean = scene.replace("material", law="neo-hookean")
    assert neo_hookean.hash != scene.hash and neo_hookean.fom_hash != scene.fom_hash
    assert 'law = "neo-hookean"' in neo_hookean.to_toml()
    with pytest.raises(InputError, match=r"\[material\] law = 'mooney' must be one of 'svk', 'neo-hookean'"):
        scene.replace("material", law="mooney")


@pytest.mark.parametrize("table, message", [
    ({"regions": {"muscles": ["left_muscle"]}}, r"\[regions\] muscles must name two different regions"),
    ({"regions": {"muscles": ["a", "a"]}}, r"\[regions\] muscles must name two different regions"),
    ({"regions": {"head": ""}}, r"\[regions\] head must be the name of a region"),
    ({"mesh": {"head_end": "+w"}}, r"\[mesh\] head_end = '\+w' must be one of '', '\+x', '-x', '\+y', '-y', '\+z', '-z'"),
    ({"mesh": {"axis": "w"}}, r"\[mesh\] axis = 'w' must be one of 'x', 'y', 'z'"),
])
def test_bad_region_names_and_head_ends_are_one_line(table, message):
    with pytest.raises(InputError, match=message):
        scene_from_dict(table, source="bad.toml")


def test_hash_follows_the_content_of_the_mesh_file(tmp_path):
    mesh = write_box_inp(tmp_path / "box.inp")
    path = write_scene(tmp_path, '[mesh]\nfile = "box.inp"\n')
    scene = Scene.load(path)
    before = scene.hash
    assert Scene.load(path).hash == before
    write_box_inp(mesh, counts=(11, 3, 3))
    assert Scene.load(path).hash != before
    assert scene.hash != before         # the file is read at every hash, not kept with the scene


def test_one_scene_in_two_folders_has_one_hash(tmp_path):
    """The mesh file enters the hash by its name and content, not by where the checkout lies: one
    scene copied into another folder keeps its hash (and its caches)."""
    hashes = []
    for folder in (tmp_path / "checkout", tmp_path / "elsewhere" / "copy"):
        folder.mkdir(parents=True)
        write_box_inp(folder / "box.inp")
        hashes.append(Scene.load(write_scene(folder, '[mesh]\nfile = "box.inp"\n')).hash)
    assert hashes[0] == hashes[1]
    Path(tmp_path / "elsewhere" / "copy" / "box.inp").rename(tmp_path / "elsewhere" / "copy" / "other.inp")
    renamed = write_scene(tmp_path / "elsewhere" / "copy", '[mesh]\nfile = "other.inp"\n')
    assert Scene.load(renamed).hash != hashes[0]


def test_replace_changes_one_value_and_keeps_the_rest():
    scene = Scene.load("so1")
    finer = scene.replace("mesh", level=2)
    assert finer.mesh.level == 2 and scene.mesh.level == 1
    assert finer.mesh.translate == scene.mesh.translate and finer.mesh.degree == scene.mesh.degree
    assert finer.shapes == scene.shapes and finer.solver == scene.solver
    assert finer.hash != scene.hash
    assert finer.replace("mesh", level=1).hash == scene.hash
    shifted = scene.replace("regions", muscle_range=(-0.9, -0.4))
    assert shifted.regions.muscle_range == (-0.9, -0.4)
    assert scene.replace("cooptimization", weights=[0.5]).cooptimization.weights == (0.5,)
    assert scene.replace("solver", duration=3).solver.duration == 3.0      # an integer for a float


@pytest.mark.parametrize("section, values, name", [
    ("solver", {"time_step": 0.0}, "time_step"),
    ("solver", {"time_step": -0.02}, "time_step"),
    ("solver", {"time_step": "abc"}, "time_step"),
    ("solver", {"duration": 0.05}, "duration"),
    ("mesh", {"level": 7}, "level"),
    ("material", {"poisson_ratio": 0.5}, "poisson_ratio"),
    ("fluid", {"drag": 1}, "drag"),
    ("regions", {"muscle_range": (-0.3, -0.6)}, "muscle_range"),
    ("actuation", {"stiffnes": 1e4}, "stiffnes"),
    ("solver", {"duration": math.nan}, "duration"),
])
def test_replace_validates(section, values, name):
    scene = Scene.load("so1")
    with pytest.raises(InputError, match=name):
        scene.replace(section, **values)


# ---------------------------------------------------------------------------------------------
# --xi assignments


def test_parse_xi_assignments_reads_name_value_pairs():
    scene = Scene.load("so1")
    assert parse_xi_assignments(None, scene) == {}
    assert parse_xi_assignments([], scene) == {}
    assert parse_xi_assignments(["y_thin=0.1", "z_tail=-3e-1", " z_head = 0 "], scene) == {
        "y_thin": 0.1, "z_tail": -0.3, "z_head": 0.0}


@pytest.mark.parametrize("text, name", [
    ("y_thin", "y_thin"),
    ("y_thin:0.1", "y_thin:0.1"),
    ("y_thin=abc", "abc"),
    ("y_thin=", "y_thin="),
    ("=0.1", "=0.1"),
    ("y_fat=0.1", "y_fat"),
    ("y_thin=nan", "nan"),
    ("y_thin=-inf", "inf"),
])
def test_parse_xi_assignments_refuses_malformed_text(text, name):
    with pytest.raises(InputError, match=name) as error:
        parse_xi_assignments([text], Scene.load("so1"))
    assert "\n" not in str(error.value)


def test_parse_xi_assignments_refuses_everything_when_the_scene_has_no_shapes():
    with pytest.raises(InputError, match="no \\[shapes\\]"):
        parse_xi_assignments(["y_thin=0.1"], scene_from_dict({}))


# ---------------------------------------------------------------------------------------------
# Bad input through the command line: exit code 2 and one line naming the problem

BAD_SCENES = {
    "malformed TOML": (COARSE + "[solver\ntime_step = 0.02\n", ["malformed TOML", "line 3"]),
    "unknown top-level key": ('colour = "red"\n' + COARSE, ["'colour'", "top-level"]),
    "unknown section key": (COARSE + "[solver]\ntime_stepp = 0.02\n", ["time_stepp", "time_step,"]),
    "time step not a number": (COARSE + '[solver]\ntime_step = "abc"\n', ["time_step", "'abc'"]),
    "drag not a boolean": (COARSE + "[fluid]\ndrag = 1\n", ["drag", "true or false"]),
    "level not an integer": (COARSE.replace("1", "1.0"), ["level", "integer"]),
    "zero time step": (COARSE + "[solver]\ntime_step = 0.0\n", ["time_step", "> 0"]),
    "negative time step": (COARSE + "[solver]\ntime_step = -0.02\n", ["time_step", "> 0"]),
    "short duration": (COARSE + "[solver]\nduration = 0.05\n", ["duration", "0.1 s"]),
    "unknown integrator": (COARSE + '[solver]\nintegrator = "euler"\n', ["integrator", "'generalized-alpha', 'newmark'"]),
    "spectral radius above 1": (COARSE + "[solver]\nrho_infinity = 1.5\n", ["rho_infinity", "[0, 1]"]),
    "zero minimum step": (COARSE + "[solver]\nmin_time_step = 0.0\n", ["min_time_step", "> 0"]),
    "atlas scale zero": (COARSE + "[reduction]\natlas_scale = 0.0\n", ["atlas_scale", "(0, 1]"]),
    "atlas scale above 1": (COARSE + "[reduction]\natlas_scale = 1.2\n", ["atlas_scale", "(0, 1]"]),
    "atlas scale not a number": (COARSE + '[reduction]\natlas_scale = "small"\n', ["atlas_scale"]),
    "atlas check negative": (COARSE + "[reduction]\natlas_check = -0.03\n", ["atlas_check", "[0, 1)"]),
    "atlas check 1": (COARSE + "[reduction]\natlas_check = 1.0\n", ["atlas_check", "[0, 1)"]),
    "atlas check not a number": (COARSE + '[reduction]\natlas_check = "on"\n', ["atlas_check"]),
    "unknown spine force": (COARSE + '[fluid]\nspine_force = "euler"\n', ["spine_force", "'source', 'lagrangian'"]),
    "unknown spine rule": (COARSE + '[fluid]\nspine_rule = "simpson"\n', ["spine_rule", "'trapezoid', 'rear'"]),
    "section not a table": ("solver = 3\n" + COARSE, ["[solver]", "table"]),
    "unknown shape": (COARSE + "[shapes]\ny_fat = { bounds = [-0.1, 0.1] }\n", ["'y_fat'", "y_thin"]),
    "bounds reversed": (COARSE + "[shapes]\ny_thin = { bounds = [0.1, -0.1] }\n",
                        ["y_thin", "lower bound above upper"]),
    "missing bounds": (COARSE + "[shapes]\ny_thin = { start = 0.1 }\n", ["y_thin", "bounds"]),
    "start outside bounds": (COARSE + "[shapes]\ny_thin = { bounds = [-0.15, 0.15], start = 0.3 }\n",
                             ["y_thin", "start = 0.3", "outside"]),
    "unknown constraint name": (COARSE + textwrap.dedent("""\
        [shapes]
        z_tail = { bounds = [-0.5, 0.5] }
        [[constraints]]
        coefficients = { z_tail = 1.0, z_tial = 1.0 }
        upper = 0.8
        """), ["constraint 1", "'z_tial'"]),
    "constraint bounds reversed": (COARSE + textwrap.dedent("""\
        [shapes]
        z_tail = { bounds = [-0.5, 0.5] }
        [[constraints]]
        coefficients = { z_tail = 1.0 }
        lower = 0.8
        upper = -0.8
        """), ["constraint 1", "lower 0.8 above upper -0.8"]),
    "missing mesh file": ('[mesh]\nlevel = 1\nfile = "nope.inp"\n', ["nope.inp", "not found"]),
    "mesh file of unknown kind": ('[mesh]\nlevel = 1\nfile = "fish.stl"\n', ["fish.stl", ".stl"]),
}


@pytest.mark.parametrize("case", sorted(BAD_SCENES))
def test_bad_scene_is_one_line_and_exit_code_2(case, tmp_path, capfd):
    text, names = BAD_SCENES[case]
    path = write_scene(tmp_path, text)
    code, out, err = run_cli(["mesh", path], capfd)
    assert_one_line_error(code, out, err, "mesh", *names)
    assert path.name in err or "nope.inp" in err or "fish.stl" in err


@pytest.mark.parametrize("content, names", [
    ("this is not\na mesh at all\n", ["garbage.inp", "*Node"]),
    ("*Node\n1, 0.0, zero, 0.0\n", ["garbage.inp", "meshio cannot read it", "zero"]),
    ("*Node\n1, 0, 0, 0\n2, 1, 0, 0\n3, 0, 1, 0\n4, 0, 0, 1\n*Element, type=C3D4\n1, 1, 2, 3, 9\n",
     ["garbage.inp", "undefined label 9"]),
    ("*Node\n1, 0, 0, 0\n2, 1, 0, 0\n3, 2, 0, 0\n4, 0, 0, 1\n*Element, type=C3D4\n1, 1, 2, 3, 4\n",
     ["garbage.inp", "zero volume"]),
    ("*Node\n1, 0, 0, 0\n2, 1, 0\n", ["garbage.inp", "meshio cannot read it"]),
])
def test_corrupt_mesh_file_is_one_line_and_exit_code_2(content, names, tmp_path, capfd):
    (tmp_path / "garbage.inp").write_text(content)
    path = write_scene(tmp_path, '[mesh]\nfile = "garbage.inp"\n')
    code, out, err = run_cli(["mesh", path], capfd)
    assert_one_line_error(code, out, err, "mesh", *names)


def test_binary_mesh_file_is_one_line_and_exit_code_2(tmp_path, capfd):
    (tmp_path / "garbage.inp").write_bytes(bytes(range(256)) * 4)
    path = write_scene(tmp_path, '[mesh]\nfile = "garbage.inp"\n')
    code, out, err = run_cli(["mesh", path], capfd)
    assert_one_line_error(code, out, err, "mesh", "garbage.inp")


def test_structured_box_with_axis_nodes_is_a_valid_fish(tmp_path, capfd):
    write_box_inp(tmp_path / "box.inp", counts=(9, 3, 3))
    path = write_scene(tmp_path, '[mesh]\nfile = "box.inp"\nhead_end = "+x"\n')
    code, out, err = run_cli(["mesh", path], capfd)
    assert code == 0, err
    assert "cells        192" in out
    assert "spine        9 nodes" in out


def test_mesh_without_nodes_on_the_body_axis_is_refused_by_the_nodal_model_only(tmp_path, capfd):
    write_box_inp(tmp_path / "box.inp", counts=(9, 4, 4))
    path = write_scene(tmp_path, '[mesh]\nfile = "box.inp"\nhead_end = "+x"\n[fluid]\nstations = "nodes"\n')
    code, out, err = run_cli(["mesh", path], capfd)
    assert_one_line_error(code, out, err, "mesh", "box.inp", "body axis", 'stations = "nodes"')
    path = write_scene(tmp_path, '[mesh]\nfile = "box.inp"\nhead_end = "+x"\n')
    code, out, err = run_cli(["mesh", path], capfd)
    assert code == 0, err
    assert "stations     41, every 0.005 m" in out and "spine        none: no nodes on the body axis" in out


def test_design_that_inverts_cells_names_the_parameter(tmp_path, capfd):
    path = write_scene(tmp_path, COARSE + "[shapes]\ny_thin = { bounds = [-2.0, 2.0] }\n")
    out_dir = tmp_path / "o"
    code, out, err = run_cli(["shapes", path, "--xi", "y_thin=1.5", "--out", out_dir], capfd)
    assert_one_line_error(code, out, err, "shapes", "y_thin=1.5", "invert")
    assert not out_dir.exists() or not any(out_dir.iterdir())


@pytest.mark.parametrize("command", ["shapes", "simulate"])
def test_xi_for_a_shape_not_in_the_scene(command, tmp_path, capfd):
    path = write_scene(tmp_path, COARSE + "[shapes]\ny_thin = { bounds = [-0.15, 0.15] }\n")
    code, out, err = run_cli([command, path, "--xi", "z_tail=0.1", "--out", tmp_path / "o"], capfd)
    assert_one_line_error(code, out, err, command, "'z_tail'", "y_thin")


@pytest.mark.parametrize("value", ["abc", "nan"])
def test_xi_value_that_is_not_a_finite_number(value, tmp_path, capfd):
    path = write_scene(tmp_path, COARSE + "[shapes]\ny_thin = { bounds = [-0.15, 0.15] }\n")
    code, out, err = run_cli(["shapes", path, "--xi", f"y_thin={value}", "--out", tmp_path / "o"], capfd)
    assert_one_line_error(code, out, err, "shapes", f"y_thin={value}")


@pytest.mark.parametrize("scene", ["missing.toml", "so10"])
def test_scene_that_does_not_exist(scene, tmp_path, capfd):
    argument = tmp_path / scene if scene.endswith(".toml") else scene
    code, out, err = run_cli(["mesh", argument], capfd)
    assert_one_line_error(code, out, err, "mesh", scene, "not found", "so1")


def test_good_scene_reports_its_mesh(tmp_path, capfd):
    path = write_scene(tmp_path, COARSE + "[shapes]\ny_thin = { bounds = [-0.15, 0.15] }\n")
    code, out, err = run_cli(["mesh", path], capfd)
    assert code == 0, err
    assert "scene scene: block level 1" in out
    assert err.strip() == ""
    code, out, err = run_cli(["mesh", "so1", "--level", "1"], capfd)
    assert code == 0, err
    assert "block level 1" in out


def test_fom_hash_ignores_what_a_fom_run_does_not_read():
    scene = Scene.load("so1")
    same_run = (scene.replace("optimizer", method="trust-region", step_size=0.1),
                scene.replace("reduction", validity_fraction=0.3),
                scene.replace("output", xdmf=True),
                dataclasses.replace(scene, shapes=(dataclasses.replace(scene.shapes[0], lower=-0.4),) + scene.shapes[1:]))
    for other in same_run:
        assert other.hash != scene.hash and other.fom_hash == scene.fom_hash
    for other in (scene.replace("solver", time_step=0.01), scene.replace("mesh", level=2),
                  scene.replace("actuation", amplitude=0.3), scene.replace("fluid", drag=False),
                  dataclasses.replace(scene, shapes=scene.shapes[:-1])):
        assert other.fom_hash != scene.fom_hash
