"""A reduced model of a Neo-Hookean scene says in one line, when it is built, that its internal force is
the law's small-strain (SVK) expansion; an SVK scene's build says nothing of it."""
import logging

from conftest import coarse_scene

from aquarom_fenics.reduction.reductor import build_prom, material_law_warning


def test_a_neo_hookean_build_warns_in_one_line_and_svk_has_no_such_line(caplog):
    svk = coarse_scene(solver={"duration": 0.2})
    neo_hookean = svk.replace("material", law="neo-hookean")
    assert material_law_warning(svk) is None
    line = material_law_warning(neo_hookean)
    assert "\n" not in line and 'law = "neo-hookean"' in line and "3 %" in line
    with caplog.at_level(logging.WARNING, logger="aquarom"):
        rom = build_prom(neo_hookean, parametric=False)
    warnings = [record.getMessage() for record in caplog.records if record.levelno >= logging.WARNING]
    assert warnings == [line]
    assert rom.size > 0
