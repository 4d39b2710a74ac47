"""The paths and control points as CAD and 3D files placed on the building model.

DXF, Rhino .3dm, 3DM-compatible JSON, glTF and IFC writers, and the placement they share
(simplification, units, the site transform, the georeference, the building files read).
"""
