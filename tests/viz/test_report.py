"""Optimization figures: history of cost and parameters, nominal against optimal fish, Pareto front."""

import os
import shutil

import numpy as np
import pytest
from matplotlib.image import imread

from aquarom_fenics.viz import report
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.scene import scene_from_dict

needs_display = pytest.mark.skipif(not os.environ.get("DISPLAY") and shutil.which("Xvfb") is None,
                                   reason="rendering needs a display or Xvfb")

SHAPE_NAMES = ["z_tail", "z_head", "y_thin"]
BOUNDS = [(-0.5, 0.5), (-0.5, 0.5), (-0.15, 0.15)]
PROM_KINDS = ["built", "approximated", "approximated", "rejected", "approximated", "built",
              "approximated", "rejected", "approximated", "built", "approximated", "approximated"]


def synthetic_history(shape_names: list[str], bounds: list[tuple[float, float]]) -> list[dict]:
    """Twelve iterations drifting towards the upper bounds, with two rejected steps overshooting them."""
    uppers = np.array([upper for _, upper in bounds])
    rows = []
    for iteration, kind in enumerate(PROM_KINDS):
        fraction = iteration / len(PROM_KINDS) + (0.4 if kind == "rejected" else 0.0)
        distance = 0.03 + 0.01 * fraction
        xi = {f"xi_{name}": value for name, value in zip(shape_names, fraction * uppers)}
        rows.append({"iteration": iteration, **xi, "cost": -distance, "distance": distance, "prom": kind})
    return rows


def read_rgb(path) -> np.ndarray:
    """(height, width, 3) colours in [0, 1] of a PNG file."""
    return imread(str(path))[..., :3]


def assert_not_blank(picture: np.ndarray) -> None:
    assert picture.std() > 0.05
    assert (picture < 0.9).any(axis=2).mean() > 0.01


def test_history_writes_cost_and_parameter_figures(tmp_path):
    paths = report.plot_optimization_history(synthetic_history(SHAPE_NAMES, BOUNDS), SHAPE_NAMES, BOUNDS, tmp_path)
    assert paths == [tmp_path / "cost.png", tmp_path / "parameters.png"]
    cost, parameters = (read_rgb(path) for path in paths)
    assert cost.shape == (660, 840, 3)
    assert parameters.shape == (330, 1350, 3)
    for picture in (cost, parameters):
        assert_not_blank(picture)


@pytest.mark.parametrize("n_parameters, pixel_size", [(1, (330, 900)), (8, (870, 1350))])
def test_parameter_figure_grows_with_the_number_of_parameters(tmp_path, n_parameters, pixel_size):
    names = [f"p{index}" for index in range(n_parameters)]
    bounds = [(-0.1 * (index + 1), 0.1 * (index + 1)) for index in range(n_parameters)]
    _, parameters = report.plot_optimization_history(synthetic_history(names, bounds), names, bounds, tmp_path)
    picture = read_rgb(parameters)
    assert picture.shape[:2] == pixel_size
    assert_not_blank(picture)


def test_history_refuses_unknown_prom_kinds_and_missing_bounds(tmp_path):
    rows = synthetic_history(SHAPE_NAMES, BOUNDS)
    with pytest.raises(ValueError, match="bounds"):
        report.plot_optimization_history(rows, SHAPE_NAMES, BOUNDS[:2], tmp_path)
    rows[3]["prom"] = "guessed"
    with pytest.raises(ValueError, match="guessed"):
        report.plot_optimization_history(rows, SHAPE_NAMES, BOUNDS, tmp_path)


def fish_rows(half: np.ndarray, min_pixels: int = 100, max_gap: int = 5) -> list[int]:
    """Heights [px] of the bands of rows, top to bottom, where a half of the sheet shows a coloured fish.

    A band bridges up to ``max_gap`` rows of drawn cell edges.
    """
    coloured = (half.max(axis=2) - half.min(axis=2)) > 0.15
    rows = np.flatnonzero(coloured.sum(axis=1) > min_pixels)
    breaks = np.flatnonzero(np.diff(rows) > max_gap)
    return [int(band[-1] - band[0] + 1) for band in np.split(rows, breaks + 1)]


@needs_display
def test_nominal_and_optimal_shows_the_thinner_fish_from_above(tmp_path):
    scene = scene_from_dict({"mesh": {"level": 1}, "shapes": {"y_thin": {"bounds": [-0.15, 0.15]}}})
    fish = load_fish(scene)
    optimal = fish.design({"y_thin": 0.1})
    path = report.render_start_and_optimal(fish, fish.mesh.points, optimal, tmp_path / "fish.png", "y_thin = 0.1")
    assert path == tmp_path / "fish.png"
    picture = read_rgb(path)
    assert picture.shape[1] == round(report.VIEW_FIGURE_WIDTH * report.DPI)
    assert_not_blank(picture)
    middle = picture.shape[1] // 2
    nominal_bands, optimal_bands = fish_rows(picture[:, :middle]), fish_rows(picture[:, middle:])
    assert len(nominal_bands) == len(optimal_bands) == 2
    (nominal_width, nominal_height), (optimal_width, optimal_height) = nominal_bands, optimal_bands
    assert optimal_width / nominal_width == pytest.approx(0.9, abs=0.04)
    assert optimal_height == pytest.approx(nominal_height, abs=3)
    assert nominal_height / nominal_width == pytest.approx(0.10 / 0.04, rel=0.1)


def test_pareto_writes_a_figure(tmp_path):
    weights = (0.2, 0.3, 0.4, 0.5, 0.7, 0.9, 0.98)
    points = [{"w1": w1, "distance_m": 0.01 + 0.05 * np.sqrt(w1), "energy": 0.002 + 0.01 * w1 ** 2,
               "amplitude": 0.05 + 0.35 * w1} for w1 in weights]
    path = report.plot_pareto(points, tmp_path / "pareto" / "pareto.png")
    assert path == tmp_path / "pareto" / "pareto.png"
    assert_not_blank(read_rgb(path))


def front_input(points, tmp_path, monkeypatch):
    """The distances the Pareto plot hands to its non-dominated filter (the plot is drawn and not blank)."""
    drawn = {}
    original = report._non_dominated

    def recording(energy, distance):
        drawn["front_input"] = distance.copy()
        return original(energy, distance)

    monkeypatch.setattr(report, "_non_dominated", recording)
    assert_not_blank(read_rgb(report.plot_pareto(points, tmp_path / "pareto.png")))
    return drawn["front_input"]


def test_pareto_leaves_a_point_whose_fom_check_stopped_off_the_front(tmp_path, monkeypatch):
    points = [{"w1": 0.2, "distance_m": 0.01, "energy": 0.001, "amplitude": 0.1, "prom_distance_m": 0.011},
              {"w1": 0.5, "distance_m": 0.03, "energy": 0.004, "amplitude": 0.2, "prom_distance_m": 0.031},
              {"w1": 0.9, "distance_m": float("nan"), "energy": 0.016, "amplitude": 0.4, "prom_distance_m": 0.09}]
    assert front_input(points, tmp_path, monkeypatch).tolist() == [1.0, 3.0]   # the infeasible one is not on the front


def test_pareto_leaves_a_point_that_did_not_converge_off_the_front(tmp_path, monkeypatch):
    """A weight whose optimiser stopped before a first-order point (``converged`` False, as the CSV
    writes it) is no optimum: however far it swims, the front is drawn without it."""
    points = [{"w1": 0.2, "distance_m": 0.01, "energy": 0.001, "amplitude": 0.1, "converged": True},
              {"w1": 0.3, "distance_m": 0.05, "energy": 0.002, "amplitude": 0.15, "converged": "False"},
              {"w1": 0.9, "distance_m": 0.03, "energy": 0.004, "amplitude": 0.2, "converged": "True"}]
    assert front_input(points, tmp_path, monkeypatch).tolist() == [1.0, 3.0]


def test_non_dominated_keeps_the_points_no_other_beats():
    energy = np.array([1.0, 2.0, 2.0, 3.0, 1.0])
    distance = np.array([1.0, 3.0, 2.0, 2.5, 0.5])
    assert report._non_dominated(energy, distance).tolist() == [True, True, False, False, False]


def test_pareto_labels_one_design_reached_by_several_weights_once():
    points = [{"w1": 0.2, "amplitude": 0.1}, {"w1": 0.7, "amplitude": 0.4}, {"w1": 0.9, "amplitude": 0.4},
              {"w1": 0.98, "amplitude": 0.4}]
    energy = np.array([0.01, 0.16, 0.16, 0.16])
    distance = np.array([10.0, 32.71, 32.67, 32.86])
    labels = [label for _, _, label in report._pareto_labels(points, energy, distance)]
    assert labels == ["w₁ 0.2, A 0.1", "w₁ 0.7, 0.9, 0.98, A 0.4"]
    distance[2] = 20.0                              # no longer at the same place: its own label
    assert len(report._pareto_labels(points, energy, distance)) == 3
