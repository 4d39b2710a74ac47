"""How sure each figure is.

Block-bootstrap intervals (:mod:`.uncertainty`), paired comparisons of estimates
(:mod:`.comparison`), NEES consistency (:mod:`.consistency`), the ground truth's own error
(:mod:`.reference_error`), the tolerance verdict (:mod:`.verdict`), and the one assessment
of an evaluation that gathers them (:mod:`.assess`).
"""
