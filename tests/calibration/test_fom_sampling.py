"""The FOM sampled at the data's times as the reduced model is: cubic Hermite interpolation of its positions and
the velocities it records (fourth order between the time steps), by the fit and by the validation study alike,
whose camera frames fall between the time steps."""
import numpy as np

from aquarom_fenics.calibration.fit import sample_trajectory
from aquarom_fenics.calibration.report import fom_model
from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.dynamics.trajectory import OBSERVED, Trajectory
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.io.swim_data import SwimData
from aquarom_fenics.verification.validation import calibration as study
from conftest import coarse_scene

OMEGA = 2 * np.pi * 2.0        # rad/s: a 2 Hz stroke


def smooth(t):
    """A known smooth motion of the five points [m] and its velocity [m/s], at rest at t = 0."""
    phases = np.arange(len(OBSERVED))
    value = 1e-2 * np.sin(OMEGA * t[:, None] + phases) - 1e-2 * np.sin(phases) + 3e-3 * t[:, None] ** 2
    rate = 1e-2 * OMEGA * np.cos(OMEGA * t[:, None] + phases) + 6e-3 * t[:, None]
    return value, rate


def smooth_run(step: float, duration: float = 0.4):
    """A stand-in for a FOM run whose trajectory is :func:`smooth` on a grid of ``step`` [s]."""
    grid = np.linspace(0.0, duration, int(round(duration / step)) + 1)
    value, rate = smooth(grid)
    trajectory = Trajectory()
    for t, y, v in zip(grid, value, rate):
        trajectory.append(t, *y, 0, rates=v)

    class Run:
        completed = True
    run = Run()
    run.trajectory = trajectory
    return run


def frames(duration: float = 0.4) -> np.ndarray:
    return study.frame_times(duration)


def test_the_sampling_is_fourth_order_between_the_time_steps():
    """max |y_h(t) - y(t)| at 240 Hz frames for h = 20, 10, 5 ms: ratios near 16; at 20 ms a hundredth of linear
    interpolation's error."""
    times = frames()
    exact = smooth(times)[0]
    errors, linear = [], []
    for step in (0.02, 0.01, 0.005):
        trajectory = smooth_run(step).trajectory
        errors.append(np.abs(sample_trajectory(trajectory, times, OBSERVED) - exact).max())
        arrays = trajectory.arrays()
        linear.append(np.abs(np.column_stack([np.interp(times, arrays["time"], arrays[name]) for name in OBSERVED])
                             - exact).max())
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((13.0 < ratios) & (ratios < 19.0)), ratios
    assert errors[0] < 1e-2 * linear[0], (errors, linear)


def test_before_the_start_the_sampled_fom_is_at_rest_and_on_the_grid_it_is_the_run():
    trajectory = smooth_run(0.02).trajectory
    np.testing.assert_array_equal(sample_trajectory(trajectory, np.array([-0.03, -0.001]), ("tail_y",)), 0.0)
    arrays = trajectory.arrays()
    on_grid = sample_trajectory(trajectory, arrays["time"], OBSERVED)
    np.testing.assert_allclose(on_grid, np.column_stack([arrays[name] for name in OBSERVED]), rtol=0, atol=1e-15)


def test_the_study_and_the_fit_sample_the_fom_alike(monkeypatch):
    """The study's clean swim and the fit's FOM model at the study's frames: both the Hermite sampling (the
    exact motion to 1e-4 of its size, where linear interpolation misses by about 1 %)."""
    run = smooth_run(0.02)
    times = frames()
    exact = smooth(times)[0][:, [OBSERVED.index(name) for name in study.OBSERVED]]

    class NoNoise:
        def standard_normal(self, shape):
            return np.zeros(shape)

    monkeypatch.setattr(study, "DURATION", 0.4)
    swim = study.synthetic_swim(run, NoNoise(), "<test>")
    np.testing.assert_array_equal(swim.time, times)
    assert np.abs(swim.values - exact).max() < 1e-4 * np.abs(exact).max()
    monkeypatch.setattr("aquarom_fenics.dynamics.simulate.simulate_fom", lambda *args, **kwargs: run)
    data = SwimData(times, np.zeros_like(exact), study.OBSERVED, "<test>")
    _, model = fom_model(None, {}, None, data, progress=False)
    np.testing.assert_array_equal(model, swim.values)


def test_the_study_s_frames_fall_between_the_time_steps():
    step = Scene.load(study.SCENE).solver.time_step
    times = study.frame_times()
    on_grid = np.isclose(times / step, np.round(times / step), rtol=0, atol=1e-9)
    assert times.size == round(study.DURATION * study.FRAME_RATE)
    assert on_grid.mean() <= 0.25 and not on_grid[0], on_grid.mean()


def velocity_deviation(step: float) -> np.ndarray:
    """Per point (head x, tail y, com x), the largest difference between the recorded velocities and the
    central differences of the positions, over the largest speed, on a 0.3 s FOM swim with ``step``."""
    run = simulate_fom(coarse_scene(solver={"duration": 0.3, "time_step": step}), progress=False)
    arrays, rates = run.trajectory.arrays(), run.trajectory.rate_arrays()
    assert np.all([rates[name][0] == 0.0 for name in OBSERVED])
    deviation = []
    for name in ("head_x", "tail_y", "com_x"):
        differences = (arrays[name][2:] - arrays[name][:-2]) / (2 * step)
        deviation.append(np.abs(rates[name][1:-1] - differences).max() / np.abs(rates[name]).max())
    return np.array(deviation)


def test_the_fom_records_its_observed_points_velocities():
    """The recorded velocities are d/dt of the recorded positions to the scheme's accuracy: their distance
    from the positions' central differences is under 10 % of the largest speed at 20 ms and falls as the step
    halves at least as h does (ratio above 1.8; measured 2.2–2.9)."""
    coarse, fine = velocity_deviation(0.02), velocity_deviation(0.01)
    assert np.all(coarse < 0.1), coarse
    assert np.all(coarse / fine > 1.8), coarse / fine
