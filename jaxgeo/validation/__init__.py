"""Validation against analytic geodesics: the sphere's great circles and the
catenoid's geodesics, on meshes of both, with the exact polyhedral length of other
packages as a second reference (`jaxgeo validate`).

One job per module: `analytic` (great circles, catenoid geodesics by Clairaut's
relation and by shooting, the laser ray's descent curve), `suites` (the meshes and
their vertex pairs), `references` (the methods run and the exact polyhedral
solvers, pygeodesic and potpourri3d), `report` (the table, CSV, Markdown,
convergence summary and plot, and `validate`, which runs it all).
"""

from .analytic import (
    CatenoidGeodesic as CatenoidGeodesic,
    catenoid_descent_curve as catenoid_descent_curve,
    catenoid_geodesic_length as catenoid_geodesic_length,
    catenoid_geodesic_points as catenoid_geodesic_points,
    catenoid_geodesics as catenoid_geodesics,
    catenoid_meridian_length as catenoid_meridian_length,
    catenoid_neck_arc_length as catenoid_neck_arc_length,
    great_circle_length as great_circle_length,
    great_circle_points as great_circle_points,
)
from .references import (
    EXACT_SOLVERS as EXACT_SOLVERS,
    MethodResult as MethodResult,
    available_methods as available_methods,
)
from .report import (
    Row as Row,
    Table as Table,
    convergence_summary as convergence_summary,
    plot_convergence as plot_convergence,
    read_csv as read_csv,
    run_suite as run_suite,
    summary_markdown as summary_markdown,
    validate as validate,
)
from .suites import (
    CATENOID_PAIRS as CATENOID_PAIRS,
    SPHERE_ANGLES as SPHERE_ANGLES,
    SUITES as SUITES,
    Pair as Pair,
    Suite as Suite,
    catenoid_mesh as catenoid_mesh,
    catenoid_suite as catenoid_suite,
    sphere_suite as sphere_suite,
)

# `from jaxgeo.validation import *`: the analytic lengths, as before the split
__all__ = [
    "CatenoidGeodesic",
    "catenoid_geodesic_length",
    "catenoid_geodesics",
    "catenoid_meridian_length",
    "catenoid_neck_arc_length",
    "great_circle_length",
]
