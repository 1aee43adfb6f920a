"""Units at the edge: every factor compgen accepts, pinned by its definition (not by
compgen's own table), and the bare zero that --fix NAME=0 relies on."""

import math

import pytest

from compgen.errors import CompgenError
from compgen.units import parse_quantity, shown, to_inside

# definitions: 1 µm = 1/1000 mm; 1 µrad = 1e-6 rad; 360° = 2π rad; 1″ = 1/3600 °
DEFINED = [("1mm", "mm", 1.0), ("1um", "mm", 0.001), ("1µm", "mm", 0.001), ("2.5um", "mm", 0.0025),
           ("0.03rad", "rad", 0.03), ("1urad", "rad", 1e-6), ("1µrad", "rad", 1e-6),
           ("1.8deg", "rad", math.pi / 100), ("3600arcsec", "rad", math.pi / 180), ("-7.2arcsec", "rad",
                                                                              -7.2 / 3600 * math.pi / 180)]


@pytest.mark.parametrize("text, inside, value", DEFINED)
def test_every_unit_converts_by_its_definition(text, inside, value):
    assert parse_quantity(text, inside, "t") == pytest.approx(value, rel=1e-15)


@pytest.mark.parametrize("inside", ["mm", "rad"])
def test_a_bare_zero_is_zero_and_a_bare_number_is_refused(inside):
    for zero in ("0", "0.0", " -0 ", "0um" if inside == "mm" else "0arcsec"):
        assert parse_quantity(zero, inside, "t") == 0.0
    with pytest.raises(CompgenError, match="has no unit"):
        parse_quantity("1", inside, "t")


@pytest.mark.parametrize("text, inside", [("1um", "rad"), ("1arcsec", "mm"), ("1deg", "mm"), ("1mm", "rad")])
def test_a_wrong_dimension_is_refused(text, inside):
    with pytest.raises(CompgenError, match="is not a"):
        parse_quantity(text, inside, "t")


def test_a_value_no_machine_error_has_is_refused():
    """Beyond 10 mm or 0.1 rad the model's arithmetic would carry nonsense to the control."""
    assert parse_quantity("9.99mm", "mm", "t") == 9.99
    for text, inside in (("10.01mm", "mm"), ("0.11rad", "rad"), ("6deg", "rad"), ("1e300um", "mm")):
        with pytest.raises(CompgenError, match="not the size of a machine error"):
            parse_quantity(text, inside, "t")


def test_non_finite_and_unknown_units_are_refused():
    with pytest.raises(CompgenError, match="not a finite number"):
        to_inside(float("inf"), "um", "mm")
    with pytest.raises(CompgenError, match="unknown unit"):
        parse_quantity("1in", "mm", "t")


def test_shown_units_are_micrometres_and_arcseconds():
    assert shown(0.0015, "mm") == (pytest.approx(1.5, rel=1e-15), "µm")
    assert shown(math.pi / 180 / 3600, "rad") == (pytest.approx(1.0, rel=1e-15), "″")


def test_three_columns_never_run_together():
    """The per-path tables: 9 characters a value, so 10 µm and more keep a space between."""
    from compgen.units import three, three_header
    assert three([1.0, 22.5, -333.25]) == "    1.000   22.500 -333.250"
    assert three([8.9, 10.263, 12.676]).split() == ["8.900", "10.263", "12.676"]
    assert three_header(("RMS dX", "dY", "dZ")) == "   RMS dX       dY       dZ"


def test_a_long_text_where_a_number_belongs_is_refused_with_its_first_forty_characters():
    """A whole line pasted where a number belongs is quoted cut at 40 characters, not in full."""
    from compgen.units import number
    text = "1.5; DROP TABLE fits; -- " + "x" * 60
    with pytest.raises(CompgenError) as refused:
        number(text, "$TC_CARR3 value", "a.spf:2")
    said = str(refused.value)
    assert f"$TC_CARR3 value {text[:40] + '...'!r} is not a number" in said and text[40:] not in said
    with pytest.raises(CompgenError, match=r"value '12x' is not a number"):
        number("12x", "value", "")
