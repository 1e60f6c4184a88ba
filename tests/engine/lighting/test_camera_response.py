"""The tone curve a capture's photos are read through (its inverse against the display transform:
test_capture_lighting.py)."""

from __future__ import annotations

import pytest

from lirm.engine.lighting.camera_response import response_for_capture


def test_a_capture_is_read_through_srgb_only_on_a_clipped_plain_backdrop():
    assert response_for_capture("auto", plain_backdrop=True, clipped_share=0.9)[0] == "srgb"
    assert response_for_capture("auto", plain_backdrop=True, clipped_share=0.2)[0] == "aces"  # a grey backdrop
    assert response_for_capture("auto", plain_backdrop=False, clipped_share=1.0)[0] == "aces"  # a bright window
    assert response_for_capture("aces", plain_backdrop=True, clipped_share=1.0) == ("aces", "as asked")
    assert response_for_capture("srgb", plain_backdrop=False, clipped_share=0.0) == ("srgb", "as asked")
    with pytest.raises(ValueError, match="unknown camera response"):
        response_for_capture("filmic", plain_backdrop=False, clipped_share=0.0)
