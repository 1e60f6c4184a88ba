"""The scale bar's label (viewport_guides.format_length)."""

from lirm.app.panels.viewport_guides import format_length


def test_lengths_read_as_a_person_writes_them():
    assert format_length(1.0, metres=False) == "1 unit"
    assert format_length(0.2, metres=False) == "0.2 units" and format_length(2.0, metres=False) == "2 units"
    assert format_length(0.05, metres=True) == "5 cm" and format_length(0.002, metres=True) == "2 mm"
    assert format_length(1.0, metres=True) == "1 m"
