"""history.csv's columns of the design vector [ξ, A, g]: xi_NAME of the shapes and the co-design's A,
gait_NAME of the [gait] variables; a checkpoint's rows written as xi_NAME are read back under the new names."""
from aquarom_fenics.io.scene import scene_from_dict
from aquarom_fenics.optimization.cost import design_space
from aquarom_fenics.optimization.history import design_columns, history_columns, history_row, relabelled

PAIRS = [{"region": f"{side}_{k}", "scale": 1.0 if side == "left" else -1.0, "phase": 120.0 * (k - 1)}
         for k in (1, 2, 3) for side in ("left", "right")]


def space_of(**sections):
    return design_space(scene_from_dict({"mesh": {"level": 1}, "regions": {"muscle_pairs": 3}, "muscles": PAIRS,
                                         "shapes": {"z_tail": {"bounds": [-0.2, 0.2]}},
                                         "gait": {"frequency": {"bounds": [0.5, 2.0]},
                                                  "phase_lag": {"bounds": [60, 180]}}} | sections, source="<test>"))


def test_gait_columns_are_named_gait_and_the_others_xi():
    space = space_of(cooptimization={"enabled": True})
    assert design_columns(space) == ["xi_z_tail", "xi_amplitude", "gait_frequency", "gait_phase_lag"]
    assert history_columns(space)[1:5] == design_columns(space)
    row = history_row(space, 0, [0.1, 0.2, 1.5, 90.0], -0.01, [0.0] * 4, 0.01, "built", 0.0)
    assert (row["gait_frequency"], row["gait_phase_lag"], row["xi_amplitude"]) == (1.5, 90.0, 0.2)
    assert "xi_frequency" not in row and row["grad_frequency"] == 0.0


def test_a_checkpoint_row_of_the_former_names_is_relabelled():
    space = space_of()
    old = {"iteration": 2, "xi_z_tail": 0.1, "xi_frequency": 1.2, "xi_phase_lag": 100.0, "grad_frequency": 0.3}
    assert relabelled(space, old) == {"iteration": 2, "xi_z_tail": 0.1, "gait_frequency": 1.2,
                                      "gait_phase_lag": 100.0, "grad_frequency": 0.3}
