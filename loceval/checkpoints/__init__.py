"""Surveyed control points as the reference.

Visits found from stops (:mod:`.stops`), the robust weighted fit and per-visit errors
(:mod:`.fit`), Hilti and LaMAria scores (:mod:`.scores`), and the options of the
control-point evaluation (:mod:`.config`).
"""
