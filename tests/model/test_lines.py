"""The conversion to axis lines, against a derivation by hand (to first order in the
angles, with the offset × angle terms): a location error of A moves the line of C, which
it carries, by A's tilt times the height of C's pivot above A's."""

import numpy as np
import pytest
from conftest import ARCSEC, TABLE4, UM

from compgen.model.lines import axis_lines

ZC = 29.794            # the C pivot above the A/C intersection, seed Table 3 (mm)
SECOND_ORDER_MM = 1e-7   # what is left: Zc × angle² ≈ 30 mm × (6e-5)² ≈ 1e-7 mm


def test_table4_lines_by_hand(seed_machine):
    t = TABLE4
    lines = axis_lines(seed_machine, t)
    a, c = lines["A"], lines["C"]
    np.testing.assert_allclose(a.offset, [0.0, t["YOA"], t["ZOA"]], atol=SECOND_ORDER_MM)
    np.testing.assert_allclose(a.tilt, [0.0, t["BOA"], t["COA"]], atol=1e-12)
    # C is carried by A: A's offset moves it, A's tilt about Y swings its pivot by BOA·Zc in
    # X; ZOA lifts it off the plane of the nominal pivot, and following the tilted line
    # (direction ≈ (tilt_y, −tilt_x, 1)) back down to that plane shifts it by −ZOA × direction;
    # C's own offsets are turned by A's COA about Z: (XOC − COA·YOC, YOC + COA·XOC)
    tilt_x, tilt_y = t["AOC"], t["BOC"] + t["BOA"]
    np.testing.assert_allclose(
        c.offset, [t["XOC"] - t["COA"] * t["YOC"] + t["BOA"] * ZC - t["ZOA"] * tilt_y,
                   t["YOC"] + t["COA"] * t["XOC"] + t["YOA"] + t["ZOA"] * tilt_x, 0.0],
        atol=SECOND_ORDER_MM)
    # composing two small rotations adds a term ½·a × b ≈ ½ · 3e-5 · 6e-5 ≈ 1e-9 rad
    np.testing.assert_allclose(c.tilt, [t["AOC"], t["BOC"] + t["BOA"], 0.0], atol=2e-9)
    # the README's figures: (+3.17, +4.60) µm, (−6.50, +7.70)″
    assert c.offset[0] / UM == pytest.approx(3.17, abs=0.005)
    assert c.tilt[1] / ARCSEC == pytest.approx(7.70, abs=0.005)


@pytest.mark.parametrize("name, value", [("XOC", 5 * UM), ("YOC", -3 * UM), ("YOA", 4 * UM),
                                         ("ZOA", -2 * UM)])
def test_an_offset_alone_gives_a_line_with_no_tilt(seed_machine, name, value):
    lines = axis_lines(seed_machine, {name: value})
    for line in lines.values():
        assert line.tilt.shape == (3,) and np.all(np.isfinite(line.offset)) and np.all(line.tilt == 0.0)
        assert np.allclose(line.direction, np.eye(3)["xyz".index(line.nominal)])
    axis = lines[name[-1]]
    assert axis.offset["XYZ".index(name[0])] == pytest.approx(value, abs=1e-15)
