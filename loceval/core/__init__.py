"""The building blocks every stage uses.

Array types, rotations and similarity transforms, quantiles, gaps in a stream of stamps,
polylines, and text made safe to show. Imports only :mod:`loceval.errors`; every other
package of the core may import it.
"""
