"""Reading vector plan files into plain geometry (VectorGeometry: segments, closed rings,
circles, in metres), one module per format: dxf.py (ezdxf), svg.py (svgelements), geojson.py
(shapely); geometry.py holds VectorGeometry and the limits they share. Curves are
flattened to chords within ARC_CHORD; every coordinate is checked finite and on Earth."""

from .dxf import read_dxf
from .geojson import read_geojson
from .geometry import ARC_CHORD, CIRCLE_FIT_TOLERANCE, MIN_CIRCLE_VERTICES, VECTOR_SUFFIXES, VectorGeometry
from .svg import read_svg

__all__ = ["ARC_CHORD", "CIRCLE_FIT_TOLERANCE", "MIN_CIRCLE_VERTICES", "VECTOR_SUFFIXES", "VectorGeometry", "read_dxf", "read_geojson",
           "read_svg"]
