"""Finished results read back: comparisons across evaluations and evo result zips."""
