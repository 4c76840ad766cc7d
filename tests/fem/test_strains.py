"""The largest principal Green–Lagrange strain of a run (fem/strains.py): its value against a closed
form on one cell, its region from the tags, the warning line, and the FOM's and ROM's reports."""
import json
import logging

import numpy as np
import pytest
from mpi4py import MPI

from conftest import write_short_scene

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.fem.strains import (STRAIN_LIMIT, StrainProbe, StrainReport, is_sampled, largest_principal,
                                        report_strains, sampling_stride)

CORNER = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
SHAPE_GRADIENT = np.array([[0.1, 0.02, 0.0], [0.0, -0.05, 0.03], [0.01, 0.0, 0.08]])
DISPLACEMENT_GRADIENT = np.array([[0.03, -0.01, 0.02], [0.04, 0.01, 0.0], [0.0, 0.02, -0.03]])


def test_the_probe_gives_the_largest_eigenvalue_of_the_strain_of_a_homogeneous_deformation():
    mesh = fx.create_tet_mesh(MPI.COMM_WORLD, CORNER, np.array([[0, 1, 2, 3]]))
    space = fx.vector_space(mesh, 1)
    shape_gradient = fx.tensor_constant(mesh, (3, 3))
    shape_gradient.value = SHAPE_GRADIENT
    probe = StrainProbe(space, shape_gradient, 2, ("passive body", "head"), np.array([1]), MPI.COMM_WORLD, 10)
    probe.displacement.interpolate(lambda x: DISPLACEMENT_GRADIENT @ x)
    probe.sample(0.5)
    shape = np.eye(3) + SHAPE_GRADIENT
    relative = (shape + DISPLACEMENT_GRADIENT) @ np.linalg.inv(shape)
    expected = np.linalg.eigvalsh(0.5 * (relative.T @ relative - np.eye(3)))[-1]
    report = probe.report
    assert report.maximum == pytest.approx(expected, rel=1e-10)
    assert (report.time, report.region) == (0.5, "head")
    assert report.by_region == {"head": pytest.approx(expected, rel=1e-10)}


def test_largest_principal_and_the_sampled_steps():
    strain = np.diag([0.01, -0.04, 0.03])
    rotation = np.linalg.qr(np.arange(9.0).reshape(3, 3) + np.eye(3))[0]
    assert largest_principal(rotation @ strain @ rotation.T) == pytest.approx(0.03)
    tensors = np.random.default_rng(5).standard_normal((200, 3, 3))
    tensors = 0.5 * (tensors + tensors.transpose(0, 2, 1))
    tensors[0], tensors[1] = 0.02 * np.eye(3), np.diag([0.01, 0.01, -0.02])      # p = 0 and a double root
    assert largest_principal(tensors) == pytest.approx(np.linalg.eigvalsh(tensors)[:, -1], rel=1e-9, abs=1e-12)
    assert sampling_stride(100) == 1 and sampling_stride(250) == 3
    assert [step for step in range(11) if is_sampled(step, 10, 3)] == [0, 3, 6, 9, 10]


def test_one_warning_line_above_the_limit_only_for_a_completed_run(caplog):
    report = StrainReport(1, 2, ("passive body", "head"))
    report.add(0.1, 0.5 * STRAIN_LIMIT, "head", [0, 0, 0], {"head": 0.5 * STRAIN_LIMIT})
    assert report.warning() is None
    report.add(0.3, 2.0 * STRAIN_LIMIT, "passive body", [1, 0, 0], {"passive body": 2.0 * STRAIN_LIMIT})
    assert (report.time, report.region) == (0.3, "passive body")
    with caplog.at_level(logging.INFO, logger="aquarom"):
        report_strains(report, warn=False)           # a stopped run: its error line only
        assert not [record for record in caplog.records if record.levelno == logging.WARNING]
        report_strains(report)
    warnings = [record.getMessage() for record in caplog.records if record.levelno == logging.WARNING]
    assert len(warnings) == 1 and "\n" not in warnings[0]
    assert f"{100 * 2 * STRAIN_LIMIT:.1f} %" in warnings[0] and "passive body" in warnings[0]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """(FOM summary, ROM summary) of `aquarom simulate` on a short level-1 scene at a design ξ ≠ 0 (the
    ROM built there: its strains are measured from that design's rest shape, as the FOM's)."""
    from aquarom_fenics.cli import main

    out = tmp_path_factory.mktemp("strain")
    scene = write_short_scene(out, duration=0.3)
    summaries = []
    for model in ("fom", "rom"):
        assert main(["simulate", scene, "--xi", "z_tail=0.2", "--xi", "y_thin=-0.1", "--no-progress",
                     "--model", model, "--out", str(out / model)]) == 0
        summaries.append(json.loads((out / model / "summary.json").read_text()))
    return summaries


def test_fom_and_rom_runs_report_the_strain_with_its_region(runs):
    full, reduced = (summary["strain"] for summary in runs)
    for strain in (full, reduced):
        assert strain["region"] in strain["by_region"]
        assert set(strain["by_region"]) <= {"passive body", "head", "left_muscle", "right_muscle"}
        assert strain["max_principal"] == max(strain["history"]["max_principal"]) > 0.0
        assert strain["time"] in strain["history"]["time"]
        assert strain["above_limit"] == (strain["max_principal"] > STRAIN_LIMIT)
    assert full["region"] in ("left_muscle", "right_muscle")      # the muscles bend the body, the head is stiff
    assert full["by_region"]["head"] < 0.1 * full["max_principal"]
    assert reduced["max_principal"] == pytest.approx(full["max_principal"], rel=0.05)
