"""Scattered-data interpolation of RRBC correction fields (docs/theory.md §4).

Data: fiducial positions x_i (N x 3, sensor frame, mm) and correction vectors e_i (N x 3, mm). A *method* object
(`IDW`, `Linear`, `TPS`, `GP`, `NoCorrection`: small frozen dataclasses holding options; one module each) is fitted with
``method.fit(points, values)`` and the fitted object predicts corrections at query points (targets, sensor
frame, mm) with ``fitted.predict(query) -> Prediction``. `make_interpolator(name, **options)` builds a method
from its command-line name (`METHODS`).

Coordinates. Every method except IDW works in the fiducials' local principal coordinates
(`geometry.LocalFrame`): centred on the fiducial centroid, rotated onto the principal axes, divided by the RMS
distance from the centroid (so they are O(1) and smoothing / length-scale values do not depend on mm), and
truncated to the dimension of the fiducial set:

- dim 3 (a volume): 3-D local coordinates.
- dim 2 (coplanar fiducials, e.g. a breadboard): the 2-D coordinates in the fiducials' best-fit plane. 3-D
  Delaunay and 3-D TPS fail on such sets (the initial simplex is flat / the monomial matrix is rank deficient),
  so the methods interpolate in the plane and a query is *projected* onto it: a target above the plate gets
  the correction of its foot point, because variation normal to the plate is unobservable from coplanar
  fiducials.
- dim 1 (collinear fiducials): the coordinate along the line; `Linear` is piecewise linear along it.
- dim 0 (all fiducials coincide): only a constant can be fitted; IDW (and `NoCorrection`) accept it, the
  other methods raise `InputError`.

IDW follows the published rule literally and uses 3-D Euclidean distances in the sensor frame.

Extrapolation flag (`hull_flags`, shared by every method). A query is *extrapolated* when its projection into
the local coordinates lies outside the convex hull of the fiducials by more than `HULL_TOL` local units (the
hull's facet equations, so queries on a fiducial or on a hull face count as inside; for dim 1 outside
[min, max] by more than `HULL_TOL` local units). **For coplanar fiducials the hull is the 2-D polygon in the
plane and a query is judged by its projection only**: a target 100 mm above the middle of a plate is *not*
flagged, and its distance from the plane is reported separately as ``off_plane_mm`` (distance from the
fiducials' affine hull: plane for dim 2, line for dim 1, zero for dim 3). For dim 0 the hull is the point
cluster itself: ``off_plane_mm`` is the distance from the fiducials' centroid and a query is extrapolated when
that distance exceeds the cluster radius (plus `HULL_TOL` mm).

Methods (docs/theory.md §4.1-4.4):

- `IDW(k, power)`: the k nearest fiducials (3-D distance, sensor frame), weights 1/d^p normalised to sum 1; a
  query closer than `EXACT_MM` to a fiducial takes its correction (the mean if several fiducials are that
  close). Exact at the data, reproduces constants only, tends to the mean of the k nearest far away. No std.
- `Linear()`: barycentric interpolation in the enclosing Delaunay simplex (local coordinates). Outside the hull
  it extends linearly from the "nearest" simplex (the one whose smallest barycentric coordinate is largest)
  instead of returning NaN; such queries are flagged. Reproduces affine fields exactly everywhere. No std.
- `TPS(smoothing)`: `scipy.interpolate.RBFInterpolator` with the thin-plate-spline kernel and a degree-1
  polynomial, in local coordinates (so ``smoothing`` is in the units of local coordinates, independent of mm).
  Exact at the data for smoothing 0; linear precision and linear extrapolation. No std.
- `GP(kernel, noise_mm)`: Gaussian process / universal kriging with a linear mean estimated by generalised least
  squares, Matérn 5/2 (or squared-exponential) kernel and a white-noise term; hyper-parameters shared by the 3
  components and fitted by restricted maximum likelihood (REML). Returns the predictive standard deviation of
  the latent correction (mm), including the trend-uncertainty term of universal kriging.
- `NoCorrection()`: predicts zero corrections (std None); the baseline.
- `Auto()`: one of the above with its options, chosen by cross-validation over the fiducials (`interpolation.auto`).

All errors in user input raise `errors.InputError`.
"""

from __future__ import annotations

from rrbc_core.interpolation.auto import Auto
from rrbc_core.interpolation.base import EXACT_MM, FittedInterpolator, Prediction
from rrbc_core.interpolation.gp import GP
from rrbc_core.interpolation.hull import HULL_TOL, hull_flags
from rrbc_core.interpolation.idw import IDW, NoCorrection
from rrbc_core.interpolation.linear import SLIVER_QUALITY, Linear
from rrbc_core.interpolation.tps import TPS
from rrbc_core.option_specs import build_from_registry

__all__ = [
    "EXACT_MM",
    "HULL_TOL",
    "SLIVER_QUALITY",
    "METHODS",
    "FittedInterpolator",
    "Prediction",
    "IDW",
    "Linear",
    "TPS",
    "GP",
    "NoCorrection",
    "Auto",
    "hull_flags",
    "make_interpolator",
]

METHODS = {"idw": IDW, "linear": Linear, "tps": TPS, "gp": GP, "none": NoCorrection, "auto": Auto}


def make_interpolator(name: str, **options) -> IDW | Linear | TPS | GP | NoCorrection | Auto:
    """The interpolation method object for a command-line name, ready to ``fit(points, values)``.

    Parameters
    ----------
    name : str
        A name in `METHODS`: "idw", "linear", "tps", "gp", "none", "auto" (chosen by cross-validation over the
        fiducials, `interpolation.auto`).
    **options
        The method's options (idw: ``k``, ``power``; tps: ``smoothing``; gp: ``kernel``, ``noise_mm``); None means
        the default.

    Returns
    -------
    IDW, Linear, TPS, GP or NoCorrection
        ``method.fit(points (N, 3) sensor frame mm, values (N, 3) mm)`` gives a fitted interpolator whose
        ``predict(query (M, 3))`` returns a `Prediction`.

    Raises
    ------
    InputError
        An unknown name, or an option the method does not take or that is out of range.
    """
    return build_from_registry(
        METHODS,
        name,
        options,
        f"unknown interpolation method {name!r}; valid methods: {', '.join(METHODS)}",
        "method {key}",
    )
