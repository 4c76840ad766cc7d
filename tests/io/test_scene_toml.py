"""Scene.to_toml: the inverse of Scene.load for every shipped scene and for the optional tables."""
import dataclasses

import pytest

from aquarom_fenics.io.scene import SCENES_DIR, Scene

SHIPPED = sorted(path.stem for path in SCENES_DIR.glob("*.toml"))


def reloaded(scene: Scene, folder) -> Scene:
    path = folder / f"{scene.name}.toml"
    path.write_text(scene.to_toml())
    return Scene.load(path)


def test_every_scene_is_shipped():
    assert {"nominal", "so1", "co"} <= set(SHIPPED)


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scene_round_trip(name, tmp_path):
    scene = Scene.load(name)
    loaded = reloaded(scene, tmp_path)
    # a mesh file (the shipped fish) is written as its absolute path
    mesh = scene.mesh if scene.mesh_file is None else dataclasses.replace(scene.mesh, file=str(scene.mesh_file))
    assert loaded == dataclasses.replace(scene, source=loaded.source, base_dir=loaded.base_dir, mesh=mesh)
    assert loaded.hash == scene.hash


def test_round_trip_of_radius_constraints_and_changed_values(tmp_path):
    scene = Scene.load("so1").replace("solver", time_step=0.01, integrator="newmark")
    scene = scene.replace("cooptimization", weights=(0.25, 0.75))
    scene = dataclasses.replace(scene, description='fin "ß" \\ tail',
                                shapes=(dataclasses.replace(scene.shapes[0], radius=0.03),) + scene.shapes[1:])
    loaded = reloaded(scene, tmp_path)
    assert loaded.shapes[0].radius == 0.03 and loaded.description == scene.description
    assert loaded.hash == scene.hash
    assert loaded.solver.integrator == "newmark" and loaded.cooptimization.weights == (0.25, 0.75)


def test_round_trip_of_linear_constraints(tmp_path):
    from aquarom_fenics.io.scene import scene_from_dict

    data = {"name": "constrained", "shapes": {"y_thin": {"bounds": [-0.1, 0.1]}, "z_tail": {"bounds": [-0.2, 0.2]}},
            "constraints": [{"coefficients": {"y_thin": 1.0, "z_tail": -2.0}, "upper": 0.05},
                            {"coefficients": {"z_tail": 1.0}, "lower": -0.1, "upper": 0.1}]}
    scene = scene_from_dict(data, source="constrained.toml")
    loaded = reloaded(scene, tmp_path)
    assert loaded.constraints == scene.constraints and loaded.hash == scene.hash
