"""Radio ranging.

The range error per anchor (:mod:`.ranging`) and positions from ranges by NLLS and Min-Max
(:mod:`.multilateration`).
"""
