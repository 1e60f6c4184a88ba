"""From a field to an asset: mesh extraction (and, later, UV atlas, baking and glTF export)."""
