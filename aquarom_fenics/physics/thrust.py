"""Lighthill thrust on a row of points (SPEC §5, "Thrust"); its exact Jacobians are in ``thrust_jacobians.py``.

Large-amplitude elongated-body theory in the x-y plane. The points are the stations (averages of
the body's motion, ``stations.py``) or, for the source's model, the spine nodes; below they are
called nodes, sorted tail -> head (node 0 at the tail); segment i joins its rear node r = i and
its front node f = i + 1.
For a segment with rest length ℓ_0 [m] and virtual mass per length m̃ [kg/m]:

    t = (x_f - x_r) / ℓ_0        (not normalised)
    n = R t,   ṅ = R (u̇_f - u̇_r) / ℓ_0,   R = [[0, -1], [1, 0]]  (+90° about z)

    f_tail  = ½ m̃ (v·n)² t                               at the tail node, segment 0, v = u̇_0
    f_spine = -m̃ ℓ_0 [ (a·n) n + (v·ṅ) n + (v·n) ṅ ]     at the rear node, v = u̇_r, a = ü_r
            = -m̃ ℓ_0 d/dt[ (v·n) n ]

    f_thrust = f_tail + Σ_segments f_spine   [N]

With ``spine_force = "lagrangian"`` each segment also carries ∂T_a/∂x of its added-mass energy
T_a = ½ m̃ ℓ_0 (v·n)² (n depends on the positions of its front and rear nodes):

    g = ∂T_a/∂x_f = -∂T_a/∂x_r = m̃ (v·n) Rᵀ v     at the front node, -g at the rear node

so that f_spine + ∂T_a/∂x = -d/dt(∂T_a/∂v) + ∂T_a/∂x (Lagrange's equations): its power is -dT_a/dt,
the added mass exchanges no net energy with the body over a closed cycle.

The spine force discretises Lighthill's line integral ∫ -d/dt[m̃ (v·n) n] ds along the body. The
rear-node rule above (SPEC §5) is its one-sided, first-order quadrature. With the segments' front
virtual masses m̃_f (``SpineGeometry.front_mass``) the *trapezoid rule* shares each segment between
its two nodes, second order in the segment length:

    f_r += ½ f_spine(v_r, a_r; m̃_r),   f_f += ½ f_spine(v_f, a_f; m̃_f)   (n, ṅ of the segment)

the added-mass energy T_a = Σ ¼ ℓ_0 [m̃_r (v_r·n)² + m̃_f (v_f·n)²]. Its front half is the rear rule
on the mirrored spine (nodes head -> tail: t, n, ṅ change sign, and every term is even in them), so
the forces and Jacobians of the front half are those of the rear half, mirrored back.

Every array is plain numpy; nodal vectors are (n_nodes, 2) in (x, y), and matrices use the dof
order (x0, y0, x1, y1, ...).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np

ROTATION_90 = np.array([[0.0, -1.0], [1.0, 0.0]])
"""R: rotation by +90° about z, R (a, b) = (-b, a)."""

_ROTATE_SIGNS = np.array([-1.0, 1.0])


def rotate(rows: np.ndarray) -> np.ndarray:
    """R x of row vectors x (..., 2): (-x_y, x_x), the product x Rᵀ without a matrix product."""
    return rows[..., ::-1] * _ROTATE_SIGNS


def rotate_back(rows: np.ndarray) -> np.ndarray:
    """Rᵀ x of row vectors x (..., 2): (x_y, -x_x), the product x R without a matrix product."""
    return rows[..., ::-1] * -_ROTATE_SIGNS


@dataclass(frozen=True)
class SpineGeometry:
    """The spine of one design at rest.

    rest_xy: (n_nodes, 2) x-y positions [m] of the spine nodes in the shape-varied configuration
        at rest, sorted tail -> head.
    virtual_mass: (n_nodes - 1,) virtual mass per length m̃ [kg/m] of each segment (at its rear node).
    spine_force: "source" (-d/dt(∂T_a/∂v)) or "lagrangian" (+∂T_a/∂x as well).
    front_mass: (n_nodes - 1,) m̃ [kg/m] at each segment's front node, for the trapezoid rule;
        None: the rear-node rule.
    """

    rest_xy: np.ndarray
    virtual_mass: np.ndarray
    spine_force: str = "source"
    front_mass: np.ndarray | None = None

    def __post_init__(self) -> None:
        rest_xy = np.asarray(self.rest_xy, dtype=float)
        segment_mass = np.asarray(self.virtual_mass, dtype=float)
        if rest_xy.ndim != 2 or rest_xy.shape[1] != 2 or rest_xy.shape[0] < 2:
            raise ValueError(f"rest_xy must be (n_nodes >= 2, 2), got {rest_xy.shape}")
        if segment_mass.shape != (rest_xy.shape[0] - 1,):
            raise ValueError(
                f"virtual_mass must be ({rest_xy.shape[0] - 1},) (one per segment), got {segment_mass.shape}"
            )
        object.__setattr__(self, "rest_xy", rest_xy)
        object.__setattr__(self, "virtual_mass", segment_mass)
        if self.front_mass is not None:
            front_mass = np.asarray(self.front_mass, dtype=float)
            if front_mass.shape != segment_mass.shape:
                raise ValueError(f"front_mass must be {segment_mass.shape} (one per segment), got {front_mass.shape}")
            object.__setattr__(self, "front_mass", front_mass)
        if np.any(self.rest_length <= 0.0):
            raise ValueError("spine nodes must be distinct (a segment has zero rest length)")
        if self.spine_force not in ("source", "lagrangian"):
            raise ValueError(f"spine_force must be 'source' or 'lagrangian', got {self.spine_force!r}")

    @property
    def lagrangian(self) -> bool:
        return self.spine_force == "lagrangian"

    @property
    def trapezoid(self) -> bool:
        """Whether the spine force follows the trapezoid rule (front masses given)."""
        return self.front_mass is not None

    @property
    def n_nodes(self) -> int:
        return self.rest_xy.shape[0]

    @cached_property
    def rest_length(self) -> np.ndarray:
        """(n_segments,) ℓ_0 = |x_f - x_r| at rest [m] (computed once: the geometry is frozen)."""
        return np.linalg.norm(segment_difference(self.rest_xy), axis=1)


def added_mass_density(fluid) -> float:
    """c_T ρ_w [kg/m³]: the fluid density of the virtual mass, ``[fluid] thrust_factor`` × ``density``
    (m̃ = c_T (π/4) ρ_w d² is linear in it, and so is the thrust)."""
    return fluid.density * fluid.thrust_factor


def virtual_mass(dorsal_z, fluid_density: float) -> np.ndarray:
    """Virtual mass per length m̃ = (π/4) ρ_w d², d = 2 z_dorsal [kg/m].

    dorsal_z: d/2 [m] of each segment in the shape-varied configuration: half the body's depth at its
    station (the stations), or the height of its dorsal node above the axis (the nodal model).
    fluid_density: ρ_w [kg/m³].
    """
    depth = 2.0 * np.asarray(dorsal_z, dtype=float)
    return 0.25 * np.pi * fluid_density * depth**2


def virtual_mass_gradient(dorsal_z, dorsal_z_gradient, fluid_density: float) -> np.ndarray:
    """∂m̃/∂ξ_k = 2π ρ_w z_dorsal ∂z_dorsal/∂ξ_k of m̃ = (π/4) ρ_w (2 z_dorsal)², (n_segments, p) [kg/m].

    dorsal_z_gradient: (n_segments, p) ∂z_dorsal/∂ξ_k [m].
    """
    return 2 * np.pi * fluid_density * np.asarray(dorsal_z, dtype=float)[..., None] * dorsal_z_gradient


def segment_difference(nodal: np.ndarray) -> np.ndarray:
    """x_f - x_r of every segment (rear r = i, front f = i + 1) of a nodal array, (n_segments, ...)."""
    return nodal[1:] - nodal[:-1]


def segment_frame(geometry: SpineGeometry, displacement: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangent t and normal n of every segment, each (n_segments, 2) [dimensionless].

    t = (x_f - x_r)/ℓ_0 (not normalised), n = R t; for a straight spine along +x, n = +y.
    """
    positions = geometry.rest_xy + displacement
    # t = (x_f - x_r) / ℓ_0
    tangent = segment_difference(positions) / geometry.rest_length[:, None]
    # n = R t
    normal = rotate(tangent)
    return tangent, normal


class SegmentState(NamedTuple):
    """Per-segment quantities entering the Lighthill forces and their Jacobians, (n_segments, ...) arrays.

    For the trapezoid rule the rows are the 2 n_segments *half-segments*: the spine's segments with
    their rear nodes' kinematics, then the mirrored spine's (segment n_segments - 1 - i of the spine,
    with -t, -ṫ and its front node's kinematics), so that one pass of the rear rule's formulas
    evaluates both halves."""

    rest_length: np.ndarray
    tangent: np.ndarray
    normal: np.ndarray
    normal_rate: np.ndarray
    rear_velocity: np.ndarray
    rear_acceleration: np.ndarray
    a_dot_n: np.ndarray          # a·n
    v_dot_ndot: np.ndarray       # v·ṅ
    v_dot_n: np.ndarray          # v·n


def segment_state(geometry: SpineGeometry, displacement, velocity, acceleration) -> SegmentState:
    """The segments' frames, rates and rear (and, for the trapezoid rule, front) kinematics of the
    (n_nodes, 2) x-y nodal fields, tail -> head."""
    displacement, velocity, acceleration = _check_nodal(geometry, displacement, velocity, acceleration)
    tangent, _ = segment_frame(geometry, displacement)
    # ṫ = (u̇_f - u̇_r) / ℓ_0
    tangent_rate = segment_difference(velocity) / geometry.rest_length[:, None]
    front = (velocity[1:], acceleration[1:]) if geometry.trapezoid else ()
    return segment_state_of(geometry.rest_length, tangent, tangent_rate, velocity[:-1], acceleration[:-1], *front)


def segment_state_of(rest_length, tangent, tangent_rate, rear_velocity, rear_acceleration,
                     front_velocity=None, front_acceleration=None) -> SegmentState:
    """The segment state from each segment's t = (x_f - x_r)/ℓ_0, its rate ṫ and the rear node's u̇ and ü,
    (n_segments, 2) each: n = R t, ṅ = R ṫ and the products a·n, v·ṅ, v·n of the rear node. With the
    front nodes' u̇ and ü (the trapezoid rule) the rows are the half-segments of :class:`SegmentState`."""
    if front_velocity is not None:
        # the mirrored spine: segments head -> tail, t and ṫ of opposite sign, rear node = the front node
        rest_length = np.concatenate([rest_length, rest_length[::-1]])
        tangent = np.concatenate([tangent, -tangent[::-1]])
        tangent_rate = np.concatenate([tangent_rate, -tangent_rate[::-1]])
        rear_velocity = np.concatenate([rear_velocity, front_velocity[::-1]])
        rear_acceleration = np.concatenate([rear_acceleration, front_acceleration[::-1]])
    normal, normal_rate = rotate(tangent), rotate(tangent_rate)
    return SegmentState(
        rest_length=rest_length,
        tangent=tangent,
        normal=normal,
        normal_rate=normal_rate,
        rear_velocity=rear_velocity,
        rear_acceleration=rear_acceleration,
        a_dot_n=_row_dot(rear_acceleration, normal),
        v_dot_ndot=_row_dot(rear_velocity, normal_rate),
        v_dot_n=_row_dot(rear_velocity, normal),
    )


def _check_nodal(geometry, *nodal_fields):
    expected = (geometry.n_nodes, 2)
    fields = tuple(np.asarray(field, dtype=float) for field in nodal_fields)
    for field in fields:
        if field.shape != expected:
            raise ValueError(f"spine nodal field must be {expected}, got {field.shape}")
    return fields


def _row_dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a_i·b_i of (..., n, 2) rows."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def _tail_force_per_mass(state: SegmentState) -> np.ndarray:
    """f_tail / m̃_0 = ½ (v·n)² t with segment 0's t, n and the tail node's v, (..., 2) [m²/s²]."""
    normal_velocity = state.v_dot_n[..., 0]
    # f_tail / m̃ = ½ (v·n)² t
    return 0.5 * (normal_velocity**2)[..., None] * state.tangent[..., 0, :]


def _spine_force_per_mass(state: SegmentState) -> np.ndarray:
    """f_spine / m̃ = -ℓ_0 [(a·n) n + (v·ṅ) n + (v·n) ṅ] per segment, (..., n_segments, 2) [m²/s²]."""
    # f_spine / m̃ = -ℓ_0 [ (a·n + v·ṅ) n + (v·n) ṅ ]
    bracket = (state.a_dot_n + state.v_dot_ndot)[..., None] * state.normal + state.v_dot_n[..., None] * state.normal_rate
    return -state.rest_length[..., None] * bracket


def _position_force_per_mass(state: SegmentState) -> np.ndarray:
    """g / m̃ = (v·n) Rᵀ v per segment (∂T_a/∂x_f / m̃, = -∂T_a/∂x_r / m̃), (..., n_segments, 2) [m²/s²]."""
    return state.v_dot_n[..., None] * rotate_back(state.rear_velocity)


def segment_weighted_force(geometry: SpineGeometry, state: SegmentState, spine_weight: np.ndarray,
                           tail_weight, front_weight: np.ndarray | None = None) -> np.ndarray:
    """Σ_i w_i f_i/m̃_i on the nodes, (..., n_nodes, 2): the per-mass forces of every segment i weighted by
    ``spine_weight`` (..., n_segments) at its rear node, f_tail/m̃_0 by ``tail_weight`` (...) at node 0 and,
    for the lagrangian form, ±g_i/m̃_i by the same weight at nodes i + 1, i. For the trapezoid rule the
    rear half carries ½ ``spine_weight`` and the front half ½ ``front_weight``.

    With w = m̃ this is the thrust f; f is linear in m̃, so with w = ∂m̃/∂ξ_k it is ∂f/∂ξ_k through the virtual
    masses (leading axis k).
    """
    spine_weight = np.asarray(spine_weight)
    n_segments = geometry.n_nodes - 1
    if geometry.trapezoid:
        # the half-segments' weights: ½ w_r, then ½ w_f of the mirrored segments (head -> tail)
        spine_weight = 0.5 * np.concatenate([spine_weight, np.asarray(front_weight)[..., ::-1]], axis=-1)
    # w f_spine/m̃ on each (half-)segment's own node: the rear node, or the front node for the mirrored half
    per_segment = spine_weight[..., :, None] * _spine_force_per_mass(state)
    force = np.zeros(per_segment.shape[:-2] + (geometry.n_nodes, 2))
    force[..., :-1, :] = per_segment[..., :n_segments, :]
    if geometry.trapezoid:
        force[..., 1:, :] += per_segment[..., :n_segments - 1:-1, :]
    # f_0 += w_0 f_tail/m̃_0
    force[..., 0, :] += np.asarray(tail_weight)[..., None] * _tail_force_per_mass(state)
    if geometry.lagrangian:
        # f_f += g, f_r -= g with g = w (v·n) Rᵀ v (for the mirrored half its f is the rear node r)
        position_force = spine_weight[..., :, None] * _position_force_per_mass(state)
        rear_half = position_force[..., :n_segments, :]
        force[..., 1:, :] += rear_half
        force[..., :-1, :] -= rear_half
        if geometry.trapezoid:
            front_half = position_force[..., :n_segments - 1:-1, :]
            force[..., :-1, :] += front_half
            force[..., 1:, :] -= front_half
    return force


def thrust_force(geometry: SpineGeometry, displacement, velocity, acceleration) -> np.ndarray:
    """Lighthill thrust f = f_tail + Σ f_spine on the spine nodes, (n_nodes, 2) [N].

    displacement [m], velocity [m/s], acceleration [m/s²]: (n_nodes, 2) x-y fields of the spine
    nodes, tail -> head. The head node (the last one) is never a rear node and receives nothing.
    """
    return thrust_force_of_state(geometry, segment_state(geometry, displacement, velocity, acceleration))


def thrust_force_of_state(geometry: SpineGeometry, state: SegmentState) -> np.ndarray:
    """``thrust_force`` from the segment state."""
    mass = geometry.virtual_mass
    return segment_weighted_force(geometry, state, mass, mass[..., 0], geometry.front_mass)


def thrust_force_per_virtual_mass(
    geometry: SpineGeometry, displacement, velocity, acceleration
) -> np.ndarray:
    """∂f/∂m̃_i of the thrust, (n_segments, n_nodes, 2) [N m/kg].

    f is linear in each segment's m̃, so f = Σ_i m̃_i ∂f/∂m̃_i. Row i holds f_spine,i / m̃_i at node
    i, plus f_tail / m̃_0 at node 0 for i = 0, and for the lagrangian form ±g_i / m̃_i at nodes
    i + 1 and i. The rear-node rule only (the trapezoid rule is linear in m̃_r and m̃_f alike).
    """
    if geometry.trapezoid:
        raise ValueError("thrust_force_per_virtual_mass is the rear-node rule's; this spine has front masses")
    state = segment_state(geometry, displacement, velocity, acceleration)
    n_segments = geometry.n_nodes - 1
    segments = np.arange(n_segments)
    per_mass = np.zeros((n_segments, geometry.n_nodes, 2))
    # ∂f_r/∂m̃_i = δ_ri f_spine,i / m̃_i
    per_mass[segments, segments] = _spine_force_per_mass(state)
    # ∂f_0/∂m̃_0 += f_tail / m̃_0
    per_mass[0, 0] += _tail_force_per_mass(state)
    if geometry.lagrangian:
        # ∂f_{i+1}/∂m̃_i += g_i / m̃_i,  ∂f_i/∂m̃_i -= g_i / m̃_i
        position_force = _position_force_per_mass(state)
        per_mass[segments, segments + 1] += position_force
        per_mass[segments, segments] -= position_force
    return per_mass


def derivative_weights(geometry: SpineGeometry, mass_gradient: np.ndarray,
                       length_gradient: np.ndarray | None = None,
                       front_mass_gradient: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(spine weights (p, n_segments), tail weights (p,), front weights (p, n_segments) or None) for which
    ``segment_weighted_force`` is ∂f/∂ξ_k at fixed positions through the virtual masses, ∂m̃/∂ξ =
    ``mass_gradient`` (n_segments, p) and, for the trapezoid rule, ∂m̃_f/∂ξ = ``front_mass_gradient``, and
    the rest lengths, ∂ℓ_0/∂ξ = ``length_gradient`` (n_segments, p; None: fixed).

    f is linear in m̃: w = ∂m̃/∂ξ_k (Σ_i (∂f/∂m̃_i) ∂m̃_i/∂ξ_k). With t, n and ṅ each ∝ 1/ℓ_0, f_spine and g are
    ∝ ℓ_0⁻¹ and f_tail ∝ ℓ_0⁻³, so ∂f/∂ℓ_0 = -(3 f_tail + f_spine ± g)/ℓ_0 at fixed positions: w gains
    -m̃ (∂ℓ_0/∂ξ_k)/ℓ_0, three times that on f_tail (and -m̃_f (∂ℓ_0/∂ξ_k)/ℓ_0 on the front half).
    """
    spine_weight = np.swapaxes(mass_gradient, -1, -2)
    tail_weight = spine_weight[..., 0]
    front_weight = np.swapaxes(front_mass_gradient, -1, -2) if geometry.trapezoid else None
    if length_gradient is not None:
        relative_length = np.swapaxes(length_gradient, -1, -2) / geometry.rest_length[..., None, :]
        length_weight = -geometry.virtual_mass[..., None, :] * relative_length
        spine_weight = spine_weight + length_weight
        tail_weight = tail_weight + 3.0 * length_weight[..., 0]
        if front_weight is not None:
            front_weight = front_weight - geometry.front_mass[..., None, :] * relative_length
    return spine_weight, tail_weight, front_weight
