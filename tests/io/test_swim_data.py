"""A measured swim's CSV (issue 52): read as the model's frame and units, every bad case refused by
`aquarom calibrate` in one line with exit code 2 before any model runs."""
import numpy as np
import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.errors import InputError
from aquarom_fenics.io.swim_data import read_swim
from conftest import one_line, write_short_scene

GOOD = "time_s,head_x_m,tail_y_m\n0.01,0.0001,0.002\n0.02,0.0003,0.004\n0.03,0.0006,0.005\n"


def test_a_good_file_reads_as_times_and_displacements(tmp_path):
    path = tmp_path / "swim.csv"
    path.write_text("\ufeff" + GOOD.replace("tail_y_m\n", "tail_y_m\n\n"))
    swim = read_swim(path, duration=0.2, n_parameters=2, body_length=0.2)
    assert swim.observables == ("head_x", "tail_y") and swim.columns == ("head_x_m", "tail_y_m")
    np.testing.assert_array_equal(swim.time, [0.01, 0.02, 0.03])
    np.testing.assert_array_equal(swim.values[:, 1], [0.002, 0.004, 0.005])


def test_tail_x_and_com_y_columns_are_read_as_their_points(tmp_path):
    path = tmp_path / "swim.csv"
    path.write_text("time_s,com_y_m,tail_x_m\n0.01,0.0001,-0.0002\n0.02,0.0003,-0.0004\n")
    swim = read_swim(path, duration=0.2, n_parameters=2, body_length=0.2)
    assert swim.observables == ("com_y", "tail_x") and swim.columns == ("com_y_m", "tail_x_m")
    np.testing.assert_array_equal(swim.values[:, 1], [-0.0002, -0.0004])


CASES = {
    "no time_s": ("t,head_x_m\n0.01,0.001\n", ["time_s"]),
    "time_s not first": ("head_x_m,time_s\n0.001,0.01\n", ["first column must be time_s"]),
    "unknown column": ("time_s,fin_x_m\n0.01,0.001\n", ["unknown column 'fin_x_m'", "head_x_m"]),
    "duplicate column": ("time_s,head_x_m,head_x_m\n0.01,0.001,0.001\n", ["head_x_m appears twice"]),
    "NaN": ("time_s,head_x_m\n0.01,0.001\n0.02,nan\n0.03,0.002\n", ["line 3", "finite"]),
    "not a number": ("time_s,head_x_m\n0.01,0.001\n0.02,1mm\n", ["'1mm' is not a number"]),
    "ragged row": ("time_s,head_x_m\n0.01,0.001,3\n", ["line 2 has 3 value(s)"]),
    "times not increasing": ("time_s,head_x_m\n0.01,0.001\n0.02,0.002\n0.02,0.003\n", ["not increasing"]),
    "times going back": ("time_s,head_x_m\n0.02,0.001\n0.01,0.002\n0.03,0.003\n", ["not increasing"]),
    "fewer rows than parameters": ("time_s,head_x_m\n0.01,0.001\n", ["1 row(s)", "more data than parameters"]),
    "times beyond the duration": ("time_s,head_x_m\n0.01,0.001\n0.5,0.002\n0.6,0.003\n", ["beyond", "duration"]),
    "range of pixels": ("time_s,tail_y_m\n0.01,12\n0.02,140\n0.03,310\n", ["tail_y_m", "10 body lengths", "pixels"]),
    "range of millimetres": ("time_s,head_x_m\n0.01,0\n0.02,1500\n0.03,3000\n", ["millimetres"]),
    "head y": ("time_s,head_x_m,head_y_m\n0.01,0.001,0.0\n", ["head_y_m", "held in y and z"]),
    "head z": ("time_s,head_z_m\n0.01,0.001\n", ["head_z_m", "held in y and z"]),
    "no tracked column": ("time_s\n0.01\n", ["no tracked column"]),
    "header only": ("time_s,head_x_m\n", ["no rows"]),
    "empty": ("", ["empty"]),
}


@pytest.mark.parametrize("case", CASES)
def test_bad_data_is_one_line_and_exit_code_2(case, tmp_path, capsys):
    text, expected = CASES[case]
    data = tmp_path / "swim.csv"
    data.write_text(text)
    scene = write_short_scene(tmp_path, duration=0.2)
    code = main(["calibrate", scene, "--data", str(data), "--fit", "material.young_modulus",
                 "--fit", "fluid.thrust_factor", "--out", str(tmp_path / "out")])
    assert code == 2
    line = one_line(capsys)
    for part in expected:
        assert part in line, line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("fits, expected", [
    (["actuation.stiffness", "actuation.amplitude"], ["product k·A"]),
    (["material.poisson_ratio"], ["not a calibration parameter", "material.young_modulus"]),
    (["fluid.drag_factor=2:1"], ["0 < LO < HI"]),
    (["fluid.drag_factor=2:3"], ["outside [2, 3]"]),
    (["fluid.drag_factor=0.5"], ["LO:HI"]),
    (["material.young_modulus", "material.young_modulus"], ["twice"]),
    ([], ["--fit is required"]),
])
def test_bad_fits_are_one_line_and_exit_code_2(fits, expected, tmp_path, capsys):
    data = tmp_path / "swim.csv"
    data.write_text(GOOD)
    scene = write_short_scene(tmp_path, duration=0.2)
    arguments = [item for fit in fits for item in ("--fit", fit)]
    assert main(["calibrate", scene, "--data", str(data), *arguments, "--out", str(tmp_path / "out")]) == 2
    line = one_line(capsys)
    for part in expected:
        assert part in line, line


def test_a_fitted_key_at_zero_and_a_missing_data_file_are_refused(tmp_path, capsys):
    scene = write_short_scene(tmp_path, duration=0.2, extra="[material]\nrayleigh_alpha = 0\n")
    data = tmp_path / "swim.csv"
    data.write_text(GOOD)
    assert main(["calibrate", scene, "--data", str(data), "--fit", "material.rayleigh_alpha"]) == 2
    assert "value > 0" in one_line(capsys)
    assert main(["calibrate", scene, "--data", str(tmp_path / "none.csv"), "--fit", "fluid.drag_factor"]) == 2
    assert "none.csv" in one_line(capsys)
    with pytest.raises(InputError):
        read_swim(tmp_path, 0.2, 1, 0.2)
