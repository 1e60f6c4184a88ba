"""How far outside a field's SDF zero level its volume rendering puts the silhouette, and so how far the
exported surface is grown to sit where the photos saw the object.

VolSDF's density (Laplace CDF of the signed distance, scale beta) reaches a few beta outside the zero
level. A ray passing a surface of curvature radius r at distance d outside gathers an optical depth of
about (1 / 2 beta) sqrt(2 pi r beta) exp(-d / beta) (the Gaussian integral of the density along the
chord), which is ln 2 (opacity 0.5, the mask's edge) at

    d = beta ln( sqrt(2 pi r / beta) / (2 ln 2) ).

A refinement fits the rendered silhouettes to the masks, so its zero level comes out inside the object
by that much (measured on the synthetic set after 3 minutes at 1/beta = 500: the field's surface points
a median 0.004-0.008 R inside the true surface on every object, 70-92% of them inside; the rendered
opacity 2-4% larger than the masks), and so would the export, which is that zero level.
"""

from __future__ import annotations

import math

# The curvature radius the offset is computed for (field units; the object's radius is about 1): the
# offset depends on it only through a logarithm (r = 0.1 to 1 moves it by 0.6 beta either way).
TYPICAL_CURVATURE_RADIUS = 0.3


def silhouette_offset(beta: float, curvature_radius: float = TYPICAL_CURVATURE_RADIUS) -> float:
    """The distance outside the zero level at which a grazing ray's opacity reaches 0.5 (field units);
    0 when beta is not positive."""
    if not beta > 0:
        return 0.0
    return max(beta * math.log(math.sqrt(2.0 * math.pi * curvature_radius / beta) / (2.0 * math.log(2.0))), 0.0)


def surface_level(field_) -> float:
    """The SDF level a field's surface is taken at (export, Chamfer distance): a refined field's
    silhouette offset at the beta it was fitted at (Field.fitted_beta), 0 for any other field."""
    beta = getattr(field_, "fitted_beta", None)
    return silhouette_offset(beta) if beta is not None else 0.0
