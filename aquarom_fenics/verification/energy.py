"""Per-force discrete energy balance of a FOM run under its time scheme (SPEC §5–§6).

The work of each force over a step n → n+1 is the trapezoidal rule on the stored states,
W_F,n = ½ (F_n + F_{n+1})·Δu with Δu = u_{n+1} - u_n: second order for every scheme, so the
works do not depend on where the scheme evaluates its forces. Summed over the steps:

    W_act + W_thrust,a + W_thrust,v + W_drag = D_Rayleigh + D_numerical + ΔT + ΔΠ + Σ_n ρ_n

    W_thrust,a   the thrust's acceleration (added-mass) term f(u, u̇, ü) - f(u, u̇, 0), an inertia, taken
                 like M ü at the points p below (Σ_p w_p f_a,p·Δu: the scheme's ü_n lags ü(t_n) by
                 O(h) for α_m ≠ α_f); W_thrust,v the rest: velocity terms, tail force and, for the
                 lagrangian form, ∂T_a/∂x
    D_Rayleigh   = Σ ½ (C u̇_n + C u̇_{n+1})·Δu
    ΔT, ΔΠ       kinetic ½ u̇ᵀM u̇ and strain energy at the end minus at the start [J]
    ρ_n          = Σ_p w_p r_p·Δu, the residuals r_p at the points where the step solved r = 0
                 (generalized-α: the evaluation point (t_{n+1-α_f}, u_{n+1-α_f}, u̇_{n+1-α_f}, ü_{n+1-α_m}),
                 w = 1; Newmark: t_n and t_{n+1}, w = ½, a run from rest with zero force has r_0 = 0)

The step equations give Σ_p w_p r_p·Δu = 0, which fixes the scheme's numerical dissipation:

    D_numerical,n = Σ_F W_F,n - D_Rayleigh,n - ΔT_n - ΔΠ_n - Σ_p w_p r_p·Δu

the energy the discrete equations remove beyond the physical dissipation (zero up to O(Δu³) for
the trapezoidal rule, Newmark α_N = 0). The imbalance that is left is Σ ρ_n, the Newton residual of
the steps, a check that the forces split here are the ones the integrator solved with.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from mpi4py import MPI

from aquarom_fenics.dynamics.integrator import TimeScheme


@dataclass
class EnergyBalance:
    """Cumulative energies [J] at the stored samples (first entry 0) and the closure of the balance."""

    time: np.ndarray
    work_actuation: np.ndarray
    work_thrust_acceleration: np.ndarray
    work_thrust_velocity: np.ndarray
    work_drag: np.ndarray
    dissipated_rayleigh: np.ndarray
    dissipated_numerical: np.ndarray
    kinetic_change: np.ndarray
    strain_change: np.ndarray
    newton_residual: np.ndarray      # Σ ρ_n, what the balance leaves

    @property
    def works(self) -> dict[str, np.ndarray]:
        return {"actuation": self.work_actuation, "thrust_acceleration": self.work_thrust_acceleration,
                "thrust_velocity": self.work_thrust_velocity, "drag": self.work_drag}

    @property
    def imbalance(self) -> np.ndarray:
        """Σ W_F - D_Rayleigh - D_numerical - ΔT - ΔΠ [J]."""
        return (sum(self.works.values()) - self.dissipated_rayleigh - self.dissipated_numerical
                - self.kinetic_change - self.strain_change)

    @property
    def throughput(self) -> float:
        """Σ_n Σ_F |ΔW_F,n| [J], the scale of the balance (final works can nearly cancel over a cycle)."""
        return float(sum(np.abs(np.diff(work)).sum() for work in self.works.values()))

    @property
    def relative_imbalance(self) -> float:
        return float(abs(self.imbalance[-1]) / self.throughput) if self.throughput > 0 else float("nan")

    def summary(self) -> dict:
        """Final values [J], the throughput and the relative imbalance."""
        values = {name: float(series[-1]) for name, series in asdict(self).items() if name != "time"}
        return values | {"throughput": self.throughput, "imbalance": float(self.imbalance[-1]),
                         "relative_imbalance": self.relative_imbalance}


def nodal_forces(model, time: float, u, v, a) -> dict[str, np.ndarray]:
    """The forces of the balance at one state, owned dofs [N]: f_act, the thrust's added-mass term
    and the rest of the thrust, f_drag, and the Rayleigh force C u̇."""
    thrust_without_acceleration = model.thrust_force(u, v, np.zeros_like(a))
    return {"actuation": model.actuation_force(time, u),
            "thrust_acceleration": model.thrust_force(u, v, a) - thrust_without_acceleration,
            "thrust_velocity": thrust_without_acceleration, "drag": model.drag_force(v),
            "rayleigh": model.matvec(model.damping_matrix, v)}


def evaluation_points(scheme: TimeScheme, time_old: float, time_new: float, old, new):
    """(weight, (t, u, u̇, ü)) of the points where the step's residuals vanish (module docstring)."""
    if scheme.alpha_m == 0.0 and scheme.alpha_f == 0.0:
        return [(0.5, (time_old, *old)), (0.5, (time_new, *new))]
    return [(1.0, scheme.evaluation_point(time_new, old, new))]


def energy_balance(result) -> EnergyBalance:
    """The balance of a completed ``simulate_fom(..., keep_states=True)`` run on the grid of h.

    Needs the states of every step of h, so a run with cut steps is refused (ValueError).
    """
    if result.cut_steps:
        raise ValueError(f"energy balance: the run cut {result.cut_steps} steps; it needs uniform steps of h")
    model = result.model
    scheme = model.scheme
    comm = model.comm
    times = np.asarray(result.trajectory.time)
    states = result.states                      # (u, u̇, ü) on the grid of h
    displacements = [u for u, _, _ in states]
    velocities = [v for _, v, _ in states]

    def dot(force, increment) -> float:
        return comm.allreduce(float(force @ increment), op=MPI.SUM)

    increments = {name: [0.0] for name in ("actuation", "thrust_acceleration", "thrust_velocity", "drag",
                                           "rayleigh", "numerical", "kinetic", "strain", "residual")}
    kinetic = [model.kinetic_energy(v) for v in velocities]
    strain = [model.elastic_energy(u) for u in displacements]
    forces = [nodal_forces(model, float(time), *state) for time, state in zip(times, states)]
    for n in range(len(states) - 1):
        old, new = states[n], states[n + 1]
        step = new[0] - old[0]
        values = {name: 0.5 * dot(forces[n][name] + forces[n + 1][name], step) for name in forces[n]}
        points = evaluation_points(scheme, float(times[n]), float(times[n + 1]), old, new)
        # the added mass is inertia: its work at the points where the scheme evaluates ü
        values["thrust_acceleration"] = sum(weight * dot(nodal_forces(model, *point)["thrust_acceleration"], step)
                                            for weight, point in points)
        values["kinetic"], values["strain"] = kinetic[n + 1] - kinetic[n], strain[n + 1] - strain[n]
        values["residual"] = sum(weight * dot(model.residual(*point)[0], step) for weight, point in points)
        # D_numerical,n = Σ_F W_F,n - D_Rayleigh,n - ΔT_n - ΔΠ_n - Σ_p w_p r_p·Δu
        values["numerical"] = (sum(values[name] for name in ("actuation", "thrust_acceleration", "thrust_velocity",
                                                              "drag"))
                               - values["rayleigh"] - values["kinetic"] - values["strain"] - values["residual"])
        for name, value in values.items():
            increments[name].append(value)
    cumulative = {name: np.cumsum(values) for name, values in increments.items()}
    return EnergyBalance(time=times, work_actuation=cumulative["actuation"],
                         work_thrust_acceleration=cumulative["thrust_acceleration"],
                         work_thrust_velocity=cumulative["thrust_velocity"], work_drag=cumulative["drag"],
                         dissipated_rayleigh=cumulative["rayleigh"], dissipated_numerical=cumulative["numerical"],
                         kinetic_change=cumulative["kinetic"], strain_change=cumulative["strain"],
                         newton_residual=cumulative["residual"])


def spine_spectrum(times, lateral, frequency: float, window: float = 1.0) -> dict:
    """Which lateral motion of the spine carries the late-time response, and whether it grows.

    ``lateral`` (n_samples, n_spine) holds y_i(t_n) of the spine nodes (tail → head) on a uniform grid.
    Over the last ``window`` s (mean removed, Hann-weighted), Y_i(f) = Σ_n w_n y_i(t_n) e^{-2πi f t_n}:

        peak         the f maximising P(f) = Σ_i |Y_i(f)|², and its share of Σ_f P(f)
        shape        Re(Y_i(f_peak) e^{-iφ}) / max_i |Y_i(f_peak)|, φ the phase of the largest entry
        sign_changes number of sign changes of the shape between neighbouring nodes (n_spine - 1: a
                     zig-zag at the node spacing, 0: a whole-body bending)
        high         the same (peak, share, shape, sign_changes) over f ≥ 2.5 f_actuation
        harmonic_share  share of Σ_f P(f) at f < 2.5 f_actuation (the forced gait and its 2nd harmonic)
        growth       RMS of the part above 2.5 f_actuation over the window's last quarter ÷ over its
                     first quarter (> 1: a high-frequency motion grows)
    """
    times = np.asarray(times, dtype=float)
    lateral = np.asarray(lateral, dtype=float)
    late = times >= times[-1] - window - 1e-12
    t, y = times[late], lateral[late]
    y = y - y.mean(axis=0)
    spectrum = np.fft.rfft(y * np.hanning(t.size)[:, None], axis=0)
    frequencies = np.fft.rfftfreq(t.size, d=float(t[1] - t[0]))
    power = (np.abs(spectrum) ** 2).sum(axis=1)
    above = frequencies >= 2.5 * frequency
    high = np.fft.irfft(np.where(above[:, None], np.fft.rfft(y, axis=0), 0.0), n=t.size, axis=0)
    quarter = max(t.size // 4, 1)
    early, final = (float(np.sqrt(np.mean(part ** 2))) for part in (high[:quarter], high[-quarter:]))
    return {"window": [float(t[0]), float(t[-1])],
            **_spectral_peak(frequencies, spectrum, power, frequencies > 0),
            "high": _spectral_peak(frequencies, spectrum, power, above),
            "harmonic_share": float(power[~above].sum() / power.sum()),
            "growth": final / early if early > 0 else float("inf"), "high_frequency_rms": final}


def _spectral_peak(frequencies, spectrum, power, selected) -> dict:
    """Peak of P(f) among the ``selected`` frequencies, its share of Σ_f P(f), its real shape along the spine."""
    peak = int(np.flatnonzero(selected)[np.argmax(power[selected])])
    mode = spectrum[peak] * np.exp(-1j * np.angle(spectrum[peak][np.argmax(np.abs(spectrum[peak]))]))
    shape = mode.real / np.abs(mode).max()
    return {"peak": float(frequencies[peak]), "peak_share": float(power[peak] / power.sum()),
            "shape": shape.tolist(),
            "sign_changes": int(np.count_nonzero(np.diff(np.sign(shape[np.abs(shape) > 1e-3]))))}
