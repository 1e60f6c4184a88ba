"""Next-view guidance: where the photographer should shoot next (coverage and model uncertainty)."""
