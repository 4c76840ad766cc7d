"""One cost estimate, on the cells per level of the mesh recipe: the dry-run plan, the sweep's estimate
and the validation runner's order of cases all follow a change of meshes/block.toml's cells."""
import tomllib
from pathlib import Path

import pytest

from aquarom_fenics.geometry import block
from aquarom_fenics.studies import estimate
from aquarom_fenics.studies.plan import plan, plan_seconds
from aquarom_fenics.studies.sweep import estimate as sweep_estimate
from aquarom_fenics.verification.validation.cases import fom_case, reduced_case
from aquarom_fenics.verification.validation.runner import estimated_cost

RECIPE = Path(__file__).resolve().parents[2] / "meshes" / "block.toml"


@pytest.fixture
def reference_laws(monkeypatch):
    """The reference figures, not a fit to whatever results/bench/ this checkout holds."""
    monkeypatch.setattr(estimate, "_bench_runs", lambda name, keep: [])


def test_the_cells_of_a_level_are_the_recipes():
    levels = tomllib.loads(RECIPE.read_text())["levels"]
    assert {int(level): entry["cells"] for level, entry in levels.items()} == {
        level: estimate.level_cells(level) for level in block.LEVEL_TARGET_CELLS}


def test_changing_the_recipes_cells_changes_every_estimate(make_scene, monkeypatch, reference_laws):
    scene = make_scene(solver={"duration": 1.0}, shapes={"z_tail": {"bounds": [-0.2, 0.2]}})
    fom, prom = fom_case("FOM", scene), reduced_case("PROM", scene, parametric=True)
    before = {"fom case": estimated_cost(fom), "prom case": estimated_cost(prom),
              "simulate": plan_seconds("simulate", scene, "fom"), "optimize": plan_seconds("optimize", scene),
              "sweep": sweep_estimate(scene, 4, "fom", 2)}
    lines = plan("simulate", scene, "fom")
    cells = block.LEVEL_TARGET_CELLS[1]
    assert any(f"level 1 (~{cells} cells)" in line for line in lines)

    monkeypatch.setitem(block.LEVEL_TARGET_CELLS, 1, 2 * cells)       # a recipe with twice the cells
    after = {"fom case": estimated_cost(fom), "prom case": estimated_cost(prom),
             "simulate": plan_seconds("simulate", scene, "fom"), "optimize": plan_seconds("optimize", scene),
             "sweep": sweep_estimate(scene, 4, "fom", 2)}
    assert after["fom case"] == pytest.approx(before["fom case"] * 2 ** estimate.REFERENCE_FOM_EXPONENT)
    assert after["simulate"] == pytest.approx(before["simulate"] * 2 ** estimate.REFERENCE_FOM_EXPONENT)
    assert all(after[name] > before[name] for name in before), (before, after)
    assert any(f"level 1 (~{2 * cells} cells)" in line for line in plan("simulate", scene, "fom"))


def test_the_runner_starts_the_finer_and_longer_cases_first(make_scene, reference_laws):
    coarse = make_scene(solver={"duration": 1.0})
    fine = coarse.replace("mesh", level=3)
    quadratic = coarse.replace("mesh", degree=2)
    costs = [estimated_cost(fom_case(label, scene)) for label, scene in
             (("coarse", coarse), ("fine", fine), ("quadratic", quadratic))]
    assert costs[1] > costs[0] and costs[2] > costs[0]
    assert estimated_cost(fom_case("long", coarse.replace("solver", duration=2.0))) == pytest.approx(2 * costs[0])
    assert estimated_cost(reduced_case("ROM", coarse, parametric=False)) < costs[0]
